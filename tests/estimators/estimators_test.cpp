// Estimator plugins (batch_ls, rls, wls, filtered_ls) on a test model with known columns.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "estimator_test_model.hpp"
#include "exid/context.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid_test.hpp"

namespace {

using est_test::DataOptions;
using est_test::makeData;
using est_test::makeModel;

std::shared_ptr<exid::Estimator> make(const std::string& name, const std::string& params = "{}") {
  return exid_test::create<exid::Estimator>(name, params);
}

double maxRelErr(const Eigen::VectorXd& a, const Eigen::VectorXd& truth) {
  return (a - truth).cwiseAbs().maxCoeff() / truth.cwiseAbs().maxCoeff();
}

void expectFilled(const exid::Estimate& e, const exid::ObservationModel& m) {
  const int p = m.numBase();
  ASSERT_EQ(e.value.size(), p);
  EXPECT_EQ(e.names, m.base().names);
  EXPECT_EQ(e.expressions, m.base().expressions);
  EXPECT_EQ(e.std.size(), p);
  EXPECT_EQ(e.covariance.rows(), p);
  EXPECT_EQ(e.covariance.cols(), p);
  EXPECT_GT(e.rows, p);
  EXPECT_GT(e.cond_W, 1.0);
  const exid::Json* t = e.details.find("parameters");
  ASSERT_NE(t, nullptr);
  ASSERT_EQ(t->size(), static_cast<std::size_t>(p));
  EXPECT_TRUE(t->at(0).contains("rel_std_percent"));
  EXPECT_TRUE((e.covariance - e.covariance.transpose()).cwiseAbs().maxCoeff() <=
              1e-12 * e.covariance.cwiseAbs().maxCoeff());
}

TEST(Estimators, BaseNamesRegroupRotorInertia) {
  auto m = makeModel(1);
  EXPECT_EQ(m->numBase(), 6);  // ZZ1 and Ia1 regrouped
  bool regrouped = false;
  for (const auto& x : m->base().expressions)
    regrouped |= x.find("Ia1") != std::string::npos && x.find("ZZ1") != std::string::npos;
  EXPECT_TRUE(regrouped);
}

TEST(Estimators, NoiseFreeAllReturnTruth) {
  const int n = 2;
  auto m = makeModel(n);
  DataOptions o;
  exid::Dataset d = makeData(*m, n, o);
  const Eigen::VectorXd truth = m->baseNominal();
  exid::RunContext ctx;
  for (const std::string name : {"batch_ls", "wls"}) {
    exid::Estimate e = make(name)->estimate(*m, d, nullptr, ctx);
    expectFilled(e, *m);
    EXPECT_LE(maxRelErr(e.value, truth), 1e-8) << name;
    EXPECT_LE(e.residual_rms, 1e-8) << name;
  }
  // filtered_ls with the position filter off: the parallel decimation filters W and y alike, so
  // noise-free linear data stay exact.
  exid::Estimate f =
      make("filtered_ls", "{cutoff_hz: 0, decimation: 5}")->estimate(*m, d, nullptr, ctx);
  expectFilled(f, *m);
  EXPECT_LE(maxRelErr(f.value, truth), 1e-8);
  EXPECT_EQ(f.details.find("decimation")->asInt(), 5);
  // rls: the prior P0 = p0 I pulls by ~ (W^T W)^-1 theta / p0.
  exid::Estimate r = make("rls", "{p0: 1e8}")->estimate(*m, d, nullptr, ctx);
  expectFilled(r, *m);
  EXPECT_LE(maxRelErr(r.value, truth), 1e-8);
}

TEST(Estimators, BatchLsChunkingAndAccumulationAgree) {
  const int n = 2;
  auto m = makeModel(n);
  DataOptions o;
  o.tau_noise = {0.05, 0.05};
  exid::Dataset d = makeData(*m, n, o);
  exid::RunContext ctx;
  exid::Estimate a = make("batch_ls", "{chunk_samples: 7}")->estimate(*m, d, nullptr, ctx);
  exid::Estimate b = make("batch_ls", "{chunk_samples: 100000}")->estimate(*m, d, nullptr, ctx);
  exid::Estimate c = make("batch_ls", "{accumulate: normal}")->estimate(*m, d, nullptr, ctx);
  EXPECT_LE(maxRelErr(a.value, b.value), 1e-11);
  EXPECT_LE(maxRelErr(a.std, b.std), 1e-9);
  EXPECT_LE(maxRelErr(c.value, b.value), 1e-8);
  EXPECT_NEAR(a.sigma, 0.05, 0.005);
  // Direct dense solution for reference.
  exid::Rows r = m->rows(d, ctx);
  Eigen::VectorXd ref = r.W.colPivHouseholderQr().solve(r.y);
  EXPECT_LE(maxRelErr(a.value, ref), 1e-11);
  Eigen::MatrixXd cov = a.sigma * a.sigma * (r.W.transpose() * r.W).inverse();
  EXPECT_LE((cov - a.covariance).cwiseAbs().maxCoeff(), 1e-8 * cov.cwiseAbs().maxCoeff());
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(r.W);
  EXPECT_NEAR(a.cond_W, svd.singularValues()(0) / svd.singularValues()(m->numBase() - 1),
              1e-8 * a.cond_W);
}

TEST(Estimators, BatchLsAutoAccumulationPicksNormalOnlyWhenWellConditioned) {
  const int n = 2;
  auto m = makeModel(n);
  DataOptions o;
  o.tau_noise = {0.05, 0.05};
  exid::Dataset d = makeData(*m, n, o);
  exid::RunContext ctx;
  const exid::Estimate q = make("batch_ls", "{accumulate: qr}")->estimate(*m, d, nullptr, ctx);
  const exid::Estimate a = make("batch_ls")->estimate(*m, d, nullptr, ctx);
  const exid::Json& ca = *a.details.find("accumulate");
  EXPECT_EQ(ca.find("requested")->asString(), "auto");
  const double kappa = ca.find("cond_W_scaled_from_gram")->asDouble();
  // The Gram matrix's estimate of the scaled condition number is the QR's one.
  EXPECT_NEAR(kappa, q.details.find("cond_W_scaled")->asDouble(), 1e-6 * kappa);
  ASSERT_LT(kappa, 1e3);
  EXPECT_EQ(ca.find("used")->asString(), "normal");
  EXPECT_LE(maxRelErr(a.value, q.value), 1e-10);
  EXPECT_LE(maxRelErr(a.std, q.std), 1e-8);
  // Above the threshold the data are folded again by QR: the result is the QR's, bit for bit.
  const exid::Estimate b = make("batch_ls", fmt::format("{{normal_max_cond: {}}}", 0.5 * kappa))
                               ->estimate(*m, d, nullptr, ctx);
  const exid::Json& cb = *b.details.find("accumulate");
  EXPECT_EQ(cb.find("used")->asString(), "qr");
  EXPECT_NE(cb.find("reason")->asString().find("folded again by Householder QR"),
            std::string::npos);
  EXPECT_EQ(maxRelErr(b.value, q.value), 0.0);
  EXPECT_EQ(make("batch_ls", "{accumulate: normal}")
                ->estimate(*m, d, nullptr, ctx)
                .details.find("accumulate")
                ->find("used")
                ->asString(),
            "normal");
}

TEST(Estimators, StreamedInChunksWhatEverTheDatasetSize) {
  auto m = makeModel(2);
  DataOptions o;
  o.samples = 20000;
  o.tau_noise = {0.1, 0.1};
  exid::Dataset d = makeData(*m, 2, o);
  exid::RunContext ctx;
  for (const std::string name : {"batch_ls", "rls", "wls"}) {
    m->max_samples_per_call = 0;
    exid::Estimate e = make(name, "{chunk_samples: 500}")->estimate(*m, d, nullptr, ctx);
    EXPECT_EQ(m->max_samples_per_call.load(), 500)
        << name;  // rows never materialised for all samples
    EXPECT_EQ(e.rows, 40000) << name;
  }
  // A model that does not declare per-sample rows gets the whole dataset at once.
  struct Windowed : est_test::PendulumModel {
    using PendulumModel::PendulumModel;
    exid::ModelSpecs specs() const override { return {}; }
  };
  auto w = std::make_shared<Windowed>(2);
  w->bind(est_test::makeRobot(2), ctx);
  make("batch_ls", "{chunk_samples: 500}")->estimate(*w, d, nullptr, ctx);
  EXPECT_EQ(w->max_samples_per_call.load(), 20000);
}

TEST(Estimators, BatchLsRefusesRankDeficientNamingDirections) {
  auto m = makeModel(1);
  DataOptions o;
  o.qd_offset = 10.0;  // the joint never reverses: sign(qd) = 1 = the offset's column
  o.tau_noise = {0.01};
  exid::Dataset d = makeData(*m, 1, o);
  exid::RunContext ctx;
  for (const std::string name : {"batch_ls", "wls", "filtered_ls"}) {
    try {
      make(name, name == "filtered_ls" ? "{cutoff_hz: 0}" : "{}")->estimate(*m, d, nullptr, ctx);
      ADD_FAILURE() << name << " accepted a rank-deficient problem";
    } catch (const exid::Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("Fc1"), std::string::npos) << msg;
      EXPECT_NE(msg.find("OFF1"), std::string::npos) << msg;
      EXPECT_NE(msg.find("rank 5 of 6"), std::string::npos) << msg;
      EXPECT_EQ(msg.find("MX1"), std::string::npos) << msg;
    }
  }
}

