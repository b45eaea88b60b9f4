// Gradients through closed loops: the closed-chain state's analytic derivatives with respect to
// the actuated coordinates (closedChainStateDerivatives, loopConstraintJerk) against central
// differences of closedChainState, the actuated torque's derivatives and the actuated
// regressor's VJP against differences of their values, on the shipped four-bar (a nonlinear G)
// and palletiser (a parallelogram: G constant, the tree's dynamics nonlinear) and a planar
// five-bar (two actuated cranks: G's cross derivatives); then gradient-based
// excitation design on the palletiser: its gradient against differences, and a short design that
// lowers the criterion.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>
#include <vector>

#include "exid/closed_chain.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/gradient_check.hpp"
#include "exid_test.hpp"

namespace {

struct State {
  Eigen::VectorXd qa, qda, qdda;
};

// A random state inside the actuated joints' limits (well inside: the mechanism assembles).
State randomState(const exid::RobotModel& m, std::mt19937& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const int n = m.dof();
  State s{Eigen::VectorXd(n), Eigen::VectorXd(n), Eigen::VectorXd(n)};
  Eigen::VectorXd q0 = Eigen::VectorXd::Zero(m.numJoints());
  if (m.closed.reference.size() == m.numJoints()) q0 = m.closed.reference;
  for (int i = 0; i < n; ++i) {
    s.qa[i] = q0[m.actuatedJoint(i)] + 0.3 * U(rng);
    s.qda[i] = 1.5 * U(rng);
    s.qdda[i] = 3.0 * U(rng);
  }
  return s;
}

double relDiff(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).lpNorm<Eigen::Infinity>() / std::max(1.0, b.lpNorm<Eigen::Infinity>());
}

class ClosedChainGradient : public ::testing::TestWithParam<const char*> {};

