// Conformance: one suite run over every registered plugin. Every shipped plugin library loads
// (none refused), declares well-formed parameters, and behaves as its kind promises.
#include <gtest/gtest.h>

#include <random>
#include <set>
#include <sstream>

#include "exid/config.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"
#include "exid_test.hpp"

namespace {

std::vector<std::string> split(const std::string& s, char d) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, d))
    if (!item.empty()) out.push_back(item);
  return out;
}

exid::ParamSet defaults(const exid::PluginInfo& info) {
  return exid::resolveParams(info, "{}", std::string(exid::toString(info.kind)) + " " + info.name,
                             exid_test::sourceDir());
}

bool allDefaulted(const exid::PluginInfo& info) {
  for (const auto& d : info.params)
    if (!d.default_value) return false;
  return true;
}

}  // namespace

TEST(Conformance, EveryShippedPluginLibraryLoads) {
  auto& reg = exid_test::registry();
  for (const auto& r : reg.refused()) ADD_FAILURE() << "refused: " << r.path << ": " << r.reason;
  std::set<std::string> loaded;
  for (const auto& p : reg.plugins())
    loaded.insert(std::filesystem::path(p.library).filename().string());
  for (const auto& target : split(EXID_PLUGIN_TARGET_LIST, ','))
    EXPECT_TRUE(loaded.count("lib" + target + ".so"))
        << target << " was built but provides no plugin";
}

TEST(Conformance, ThePluginsTheDesignNamesAreShipped) {
  auto& reg = exid_test::registry();
  const std::vector<std::pair<exid::PluginKind, std::vector<std::string>>> expected = {
      {exid::PluginKind::Robot,
       {"urdf", "dh", "planar2r", "puma560", "irp6", "stanford", "panda", "humanoid", "quadruped"}},
      {exid::PluginKind::Criterion, {"cond", "min_sv", "frobenius_cond", "log_det"}},
      {exid::PluginKind::Model,
       {"differential", "integral", "load_wrench", "load_torque", "floating_base"}},
      {exid::PluginKind::Trajectory, {"pointwise", "fourier", "spline"}},
      {exid::PluginKind::Optimizer, {"adjoint_gradient", "nlopt"}},
      {exid::PluginKind::Experiment, {"simulate", "csv", "rosbag2"}},
      {exid::PluginKind::Estimator, {"rls", "batch_ls", "filtered_ls", "wls"}},
  };
  for (const auto& [kind, names] : expected)
    for (const auto& n : names)
      EXPECT_NE(reg.find(kind, n), nullptr) << exid::toString(kind) << " " << n;
}

TEST(Conformance, ParameterDeclarationsAreWellFormed) {
  for (const auto& p : exid_test::registry().plugins()) {
    SCOPED_TRACE(std::string(exid::toString(p.kind)) + " " + p.name);
    EXPECT_FALSE(p.doc.empty());
    EXPECT_FALSE(p.version.empty());
    std::set<std::string> names;
    for (const auto& d : p.params) {
      SCOPED_TRACE(d.name);
      EXPECT_TRUE(names.insert(d.name).second) << "duplicate parameter";
      EXPECT_FALSE(d.doc.empty()) << "parameter without a one-line doc";
      for (char c : d.name)
        EXPECT_TRUE(std::islower(static_cast<unsigned char>(c)) ||
                    std::isdigit(static_cast<unsigned char>(c)) || c == '_' ||
                    std::isupper(static_cast<unsigned char>(c)));
      if (d.default_value) {
        EXPECT_EQ(d.violation(*d.default_value), "") << "default breaks its own range";
      }
    }
  }
}

TEST(Conformance, RobotsBuildValidModels) {
  auto& reg = exid_test::registry();
  for (const exid::PluginInfo* p : reg.plugins(exid::PluginKind::Robot)) {
    if (!allDefaulted(*p)) continue;  // urdf and dh need a file
    SCOPED_TRACE(p->name);
    auto robot = reg.create<exid::Robot>(p->name, defaults(*p));
    exid::RunContext ctx;
    auto model = robot->build(ctx);
    ASSERT_NE(model, nullptr);
    EXPECT_GT(model->dof(), 0);
    EXPECT_NO_THROW(model->validateStructure());
    EXPECT_EQ(static_cast<int>(model->limits.size()), model->dof());
    EXPECT_EQ(static_cast<int>(model->drives.size()), model->dof());
  }
}

TEST(Conformance, CriteriaGradientsMatchFiniteDifferences) {
  auto& reg = exid_test::registry();
  std::mt19937 rng(3);
  std::normal_distribution<double> nd;
  for (const exid::PluginInfo* p : reg.plugins(exid::PluginKind::Criterion)) {
    SCOPED_TRACE(p->name);
    auto crit = reg.create<exid::Criterion>(p->name, defaults(*p));
    const int m = 6;
    Eigen::MatrixXd W(20, m);
    for (int i = 0; i < W.size(); ++i) W.data()[i] = nd(rng);
    Eigen::MatrixXd M = W.transpose() * W, G;
    const double J = crit->evaluate(M, &G);
    EXPECT_TRUE(std::isfinite(J));
    EXPECT_LT((G - G.transpose()).norm(), 1e-10 * (1 + G.norm()));
    // Directional derivative along a random symmetric direction.
    Eigen::MatrixXd D(m, m);
    for (int i = 0; i < D.size(); ++i) D.data()[i] = nd(rng);
    D = 0.5 * (D + D.transpose());
    const double h = 1e-6;
    const double fd =
        (crit->evaluate(M + h * D, nullptr) - crit->evaluate(M - h * D, nullptr)) / (2 * h);
    const double an = (G.array() * D.array()).sum();
    EXPECT_NEAR(an, fd, 1e-6 * (1 + std::abs(fd)));
    // A singular information matrix is an error, not a number.
    Eigen::MatrixXd S = M;
    S.row(0).setZero();
    S.col(0).setZero();
    EXPECT_THROW(crit->evaluate(S, nullptr), exid::Error);
  }
}

