// The `didim` estimator (output error): its Jacobian, from CVODES forward sensitivities, equals
// central differences; from torques without noise it recovers the plant's parameters even
// where the inverse model's start is biased by noisy positions and derivatives (the output
// error never uses them); with noisy torques it stays within its reported standard deviations;
// a position output works too.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "closed_loop_test_util.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

namespace fs = std::filesystem;

using cltest::Loop;

Loop setup(double duration) {
  Loop s = cltest::pumaTracking(duration, "exid_didim_");
  s.model =
      mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}", s.robot);
  s.truth = s.model->baseNominal();
  return s;
}

// Noise on q, qd, qdd only: the inverse model's start is biased; the torques are exact.
exid::Dataset noisyPositions(const exid::Dataset& clean, double tau_noise, std::uint64_t seed) {
  exid::Dataset d = clean;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  for (int k = 0; k < d.size(); ++k)
    for (int j = 0; j < d.dof(); ++j) {
      d.q(k, j) += 1e-4 * nd(rng);
      d.qd(k, j) += 0.005 * nd(rng);
      d.qdd(k, j) += 0.1 * nd(rng);
      d.tau(k, j) += tau_noise * nd(rng);
    }
  return d;
}

TEST(Didim, RecoversThePlantFromExactTorquesWhereTheInverseModelIsBiased) {
  const Loop s = setup(6.0);
  const exid::Dataset d = noisyPositions(s.data, 0.0, 1);
  auto ls = exid_test::create<exid::Estimator>("batch_ls", "{}");
  const exid::Estimate el = ls->estimate(*s.model, d, nullptr, mtest::context());
  auto didim = exid_test::create<exid::Estimator>("didim", "{" + s.params + ", gradient_check: 2}");
  const exid::Estimate e = didim->estimate(*s.model, d, nullptr, mtest::context());
  const double err = (e.value - s.truth).norm() / s.truth.norm();
  const double err_ls = (el.value - s.truth).norm() / s.truth.norm();
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  std::printf(
      "[didim] torques exact: parameters %.2e (least squares %.2e), %s iterations, "
      "%s; sensitivities against central differences %.2e\n",
      err, err_ls, e.details.find("iterations")->dump().c_str(),
      e.details.find("stop")->asString().c_str(), grad);
  std::printf("[didim] %s simulations, %.1f s\n", e.details.find("simulations")->dump().c_str(),
              e.details.find("wall_s")->asDouble());
  EXPECT_LT(grad, 1e-3);
  EXPECT_LT(err, 1e-6);
  EXPECT_GT(err_ls, 1e-3);
}

TEST(Didim, NoisyTorquesGiveEstimatesWithinTheirReportedStandardDeviations) {
  const Loop s = setup(6.0);
  int within2 = 0, count = 0;
  double z2 = 0;
  for (int seed = 1; seed <= 2; ++seed) {
    const exid::Dataset d = noisyPositions(s.data, 0.3, static_cast<std::uint64_t>(seed));
    auto didim =
        exid_test::create<exid::Estimator>("didim", "{" + s.params + ", fit_nonlinear: false}");
    const exid::Estimate e = didim->estimate(*s.model, d, nullptr, mtest::context());
    for (Eigen::Index i = 0; i < s.truth.size(); ++i) {
      const double z = (e.value[i] - s.truth[i]) / e.std[i];
      z2 += z * z;
      within2 += std::abs(z) < 2.0;
      ++count;
    }
  }
  std::printf("[didim] noisy torques: %d of %d within 2 sigma, mean z^2 = %.2f\n", within2, count,
              z2 / count);
  EXPECT_GE(within2, static_cast<int>(0.8 * count));
  EXPECT_GT(z2 / count, 0.3);
  EXPECT_LT(z2 / count, 2.5);
}

TEST(Didim, APositionOutputRecoversThePlantToo) {
  const Loop s = setup(6.0);
  const exid::Dataset d = noisyPositions(s.data, 0.0, 2);
  exid::Dataset exact_q = d;
  exact_q.q = s.data.q;  // the output fitted: the recorded positions, exact here
  auto didim = exid_test::create<exid::Estimator>(
      "didim", "{" + s.params + ", output: position, fit_nonlinear: false}");
  const exid::Estimate e = didim->estimate(*s.model, exact_q, nullptr, mtest::context());
  const double err = (e.value - s.truth).norm() / s.truth.norm();
  std::printf("[didim] positions exact: parameters %.2e, %s iterations\n", err,
              e.details.find("iterations")->dump().c_str());
  EXPECT_LT(err, 1e-5);
  EXPECT_EQ(e.details.find("output")->asString(), "position");
}

// The friction's tanh widths (the model's nonlinear parameters) fitted with theta: from widths
// twice the plant's, the output error recovers both; kept at the wrong widths, theta is biased.
// The sensitivities with respect to log eta come from the model's exact column derivatives.
TEST(Didim, FitsTheFrictionWidthsWithTheBaseParameters) {
  Loop s = setup(6.0);
  s.model = mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.1]}", s.robot);
  const exid::Dataset d = noisyPositions(s.data, 0.0, 3);
  auto didim = exid_test::create<exid::Estimator>("didim", "{" + s.params + ", gradient_check: 2}");
  const exid::Estimate e = didim->estimate(*s.model, d, nullptr, mtest::context());
  ASSERT_EQ(e.nonlinear.size(), 6);
  const double err = (e.value - s.truth).norm() / s.truth.norm();
  const double eta_err = (e.nonlinear.array() / 0.05 - 1.0).abs().maxCoeff();
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  auto fixed =
      exid_test::create<exid::Estimator>("didim", "{" + s.params + ", fit_nonlinear: false}");
  const exid::Estimate ef = fixed->estimate(*s.model, d, nullptr, mtest::context());
  const double err_fixed = (ef.value - s.truth).norm() / s.truth.norm();
  std::printf(
      "[didim] widths fitted from twice the plant's: widths %.2e, parameters %.2e (widths kept: "
      "%.2e); sensitivities against central differences %.2e; %s simulations\n",
      eta_err, err, err_fixed, grad, e.details.find("simulations")->dump().c_str());
  EXPECT_LT(grad, 1e-3);
  EXPECT_LT(eta_err, 1e-5);
  EXPECT_LT(err, 1e-5);
  EXPECT_GT(err_fixed, 1e-3);
  EXPECT_TRUE(ef.nonlinear.size() == 0);
  for (Eigen::Index k = 0; k < e.nonlinear.size(); ++k) EXPECT_GT(e.nonlinear_std[k], 0.0);
}

}  // namespace