TEST_P(ClosedChainGradient, StateDerivativesAgainstCentralDifferences) {
  const auto robot = exid_test::robot(GetParam());
  const exid::RobotModel& m = *robot;
  ASSERT_TRUE(m.hasLoops());
  const int n = m.dof(), nt = m.numJoints();
  std::mt19937 rng(2024);
  const double h = 1e-5;  // central differences: truncation ~h^2, rounding ~1e-16/h
  double worst = 0.0, largest_dG = 0.0;
  for (int t = 0; t < 5; ++t) {
    const State s = randomState(m, rng);
    Eigen::VectorXd q, qd, qdd;
    Eigen::MatrixXd G, Dqd, Dqdd, Dqdd_d;
    std::vector<Eigen::MatrixXd> dG;
    exid::closedChainStateDerivatives(m, s.qa, s.qda, s.qdda, &q, &qd, &qdd, &G, &dG, &Dqd, &Dqdd,
                                      &Dqdd_d);
    ASSERT_EQ(static_cast<int>(dG.size()), n);
    // the values are closedChainState's
    Eigen::VectorXd q2, qd2, qdd2;
    Eigen::MatrixXd G2;
    exid::closedChainState(m, s.qa, &s.qda, &s.qdda, &q2, &qd2, &qdd2, &G2, nullptr);
    EXPECT_EQ(q, q2);
    EXPECT_EQ(qdd, qdd2);
    for (int k = 0; k < n; ++k) {
      // in qa_k
      State p = s, mi = s;
      p.qa[k] += h, mi.qa[k] -= h;
      Eigen::VectorXd qdp, qddp, qdm, qddm;
      Eigen::MatrixXd Gp, Gmi;
      exid::closedChainState(m, p.qa, &p.qda, &p.qdda, nullptr, &qdp, &qddp, &Gp, nullptr);
      exid::closedChainState(m, mi.qa, &mi.qda, &mi.qdda, nullptr, &qdm, &qddm, &Gmi, nullptr);
      const Eigen::MatrixXd fdG = (Gp - Gmi) / (2 * h);
      largest_dG = std::max(largest_dG, fdG.lpNorm<Eigen::Infinity>());
      worst = std::max(worst, relDiff(dG[static_cast<std::size_t>(k)], fdG));
      EXPECT_LT(relDiff(dG[static_cast<std::size_t>(k)], fdG), 1e-7)
          << GetParam() << " dG/dqa" << k;
      EXPECT_LT(relDiff(Dqd.col(k), (qdp - qdm) / (2 * h)), 1e-7) << GetParam() << " dqd/dqa" << k;
      EXPECT_LT(relDiff(Dqdd.col(k), (qddp - qddm) / (2 * h)), 1e-7)
          << GetParam() << " dqdd/dqa" << k;
      worst = std::max(worst, relDiff(Dqdd.col(k), (qddp - qddm) / (2 * h)));
      // in qda_k (qdd is quadratic in qda: the difference is exact but for rounding)
      p = s, mi = s;
      p.qda[k] += h, mi.qda[k] -= h;
      exid::closedChainState(m, p.qa, &p.qda, &p.qdda, nullptr, &qdp, &qddp, nullptr, nullptr);
      exid::closedChainState(m, mi.qa, &mi.qda, &mi.qdda, nullptr, &qdm, &qddm, nullptr, nullptr);
      EXPECT_LT(relDiff(Dqdd_d.col(k), (qddp - qddm) / (2 * h)), 1e-7)
          << GetParam() << " dqdd/dqda" << k;
      EXPECT_LT(relDiff(G.col(k), (qdp - qdm) / (2 * h)), 1e-7) << GetParam() << " dqd/dqda" << k;
    }
    // the jerk (cubic in w) is the bias's derivative along q + t w at constant w
    const Eigen::VectorXd w = Eigen::VectorXd::Random(nt);
    const Eigen::VectorXd fdj =
        (exid::loopConstraintBias(m, q + h * w, w) - exid::loopConstraintBias(m, q - h * w, w)) /
        (2 * h);
    EXPECT_LT(relDiff(exid::loopConstraintJerk(m, q, w), fdj), 1e-7) << GetParam() << " jerk";
  }
  std::cout << "  " << GetParam() << ": largest |dG/dqa| " << largest_dG
            << ", worst relative difference " << worst << " (step " << h << ")\n";
  RecordProperty("worst_rel_diff", std::to_string(worst));
}

