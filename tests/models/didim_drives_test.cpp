// The closed loop of `iv` and `didim` with what acts on the drives' command: drive gains (the
// drives deliver (1 + dK) times the recorded command), a Coulomb friction growing with the
// command (FcL), and a delay of the recorded torque behind the controller. The plant is the
// `simulate` experiment's (drive_torque_gain, coulomb_load_Nm_per_Nm, torque_delay_s); the
// output error recovers each from exact torques, its Jacobian (forward sensitivities, and the
// delay's column -d tau_c / dt with the reference's jerk) equals central differences, and what
// the closed loop cannot simulate is refused by name.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "closed_loop_test_util.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

namespace fs = std::filesystem;

using cltest::Loop;

// The PUMA tracking a smooth reference through PD + feed-forward for `duration` s; `plant` adds
// the experiment's keys, `model` the differential model's.
// A reference whose joints never reverse: q_j = v_j t + small sines, |qd_j| >= 0.1 rad/s (a
// Coulomb friction through sign(qd) is then smooth along the motion).
exid::Samples monotonic(int n, double duration) {
  exid::Samples s = cltest::reference(n, duration);
  for (int k = 0; k < s.size(); ++k)
    for (int j = 0; j < n; ++j) {
      const double v = (j % 2 ? -1.0 : 1.0) * (0.45 + 0.05 * j);
      s.q(k, j) = v * s.t[k] + 0.1 * s.q(k, j);
      s.qd(k, j) = v + 0.1 * s.qd(k, j);
      s.qdd(k, j) = 0.1 * s.qdd(k, j);
    }
  return s;
}

Loop setup(double duration, const std::string& plant, const std::string& model,
           bool never_reversing = false, double period_s = 0.005) {
  Loop s;
  s.robot = mtest::robot("puma560");
  const exid::Samples ref = never_reversing ? monotonic(s.robot->dof(), duration)
                                            : cltest::reference(s.robot->dof(), duration);
  s.data = mtest::simulate(
      s.robot,
      fmt::format("{{controller: pd_feedforward, kp: 400, kd: 40, sample_period_s: {}, {}}}",
                  period_s, plant),
      7, &ref);
  const fs::path dir = exid_cli::freshTempDir("exid_didim_drives_", "ref");
  cltest::writeReference(ref, dir / "reference.csv");
  s.model = mtest::model("differential", "{" + model + "}", s.robot);
  s.truth = s.model->baseNominal();
  s.params = fmt::format("reference_file: {}, {}", (dir / "reference.csv").string(),
                         cltest::gains(s.data.meta));
  return s;
}

int baseIndex(const exid::ObservationModel& m, const std::string& name) {
  const auto& n = m.base().names;
  for (std::size_t i = 0; i < n.size(); ++i)
    if (n[i] == name) return static_cast<int>(i);
  return -1;
}

const double kGain[6] = {1.06, 0.95, 1.03, 0.92, 1.08, 0.97};

std::string gainList() {
  std::string g;
  for (int j = 0; j < 6; ++j) g += fmt::format("{}{}", j ? ", " : "", kGain[j]);
  return "[" + g + "]";
}