TEST(Conformance, ObservationModelsBindAndTheirGradientsMatchFiniteDifferences) {
  auto& reg = exid_test::registry();
  auto robot = exid_test::robot("puma560");
  for (const exid::PluginInfo* p : reg.plugins(exid::PluginKind::Model)) {
    if (!allDefaulted(*p)) continue;
    SCOPED_TRACE(p->name);
    auto model = reg.create<exid::ObservationModel>(p->name, defaults(*p));
    exid::RunContext ctx;
    if (model->specs().floating_base) {
      // a floating-base model: binds a floating robot, refuses a fixed one; no VJP (excitation
      // design refuses a floating robot)
      EXPECT_THROW(model->bind(robot, ctx), exid::Error);
      model = reg.create<exid::ObservationModel>(p->name, defaults(*p));
      model->bind(exid_test::robot("humanoid"), ctx);
      EXPECT_GT(model->numBase(), 0);
      exid::Samples s = model->randomSamples(5, 5), g;
      const Eigen::MatrixXd W = model->design(s);
      EXPECT_EQ(W.rows(), 5 * 16);
      EXPECT_THROW(model->designVjp(s, W, &g), exid::Error);
      continue;
    }
    model->bind(robot, ctx);
    EXPECT_GT(model->numBase(), 0);
    EXPECT_EQ(static_cast<int>(model->fullNames().size()), model->base().numFull());
    EXPECT_EQ(model->fullNominal().size(), model->base().numFull());
    // 61 samples over 1.2 s: long enough for the default windows of the integral model.
    exid::Samples s = model->randomSamples(61, 5);
    s.t = Eigen::VectorXd::LinSpaced(61, 0.0, 1.2);
    Eigen::MatrixXd W = model->design(s);
    ASSERT_GT(W.rows(), 0);
    Eigen::MatrixXd G = Eigen::MatrixXd::Random(W.rows(), W.cols());
    exid::Samples g;
    model->designVjp(s, G, &g);
    // Check the q, qd and qdd gradients along random directions.
    const double h = 1e-6;
    for (int which = 0; which < 3; ++which) {
      Eigen::MatrixXd dir = Eigen::MatrixXd::Random(s.q.rows(), s.q.cols());
      exid::Samples sp = s, sm = s;
      Eigen::MatrixXd& xp = which == 0 ? sp.q : (which == 1 ? sp.qd : sp.qdd);
      Eigen::MatrixXd& xm = which == 0 ? sm.q : (which == 1 ? sm.qd : sm.qdd);
      xp += h * dir;
      xm -= h * dir;
      const double fd =
          ((model->design(sp) - model->design(sm)).array() * G.array()).sum() / (2 * h);
      const Eigen::MatrixXd& gx = which == 0 ? g.q : (which == 1 ? g.qd : g.qdd);
      const double an = (gx.array() * dir.array()).sum();
      EXPECT_NEAR(an, fd, 1e-5 * (1 + std::abs(fd))) << "signal " << which;
    }
  }
}

#include "dyn_reference.hpp"
#include "exid/dynamics.hpp"

// Every shipped robot (as its plugin builds it): Y * pi equals an independent Newton-Euler
// (tests/support/dyn_reference.cpp, no code shared with the library), and the energy regressor
// equals the reference energy.
TEST(Conformance, EveryShippedRobotsRegressorMatchesIndependentNewtonEuler) {
  auto& reg = exid_test::registry();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int robots = 0;
  for (const exid::PluginInfo* p : reg.plugins(exid::PluginKind::Robot)) {
    if (!allDefaulted(*p)) continue;
    SCOPED_TRACE(p->name);
    exid::RunContext ctx;
    auto model = reg.create<exid::Robot>(p->name, defaults(*p))->build(ctx);
    const int n = model->numJoints();  // (the tree of a closed chain)
    // (a floating base: tests/robots/floating_robots_test.cpp checks it against the fixed-base
    // chain with six virtual joints; the fixed-base algorithms refuse it)
    if (model->floating_base) {
      EXPECT_THROW(exid::makeDynamicsData(*model), exid::Error);
      continue;
    }
    auto data = exid::makeDynamicsData(*model);
    const Eigen::VectorXd pi = model->inertialParameters();
    Eigen::MatrixXd Y(n, 10 * n);
    Eigen::RowVectorXd kin(10 * n), pot(10 * n);
    for (int k = 0; k < 10; ++k) {
      Eigen::VectorXd q(n), qd(n), qdd(n);
      for (int j = 0; j < n; ++j) {
        q(j) = 1.5 * u(rng);
        qd(j) = u(rng);
        qdd(j) = 2 * u(rng);
      }
      exid::torqueRegressor(*model, *data, q, qd, qdd, Y);
      const Eigen::VectorXd ref = exid::testing::refTorques(*model, q, qd, qdd, pi);
      EXPECT_LT((Y * pi - ref).norm(), 1e-10 * (1 + ref.norm())) << "config " << k;
      exid::energyRegressor(*model, *data, q, qd, kin, pot);
      double T = 0, U = 0;
      exid::testing::refEnergy(*model, q, qd, pi, &T, &U);
      EXPECT_NEAR(kin.dot(pi), T, 1e-10 * (1 + std::abs(T)));
      EXPECT_NEAR(pot.dot(pi), U, 1e-10 * (1 + std::abs(U)));
    }
    ++robots;
  }
  EXPECT_GE(robots, 5);
}
