// EXAMPLE (testing your derivatives): the exact derivatives of this folder's plugins against
// central differences, with the installed exid's checks (exid/gradient_check.hpp; docs/plugins.md,
// "Testing your derivatives"): the criterion a_optimal's dJ/dM, the trajectory template_sine's
// jacobian / vjp / vjpAt and the model template_model's fullDesignVjp. The plugins are loaded
// as exid loads them (the registry, from the folder given), so the libraries built here are the
// ones checked. Last, the check is shown to catch a wrong dJ/dM. Registered as a ctest
// (CMakeLists.txt): `ctest --test-dir build`. Exit 0 when every check passes.
#include <iostream>
#include <memory>
#include <string>

#include "exid/eigen_instances.hpp"
#include "exid/exid.hpp"
#include "exid/gradient_check.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"

namespace {

template <class T>
std::shared_ptr<T> create(exid::Registry& reg, const std::string& name, const std::string& params) {
  const exid::PluginInfo& info = reg.get(T::kKind, name);
  return reg.create<T>(name, exid::pluginParams(info, params, name, "."));
}

bool report(const exid::DerivativeCheck& c) {
  std::cout << c.message() << "\n";
  return c.ok;
}

// a_optimal with a slip in its derivative: -M^-1 instead of -M^-2 (what the check must catch).
class Slip final : public exid::Criterion {
 public:
  explicit Slip(std::shared_ptr<exid::Criterion> c) : c_(std::move(c)) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    const double J = c_->evaluate(M, dM);
    if (dM) *dM = -M.inverse();
    return J;
  }

 private:
  std::shared_ptr<exid::Criterion> c_;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: check_derivatives PLUGIN_DIR\n";
    return 2;
  }
  try {
    exid::Registry reg;
    reg.addSearchPath(argv[1]);
    reg.scan();
    exid::RunContext ctx;
    auto robot = create<exid::Robot>(reg, "template_robot", "{drives: false}")->build(ctx);
    auto traj = create<exid::Trajectory>(reg, "template_sine", "{}");
    traj->bind(robot, ctx);
    auto model = create<exid::ObservationModel>(reg, "template_model", "{}");
    model->bind(robot, ctx);
    const Eigen::VectorXd z = traj->initial();
    bool ok = true;

    // The criterion at the information matrix of the template trajectory (base columns).
    const Eigen::MatrixXd W = model->design(traj->evaluate(z));
    const Eigen::MatrixXd M = W.transpose() * W;
    auto crit = create<exid::Criterion>(reg, "a_optimal", "{weight: 2.0}");
    ok = report(exid::checkCriterion(*crit, M)) && ok;
    // The trajectory's derivatives with respect to its variables.
    ok = report(exid::checkTrajectory(*traj, z)) && ok;
    // The model's VJP at a few of its own random samples.
    ok = report(exid::checkModel(*model, model->randomSamples(4, 7))) && ok;

    // The same check fails on a wrong derivative, and says where.
    Slip slip(crit);
    slip.setPluginName("a_optimal_slip");
    const exid::DerivativeCheck wrong = exid::checkCriterion(slip, M);
    std::cout << wrong.message() << "\n";
    if (wrong.ok) {
      std::cerr << "FAIL: the check passed a wrong derivative\n";
      ok = false;
    }
    std::cout << (ok ? "derivatives: OK\n" : "derivatives: FAILED\n");
    return ok ? 0 : 1;
  } catch (const std::exception& e) {
    std::cerr << "check_derivatives: " << e.what() << "\n";
    return 1;
  }
}