TEST(Estimators, RlsConvergesToBatchLs) {
  const int n = 2;
  auto m = makeModel(n);
  DataOptions o;
  o.tau_noise = {0.1, 0.1};
  exid::Dataset d = makeData(*m, n, o);
  exid::RunContext ctx;
  exid::Estimate b = make("batch_ls")->estimate(*m, d, nullptr, ctx);
  for (const std::string upd : {"joseph", "standard"}) {
    exid::Estimate r = make("rls", "{p0: 1e8, update: " + upd + "}")->estimate(*m, d, nullptr, ctx);
    EXPECT_LE(((r.value - b.value).cwiseQuotient(b.std)).cwiseAbs().maxCoeff(), 1e-4) << upd;
    EXPECT_LE(maxRelErr(r.std, b.std), 1e-3) << upd;
    EXPECT_NEAR(r.residual_rms, b.residual_rms, 1e-6 * b.residual_rms) << upd;
    EXPECT_NEAR(r.cond_W / b.cond_W, 1.0, 1e-3) << upd;
    // History: every sample, time stamps, final value, diag(P) shrinking.
    ASSERT_EQ(r.history_t.size(), d.size());
    EXPECT_DOUBLE_EQ(r.history_t(d.size() - 1), d.t(d.size() - 1));
    EXPECT_LE((r.history_value.row(d.size() - 1).transpose() - r.value).norm(),
              1e-12 * r.value.norm());
    EXPECT_LT(r.history_pdiag(d.size() - 1, 0), 1e-3 * r.history_pdiag(0, 0));
    EXPECT_EQ(r.history_pdiag.cols(), m->numBase());
  }
  // The default p0 = 1e6 is close too (bias ~ (W^T W)^-1 theta / p0).
  exid::Estimate r6 = make("rls")->estimate(*m, d, nullptr, ctx);
  EXPECT_LE(((r6.value - b.value).cwiseQuotient(b.std)).cwiseAbs().maxCoeff(), 1e-2);
}