// Drive gains: the plant's drives deliver gain times the command. With a prior at the true
// gains (their scale with theta), the output error recovers every base parameter and gain.
TEST(DidimDrives, RecoversDriveGainsWithAPrior) {
  Loop s =
      setup(3.0, "coulomb: tanh, coulomb_velocity_scale: 0.05, drive_torque_gain: " + gainList(),
            "offset: true, coulomb_smoothing_rad_s: [0.05], drive_gains: true, "
            "drive_gains_scale: prior");
  std::string mu;
  for (int j = 0; j < 6; ++j) {
    const int b = baseIndex(*s.model, fmt::format("dK{}", j + 1));
    ASSERT_GE(b, 0);
    s.truth[b] = kGain[j] - 1.0;
    mu += fmt::format("{}{:.17g}", j ? ", " : "", kGain[j] - 1.0);
  }
  auto didim = exid_test::create<exid::Estimator>(
      "didim", "{" + s.params +
                   ", fit_nonlinear: false, gradient_check: 2, gain_prior_std: [0.05], "
                   "gain_prior_dK: [" +
                   mu + "]}");
  const exid::Estimate e = didim->estimate(*s.model, s.data, nullptr, mtest::context());
  const double err = (e.value - s.truth).norm() / s.truth.norm();
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  double gerr = 0;
  for (int j = 0; j < 6; ++j)
    gerr = std::max(gerr, std::abs(e.value[baseIndex(*s.model, fmt::format("dK{}", j + 1))] -
                                   (kGain[j] - 1.0)));
  std::printf(
      "[didim] drive gains with a prior at the truth: parameters %.2e, gains %.2e; Jacobian "
      "against central differences %.2e; %s simulations\n",
      err, gerr, grad, e.details.find("simulations")->dump().c_str());
  EXPECT_LT(grad, 1e-3);
  EXPECT_LT(err, 1e-6);
  EXPECT_LT(gerr, 1e-6);
  ASSERT_NE(e.details.find("gain_prior"), nullptr);
  EXPECT_EQ(e.details.find("gain_prior")->find("gains")->size(), 6u);

  // Without the loop's gains (the model without drive_gains) the fit is biased: the gains act.
  auto plain =
      mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}", s.robot);
  auto d2 = exid_test::create<exid::Estimator>("didim", "{" + s.params + ", fit_nonlinear: false}");
  const exid::Estimate e2 = d2->estimate(*plain, s.data, nullptr, mtest::context());
  const Eigen::VectorXd nominal = plain->baseNominal();
  EXPECT_GT((e2.value - nominal).norm() / nominal.norm(), 1e-3);
}

// A prior away from the truth (mean 0): the data fix the gains' ratios, the prior their common
// scale; every gain lies within 3 posterior std of the truth, below the prior's std.
TEST(DidimDrives, APriorOffTheTruthGivesAPosteriorThatHoldsTheTruth) {
  Loop s =
      setup(3.0, "coulomb: tanh, coulomb_velocity_scale: 0.05, drive_torque_gain: " + gainList(),
            "offset: true, coulomb_smoothing_rad_s: [0.05], drive_gains: true, "
            "drive_gains_scale: prior");
  auto didim = exid_test::create<exid::Estimator>(
      "didim", "{" + s.params + ", fit_nonlinear: false, gain_prior_std: [0.05]}");
  const exid::Estimate e = didim->estimate(*s.model, s.data, nullptr, mtest::context());
  double worst_z = 0, worst_std = 0;
  for (int j = 0; j < 6; ++j) {
    const int b = baseIndex(*s.model, fmt::format("dK{}", j + 1));
    worst_z = std::max(worst_z, std::abs(e.value[b] - (kGain[j] - 1.0)) / e.std[b]);
    worst_std = std::max(worst_std, e.std[b]);
  }
  std::printf(
      "[didim] gain prior at 0 (std 0.05): gains within %.2f posterior std of the truth, the "
      "largest posterior std %.3f; %s\n",
      worst_z, worst_std, e.details.find("stop")->asString().c_str());
  EXPECT_LT(worst_z, 3.0);
  EXPECT_LT(worst_std, 0.05);
  EXPECT_TRUE(e.details.find("converged")->asBool());
}

