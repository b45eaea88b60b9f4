// exid::inspectDataset and the csv experiment's meta.recording: a recording with a flipped torque
// sign, a delay, a standstill, duplicate and frozen rows or a saturated torque column is found
// out; clean simulated data gives no warning.
#include "exid/inspect.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "../../models/model_test_util.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"

namespace {

namespace fs = std::filesystem;

fs::path tmpDir() {
  fs::path p = fs::temp_directory_path() / ("exid_inspect_test_" + std::to_string(::getpid()));
  fs::create_directories(p);
  return p;
}

std::shared_ptr<const exid::RobotModel> puma() { return mtest::robot("puma560"); }

exid::Dataset readCsv(const fs::path& file, const std::string& extra,
                      const std::shared_ptr<const exid::RobotModel>& r) {
  auto e = exid_test::create<exid::Experiment>(
      "csv", "{file: " + file.string() + (extra.empty() ? "" : ", " + extra) + "}");
  return e->run(r, nullptr, mtest::context());
}

exid::Json inspect(const std::shared_ptr<const exid::RobotModel>& r, const exid::Dataset& d) {
  auto m = mtest::model("differential", "{}", r);
  return exid::inspectDataset(*r, m.get(), d, mtest::context());
}

std::string verdict(const exid::Json& J, int joint) {
  return J.find("joints")
      ->at(static_cast<std::size_t>(joint))
      .find("sign_check")
      ->find("verdict")
      ->asString();
}

std::string allWarnings(const exid::Json& J) {
  std::string s;
  const exid::Json* w = J.find("warnings");
  for (std::size_t i = 0; w && i < w->size(); ++i) s += w->at(i).asString() + "\n";
  return s;
}

/// A motion computed from the robot's own model (no simulation): each joint moves by
/// c + a (1 - cos(2 pi s / T)) around the middle of its range, where s(t) is the time with the
/// stretch [rest0, rest1) removed (a standstill there when rest1 > rest0). The torque is the
/// full actuator torque at time t - delay_s (the torque lags by delay_s).
exid::Dataset modelData(const exid::RobotModel& r, double dt, double duration, double rest0 = 0,
                        double rest1 = 0, double delay_s = 0) {
  const int n = r.dof();
  const int K = static_cast<int>(std::lround(duration / dt)) + 1;
  exid::Dataset d;
  d.t.resize(K);
  d.q.resize(K, n);
  d.qd.resize(K, n);
  d.qdd.resize(K, n);
  d.tau.resize(K, n);
  const double T = 3.0;
  auto state = [&](double t, Eigen::VectorXd* q, Eigen::VectorXd* qd, Eigen::VectorXd* qdd) {
    double s = t, ds = 1;
    if (rest1 > rest0 && t >= rest0) {
      if (t < rest1) {
        s = rest0;
        ds = 0;
      } else {
        s = t - (rest1 - rest0);
      }
    }
    q->resize(n);
    qd->resize(n);
    qdd->resize(n);
    for (int j = 0; j < n; ++j) {
      const auto& L = r.limits[static_cast<std::size_t>(j)];
      const double c = L.q_max < 1e299 ? 0.5 * (L.q_min + L.q_max) : 0.0;
      const double a = 0.2 + 0.05 * j;
      const double w = 2 * M_PI / (T / (1 + 0.5 * (j % 3)));  // 1, 1.5, 2 cycles per T
      (*q)[j] = c + a * (1 - std::cos(w * s));
      (*qd)[j] = ds * a * w * std::sin(w * s);
      (*qdd)[j] = ds * a * w * w * std::cos(w * s);
    }
  };
  auto dd = exid::makeDynamicsData(r);
  exid::DriveColumns cols;
  cols.rotor_inertia = cols.coulomb = cols.viscous = cols.offset = true;
  for (int k = 0; k < K; ++k) {
    const double t = k * dt;
    d.t[k] = t;
    Eigen::VectorXd q, qd, qdd;
    state(t, &q, &qd, &qdd);
    d.q.row(k) = q.transpose();
    d.qd.row(k) = qd.transpose();
    d.qdd.row(k) = qdd.transpose();
    state(t - delay_s, &q, &qd, &qdd);
    d.tau.row(k) = exid::actuatorTorque(r, *dd, cols, q, qd, qdd).transpose();
  }
  d.source = "model";
  return d;
}

}  // namespace

