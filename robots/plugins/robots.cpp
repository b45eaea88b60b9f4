// exid — the robot plugins, in one library: `dh`, `urdf`, `mjcf` and `sdf` (a robot from the
// user's file) and every robot of robots/catalogue.yaml (a shipped robot is data only: its
// description files and its catalogue entry, embedded at build time so that the library works
// when installed).
#include <yaml-cpp/yaml.h>

#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/params.hpp"
#include "exid/plugin.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/yaml_strict.hpp"
#include "shipped_files.hpp"

namespace {

using exid::Error;

// ------------------------------------------------------------------ options of every robot
std::vector<exid::ParamDecl> commonParams() {
  return {
      exid::param_bool("strict", false,
                       "physically impossible inertial data is an error instead of a warning"),
      exid::param_doubles("gravity", std::vector<double>{}, "m/s^2",
                          "gravity [gx, gy, gz] in the base frame, overriding the description's; "
                          "empty: from the description",
                          0, 3),
  };
}

struct CommonOptions {
  bool strict = false;
  std::vector<double> gravity;

  explicit CommonOptions(const exid::ParamSet& p)
      : strict(p.getBool("strict")), gravity(p.getDoubles("gravity")) {
    if (!gravity.empty() && gravity.size() != 3) {
      throw Error(p.context + ": gravity: expected 3 numbers [gx, gy, gz] or none, found " +
                  std::to_string(gravity.size()));
    }
  }

  /// Loads with these options and applies the gravity override. The loader's warnings are
  /// logged and kept in the model's `warnings`; with `known_defects` (published data whose
  /// defects are documented and kept on purpose) they are stated once as a note instead:
  /// `known_defects` followed by what the checks found.
  template <class Load>
  std::shared_ptr<const exid::RobotModel> build(Load&& load,
                                                const std::string& known_defects = {}) const {
    std::vector<std::string> warnings;
    exid::LoadOptions opt;
    opt.strict = strict;
    opt.warnings = &warnings;
    exid::RobotModel m = load(opt);
    if (!known_defects.empty() && !warnings.empty()) {
      std::string found;
      for (const auto& w : warnings) found += (found.empty() ? "" : "; ") + w;
      m.notes.push_back(known_defects + " Found: " + found + ".");
      for (const auto& w : warnings) exid::logDebug(w);
    } else {
      for (const auto& w : warnings) exid::logWarn(w);
      m.warnings.insert(m.warnings.end(), warnings.begin(), warnings.end());
    }
    if (!gravity.empty()) m.gravity = Eigen::Vector3d(gravity[0], gravity[1], gravity[2]);
    return std::make_shared<const exid::RobotModel>(std::move(m));
  }
};

std::filesystem::path fromStudy(const std::string& file, const exid::RunContext& ctx) {
  std::filesystem::path f(file);
  if (f.is_relative() && !ctx.study_dir.empty()) f = ctx.study_dir / f;
  return f;
}

// ------------------------------------------------------------------ dh, urdf
class DhRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "dh";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "robot from a DH / modified DH YAML table (inertia, limits, drives, transmission, sensor "
      "frame)";
  static std::vector<exid::ParamDecl> params() {
    auto p = commonParams();
    p.insert(p.begin(), exid::param_path("file", std::nullopt,
                                         "the DH YAML file (relative paths: to the study file)"));
    return p;
  }
  explicit DhRobot(const exid::ParamSet& p) : file_(p.getString("file")), opt_(p) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext& ctx) override {
    const auto f = fromStudy(file_, ctx);
    return opt_.build([&](const exid::LoadOptions& o) { return exid::loadDhYaml(f, o); });
  }

 private:
  std::string file_;
  CommonOptions opt_;
};

class UrdfRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "urdf";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "robot from a URDF file (revolute, continuous, prismatic, fixed joints; <exid> extension "
      "for drives, transmission, sensor frame)";
  static std::vector<exid::ParamDecl> params() {
    auto p = commonParams();
    p.insert(p.begin(), exid::param_path("file", std::nullopt,
                                         "the URDF file (relative paths: to the study file)"));
    p.insert(p.begin() + 1,
             exid::param_path("extension", std::string(),
                              "optional companion XML file whose root is an <exid> element "
                              "(drives, transmission, sensor, ...) for a URDF kept as published "
                              "(relative paths: to the study file); empty: none"));
    p.push_back(exid::param_bool(
        "dynamics_as_friction", false,
        "use the URDF's <dynamics damping friction> as nominal viscous and Coulomb friction "
        "(usually a simulator's values; off: ignored, and the robot's notes say so)"));
    return p;
  }
  explicit UrdfRobot(const exid::ParamSet& p)
      : file_(p.getString("file")),
        extension_(p.getString("extension")),
        dynamics_(p.getBool("dynamics_as_friction")),
        opt_(p) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext& ctx) override {
    const auto f = fromStudy(file_, ctx);
    const auto e = extension_.empty() ? std::filesystem::path() : fromStudy(extension_, ctx);
    return opt_.build([&](const exid::LoadOptions& o) {
      exid::LoadOptions oe = o;
      oe.urdf_extension = e;
      oe.urdf_dynamics_as_friction = dynamics_;
      return exid::loadUrdf(f, oe);
    });
  }

 private:
  std::string file_, extension_;
  bool dynamics_;
  CommonOptions opt_;
};

