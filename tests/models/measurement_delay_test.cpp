// A delay between the measurement and the position channels: the interpolant that reads a signal
// at shifted times (exact for cubics, its derivative in the shift equal to central differences
// and continuous across samples), the csv and simulate experiments' known delay, and the
// `varpro` estimator that fits an unknown one with the other parameters (noise-free: recovered;
// noisy: within its own standard deviation), then validates on rows compensated by it.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "exid/delay.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

namespace fs = std::filesystem;

// Cubics on a slightly uneven grid: the five-point slopes are exact for quartics, so the
// Hermite interpolant is exact for cubics, whatever the steps.
TEST(MeasurementDelay, TheInterpolantIsExactForCubicsAndItsDerivativeIsTheShifts) {
  const int K = 40;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd t(K);
  auto f = [](double x, int j) {
    return j == 0 ? 3 - 2 * x + 5 * x * x - 7 * x * x * x : -1 + 4 * x * x + x * x * x;
  };
  auto df = [](double x, int j) { return j == 0 ? -2 + 10 * x - 21 * x * x : 8 * x + 3 * x * x; };
  double at = 0.2;
  for (int k = 0; k < K; ++k) {
    t[k] = at;
    at += 0.01 * (1 + 0.3 * u(rng));
  }
  // two rows per sample: (f0, f1) and (2 f0, -f1)
  Eigen::MatrixXd X(2 * K, 2);
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < 2; ++j) {
      X(2 * k, j) = f(t[k], j);
      X(2 * k + 1, j) = (j == 0 ? 2.0 : -1.0) * f(t[k], j);
    }
  for (double d : {0.0, 0.0037, -0.0121, 0.05, 0.01}) {
    int a = 0, b = 0;
    exid::shiftedRange(t, d, &a, &b);
    ASSERT_LT(a, b);
    Eigen::MatrixXd out, dout;
    exid::shiftedRows(t, X, 2, d, a, b, &out, &dout);
    for (int k = a; k < b; ++k)
      for (int j = 0; j < 2; ++j) {
        const double x = t[k] + d, c = j == 0 ? 2.0 : -1.0;
        EXPECT_NEAR(out(2 * (k - a), j), f(x, j), 1e-12) << d << " " << k;
        EXPECT_NEAR(out(2 * (k - a) + 1, j), c * f(x, j), 1e-12) << d << " " << k;
        EXPECT_NEAR(dout(2 * (k - a), j), df(x, j), 1e-9) << d << " " << k;
      }
    // the range: t_k + d within [t_2, t_{K-3}], every other sample outside
    EXPECT_GE(t[a] + d, t[2]);
    if (a > 0) {
      EXPECT_LT(t[a - 1] + d, t[2]);
    }
    EXPECT_LE(t[b - 1] + d, t[K - 3]);
    if (b < K) {
      EXPECT_GT(t[b] + d, t[K - 3]);
    }
  }
  // a sample read outside the interpolable range is refused
  Eigen::MatrixXd out;
  EXPECT_THROW(exid::shiftedRows(t, X, 2, 0.02, K - 4, K, &out, nullptr), exid::Error);
}