TEST_P(ClosedChainGradient, TorqueDerivativesAndRegressorVjpAgainstCentralDifferences) {
  const auto robot = exid_test::robot(GetParam());
  const exid::RobotModel& m = *robot;
  const int n = m.dof();
  exid::DriveColumns cols;
  cols.rotor_inertia = cols.viscous = cols.coulomb = cols.offset = true;
  auto data = exid::makeDynamicsData(m);
  std::mt19937 rng(77);
  // (a step of 1e-4: the position solve's 1e-12 residual over the step stays below 1e-8)
  const double h = 1e-4;
  const int P = exid::numParameters(m, cols);
  const Eigen::VectorXd params = exid::parameterValues(m, cols) + 0.1 * Eigen::VectorXd::Random(P);
  for (int t = 0; t < 4; ++t) {
    const State s = randomState(m, rng);
    Eigen::VectorXd tau;
    Eigen::MatrixXd Dq, Dqd, Dqdd;
    exid::actuatorTorqueWith(m, *data, cols, params, s.qa, s.qda, s.qdda, &tau, &Dq, &Dqd, &Dqdd);
    Eigen::VectorXd tau0;
    exid::actuatorTorqueWith(m, *data, cols, params, s.qa, s.qda, s.qdda, &tau0, nullptr, nullptr,
                             nullptr);
    EXPECT_LT(relDiff(tau, tau0), 1e-13);
    auto torque = [&](const State& x) {
      Eigen::VectorXd v;
      exid::actuatorTorqueWith(m, *data, cols, params, x.qa, x.qda, x.qdda, &v, nullptr, nullptr,
                               nullptr);
      return v;
    };
    // the regressor's VJP: <W, Y(qa, qda, qdda)>
    const Eigen::MatrixXd W = Eigen::MatrixXd::Random(n, P);
    Eigen::VectorXd gq, gqd, gqdd;
    exid::actuatorRegressorVjp(m, *data, cols, s.qa, s.qda, s.qdda, W, &gq, &gqd, &gqdd);
    auto inner = [&](const State& x) {
      Eigen::MatrixXd Y(n, P);
      exid::actuatorRegressor(m, *data, cols, x.qa, x.qda, x.qdda, Y);
      return W.cwiseProduct(Y).sum();
    };
    for (int k = 0; k < n; ++k)
      for (int which = 0; which < 3; ++which) {
        State p = s, mi = s;
        Eigen::VectorXd& xp = which == 0 ? p.qa : which == 1 ? p.qda : p.qdda;
        Eigen::VectorXd& xm = which == 0 ? mi.qa : which == 1 ? mi.qda : mi.qdda;
        if (which == 1 && std::abs(s.qda[k]) < 10 * h) continue;  // sign(qd) jumps at 0
        xp[k] += h, xm[k] -= h;
        const Eigen::VectorXd fd = (torque(p) - torque(mi)) / (2 * h);
        const Eigen::MatrixXd& D = which == 0 ? Dq : which == 1 ? Dqd : Dqdd;
        EXPECT_LT(relDiff(D.col(k), fd), 1e-7) << GetParam() << " dtau/d" << which << " " << k;
        const double fdv = (inner(p) - inner(mi)) / (2 * h);
        const Eigen::VectorXd& g = which == 0 ? gq : which == 1 ? gqd : gqdd;
        EXPECT_LT(std::abs(g[k] - fdv) / std::max(1.0, std::abs(fdv)), 1e-7)
            << GetParam() << " vjp d" << which << " " << k << ": " << g[k] << " vs " << fdv;
      }
  }
}

INSTANTIATE_TEST_SUITE_P(ShippedClosedChains, ClosedChainGradient,
                         ::testing::Values("fourbar", "palletizer"));

// A two-dof closed chain whose G depends on both actuated coordinates: a planar five-bar
// (ground pivots 0.2 m apart, cranks 0.15 m, couplers 0.3 m, in the vertical x-y plane; actuated:
// the two cranks; the cut joint where the couplers meet), so dG/dqa_k e_j, k != j, is exercised.
exid::RobotModel fiveBar() {
  const double a = 0.15, b = 0.3, d = 0.2, th1 = 2.0, th2 = 1.0;
  exid::RobotModel m;
  m.name = "five_bar";
  m.gravity = Eigen::Vector3d(0, -9.81, 0);
  std::vector<exid::Body> B(4);
  B[0].name = "crank1", B[0].joint_name = "j1", B[0].parent = -1;
  B[1].name = "coupler1", B[1].joint_name = "j2", B[1].parent = 0, B[1].pre.p = {a, 0.0, 0.0};
  B[2].name = "crank2", B[2].joint_name = "j3", B[2].parent = -1, B[2].pre.p = {d, 0.0, 0.0};
  B[3].name = "coupler2", B[3].joint_name = "j4", B[3].parent = 2, B[3].pre.p = {a, 0.0, 0.0};
  for (int i = 0; i < 4; ++i) {
    Eigen::Matrix<double, 10, 1> p;
    p << 0.02 + 0.01 * i, 0.001, -0.002, 0.03, 0.0015, 0.025 + 0.005 * i, 0.1 + 0.05 * i, 0.01,
        -0.02, 1.0 + 0.5 * i;
    B[static_cast<std::size_t>(i)].inertia = p;
  }
  m.bodies = B;
  exid::LoopJoint L;
  L.name = "C";
  L.body_a = 1, L.body_b = 3;
  L.pose_a.p = {b, 0, 0};
  L.pose_b.p = {b, 0, 0};
  m.closed.loops = {L};
  m.closed.actuated = {0, 2};
  // the assembled reference: C on the circles of radius b about the cranks' ends
  const Eigen::Vector2d B1(a * std::cos(th1), a * std::sin(th1)),
      B2(d + a * std::cos(th2), a * std::sin(th2));
  const Eigen::Vector2d u = (B2 - B1).normalized(), v(-u.y(), u.x());
  const double l = (B2 - B1).norm();
  const Eigen::Vector2d C = B1 + 0.5 * l * u + std::sqrt(b * b - 0.25 * l * l) * v;
  m.closed.reference.resize(4);
  m.closed.reference << th1, std::atan2(C.y() - B1.y(), C.x() - B1.x()) - th1, th2,
      std::atan2(C.y() - B2.y(), C.x() - B2.x()) - th2;
  m.limits.assign(2, exid::JointLimits{});
  m.drives.assign(2, exid::Drive{});
  m.validateStructure();
  return m;
}