// ------------------------------------------------------------------ mjcf, sdf
/// A robot from a simulator's description (MJCF or SDF): `Format` names the plugin and the loader.
template <class Format>
class SimulatorFileRobot : public exid::Robot {
 public:
  static constexpr const char* kName = Format::kName;
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc = Format::kDoc;
  static std::vector<exid::ParamDecl> params() {
    auto p = commonParams();
    p.insert(p.begin(), exid::param_path("file", std::nullopt,
                                         std::string("the ") + Format::kWhat +
                                             " file (relative paths: to the study file)"));
    p.push_back(exid::param_bool("dynamics_as_friction", false, Format::kDynamics));
    return p;
  }
  explicit SimulatorFileRobot(const exid::ParamSet& p)
      : file_(p.getString("file")), dynamics_(p.getBool("dynamics_as_friction")), opt_(p) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext& ctx) override {
    const auto f = fromStudy(file_, ctx);
    return opt_.build([&](const exid::LoadOptions& o) {
      exid::LoadOptions oe = o;
      oe.urdf_dynamics_as_friction = dynamics_;
      return Format::load(f, oe);
    });
  }

 private:
  std::string file_;
  bool dynamics_;
  CommonOptions opt_;
};

struct MjcfFormat {
  static constexpr const char* kName = "mjcf";
  static constexpr const char* kWhat = "MJCF (MuJoCo XML)";
  static constexpr const char* kDoc =
      "robot from a MuJoCo MJCF file (hinge and slide joints, <inertial> elements, joint "
      "defaults; the exid_sensor site as the sensor frame)";
  static constexpr const char* kDynamics =
      "use the joints' armature, damping and frictionloss as nominal rotor inertia, viscous and "
      "Coulomb friction (usually a simulator's values; off: ignored, and the robot's notes say "
      "so)";
  static exid::RobotModel load(const std::filesystem::path& f, const exid::LoadOptions& o) {
    return exid::loadMjcf(f, o);
  }
};

struct SdfFormat {
  static constexpr const char* kName = "sdf";
  static constexpr const char* kWhat = "SDFormat";
  static constexpr const char* kDoc =
      "robot from an SDFormat 1.5-1.9 file (one model fixed to the world; revolute, continuous, "
      "prismatic and fixed joints; the exid_sensor frame as the sensor frame)";
  static constexpr const char* kDynamics =
      "use the joints' <dynamics> damping and friction as nominal viscous and Coulomb friction "
      "(usually a simulator's values; off: ignored, and the robot's notes say so)";
  static exid::RobotModel load(const std::filesystem::path& f, const exid::LoadOptions& o) {
    return exid::loadSdf(f, o);
  }
};

// ------------------------------------------------------------------ the shipped robots
/// One description of a shipped robot (a catalogue variant).
struct ShippedVariant {
  std::string name;
  std::string file;  // relative to robots/, a key of the embedded files
  bool dynamics_as_friction = false;
};

struct ShippedEntry {
  std::string name, doc, known_defects;
  std::vector<ShippedVariant> variants;  // the first is the default
};

const char* embeddedText(const std::string& path) {
  for (int i = 0; i < exid_shipped_file_count; ++i)
    if (path == exid_shipped_files[i].path) return *exid_shipped_files[i].text;
  return nullptr;
}

constexpr const char* kCatalogue = "robots/catalogue.yaml (embedded in the robots plugins)";

[[noreturn]] void catalogueError(const YAML::Node& n, const std::string& what) {
  throw Error(std::string(kCatalogue) + ":" + std::to_string(n.Mark().line + 1) + ": " + what);
}

std::string scalar(const YAML::Node& n, const std::string& where) {
  if (!n.IsScalar()) catalogueError(n, where + ": expected a string");
  return n.Scalar();
}