TEST(MeasurementDelay, TheDerivativeEqualsCentralDifferencesAndIsContinuousAcrossSamples) {
  const int K = 60;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd t(K);
  Eigen::MatrixXd X(K, 3);
  double at = 0;
  for (int k = 0; k < K; ++k) {
    at += 0.002 * (1 + 0.2 * u(rng));  // uneven steps
    t[k] = at;
    for (int j = 0; j < 3; ++j) X(k, j) = std::sin(40 * at + j) + 0.1 * u(rng);
  }
  const int a = 10, b = 50;
  double worst = 0;
  for (double d : {0.0011, -0.0043, 0.007}) {
    Eigen::MatrixXd out, dout, op, om;
    exid::shiftedRows(t, X, 1, d, a, b, &out, &dout);
    const double e = 1e-7;
    exid::shiftedRows(t, X, 1, d + e, a, b, &op, nullptr);
    exid::shiftedRows(t, X, 1, d - e, a, b, &om, nullptr);
    const Eigen::MatrixXd fd = (op - om) / (2 * e);
    worst = std::max(worst, (fd - dout).cwiseAbs().maxCoeff() / dout.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-6);
  // at a shift that lands every sample on another sample, the value is that sample's and the
  // derivative from either side agrees (C1)
  Eigen::VectorXd tu(K);
  for (int k = 0; k < K; ++k) tu[k] = 0.002 * k;
  Eigen::MatrixXd on, don, lo, dlo, hi, dhi;
  const double d = 3 * 0.002;
  exid::shiftedRows(tu, X, 1, d, a, b, &on, &don);
  exid::shiftedRows(tu, X, 1, d - 1e-12, a, b, &lo, &dlo);
  exid::shiftedRows(tu, X, 1, d + 1e-12, a, b, &hi, &dhi);
  EXPECT_LT((on - X.middleRows(a + 3, b - a)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((dlo - dhi).cwiseAbs().maxCoeff(), 1e-6 * don.cwiseAbs().maxCoeff());
}

TEST(MeasurementDelay, CompensationReadsThePositionsEarlierAndCountsTheEnds) {
  exid::Dataset d;
  const int K = 100;
  d.t = Eigen::VectorXd::LinSpaced(K, 0.0, 0.99);
  d.q = Eigen::MatrixXd::Zero(K, 2);
  d.tau = Eigen::MatrixXd::Random(K, 2);
  for (int k = 0; k < K; ++k) d.q(k, 0) = 2 * d.t[k];
  int front = -1, back = -1;
  const exid::Dataset c = exid::compensateDelay(d, 0.035, "test", &front, &back);
  EXPECT_EQ(front, 6);  // t - 0.035 below t_2 = 0.02: t < 0.055
  EXPECT_EQ(back, 0);
  EXPECT_EQ(c.size(), K - 6);
  EXPECT_NEAR(c.q(10, 0), 2 * (d.t[16] - 0.035), 1e-12);
  EXPECT_EQ(c.tau.row(10), d.tau.row(16));  // the measurement as recorded
  EXPECT_EQ(c.t[10], d.t[16]);
  const exid::Dataset n = exid::compensateDelay(d, -0.025, "test", &front, &back);
  EXPECT_EQ(front, 0);
  EXPECT_EQ(back, 5);  // t + 0.025 beyond t_{K-3} = 0.97: t > 0.945
  EXPECT_NEAR(n.t[n.size() - 1], 0.94, 1e-12);
  try {
    (void)exid::compensateDelay(d, 2.0, "experiment 'x'", &front, &back);
    ADD_FAILURE() << "a delay longer than the recording was accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(
        std::string(e.what()).find("experiment 'x': a measurement delay of 2 s leaves 0 of 100"),
        std::string::npos)
        << e.what();
  }
}

// The simulated plant's torque lags by a sub-sample delay; the model has the plant's own
// drive terms (rotor inertia, Coulomb through tanh, viscous, offset).
constexpr double kDelay = 0.0013;
constexpr const char* kPlant =
    "{{duration_s: 6, sample_period_s: 0.001, coulomb: tanh, coulomb_velocity_scale: 0.05, "
    "rtol: 1e-11, atol: 1e-12, torque_delay_s: {}}}";
constexpr const char* kModel = "{offset: true, coulomb_smoothing_rad_s: [0.03]}";

TEST(Varpro, RecoversASimulatedDelayWithTheOtherParameters) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(r, fmt::format(kPlant, kDelay));
  const exid::Json* td = d.meta.find("torque_delay");
  ASSERT_NE(td, nullptr);
  EXPECT_EQ(td->find("dropped_samples_front")->asInt(), 2);  // t - 0.0013 before the start
  auto m = mtest::model("differential", kModel, r);
  auto v = exid_test::create<exid::Estimator>(
      "varpro", "{measurement_delay: true, measurement_delay_max_s: 0.01}");
  const exid::Estimate e = v->estimate(*m, d, nullptr, mtest::context());
  ASSERT_EQ(e.nonlinear_names.back(), "measurement_delay_s");
  const double got = e.nonlinear[e.nonlinear.size() - 1];
  std::printf("[varpro] delay: %.10f s (true %.4f), eps1 %.8g, %s evaluations, %s\n", got, kDelay,
              e.nonlinear[0], e.details.find("evaluations")->dump().c_str(),
              e.details.find("stop")->asString().c_str());
  EXPECT_NEAR(got, kDelay, 1e-6 * kDelay);
  // The widths to 1e-5: the rows are read between samples by a fourth-order interpolation,
  // and the tanh columns are the steepest in time (2e-6 on one joint at 1 kHz).
  for (int k = 0; k < e.nonlinear.size() - 1; ++k) EXPECT_NEAR(e.nonlinear[k], 0.05, 1e-5 * 0.05);
  // every Coulomb level is the plant's (the drive's nominal), to 1e-6
  for (std::size_t i = 0; i < e.names.size(); ++i)
    if (e.names[i].rfind("Fc", 0) == 0) {
      const auto j = static_cast<std::size_t>(e.names[i].back() - '1');
      EXPECT_NEAR(e.value[static_cast<Eigen::Index>(i)], r->drives[j].coulomb,
                  1e-6 * r->drives[j].coulomb)
          << e.names[i];
    }
  const exid::Json* dd = e.details.find("measurement_delay");
  ASSERT_NE(dd, nullptr);
  EXPECT_EQ(dd->find("samples_without_rows_each_end")->asInt(), 13);  // 0.01 / 0.001 + 3
  EXPECT_EQ(e.rows, static_cast<long>(6 * (d.size() - 26)));
  // without the delay the same fit is far worse
  auto v0 = exid_test::create<exid::Estimator>("varpro", "{}");
  const exid::Estimate e0 = v0->estimate(*m, d, nullptr, mtest::context());
  EXPECT_GT(e0.residual_rms, 100 * e.residual_rms);
}

// White noise on the measured torque: the measurement is never interpolated, so the fitted
// delay is unbiased and its reported standard deviation holds (interpolating the noisy torque
// instead pulls every estimate to half a sample).
TEST(Varpro, NoisyDelayEstimatesLieWithinTheirReportedStandardDeviations) {
  auto r = mtest::robot("puma560");
  const double delay = 0.0031;
  const exid::Dataset clean =
      mtest::simulate(r, fmt::format("{{duration_s: 3, sample_period_s: 0.002, drive_terms: false, "
                                     "torque_delay_s: {}}}",
                                     delay));
  auto m =
      mtest::model("differential", "{rotor_inertia: false, coulomb: false, viscous: false}", r);
  const int draws = 24;
  int within2 = 0;
  double z2 = 0;
  for (int seed = 1; seed <= draws; ++seed) {
    exid::Dataset d = clean;
    std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
    std::normal_distribution<double> nd(0.0, 0.5);
    for (int k = 0; k < d.size(); ++k)
      for (int j = 0; j < d.dof(); ++j) d.tau(k, j) += nd(rng);
    auto v = exid_test::create<exid::Estimator>(
        "varpro", "{measurement_delay: true, measurement_delay_max_s: 0.01}");
    const exid::Estimate e = v->estimate(*m, d, nullptr, mtest::context());
    const double z = (e.nonlinear[0] - delay) / e.nonlinear_std[0];
    z2 += z * z;
    within2 += std::abs(z) < 2.0;
  }
  const double mean_z2 = z2 / draws;
  std::printf("[varpro] noisy delay: %d of %d within 2 sigma, mean z^2 = %.2f\n", within2, draws,
              mean_z2);
  EXPECT_GE(within2, 19);
  EXPECT_GT(mean_z2, 0.3);
  EXPECT_LT(mean_z2, 2.5);
}

TEST(Varpro, ADelayIsRefusedWithoutItsBoundOrWithAModelThatIsNotPerSample) {
  try {
    (void)exid_test::create<exid::Estimator>("varpro", "{measurement_delay: true}");
    ADD_FAILURE() << "measurement_delay without measurement_delay_max_s was accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("measurement_delay_max_s"), std::string::npos) << e.what();
  }
  EXPECT_THROW(
      (void)exid_test::create<exid::Estimator>("varpro", "{measurement_delay_max_s: 0.01}"),
      exid::Error);
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 2, sample_period_s: 0.01}");
  auto m = mtest::model("integral", "{}", r);
  auto v = exid_test::create<exid::Estimator>(
      "varpro", "{measurement_delay: true, measurement_delay_max_s: 0.01}");
  try {
    (void)v->estimate(*m, d, nullptr, mtest::context());
    ADD_FAILURE() << "a delay with the integral model was accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("per sample"), std::string::npos) << e.what();
  }
}

