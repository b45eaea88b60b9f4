// Fuzz target: the DH YAML loader (exid::loadDhYamlString), then the model is used once.
#include <Eigen/Core>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "fuzz_common_min.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<std::string> warnings;
  exid::LoadOptions opt;
  opt.warnings = &warnings;
  try {
    const exid::RobotModel m =
        exid::loadDhYamlString(exid_fuzz::text(data, size), "fuzz.yaml", opt);
    const Eigen::VectorXd z = Eigen::VectorXd::Zero(m.dof());
    exid::DynamicsDataPtr dd = exid::makeDynamicsData(m);
    (void)exid::inverseDynamics(m, *dd, z, z, z);
  } catch (const exid::Error&) {
  }
  return 0;
}
