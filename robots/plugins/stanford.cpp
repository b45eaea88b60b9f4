// exid — robot plugin `stanford`: Stanford arm (prismatic joint 3), standard DH, Paul 1981 data via
// Corke's mdl_stanford The description file robots/stanford/stanford.yaml is embedded at build time
// (works when installed).
#include "robot_plugin_common.hpp"

extern const char* const exid_embedded_stanford_yaml;

namespace {

class StanfordRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "stanford";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "Stanford arm (prismatic joint 3), standard DH, Paul 1981 data via Corke's mdl_stanford";
  static std::vector<exid::ParamDecl> params() { return exid::robots::commonParams(); }
  explicit StanfordRobot(const exid::ParamSet& p) : opt_(p) {}

  // What the published data are, said once in the report (not a warning: nothing to act on).
  static constexpr const char* kKnownDefects =
      "The Stanford arm parameters are the published ones (Paul 1981, as in Corke's toolbox), "
      "kept as published: the inertia of link 5 violates the triangle inequality. Simulation "
      "and identification are unaffected (strict: true refuses the data).";
  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    return opt_.build(
        [](const exid::LoadOptions& o) {
          return exid::loadDhYamlString(exid_embedded_stanford_yaml,
                                        "stanford.yaml (embedded in plugin stanford)", o);
        },
        kKnownDefects);
  }

 private:
  exid::robots::CommonOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(StanfordRobot)