TEST(Estimators, RlsHistoryStride) {
  auto m = makeModel(1);
  DataOptions o;
  o.samples = 1001;
  exid::Dataset d = makeData(*m, 1, o);
  exid::RunContext ctx;
  exid::Estimate r = make("rls", "{history_stride: 100}")->estimate(*m, d, nullptr, ctx);
  ASSERT_EQ(r.history_t.size(), 11);  // samples 0, 100, ..., 1000
  EXPECT_DOUBLE_EQ(r.history_t(1), d.t(100));
  exid::Estimate r2 = make("rls", "{history_stride: 300}")->estimate(*m, d, nullptr, ctx);
  ASSERT_EQ(r2.history_t.size(), 5);  // 0, 300, 600, 900 and the last
  EXPECT_DOUBLE_EQ(r2.history_t(4), d.t(1000));
}

TEST(Estimators, RlsForgettingTracksAChange) {
  auto m = makeModel(1);
  DataOptions o;
  o.samples = 3000;
  o.tau_noise = {0.01};
  exid::Dataset d1 = makeData(*m, 1, o);
  Eigen::VectorXd pi2 = m->fullNominal();
  pi2(1) *= 1.5;  // MX1 changes (a payload)
  o.pi = pi2;
  o.t0 = d1.t(o.samples - 1) + o.dt;
  exid::Dataset d2 = makeData(*m, 1, o);
  exid::Dataset d = d1;
  d.t.resize(2 * o.samples);
  d.t << d1.t, d2.t;
  auto stack = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    Eigen::MatrixXd s(a.rows() + b.rows(), a.cols());
    s << a, b;
    return s;
  };
  d.q = stack(d1.q, d2.q);
  d.qd = stack(d1.qd, d2.qd);
  d.qdd = stack(d1.qdd, d2.qdd);
  d.tau = stack(d1.tau, d2.tau);
  exid::RunContext ctx;
  const Eigen::VectorXd truth2 = m->base().reduce(pi2);
  exid::Estimate forget = make("rls", "{forgetting_factor: 0.995, history_stride: 1000}")
                              ->estimate(*m, d, nullptr, ctx);
  exid::Estimate plain = make("rls")->estimate(*m, d, nullptr, ctx);
  EXPECT_LT(maxRelErr(forget.value, truth2), 0.01);
  EXPECT_GT(maxRelErr(plain.value, truth2), 0.1);
  EXPECT_EQ(forget.details.find("rss_method")->asString().rfind("second pass", 0), 0u);
}

