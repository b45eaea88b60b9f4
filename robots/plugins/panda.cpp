// exid — robot plugin `panda`: Franka Emika Panda, modified DH, Gaz et al. RA-L 2019 feasible
// parameters and linear friction The description file robots/panda/panda.yaml is embedded at build
// time (works when installed).
#include "robot_plugin_common.hpp"

extern const char* const exid_embedded_panda_yaml;

namespace {

class PandaRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "panda";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "Franka Emika Panda, modified DH, Gaz et al. RA-L 2019 feasible parameters and linear "
      "friction";
  static std::vector<exid::ParamDecl> params() { return exid::robots::commonParams(); }
  explicit PandaRobot(const exid::ParamSet& p) : opt_(p) {}

  // What the published data are, said once in the report (not a warning: nothing to act on).
  static constexpr const char* kKnownDefects =
      "The Panda parameters are the published ones (Gaz et al., RA-L 2019), kept as published: "
      "the viscous friction of joint 6 is negative (fv6 = -0.0132 N m s/rad). Simulation and "
      "identification are unaffected (strict: true refuses the data).";
  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    return opt_.build(
        [](const exid::LoadOptions& o) {
          return exid::loadDhYamlString(exid_embedded_panda_yaml,
                                        "panda.yaml (embedded in plugin panda)", o);
        },
        kKnownDefects);
  }

 private:
  exid::robots::CommonOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(PandaRobot)
