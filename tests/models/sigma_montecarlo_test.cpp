// Monte-Carlo checks of the reported standard deviations of the estimators that iterate
// (iv's outer loop, gains_ls, didim): over seeded noise draws of a simulated recording the reported
// std of each base parameter is compared with the empirical spread of its estimates, on a robot
// of revolute joints (PUMA 560) and on one with a prismatic joint (the Stanford arm's joint 3).
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <random>

#include "closed_loop_test_util.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

namespace fs = std::filesystem;

int draws(int fallback) {
  const char* s = std::getenv("EXID_MC_DRAWS");  // a longer study by hand; the test's own count
  return s ? std::max(3, std::atoi(s)) : fallback;
}

struct Spread {
  std::vector<double> ratio;  // reported / empirical std, per parameter
  double median = 0;
  double mean_z2_spread = 0;  // mean over parameters of (empirical / reported)^2
};

// Estimates of `n` draws; per parameter the mean reported std against the empirical std.
Spread spread(const char* label, const std::vector<std::string>& names,
              const Eigen::VectorXd& truth, int n,
              const std::function<exid::Estimate(int)>& estimate) {
  const auto p = truth.size();
  Eigen::MatrixXd est(n, p), rep(n, p);
  for (int s = 0; s < n; ++s) {
    const exid::Estimate e = estimate(s);
    est.row(s) = e.value.transpose();
    rep.row(s) = e.std.transpose();
  }
  Spread out;
  for (Eigen::Index i = 0; i < p; ++i) {
    const double mean = est.col(i).mean();
    const double sd = std::sqrt((est.col(i).array() - mean).square().sum() / (n - 1));
    const double r = rep.col(i).mean() / sd;
    out.ratio.push_back(r);
    out.mean_z2_spread += 1.0 / (r * r) / static_cast<double>(p);
    std::printf(
        "[%s] %-12s truth %+.4e bias %+.2e (%.1f se) empirical std %.3e reported %.3e "
        "ratio %.3f\n",
        label, names[static_cast<std::size_t>(i)].c_str(), truth[i], mean - truth[i],
        (mean - truth[i]) / (sd / std::sqrt(n)), sd, rep.col(i).mean(), r);
  }
  std::vector<double> sorted = out.ratio;
  std::sort(sorted.begin(), sorted.end());
  out.median = sorted[sorted.size() / 2];
  std::printf(
      "[%s] %d draws, %zu parameters: reported / empirical std median %.3f, range "
      "[%.3f, %.3f], mean (empirical/reported)^2 %.3f\n",
      label, n, sorted.size(), out.median, sorted.front(), sorted.back(), out.mean_z2_spread);
  return out;
}

// iv (or didim) on a closed loop (the iv test's set-up): PD + feed-forward, tanh Coulomb, noise
// on q, qd, qdd and tau.
Spread loopSpread(const std::string& robot, int n, double duration, double noise,
                  const char* estimator = "iv", const char* extra = "") {
  auto r = mtest::robot(robot);
  EXPECT_NE(r, nullptr);
  const int dof = r->dof();
  const exid::Samples ref = cltest::reference(dof, duration);
  const exid::Dataset clean = mtest::simulate(
      r,
      "{controller: pd_feedforward, kp: 400, kd: 40, sample_period_s: 0.005, coulomb: tanh, "
      "coulomb_velocity_scale: 0.05}",
      7, &ref);
  const fs::path dir = exid_cli::freshTempDir("exid_mc_iv_", robot);
  cltest::writeReference(ref, dir / "reference.csv");
  auto m = mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}", r);
  const std::string params =
      fmt::format("{{reference_file: {}, {}{}}}", (dir / "reference.csv").string(),
                  cltest::gains(clean.meta), extra);
  return spread((std::string(estimator) + " " + robot).c_str(), m->base().names, m->baseNominal(),
                n, [&](int s) {
                  exid::Dataset d = clean;
                  std::mt19937_64 rng(static_cast<std::uint64_t>(100 + s));
                  std::normal_distribution<double> nd(0.0, 1.0);
                  for (int k = 0; k < d.size(); ++k)
                    for (int j = 0; j < dof; ++j) {
                      d.q(k, j) += noise * 2e-4 * nd(rng);
                      d.qd(k, j) += noise * 0.015 * nd(rng);
                      d.qdd(k, j) += noise * 0.3 * nd(rng);
                      d.tau(k, j) += noise * 0.1 * nd(rng);
                    }
                  return exid_test::create<exid::Estimator>(estimator, params)
                      ->estimate(*m, d, nullptr, mtest::context());
                });
}