TEST(Inspect, CleanSimulatedDataGivesNoWarning) {
  auto r = puma();
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 10, noise_tau_Nm: 0.05}");
  const fs::path f = tmpDir() / "clean.csv";
  exid::writeCsvAtomic(f, exid::datasetTable(d));
  const exid::Json J = inspect(r, readCsv(f, "", r));
  EXPECT_EQ(J.find("warnings")->size(), 0u) << J.dump(2);
  for (int j = 0; j < 6; ++j) EXPECT_EQ(verdict(J, j), "ok") << j;
  // A 100 Hz file is 100 Hz exactly, with no jitter beyond the stamps' rounding.
  const exid::Json& tm = *J.find("recording")->find("timing");
  EXPECT_EQ(tm.find("rate_hz")->asDouble(), 100.0);
  EXPECT_LT(tm.find("jitter")->find("max_rel")->asDouble(), 1e-6);
  EXPECT_EQ(tm.find("gaps")->find("count")->asInt(), 0);
  EXPECT_TRUE(std::isfinite(J.find("regressor")->find("cond_scaled")->asDouble()));
  EXPECT_EQ(J.find("recording")->find("duplicate_rows")->find("count")->asInt(), 0);
  EXPECT_EQ(J.find("recording")->find("frozen_rows")->find("rows")->asInt(), 0);
}

// The regressor's condition number from one sample in s (the runner's cap): stated, with the
// samples it used, and close to the one from every sample (a smooth motion at 100 Hz).
TEST(Inspect, TheRegressorCheckFromEverySthSampleSaysSoAndAgrees) {
  auto r = puma();
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 10, noise_tau_Nm: 0.05}");
  auto m = mtest::model("differential", "{}", r);
  const exid::Json full = *exid::inspectDataset(*r, m.get(), d, mtest::context()).find("regressor");
  const exid::Json some =
      *exid::inspectDataset(*r, m.get(), d, mtest::context(), 300).find("regressor");
  EXPECT_EQ(full.find("stride"), nullptr);
  EXPECT_EQ(full.find("rows")->asInt(), 6 * d.size());
  const long stride = (d.size() + 299) / 300;
  EXPECT_EQ(some.find("stride")->asInt(), stride);
  EXPECT_EQ(some.find("samples_used")->asInt(), (d.size() + stride - 1) / stride);
  EXPECT_LE(some.find("samples_used")->asInt(), 300);
  EXPECT_EQ(some.find("rows")->asInt(), 6 * some.find("samples_used")->asInt());
  EXPECT_NE(some.find("method")->asString().find(fmt::format("one sample in {}", stride)),
            std::string::npos);
  const double a = full.find("cond_scaled")->asDouble(), b = some.find("cond_scaled")->asDouble();
  EXPECT_NE(a, b);  // other rows
  EXPECT_LT(std::abs(b - a), 0.2 * a);
}

TEST(Inspect, FlippedTorqueSignsAreFoundForExactlyThoseJoints) {
  auto r = puma();
  exid::Dataset d = mtest::simulate(r, "{duration_s: 10, noise_tau_Nm: 0.05}");
  d.tau.col(1) *= -1.0;  // tau2
  d.tau.col(3) *= -1.0;  // tau4
  const fs::path f = tmpDir() / "flipped.csv";
  exid::writeCsvAtomic(f, exid::datasetTable(d));
  const exid::Json J = inspect(r, readCsv(f, "", r));
  for (int j = 0; j < 6; ++j) EXPECT_EQ(verdict(J, j), j == 1 || j == 3 ? "flipped" : "ok") << j;
  const std::string w = allWarnings(J);
  EXPECT_NE(w.find("tau2, tau4 are the negative of the nominal model's torque"), std::string::npos)
      << w;
  EXPECT_NE(w.find("torque sign flipped"), std::string::npos) << w;
  EXPECT_EQ(w.find("for every joint"), std::string::npos) << w;  // two of six: not the robot's
  // The csv experiment's own remedy undoes it: tau_scale -1 on those joints.
  const exid::Json K = inspect(r, readCsv(f, "tau_scale: [1, -1, 1, -1, 1, 1]", r));
  for (int j = 0; j < 6; ++j) EXPECT_EQ(verdict(K, j), "ok") << j;
}

