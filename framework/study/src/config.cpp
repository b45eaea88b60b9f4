#include "exid/config.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "exid/collision_yaml.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/registry.hpp"
#include "exid/study_check.hpp"
#include "exid/yaml_strict.hpp"

namespace exid {

namespace fs = std::filesystem;

namespace {

struct Problems {
  std::string source;
  std::vector<std::string> items;
  void add(const YAML::Node& at, const std::string& msg) {
    int line = (at && at.Mark().line >= 0) ? at.Mark().line + 1 : 0;
    add(line, msg);
  }
  void add(int line, const std::string& msg) {
    items.push_back(line > 0 ? fmt::format("{}:{}: {}", source, line, msg)
                             : fmt::format("{}: {}", source, msg));
  }
};

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

void emitValue(YAML::Emitter& e, const ParamValue& v) {
  std::visit(
      [&](const auto& x) {
        using T = std::decay_t<decltype(x)>;
        if constexpr (std::is_same_v<T, bool>)
          e << x;
        else if constexpr (std::is_same_v<T, std::int64_t>)
          e << static_cast<long long>(x);
        else if constexpr (std::is_same_v<T, double>)
          e << formatValue(ParamValue(x));
        else if constexpr (std::is_same_v<T, std::string>)
          e << x;
        else {
          e << YAML::Flow << YAML::BeginSeq;
          for (const auto& el : x) {
            if constexpr (std::is_same_v<std::decay_t<decltype(el)>, double>)
              e << formatValue(ParamValue(el));
            else if constexpr (std::is_same_v<std::decay_t<decltype(el)>, std::int64_t>)
              e << static_cast<long long>(el);
            else
              e << el;
          }
          e << YAML::EndSeq;
        }
      },
      v);
}

void emitSpec(YAML::Emitter& e, const PluginSpec& s, bool with_weight) {
  e << YAML::BeginMap << YAML::Key << "type" << YAML::Value << s.type;
  if (with_weight) e << YAML::Key << "weight" << YAML::Value << formatValue(ParamValue(s.weight));
  e << YAML::Key << "params" << YAML::Value << YAML::BeginMap;
  for (const auto& [k, v] : s.params.values()) {
    e << YAML::Key << k << YAML::Value;
    emitValue(e, v);
  }
  e << YAML::EndMap << YAML::EndMap;
}

Json specJson(const PluginSpec& s) {
  Json j = Json::object();
  j["type"] = s.type;
  Json p = Json::object();
  for (const auto& [name, v] : s.params.values()) {
    const std::string& k = name;  // a structured binding cannot be captured before C++20 (clang)
    std::visit(
        [&](const auto& x) {
          using T = std::decay_t<decltype(x)>;
          if constexpr (std::is_same_v<T, std::vector<std::int64_t>>) {
            Json a = Json::array();
            for (auto i : x) a.push_back(Json(static_cast<long long>(i)));
            p[k] = a;
          } else if constexpr (std::is_same_v<T, std::int64_t>) {
            p[k] = Json(static_cast<long long>(x));
          } else {
            p[k] = Json(x);
          }
        },
        v);
  }
  j["params"] = p;
  return j;
}

}  // namespace

std::vector<ParamDecl> excitationConstraintParams() {
  return {
      param_double("torque_margin", 0.0, "",
                   "torque limits: |tau_j(t)| <= torque_margin * tau_max,j at every sample, tau "
                   "the torque the robot's full model (rigid body + drives, nominal parameters) "
                   "predicts; 0: no torque limits",
                   0.0, 1.0),
      param_doubles("torque_max_Nm", std::vector<double>{}, "N m or N",
                    "tau_max per joint (measured coordinates); empty: the robot's own limits (URDF "
                    "effort), required when it has none"),
  };
}

std::vector<ParamDecl> excitationInformationParams() {
  return {
      param_path("earlier_study", std::string(),
                 "an earlier run folder of the same robot, model and base columns: the "
                 "information of its identification (covariance.csv: the inverse of the "
                 "estimate's covariance) is added to the new trajectory's; empty: none"),
      param_double("prior_relative_std", 0.0, "",
                   "the robot description's parameters as a prior: std = relative_std * |value| "
                   "(+ absolute_std) per standard parameter, its information added; 0 and "
                   "prior_absolute_std 0: none",
                   0.0),
      param_double("prior_absolute_std", 0.0, "", "see prior_relative_std", 0.0),
      param_double("noise_std", 0.0, "N m (the model's row units)",
                   "std of the new experiment's measurement noise per row; required with an "
                   "earlier study or a prior (it weighs the new rows against what is known)",
                   0.0),
      param_double("recording_rate_hz", 0.0, "Hz",
                   "the rate the new experiment will be recorded at (rows per second of each "
                   "equation); required with an earlier study or a prior",
                   0.0),
  };
}

bool StudyConfig::hasExcitationInformation() const {
  return excitation_information.has("earlier_study") &&
         (!excitation_information.getString("earlier_study").empty() ||
          excitation_information.getDouble("prior_relative_std") > 0 ||
          excitation_information.getDouble("prior_absolute_std") > 0);
}

std::string studyNameProblem(const std::string& name) {
  if (name.empty()) return "";  // unnamed: loadStudy names it after the file
  if (name.size() > 200) return fmt::format("has {} characters; at most 200", name.size());
  if (name == "." || name == "..") return "must not be '.' or '..'";
  if (name[0] == '.') return "must not start with '.' (hidden or relative folder)";
  for (unsigned char c : name) {
    if (c == '/' || c == '\\')
      return "must be a plain name without '/' or '\\' (it names the output folder out/<name>)";
    if (c < 0x20 || c == 0x7f) return fmt::format("contains the control byte 0x{:02X}", c);
  }
  return "";
}

namespace {

const std::vector<std::string> kTopKeys = {
    "name",       "description", "seed",      "budget_s",   "robot",  "model", "base_columns",
    "excitation", "experiment",  "estimator", "validation", "report", "prior", "split"};

std::optional<PriorSpec> parsePrior(const YAML::Node& n, const fs::path& base_dir, Problems& pr) {
  if (!n.IsMap()) {
    pr.add(n,
           fmt::format(
               "prior: expected a mapping {{from: robot, relative_std: 0.3, absolute_std: 1e-3}} "
               "or {{from: study, study: DIR, scale: 1}}, found '{}'",
               scalarText(n)));
    return std::nullopt;
  }
  PriorSpec spec;
  spec.line = n.Mark().line + 1;
  YAML::Node from = n["from"];
  if (!from || !from.IsScalar() || (from.Scalar() != "robot" && from.Scalar() != "study")) {
    pr.add(from ? from : n, fmt::format("prior.from: expected 'robot' or 'study', found '{}'",
                                        from ? scalarText(from) : std::string("nothing")));
    return std::nullopt;
  }
  spec.from = from.Scalar();
  const std::vector<std::string> allowed =
      spec.from == "robot" ? std::vector<std::string>{"from", "relative_std", "absolute_std",
                                                      "drive_relative_std", "drive_absolute_std"}
                           : std::vector<std::string>{"from", "study", "scale"};
  bool bad = false;
  for (const auto& kv : n) {
    const std::optional<std::string> key = keyName(pr, kv.first, "prior");
    if (!key || std::find(allowed.begin(), allowed.end(), *key) == allowed.end()) {
      if (key) unknownKey(pr, kv.first, "prior", *key, allowed);
      bad = true;
    }
  }
  // Reads n[key] into *out; false (and *out unchanged) when the key is absent or bad.
  // (at most kMaxPriorStd: a std of 1e300 squares to infinity; no usable prior is that wide)
  auto number = [&](const char* key, double lo, bool lo_open, double* out) {
    YAML::Node v = n[key];
    if (!v) return false;
    auto d = v.IsScalar() ? toDouble(v.Scalar()) : std::nullopt;
    if (!d || !std::isfinite(*d) || (lo_open ? !(*d > lo) : !(*d >= lo))) {
      pr.add(v, fmt::format("prior.{} = {}: must be a number in {}{}, inf)", key, scalarText(v),
                            lo_open ? "(" : "[", lo));
      bad = true;
      return false;
    }
    if (*d > kMaxPriorStd) {
      pr.add(v, fmt::format("prior.{} = {}: too large to be used (at most {:g}; a std this large "
                            "is no prior: its variance overflows)",
                            key, scalarText(v), kMaxPriorStd));
      bad = true;
      return false;
    }
    *out = *d;
    return true;
  };
  if (spec.from == "robot") {
    number("relative_std", 0.0, false, &spec.relative_std);
    number("absolute_std", 0.0, false, &spec.absolute_std);
    const std::pair<const char*, std::optional<double>*> drive[] = {
        {"drive_relative_std", &spec.drive_relative_std},
        {"drive_absolute_std", &spec.drive_absolute_std}};
    for (const auto& [key, out] : drive) {
      double v = 0.0;
      if (number(key, 0.0, false, &v)) *out = v;
    }
  } else {
    number("scale", 0.0, true, &spec.scale);
    YAML::Node st = n["study"];
    if (!st || !st.IsScalar() || st.Scalar().empty()) {
      pr.add(st ? st : n,
             "prior.study: missing; the output folder of a study (its parameters.csv is read)");
      bad = true;
    } else {
      fs::path d(st.Scalar());
      if (d.is_relative() && !base_dir.empty()) d = base_dir / d;
      spec.study = d.lexically_normal();
    }
  }
  if (bad) return std::nullopt;
  return spec;
}

/// `split:` expands into the experiment (identification part) and a copy of it as validation
/// (the rest, with split.validation's parameters laid over). False when it cannot.
bool expandSplit(const YAML::Node& root, const fs::path& base_dir, const Registry& reg,
                 Problems& pr, StudyConfig& cfg) {
  const YAML::Node n = root["split"];
  if (!n.IsMap()) {
    pr.add(n, fmt::format("split: expected a mapping {{identification_fraction: 0.65}} or {{at_s: "
                          "5.0}} (optionally validation: {{...experiment parameters}}), found '{}'",
                          scalarText(n)));
    return false;
  }
  const std::vector<std::string> allowed = {"identification_fraction", "at_s", "validation"};
  bool bad = false;
  for (const auto& kv : n) {
    const std::optional<std::string> key = keyName(pr, kv.first, "split");
    if (!key || std::find(allowed.begin(), allowed.end(), *key) == allowed.end()) {
      if (key) unknownKey(pr, kv.first, "split", *key, allowed);
      bad = true;
    }
  }
  SplitSpec sp;
  sp.line = n.Mark().line + 1;
  const YAML::Node f = n["identification_fraction"], a = n["at_s"];
  if (static_cast<bool>(f) == static_cast<bool>(a)) {
    pr.add(n,
           "split: give exactly one of identification_fraction (of the experiment's segment, "
           "in (0, 1)) and at_s (seconds after the segment's start)");
    return false;
  }
  const YAML::Node v = f ? f : a;
  const auto d = v.IsScalar() ? toDouble(v.Scalar()) : std::nullopt;
  if (!d || !std::isfinite(*d) || !(*d > 0.0) || (f && !(*d < 1.0))) {
    pr.add(v, fmt::format("split.{} = {}: must be a number in {}",
                          f ? "identification_fraction" : "at_s", scalarText(v),
                          f ? "(0, 1)" : "(0, inf)"));
    return false;
  }
  (f ? sp.identification_fraction : sp.at_s) = *d;
  if (root["validation"]) {
    pr.add(root["validation"],
           "validation: a study with split validates on the rest of its experiment's recording; "
           "give split or a validation section, not both");
    bad = true;
  }
  const YAML::Node e = root["experiment"];
  if (!e || !e.IsMap() || !e["type"] || !e["type"].IsScalar()) {
    pr.add(n, "split: needs an experiment section (the recording that is split)");
    return false;
  }
  const PluginInfo* info = reg.find(PluginKind::Experiment, e["type"].Scalar());
  if (!info) return false;  // reported by the experiment section
  const bool can = std::any_of(info->params.begin(), info->params.end(),
                               [](const ParamDecl& p) { return p.name == "split_part"; });
  if (!can) {
    pr.add(n, fmt::format("split: experiment '{}' cannot split its data (no split_part "
                          "parameter; the csv and rosbag2 experiments can); give a validation "
                          "section",
                          info->name));
    return false;
  }
  const YAML::Node vo = n["validation"];
  if (vo && !vo.IsMap()) {
    pr.add(vo, fmt::format("split.validation: expected a mapping of the experiment's parameters "
                           "for the validation part, found '{}'",
                           scalarText(vo)));
    return false;
  }
  if (bad) return false;
  YAML::Node ident = YAML::Clone(e), valid = YAML::Clone(e);
  for (const char* k : {"split_part", "split_fraction", "split_at_s"}) {
    if ((e["params"] && e["params"].IsMap() && e["params"][k]) || (vo && vo[k])) {
      pr.add(n,
             fmt::format("split: sets {} itself; remove it from the experiment's parameters", k));
      return false;
    }
  }
  if (vo)
    for (const auto& kv : vo) {
      valid["params"][kv.first.Scalar()] = YAML::Clone(kv.second);
      sp.validation_overrides.push_back(kv.first.Scalar());
    }
  const std::string point = fmt::format("{:.17g}", *d);
  for (const auto& [node, part] : {std::pair<YAML::Node*, const char*>{&ident, "identification"},
                                   std::pair<YAML::Node*, const char*>{&valid, "validation"}}) {
    (*node)["params"]["split_part"] = part;
    (*node)["params"][f ? "split_fraction" : "split_at_s"] = point;
  }
  cfg.experiment = parseSpec(ident, PluginKind::Experiment, "experiment", base_dir, reg, pr, false);
  cfg.validation = parseSpec(valid, PluginKind::Experiment, "validation", base_dir, reg, pr, false);
  if (cfg.validation) cfg.validation->line = sp.line;
  cfg.split = sp;
  return true;
}

// `base_columns:` (StudyConfig::base_columns).
void parseBaseColumns(const YAML::Node& root, Problems& pr, StudyConfig& cfg) {
  if (const YAML::Node b = root["base_columns"]) {
    if (!b.IsSequence() || b.size() == 0) {
      pr.add(b,
             "base_columns: expected a non-empty list of full parameter names (e.g. [ZZ1, "
             "XX2, MX2]); leave the key out for the natural order");
    } else {
      for (std::size_t i = 0; i < b.size(); ++i) {
        if (!b[i].IsScalar() || b[i].Scalar().empty())
          pr.add(b[i], fmt::format("base_columns[{}]: expected a parameter name", i));
        else if (std::find(cfg.base_columns.begin(), cfg.base_columns.end(), b[i].Scalar()) !=
                 cfg.base_columns.end())
          pr.add(b[i], fmt::format("base_columns[{}]: '{}' is named twice", i, b[i].Scalar()));
        else
          cfg.base_columns.push_back(b[i].Scalar());
      }
      if (!root["model"]) pr.add(b, "base_columns: needs a model section");
    }
  }
}

// `excitation:` trajectory, criterion, optimizer, constraints and information.
// A YAML value as JSON: mappings, lists, numbers (what toDouble reads), true/false, text.
Json yamlJson(const YAML::Node& n) {
  if (n.IsMap()) {
    Json j = Json::object();
    for (const auto& kv : n) j[kv.first.Scalar()] = yamlJson(kv.second);
    return j;
  }
  if (n.IsSequence()) {
    Json j = Json::array();
    for (const auto& e : n) j.push_back(yamlJson(e));
    return j;
  }
  if (!n.IsScalar()) return Json();
  const std::string& t = n.Scalar();
  if (t == "true" || t == "false") return Json(t == "true");
  if (const std::optional<double> d = toDouble(t); d && std::isfinite(*d)) return Json(*d);
  return Json(t);
}

// JSON into a YAML emitter (flow style for lists of numbers and of texts).
void emitJson(YAML::Emitter& e, const Json& j) {
  switch (j.type()) {
    case Json::Type::Object:
      e << YAML::BeginMap;
      for (const auto& [k, v] : j.items()) {
        e << YAML::Key << k << YAML::Value;
        emitJson(e, v);
      }
      e << YAML::EndMap;
      break;
    case Json::Type::Array: {
      bool flat = true;
      for (std::size_t i = 0; i < j.size(); ++i)
        flat = flat && !j.at(i).isObject() && !j.at(i).isArray();
      if (flat) e << YAML::Flow;
      e << YAML::BeginSeq;
      for (std::size_t i = 0; i < j.size(); ++i) emitJson(e, j.at(i));
      e << YAML::EndSeq;
      break;
    }
    case Json::Type::Bool:
      e << j.asBool();
      break;
    case Json::Type::Int:
    case Json::Type::Double:
      e << formatValue(ParamValue(j.asDouble()));
      break;
    case Json::Type::String:
      e << j.asString();
      break;
    default:
      e << YAML::Null;
  }
}

// excitation.collision: {margin_m, self, allowed_pairs, obstacles} (docs/excitation.md §12).
void parseCollision(const YAML::Node& c, const fs::path& base_dir, Problems& pr, StudyConfig& cfg) {
  const std::string path = "excitation.collision";
  if (!c.IsMap()) {
    pr.add(c, path + ": expected a mapping {margin_m, self, allowed_pairs, obstacles}");
    return;
  }
  const std::vector<std::string> allowed = {"margin_m", "self", "allowed_pairs", "obstacles"};
  for (const auto& kv : c) {
    const std::optional<std::string> key = keyName(pr, kv.first, path);
    if (key && std::find(allowed.begin(), allowed.end(), *key) == allowed.end())
      unknownKey(pr, kv.first, path, *key, allowed);
  }
  auto o = std::make_shared<CollisionOptions>();
  o->mesh_dir = base_dir.string();
  Json j = Json::object();
  const YAML::Node m = c["margin_m"];
  double margin = NAN;
  if (m && m.IsScalar())
    if (const std::optional<double> v = toDouble(m.Scalar())) margin = *v;
  if (!m)
    pr.add(c, path +
                  ".margin_m: missing; the smallest distance [m] allowed between checked "
                  "bodies and obstacles (exid cannot choose it for your robot)");
  else if (!std::isfinite(margin) || margin < 0)
    pr.add(m, path + ".margin_m: expected a finite distance >= 0 [m], found " + scalarText(m));
  else
    o->margin_m = margin;
  if (const YAML::Node s = c["self"]) {
    if (!s.IsScalar() || (s.Scalar() != "true" && s.Scalar() != "false"))
      pr.add(s, path + ".self: expected true or false, found " + scalarText(s));
    else
      o->self = s.Scalar() == "true";
  }
  j["margin_m"] = o->margin_m;
  j["self"] = o->self;
  Json pairs = Json::array();
  if (const YAML::Node a = c["allowed_pairs"]) {
    if (!a.IsSequence()) pr.add(a, path + ".allowed_pairs: expected a list of [name, name]");
    for (std::size_t i = 0; a.IsSequence() && i < a.size(); ++i) {
      const YAML::Node e = a[i];
      if (!e.IsSequence() || e.size() != 2 || !e[0].IsScalar() || !e[1].IsScalar()) {
        pr.add(e, fmt::format("{}.allowed_pairs[{}]: expected [name, name] (bodies or obstacles)",
                              path, i));
        continue;
      }
      o->allowed_pairs.emplace_back(e[0].Scalar(), e[1].Scalar());
      pairs.push_back(Json(std::vector<std::string>{e[0].Scalar(), e[1].Scalar()}));
    }
  }
  j["allowed_pairs"] = pairs;
  Json obs = Json::array();
  if (const YAML::Node ob = c["obstacles"]) {
    if (!ob.IsSequence()) pr.add(ob, path + ".obstacles: expected a list of shapes");
    for (std::size_t i = 0; ob.IsSequence() && i < ob.size(); ++i) {
      Obstacle x;
      try {
        x.shape = parseCollisionShape(ob[i], pr.source, fmt::format("{}.obstacles[{}]", path, i),
                                      &x.name);
      } catch (const Error& e) {
        pr.items.push_back(e.what());
        continue;
      }
      o->obstacles.push_back(x);
      obs.push_back(yamlJson(ob[i]));
    }
  }
  j["obstacles"] = obs;
  cfg.excitation_collision = o;
  cfg.excitation_collision_json = j;
}

void parseExcitation(const YAML::Node& root, const fs::path& base_dir, const Registry& reg,
                     Problems& pr, StudyConfig& cfg) {
  if (const YAML::Node x = root["excitation"]) {
    if (!x.IsMap()) {
      pr.add(x, "excitation: expected a mapping with trajectory, criterion, optimizer");
    } else {
      const std::vector<std::string> allowed = {"trajectory",  "criterion",   "optimizer",
                                                "constraints", "information", "collision"};
      for (const auto& kv : x) {
        const std::optional<std::string> key = keyName(pr, kv.first, "excitation");
        if (key && std::find(allowed.begin(), allowed.end(), *key) == allowed.end())
          unknownKey(pr, kv.first, "excitation", *key, allowed);
      }
      if (x["trajectory"])
        cfg.trajectory = parseSpec(x["trajectory"], PluginKind::Trajectory, "excitation.trajectory",
                                   base_dir, reg, pr, false);
      else
        pr.add(x, "excitation.trajectory: missing; name a trajectory plugin");
      if (x["criterion"])
        cfg.criterion = parseSpec(x["criterion"], PluginKind::Criterion, "excitation.criterion",
                                  base_dir, reg, pr, false);
      else
        pr.add(x, "excitation.criterion: missing; name a criterion plugin");
      if (x["optimizer"])
        cfg.optimizer = parseSpec(x["optimizer"], PluginKind::Optimizer, "excitation.optimizer",
                                  base_dir, reg, pr, false);
      else
        pr.add(x, "excitation.optimizer: missing; name an optimizer plugin");
      PluginInfo cinfo;
      cinfo.params = excitationConstraintParams();
      resolveInto(cinfo, x["constraints"], "excitation.constraints", base_dir, pr,
                  cfg.excitation_constraints);
      if (x["collision"]) parseCollision(x["collision"], base_dir, pr, cfg);
      PluginInfo iinfo;
      iinfo.params = excitationInformationParams();
      resolveInto(iinfo, x["information"], "excitation.information", base_dir, pr,
                  cfg.excitation_information);
      if (cfg.hasExcitationInformation() &&
          (!(cfg.excitation_information.getDouble("noise_std") > 0) ||
           !(cfg.excitation_information.getDouble("recording_rate_hz") > 0)))
        pr.add(x["information"],
               "excitation.information: noise_std and recording_rate_hz are required with an "
               "earlier study or a prior (the new experiment's noise std per row and its "
               "recording rate weigh its information against what is known; exid cannot know "
               "them)");
    }
  }
}

}  // namespace

// report: {type: standard, params: {plots, experiment_csv, title}}
static void parseReport(const YAML::Node& r, const fs::path& base_dir, Problems& pr,
                        StudyConfig& cfg) {
  if (!r.IsMap()) {
    pr.add(r, "report: expected a mapping {type: standard, params: {plots: true}}");
  } else {
    for (const auto& kv : r) {
      const std::optional<std::string> key = keyName(pr, kv.first, "report");
      if (key && *key != "type" && *key != "params")
        unknownKey(pr, kv.first, "report", *key, {"type", "params"});
    }
    if (r["type"] && (!r["type"].IsScalar() || r["type"].Scalar() != "standard"))
      pr.add(r["type"], fmt::format("report.type: unknown report '{}'; available: standard",
                                    scalarText(r["type"])));
    PluginInfo rep;
    rep.name = "standard";
    rep.params = {param_bool("plots", true, "draw plots with gnuplot when it is installed"),
                  param_string("experiment_csv", std::string("auto"),
                               "write experiment.csv: auto (simulated data always; recorded "
                               "data, a copy of the input, up to 100000 samples), always, never",
                               {"auto", "always", "never"}),
                  param_string("title", std::string(), "title of the report")};
    ParamSet ps;
    resolveInto(rep, r["params"], "report.params", base_dir, pr, ps);
    if (ps.has("plots")) cfg.report.plots = ps.getBool("plots");
    if (ps.has("experiment_csv")) cfg.report.experiment_csv = ps.getString("experiment_csv");
    if (ps.has("title")) cfg.report.title = ps.getString("title");
  }
}

// Models of one stack (`model:` as a list) at most.
constexpr std::size_t kMaxStackedModels = 64;

static StudyConfig parseStudyUnchecked(const std::string& text, const std::string& source_name,
                                       const fs::path& base_dir, const Registry& reg) {
  Problems pr;
  pr.source = source_name;
  checkYamlAliases(text, source_name);  // before any node is built
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(fmt::format("{}:{}: malformed YAML: {}", source_name, e.mark.line + 1, e.msg));
  }
  StudyConfig cfg;
  cfg.dir = base_dir;
  duplicateKeys(root, source_name, "", &pr.items);
  if (!root.IsMap()) {
    throw Error(fmt::format("{}: expected a mapping with sections ({}), found '{}'", source_name,
                            fmt::join(kTopKeys, ", "), scalarText(root)));
  }
  for (const auto& kv : root) {
    const std::optional<std::string> key = keyName(pr, kv.first, "");
    if (key && std::find(kTopKeys.begin(), kTopKeys.end(), *key) == kTopKeys.end())
      unknownKey(pr, kv.first, "", *key, kTopKeys);
  }
  if (root["name"]) {
    if (root["name"].IsScalar()) {
      cfg.name = root["name"].Scalar();
      if (const std::string why = studyNameProblem(cfg.name); !why.empty())
        pr.add(root["name"], fmt::format("name = '{}': {}", scalarText(root["name"]), why));
    } else {
      pr.add(root["name"], "name: expected a string");
    }
  }
  if (root["seed"]) {
    auto s = root["seed"].IsScalar() ? toInt(root["seed"].Scalar()) : std::nullopt;
    if (!s || *s < 0)
      pr.add(root["seed"],
             fmt::format("seed = {}: must be a non-negative integer", scalarText(root["seed"])));
    else
      cfg.seed = static_cast<std::uint64_t>(*s);
  }
  if (root["budget_s"]) {
    auto b = root["budget_s"].IsScalar() ? toDouble(root["budget_s"].Scalar()) : std::nullopt;
    if (!b || !(*b >= 0) || !(*b <= 1e9))
      pr.add(root["budget_s"], fmt::format("budget_s = {}: must be in [0, 1e9] s (0: none)",
                                           scalarText(root["budget_s"])));
    else
      cfg.budget_s = *b;
  }
  if (root["robot"])
    cfg.robot = parseSpec(root["robot"], PluginKind::Robot, "robot", base_dir, reg, pr, false);
  else
    pr.add(0,
           "robot: missing section; name a robot plugin ({type: puma560}) or a file ({type: urdf, "
           "params: {file: ...}})");

