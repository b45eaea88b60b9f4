// Fuzz target: the MJCF and SDF loaders (exid::loadMjcfString, exid::loadSdfString) on the same
// input, then each model is used once (a floating base by the floating-base dynamics).
#include <Eigen/Core>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/robot_loaders.hpp"
#include "fuzz_common_min.hpp"

namespace {

template <class Load>
void tryLoad(Load&& load) {
  try {
    const exid::RobotModel m = load();
    const Eigen::VectorXd z = Eigen::VectorXd::Zero(m.dof());
    if (m.floating_base) {  // (a free joint in MJCF, an SDF model with no joint to the world)
      exid::BaseMotion base = exid::BaseMotion::Zero();
      base(8) = 9.81;
      (void)exid::floatingInverseDynamics(m, z, z, z, base);
      return;
    }
    exid::DynamicsDataPtr dd = exid::makeDynamicsData(m);
    (void)exid::inverseDynamics(m, *dd, z, z, z);
  } catch (const exid::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<std::string> warnings;
  exid::LoadOptions opt;
  opt.warnings = &warnings;
  const std::string text = exid_fuzz::text(data, size);
  tryLoad([&] { return exid::loadMjcfString(text, "fuzz.xml", opt); });
  tryLoad([&] { return exid::loadSdfString(text, "fuzz.sdf", opt); });
  return 0;
}