TEST(Inspect, ATorqueUnrelatedToTheModelDoesNotFollowIt) {
  auto r = puma();
  exid::Dataset d = mtest::simulate(r, "{duration_s: 10, noise_tau_Nm: 0.05}");
  d.tau.col(2) = d.tau.col(4);  // the wrong column for tau3
  const exid::Json J = inspect(r, d);
  EXPECT_EQ(verdict(J, 2), "does not follow") << J.find("joints")->at(2).dump(2);
  EXPECT_NE(allWarnings(J).find("tau3 does not follow"), std::string::npos) << allWarnings(J);
}

TEST(Inspect, AKnownTorqueDelayIsEstimatedToWithinAThirdOfASample) {
  auto r = puma();
  // Injected into the simulated torque: tau(k) recorded d samples late (d whole samples).
  const exid::Dataset sim = mtest::simulate(r, "{duration_s: 10, noise_tau_Nm: 0.05}");
  const int K = sim.size();
  for (int delay : {3, -2, 0}) {
    const int a = std::max(delay, 0), b = std::max(-delay, 0), m = K - std::abs(delay);
    exid::Dataset d = sim;
    d.t = sim.t.segment(a, m);
    d.q = sim.q.middleRows(a, m);
    d.qd = sim.qd.middleRows(a, m);
    d.qdd = sim.qdd.middleRows(a, m);
    d.tau = sim.tau.middleRows(b, m);  // tau(k) = tau_sim(k - delay)
    const exid::Json J = inspect(r, d);
    const exid::Json& D = *J.find("delay");
    EXPECT_NEAR(D.find("delay_samples")->asDouble(), delay, 0.3) << D.dump(2);
    EXPECT_NEAR(D.find("delay_s")->asDouble(), 0.01 * delay, 0.003);
    if (delay != 0)
      EXPECT_NE(allWarnings(J).find(delay > 0 ? "lags" : "leads"), std::string::npos);
    else
      EXPECT_EQ(J.find("warnings")->size(), 0u) << allWarnings(J);
  }
  // A fraction of a sample: the torque of the robot's own model at t - 2.5 dt (drives without
  // Coulomb friction: its jumps at velocity reversals fall on whole samples).
  exid::RobotModel smooth = *r;
  for (auto& dr : smooth.drives) dr.coulomb = 0;
  auto rs = std::make_shared<const exid::RobotModel>(smooth);
  for (double delay : {2.5, -3.25}) {
    const exid::Json J = inspect(rs, modelData(smooth, 0.01, 9.0, 0, 0, delay * 0.01));
    EXPECT_NEAR(J.find("delay")->find("delay_samples")->asDouble(), delay, 0.3)
        << J.find("delay")->dump(2);
  }
}

TEST(Inspect, AStandstillStretchIsFoundAsASegment) {
  auto r = puma();
  const exid::Dataset d = modelData(*r, 0.01, 8.0, 3.0, 5.0);
  const exid::Json J = inspect(r, d);
  const exid::Json& M = *J.find("motion");
  const exid::Json& rest = *M.find("standstill_s");
  ASSERT_EQ(rest.size(), 1u) << M.dump(2);
  EXPECT_LE(rest.at(0).at(0).asDouble(), 3.05);
  EXPECT_GE(rest.at(0).at(0).asDouble(), 2.8);
  EXPECT_GE(rest.at(0).at(1).asDouble(), 4.95);
  EXPECT_LE(rest.at(0).at(1).asDouble(), 5.2);
  EXPECT_EQ(M.find("moving_s")->size(), 2u) << M.dump(2);
  // motion judges the sign, on the moving samples only
  const exid::Json& s = *J.find("joints")->at(1).find("sign_check");
  EXPECT_LT(s.find("samples")->asInt(), 650);
  EXPECT_GT(s.find("samples")->asInt(), 500);
  EXPECT_EQ(s.find("judged_on")->asString(), "motion");
  EXPECT_EQ(s.find("verdict")->asString(), "ok");
}