// Load-dependent Coulomb: the plant's friction FcL |tau_c| sign(qd), along a motion that never
// reverses (sign(qd) fixed: the offset would be Coulomb's twin, so the model has none); didim
// recovers FcL with the rest; iv, whose instrument holds the simulated command, too.
TEST(DidimDrives, RecoversLoadDependentCoulombFriction) {
  Loop s = setup(3.0, "coulomb_load_Nm_per_Nm: [0.03]", "coulomb_load: true", true);
  for (int j = 0; j < 6; ++j) {
    const int b = baseIndex(*s.model, fmt::format("FcL{}", j + 1));
    ASSERT_GE(b, 0);
    s.truth[b] = 0.03;
    // the plant's offset rides on Coulomb (sign(qd_j) is the reference's sign throughout)
    const int c = baseIndex(*s.model, fmt::format("Fc{}", j + 1));
    ASSERT_GE(c, 0);
    s.truth[c] += (j % 2 ? -1.0 : 1.0) * s.robot->drives[static_cast<std::size_t>(j)].offset;
  }
  auto didim = exid_test::create<exid::Estimator>("didim", "{" + s.params + ", gradient_check: 2}");
  const exid::Estimate e = didim->estimate(*s.model, s.data, nullptr, mtest::context());
  const double err = (e.value - s.truth).norm() / s.truth.norm();
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  std::printf(
      "[didim] load-dependent Coulomb 0.03: parameters %.2e; Jacobian against central "
      "differences %.2e\n",
      err, grad);
  auto iv = exid_test::create<exid::Estimator>("iv", "{" + s.params + "}");
  const exid::Estimate ei = iv->estimate(*s.model, s.data, nullptr, mtest::context());
  const double err_iv = (ei.value - s.truth).norm() / s.truth.norm();
  std::printf("[iv] load-dependent Coulomb 0.03: parameters %.2e\n", err_iv);
  EXPECT_LT(grad, 1e-3);
  EXPECT_LT(err, 1e-6);
  EXPECT_LT(err_iv, 1e-6);

  // End to end: a study with iv reads the recording; no errors-in-variables warning is given
  // (the instrument is simulated), batch_ls gets one.
  const fs::path dir = exid_cli::freshTempDir("exid_didim_drives_", "study");
  mtest::writeCsv(s.data, dir / "rec.csv");
  for (const char* est : {"iv", "batch_ls"}) {
    std::ofstream(dir / fmt::format("{}.yaml", est))
        << "name: fcl\nrobot: {type: puma560}\n"
        << "model: {type: differential, params: {coulomb_load: true}}\n"
        << "experiment: {type: csv, params: {file: rec.csv}}\n"
        << "estimator: {type: " << est << ", params: {"
        << (std::string(est) == "iv" ? s.params : std::string()) << "}}\n"
        << "report: {type: standard, params: {plots: false}}\n";
    const auto res = exid_cli::runExid(fmt::format(
        "-q run {} --out {}", (dir / fmt::format("{}.yaml", est)).string(), (dir / est).string()));
    ASSERT_EQ(res.code, 0) << res.out;
    const std::string summary = exid_cli::slurp(dir / est / "summary.json");
    EXPECT_EQ(summary.find("errors in variables there") == std::string::npos,
              std::string(est) == "iv")
        << est;
  }
}