  if (YAML::Node m = root["model"]) {
    if (m.IsSequence() && m.size() > kMaxStackedModels) {
      pr.add(m, fmt::format("model: a stack of {} models; at most {} (every stacked model adds "
                            "its rows for every sample: a stack is a few models, e.g. "
                            "differential + load_wrench)",
                            m.size(), kMaxStackedModels));
    } else if (m.IsSequence()) {
      for (std::size_t i = 0; i < m.size(); ++i)
        if (auto s = parseSpec(m[i], PluginKind::Model, fmt::format("model[{}]", i), base_dir, reg,
                               pr, true))
          cfg.models.push_back(*s);
      if (m.size() == 0) pr.add(m, "model: empty list");
    } else if (auto s = parseSpec(m, PluginKind::Model, "model", base_dir, reg, pr, true)) {
      cfg.models.push_back(*s);
    }
  }
  parseBaseColumns(root, pr, cfg);
  parseExcitation(root, base_dir, reg, pr, cfg);
  bool split_done = false;
  if (root["split"] && root["experiment"])
    split_done = expandSplit(root, base_dir, reg, pr, cfg);
  else if (root["split"])
    pr.add(root["split"], "split: needs an experiment section (the recording that is split)");
  if (root["experiment"] && !split_done)
    cfg.experiment = parseSpec(root["experiment"], PluginKind::Experiment, "experiment", base_dir,
                               reg, pr, false);
  if (root["estimator"])
    cfg.estimator =
        parseSpec(root["estimator"], PluginKind::Estimator, "estimator", base_dir, reg, pr, false);
  if (root["validation"] && !split_done)
    cfg.validation = parseSpec(root["validation"], PluginKind::Experiment, "validation", base_dir,
                               reg, pr, false);
  if (YAML::Node r = root["report"]) parseReport(r, base_dir, pr, cfg);
  if (root["prior"]) cfg.prior = parsePrior(root["prior"], base_dir, pr);
  // Which stages need which.
  if ((cfg.estimator || cfg.hasExcitation() || cfg.validation) && cfg.models.empty() &&
      !root["model"])
    pr.add(0,
           "model: missing section; the estimator, excitation and validation stages need an "
           "observation model");
  if (cfg.estimator && !cfg.experiment && !root["experiment"])
    pr.add(0,
           "experiment: missing section; the estimator needs data (e.g. {type: simulate} or {type: "
           "csv, params: {file: ...}})");
  if (root["prior"] && !cfg.estimator && !root["estimator"])
    pr.add(root["prior"], "prior: needs an estimator section (the prior is the estimator's)");
  if (cfg.split && !cfg.estimator && !root["estimator"])
    pr.add(root["split"], "split: needs an estimator section (the identified model is validated)");
  else if (cfg.validation && !cfg.estimator && !root["estimator"])
    pr.add(0, "validation: needs an estimator section (the identified model is what is validated)");