TEST(Inspect, AtRestTheSignIsJudgedFromSeveralPoses) {
  // Rest 1 s at each of six poses, 1 s of smooth motion between them; tau2 negated.
  auto r = puma();
  const int n = r->dof();
  const double dt = 0.01;
  std::vector<Eigen::VectorXd> poses;
  for (int i = 0; i < 6; ++i) {
    Eigen::VectorXd p(n);
    for (int j = 0; j < n; ++j) p[j] = 0.6 * std::sin(1.3 * i + 0.7 * j);
    poses.push_back(p);
  }
  exid::Dataset d;
  const int K = static_cast<int>(std::lround(11.0 / dt));
  d.t.resize(K);
  d.q.resize(K, n);
  d.qd.resize(K, n);
  d.qdd.resize(K, n);
  d.tau.resize(K, n);
  auto dd = exid::makeDynamicsData(*r);
  exid::DriveColumns cols;
  cols.rotor_inertia = cols.coulomb = cols.viscous = cols.offset = true;
  for (int k = 0; k < K; ++k) {
    const double t = k * dt;
    const int i = std::min(5, static_cast<int>(t / 2.0));
    const double u = t - 2.0 * i;  // [0, 1): rest at pose i; [1, 2): move to pose i + 1
    const Eigen::VectorXd& a = poses[static_cast<std::size_t>(i)];
    const Eigen::VectorXd& b = poses[static_cast<std::size_t>(std::min(5, i + 1))];
    const double v = u < 1 ? 0 : u - 1;
    d.t[k] = t;
    d.q.row(k) = (a + (b - a) * 0.5 * (1 - std::cos(M_PI * v))).transpose();
    d.qd.row(k) = ((b - a) * (u < 1 ? 0 : 0.5 * M_PI * std::sin(M_PI * v))).transpose();
    d.qdd.row(k) = ((b - a) * (u < 1 ? 0 : 0.5 * M_PI * M_PI * std::cos(M_PI * v))).transpose();
    d.tau.row(k) = exid::actuatorTorque(*r, *dd, cols, d.q.row(k).transpose(),
                                        d.qd.row(k).transpose(), d.qdd.row(k).transpose())
                       .transpose();
    d.tau(k, 1) *= -1.0;
  }
  const exid::Json J = inspect(r, d);
  EXPECT_GE(J.find("motion")->find("standstill_s")->size(), 5u) << J.find("motion")->dump(2);
  const exid::Json& s2 = *J.find("joints")->at(1).find("sign_check");
  EXPECT_NEAR(s2.find("gain")->asDouble(), -1.0, 0.05) << s2.dump(2);
  EXPECT_EQ(s2.find("verdict")->asString(), "flipped");
  EXPECT_NEAR(J.find("joints")->at(2).find("sign_check")->find("gain")->asDouble(), 1.0, 0.05);
  EXPECT_EQ(verdict(J, 2), "ok");
}

TEST(Inspect, DuplicateAndFrozenRowsAndASaturatedTorqueColumnAreCounted) {
  auto r = puma();
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 6, noise_tau_Nm: 0.05}");
  exid::CsvTable T = exid::datasetTable(d);
  // no time column: a duplicated row repeats every used column
  T.columns.erase(T.columns.begin());
  Eigen::MatrixXd X = T.data.rightCols(T.data.cols() - 1);
  const int q0 = 0, tau3 = 3 * 6 + 2;  // columns q1.., qd.., qdd.., tau..
  // frozen: rows 301 and 302 (0-based 300, 301) hold the q of row 300 (0-based 299)
  for (int k : {300, 301}) X.block(k, q0, 1, 6) = X.block(299, q0, 1, 6);
  // saturated: tau3 clipped at 60 % of its maximum
  const double hi = 0.6 * X.col(tau3).maxCoeff();
  for (Eigen::Index k = 0; k < X.rows(); ++k) X(k, tau3) = std::min(X(k, tau3), hi);
  // one duplicated row: row 101 written twice
  Eigen::MatrixXd Y(X.rows() + 1, X.cols());
  Y.topRows(101) = X.topRows(101);
  Y.row(101) = X.row(100);
  Y.bottomRows(X.rows() - 101) = X.bottomRows(X.rows() - 101);
  long long expect_sat = 0;  // clipped samples in runs of 3 or more
  for (Eigen::Index k = 0; k < Y.rows();) {
    Eigen::Index e = k + 1;
    while (e < Y.rows() && Y(e, tau3) == Y(k, tau3)) ++e;
    if (Y(k, tau3) == hi && e - k >= 3) expect_sat += e - k;
    k = e;
  }
  ASSERT_GT(expect_sat, 20);
  T.data = Y;
  const fs::path f = tmpDir() / "bad_rows.csv";
  exid::writeCsvAtomic(f, T);
  const exid::Dataset b = readCsv(f, "sample_period_s: 0.01", r);
  const exid::Json& rec = *b.meta.find("recording");
  EXPECT_EQ(rec.find("duplicate_rows")->find("count")->asInt(), 1) << rec.dump(2);
  EXPECT_EQ(rec.find("duplicate_rows")->find("data_rows")->at(0).asInt(), 102);
  EXPECT_EQ(rec.find("frozen_rows")->find("rows")->asInt(), 2) << rec.dump(2);
  EXPECT_EQ(rec.find("frozen_rows")->find("runs")->asInt(), 1);
  const exid::Json& sat = *rec.find("saturation");
  ASSERT_EQ(sat.size(), 6u);
  EXPECT_EQ(sat.at(2).find("column")->asString(), "tau3");
  EXPECT_EQ(sat.at(2).find("saturated_samples")->asInt(), expect_sat);
  for (std::size_t j : {0u, 1u, 3u, 4u, 5u})
    EXPECT_EQ(sat.at(j).find("saturated_samples")->asInt(), 0) << j;
  EXPECT_EQ(rec.find("timing")->find("rate_hz")->asDouble(), 100.0);
  // and the inspection says so, naming them
  const std::string w = allWarnings(inspect(r, b));
  EXPECT_NE(w.find("1 row(s) repeat the previous row"), std::string::npos) << w;
  EXPECT_NE(w.find("2 row(s) in 1 run(s) hold every joint position"), std::string::npos) << w;
  EXPECT_NE(w.find("torque column 'tau3' sits at its minimum or maximum"), std::string::npos) << w;
}

