// `didim` with loop: open: the simulation driven by the recorded torque in windows, each from
// its recorded start, fitted to the recorded positions; no reference or controller gains. From
// exact data it recovers the plant; its Jacobian equals central differences; what it needs is
// refused by name when missing.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "closed_loop_test_util.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "model_test_util.hpp"

namespace {

TEST(DidimOpen, RecoversThePlantFromTheRecordedTorqueWithoutItsController) {
  auto robot = mtest::robot("puma560");
  const exid::Samples ref = cltest::reference(robot->dof(), 2.0);
  const exid::Dataset data =
      mtest::simulate(robot,
                      "{controller: computed_torque, sample_period_s: 0.001, coulomb: tanh, "
                      "coulomb_velocity_scale: 0.5}",
                      7, &ref);
  auto model =
      mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.5]}", robot);
  const Eigen::VectorXd truth = model->baseNominal();
  // The plant under computed torque with a tanh Coulomb law: the recorded torque is smooth
  // (a feed-forward with sign(qdr) would put jumps between samples that no interpolation of
  // the samples follows). The start: least squares on noisy accelerations (biased); the output
  // error uses q and qd only (the windows' starts, exact here).
  exid::Dataset d = data;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> nd(0.0, 1.0);
  for (int k = 0; k < d.size(); ++k)
    for (int j = 0; j < d.dof(); ++j) d.qdd(k, j) += 0.002 * nd(rng);
  auto didim = exid_test::create<exid::Estimator>(
      "didim",
      "{loop: open, window_s: 0.25, output: position, fit_nonlinear: false, gradient_check: 2, "
      "rtol: 1e-10, atol: 1e-12}");
  const exid::Estimate e = didim->estimate(*model, d, nullptr, mtest::context());
  auto ls = exid_test::create<exid::Estimator>("batch_ls", "{}");
  const exid::Estimate el = ls->estimate(*model, d, nullptr, mtest::context());
  const double err = (e.value - truth).norm() / truth.norm();
  const double err_ls = (el.value - truth).norm() / truth.norm();
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  const exid::Json& w = *e.details.find("windows");
  std::printf(
      "[didim open] %s windows of 0.25 s, %s samples fitted: parameters %.2e (least squares on "
      "noisy accelerations %.2e); Jacobian against central differences %.2e; %s "
      "simulations, %.1f s\n",
      w.find("windows")->dump().c_str(), w.find("samples_fitted")->dump().c_str(), err, err_ls,
      grad, e.details.find("simulations")->dump().c_str(), e.details.find("wall_s")->asDouble());
  EXPECT_LT(grad, 1e-3);
  EXPECT_LT(err, 1e-5);  // (4.9e-6 here: the position output's weak directions at rtol 1e-10)
  EXPECT_GT(err_ls, 1e-3);
  EXPECT_EQ(e.details.find("loop")->asString(), "open");
  EXPECT_EQ(w.find("windows")->asInt(), 8);
  // every accepted step's Jacobian was taken along its trial's path, not simulated again
  EXPECT_EQ(e.details.find("jacobians")->asInt(), e.details.find("iterations")->asInt() + 1);
  // CVODES's own sensitivities: the same estimate, the Jacobian closer to central differences
  auto cv = exid_test::create<exid::Estimator>(
      "didim",
      "{loop: open, window_s: 0.25, output: position, fit_nonlinear: false, gradient_check: 2, "
      "rtol: 1e-10, atol: 1e-12, sensitivities: cvodes}");
  const exid::Estimate ec = cv->estimate(*model, d, nullptr, mtest::context());
  const double grad_cv =
      ec.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  std::printf("[didim open] sensitivities: cvodes: parameters %.2e, Jacobian %.2e, %.1f s\n",
              (ec.value - truth).norm() / truth.norm(), grad_cv,
              ec.details.find("wall_s")->asDouble());
  EXPECT_LT((ec.value - truth).norm() / truth.norm(), 1e-5);
  EXPECT_LT((ec.value - e.value).norm() / truth.norm(), 1e-5);
  EXPECT_LT(grad_cv, 1e-4);
  EXPECT_LT(grad_cv, grad);
}

TEST(DidimOpen, ItsInputsAreCheckedByName) {
  auto bad = [](const std::string& yaml, const std::string& needle) {
    try {
      exid_test::create<exid::Estimator>("didim", yaml);
      ADD_FAILURE() << yaml << ": no error";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  bad("{loop: open, output: position}", "window_s");
  bad("{loop: open, window_s: 0.2}", "output: position");
  bad("{loop: open, window_s: 0.2, output: position, kp_Nm_per_rad: [1]}", "kp_Nm_per_rad");
  bad("{window_s: 0.2, reference_file: r.csv, kp_Nm_per_rad: [1], kd_Nm_s_per_rad: [1]}",
      "window_s is for loop: open");
  // no qd in the data
  auto robot = mtest::robot("puma560");
  exid::Dataset d = mtest::simulate(robot, "{duration_s: 1, sample_period_s: 0.01}");
  d.qd.resize(0, 0);
  auto model = mtest::model("differential", "{}", robot);
  auto didim =
      exid_test::create<exid::Estimator>("didim", "{loop: open, window_s: 0.2, output: position}");
  try {
    didim->estimate(*model, d, nullptr, mtest::context());
    ADD_FAILURE() << "no error without qd";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("no qd"), std::string::npos) << e.what();
  }
}

}  // namespace
