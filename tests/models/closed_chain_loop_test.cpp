// The estimators that simulate the closed loop (didim, iv) on a closed chain: the palletiser
// (elbow driven through a parallelogram) tracking a commanded trajectory under PD and
// feed-forward; the simulation's forward dynamics are the actuated ones (M_a = G^T M G,
// h_a = G^T (h + M g)) and its sensitivities need the actuated torque's derivatives through the
// loop constraints. From noise-free torques both recover the base parameters.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "closed_loop_test_util.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

// The palletiser tracking a reference around its reference configuration (measured
// coordinates joint1, joint2, joint5, joint4; joint5 at 90 deg): the sums of sines of
// cltest::reference scaled to a quarter, about 15 deg per joint, inside the joint limits.
cltest::Loop palletizerTracking(double duration, const std::string& tmp_prefix) {
  cltest::Loop s;
  s.robot = mtest::robot("palletizer");
  exid::Samples ref = cltest::reference(s.robot->dof(), duration);
  const double scale = 0.25;
  ref.q *= scale;
  ref.qd *= scale;
  ref.qdd *= scale;
  ref.q.col(2).array() += M_PI / 2;
  s.data =
      mtest::simulate(s.robot,
                      "{controller: pd_feedforward, kp: 4000, kd: 400, sample_period_s: 0.005, "
                      "coulomb: tanh, coulomb_velocity_scale: 0.05, rtol: 1e-13, atol: 1e-15}",
                      7, &ref);
  const std::filesystem::path dir = exid_cli::freshTempDir(tmp_prefix, "ref");
  cltest::writeReference(ref, dir / "reference.csv");
  s.params = fmt::format("reference_file: {}, {}", (dir / "reference.csv").string(),
                         cltest::gains(s.data.meta));
  s.model = mtest::model("differential",
                         "{rotor_inertia: true, viscous: true, coulomb: true, offset: true, "
                         "coulomb_smoothing_rad_s: [0.05]}",
                         s.robot);
  s.truth = s.model->baseNominal();
  return s;
}

double relErr(const Eigen::VectorXd& x, const Eigen::VectorXd& truth) {
  return (x - truth).norm() / truth.norm();
}

TEST(ClosedChainLoop, DidimAndIvIdentifyThePalletizer) {
  // (the plant integrated at rtol 1e-13: didim's output error is fitted against the plant's
  // integrated loop, so the plant's integration error is its floor -- 1.5e-5 at the simulate
  // experiment's default rtol 1e-8, 2.7e-9 with both at 1e-12, 7.5e-10 with both at 1e-13; iv
  // regresses the recorded torques on their own rows and has no such floor)
  const cltest::Loop s = palletizerTracking(2.0, "exid_closed_loop_");
  for (const std::string est : {"didim", "iv"}) {
    const std::string extra =
        est == "didim" ? ", rtol: 1e-13, atol: 1e-15, step_tolerance: 1e-12, gradient_check: 2"
                       : "";
    auto e = exid_test::create<exid::Estimator>(est, "{" + s.params + extra + "}");
    const exid::Estimate r = e->estimate(*s.model, s.data, nullptr, mtest::context());
    const double err = relErr(r.value, s.truth);
    std::printf("[%s] palletizer, noise-free torques: parameters %.2e, %s iterations\n",
                est.c_str(), err, r.details.find("iterations")->dump().c_str());
    RecordProperty(est, fmt::format("{:.3e}", err));
    if (est == "didim") {
      // its sensitivities (through the actuated torque's derivatives in qa, qda) against central
      // differences of the simulation: 2.7e-6 at rtol 1e-12, 1.2e-6 at 1e-13; with the tree's
      // dtau/dq G term of the actuated torque's derivative 10 % off, 2.4e-5
      const double grad =
          r.details.find("gradient_check")->find("max_relative_difference")->asDouble();
      std::printf("[didim] sensitivities against central differences %.2e\n", grad);
      EXPECT_LT(grad, 1e-5);
    }
    EXPECT_LT(err, 1e-9);
  }
}

}  // namespace