// A row written twice just after a turning point, where every joint's step into it is below
// three encoder resolutions: the recorded velocities say the robot moves there, so it is a
// duplicate; without velocity columns the positions alone cannot tell it from a brief rest.
TEST(Inspect, ADuplicateAtATurningPointIsToldFromRestByTheRecordedVelocity) {
  auto r = puma();
  constexpr double dt = 0.01, T = 2.0, res = 1e-4;
  const int K = 400, turn = 100;  // every joint at its lowest point at row 100 (t = 1 s)
  const double w = 2 * M_PI / T;
  exid::CsvTable tab;
  for (const char* g : {"q", "qd", "tau"})
    for (int j = 1; j <= 6; ++j) tab.columns.push_back(g + std::to_string(j));
  tab.data.resize(K, 18);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0.0, 0.1);
  // (the first 20 rows creep by one resolution per row: the encoders' step is seen)
  constexpr int creep = 20;
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < 6; ++j) {
      const double A = 0.4 + 0.05 * j, ph = w * (std::max(k, creep) - turn) * dt;
      tab.data(k, j) =
          std::round(-A * std::cos(ph) / res) * res + (creep - std::min(k, creep)) * res;
      tab.data(k, 6 + j) = k < creep ? -res / dt : A * w * std::sin(ph);
      tab.data(k, 12 + j) = N(rng);
    }
  // (the step into row 102 is below three resolutions on every joint)
  for (int j = 0; j < 6; ++j)
    ASSERT_LT(std::abs(tab.data(turn + 1, j) - tab.data(turn, j)), 3 * res) << j;
  tab.data.row(turn + 2) = tab.data.row(turn + 1);  // data row 103 repeats row 102
  const fs::path f = tmpDir() / "turning_dup.csv";
  exid::writeCsvAtomic(f, tab);
  {
    const exid::Dataset b = readCsv(f, "sample_period_s: 0.01", r);
    const exid::Json& rec = *b.meta.find("recording");
    EXPECT_EQ(rec.find("duplicate_rows")->find("count")->asInt(), 1) << rec.dump(2);
    EXPECT_EQ(rec.find("duplicate_rows")->find("data_rows")->at(0).asInt(), 103);
    EXPECT_EQ(rec.find("held_at_rest")->find("rows")->asInt(), 0) << rec.dump(2);
  }
  {  // the same held row at a standstill (velocities zero): at rest, not a duplicate
    exid::CsvTable rest = tab;
    for (int j = 0; j < 6; ++j) rest.data.col(6 + j).setZero();
    exid::writeCsvAtomic(f, rest);
    const exid::Dataset b = readCsv(f, "sample_period_s: 0.01", r);
    const exid::Json& rec = *b.meta.find("recording");
    EXPECT_EQ(rec.find("duplicate_rows")->find("count")->asInt(), 0) << rec.dump(2);
    EXPECT_EQ(rec.find("held_at_rest")->find("exact_repeats")->asInt(), 1) << rec.dump(2);
  }
  fs::remove(f);
}