// rls's Kalman filter (random_walk_std): parameters drawn as the random walk it assumes, and
// rows y_k = W_k theta_k + noise. Its final estimate is then within its own covariance of the
// final parameters (Monte Carlo: mean z^2 ~ 1), where least squares on the same data is not.
// Without drift it is rls exactly; the settings it needs are asked for.
TEST(Estimators, RlsKalmanTracksARandomWalkWithinItsCovariance) {
  const int n = 2;
  auto m = makeModel(n);
  const int p = m->numBase();
  const double noise = 0.02, walk = 0.05;  // [N m], [parameter unit / sqrt(s)]
  exid::RunContext ctx;
  double z2_kalman = 0, z2_ls = 0;
  int within2 = 0, count = 0;
  for (std::uint64_t seed = 1; seed <= 30; ++seed) {
    DataOptions o;
    o.samples = 1500;
    o.seed = seed;
    exid::Dataset d = makeData(*m, n, o);
    const exid::Rows rows = m->rows(d, ctx);  // W_k (noise-free data: y unused)
    std::mt19937_64 rng(1000 + seed);
    std::normal_distribution<double> N01;
    Eigen::VectorXd theta = m->baseNominal();
    for (int k = 0; k < d.size(); ++k) {
      if (k > 0)
        for (int i = 0; i < p; ++i) theta[i] += walk * std::sqrt(d.t[k] - d.t[k - 1]) * N01(rng);
      for (int j = 0; j < n; ++j) d.tau(k, j) = rows.W.row(k * n + j).dot(theta) + noise * N01(rng);
    }
    exid::Estimate kf =
        make("rls", fmt::format("{{noise_std: {}, random_walk_std: [{}], history_stride: 500}}",
                                noise, walk))
            ->estimate(*m, d, nullptr, ctx);
    exid::Estimate ls = make("rls", "{history_stride: 500}")->estimate(*m, d, nullptr, ctx);
    ASSERT_EQ(kf.details.find("filter")->asString().rfind("kalman", 0), 0u);
    for (int i = 0; i < p; ++i) {
      const double z = (kf.value[i] - theta[i]) / kf.std[i];
      z2_kalman += z * z;
      within2 += std::abs(z) <= 2.0;
      const double zl = (ls.value[i] - theta[i]) / ls.std[i];
      z2_ls += zl * zl;
      ++count;
    }
  }
  z2_kalman /= count;
  z2_ls /= count;
  RecordProperty("mean_z2_kalman", std::to_string(z2_kalman));
  RecordProperty("mean_z2_least_squares", std::to_string(z2_ls));
  RecordProperty("within_2_std", std::to_string(within2) + " of " + std::to_string(count));
  EXPECT_GT(z2_kalman, 0.7);
  EXPECT_LT(z2_kalman, 1.4);
  EXPECT_GE(within2, static_cast<int>(0.9 * count));
  EXPECT_GT(z2_ls, 5.0);  // least squares averages the walk: far outside its own std

  // No drift: rls itself (the same rows, the same updates); the covariance from noise_std.
  DataOptions o;
  o.tau_noise = {0.02, 0.02};
  exid::Dataset d = makeData(*m, n, o);
  exid::Estimate still =
      make("rls", "{noise_std: 0.02, random_walk_std: [0]}")->estimate(*m, d, nullptr, ctx);
  exid::Estimate plain = make("rls")->estimate(*m, d, nullptr, ctx);
  EXPECT_LE((still.value - plain.value).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(still.sigma, 0.02, 1e-15);
  // what it needs, asked for
  EXPECT_THROW(make("rls", "{random_walk_std: [0.1]}"), exid::Error);  // no noise_std
  EXPECT_THROW(make("rls", "{noise_std: 0.1, random_walk_std: [0.1], forgetting_factor: 0.99}"),
               exid::Error);
  EXPECT_THROW(
      make("rls", "{noise_std: 0.1, random_walk_std: [0.1, 0.2]}")->estimate(*m, d, nullptr, ctx),
      exid::Error);  // neither 1 nor p values
}

TEST(Estimators, RlsPriorSeedsThetaAndP) {
  auto m = makeModel(1);
  DataOptions o;
  o.samples = 50;
  o.tau_noise = {0.1};
  exid::Dataset d = makeData(*m, 1, o);
  exid::RunContext ctx;
  const int p = m->numBase();
  exid::Prior prior;
  prior.value = m->baseNominal();
  prior.covariance = 1e-12 * Eigen::MatrixXd::Identity(p, p);
  auto rls = make("rls", "{noise_std: 0.1}");
  EXPECT_TRUE(rls->specs().accepts_prior);
  EXPECT_TRUE(rls->specs().recursive);
  exid::Estimate r = rls->estimate(*m, d, &prior, ctx);
  EXPECT_LE(maxRelErr(r.value, prior.value), 1e-6);  // a very confident prior dominates
  EXPECT_LE(maxRelErr(r.history_value.row(0).transpose(), prior.value), 1e-6);
  exid::Prior bad;
  bad.value = Eigen::VectorXd::Zero(p - 1);
  bad.covariance = Eigen::MatrixXd::Identity(p - 1, p - 1);
  EXPECT_THROW(rls->estimate(*m, d, &bad, ctx), exid::Error);
}

TEST(Estimators, WlsWeightsPerEquationAndReportsOls) {
  const int n = 2;
  auto m = makeModel(n);
  DataOptions o;
  o.tau_noise = {0.02, 0.5};
  exid::Dataset d = makeData(*m, n, o);
  exid::RunContext ctx;
  exid::Estimate w = make("wls")->estimate(*m, d, nullptr, ctx);
  exid::Estimate b = make("batch_ls")->estimate(*m, d, nullptr, ctx);
  expectFilled(w, *m);
  const exid::Json* eqs = w.details.find("equations");
  ASSERT_NE(eqs, nullptr);
  ASSERT_EQ(eqs->size(), 2u);
  const double s0 = eqs->at(0).find("residual_std")->asDouble(),
               s1 = eqs->at(1).find("residual_std")->asDouble();
  EXPECT_NEAR(s0, 0.02, 0.01);  // OLS residuals spread the noise a little
  EXPECT_NEAR(s1, 0.5, 0.05);
  EXPECT_NEAR(eqs->at(0).find("weight")->asDouble() * s0, 1.0, 1e-12);
  EXPECT_EQ(eqs->at(0).find("parameters_in_equation")->asInt(), m->numBase() - 1);  // OFF2 absent
  // One Gautier pass: sigma_0 from OLS residuals is inflated by the OLS misfit, so the weighted
  // residuals have a variance a little under 1; iterating the weights brings it to 1.
  EXPECT_GT(w.sigma, 0.6);
  EXPECT_LT(w.sigma, 1.1);
  exid::Estimate w3 = make("wls", "{iterations: 4}")->estimate(*m, d, nullptr, ctx);
  EXPECT_NEAR(w3.sigma, 1.0, 0.05);
  EXPECT_NEAR(w3.details.find("equations")->at(0).find("residual_std")->asDouble(), 0.02, 0.002);
  // Reported precision of the shared parameters is better than OLS's.
  for (int i = 0; i < 5; ++i)
    EXPECT_LT(w.std(i), 0.5 * b.std(i)) << w.names[static_cast<std::size_t>(i)];
  EXPECT_TRUE(w.details.contains("ols"));
}

TEST(Estimators, FilteredLsRecoversFromNoisyPositionsWithinItsSigma) {
  auto m = makeModel(1);
  DataOptions o;
  o.samples = 20000;
  o.dt = 0.001;  // 1 kHz, 20 s
  o.q_noise = 1e-4;
  o.tau_noise = {0.02};
  o.derivatives = false;  // only q and tau recorded
  exid::Dataset d = makeData(*m, 1, o);
  exid::RunContext ctx;
  auto f = make("filtered_ls", "{cutoff_hz: 10, filter_order: 4}");
  EXPECT_TRUE(f->specs().needs_raw_dataset);
  exid::Estimate e = f->estimate(*m, d, nullptr, ctx);
  expectFilled(e, *m);
  const Eigen::VectorXd truth = m->baseNominal();
  for (int i = 0; i < m->numBase(); ++i)
    EXPECT_LE(std::abs(e.value(i) - truth(i)), 3.0 * e.std(i))
        << e.names[static_cast<std::size_t>(i)] << " " << e.value(i) << " vs " << truth(i)
        << " std " << e.std(i);
  EXPECT_EQ(e.details.find("decimation")->asInt(), 20);  // auto: floor(0.2 * 1000 / 10)
  EXPECT_LT(e.details.find("parameters")->at(1).find("rel_std_percent")->asDouble(), 5.0);
  // Without filtering, differentiating noisy positions destroys the accelerations.
  exid::Estimate raw =
      make("filtered_ls", "{cutoff_hz: 0, decimation: 1}")->estimate(*m, d, nullptr, ctx);
  EXPECT_GT(std::abs(raw.value(0) - truth(0)), 10 * std::abs(e.value(0) - truth(0)));
}

TEST(Estimators, FilteredLsNoiseFreeWithFilterIsClose) {
  auto m = makeModel(2);
  DataOptions o;
  o.samples = 10000;
  o.dt = 0.001;
  o.derivatives = false;
  exid::Dataset d = makeData(*m, 2, o);
  exid::RunContext ctx;
  exid::Estimate e = make("filtered_ls", "{cutoff_hz: 20}")->estimate(*m, d, nullptr, ctx);
  EXPECT_LE(maxRelErr(e.value, m->baseNominal()), 1e-3);
}

TEST(Estimators, StopRequestIsHonoured) {
  auto m = makeModel(1);
  exid::Dataset d = makeData(*m, 1, DataOptions{});
  exid::RunContext ctx;
  ctx.cancelled = [] { return true; };
  for (const std::string name : {"batch_ls", "rls", "wls", "filtered_ls"})
    EXPECT_THROW(make(name)->estimate(*m, d, nullptr, ctx), exid::Error) << name;
}

TEST(Estimators, ProgressIsReported) {
  auto m = makeModel(1);
  DataOptions o;
  o.samples = 10000;
  exid::Dataset d = makeData(*m, 1, o);
  exid::RunContext ctx;
  std::vector<double> seen;
  ctx.progress = [&](double f, const std::string&) { seen.push_back(f); };
  make("batch_ls", "{chunk_samples: 1000}")->estimate(*m, d, nullptr, ctx);
  ASSERT_GE(seen.size(), 10u);
  EXPECT_DOUBLE_EQ(seen.back(), 1.0);
  for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_GE(seen[i], seen[i - 1]);
}

}  // namespace

