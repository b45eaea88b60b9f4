// Physically consistent identification (consistent_ls), priors (batch_ls, wls, consistent_ls)
// and the identified robot written back as URDF (exid export). docs/consistent.md.
#include "exid/estimators/consistent.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include "estimator_test_model.hpp"
#include "exid/config.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/prior_scale.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"
#include "exid/urdf_writer.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;
using exid::estimators::Vec10;

namespace {

std::shared_ptr<exid::Estimator> make(const std::string& name, const std::string& params = "{}") {
  return exid_test::create<exid::Estimator>(name, params);
}

// ---------------------------------------------------------------- log-Cholesky
TEST(LogCholesky, EveryPointIsConsistentAndTheMapInverts) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    Vec10 t;
    for (int k = 0; k < 10; ++k) t(k) = n(rng);
    const Vec10 pi = exid::estimators::logCholeskyToInertial(t);
    EXPECT_TRUE(exid::checkPhysical(pi, 0.0).ok) << exid::checkPhysical(pi, 0.0).rule;
    EXPECT_GT(exid::estimators::pseudoInertiaMinEigenvalue(pi), 0.0);
    EXPECT_LE(
        (exid::estimators::inertialFromPseudo(exid::estimators::pseudoInertia(pi)) - pi).norm(),
        1e-12 * pi.norm());
    bool projected = true;
    const Vec10 back = exid::estimators::logCholeskyFromInertial(pi, 1e-300, &projected);
    EXPECT_FALSE(projected);
    EXPECT_LE((exid::estimators::logCholeskyToInertial(back) - pi).norm(), 1e-10 * pi.norm());
  }
}

TEST(LogCholesky, GradientMatchesFiniteDifferences) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    Vec10 t, g;
    for (int k = 0; k < 10; ++k) {
      t(k) = 0.5 * n(rng);
      g(k) = n(rng);
    }
    // f(t) = g . pi(t) + 0.5 |pi(t)|^2: df/dpi = g + pi.
    auto f = [&](const Vec10& x) {
      const Vec10 p = exid::estimators::logCholeskyToInertial(x);
      return g.dot(p) + 0.5 * p.squaredNorm();
    };
    const Vec10 grad =
        exid::estimators::logCholeskyVjp(t, g + exid::estimators::logCholeskyToInertial(t));
    const Eigen::Matrix<double, 10, 10> J = exid::estimators::logCholeskyJacobian(t);
    for (int k = 0; k < 10; ++k) {
      const double h = 1e-6;
      Vec10 a = t, b = t;
      a(k) += h;
      b(k) -= h;
      const double fd = (f(a) - f(b)) / (2 * h);
      EXPECT_NEAR(grad(k), fd, 1e-6 * std::max(1.0, std::abs(fd))) << "coordinate " << k;
      const Vec10 dpi = (exid::estimators::logCholeskyToInertial(a) -
                         exid::estimators::logCholeskyToInertial(b)) /
                        (2 * h);
      EXPECT_LE((J.col(k) - dpi).norm(), 1e-6 * std::max(1.0, dpi.norm())) << "column " << k;
    }
  }
}

TEST(LogCholesky, ProjectionRepairsAnInconsistentBody) {
  // The PUMA 560's published link 3 breaks the triangle inequality; a negative mass too.
  Vec10 bad;
  bad << 0.01, 0, 0, 0.5, 0, 0.02, 0.1, 0, 0, 3.0;
  EXPECT_FALSE(exid::checkPhysical(bad).ok);
  bool projected = false;
  const Vec10 t = exid::estimators::logCholeskyFromInertial(bad, 1e-6, &projected);
  EXPECT_TRUE(projected);
  EXPECT_TRUE(exid::checkPhysical(exid::estimators::logCholeskyToInertial(t), 0.0).ok);
  Vec10 neg = Vec10::Zero();
  neg(9) = -1.0;
  EXPECT_TRUE(exid::checkPhysical(exid::estimators::logCholeskyToInertial(
                                      exid::estimators::logCholeskyFromInertial(neg, 1e-6)),
                                  0.0)
                  .ok);
}

