// exid — the study's excitation section: its plugins, its constraints and information (their
// declared parameters) and its collision checks.
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "config_internal.hpp"
#include "exid/collision_yaml.hpp"
#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/registry.hpp"

namespace exid {

namespace fs = std::filesystem;

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

namespace config_detail {

namespace {

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

}  // namespace

// `excitation:` trajectory, criterion, optimizer, constraints and information.
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

}  // namespace config_detail

}  // namespace exid