/// A variant's keys; `entry`: the entry itself is the one variant (its own keys allowed too).
ShippedVariant parseVariant(const std::string& name, const YAML::Node& n, const std::string& where,
                            bool entry) {
  if (!n.IsMap()) catalogueError(n, where + ": expected a mapping");
  ShippedVariant v;
  v.name = name;
  for (const auto& kv : n) {
    const std::string key = kv.first.Scalar();
    if (key == "file") {
      v.file = scalar(kv.second, where + ".file");
    } else if (key == "dynamics_as_friction") {
      v.dynamics_as_friction = kv.second.as<bool>();
    } else if (!entry || (key != "doc" && key != "known_defects")) {
      catalogueError(kv.first, where + ": unknown key '" + key + "'");
    }
  }
  if (v.file.empty()) catalogueError(n, where + ": no 'file'");
  if (!embeddedText(v.file)) {
    catalogueError(n, where + ".file: '" + v.file + "' is not among the embedded files");
  }
  return v;
}

/// The catalogue, parsed once. A defect in it is a defect of this build (the tests load every
/// entry), reported as an error naming the catalogue's line.
const std::vector<ShippedEntry>& catalogue() {
  static const std::vector<ShippedEntry> entries = [] {
    const char* text = embeddedText("catalogue.yaml");
    if (!text) throw Error(std::string(kCatalogue) + ": not embedded");
    const YAML::Node root = YAML::Load(text);
    std::vector<std::string> dup;
    exid::duplicateKeys(root, kCatalogue, "", &dup);
    if (!dup.empty()) throw Error(dup.front());
    std::vector<ShippedEntry> out;
    for (const auto& kv : root) {
      ShippedEntry e;
      e.name = kv.first.Scalar();
      const YAML::Node& n = kv.second;
      if (!n.IsMap()) catalogueError(n, e.name + ": expected a mapping");
      if (!n["doc"]) catalogueError(n, e.name + ": no 'doc'");
      e.doc = scalar(n["doc"], e.name + ".doc");
      if (n["known_defects"]) e.known_defects = scalar(n["known_defects"], e.name);
      if (n["variants"]) {
        if (n["file"]) catalogueError(n, e.name + ": 'file' and 'variants' together");
        for (const auto& v : n["variants"])
          e.variants.push_back(parseVariant(v.first.Scalar(), v.second,
                                            e.name + ".variants." + v.first.Scalar(), false));
      } else {
        e.variants.push_back(parseVariant("default", n, e.name, true));
      }
      out.push_back(std::move(e));
    }
    return out;
  }();
  return entries;
}

class ShippedRobot : public exid::Robot {
 public:
  ShippedRobot(const ShippedEntry& e, const exid::ParamSet& p) : entry_(e), opt_(p) {
    variant_ = &entry_.variants.front();
    if (entry_.variants.size() > 1) {
      const std::string v = p.getString("variant");
      for (const auto& c : entry_.variants)
        if (c.name == v) variant_ = &c;
    }
  }

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    const std::string text = embeddedText(variant_->file);
    const std::string source = variant_->file + " (embedded in plugin " + entry_.name + ")";
    const bool urdf = variant_->file.size() > 5 &&
                      variant_->file.compare(variant_->file.size() - 5, 5, ".urdf") == 0;
    const bool dynamics = variant_->dynamics_as_friction;
    return opt_.build(
        [&](const exid::LoadOptions& o) {
          if (!urdf) return exid::loadDhYamlString(text, source, o);
          exid::LoadOptions u = o;
          u.urdf_dynamics_as_friction = dynamics;
          return exid::loadUrdfString(text, source, u);
        },
        entry_.known_defects);
  }

  static exid::PluginInfo describe(const ShippedEntry& e) {
    exid::PluginInfo info;
    info.kind = exid::PluginKind::Robot;
    info.name = e.name;
    info.version = "1.0.0";
    info.doc = e.doc;
    info.params = commonParams();
    if (e.variants.size() > 1) {
      std::vector<std::string> names;
      for (const auto& v : e.variants) names.push_back(v.name);
      info.params.push_back(
          exid::param_string("variant", names.front(), "which description of the robot", names));
    }
    info.factory = [&e](const exid::ParamSet& p) -> std::unique_ptr<exid::PluginObject> {
      return std::make_unique<ShippedRobot>(e, p);
    };
    return info;
  }

 private:
  const ShippedEntry& entry_;  // the catalogue lives as long as the library
  CommonOptions opt_;
  const ShippedVariant* variant_ = nullptr;
};

void listRobots(exid::PluginList& out) {
  out.push_back(exid::describePlugin<DhRobot>());
  out.push_back(exid::describePlugin<UrdfRobot>());
  out.push_back(exid::describePlugin<SimulatorFileRobot<MjcfFormat>>());
  out.push_back(exid::describePlugin<SimulatorFileRobot<SdfFormat>>());
  for (const auto& e : catalogue()) out.push_back(ShippedRobot::describe(e));
}

}  // namespace

EXID_REGISTER_PLUGIN_LIST(listRobots)