// gains_ls on drive gains (the drive_gains test's set-up): a recording in two parts, the second
// with a known payload, both recorded through gains recorded/true = 0.9 .. 1.2, noise 1 % of
// each joint's rms torque.
Spread gainsSpread(const std::string& robot, int n) {
  auto r = mtest::robot(robot);
  EXPECT_NE(r, nullptr);
  const int dof = r->dof();
  const std::vector<double> gain = {0.9, 1.1, 1.05, 0.95, 1.2, 0.8};
  const std::string payload =
      "payload_mass_kg: 2.5, payload_com_m: [0.01, -0.02, 0.08], "
      "payload_inertia_kg_m2: [0.02, 0.001, 0, 0.03, -0.002, 0.015]";
  auto m = mtest::model("differential",
                        fmt::format("{{offset: true, drive_gains: true, {}}}", payload), r);
  const std::string gains = fmt::format("[{}]", fmt::join(gain.begin(), gain.begin() + dof, ", "));
  exid::Dataset a = mtest::gainedTwoParts(r, gains, payload);
  // the truth: dK_j = 1 / gain_j - 1, the rest the robot's nominal values
  Eigen::VectorXd full = m->fullNominal();
  const std::vector<std::string> fn = m->fullNames();
  for (std::size_t i = 0; i < fn.size(); ++i)
    if (fn[i].rfind("dK", 0) == 0)
      full[static_cast<Eigen::Index>(i)] =
          1.0 / gain[static_cast<std::size_t>(std::stoi(fn[i].substr(2)) - 1)] - 1.0;
  const Eigen::VectorXd truth = m->base().reduce(full);
  std::vector<double> rms(static_cast<std::size_t>(dof));
  for (int j = 0; j < dof; ++j)
    rms[static_cast<std::size_t>(j)] =
        a.tau.col(j).norm() / std::sqrt(static_cast<double>(a.tau.rows()));
  return spread(("gains_ls " + robot).c_str(), m->base().names, truth, n, [&](int s) {
    exid::Dataset d = a;
    std::mt19937_64 rng(static_cast<std::uint64_t>(100 + s));
    std::normal_distribution<double> nd(0.0, 1.0);
    for (Eigen::Index j = 0; j < d.tau.cols(); ++j)
      for (Eigen::Index k = 0; k < d.tau.rows(); ++k)
        d.tau(k, j) += 0.01 * rms[static_cast<std::size_t>(j)] * nd(rng);
    return exid_test::create<exid::Estimator>("gains_ls", "{}")
        ->estimate(*m, d, nullptr, mtest::context());
  });
}

// Every parameter's reported / empirical std within [lo, hi], the median within
// [1 / (1 + tol), 1 + tol].
void expectHonest(const Spread& s, const std::vector<std::string>& names, double lo, double hi,
                  double tol = 0.1) {
  EXPECT_GE(s.median, 1.0 / (1.0 + tol));
  EXPECT_LE(s.median, 1.0 + tol);
  for (std::size_t i = 0; i < s.ratio.size(); ++i) {
    EXPECT_GE(s.ratio[i], lo) << names[i] << ": reported / empirical std " << s.ratio[i];
    EXPECT_LE(s.ratio[i], hi) << names[i] << ": reported / empirical std " << s.ratio[i];
  }
}

// The noise is 1 % of each joint's rms torque, so unequal across joints: one pooled noise std
// gave the wrist's drive parameters a std up to 2.7 (PUMA) and 7.3 (Stanford) times their
// spread and joint 2's about half of it; per equation, within [0.85, 1.16] over 100 draws.
TEST(SigmaMonteCarlo, GainsLsStdMatchesTheSpreadForRevoluteAndPrismaticJoints) {
  for (const char* robot : {"puma560", "stanford"}) {
    auto m = mtest::model("differential",
                          "{offset: true, drive_gains: true, payload_mass_kg: 2.5, "
                          "payload_com_m: [0.01, -0.02, 0.08], payload_inertia_kg_m2: [0.02, "
                          "0.001, 0, 0.03, -0.002, 0.015]}",
                          mtest::robot(robot));
    expectHonest(gainsSpread(robot, draws(60)), m->base().names, 0.75, 1.33);
  }
}

// iv: the sandwich over each sample's rows (unchanged; these tests guard it). Over 40 draws on
// the PUMA the median ratio is 0.935 (range [0.77, 1.21]): not 1.4 times too large. Noise on q, qd,
// qdd and tau; on the Stanford arm 0.03 of the PUMA's (more makes some least-squares starts' mass
// matrix indefinite, which iv cannot simulate). Its estimates of the Coulomb and viscous levels are
// biased by the velocity noise inside tanh(qd / 0.05) (up to 17 standard errors of the mean over 40
// draws): the mean z^2 of iv_test is that bias, not the std.
TEST(SigmaMonteCarlo, IvStdMatchesTheSpreadOnRevoluteJoints) {
  auto m = mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}",
                        mtest::robot("puma560"));
  expectHonest(loopSpread("puma560", draws(24), 6.0, 1.0), m->base().names, 0.6, 1.6, 0.25);
}

TEST(SigmaMonteCarlo, IvStdMatchesTheSpreadWithAPrismaticJoint) {
  auto m = mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}",
                        mtest::robot("stanford"));
  expectHonest(loopSpread("stanford", draws(40), 6.0, 0.03), m->base().names, 0.6, 1.6, 0.25);
}

// didim (output error on the torque, fit_nonlinear: false): sigma^2 (J^T J)^-1. On the PUMA
// (6 s, the noise above) 30 draws gave a median ratio of 1.08, range [0.81, 1.50], too slow for
// a test (60 s); on the Stanford arm it is tested.
TEST(SigmaMonteCarlo, DidimStdMatchesTheSpreadWithAPrismaticJoint) {
  auto m = mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}",
                        mtest::robot("stanford"));
  expectHonest(loopSpread("stanford", draws(30), 6.0, 0.03, "didim", ", fit_nonlinear: false"),
               m->base().names, 0.6, 1.6, 0.25);
}

}  // namespace