TEST(Estimators, FilteredLsDefaultTrimIsCappedAndMinSpeedRemovesSlowSamples) {
  auto m = makeModel(1);
  DataOptions o;
  o.samples = 2000;
  o.dt = 0.001;  // 2 s at 1 kHz
  o.derivatives = false;
  const exid::Dataset d = makeData(*m, 1, o);
  exid::RunContext ctx;
  // A 2 Hz cut-off has an edge transient of 2 fs / fc = 1000 samples: half the recording at
  // each end. The default trims 5 % of it at each end instead, and says why.
  exid::Estimate e =
      make("filtered_ls", "{cutoff_hz: 2, decimation: 1}")->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(e.details.find("trimmed_samples_each_end")->asInt(), 100);
  EXPECT_NE(e.details.find("trim_rule")->asString().find("= 1000 samples capped at 5 %"),
            std::string::npos);
  EXPECT_EQ(e.details.find("warnings"), nullptr);
  // An explicit trim above 10 % is a warning.
  e = make("filtered_ls", "{cutoff_hz: 2, decimation: 1, trim_edges: 300}")
          ->estimate(*m, d, nullptr, ctx);
  ASSERT_NE(e.details.find("warnings"), nullptr);
  EXPECT_NE(e.details.find("warnings")->at(0).asString().find("600 of the 2000 samples"),
            std::string::npos);
  // min_speed: the decimated samples whose speed is below it are removed (counted), and
  // noise-free data still give the parameters.
  const exid::Dataset l = makeData(*m, 1, [] {
    DataOptions x;
    x.samples = 10000;
    x.dt = 0.001;
    x.derivatives = false;
    return x;
  }());
  e = make("filtered_ls", "{cutoff_hz: 20, decimation: 10, min_speed: [0.3]}")
          ->estimate(*m, l, nullptr, ctx);
  long slow = 0, total = 0;
  const exid::Dataset truth = makeData(*m, 1, [] {
    DataOptions x;
    x.samples = 10000;
    x.dt = 0.001;
    return x;
  }());
  for (int k = 100; k < 9900; k += 10, ++total) slow += std::abs(truth.qd(k, 0)) < 0.3;
  ASSERT_GT(slow, 20);
  EXPECT_NEAR(static_cast<double>(e.details.find("slow_samples_removed")->asInt()),
              static_cast<double>(slow), 3.0);
  EXPECT_EQ(e.rows, total - e.details.find("slow_samples_removed")->asInt());
  EXPECT_LE(maxRelErr(e.value, m->baseNominal()), 1e-3);
}

