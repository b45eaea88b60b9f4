// exid — strict YAML: a mapping that repeats a key is an error naming both lines (yaml-cpp keeps
// both entries and answers a lookup with the first, so a second `estimator:` was silently
// ignored). Header-only: used by the study and matrix parsers and the DH robot loader.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>
#include <vector>

namespace exid {

/// Nodes visited at most (aliases are visited once per reference: a document whose aliases
/// expand beyond this is refused).
inline constexpr long kMaxYamlNodes = 2000000;

/// Every repeated key of every mapping under node: "FILE:LINE: PATH: duplicate key 'k' (first
/// at line L0)". max_depth bounds the recursion; *budget the number of nodes visited.
inline void duplicateKeys(const YAML::Node& node, const std::string& source,
                          const std::string& path, std::vector<std::string>* out,
                          int max_depth = 200, long* budget = nullptr) {
  long own = kMaxYamlNodes;
  if (!budget) budget = &own;
  if (!node || max_depth <= 0 || *budget < 0) return;
  if (--*budget < 0) {
    out->push_back(source + ": more than " + std::to_string(kMaxYamlNodes) +
                   " YAML nodes once aliases are expanded; refused");
    return;
  }
  if (node.IsMap()) {
    std::vector<std::pair<std::string, int>> seen;
    for (const auto& kv : node) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
      const int line = kv.first.Mark().line + 1;
      if (kv.first.IsScalar()) {
        for (const auto& [k, l] : seen)
          if (k == key) {
            out->push_back(source + ":" + std::to_string(line) + ": " +
                           (path.empty() ? key : path + "." + key) + ": duplicate key '" + key +
                           "' (first at line " + std::to_string(l) +
                           "); a key may appear once in a mapping");
            break;
          }
        seen.emplace_back(key, line);
      }
      duplicateKeys(kv.second, source, path.empty() ? key : path + "." + key, out, max_depth - 1,
                    budget);
    }
  } else if (node.IsSequence()) {
    std::size_t i = 0;
    for (const auto& e : node) {
      duplicateKeys(e, source, path + "[" + std::to_string(i) + "]", out, max_depth - 1, budget);
      ++i;
    }
  }
}

}  // namespace exid