// ---------------------------------------------------------------- priors
// A joint that never reverses: sign(qd) and the offset columns are equal, so Fc1 and OFF1 are
// not separately identifiable. With a prior, the estimate must follow the data wherever they
// speak (W (theta - truth) = 0 on noise-free data) and the prior along the unexcited direction
// v (v^T Sigma^-1 (theta - theta0) = 0).
TEST(Priors, UnexcitedDirectionsFallBackToThePrior) {
  auto m = est_test::makeModel(1);
  est_test::DataOptions o;
  o.qd_offset = 100.0;  // qd > 0 throughout
  const exid::Dataset d = est_test::makeData(*m, 1, o);
  const Eigen::VectorXd truth = m->baseNominal();
  const int p = m->numBase();
  exid::RunContext ctx;
  // Without a prior: refused, with the direction named.
  try {
    make("batch_ls")->estimate(*m, d, nullptr, ctx);
    FAIL() << "rank-deficient data accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("Fc1"), std::string::npos) << e.what();
  }
  exid::Prior prior;
  prior.value = truth;
  for (int i = 0; i < p; ++i) prior.value(i) += 0.1 * (i + 1);  // a wrong prior everywhere
  Eigen::VectorXd sd(p);
  for (int i = 0; i < p; ++i) sd(i) = 0.05 * (1 + i % 3);
  prior.covariance = sd.cwiseAbs2().asDiagonal();
  // The unexcited direction: null vector of the data's W.
  const exid::Rows rows = m->rows(d, ctx);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(rows.W, Eigen::ComputeThinV);
  ASSERT_LT(svd.singularValues()(p - 1), 1e-9 * svd.singularValues()(0));
  const Eigen::VectorXd v = svd.matrixV().col(p - 1);
  const Eigen::MatrixXd Sinv = prior.covariance.inverse();
  // filtered_ls without filtering or differentiation (cutoff_hz 0, measured qd and qdd): the same
  // rows, so the same identities
  for (const std::string name : {"batch_ls", "wls", "consistent_ls", "filtered_ls"}) {
    SCOPED_TRACE(name);
    auto est = make(name, name == "filtered_ls" ? "{cutoff_hz: 0}" : "{}");
    ASSERT_TRUE(est->specs().accepts_prior);
    const exid::Estimate e = est->estimate(*m, d, &prior, ctx);
    // the data: every excited combination equals the truth
    EXPECT_LE((rows.W * (e.value - truth)).norm(), 1e-6 * (rows.W * truth).norm());
    // the prior: along v, the prior's value
    EXPECT_LE(
        std::abs(v.dot(Sinv * (e.value - prior.value))) / (Sinv * (e.value - prior.value)).norm(),
        name == "consistent_ls" ? 1e-4 : 1e-6);
    // far from the truth along v (the prior was wrong there), so the test means something
    EXPECT_GT(std::abs(v.dot(e.value - truth)), 0.01);
    // posterior std along the unexcited combination ~ the prior's
    ASSERT_NE(e.details.find("prior"), nullptr);
    EXPECT_TRUE(e.covariance.allFinite());
  }
}

TEST(Priors, StudyConfigValidatesThePriorSection) {
  const std::string head =
      "robot: {type: panda}\nmodel: {type: differential}\nexperiment: {type: csv, params: {file: "
      "x.csv}}\n"
      "estimator: {type: wls}\n";
  const exid::StudyConfig cfg =
      exid::parseStudy(head + "prior: {from: robot, relative_std: 0.2, absolute_std: 1e-3}\n",
                       "s.yaml", exid_test::sourceDir(), exid_test::registry());
  ASSERT_TRUE(cfg.prior.has_value());
  EXPECT_EQ(cfg.prior->from, "robot");
  EXPECT_DOUBLE_EQ(cfg.prior->relative_std, 0.2);
  EXPECT_DOUBLE_EQ(cfg.prior->absolute_std, 1e-3);
  EXPECT_NE(cfg.resolvedYaml().find("prior"), std::string::npos);
  EXPECT_FALSE(cfg.prior->drive_relative_std.has_value());
  EXPECT_FALSE(cfg.prior->drive_absolute_std.has_value());
  // drive columns with their own std; the resolved study keeps them and hashes the same
  const exid::StudyConfig cfgd = exid::parseStudy(
      head +
          "prior: {from: robot, relative_std: 0.2, absolute_std: 1e-3, drive_relative_std: 0, "
          "drive_absolute_std: 10}\n",
      "s.yaml", exid_test::sourceDir(), exid_test::registry());
  ASSERT_TRUE(cfgd.prior->drive_relative_std && cfgd.prior->drive_absolute_std);
  EXPECT_DOUBLE_EQ(*cfgd.prior->drive_relative_std, 0.0);
  EXPECT_DOUBLE_EQ(*cfgd.prior->drive_absolute_std, 10.0);
  EXPECT_NE(cfgd.hash(), cfg.hash());
  const exid::StudyConfig back = exid::parseStudy(cfgd.resolvedYaml(), "resolved.yaml",
                                                  exid_test::sourceDir(), exid_test::registry());
  ASSERT_TRUE(back.prior->drive_absolute_std.has_value());
  EXPECT_DOUBLE_EQ(*back.prior->drive_absolute_std, 10.0);
  EXPECT_EQ(back.hash(), cfgd.hash());
  try {
    exid::parseStudy(head + "prior: {from: robot, drive_absolute_std: -2}\n", "s.yaml",
                     exid_test::sourceDir(), exid_test::registry());
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("s.yaml:5: prior.drive_absolute_std = -2: must be a number in [0, inf)"),
              std::string::npos)
        << m;
  }
  try {
    exid::parseStudy(head + "prior: {from: study, study: out/a, drive_relative_std: 1}\n", "s.yaml",
                     exid_test::sourceDir(), exid_test::registry());
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown key 'drive_relative_std'"), std::string::npos)
        << e.what();
  }
  const exid::StudyConfig cfg2 =
      exid::parseStudy(head + "prior: {from: study, study: out/a, scale: 2}\n", "s.yaml",
                       exid_test::sourceDir(), exid_test::registry());
  EXPECT_EQ(cfg2.prior->study, exid_test::sourceDir() / "out/a");
  EXPECT_NE(cfg.hash(), cfg2.hash());
  try {
    exid::parseStudy(head + "prior: {from: robot, relative_std: -1, bogus: 2}\n", "s.yaml",
                     exid_test::sourceDir(), exid_test::registry());
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("s.yaml:5: prior.relative_std = -1"), std::string::npos) << m;
    EXPECT_NE(m.find("unknown key 'bogus'"), std::string::npos) << m;
  }
  try {
    exid::parseStudy("robot: {type: panda}\nprior: {from: moon}\n", "s.yaml",
                     exid_test::sourceDir(), exid_test::registry());
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("prior.from: expected 'robot' or 'study'"),
              std::string::npos)
        << e.what();
  }
}