namespace {

// 30 s of raw two-joint data at 1 kHz (q and tau noisy, no qd, qdd): filtered_ls's tests.
exid::Dataset filteredLsData(const est_test::PendulumModel& m) {
  DataOptions o;
  o.samples = 30000;
  o.dt = 0.001;
  o.q_noise = 1e-5;
  o.tau_noise = {0.02, 0.02};
  o.derivatives = false;
  return makeData(m, 2, o);
}

}  // namespace

TEST(Estimators, FilteredLsInChunksEqualsTheWholeRecordingAndAnyThreadCountGivesTheSameBits) {
  auto m = makeModel(2);
  const exid::Dataset d = filteredLsData(*m);
  exid::RunContext ctx;
  // one chunk holding the whole recording: the reference
  const exid::Estimate whole =
      make("filtered_ls", "{cutoff_hz: 10, chunk_samples: 100000000, threads: 1}")
          ->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(whole.details.find("chunks")->asInt(), 1);
  // small chunks (the settling margin sets the floor: 8 margins), 1 and 3 threads: each chunk's
  // positions filtered and differentiated from its own samples and margins, its rows decimated
  // with the decimation filter's margins
  const exid::Estimate c1 = make("filtered_ls", "{cutoff_hz: 10, chunk_samples: 64, threads: 1}")
                                ->estimate(*m, d, nullptr, ctx);
  const exid::Estimate c3 = make("filtered_ls", "{cutoff_hz: 10, chunk_samples: 64, threads: 3}")
                                ->estimate(*m, d, nullptr, ctx);
  const long C = c1.details.find("chunk_samples")->asInt();
  EXPECT_LT(C, 10000);  // several chunks, of equal sizes (the last one at most R shorter)
  const long chunks = c1.details.find("chunks")->asInt();
  EXPECT_GT(chunks, 3);
  const long Kt = 30000 - 2 * c1.details.find("trimmed_samples_each_end")->asInt();
  EXPECT_GT(Kt - (chunks - 1) * C, C - c1.details.find("decimation")->asInt() * chunks);
  EXPECT_EQ(c1.details.find("threads")->asInt(), 1);
  EXPECT_EQ(c3.details.find("threads")->asInt(), 3);
  EXPECT_EQ(c1.rows, whole.rows);
  for (Eigen::Index i = 0; i < whole.value.size(); ++i) {
    EXPECT_NEAR(c1.value(i), whole.value(i), 1e-9 * (1.0 + std::abs(whole.value(i))));
    EXPECT_NEAR(c1.std(i), whole.std(i), 1e-6 * whole.std(i));
  }
  EXPECT_EQ(c1.value, c3.value);  // bit for bit
  EXPECT_EQ(c1.std, c3.std);
}