// The recorded torque 4.2 ms (4.2 samples) behind the controller: didim fits the delay with
// the parameters from a start near it (measurement_delay_initial_s, e.g. varpro's delay); its
// column -d tau_c / dt is checked against central differences.
TEST(DidimDrives, FitsAMeasurementDelay) {
  Loop s = setup(3.0, "coulomb: tanh, coulomb_velocity_scale: 0.05, torque_delay_s: 0.0042",
                 "offset: true, coulomb_smoothing_rad_s: [0.05]", false, 0.001);
  const std::string base = s.params + ", fit_nonlinear: false";
  auto didim = exid_test::create<exid::Estimator>(
      "didim", "{" + base +
                   ", measurement_delay: true, measurement_delay_max_s: 0.01, "
                   "measurement_delay_initial_s: 0.0038, gradient_check: 2}");
  const exid::Estimate e = didim->estimate(*s.model, s.data, nullptr, mtest::context());
  ASSERT_EQ(e.nonlinear.size(), 1);
  EXPECT_EQ(e.nonlinear_names[0], "measurement_delay_s");
  const double err = (e.value - s.truth).norm() / s.truth.norm();
  const double derr = std::abs(e.nonlinear[0] - 0.0042);
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  auto plain = exid_test::create<exid::Estimator>("batch_ls", "{}");
  const exid::Estimate ep = plain->estimate(*s.model, s.data, nullptr, mtest::context());
  const double err_plain = (ep.value - s.truth).norm() / s.truth.norm();
  std::printf(
      "[didim] delay 4.2 ms: delay to %.2e s (std %.2e s), parameters %.2e (batch_ls, the delay "
      "ignored: %.2e); Jacobian against central differences %.2e; %lld samples left out\n",
      derr, e.nonlinear_std[0], err, err_plain, grad,
      static_cast<long long>(
          e.details.find("measurement_delay")->find("samples_left_out")->asDouble()));
  // central differences of an adaptive simulation (steps of 1e-4 of each parameter): their own
  // error is of this order, and moves with the last bits of the joints' sin and cos (4.9e-4
  // with glibc's, 1.2e-3 with exid's; a wrong column is off by far more)
  EXPECT_LT(grad, 3e-3);
  EXPECT_LT(derr, 1e-7);
  EXPECT_LT(err, 1e-6);
  EXPECT_GT(err_plain, 1e-3);
  EXPECT_GT(e.details.find("measurement_delay")->find("samples_left_out")->asDouble(), 0);

  // End to end: the summary names the delay with its unit, says the model's widths were kept,
  // and the held-out rows are compensated for the delay.
  const fs::path dir = exid_cli::freshTempDir("exid_didim_drives_", "delay_study");
  mtest::writeCsv(s.data, dir / "rec.csv");
  std::ofstream(dir / "delay.yaml")
      << "name: delay\nrobot: {type: puma560}\n"
      << "model: {type: differential, params: {offset: true, coulomb_smoothing_rad_s: [0.05]}}\n"
      << "experiment: {type: csv, params: {file: rec.csv}}\n"
      << "estimator: {type: didim, params: {" << base
      << ", max_iterations: 2, measurement_delay: true, measurement_delay_max_s: 0.01, "
         "measurement_delay_initial_s: 0.0038}}\n"
      << "validation: {type: csv, params: {file: rec.csv}}\n"
      << "report: {type: standard, params: {plots: false}}\n";
  const auto res = exid_cli::runExid(
      fmt::format("-q run {} --out {}", (dir / "delay.yaml").string(), (dir / "out").string()));
  ASSERT_EQ(res.code, 0) << res.out;
  const exid::Json S = exid::Json::parse(exid_cli::slurp(dir / "out" / "summary.json"));
  const exid::Json* nl = S.find("identification")->find("nonlinear_parameters");
  ASSERT_NE(nl, nullptr);
  ASSERT_EQ(nl->size(), 1u);
  EXPECT_EQ(nl->at(0).find("name")->asString(), "measurement_delay_s");
  EXPECT_EQ(nl->at(0).find("unit")->asString(), "s");
  EXPECT_NE(S.dump().find("kept the model's nonlinear parameters"), std::string::npos);
  EXPECT_NE(S.find("validation")->find("measurement_delay_compensation"), nullptr);
}

