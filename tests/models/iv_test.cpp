// The `iv` estimator (instrumental variables, the instrument simulated from the model): with the
// true parameters its simulation is the plant's closed loop; noise in the measured positions and
// their derivatives biases least squares, while iv, simulating the closed loop from the
// recording's reference and the robot's PD gains, stays within its reported standard
// deviations. Its inputs are checked by name.
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

TEST(Iv, StaysWithinItsStandardDeviationsWhereNoisyPositionsBiasLeastSquares) {
  auto r = mtest::robot("puma560");
  const int n = r->dof();
  const exid::Samples ref = cltest::reference(n, 6.0);
  const exid::Dataset clean = mtest::simulate(
      r,
      "{controller: pd_feedforward, kp: 400, kd: 40, sample_period_s: 0.005, coulomb: tanh, "
      "coulomb_velocity_scale: 0.05}",
      7, &ref);
  const fs::path dir = exid_cli::freshTempDir("exid_iv_", "ref");
  cltest::writeReference(ref, dir / "reference.csv");
  // (the plant's smooth Coulomb friction: a sign(qd) would make a simulation with a wrong
  // estimate chatter where a joint sticks)
  auto m = mtest::model("differential", "{offset: true, coulomb_smoothing_rad_s: [0.05]}", r);
  const Eigen::VectorXd truth = m->baseNominal();
  const std::string params = fmt::format(
      "{{reference_file: {}, {}}}", (dir / "reference.csv").string(), cltest::gains(clean.meta));
  {  // noise-free: the simulation with the true parameters is the plant (same controller)
    auto iv = exid_test::create<exid::Estimator>("iv", params);
    const exid::Estimate e = iv->estimate(*m, clean, nullptr, mtest::context());
    const double err = (e.value - truth).norm() / truth.norm();
    const double track = e.details.find("trace")->at(0).find("tracking_rms_rad")->asDouble();
    std::printf("[iv] noise free: parameters %.2e, simulated against recorded q %.2e rad rms\n",
                err, track);
    EXPECT_LT(err, 1e-9);
    EXPECT_LT(track, 1e-7);
  }
  int draws = 4, within2 = 0, count = 0;
  double z2 = 0, z2_ls = 0;
  for (int seed = 1; seed <= draws; ++seed) {
    exid::Dataset d = clean;
    std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
    std::normal_distribution<double> nd(0.0, 1.0);
    for (int k = 0; k < d.size(); ++k)
      for (int j = 0; j < n; ++j) {
        d.q(k, j) += 2e-4 * nd(rng);
        d.qd(k, j) += 0.015 * nd(rng);
        d.qdd(k, j) += 0.3 * nd(rng);
        d.tau(k, j) += 0.1 * nd(rng);
      }
    auto ls = exid_test::create<exid::Estimator>("batch_ls", "{}");
    const exid::Estimate el = ls->estimate(*m, d, nullptr, mtest::context());
    auto iv = exid_test::create<exid::Estimator>("iv", params);
    const exid::Estimate e = iv->estimate(*m, d, nullptr, mtest::context());
    for (Eigen::Index i = 0; i < truth.size(); ++i) {
      const double z = (e.value[i] - truth[i]) / e.std[i];
      const double zl = (el.value[i] - truth[i]) / el.std[i];
      z2 += z * z;
      z2_ls += zl * zl;
      within2 += std::abs(z) < 2.0;
      ++count;
    }
    if (seed == 1)
      std::printf("[iv] %s iterations, %s\n", e.details.find("iterations")->dump().c_str(),
                  e.details.find("stop")->asString().c_str());
  }
  std::printf("[iv] %d of %d within 2 sigma, mean z^2 = %.2f (batch_ls: mean z^2 = %.2f)\n",
              within2, count, z2 / count, z2_ls / count);
  EXPECT_GE(within2, static_cast<int>(0.8 * count));
  EXPECT_LT(z2 / count, 2.5);
  EXPECT_GT(z2 / count, 0.3);
  EXPECT_GT(z2_ls / count, 2 * z2 / count);  // (why iv exists)
}

TEST(Iv, ItsInputsAreCheckedByName) {
  auto expectError = [](const std::string& params, const std::string& what) {
    try {
      (void)exid_test::create<exid::Estimator>("iv", params);
      ADD_FAILURE() << params << " was accepted";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  expectError("{kp_Nm_per_rad: [1], kd_Nm_s_per_rad: [1]}", "reference_file");
  expectError("{reference_file: x.csv}", "kp_Nm_per_rad");
  auto r = mtest::robot("puma560");
  const fs::path dir = exid_cli::freshTempDir("exid_iv_", "bad");
  cltest::writeReference(cltest::reference(r->dof(), 1.0), dir / "short.csv");
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 2, sample_period_s: 0.01}");
  auto m = mtest::model("differential", "{}", r);
  auto iv = exid_test::create<exid::Estimator>(
      "iv", fmt::format("{{reference_file: {}, kp_Nm_per_rad: [100], kd_Nm_s_per_rad: [10]}}",
                        (dir / "short.csv").string()));
  try {
    (void)iv->estimate(*m, d, nullptr, mtest::context());
    ADD_FAILURE() << "a recording longer than its reference was accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("not within the reference"), std::string::npos)
        << e.what();
  }
  auto m2 = mtest::model("differential", "{joints: [2]}", r);
  try {
    (void)iv->estimate(*m2, d, nullptr, mtest::context());
    ADD_FAILURE() << "a model of one joint was accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("one row per joint"), std::string::npos) << e.what();
  }
}

}  // namespace
