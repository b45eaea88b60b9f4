// exid — robot plugin `urdf`: a robot from a URDF file (see docs/robots.md).
#include "robot_plugin_common.hpp"

namespace {

class UrdfRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "urdf";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "robot from a URDF file (revolute, continuous, prismatic, fixed joints; <exid> extension "
      "for drives, transmission, sensor frame)";
  static std::vector<exid::ParamDecl> params() {
    auto p = exid::robots::commonParams();
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
    std::filesystem::path f(file_);
    if (f.is_relative() && !ctx.study_dir.empty()) f = ctx.study_dir / f;
    std::filesystem::path e(extension_);
    if (!e.empty() && e.is_relative() && !ctx.study_dir.empty()) e = ctx.study_dir / e;
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
  exid::robots::CommonOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(UrdfRobot)
