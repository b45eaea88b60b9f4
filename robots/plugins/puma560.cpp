// exid — robot plugin `puma560`: Unimation PUMA 560, standard DH (Corke's toolbox parameters),
// or the same robot from its URDF. Both description files are embedded at build time.
#include "robot_plugin_common.hpp"

extern const char* const exid_embedded_puma560_yaml;
extern const char* const exid_embedded_puma560_urdf;

namespace {

class Puma560Robot : public exid::Robot {
 public:
  static constexpr const char* kName = "puma560";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "Unimation PUMA 560 (Corke/Armstrong-Khatib-Burdick parameters, reflected motor inertias, "
      "link-side friction); loads with warnings (published data violate the triangle inequality)";
  static std::vector<exid::ParamDecl> params() {
    auto p = exid::robots::commonParams();
    p.push_back(exid::param_string("variant", std::string("standard_dh"),
                                   "which description: the DH table or the URDF of the same robot",
                                   {"standard_dh", "urdf"}));
    return p;
  }
  // What the published data are, said once in the report (not a warning: nothing to act on).
  static constexpr const char* kKnownDefects =
      "The PUMA 560 parameters are the published ones (Armstrong, Khatib & Burdick 1986; Corke & "
      "Armstrong-Helouvry 1994), kept as published: link 1 has no mass (it does not enter the "
      "torques) but a rotational inertia about its axis, and the inertia tensors of links 1 and "
      "3 violate the triangle inequality. Base parameters, simulation and identification are "
      "unaffected (strict: true refuses the data).";
  explicit Puma560Robot(const exid::ParamSet& p) : opt_(p), variant_(p.getString("variant")) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    if (variant_ == "urdf") {
      return opt_.build(
          [](const exid::LoadOptions& o) {
            exid::LoadOptions u = o;  // its <dynamics> hold the published friction
            u.urdf_dynamics_as_friction = true;
            return exid::loadUrdfString(exid_embedded_puma560_urdf,
                                        "puma560.urdf (embedded in plugin puma560)", u);
          },
          kKnownDefects);
    }
    return opt_.build(
        [](const exid::LoadOptions& o) {
          return exid::loadDhYamlString(exid_embedded_puma560_yaml,
                                        "puma560.yaml (embedded in plugin puma560)", o);
        },
        kKnownDefects);
  }

 private:
  exid::robots::CommonOptions opt_;
  std::string variant_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Puma560Robot)
