// Test helpers for tests that use plugins through the real registry (link exid_core).
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "exid/config.hpp"
#include "exid/context.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"

namespace exid_test {

/// The registry of the build tree's plugins (scanned once per process).
inline exid::Registry& registry() {
  static exid::Registry* reg = [] {
    auto* r = new exid::Registry();
    r->addSearchPath(std::filesystem::path(EXID_BINARY_DIR) / "plugins");
    r->scan();
    return r;
  }();
  return *reg;
}

/// Creates plugin `name` of T's kind with parameters given as YAML text ("{a: 1}").
template <class T>
std::shared_ptr<T> create(const std::string& name, const std::string& yaml_params = "{}") {
  const exid::PluginInfo& info = registry().get(T::kKind, name);
  exid::ParamSet ps =
      exid::resolveParams(info, yaml_params, std::string(exid::toString(T::kKind)) + " " + name,
                          std::filesystem::path(EXID_SOURCE_DIR));
  return registry().create<T>(name, ps);
}

/// A robot model from a robot plugin.
inline std::shared_ptr<const exid::RobotModel> robot(const std::string& name,
                                                     const std::string& yaml_params = "{}") {
  exid::RunContext ctx;
  return create<exid::Robot>(name, yaml_params)->build(ctx);
}

inline std::filesystem::path sourceDir() { return EXID_SOURCE_DIR; }
/// Recordings shipped in the repository (data/).
inline std::filesystem::path dataDir() { return std::filesystem::path(EXID_SOURCE_DIR) / "data"; }

/// Central differences (step h) of an excitation problem's nonlinear constraint rows along each
/// variable: rows x numVariables, to compare with the analytic Jacobian.
inline Eigen::MatrixXd nonlinearConstraintDifferences(exid::ExcitationProblem& p,
                                                      const Eigen::VectorXd& z, double h) {
  Eigen::MatrixXd D(p.numNonlinearConstraints(), p.numVariables());
  for (int i = 0; i < p.numVariables(); ++i) {
    Eigen::VectorXd zp = z, zm = z, gp, gm;
    zp(i) += h;
    zm(i) -= h;
    p.nonlinearConstraints(zp, &gp, nullptr);
    p.nonlinearConstraints(zm, &gm, nullptr);
    D.col(i) = (gp - gm) / (2 * h);
  }
  return D;
}

}  // namespace exid_test
