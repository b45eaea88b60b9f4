// exid — robot plugin `planar2r`: 2R arm in a vertical plane (textbook example, uniform slender
// links) The description file robots/planar2r/planar2r.yaml is embedded at build time (works when
// installed).
#include "robot_plugin_common.hpp"

extern const char* const exid_embedded_planar2r_yaml;

namespace {

class Planar2rRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "planar2r";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "2R arm in a vertical plane (textbook example, uniform slender links)";
  static std::vector<exid::ParamDecl> params() { return exid::robots::commonParams(); }
  explicit Planar2rRobot(const exid::ParamSet& p) : opt_(p) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    return opt_.build([](const exid::LoadOptions& o) {
      return exid::loadDhYamlString(exid_embedded_planar2r_yaml,
                                    "planar2r.yaml (embedded in plugin planar2r)", o);
    });
  }

 private:
  exid::robots::CommonOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Planar2rRobot)