  if (!pr.items.empty()) {
    std::string msg = fmt::format("{}: {} problem{} in the study:\n", source_name, pr.items.size(),
                                  pr.items.size() == 1 ? "" : "s");
    for (const auto& it : pr.items) msg += "  " + it + "\n";
    msg.pop_back();
    throw Error(msg);
  }
  return cfg;
}

StudyConfig parseStudy(const std::string& text, const std::string& source_name,
                       const fs::path& base_dir, const Registry& reg) {
  try {
    return parseStudyUnchecked(text, source_name, base_dir, reg);
  } catch (const YAML::Exception& e) {  // a conversion not checked above: still the input's fault
    throw Error(e.mark.line >= 0 ? fmt::format("{}:{}: {}", source_name, e.mark.line + 1, e.msg)
                                 : fmt::format("{}: {}", source_name, e.msg));
  }
}

StudyConfig loadStudy(const fs::path& file, const Registry& reg) {
  const std::string text = readInputFile(file, "study", kMaxStudyFileBytes);
  fs::path abs = fs::absolute(file);
  StudyConfig cfg = parseStudy(text, file.string(), abs.parent_path(), reg);
  cfg.file = abs;
  if (cfg.name.empty()) {
    cfg.name = file.stem().string();
    if (!studyNameProblem(cfg.name).empty()) cfg.name = "study";
  }
  return cfg;
}

