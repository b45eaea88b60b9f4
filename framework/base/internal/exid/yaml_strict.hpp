// exid — strict YAML: a mapping that repeats a key is an error naming both lines (yaml-cpp keeps
// both entries and answers a lookup with the first, so a second `estimator:` was silently
// ignored). Header-only: used by the study and matrix parsers and the DH robot loader.
#pragma once

#include <fmt/format.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/export.hpp"

namespace exid {

/// Nodes reached through aliases at most, each alias counted with everything under its anchor
/// (nested aliases expanded): yaml-cpp shares an anchored node between its aliases, so 5,000
/// aliases of one model cost nothing to parse, but every consumer expands them (a 35 KB study
/// stacked 5,000 models and took 3.2 GB).
inline constexpr long kMaxYamlAliasNodes = 100000;

namespace detail {

// Counts, from the parser's events (no node tree is built), the nodes every alias stands for,
// and stops at the alias that takes the total over kMaxYamlAliasNodes, with its place.
class EXID_API AliasCounter : public YAML::EventHandler {
 public:
  struct Stop {};
  bool over = false, cycle = false;
  double through_aliases = 0;  // nodes reached through aliases so far (double: may be huge)
  int line = 0;
  std::string path, alias;

  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnAnchor(const YAML::Mark&, const std::string& name) override { anchor_name_ = name; }
  void OnNull(const YAML::Mark&, YAML::anchor_t anchor) override {
    keyOrValue("~");
    done(1, anchor);
  }
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t anchor,
                const std::string& value) override {
    keyOrValue(value);
    done(1, anchor);
  }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t anchor) override {
    // an alias inside the node its anchor names: a cycle, whose expansion never ends
    for (const Frame& f : stack_)
      if (f.anchor != 0 && f.anchor == anchor) {
        cycle = true;
        line = mark.line + 1;
        path = currentPath();
        const auto nm = names_.find(anchor);
        alias = nm == names_.end() ? std::string("?") : nm->second;
        throw Stop{};
      }
    const auto it = size_.find(anchor);
    const double n = it == size_.end() ? 1.0 : it->second;  // (an anchor still open: 1)
    keyOrValue("*");
    through_aliases += n;
    if (through_aliases > static_cast<double>(kMaxYamlAliasNodes)) {
      over = true;
      line = mark.line + 1;
      path = currentPath();
      const auto nm = names_.find(anchor);
      alias = nm == names_.end() ? std::string("?") : nm->second;
      throw Stop{};
    }
    done(n, 0);
  }
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t anchor,
                       YAML::EmitterStyle::value) override {
    open(false, anchor);
  }
  void OnSequenceEnd() override { close(); }
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t anchor,
                  YAML::EmitterStyle::value) override {
    open(true, anchor);
  }
  void OnMapEnd() override { close(); }

 private:
  struct Frame {
    bool map;
    YAML::anchor_t anchor;
    double count = 1;  // the container itself
    long index = 0;    // a sequence's next element
    bool at_key = true;
    std::string key;
  };
  std::vector<Frame> stack_;
  std::map<YAML::anchor_t, double> size_;
  std::map<YAML::anchor_t, std::string> names_;
  std::string anchor_name_;

  void named(YAML::anchor_t anchor) {
    if (anchor != 0) names_[anchor] = anchor_name_;
  }
  // a scalar in a key's place names the value that follows
  void keyOrValue(const std::string& text) {
    if (!stack_.empty() && stack_.back().map && stack_.back().at_key) stack_.back().key = text;
  }
  void open(bool map, YAML::anchor_t anchor) {
    if (!stack_.empty() && stack_.back().map && stack_.back().at_key) stack_.back().key = "?";
    named(anchor);
    stack_.push_back(Frame{map, anchor, 1, 0, true, {}});
  }
  void close() {
    const Frame f = stack_.back();
    stack_.pop_back();
    done(f.count, f.anchor);
  }
  // a whole node of n nodes (expanded) ends
  void done(double n, YAML::anchor_t anchor) {
    if (anchor != 0) {
      named(anchor);
      size_[anchor] = n;
    }
    if (stack_.empty()) return;
    Frame& p = stack_.back();
    p.count += n;
    if (p.map)
      p.at_key = !p.at_key;
    else
      ++p.index;
  }
  std::string currentPath() const {
    std::string out;
    for (const Frame& f : stack_) {
      if (f.map)
        out += (out.empty() ? "" : ".") + f.key;
      else
        out += "[" + std::to_string(f.index) + "]";
    }
    return out;
  }
};

}  // namespace detail

/// Refuses a document whose aliases stand for more than kMaxYamlAliasNodes nodes, counted from
/// the text before any node is built: "FILE:LINE: PATH: alias *a ...". Malformed YAML is left to
/// the parser that builds the nodes (its message is the one reported).
inline void checkYamlAliases(const std::string& text, const std::string& source) {
  if (text.find('*') == std::string::npos) return;  // no alias (the pass costs 40 % of a parse)
  detail::AliasCounter counter;
  try {
    std::istringstream in(text);
    YAML::Parser parser(in);
    parser.HandleNextDocument(counter);
  } catch (const detail::AliasCounter::Stop&) {
  } catch (const YAML::Exception&) {
    return;
  }
  if (counter.cycle)
    throw Error(fmt::format(
        "{}:{}: {}: alias *{} stands inside the node its anchor &{} names: a cycle, which never "
        "ends when expanded; refused",
        source, counter.line, counter.path.empty() ? std::string("(top level)") : counter.path,
        counter.alias, counter.alias));
  if (counter.over)
    throw Error(fmt::format(
        "{}:{}: {}: alias *{} takes the nodes reached through aliases beyond {} (each alias "
        "counts every node under its anchor); a document may share a block through a few "
        "aliases, not multiply itself: write the blocks out",
        source, counter.line, counter.path.empty() ? std::string("(top level)") : counter.path,
        counter.alias, kMaxYamlAliasNodes));
}

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