TEST(Estimators, FilteredLsColumnBlocksKeepTheBufferWithinItsBudgetAndTheSameBits) {
  // a chunk's rows filtered a block of columns at a time (chunk_memory_mb): the same numbers,
  // bit for bit, as one block; the buffer within the budget
  auto m = makeModel(2);
  const exid::Dataset d = filteredLsData(*m);
  exid::RunContext ctx;
  const exid::Estimate one =
      make("filtered_ls", "{cutoff_hz: 10, chunk_samples: 64, threads: 1, chunk_memory_mb: 1e4}")
          ->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(one.details.find("column_blocks")->asInt(), 1);
  const double whole_mb = one.details.find("chunk_buffer_mb")->asDouble();
  const long C = one.details.find("chunk_samples")->asInt(),
             margin = one.details.find("chunk_margin_samples")->asInt();
  // one row per sample of the chunk and its margins, (p + 1) columns per equation (2 joints)
  EXPECT_NEAR(whole_mb, 8.0 * static_cast<double>(C + 2 * margin) * 2 * (m->numBase() + 1) / 1e6,
              1e-9);
  for (const char* th : {"1", "2"}) {
    const double budget = whole_mb / 3.5;
    const exid::Estimate b =
        make("filtered_ls", fmt::format("{{cutoff_hz: 10, chunk_samples: 64, threads: {}, "
                                        "chunk_memory_mb: {}}}",
                                        th, budget))
            ->estimate(*m, d, nullptr, ctx);
    EXPECT_EQ(b.details.find("column_blocks")->asInt(), 4) << th;
    EXPECT_LE(b.details.find("chunk_buffer_mb")->asDouble(), budget) << th;
    EXPECT_EQ(b.rows, one.rows);
    EXPECT_EQ(b.value, one.value) << th;  // bit for bit
    EXPECT_EQ(b.std, one.std) << th;
  }
  // without decimation nothing is filtered: one block, whatever the budget
  const exid::Estimate nodec =
      make("filtered_ls", "{cutoff_hz: 10, decimation: 1, threads: 1, chunk_memory_mb: 0.01}")
          ->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(nodec.details.find("column_blocks")->asInt(), 1);
}

TEST(Estimators, FilteredLsChoosesItsThreadsFromTheWork) {
  // threads: 0 gives a thread per 4 chunks at least: a recording of 2 chunks runs on 1 thread
  auto m = makeModel(2);
  const exid::Dataset d = filteredLsData(*m);
  exid::RunContext ctx;
  const exid::Estimate few =
      make("filtered_ls", "{cutoff_hz: 10, chunk_samples: 15000}")->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(few.details.find("chunks")->asInt(), 2);
  EXPECT_EQ(few.details.find("threads")->asInt(), 1);
  EXPECT_NE(few.details.find("threads_from")->asString().find("the work"), std::string::npos);
  const exid::Estimate many =
      make("filtered_ls", "{cutoff_hz: 40, chunk_samples: 64}")->estimate(*m, d, nullptr, ctx);
  const long chunks = many.details.find("chunks")->asInt();
  ASSERT_GE(chunks, 8);
  EXPECT_EQ(many.details.find("threads")->asInt(),
            std::max(1L, std::min<long>(exid::resolveThreads(0), chunks / 4)));
  // a count the study gives is kept
  const exid::Estimate given = make("filtered_ls",
                                    "{cutoff_hz: 10, chunk_samples: 15000, "
                                    "threads: 2}")
                                   ->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(given.details.find("threads")->asInt(), 2);
  EXPECT_EQ(given.value, few.value);
}

TEST(Estimators, BatchLsGivesTheSameBitsForAnyThreadCount) {
  auto m = makeModel(2);
  DataOptions o;
  o.samples = 50000;
  o.tau_noise = {0.05, 0.05};
  const exid::Dataset d = makeData(*m, 2, o);
  exid::RunContext ctx;
  const exid::Estimate a = make("batch_ls", "{threads: 1}")->estimate(*m, d, nullptr, ctx);
  const exid::Estimate b = make("batch_ls", "{threads: 3}")->estimate(*m, d, nullptr, ctx);
  EXPECT_EQ(b.details.find("threads")->asInt(), 3);
  EXPECT_EQ(a.value, b.value);
  EXPECT_EQ(a.std, b.std);
  EXPECT_EQ(a.residual_rms, b.residual_rms);
  // and the truth within the estimate's own standard deviations
  const Eigen::VectorXd truth = m->baseNominal();
  for (Eigen::Index i = 0; i < truth.size(); ++i)
    EXPECT_LE(std::abs(a.value(i) - truth(i)), 4.0 * a.std(i));
}