std::vector<fs::path> studyInputFiles(const StudyConfig& cfg, const Registry& reg) {
  std::vector<fs::path> out;
  auto add = [&](const std::optional<PluginSpec>& spec) {
    if (!spec) return;
    const PluginInfo* info = reg.find(spec->kind, spec->type);
    if (!info) return;
    for (const auto& d : info->params) {
      if (d.type != ParamType::Path || !spec->params.has(d.name)) continue;
      const auto* v = std::get_if<std::string>(&spec->params.at(d.name));
      if (v && !v->empty()) {
        fs::path p(*v);
        if (p.is_relative() && !cfg.dir.empty()) p = cfg.dir / p;
        out.push_back(p.lexically_normal());
      }
    }
  };
  add(cfg.robot);
  for (const auto& m : cfg.models) add(m);
  add(cfg.trajectory);
  add(cfg.criterion);
  add(cfg.optimizer);
  add(cfg.experiment);
  add(cfg.estimator);
  add(cfg.validation);
  if (cfg.prior && cfg.prior->from == "study") out.push_back(cfg.prior->study / "parameters.csv");
  if (cfg.hasExcitationInformation() &&
      !cfg.excitation_information.getString("earlier_study").empty())
    out.push_back(fs::path(cfg.excitation_information.getString("earlier_study")) /
                  "covariance.csv");
  return out;
}

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