TEST(ClosedChainGradientTwoDof, FiveBarStateAndVjpAgainstCentralDifferences) {
  const exid::RobotModel m = fiveBar();
  const int n = m.dof();
  ASSERT_EQ(n, 2);
  std::mt19937 rng(5);
  const double h = 1e-5;
  double cross = 0.0;
  exid::DriveColumns cols;
  cols.viscous = true;
  auto data = exid::makeDynamicsData(m);
  const int P = exid::numParameters(m, cols);
  for (int t = 0; t < 5; ++t) {
    const State s = randomState(m, rng);
    Eigen::MatrixXd G, Dqd, Dqdd, Dqdd_d;
    std::vector<Eigen::MatrixXd> dG;
    exid::closedChainStateDerivatives(m, s.qa, s.qda, s.qdda, nullptr, nullptr, nullptr, &G, &dG,
                                      &Dqd, &Dqdd, &Dqdd_d);
    const Eigen::MatrixXd W = Eigen::MatrixXd::Random(n, P);
    Eigen::VectorXd gq, gqd, gqdd;
    exid::actuatorRegressorVjp(m, *data, cols, s.qa, s.qda, s.qdda, W, &gq, &gqd, &gqdd);
    auto inner = [&](const State& x) {
      Eigen::MatrixXd Y(n, P);
      exid::actuatorRegressor(m, *data, cols, x.qa, x.qda, x.qdda, Y);
      return W.cwiseProduct(Y).sum();
    };
    for (int k = 0; k < n; ++k) {
      State p = s, mi = s;
      p.qa[k] += h, mi.qa[k] -= h;
      Eigen::VectorXd qdp, qddp, qdm, qddm;
      Eigen::MatrixXd Gp, Gmi;
      exid::closedChainState(m, p.qa, &p.qda, &p.qdda, nullptr, &qdp, &qddp, &Gp, nullptr);
      exid::closedChainState(m, mi.qa, &mi.qda, &mi.qdda, nullptr, &qdm, &qddm, &Gmi, nullptr);
      const Eigen::MatrixXd fdG = (Gp - Gmi) / (2 * h);
      cross = std::max(cross, fdG.col(1 - k).lpNorm<Eigen::Infinity>());
      EXPECT_LT(relDiff(dG[static_cast<std::size_t>(k)], fdG), 1e-7) << "dG/dqa" << k;
      EXPECT_LT(relDiff(Dqd.col(k), (qdp - qdm) / (2 * h)), 1e-7) << "dqd/dqa" << k;
      EXPECT_LT(relDiff(Dqdd.col(k), (qddp - qddm) / (2 * h)), 1e-7) << "dqdd/dqa" << k;
      const double fdv = (inner(p) - inner(mi)) / (2 * h);
      EXPECT_LT(std::abs(gq[k] - fdv) / std::max(1.0, std::abs(fdv)), 1e-7) << "vjp qa" << k;
      p = s, mi = s;
      p.qda[k] += h, mi.qda[k] -= h;
      exid::closedChainState(m, p.qa, &p.qda, &p.qdda, nullptr, nullptr, &qddp, nullptr, nullptr);
      exid::closedChainState(m, mi.qa, &mi.qda, &mi.qdda, nullptr, nullptr, &qddm, nullptr,
                             nullptr);
      EXPECT_LT(relDiff(Dqdd_d.col(k), (qddp - qddm) / (2 * h)), 1e-7) << "dqdd/dqda" << k;
      const double fdd = (inner(p) - inner(mi)) / (2 * h);
      EXPECT_LT(std::abs(gqd[k] - fdd) / std::max(1.0, std::abs(fdd)), 1e-7) << "vjp qda" << k;
    }
  }
  std::cout << "  five-bar: largest cross term |dG/dqa_k e_j|, k != j: " << cross << "\n";
  EXPECT_GT(cross, 1e-2);  // the cross terms are exercised
}