// Noisy torques (0.1 N m) with the delay and drive gains (a prior at the truth, std 0.05):
// the parameters, gains and delay lie within their reported standard deviations.
TEST(DidimDrives, NoisyTorquesGiveDelayGainsAndParametersWithinTheirStd) {
  Loop s = setup(3.0,
                 "coulomb: tanh, coulomb_velocity_scale: 0.05, torque_delay_s: 0.0042, "
                 "drive_torque_gain: " +
                     gainList(),
                 "offset: true, coulomb_smoothing_rad_s: [0.05], drive_gains: true, "
                 "drive_gains_scale: prior",
                 false, 0.001);
  std::string mu;
  for (int j = 0; j < 6; ++j) {
    s.truth[baseIndex(*s.model, fmt::format("dK{}", j + 1))] = kGain[j] - 1.0;
    mu += fmt::format("{}{:.17g}", j ? ", " : "", kGain[j] - 1.0);
  }
  int within2 = 0, count = 0;
  double z2 = 0, zd2 = 0;
  for (int seed = 1; seed <= 2; ++seed) {
    exid::Dataset d = s.data;
    std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
    std::normal_distribution<double> nd(0.0, 0.1);
    for (int k = 0; k < d.size(); ++k)
      for (int j = 0; j < d.dof(); ++j) d.tau(k, j) += nd(rng);
    auto didim = exid_test::create<exid::Estimator>(
        "didim", "{" + s.params +
                     ", fit_nonlinear: false, measurement_delay: true, measurement_delay_max_s: "
                     "0.01, measurement_delay_initial_s: 0.0038, gain_prior_std: [0.05], "
                     "gain_prior_dK: [" +
                     mu + "]}");
    const exid::Estimate e = didim->estimate(*s.model, d, nullptr, mtest::context());
    for (Eigen::Index i = 0; i < s.truth.size(); ++i) {
      const double z = (e.value[i] - s.truth[i]) / e.std[i];
      z2 += z * z;
      within2 += std::abs(z) < 2.0;
      ++count;
    }
    const double zd = (e.nonlinear[0] - 0.0042) / e.nonlinear_std[0];
    zd2 += zd * zd;
    within2 += std::abs(zd) < 2.0;
    ++count;
    std::printf("[didim] noisy, seed %d: delay %.6f s (std %.2e s)\n", seed, e.nonlinear[0],
                e.nonlinear_std[0]);
  }
  std::printf(
      "[didim] noisy torques with a delay and gains: %d of %d within 2 sigma, mean z^2 "
      "%.2f (delay's z^2 %.2f over 2 draws)\n",
      within2, count, z2 / (count - 2), zd2 / 2);
  EXPECT_GE(within2, static_cast<int>(0.8 * count));
  EXPECT_GT(z2 / (count - 2), 0.3);
  EXPECT_LT(z2 / (count - 2), 2.5);
  EXPECT_LT(zd2 / 2, 9.0);
}

TEST(DidimDrives, RefusesWhatTheClosedLoopCannotSimulate) {
  Loop s = setup(1.0, "coulomb: tanh, coulomb_velocity_scale: 0.05",
                 "offset: true, coulomb_smoothing_rad_s: [0.05], drive_gains: true, "
                 "drive_gains_scale: prior");
  auto expectError = [&](const std::string& est, const std::string& extra, const exid::Dataset& d,
                         const std::string& needle) {
    auto e = exid_test::create<exid::Estimator>(est, "{" + s.params + extra + "}");
    try {
      e->estimate(*s.model, d, nullptr, mtest::context());
      ADD_FAILURE() << est << extra << ": no error";
    } catch (const exid::Error& err) {
      EXPECT_NE(std::string(err.what()).find(needle), std::string::npos) << err.what();
    }
  };
  expectError("didim", "", s.data, "gain_prior_std");
  expectError("iv", "", s.data, "drive gains");
  exid::Dataset loaded = s.data;
  loaded.facts.payload_part_from_t_s = 0.5;
  expectError("didim", ", gain_prior_std: [0.1]", loaded, "payload_part_from_t_s");
  EXPECT_THROW(exid_test::create<exid::Estimator>(
                   "didim", "{" + s.params +
                                ", output: position, measurement_delay: true, "
                                "measurement_delay_max_s: 0.01}"),
               exid::Error);
  EXPECT_THROW(
      exid_test::create<exid::Estimator>("didim", "{" + s.params + ", measurement_delay: true}"),
      exid::Error);
}

}  // namespace