TEST(Inspect, RateIsExactToTheStampsResolutionAndJitterAndGapsAreMeasured) {
  // 250 Hz stamps in ms, one stamp 1 ms late, one sample lost
  std::vector<double> t;
  std::vector<int> row;
  for (int k = 0; k < 400; ++k) {
    if (k == 200) continue;  // lost: a gap of 8 ms
    t.push_back(4.0 * k + (k == 100 ? 1.0 : 0.0));
    row.push_back(static_cast<int>(row.size()));
  }
  const exid::Json J = exid::samplingStats(t, 1e-3, row, 1.5);
  EXPECT_EQ(J.find("rate_hz")->asDouble(), 250.0);
  EXPECT_DOUBLE_EQ(J.find("period_s")->asDouble(), 0.004);
  EXPECT_DOUBLE_EQ(J.find("jitter")->find("max_rel")->asDouble(), 1.0);  // the 8 ms step
  EXPECT_EQ(J.find("gaps")->find("count")->asInt(), 1);
  EXPECT_NEAR(J.find("gaps")->find("largest_s")->asDouble(), 0.008, 1e-12);
  EXPECT_NEAR(J.find("gaps")->find("at_s")->at(0).at(0).asDouble(), 0.796, 1e-12);
  EXPECT_EQ(exid::rateFromPeriod(0.0002), 5000.0);
  EXPECT_EQ(exid::rateFromPeriod(0.01), 100.0);
  EXPECT_NEAR(exid::rateFromPeriod(1.0 / 3.0), 3.0, 1e-12);
}

TEST(Inspect, PositionAndVelocityCoverageAgainstTheLimits) {
  auto r = puma();
  const exid::Dataset d = modelData(*r, 0.01, 6.0);
  const exid::Json J = inspect(r, d);
  for (int j = 0; j < 6; ++j) {
    const exid::Json& e = J.find("joints")->at(static_cast<std::size_t>(j));
    const auto& L = r->limits[static_cast<std::size_t>(j)];
    const double range = d.q.col(j).maxCoeff() - d.q.col(j).minCoeff();
    if (L.q_max < 1e299) {
      EXPECT_NEAR(e.find("position_coverage")->asDouble(), range / (L.q_max - L.q_min), 1e-12);
    } else {
      EXPECT_TRUE(e.find("position_coverage")->isNull());
      EXPECT_NE(e.find("limits")->asString().find("unknown"), std::string::npos);
    }
  }
}

TEST(Inspect, TheMedianWithoutHoldingTheValuesIsNthElementsValueBitForBit) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> N(0.0, 1.0);
  for (std::size_t n : {1u, 2u, 3u, 10u, 1001u, 40000u}) {
    for (int kind = 0; kind < 4; ++kind) {
      std::vector<double> v(n);
      for (std::size_t i = 0; i < n; ++i) {
        const double x = N(rng);
        // normal values of both signs; time steps of a 1 kHz log written with 3 decimals (many
        // equal, a few one ulp apart); a few distinct values; values equal but for the sign of 0
        v[i] = kind == 0   ? x
               : kind == 1 ? (std::round(1000.0 * (1.0 + i)) - std::round(1000.0 * i)) * 1e-3 +
                                 (i % 7 == 0 ? 1e-12 * x : 0.0)
               : kind == 2 ? static_cast<double>(static_cast<int>(3 * x))
                           : (i % 2 ? 0.0 : -0.0);
      }
      std::vector<double> s = v;
      std::nth_element(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(n / 2), s.end());
      const double m = exid::medianOfValues(n, [&](std::size_t i) { return v[i]; });
      EXPECT_EQ(m, s[n / 2]) << "n = " << n << ", kind " << kind;
      if (kind != 3) {
        EXPECT_EQ(std::signbit(m), std::signbit(s[n / 2]));
      }
    }
  }
  EXPECT_TRUE(std::isnan(exid::medianOfValues(0, [](std::size_t) { return 1.0; })));
}
