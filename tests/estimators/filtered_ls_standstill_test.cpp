// filtered_ls where the whole robot stands still (docs/estimators.md, "filtered_ls at a
// standstill"): the zero-phase position filter starts a motion a few samples early, so the last
// samples of a standstill carry small velocities whose Coulomb sign the torque at rest does not
// have, and at the standstill's end the robot may already move below the encoders' resolution.
// By default those samples' rows are dropped (counted); where the robot moves nothing changes.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "estimator_test_model.hpp"
#include "exid/error.hpp"
#include "exid_test.hpp"

namespace {

using est_test::makeModel;

std::shared_ptr<exid::Estimator> make(const std::string& params) {
  return exid_test::create<exid::Estimator>("filtered_ls", params);
}

double maxRelErr(const Eigen::VectorXd& a, const Eigen::VectorXd& truth) {
  return (a - truth).cwiseAbs().maxCoeff() / truth.cwiseAbs().maxCoeff();
}

/// rest_s at rest, then motion_s of a motion that leaves rest smoothly (q, qd, qdd continuous):
/// q_j = c_j + sum_h a_h (1 - cos(w_jh u))^2 / 4, u = max(0, t - rest_s). Torques of the model
/// from the exact derivatives; positions rounded to `quantum` (0: not) plus Gaussian q_noise;
/// no qd, qdd in the data (filtered_ls differentiates). `held` joints never move.
exid::Dataset restThenMotion(const est_test::PendulumModel& m, int n, double rest_s,
                             double motion_s, double dt, double quantum, double q_noise = 0.0,
                             std::vector<int> held = {}) {
  const int K = static_cast<int>(std::lround((rest_s + motion_s) / dt)) + 1;
  exid::Dataset d;
  d.t = Eigen::VectorXd::LinSpaced(K, 0.0, (K - 1) * dt);
  d.q.resize(K, n);
  d.tau.resize(K, n);
  const double a[3] = {0.6, 0.4, 0.25}, f[3] = {0.35, 0.8, 1.45};
  const Eigen::VectorXd pi = m.fullNominal();
  Eigen::RowVectorXd w(m.numFullCols());
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j) {
      const bool still = std::find(held.begin(), held.end(), j) != held.end();
      const double u = std::max(0.0, d.t(k) - rest_s);
      double q = 0.3 + 0.2 * j, qd = 0, qdd = 0;
      for (int h = 0; h < 3 && !still; ++h) {
        const double om = 2 * M_PI * f[h] * (1.0 + 0.17 * j), ph = om * u, c = std::cos(ph),
                     s = std::sin(ph);
        q += a[h] * (1 - c) * (1 - c) / 4;
        qd += a[h] * om * (1 - c) * s / 2;
        qdd += a[h] * om * om * (s * s + (1 - c) * c) / 2;
      }
      m.fullRow(j, q, qd, qdd, w);
      d.tau(k, j) = w.dot(pi);
      const double qn = q + q_noise * N(rng);
      d.q(k, j) = quantum > 0 ? std::round(qn / quantum) * quantum : qn;
    }
  d.source = "restThenMotion";
  return d;
}

/// The first sample at which some joint's position differs from its first sample's.
long firstTick(const exid::Dataset& d) {
  for (long k = 1; k < d.size(); ++k)
    if ((d.q.row(k).array() != d.q.row(0).array()).any()) return k;
  return d.size();
}

long standstillSamples(const exid::Estimate& e) {
  return e.details.find("standstill")->find("samples")->asInt();
}

}  // namespace

TEST(FilteredLsStandstill, RowsAtAStandstillAreDroppedCountedAndTheFitIsTheTruths) {
  auto m = makeModel(2);
  // 3 s at rest, 5 s of motion, 1 kHz, encoders of 1e-6 rad
  const exid::Dataset d = restThenMotion(*m, 2, 3.0, 5.0, 1e-3, 1e-6);
  exid::RunContext ctx;
  const exid::Estimate e = make("{cutoff_hz: 10}")->estimate(*m, d, nullptr, ctx);
  const exid::Json& st = *e.details.find("standstill");
  EXPECT_EQ(st.find("mode")->asString(), "drop");
  EXPECT_EQ(st.find("min_samples")->asInt(), 200);  // 2 / cutoff_hz at 1 kHz
  // every trimmed sample before the first encoder tick stands still, and no other
  const long trim = e.details.find("trimmed_samples_each_end")->asInt();
  const long tick = firstTick(d);
  ASSERT_GT(tick, 3000);
  EXPECT_EQ(standstillSamples(e), tick - trim);
  // the position filter's transient after it (2 / cutoff_hz) is its edge
  EXPECT_EQ(st.find("edge_samples")->asInt(), 200);
  // their decimated rows are removed, counted
  const long R = e.details.find("decimation")->asInt();
  const long removed = st.find("rows_removed")->asInt();
  EXPECT_NEAR(static_cast<double>(removed), static_cast<double>(tick - trim + 200) / R, 1.0);
  EXPECT_EQ(e.rows, 2 * ((d.size() - 2 * trim + R - 1) / R - removed));
  // noise-free data: as close to the parameters as the motion alone gives them
  const exid::Estimate only =
      make("{cutoff_hz: 10}")->estimate(*m, exid::sliceDataset(d, 3000, d.size()), nullptr, ctx);
  const double err = maxRelErr(e.value, m->baseNominal()),
               err_only = maxRelErr(only.value, m->baseNominal());
  EXPECT_LE(err, 1.5 * err_only);
  // As filtered, the standstill's last samples carry the filter's early start of the motion
  // with its Coulomb sign: the fit is off by far more.
  const exid::Estimate f =
      make("{cutoff_hz: 10, standstill: filter}")->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(f.details.find("standstill")->find("samples"), nullptr);
  const double err_filter = maxRelErr(f.value, m->baseNominal());
  EXPECT_GT(err_filter, 10 * err) << err;
  // zero_velocity keeps the rows at rest with qd = qdd = 0 (torque at rest: gravity and offset)
  const exid::Estimate z =
      make("{cutoff_hz: 10, standstill: zero_velocity}")->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(standstillSamples(z), tick - trim);
  EXPECT_EQ(z.details.find("standstill")->find("rows_removed"), nullptr);
  EXPECT_LT(maxRelErr(z.value, m->baseNominal()), err_filter);
  std::printf("max relative error: drop %.2e, zero_velocity %.2e, filter %.2e, motion alone %.2e\n",
              err, maxRelErr(z.value, m->baseNominal()), err_filter, err_only);
}