namespace {
bool hasTorqueLimits(const StudyConfig& c) {
  return c.excitation_constraints.has("torque_margin") &&
         (c.excitation_constraints.getDouble("torque_margin") > 0 ||
          !c.excitation_constraints.getDoubles("torque_max_Nm").empty());
}
}  // namespace

std::string StudyConfig::resolvedYaml() const {
  YAML::Emitter e;
  e << YAML::BeginMap;
  e << YAML::Key << "name" << YAML::Value << name;
  e << YAML::Key << "seed" << YAML::Value << static_cast<unsigned long long>(seed);
  if (budget_s > 0)
    e << YAML::Key << "budget_s" << YAML::Value << formatValue(ParamValue(budget_s));
  if (robot) {
    e << YAML::Key << "robot" << YAML::Value;
    emitSpec(e, *robot, false);
  }
  if (!models.empty()) {
    e << YAML::Key << "model" << YAML::Value;
    if (models.size() == 1)
      emitSpec(e, models[0], false);
    else {
      e << YAML::BeginSeq;
      for (const auto& m : models) emitSpec(e, m, true);
      e << YAML::EndSeq;
    }
  }
  if (!base_columns.empty()) {
    e << YAML::Key << "base_columns" << YAML::Value << YAML::Flow << base_columns;
  }

  if (hasExcitation()) {
    e << YAML::Key << "excitation" << YAML::Value << YAML::BeginMap;
    e << YAML::Key << "trajectory" << YAML::Value;
    emitSpec(e, *trajectory, false);
    e << YAML::Key << "criterion" << YAML::Value;
    emitSpec(e, *criterion, false);
    e << YAML::Key << "optimizer" << YAML::Value;
    emitSpec(e, *optimizer, false);
    // Only when set, so that studies without them keep their resolved text and hash.
    if (hasTorqueLimits(*this)) {
      e << YAML::Key << "constraints" << YAML::Value << YAML::BeginMap;
      for (const auto& d : excitationConstraintParams()) {
        e << YAML::Key << d.name << YAML::Value;
        emitValue(e, excitation_constraints.at(d.name));
      }
      e << YAML::EndMap;
    }
    if (excitation_collision) {
      e << YAML::Key << "collision" << YAML::Value;
      emitJson(e, excitation_collision_json);
    }
    if (hasExcitationInformation()) {
      e << YAML::Key << "information" << YAML::Value << YAML::BeginMap;
      for (const auto& d : excitationInformationParams()) {
        e << YAML::Key << d.name << YAML::Value;
        emitValue(e, excitation_information.at(d.name));
      }
      e << YAML::EndMap;
    }
    e << YAML::EndMap;
  }
  if (experiment) {
    e << YAML::Key << "experiment" << YAML::Value;
    emitSpec(e, *experiment, false);
  }
  if (estimator) {
    e << YAML::Key << "estimator" << YAML::Value;
    emitSpec(e, *estimator, false);
  }
  if (validation) {
    e << YAML::Key << "validation" << YAML::Value;
    emitSpec(e, *validation, false);
  }
  if (prior) {
    e << YAML::Key << "prior" << YAML::Value << YAML::BeginMap << YAML::Key << "from" << YAML::Value
      << prior->from;
    if (prior->from == "robot") {
      e << YAML::Key << "relative_std" << YAML::Value
        << formatValue(ParamValue(prior->relative_std));
      e << YAML::Key << "absolute_std" << YAML::Value
        << formatValue(ParamValue(prior->absolute_std));
      if (prior->drive_relative_std)
        e << YAML::Key << "drive_relative_std" << YAML::Value
          << formatValue(ParamValue(*prior->drive_relative_std));
      if (prior->drive_absolute_std)
        e << YAML::Key << "drive_absolute_std" << YAML::Value
          << formatValue(ParamValue(*prior->drive_absolute_std));
    } else {
      e << YAML::Key << "study" << YAML::Value << prior->study.string();
      e << YAML::Key << "scale" << YAML::Value << formatValue(ParamValue(prior->scale));
    }
    e << YAML::EndMap;
  }
  e << YAML::Key << "report" << YAML::Value << YAML::BeginMap << YAML::Key << "type" << YAML::Value
    << "standard" << YAML::Key << "params" << YAML::Value << YAML::BeginMap << YAML::Key << "plots"
    << YAML::Value << report.plots << YAML::Key << "title" << YAML::Value << report.title
    << YAML::Key << "experiment_csv" << YAML::Value << report.experiment_csv << YAML::EndMap
    << YAML::EndMap;
  e << YAML::EndMap;
  return std::string(e.c_str()) + "\n";
}

