// exid — robot plugin `irp6`: IRp-6, 5 DOF, absolute angles for joints 2-4 (MRROC++ kinematics;
// plausible masses) The description file robots/irp6/irp6.yaml is embedded at build time (works
// when installed).
#include "robot_plugin_common.hpp"

extern const char* const exid_embedded_irp6_yaml;

namespace {

class Irp6Robot : public exid::Robot {
 public:
  static constexpr const char* kName = "irp6";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "IRp-6, 5 DOF, absolute angles for joints 2-4 (MRROC++ kinematics; plausible masses)";
  static std::vector<exid::ParamDecl> params() { return exid::robots::commonParams(); }
  explicit Irp6Robot(const exid::ParamSet& p) : opt_(p) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    return opt_.build([](const exid::LoadOptions& o) {
      return exid::loadDhYamlString(exid_embedded_irp6_yaml, "irp6.yaml (embedded in plugin irp6)",
                                    o);
    });
  }

 private:
  exid::robots::CommonOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Irp6Robot)