TEST(FilteredLsStandstill, NothingStandsStillWhereTheRobotMovesOrOnlySomeJointsStand) {
  auto m = makeModel(2);
  exid::RunContext ctx;
  // always moving: no standstill, the same bits as without the rule
  est_test::DataOptions o;
  o.samples = 6000;
  o.dt = 1e-3;
  o.derivatives = false;
  const exid::Dataset moving = est_test::makeData(*m, 2, o);
  const exid::Estimate a = make("{cutoff_hz: 10}")->estimate(*m, moving, nullptr, ctx);
  const exid::Estimate b =
      make("{cutoff_hz: 10, standstill: filter}")->estimate(*m, moving, nullptr, ctx);
  EXPECT_EQ(standstillSamples(a), 0);
  EXPECT_EQ(a.details.find("standstill")->find("rows_removed")->asInt(), 0);
  EXPECT_EQ(a.value, b.value);
  EXPECT_EQ(a.rows, b.rows);
  // joint 2 held for the whole recording while joint 1 moves after 1 s: only the first second
  // (both standing) stands still
  const exid::Dataset one = restThenMotion(*m, 2, 1.0, 5.0, 1e-3, 1e-6, 0.0, {1});
  const exid::Estimate c =
      make("{cutoff_hz: 10, standstill: zero_velocity}")->estimate(*m, one, nullptr, ctx);
  EXPECT_EQ(standstillSamples(c),
            firstTick(one) - c.details.find("trimmed_samples_each_end")->asInt());
  EXPECT_LT(firstTick(one), 1400);
}

TEST(FilteredLsStandstill, NoisyEncodersStandStillOnlyWithinATolerance) {
  auto m = makeModel(2);
  exid::RunContext ctx;
  const exid::Dataset d = restThenMotion(*m, 2, 3.0, 5.0, 1e-3, 0.0, 1e-4);
  // positions never repeat exactly: nothing stands still, and the rule says why
  const exid::Estimate e = make("{cutoff_hz: 10}")->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(standstillSamples(e), 0);
  EXPECT_EQ(e.details.find("standstill")->find("tolerance")->asString(), "exact repetition");
  // within 1e-3 rad (10 noise std): the rest, and the first instants of the motion while it
  // stays within the tolerance
  const exid::Estimate t =
      make("{cutoff_hz: 10, standstill_tolerance: [1e-3, 1e-3]}")->estimate(*m, d, nullptr, ctx);
  const long trim = t.details.find("trimmed_samples_each_end")->asInt();
  EXPECT_GE(standstillSamples(t), 3000 - trim);
  EXPECT_LE(standstillSamples(t), 3000 - trim + 300);
  // wrong sizes and values are named
  try {
    make("{standstill_tolerance: [1e-3]}")->estimate(*m, d, nullptr, ctx);
    ADD_FAILURE() << "one tolerance for two joints accepted";
  } catch (const exid::Error& x) {
    EXPECT_NE(std::string(x.what()).find("standstill_tolerance: expected 2 values"),
              std::string::npos)
        << x.what();
  }
}

TEST(FilteredLsStandstill, ARecordingThatNeverMovesIsRefusedByDropNamingTheAlternative) {
  auto m = makeModel(1);
  exid::RunContext ctx;
  const exid::Dataset d = restThenMotion(*m, 1, 4.0, 0.0, 1e-3, 1e-6);
  try {
    make("{cutoff_hz: 10}")->estimate(*m, d, nullptr, ctx);
    ADD_FAILURE() << "a recording at rest gave an estimate with every row dropped";
  } catch (const exid::Error& x) {
    const std::string w = x.what();
    EXPECT_NE(w.find("no rows left"), std::string::npos) << w;
    EXPECT_NE(w.find("zero_velocity keeps them"), std::string::npos) << w;
  }
}

TEST(FilteredLsStandstill, ChunksDecideAsTheWholeRecording) {
  auto m = makeModel(2);
  exid::RunContext ctx;
  const exid::Dataset d = restThenMotion(*m, 2, 3.0, 27.0, 1e-3, 1e-6);
  const exid::Estimate whole =
      make("{cutoff_hz: 10, chunk_samples: 100000000, threads: 1}")->estimate(*m, d, nullptr, ctx);
  const exid::Estimate small =
      make("{cutoff_hz: 10, chunk_samples: 64, threads: 2}")->estimate(*m, d, nullptr, ctx);
  ASSERT_GT(small.details.find("chunks")->asInt(), 3);
  EXPECT_EQ(standstillSamples(small), standstillSamples(whole));
  EXPECT_EQ(small.rows, whole.rows);
  for (Eigen::Index i = 0; i < whole.value.size(); ++i)
    EXPECT_NEAR(small.value(i), whole.value(i), 1e-9 * (1.0 + std::abs(whole.value(i))));
}