// The palletiser's excitation problem: a Fourier trajectory of its four measured coordinates,
// the differential model with drive columns, the torque limits as constraints (through the
// loops: the actuated torques' derivatives).
struct Design {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

Design palletizerDesign(const std::string& criterion, double torque_margin) {
  Design d;
  exid::RunContext ctx;
  ctx.seed = 11;
  d.robot = exid_test::robot("palletizer");
  d.model = exid_test::create<exid::ObservationModel>(
      "differential", "{rotor_inertia: true, coulomb: true, viscous: true, offset: true}");
  d.model->bind(d.robot, ctx);
  d.traj = exid_test::create<exid::Trajectory>(
      "fourier",
      "{period_s: 6, harmonics: 3, sample_period_s: 0.1, position_margin_rad: 0.05, init: random, "
      "init_scale: 0.3}");
  d.traj->bind(d.robot, ctx);
  exid::ExcitationOptions xo;
  xo.position_margin = d.traj->positionMargin();
  xo.velocity_limits = d.traj->velocityLimits();
  xo.acceleration_limits = d.traj->accelerationLimits();
  xo.torque_margin = torque_margin;
  d.problem = exid::makeExcitationProblem(d.traj, d.model,
                                          exid_test::create<exid::Criterion>(criterion, "{}"), xo);
  return d;
}

TEST(ClosedChainExcitation, PalletizerDesignGradientAgainstCentralDifferences) {
  for (const char* crit : {"cond", "log_det"}) {
    Design d = palletizerDesign(crit, 0.9);
    exid::ExcitationProblem& p = *d.problem;
    const Eigen::VectorXd z = p.initial();
    Eigen::VectorXd grad;
    const double J = p.value(z, &grad);
    ASSERT_TRUE(std::isfinite(J));
    exid::DerivativeCheckOptions o;
    o.tolerance = 1e-5;
    // (a relative step of 1e-4: the differences of a closed chain's design carry the position
    // solve's residual over the step, 4e-5 of the gradient at the default 1e-6, 3.6e-6 at 1e-5,
    // 4.6e-7 at 1e-4 -- shrinking as 1/h, noise and not a wrong derivative)
    o.relative_step = 1e-4;
    const exid::DerivativeCheck c =
        exid::checkGradient([&](const Eigen::VectorXd& v) { return p.value(v, nullptr); }, z, grad,
                            o, std::string("palletizer excitation problem, ") + crit);
    std::cout << "  " << c.message() << "\n";
    EXPECT_TRUE(c.ok) << c.message();
    // the torque-limit rows' Jacobian (the actuated torques' derivatives through the loops)
    ASSERT_GT(p.numNonlinearConstraints(), 0);
    Eigen::VectorXd g;
    Eigen::MatrixXd Jg;
    p.nonlinearConstraints(z, &g, &Jg);
    const Eigen::MatrixXd D = exid_test::nonlinearConstraintDifferences(p, z, 1e-5);
    const double scale = std::max(1.0, D.lpNorm<Eigen::Infinity>());
    EXPECT_LT((Eigen::MatrixXd(Jg) - D).lpNorm<Eigen::Infinity>() / scale, 1e-6) << crit;
  }
}

TEST(ClosedChainExcitation, PalletizerShortDesignLowersTheCriterion) {
  Design d = palletizerDesign("cond", 0.9);
  exid::RunContext ctx;
  ctx.seed = 3;
  const exid::OptimizerResult r =
      exid_test::create<exid::Optimizer>(
          "nlopt", "{algorithm: LD_SLSQP, objective: log, starts: 1, max_evaluations: 60}")
          ->minimize(*d.problem, ctx);
  std::cout << "  palletizer cond: " << r.criterion_initial << " -> " << r.criterion_final << " ("
            << exid::stopReasonText(r) << ")\n";
  RecordProperty("cond_initial", std::to_string(r.criterion_initial));
  RecordProperty("cond_final", std::to_string(r.criterion_final));
  EXPECT_TRUE(r.feasible) << exid::stopReasonText(r);
  EXPECT_LT(r.criterion_final, 0.5 * r.criterion_initial);
}

TEST(ClosedChainExcitation, EnergyModelDesignVjpThroughTheLoops) {
  // the `integral` (energy) model's design VJP: the tree's energy gradient mapped to the
  // actuated coordinates by the chain rule (jointGradientToMeasured)
  for (const char* robot : {"fourbar", "palletizer"}) {
    exid::RunContext ctx;
    auto r = exid_test::robot(robot);
    auto model = exid_test::create<exid::ObservationModel>(
        "integral", "{rotor_inertia: true, friction: true, offset: true, window_s: 0.2}");
    model->bind(r, ctx);
    auto traj = exid_test::create<exid::Trajectory>(
        "fourier",
        "{period_s: 2, harmonics: 2, sample_period_s: 0.1, init: random, "
        "init_scale: 0.3}");
    traj->bind(r, ctx);
    const exid::Samples s = traj->evaluate(traj->initial());
    exid::DerivativeCheckOptions o;
    o.relative_step = 1e-4;  // (the position solve's residual over the step, as above)
    const exid::DerivativeCheck c = exid::checkModel(*model, s, o);
    std::cout << "  " << robot << ": " << c.message() << "\n";
    EXPECT_TRUE(c.ok) << robot << ": " << c.message();
  }
}

TEST(ClosedChainExcitation, PayloadGainColumnsDesignVjpThroughTheLoops) {
  // the `differential` model's drive-gain columns with a known payload (their design gradient
  // projects the payload's torque through G, which depends on qa: the four-bar's does)
  for (const char* robot : {"fourbar", "palletizer"}) {
    exid::RunContext ctx;
    auto r = exid_test::robot(robot);
    auto model = exid_test::create<exid::ObservationModel>(
        "differential",
        "{offset: true, drive_gains: true, payload_mass_kg: 2.5, payload_com_m: [0.05, -0.02, "
        "0.1], payload_inertia_kg_m2: [0.02, 0.001, 0, 0.03, -0.002, 0.015]}");
    model->bind(r, ctx);
    auto traj = exid_test::create<exid::Trajectory>(
        "fourier",
        "{period_s: 2, harmonics: 2, sample_period_s: 0.25, init: random, init_scale: 0.3}");
    traj->bind(r, ctx);
    const exid::Samples s = traj->evaluate(traj->initial());
    exid::DerivativeCheckOptions o;
    o.relative_step = 1e-4;  // (the position solve's residual over the step, as above)
    const exid::DerivativeCheck c = exid::checkModel(*model, s, o);
    std::cout << "  " << robot << ": " << c.message() << "\n";
    EXPECT_TRUE(c.ok) << robot << ": " << c.message();
  }
}

}  // namespace
