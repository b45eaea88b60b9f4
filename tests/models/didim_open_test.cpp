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
#include "exid/estimators/closed_loop.hpp"
#include "exid/json.hpp"
#include "model_test_util.hpp"

namespace {

// The PUMA under computed torque with a tanh Coulomb law, recorded at 1 kHz for `duration` s,
// and the model of that plant.
struct Plant {
  exid::Dataset data;
  std::shared_ptr<exid::ObservationModel> model;
};
Plant computedTorquePuma(double duration) {
  auto robot = mtest::robot("puma560");
  const exid::Samples ref = cltest::reference(robot->dof(), duration);
  return {mtest::simulate(robot,
                          "{controller: computed_torque, sample_period_s: 0.001, coulomb: tanh, "
                          "coulomb_velocity_scale: 0.5}",
                          7, &ref),
          mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.5]}", robot)};
}

TEST(DidimOpen, RecoversThePlantFromTheRecordedTorqueWithoutItsController) {
  const Plant plant = computedTorquePuma(2.0);
  const exid::Dataset& data = plant.data;
  auto model = plant.model;
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

// The sensitivities along CVODES's steps (BDF2 at each step's end, S' there from the formula,
// cubic Hermite between steps) against CVODES's own forward sensitivities at tight tolerances,
// sample by sample: each of the 250 samples of a 0.25-s window, most of them between two
// steps, within 2e-3 of the reference's largest entry there (measured 7.9e-4, BDF2's second
// order; with S' at the steps' ends off by a factor 2, which only the interpolation between
// steps reads, 2.7e-2).
TEST(DidimOpen, SensitivitiesAtEverySampleMatchCvodesOwn) {
  const Plant plant = computedTorquePuma(0.5);
  const exid::Dataset& data = plant.data;
  const auto& model = plant.model;
  exid::estimators::ClosedLoop loop(*model, data, "test");
  const int n = loop.dof();
  const int first = 3, count = 250;
  const Eigen::VectorXd times = data.t.segment(first + 1, count);
  const Eigen::VectorXd x0 =
      (Eigen::VectorXd(2 * n) << data.q.row(first).transpose(), data.qd.row(first).transpose())
          .finished();
  auto run = [&](const exid::estimators::ClosedLoop::Tolerances& tol) {
    std::vector<Eigen::MatrixXd> S(static_cast<std::size_t>(count));
    loop.simulateFrom(model->baseNominal(), data.t[first], x0, times, tol, true,
                      [&](int k, const Eigen::VectorXd&, const Eigen::MatrixXd* Sk) {
                        ASSERT_NE(Sk, nullptr);
                        S[static_cast<std::size_t>(k)] = *Sk;
                      });
    return S;
  };
  exid::estimators::ClosedLoop::Tolerances steps;  // (the defaults: rtol 1e-8, atol 1e-10)
  exid::estimators::ClosedLoop::Tolerances cv;
  cv.rtol = 1e-11;
  cv.atol = 1e-13;
  cv.cvodes_sensitivities = true;
  const std::vector<Eigen::MatrixXd> S = run(steps), R = run(cv);
  double worst = 0.0, late = 0.0;
  for (int k = 0; k < count; ++k) {
    const auto u = static_cast<std::size_t>(k);
    const double e = (S[u] - R[u]).cwiseAbs().maxCoeff() / R[u].cwiseAbs().maxCoeff();
    worst = std::max(worst, e);
    if (k == count - 1) late = e;
  }
  std::printf("[sensitivities] steps against CVODES's own: largest %.3g, at the last sample %.3g\n",
              worst, late);
  EXPECT_LT(worst, 2e-3);
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