TEST(Priors, DataDominateAWeakPriorOnExcitingData) {
  auto m = est_test::makeModel(2);
  est_test::DataOptions o;
  o.tau_noise = {0.01, 0.01};
  const exid::Dataset d = est_test::makeData(*m, 2, o);
  exid::RunContext ctx;
  const exid::Estimate ols = make("batch_ls")->estimate(*m, d, nullptr, ctx);
  exid::Prior weak;
  weak.value = Eigen::VectorXd::Zero(m->numBase());
  weak.covariance = 1e6 * Eigen::MatrixXd::Identity(m->numBase(), m->numBase());
  const exid::Estimate reg = make("batch_ls")->estimate(*m, d, &weak, ctx);
  EXPECT_LE((reg.value - ols.value).cwiseQuotient(ols.std).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LE((reg.std - ols.std).cwiseQuotient(ols.std).cwiseAbs().maxCoeff(), 0.05);
}

// ---------------------------------------------------------------- Panda (consistent truth)
struct Panda {
  std::shared_ptr<exid::RobotModel> truth;
  std::shared_ptr<exid::ObservationModel> model;
};

/// A solid sphere (mass ms, radius r) added at each body's centre of mass: a margin inside the
/// consistent set (Gaz et al.'s bodies are at its edge: their pseudo-inertias are near singular).
void fatten(Vec10* pi, double ms, double r) {
  const Eigen::Vector3d c = Eigen::Vector3d((*pi)(6), (*pi)(7), (*pi)(8)) / (*pi)(9);
  const Eigen::Matrix3d I =
      ms * ((0.4 * r * r + c.squaredNorm()) * Eigen::Matrix3d::Identity() - c * c.transpose());
  (*pi)(0) += I(0, 0);
  (*pi)(1) += I(0, 1);
  (*pi)(2) += I(0, 2);
  (*pi)(3) += I(1, 1);
  (*pi)(4) += I(1, 2);
  (*pi)(5) += I(2, 2);
  (*pi).segment<3>(6) += ms * c;
  (*pi)(9) += ms;
}

Panda panda(bool fat = false) {
  Panda p;
  p.truth = std::make_shared<exid::RobotModel>(*exid_test::robot("panda"));
  if (fat)
    for (auto& b : p.truth->bodies) fatten(&b.inertia, 0.5 * b.inertia(9), 0.1);
  // Gaz et al.'s viscous friction of joint 6 is negative: a consistent truth needs Fv >= 0.
  for (std::size_t j = 0; j < p.truth->drives.size(); ++j) {
    exid::Drive& d = p.truth->drives[j];
    d.viscous = std::abs(d.viscous) + 0.02;
    d.coulomb = std::abs(d.coulomb);
    d.rotor_inertia = 0.05 + 0.01 * static_cast<double>(j);
  }
  for (const auto& b : p.truth->bodies)
    EXPECT_GT(exid::estimators::pseudoInertiaMinEigenvalue(b.inertia), 0.0) << b.name;
  p.model = exid_test::create<exid::ObservationModel>("differential", "{}");
  exid::RunContext ctx;
  ctx.seed = 3;
  p.model->bind(p.truth, ctx);
  return p;
}

/// Sum-of-sines motion about the middle of the joint ranges; torques by inverse dynamics.
exid::Dataset pandaData(const exid::RobotModel& r, double noise, std::uint64_t seed,
                        int samples = 1500) {
  const int n = r.dof();
  exid::Dataset d;
  d.t = Eigen::VectorXd::LinSpaced(samples, 0.0, 0.01 * (samples - 1));
  d.q.resize(samples, n);
  d.qd.resize(samples, n);
  d.qdd.resize(samples, n);
  d.tau.resize(samples, n);
  std::mt19937 rng(static_cast<unsigned>(seed));
  std::uniform_real_distribution<double> ph(0.0, 2 * M_PI);
  std::normal_distribution<double> nz(0.0, 1.0);
  const double w[3] = {0.6, 1.1, 1.9};
  for (int j = 0; j < n; ++j) {
    const exid::JointLimits& L = r.limits[static_cast<std::size_t>(j)];
    const double mid = 0.5 * (L.q_min + L.q_max), half = 0.5 * (L.q_max - L.q_min);
    const double amp = std::min(0.25 * half, 1.0) / 3.0;
    double phase[3];
    for (double& x : phase) x = ph(rng);
    for (int k = 0; k < samples; ++k) {
      double q = mid, qd = 0, qdd = 0;
      for (int h = 0; h < 3; ++h) {
        const double a = amp * (1 + 0.3 * (j % 2)),
                     s = std::sin(w[h] * (1 + 0.1 * j) * d.t(k) + phase[h]);
        const double c = std::cos(w[h] * (1 + 0.1 * j) * d.t(k) + phase[h]);
        const double ww = w[h] * (1 + 0.1 * j);
        q += a * s;
        qd += a * ww * c;
        qdd -= a * ww * ww * s;
      }
      d.q(k, j) = q;
      d.qd(k, j) = qd;
      d.qdd(k, j) = qdd;
    }
  }
  auto dyn = exid::makeDynamicsData(r);
  exid::DriveColumns cols;
  cols.rotor_inertia = cols.coulomb = cols.viscous = true;
  for (int k = 0; k < samples; ++k) {
    const Eigen::VectorXd tau = exid::actuatorTorque(
        r, *dyn, cols, d.q.row(k).transpose(), d.qd.row(k).transpose(), d.qdd.row(k).transpose());
    for (int j = 0; j < n; ++j) d.tau(k, j) = tau(j) + noise * nz(rng);
  }
  d.source = "panda (test)";
  return d;
}

void expectConsistent(const exid::Estimate& e) {
  ASSERT_TRUE(e.details.find("consistent")) << "no 'consistent' in details";
  EXPECT_TRUE(e.details.find("consistent")->asBool());
  const exid::Json& sp = *e.details.find("standard_parameters");
  const exid::Json& names = *sp.find("names");
  const exid::Json& values = *sp.find("values");
  ASSERT_EQ(names.size(), values.size());
  for (std::size_t i = 0; i + 10 <= 70; i += 10) {
    Vec10 pi;
    for (std::size_t k = 0; k < 10; ++k)
      pi(static_cast<Eigen::Index>(k)) = values.at(i + k).asDouble();
    EXPECT_EQ(names.at(i + 9).asString(), "M" + std::to_string(i / 10 + 1));
    EXPECT_TRUE(exid::checkPhysical(pi, 0.0).ok)
        << "body " << i / 10 + 1 << ": " << exid::checkPhysical(pi, 0.0).rule;
    EXPECT_GT(exid::estimators::pseudoInertiaMinEigenvalue(pi), 0.0) << "body " << i / 10 + 1;
  }
  for (std::size_t i = 70; i < names.size(); ++i) {
    const std::string n = names.at(i).asString();
    if (n.rfind("Ia", 0) == 0 || n.rfind("Fc", 0) == 0 || n.rfind("Fv", 0) == 0) {
      EXPECT_GE(values.at(i).asDouble(), 0.0) << n;
    }
  }
}

TEST(ConsistentLs, PandaNoiseFreeMatchesOls) {
  Panda p = panda();
  const exid::Dataset d = pandaData(*p.truth, 0.0, 1);
  exid::RunContext ctx;
  const exid::Estimate ols = make("batch_ls")->estimate(*p.model, d, nullptr, ctx);
  const exid::Estimate c = make("consistent_ls")->estimate(*p.model, d, nullptr, ctx);
  expectConsistent(c);
  const Eigen::VectorXd truth = p.model->base().K * [&] {
    Eigen::VectorXd v =
        exid::parameterValues(*p.truth, exid::DriveColumns{true, true, true, false});
    return v;
  }();
  const double scale = ols.value.cwiseAbs().maxCoeff();
  double worst = 0.0, worst_rel = 0.0;
  for (Eigen::Index i = 0; i < ols.value.size(); ++i) {
    worst = std::max(worst, std::abs(c.value(i) - ols.value(i)) / scale);
    worst_rel = std::max(worst_rel, std::abs(c.value(i) - ols.value(i)) /
                                        std::max(std::abs(ols.value(i)), 1e-3 * scale));
  }
  std::printf(
      "panda noise-free: max |consistent - ols| / max|ols| = %.3g, per parameter %.3g; ols vs "
      "truth %.3g\n",
      worst, worst_rel, (ols.value - truth).cwiseAbs().maxCoeff() / scale);
  EXPECT_LE(worst_rel, 1e-6);
  EXPECT_LE((c.value - truth).norm(), 1e-6 * truth.norm());
}

TEST(ConsistentLs, PandaConsistentAtEveryNoiseLevel) {
  Panda p = panda();
  exid::RunContext ctx;
  for (double noise : {0.01, 0.3, 3.0}) {
    SCOPED_TRACE(noise);
    const exid::Dataset d = pandaData(*p.truth, noise, 7, 600);
    const exid::Estimate ols = make("batch_ls")->estimate(*p.model, d, nullptr, ctx);
    const exid::Estimate c = make("consistent_ls")->estimate(*p.model, d, nullptr, ctx);
    expectConsistent(c);
    const double ratio = c.details.find("residual_rms_ratio")->asDouble();
    const double maha = c.details.find("mahalanobis_from_unconstrained")->asDouble();
    std::printf(
        "panda noise %.2g N m: residual rms ratio %.4f, Mahalanobis distance from OLS %.3g (p = "
        "%d)\n",
        noise, ratio, maha, p.model->numBase());
    EXPECT_GE(ratio, 1.0 - 1e-9);
    // Linearised std: zero only for a base parameter pinned by an active bound (e.g. Fc = 0).
    EXPECT_TRUE(c.std.allFinite());
    EXPECT_GE(c.std.minCoeff(), 0.0);
    int pinned = 0;
    for (Eigen::Index i = 0; i < c.std.size(); ++i) pinned += c.std(i) < 1e-6 * ols.std(i) ? 1 : 0;
    std::printf("  %d base parameters pinned by active bounds (linearised std 0)\n", pinned);
    // with the robot's prior on the standard parameters (the default prior_on), too
    exid::PriorSpec spec;
    spec.from = "robot";
    spec.relative_std = 0.3;
    spec.absolute_std = 1e-3;
    const exid::Prior prior = exid::buildPrior(spec, *p.model);
    const exid::Estimate cp = make("consistent_ls")->estimate(*p.model, d, &prior, ctx);
    expectConsistent(cp);
    EXPECT_EQ(cp.details.find("prior")->find("on")->asString(), "standard");
    EXPECT_TRUE(cp.std.allFinite());
  }
}

// The prior from the robot description acts on the STANDARD parameters inside the consistent fit
// (prior_on: standard): min ||F K pi - f||^2 + ||D^-1 (pi - pi0)||^2 over consistent pi. Where no
// constraint is active this is the linear problem, whose minimiser has (i) the same base
// parameters as the base-level prior N(K pi0, K D^2 K^T) and (ii) as standard parameters the
// D-weighted completion pi0 + D^2 K^T (K D^2 K^T)^-1 (theta - K pi0). With prior_on: base the
// standard parameters are any consistent completion, farther from the prior in its own metric.
TEST(ConsistentLs, StandardPriorCompletesTheBodiesByThePrior) {
  // The prior's centre (the truth) strictly inside the consistent set, and a prior narrow enough
  // (5 %) that the estimate stays inside it: independent 30 % std on XX, YY, ZZ of a body would
  // already reach across the triangle inequalities, and the constraints would be active.
  Panda pa = panda(true);
  exid::RunContext ctx;
  const exid::Dataset d = pandaData(*pa.truth, 0.05, 21, 600);
  exid::PriorSpec spec;
  spec.from = "robot";
  spec.relative_std = 0.05;
  spec.absolute_std = 1e-3;
  spec.drive_relative_std = 0.0;
  spec.drive_absolute_std = 0.5;
  const exid::Prior prior = exid::buildPrior(spec, *pa.model);
  const std::vector<std::string> names = pa.model->fullNames();
  const Eigen::VectorXd pi0 = pa.model->fullNominal();
  const int nf = static_cast<int>(names.size());
  ASSERT_EQ(prior.standard_value.size(), nf);
  ASSERT_EQ(prior.standard_std.size(), nf);
  int drives = 0;
  for (int i = 0; i < nf; ++i) {
    const bool drive = exid::isDriveParameterName(names[static_cast<std::size_t>(i)]);
    drives += drive ? 1 : 0;
    EXPECT_DOUBLE_EQ(prior.standard_value(i), pi0(i));
    EXPECT_DOUBLE_EQ(prior.standard_std(i), drive ? 0.5 : std::hypot(0.05 * pi0(i), 1e-3))
        << names[static_cast<std::size_t>(i)];
  }
  EXPECT_EQ(drives, 21);  // Ia, Fc, Fv of 7 joints
  const Eigen::MatrixXd& K = pa.model->base().K;
  const Eigen::VectorXd D2 = prior.standard_std.cwiseAbs2();
  EXPECT_LE((prior.covariance - K * D2.asDiagonal() * K.transpose()).norm(),
            1e-12 * prior.covariance.norm());
  // scaling the prior scales both forms
  const exid::Prior half = exid::estimators::scaledPrior(prior, 0.5);
  EXPECT_LE((half.standard_std - 0.5 * prior.standard_std).norm(), 1e-15);

  const exid::Estimate s = make("consistent_ls")->estimate(*pa.model, d, &prior, ctx);
  const exid::Estimate b =
      make("consistent_ls", "{prior_on: base}")->estimate(*pa.model, d, &prior, ctx);
  expectConsistent(s);
  expectConsistent(b);
  EXPECT_EQ(s.details.find("prior")->find("on")->asString(), "standard");
  EXPECT_EQ(b.details.find("prior")->find("on")->asString(), "base");
  auto standard = [&](const exid::Estimate& e) {
    const exid::Json& v = *e.details.find("standard_parameters")->find("values");
    Eigen::VectorXd out(nf);
    for (int i = 0; i < nf; ++i) out(i) = v.at(static_cast<std::size_t>(i)).asDouble();
    return out;
  };
  const Eigen::VectorXd pis = standard(s), pib = standard(b);
  // (i) the same base parameters (no constraint active: the consistent fit is the linear one)
  EXPECT_LE(s.details.find("mahalanobis_from_unconstrained")->asDouble(), 1e-4);
  EXPECT_LE((s.value - b.value).cwiseQuotient(s.std).cwiseAbs().maxCoeff(), 1e-3);
  // ... and the same linearised covariance: K (K^T F^T F K + D^-2)^-1 K^T = (F^T F + (K D^2
  // K^T)^-1)^-1 (Woodbury), the base prior's posterior
  EXPECT_LE((s.covariance - b.covariance).norm(), 1e-6 * b.covariance.norm());
  // (ii) the standard parameters are the prior's own completion of them
  const Eigen::MatrixXd KD2Kt = K * D2.asDiagonal() * K.transpose();
  const Eigen::VectorXd completion =
      pi0 + D2.asDiagonal() * K.transpose() * KD2Kt.ldlt().solve(s.value - K * pi0);
  const Eigen::VectorXd dinv = prior.standard_std.cwiseInverse();
  const double dev = dinv.cwiseProduct(pis - completion).norm();
  const double dist_s = dinv.cwiseProduct(pis - pi0).norm();
  const double dist_b = dinv.cwiseProduct(pib - pi0).norm();
  std::printf(
      "standard prior: ||D^-1 (pi - completion)|| = %.3g; distance from the prior in its std: "
      "prior_on standard %.3f, base %.3f\n",
      dev, dist_s, dist_b);
  EXPECT_LE(dev, 1e-4 * dist_s);
  EXPECT_NEAR(s.details.find("prior")->find("standard_mahalanobis")->asDouble(), dist_s,
              1e-9 * dist_s);
  EXPECT_LT(dist_s, 0.9 * dist_b);
}

// ---------------------------------------------------------------- prior scale
// A linear problem y = W theta + e (unit noise) whose truth is a draw from the prior with its
// standard deviations multiplied by a_true: the evidence must recover a_true and the unit noise
// variance, cross-validation a scale of the same order.
TEST(PriorScale, EvidenceAndCrossValidationRecoverTheScaleOfThePriorDraw) {
  const int p = 50, m = 4000, blocks = 5;
  std::mt19937 rng(17);
  std::normal_distribution<double> nz(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.5, 2.0);
  exid::Prior prior;
  prior.value.resize(p);
  Eigen::VectorXd sd(p);
  for (int i = 0; i < p; ++i) {
    prior.value(i) = 3.0 * nz(rng);
    sd(i) = uni(rng);
  }
  prior.covariance = sd.cwiseAbs2().asDiagonal();
  // Data std of each parameter ~ 1 / (0.1 sqrt(m)) ~ 0.16: the draw's deviation from the prior
  // (a_true * sd, sd in [0.5, 2]) is visible in the data for every a_true below, and the prior
  // still matters.
  Eigen::MatrixXd W(m, p);
  for (int r = 0; r < m; ++r)
    for (int c = 0; c < p; ++c) W(r, c) = 0.1 * nz(rng);
  for (double a_true : {0.3, 1.0, 10.0}) {
    SCOPED_TRACE(a_true);
    Eigen::VectorXd theta(p);
    for (int i = 0; i < p; ++i) theta(i) = prior.value(i) + a_true * sd(i) * nz(rng);
    Eigen::VectorXd y = W * theta;
    for (int r = 0; r < m; ++r) y(r) += nz(rng);
    exid::estimators::RowAccumulator all(p);
    all.add(W, y);
    const exid::estimators::PriorScaleChoice ev =
        exid::estimators::selectPriorScaleEvidence(all, prior, 1e-3, 1e3, "test");
    std::vector<exid::estimators::RowAccumulator> folds;
    for (int b = 0; b < blocks; ++b) {
      folds.emplace_back(p);
      folds.back().add(W.middleRows(b * m / blocks, m / blocks),
                       y.segment(b * m / blocks, m / blocks));
    }
    const exid::estimators::PriorScaleChoice cv = exid::estimators::selectPriorScaleCv(
        folds, prior, exid::estimators::logGrid(1e-3, 1e3, 8), "test");
    std::printf("a_true %g: evidence a = %.3g (s^2 = %.3g, gamma = %.1g), cv a = %.3g\n", a_true,
                ev.scale, ev.noise_variance, ev.effective_parameters, cv.scale);
    EXPECT_GT(ev.scale, 0.7 * a_true);
    EXPECT_LT(ev.scale, 1.4 * a_true);
    EXPECT_NEAR(ev.noise_variance, 1.0, 0.1);
    EXPECT_GT(cv.scale, a_true / 4);
    EXPECT_LT(cv.scale, 4 * a_true);
    ASSERT_EQ(cv.criterion.size(), cv.grid.size());
    // inside the range [1e-3, 1e3]: no doubt said
    EXPECT_EQ(cv.at_edge, "");
    EXPECT_EQ(ev.at_edge, "");
    EXPECT_EQ(cv.edgeText("test"), "");
    // a range that ends below the truth: the choice sits at its upper end, and says so
    const exid::estimators::PriorScaleChoice cv_low = exid::estimators::selectPriorScaleCv(
        folds, prior, exid::estimators::logGrid(a_true / 100, a_true / 30, 8), "test");
    EXPECT_EQ(cv_low.at_edge, "high");
    EXPECT_NE(cv_low.edgeText("test").find("upper end"), std::string::npos);
    const exid::estimators::PriorScaleChoice ev_low =
        exid::estimators::selectPriorScaleEvidence(all, prior, a_true / 100, a_true / 30, "test");
    EXPECT_EQ(ev_low.at_edge, "high");
    // and one that starts above it: the lower end
    const exid::estimators::PriorScaleChoice cv_high = exid::estimators::selectPriorScaleCv(
        folds, prior, exid::estimators::logGrid(a_true * 30, a_true * 100, 8), "test");
    EXPECT_EQ(cv_high.at_edge, "low");
    EXPECT_NE(cv_high.toJson().find("at_range_edge"), nullptr);
    EXPECT_EQ(cv_high.toJson().find("at_range_edge")->asString(), "low");
  }
}

// consistent_ls on noisy, short Panda data with a prior whose stated standard deviations are
// wrong by a factor 10 either way: the selected scale moves the right way and the estimate
// predicts fresh (noise-free) torques better than with the prior as stated.
TEST(PriorScale, SelectionCorrectsAMisstatedPriorInConsistentLs) {
  Panda pa = panda();
  exid::RunContext ctx;
  const exid::Dataset d = pandaData(*pa.truth, 2.0, 11, 500);
  const exid::Dataset fresh = pandaData(*pa.truth, 0.0, 12, 1500);
  const Eigen::MatrixXd Wt = pa.model->rows(fresh, ctx).W;
  const Eigen::VectorXd truth =
      pa.model->base().K *
      exid::parameterValues(*pa.truth, exid::DriveColumns{true, true, true, false});
  const int p = pa.model->numBase();
  std::mt19937 rng(5);
  std::normal_distribution<double> nz(0.0, 1.0);
  Eigen::VectorXd sd(p), xi(p);
  for (int i = 0; i < p; ++i) {
    sd(i) = 0.3 * std::abs(truth(i)) + 0.02;
    xi(i) = nz(rng);
  }
  auto predictionError = [&](const exid::Estimate& e) {
    return (Wt * (e.value - truth)).norm() / (Wt * truth).norm();
  };
  for (double actual : {0.1, 10.0}) {  // prior error / stated std
    SCOPED_TRACE(actual);
    exid::Prior prior;
    prior.value = truth + actual * sd.cwiseProduct(xi);
    prior.covariance = sd.cwiseAbs2().asDiagonal();
    const exid::Estimate fixed = make("consistent_ls")->estimate(*pa.model, d, &prior, ctx);
    const double e_fixed = predictionError(fixed);
    // a prior on base parameters only: prior_on: standard (the default) falls back, and says so
    EXPECT_EQ(fixed.details.find("prior")->find("on")->asString(), "base");
    EXPECT_TRUE(fixed.details.find("prior")->find("on_note"));
    EXPECT_EQ(fixed.details.find("prior")->find("scale")->find("method")->asString(), "fixed");
    for (const std::string method : {"cv", "evidence"}) {
      SCOPED_TRACE(method);
      const exid::Estimate sel = make("consistent_ls", "{prior_scale_selection: " + method + "}")
                                     ->estimate(*pa.model, d, &prior, ctx);
      expectConsistent(sel);
      const exid::Json& sc = *sel.details.find("prior")->find("scale");
      EXPECT_EQ(sc.find("method")->asString(), method);
      const double a = sc.find("scale")->asDouble();
      const double e_sel = predictionError(sel);
      std::printf(
          "prior off by %g x its std, %s: scale %.3g, fresh torque error %.4f (stated "
          "prior %.4f)\n",
          actual, method.c_str(), a, e_sel, e_fixed);
      if (actual < 1) {
        EXPECT_LT(a, 0.5);
      } else {
        EXPECT_GT(a, 2.0);
      }
      EXPECT_LT(e_sel, e_fixed);
    }
  }
}

// ---------------------------------------------------------------- export round trip
struct Cmd {
  int code = -1;
  std::string out;
};
Cmd run(const std::string& args) {
  Cmd r;
  FILE* p = ::popen((std::string(EXID_EXE) + " " + args + " 2>&1").c_str(), "r");
  std::array<char, 4096> buf{};
  while (p && std::fgets(buf.data(), buf.size(), p)) r.out += buf.data();
  const int status = p ? ::pclose(p) : -1;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

TEST(Export, IdentifiedUrdfReproducesTheIdentifiedModel) {
  Panda p = panda();
  const exid::Dataset d = pandaData(*p.truth, 0.05, 11);
  const fs::path dir = fs::temp_directory_path() / ("exid_export_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  exid::CsvTable t;
  t.columns = {"t"};
  for (const char* s : {"q", "qd", "qdd", "tau"})
    for (int j = 1; j <= 7; ++j) t.columns.push_back(s + std::to_string(j));
  t.data.resize(d.size(), 29);
  t.data << d.t, d.q, d.qd, d.qdd, d.tau;
  exid::writeCsvAtomic(dir / "data.csv", t);
  {
    std::ofstream s(dir / "study.yaml");
    s << "robot: {type: panda}\nmodel: {type: differential}\nexperiment: {type: csv, params: "
         "{file: data.csv}}\n"
         "estimator: {type: consistent_ls}\nprior: {from: robot, relative_std: 1.0, absolute_std: "
         "0.1}\n"
         "report: {type: standard, params: {plots: false}}\n";
  }
  const Cmd r = run("-q run " + (dir / "study.yaml").string() + " --out " + (dir / "out").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const Cmd x = run("export --study " + (dir / "out").string() + " --out " +
                    (dir / "identified.urdf").string());
  ASSERT_EQ(x.code, 0) << x.out;

  // The identified model: the panda with the identified standard parameters.
  std::ifstream in(dir / "out/summary.json");
  const exid::Json S = exid::Json::parse(
      std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()));
  const exid::Json& I = *S.find("identification");
  const exid::Json& sp = *I.find("details")->find("standard_parameters");
  exid::RobotModel ident = *exid_test::robot("panda");
  Eigen::VectorXd pi(static_cast<Eigen::Index>(sp.find("values")->size()));
  for (std::size_t i = 0; i < sp.find("values")->size(); ++i)
    pi(static_cast<Eigen::Index>(i)) = sp.find("values")->at(i).asDouble();
  for (int j = 0; j < 7; ++j) {
    ident.bodies[static_cast<std::size_t>(j)].inertia = pi.segment<10>(10 * j);
    ident.drives[static_cast<std::size_t>(j)].rotor_inertia = pi(70 + 3 * j);
    ident.drives[static_cast<std::size_t>(j)].coulomb = pi(71 + 3 * j);
    ident.drives[static_cast<std::size_t>(j)].viscous = pi(72 + 3 * j);
  }
  const auto loaded = exid_test::robot(
      "urdf", "{file: '" + (dir / "identified.urdf").string() + "', strict: true}");
  ASSERT_EQ(loaded->dof(), 7);
  auto da = exid::makeDynamicsData(ident);
  auto db = exid::makeDynamicsData(*loaded);
  exid::DriveColumns cols{true, true, true, false};
  double worst = 0.0;
  for (int k = 0; k < d.size(); k += 37) {
    const Eigen::VectorXd q = d.q.row(k).transpose(), qd = d.qd.row(k).transpose(),
                          qdd = d.qdd.row(k).transpose();
    const Eigen::VectorXd ta = exid::actuatorTorque(ident, *da, cols, q, qd, qdd);
    const Eigen::VectorXd tb = exid::actuatorTorque(*loaded, *db, cols, q, qd, qdd);
    worst =
        std::max(worst, (ta - tb).cwiseAbs().maxCoeff() / std::max(1.0, ta.cwiseAbs().maxCoeff()));
  }
  EXPECT_LE(worst, 1e-9);
  // Its base parameters are the identified ones.
  auto m2 = exid_test::create<exid::ObservationModel>("differential", "{}");
  exid::RunContext ctx;
  ctx.seed = 1;  // the study's seed: the same base parameters
  m2->bind(loaded, ctx);
  const Eigen::VectorXd b2 = m2->baseNominal();
  const exid::Json& ps = *I.find("parameters");
  ASSERT_EQ(static_cast<std::size_t>(b2.size()), ps.size());
  for (std::size_t i = 0; i < ps.size(); ++i) {
    EXPECT_EQ(m2->base().names[i], ps.at(i).find("name")->asString());
    const double v = ps.at(i).find("value")->asDouble();
    EXPECT_NEAR(b2(static_cast<Eigen::Index>(i)), v, 1e-8 * std::max(1.0, std::abs(v)))
        << ps.at(i).find("name")->asString();
  }
  // `exid eval --rigid-body-only` on the exported file gives the identified rigid-body torques.
  exid::CsvTable s;
  s.columns.clear();
  for (const char* c : {"q", "qd", "qdd"})
    for (int j = 1; j <= 7; ++j) s.columns.push_back(c + std::to_string(j));
  s.data.resize(5, 21);
  for (int k = 0; k < 5; ++k)
    s.data.row(k) << d.q.row(100 * k), d.qd.row(100 * k), d.qdd.row(100 * k);
  exid::writeCsvAtomic(dir / "samples.csv", s);
  const Cmd ev = run("eval " + (dir / "identified.urdf").string() + " --samples " +
                     (dir / "samples.csv").string() + " --what torque --rigid-body-only --out " +
                     (dir / "tau.csv").string());
  ASSERT_EQ(ev.code, 0) << ev.out;
  const exid::CsvTable tau = exid::readCsv(dir / "tau.csv");
  for (int k = 0; k < 5; ++k) {
    const Eigen::VectorXd ref =
        exid::inverseDynamics(ident, *da, d.q.row(100 * k).transpose(),
                              d.qd.row(100 * k).transpose(), d.qdd.row(100 * k).transpose());
    EXPECT_LE((tau.data.row(k).transpose() - ref).cwiseAbs().maxCoeff(),
              1e-8 * std::max(1.0, ref.cwiseAbs().maxCoeff()));
  }
  // A study without consistent standard parameters is refused with a reason.
  fs::remove_all(dir);
}

TEST(Export, WriterRoundTripsADhRobotWithPostTransforms) {
  // The PUMA 560 (standard DH: post transforms) with consistent link parameters.
  exid::RobotModel r = *exid_test::robot("puma560");
  for (auto& b : r.bodies) {
    const Vec10 t = exid::estimators::logCholeskyFromInertial(b.inertia, 1e-4);
    b.inertia = exid::estimators::logCholeskyToInertial(t);
  }
  const fs::path f =
      fs::temp_directory_path() / ("exid_puma_" + std::to_string(::getpid()) + ".urdf");
  exid::writeFileAtomic(f, exid::writeUrdf(r));
  const auto l = exid_test::robot("urdf", "{file: '" + f.string() + "', strict: true}");
  fs::remove(f);
  auto da = exid::makeDynamicsData(r);
  auto db = exid::makeDynamicsData(*l);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int k = 0; k < 20; ++k) {
    Eigen::VectorXd q(6), qd(6), qdd(6);
    for (int j = 0; j < 6; ++j) {
      q(j) = u(rng);
      qd(j) = u(rng);
      qdd(j) = u(rng);
    }
    const Eigen::VectorXd a = exid::inverseDynamics(r, *da, q, qd, qdd),
                          b = exid::inverseDynamics(*l, *db, q, qd, qdd);
    EXPECT_LE((a - b).cwiseAbs().maxCoeff(), 1e-9 * std::max(1.0, a.cwiseAbs().maxCoeff()));
  }
}

}  // namespace
