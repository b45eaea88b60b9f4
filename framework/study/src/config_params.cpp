// exid — a plugin's parameters resolved against its declarations: each value converted to its
// declared type and checked against its rules, defaults filled in, unknown and missing keys
// reported (resolveInto, resolveParams); a plugin's section {type, params} (parseSpec).
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>

#include "config_internal.hpp"
#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/registry.hpp"

namespace exid {

namespace fs = std::filesystem;

namespace config_detail {

std::string scalarText(const YAML::Node& n) {
  if (n.IsScalar()) return n.Scalar();
  if (n.IsSequence()) return "[...]";
  if (n.IsMap()) return "{...}";
  return "null";
}

std::optional<std::int64_t> toInt(const std::string& s) {
  if (s.empty()) return std::nullopt;
  std::size_t pos = 0;
  try {
    long long v = std::stoll(s, &pos, 10);
    if (pos != s.size()) return std::nullopt;
    return v;
  } catch (...) {
    return std::nullopt;
  }
}

std::optional<double> toDouble(const std::string& s) {
  if (s == ".inf" || s == "inf" || s == "+.inf") return HUGE_VAL;
  if (s == "-.inf" || s == "-inf") return -HUGE_VAL;
  if (s == ".nan" || s == "nan" || s == "NaN") return std::nan("");
  if (s.empty() || std::isspace(static_cast<unsigned char>(s[0]))) return std::nullopt;
  // strtod, not stod: a subnormal (5e-324) is a number (stod threw on the underflow); an
  // overflow is inf, which the range check refuses.
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size()) return std::nullopt;
  return v;
}

std::optional<bool> toBool(const std::string& s) {
  if (s == "true" || s == "True" || s == "TRUE" || s == "yes" || s == "on") return true;
  if (s == "false" || s == "False" || s == "FALSE" || s == "no" || s == "off") return false;
  return std::nullopt;
}

namespace {

// Elements of one list parameter at most (a longer list is refused before it is converted).
constexpr std::size_t kMaxListElements = 100000;

// Converts a YAML node into the declared type; returns nullopt and sets why on failure.
std::optional<ParamValue> convert(const ParamDecl& d, const YAML::Node& n, const fs::path& base_dir,
                                  std::string* why) {
  auto expect = [&](const char* what) {
    std::string found = scalarText(n);
    if (found.size() > 80)
      found = found.substr(0, 60) + fmt::format("... ({} bytes)", found.size());
    *why = fmt::format("expected {}, found '{}'", what, found);
    return std::nullopt;
  };
  if (n.IsSequence() && n.size() > kMaxListElements) {
    *why =
        fmt::format("a list of {} elements; at most {} are accepted", n.size(), kMaxListElements);
    return std::nullopt;
  }
  switch (d.type) {
    case ParamType::Bool: {
      if (!n.IsScalar()) return expect("true or false");
      auto b = toBool(n.Scalar());
      if (!b) return expect("true or false");
      return ParamValue(*b);
    }
    case ParamType::Int: {
      if (!n.IsScalar()) return expect("an integer");
      auto i = toInt(n.Scalar());
      if (!i) return expect("an integer");
      return ParamValue(*i);
    }
    case ParamType::Double: {
      if (!n.IsScalar()) return expect("a number");
      auto v = toDouble(n.Scalar());
      if (!v) return expect("a number");
      return ParamValue(*v);
    }
    case ParamType::String: {
      if (!n.IsScalar()) return expect("a string");
      return ParamValue(n.Scalar());
    }
    case ParamType::Path: {
      if (!n.IsScalar()) return expect("a file path");
      // An empty path means "none" where the plugin's default is empty (optional files); it must
      // survive a round trip through the resolved study.
      if (n.Scalar().empty()) {
        const auto* def = d.default_value ? std::get_if<std::string>(&*d.default_value) : nullptr;
        if (def && def->empty()) return ParamValue(std::string());
        return expect("a file path");
      }
      // A NUL would cut the path where the system reads it (`good.csv\0.ignored` read good.csv).
      const std::string& text = n.Scalar();
      for (std::size_t i = 0; i < text.size(); ++i) {
        const auto u = static_cast<unsigned char>(text[i]);
        if (u < 0x20 || u == 0x7F) {
          *why = fmt::format(
              "the path '{}' holds the control byte 0x{:02X} at byte {}; a file path must not "
              "hold control bytes",
              printablePath(text), u, i + 1);
          return std::nullopt;
        }
      }
      fs::path p(text);
      if (p.is_relative() && !base_dir.empty()) p = base_dir / p;
      return ParamValue(p.lexically_normal().string());
    }
    case ParamType::IntList: {
      if (!n.IsSequence()) return expect("a list of integers");
      std::vector<std::int64_t> out;
      for (const auto& e : n) {
        auto i = e.IsScalar() ? toInt(e.Scalar()) : std::nullopt;
        if (!i) return expect("a list of integers");
        out.push_back(*i);
      }
      return ParamValue(out);
    }
    case ParamType::DoubleList: {
      if (!n.IsSequence()) return expect("a list of numbers");
      std::vector<double> out;
      for (const auto& e : n) {
        auto v = e.IsScalar() ? toDouble(e.Scalar()) : std::nullopt;
        if (!v) return expect("a list of numbers");
        out.push_back(*v);
      }
      return ParamValue(out);
    }
    case ParamType::StringList: {
      if (!n.IsSequence()) return expect("a list of strings");
      std::vector<std::string> out;
      for (const auto& e : n) {
        if (!e.IsScalar()) return expect("a list of strings");
        out.push_back(e.Scalar());
      }
      return ParamValue(out);
    }
  }
  return std::nullopt;
}

std::vector<std::string> keysOf(const std::vector<ParamDecl>& decls) {
  std::vector<std::string> k;
  for (const auto& d : decls) k.push_back(d.name);
  return k;
}

}  // namespace

void unknownKey(Problems& pr, const YAML::Node& at, const std::string& path, const std::string& key,
                const std::vector<std::string>& allowed) {
  std::string msg =
      fmt::format("{}: unknown key '{}'; allowed: {}", path.empty() ? key : path + "." + key, key,
                  allowed.empty() ? "(none)" : fmt::format("{}", fmt::join(allowed, ", ")));
  std::string close = closestMatch(key, allowed);
  if (!close.empty()) msg += fmt::format("; did you mean '{}'?", close);
  pr.add(at, msg);
}

// The text of a mapping key; a key that is not a plain scalar (`{a: 1}: x`, `[a]: x`, `? ...`) is
// a problem at its line (found by tests/fuzz/fuzz_study: converting it to a string threw
// YAML::TypedBadConversion out of parseStudy).
std::optional<std::string> keyName(Problems& pr, const YAML::Node& key, const std::string& path) {
  if (key.IsScalar()) return key.Scalar();
  pr.add(key, fmt::format("{}a key must be a plain name, found '{}'",
                          path.empty() ? "" : path + ": ", scalarText(key)));
  return std::nullopt;
}

// Fills `out` from a params mapping node (may be null) and the declarations.
void resolveInto(const PluginInfo& info, const YAML::Node& params, const std::string& path,
                 const fs::path& base_dir, Problems& pr, ParamSet& out) {
  out.context = path;
  if (params && !params.IsNull() && !params.IsMap()) {
    pr.add(params, fmt::format("{}: expected a mapping of parameters, found '{}'", path,
                               scalarText(params)));
    return;
  }
  if (params && params.IsMap()) {
    for (const auto& kv : params) {
      const std::optional<std::string> name = keyName(pr, kv.first, path);
      if (!name) continue;
      const std::string& key = *name;
      bool known = false;
      for (const auto& d : info.params) known = known || d.name == key;
      if (!known) unknownKey(pr, kv.first, path, key, keysOf(info.params));
    }
  }
  for (const auto& d : info.params) {
    YAML::Node v = (params && params.IsMap()) ? params[d.name] : YAML::Node();
    if (v && !v.IsNull()) {
      std::string why;
      auto val = convert(d, v, base_dir, &why);
      if (!val) {
        pr.add(v, fmt::format("{}.{}: {}", path, d.name, why));
        continue;
      }
      std::string rule = d.violation(*val);
      if (!rule.empty()) {
        pr.add(v, fmt::format("{}.{} = {}: {}", path, d.name, formatValue(*val), rule));
        continue;
      }
      out.set(d.name, *val);
    } else if (d.default_value) {
      ParamValue def = *d.default_value;
      if (d.type == ParamType::Path) {
        fs::path p(std::get<std::string>(def));
        if (!p.empty() && p.is_relative() && !base_dir.empty())
          def = (base_dir / p).lexically_normal().string();
      }
      out.set(d.name, def);
    } else {
      pr.add(params ? params : YAML::Node(),
             fmt::format("{}.{}: required parameter is missing ({}{}{})", path, d.name,
                         toString(d.type), d.unit.empty() ? "" : ", " + d.unit,
                         d.doc.empty() ? "" : ": " + d.doc));
    }
  }
}

std::optional<PluginSpec> parseSpec(const YAML::Node& node, PluginKind kind,
                                    const std::string& path, const fs::path& base_dir,
                                    const Registry& reg, Problems& pr, bool allow_weight) {
  if (!node.IsMap()) {
    pr.add(node, fmt::format("{}: expected a mapping {{type: NAME, params: {{...}}}}, found '{}'",
                             path, scalarText(node)));
    return std::nullopt;
  }
  std::vector<std::string> allowed = {"type", "params"};
  if (allow_weight) allowed.push_back("weight");
  for (const auto& kv : node) {
    const std::optional<std::string> key = keyName(pr, kv.first, path);
    if (key && std::find(allowed.begin(), allowed.end(), *key) == allowed.end())
      unknownKey(pr, kv.first, path, *key, allowed);
  }
  YAML::Node type = node["type"];
  if (!type || !type.IsScalar()) {
    pr.add(node, fmt::format("{}.type: missing; name a {} plugin", path, toString(kind)));
    return std::nullopt;
  }
  PluginSpec spec;
  spec.kind = kind;
  spec.type = type.Scalar();
  spec.key_path = path;
  spec.line = node.Mark().line + 1;
  if (allow_weight && node["weight"]) {
    auto w = node["weight"].IsScalar() ? toDouble(node["weight"].Scalar()) : std::nullopt;
    if (!w || !(*w > 0) || !std::isfinite(*w))
      pr.add(node["weight"], fmt::format("{}.weight = {}: must be a number in (0, inf)", path,
                                         scalarText(node["weight"])));
    else
      spec.weight = *w;
  }
  const PluginInfo* info = reg.find(kind, spec.type);
  if (!info) {
    pr.add(type, fmt::format("{}.type: {}", path, reg.unknownMessage(kind, spec.type)));
    return std::nullopt;
  }
  resolveInto(*info, node["params"], path + ".params", base_dir, pr, spec.params);
  return spec;
}

}  // namespace config_detail

using config_detail::Problems;
using config_detail::resolveInto;

ParamSet resolveParams(const PluginInfo& info, const std::string& yaml_params,
                       const std::string& context, const fs::path& base_dir) {
  Problems pr;
  pr.source = context;
  YAML::Node node;
  try {
    node = YAML::Load(yaml_params.empty() ? "{}" : yaml_params);
  } catch (const YAML::Exception& e) {
    throw Error(fmt::format("{}: malformed YAML: {}", context, e.msg));
  }
  ParamSet ps;
  resolveInto(info, node, context, base_dir, pr, ps);
  if (!pr.items.empty()) {
    std::string msg;
    for (const auto& it : pr.items) msg += (msg.empty() ? "" : "\n") + it;
    throw Error(msg);
  }
  return ps;
}

}  // namespace exid