namespace {

// pipelineChunks: inputs read in order, each chunk worked on its own input, results consumed in
// order (each chunk's result in slot c % 2T still its own when consumed), and a failing chunk
// stops the run with every chunk before it consumed and none after.
TEST(Streaming, PipelineConsumesEveryChunkInOrderFromItsOwnSlot) {
  const long n = 37;
  for (int T : {1, 2, 3, 4}) {
    SCOPED_TRACE(T);
    for (long fail : {-1L, 20L}) {
      std::vector<long> slot(2 * static_cast<std::size_t>(T), -1), read_order, consumed;
      auto run = [&] {
        exid::estimators::pipelineChunks(
            n, T,
            [&](long c, exid::Dataset* in) {
              read_order.push_back(c);
              in->t = Eigen::VectorXd::Constant(1, static_cast<double>(c));
            },
            [&](long c, const exid::Dataset& in) {
              ASSERT_EQ(in.t.size(), 1);
              ASSERT_EQ(in.t[0], static_cast<double>(c));  // its own input
              if (c == fail) throw exid::Error(fmt::format("chunk {} failed", c));
              slot[static_cast<std::size_t>(c % (2 * T))] = c;
            },
            [&](long c) {
              EXPECT_EQ(slot[static_cast<std::size_t>(c % (2 * T))], c);  // not overwritten
              consumed.push_back(c);
            });
      };
      if (fail < 0) {
        run();
        ASSERT_EQ(static_cast<long>(consumed.size()), n);
      } else {
        try {
          run();
          ADD_FAILURE() << "no error";
        } catch (const exid::Error& e) {
          EXPECT_NE(std::string(e.what()).find("chunk 20 failed"), std::string::npos);
        }
        // the chunks before the failing one, and no other
        EXPECT_EQ(static_cast<long>(consumed.size()), fail);
      }
      for (std::size_t i = 0; i < consumed.size(); ++i)
        EXPECT_EQ(consumed[i], static_cast<long>(i));
      for (std::size_t i = 0; i < read_order.size(); ++i)
        EXPECT_EQ(read_order[i], static_cast<long>(i));
    }
  }
}

// The secant update of a least-squares Hessian's second-order term (didim's hessian: secant):
// symmetric, and the updated S maps the step to y# (the secant condition); a step along which
// the gradient did not grow leaves S as it was.
TEST(Estimators, SecantSecondOrderUpdateMeetsTheSecantConditionAndStaysSymmetric) {
  std::mt19937 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  auto randomVector = [&](int n) {
    Eigen::VectorXd v(n);
    for (int i = 0; i < n; ++i) v[i] = N(rng);
    return v;
  };
  for (int trial = 0; trial < 20; ++trial) {
    const int n = 2 + trial % 7;
    Eigen::MatrixXd S0(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) S0(i, j) = N(rng);
    S0 = (trial % 3 == 0) ? Eigen::MatrixXd::Zero(n, n) : Eigen::MatrixXd(S0 + S0.transpose());
    const Eigen::VectorXd s = randomVector(n), ysharp = randomVector(n);
    Eigen::VectorXd y = randomVector(n);
    if (y.dot(s) < 0) y = -y;
    Eigen::MatrixXd S = S0;
    ASSERT_TRUE(exid::estimators::secantSecondOrderUpdate(&S, s, y, ysharp));
    EXPECT_LT((S * s - ysharp).norm(), 1e-10 * (1 + ysharp.norm())) << "trial " << trial;
    EXPECT_LT((S - S.transpose()).norm(), 1e-12 * (1 + S.norm())) << "trial " << trial;
    // the change is of rank two at most, in the span of y and y# - S s
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(
        S - S0 * std::min(1.0, std::abs(s.dot(ysharp)) / std::abs(s.dot(S0 * s))));
    if (n > 2 && trial % 3 != 0) {
      EXPECT_LT(svd.singularValues()[2], 1e-10 * svd.singularValues()[0]) << "trial " << trial;
    }
    // a step along which the gradient fell: no update
    Eigen::MatrixXd T = S0;
    EXPECT_FALSE(exid::estimators::secantSecondOrderUpdate(&T, s, -y, ysharp));
    EXPECT_EQ(T, S0);
  }
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(3, 3);
  EXPECT_THROW(
      exid::estimators::secantSecondOrderUpdate(&S, Eigen::VectorXd::Ones(2),
                                                Eigen::VectorXd::Ones(3), Eigen::VectorXd::Ones(3)),
      exid::Error);
}

}  // namespace