// End to end: a recording whose torque lags by a known delay. The csv experiment compensates a
// given delay (batch_ls then fits exactly); varpro finds it and validates on rows compensated
// by it; batch_ls without either is far off.
TEST(Varpro, AStudyFitsTheDelayAndValidatesOnRowsCompensatedByIt) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(
      r, "{duration_s: 6, sample_period_s: 0.002, drive_terms: false, torque_delay_s: 0.0027}");
  const fs::path dir = exid_cli::freshTempDir("exid_delay_", "study");
  mtest::writeCsv(d, dir / "rec.csv");
  const std::string model =
      "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
      "false}}\n";
  struct Case {
    const char* name;
    const char* experiment;
    const char* estimator;
  };
  for (const Case& c :
       {Case{"known", "{file: rec.csv, measurement_delay_s: 0.0027}", "{type: batch_ls}"},
        Case{"fitted", "{file: rec.csv}",
             "{type: varpro, params: {measurement_delay: true, measurement_delay_max_s: 0.01}}"},
        Case{"ignored", "{file: rec.csv}", "{type: batch_ls}"}}) {
    std::ofstream(dir / fmt::format("{}.yaml", c.name))
        << "name: delay_" << c.name << "\nrobot: {type: puma560}\n"
        << model << "experiment: {type: csv, params: " << c.experiment << "}\n"
        << "estimator: " << c.estimator << "\n"
        << "validation: {type: csv, params: {file: rec.csv}}\n"
        << "report: {type: standard, params: {plots: false}}\n";
    const auto res = exid_cli::runExid(fmt::format("-q run {} --out {}",
                                                   (dir / fmt::format("{}.yaml", c.name)).string(),
                                                   (dir / c.name).string()));
    ASSERT_EQ(res.code, 0) << res.out;
    const exid::Json S = exid::Json::parse(exid_cli::slurp(dir / c.name / "summary.json"));
    const exid::Json& I = *S.find("identification");
    const double rms = I.find("residual_rms")->asDouble();
    const double verr = S.find("validation")->find("relative_error")->asDouble();
    const std::string name = c.name;
    std::printf("[delay study] %s: residual rms %.3g, held-out %.3g\n", c.name, rms, verr);
    if (name == "known") {
      const exid::Json* md = S.find("experiment")->find("meta")->find("measurement_delay");
      ASSERT_NE(md, nullptr) << S.find("experiment")->dump();
      EXPECT_EQ(md->find("dropped_samples_front")->asInt(), 4);  // t - 0.0027 before t_2
      int back = 0;  // t - 0.0027 beyond t_{K-3} (the recording's last step may be short)
      for (int k = 0; k < d.size(); ++k) back += d.t[k] - 0.0027 > d.t[d.size() - 3];
      EXPECT_EQ(md->find("dropped_samples_back")->asInt(), back);
      EXPECT_LT(rms, 1e-4);
    } else if (name == "fitted") {
      const exid::Json* nl = I.find("nonlinear_parameters");
      ASSERT_NE(nl, nullptr);
      ASSERT_EQ(nl->size(), 1u);
      EXPECT_EQ(nl->at(0).find("name")->asString(), "measurement_delay_s");
      EXPECT_EQ(nl->at(0).find("unit")->asString(), "s");
      EXPECT_NEAR(nl->at(0).find("value")->asDouble(), 0.0027, 1e-8);
      const exid::Json* vc = S.find("validation")->find("measurement_delay_compensation");
      ASSERT_NE(vc, nullptr);
      EXPECT_EQ(vc->find("samples_without_rows_front")->asInt(), 4);
      EXPECT_LT(verr, 1e-5);
    } else {
      EXPECT_GT(verr, 1e-3);  // the uncompensated fit
    }
  }
}

}  // namespace
