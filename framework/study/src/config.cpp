// exid — the study file (parseStudy, loadStudy): its keys, each section read and checked (a
// plugin's parameters: config_params.cpp; the excitation section: config_excitation.cpp), the
// sections the stages need, and the files a study reads.
#include "exid/config.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "config_internal.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/registry.hpp"
#include "exid/study_check.hpp"
#include "exid/yaml_strict.hpp"

namespace exid {

namespace fs = std::filesystem;

using namespace config_detail;

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
    if (b.IsScalar() && b.Scalar() == "pivoted") {
      cfg.base_columns_pivoted = true;
      if (!root["model"]) pr.add(b, "base_columns: needs a model section");
    } else if (!b.IsSequence() || b.size() == 0) {
      pr.add(b,
             "base_columns: expected a non-empty list of full parameter names (e.g. [ZZ1, "
             "XX2, MX2]) or `pivoted` (QR with column pivoting on unit-norm columns); leave the "
             "key out for the natural order");
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

namespace {

// name, seed and budget_s.
void parseScalars(const YAML::Node& root, Problems& pr, StudyConfig& cfg) {
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
}

// `model:` one model, or a stack of them (a list).
void parseModels(const YAML::Node& root, const fs::path& base_dir, const Registry& reg,
                 Problems& pr, StudyConfig& cfg) {
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
}

// Which stages need which.
void checkStageNeeds(const YAML::Node& root, Problems& pr, const StudyConfig& cfg) {
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
}

}  // namespace

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
  parseScalars(root, pr, cfg);
  if (root["robot"])
    cfg.robot = parseSpec(root["robot"], PluginKind::Robot, "robot", base_dir, reg, pr, false);
  else
    pr.add(0,
           "robot: missing section; name a robot plugin ({type: puma560}) or a file ({type: urdf, "
           "params: {file: ...}})");

  parseModels(root, base_dir, reg, pr, cfg);
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
  checkStageNeeds(root, pr, cfg);

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

}  // namespace exid
