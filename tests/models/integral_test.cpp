// Observation model `integral` (energy model): on noise-free simulated data both short and long
// windows reproduce the measured work and recover the base parameters; the quadrature rules
// behave as documented; fullDesignVjp matches finite differences.
#include "model_test_util.hpp"

namespace {

// A fine sampling and tight integration: the rows are then exact to the quadrature error.
const char* kSim = "{rtol: 1e-12, atol: 1e-14, duration_s: 10, sample_period_s: 0.0025}";

exid::Dataset pumaData() {
  static exid::Dataset d = mtest::simulate(mtest::robot("puma560"), kSim);
  return d;
}

void check(const std::string& params, double rows_tol, double est_tol) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("integral", params, r);
  const mtest::Recovery rec = mtest::recover(*m, pumaData());
  mtest::print(("puma560 integral " + params).c_str(), rec);
  EXPECT_LT(rec.rows_rel, rows_tol) << params;
  EXPECT_LT(rec.est_rel, est_tol) << params;
}

TEST(Integral, ShortDisjointWindowsSimpsonExact) {
  check("{window: short, window_s: 0.1, overlap: disjoint, offset: true}", 1e-8, 1e-6);
}

TEST(Integral, ShortSlidingWindowsSimpsonExact) {
  check("{window: short, window_s: 0.5, overlap: sliding, offset: true}", 1e-8, 1e-6);
}

TEST(Integral, LongWindowsSimpsonExact) {
  check("{window: long, window_s: 0.1, overlap: disjoint, offset: true}", 1e-8, 1e-6);
}

TEST(Integral, LongSlidingWindowsSimpsonExact) {
  check("{window: long, window_s: 0.1, overlap: sliding, offset: true}", 1e-8, 1e-6);
}

TEST(Integral, PandaAndIrp6Exact) {
  // IRp-6: absolute angles for joints 2-4 (a coupled transmission) exercise the coordinate maps.
  for (const char* name : {"panda", "irp6"}) {
    auto r = mtest::robot(name);
    if (!r) continue;
    // 20 s without repetition (period 20 s, 10 harmonics), 1 kHz: the Panda's energy rows are
    // less well conditioned (cond(W) ~ 1e7), so the quadrature error must be smaller.
    const exid::Dataset d = mtest::simulate(r,
                                            "{rtol: 1e-12, atol: 1e-14, duration_s: 20, period_s: "
                                            "20, harmonics: 10, sample_period_s: 0.001}");
    auto m = mtest::model("integral", "{window: short, window_s: 0.05, offset: true}", r);
    const mtest::Recovery rec = mtest::recover(*m, d);
    mtest::print((std::string(name) + " integral short 0.05 s").c_str(), rec);
    EXPECT_LT(rec.rows_rel, 1e-8) << name;
    EXPECT_LT(rec.est_rel, 1e-6) << name;
  }
}

TEST(Integral, TrapezoidIsSecondOrder) {
  // Same data, trapezoid rule: the error of the work integral is O(dt^2) (printed); the estimate
  // is still close.
  check("{window: short, window_s: 0.1, quadrature: trapezoid, offset: true}", 1e-3, 1e-2);
}

TEST(Integral, FrictionSubtracted) {
  check("{friction: false, subtract_friction: true, window_s: 0.1}", 1e-8, 1e-6);
}

TEST(Integral, SameBaseParametersAsDifferential) {
  auto r = mtest::robot("puma560");
  auto mi = mtest::model("integral", "{offset: true}", r);
  auto md = mtest::model("differential", "{offset: true}", r);
  std::printf("base parameters: integral %d, differential %d\n", mi->numBase(), md->numBase());
  // Offsets enter the energy model as OFF_j (qm_j(t2) - qm_j(t1)); the rest matches.
  EXPECT_EQ(mi->numBase(), md->numBase());
}

TEST(Integral, WindowsAreCounted) {
  auto r = mtest::robot("puma560");
  exid::Dataset d = pumaData();  // 4001 samples over 10 s
  auto count = [&](const std::string& p) {
    return static_cast<int>(mtest::model("integral", p, r)->fullRows(d, mtest::context()).y.size());
  };
  EXPECT_EQ(count("{window: short, window_s: 0.5, overlap: disjoint}"), 20);
  EXPECT_EQ(count("{window: short, window_s: 0.5, overlap: sliding}"), 4001 - 200);
  EXPECT_EQ(count("{window: long, window_s: 0.5, overlap: disjoint}"), 20);
  EXPECT_EQ(count("{window: long, window_s: 0.5, overlap: sliding}"), 4001 - 200);
}

TEST(Integral, NeedsNoAcceleration) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("integral", "{}", r);
  exid::Dataset d = pumaData();
  d.qdd.resize(0, 0);
  EXPECT_NO_THROW(m->fullRows(d, mtest::context()));
  EXPECT_EQ(m->specs().required_signals, (std::vector<std::string>{"q", "qd", "tau"}));
  EXPECT_FALSE(m->specs().per_sample);
}

TEST(Integral, VjpMatchesFiniteDifferences) {
  for (const char* name : {"puma560", "irp6"}) {
    auto r = mtest::robot(name);
    if (!r) continue;
    for (const char* p : {"{window_s: 0.02, offset: true}",
                          "{window: long, window_s: 0.03, overlap: sliding, quadrature: trapezoid}",
                          "{window_s: 0.03, overlap: sliding, friction: false}"}) {
      auto m = mtest::model("integral", p, r);
      const double err = mtest::vjpError(*m, mtest::randomSamples(*r, 9, 0.01, 9), false);
      std::printf("[%s integral %s] VJP vs FD relative error %.2e\n", name, p, err);
      EXPECT_LT(err, 1e-6) << name << " " << p;
    }
  }
}

TEST(Integral, SimpsonIsExactForQuadraticsOnUnevenGrids) {
  // Work of a constant torque along q = t^3 / 3: power 2 t^2, integrated exactly by the
  // uneven-grid Simpson rule including the odd last interval.
  auto r = mtest::robot("puma560");
  auto m = mtest::model("integral",
                        "{window: long, window_s: 1.0, friction: false, rotor_inertia: false}", r);
  exid::Dataset d;
  const int K = 8;  // 7 intervals: odd, uneven
  d.t.resize(K);
  d.t << 0.0, 0.13, 0.3, 0.41, 0.66, 0.8, 0.93, 1.0;
  d.q = Eigen::MatrixXd::Zero(K, 6);
  d.qd = Eigen::MatrixXd::Zero(K, 6);
  d.tau = Eigen::MatrixXd::Zero(K, 6);
  for (int k = 0; k < K; ++k) {
    const double t = d.t[k];
    d.qd(k, 0) = t * t;  // quadratic velocity
    d.q(k, 0) = t * t * t / 3.0;
    d.tau(k, 0) = 2.0;  // power 2 t^2: quadratic
  }
  const exid::Rows rows = m->fullRows(d, mtest::context());
  ASSERT_EQ(rows.y.size(), 1);
  EXPECT_NEAR(rows.y[0], 2.0 / 3.0, 1e-12);
}

}  // namespace