Json StudyConfig::resolvedJson() const {
  Json j = Json::object();
  j["name"] = name;
  j["seed"] = Json(static_cast<long long>(seed));
  if (robot) j["robot"] = specJson(*robot);
  if (!models.empty()) {
    Json m = Json::array();
    for (const auto& s : models) {
      Json x = specJson(s);
      x["weight"] = s.weight;
      m.push_back(x);
    }
    j["model"] = m;
  }
  if (!base_columns.empty()) j["base_columns"] = Json(base_columns);
  if (hasExcitation()) {
    j["excitation"]["trajectory"] = specJson(*trajectory);
    j["excitation"]["criterion"] = specJson(*criterion);
    j["excitation"]["optimizer"] = specJson(*optimizer);
    if (hasTorqueLimits(*this)) {
      j["excitation"]["constraints"]["torque_margin"] =
          excitation_constraints.getDouble("torque_margin");
      j["excitation"]["constraints"]["torque_max_Nm"] =
          Json(excitation_constraints.getDoubles("torque_max_Nm"));
    }
    if (excitation_collision) j["excitation"]["collision"] = excitation_collision_json;
    if (hasExcitationInformation()) {
      Json& I = j["excitation"]["information"];
      I["earlier_study"] = excitation_information.getString("earlier_study");
      for (const char* k :
           {"prior_relative_std", "prior_absolute_std", "noise_std", "recording_rate_hz"})
        I[k] = excitation_information.getDouble(k);
    }
  }
  if (experiment) j["experiment"] = specJson(*experiment);
  if (estimator) j["estimator"] = specJson(*estimator);
  if (validation) j["validation"] = specJson(*validation);
  if (prior) {
    Json p = Json::object();
    p["from"] = prior->from;
    if (prior->from == "robot") {
      p["relative_std"] = prior->relative_std;
      p["absolute_std"] = prior->absolute_std;
      if (prior->drive_relative_std) p["drive_relative_std"] = *prior->drive_relative_std;
      if (prior->drive_absolute_std) p["drive_absolute_std"] = *prior->drive_absolute_std;
    } else {
      p["study"] = prior->study.string();
      p["scale"] = prior->scale;
    }
    j["prior"] = p;
  }
  return j;
}

std::string StudyConfig::hash() const {
  // The name is not part of the configuration's identity.
  StudyConfig copy = *this;
  copy.name.clear();
  return hashHex(fnv1a64(copy.resolvedYaml()));
}

}  // namespace exid
