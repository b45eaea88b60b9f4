// exid — the resolved study: its text (resolvedYaml: every parameter written, defaults
// included), its JSON (resolvedJson) and its hash (the identity of its configuration).
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <type_traits>

#include "config_internal.hpp"
#include "exid/config.hpp"
#include "exid/input_file.hpp"

namespace exid {

namespace {

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
  } else if (base_columns_pivoted) {
    e << YAML::Key << "base_columns" << YAML::Value << "pivoted";
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
  if (base_columns_pivoted) j["base_columns"] = Json("pivoted");
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
