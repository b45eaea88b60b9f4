// Torque limits of the excitation problem: exact Jacobian of the torque rows against central
// finite differences, refusals when exid cannot know the torques or their limits, and optimisers
// that end within the limits where the unconstrained design exceeds them (checked again between
// the design samples, at 1 kHz).
#include <gtest/gtest.h>

#include <cmath>

#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid_test.hpp"

namespace {

const std::vector<double> kPandaTauMax = {87, 87, 87, 87, 12, 12, 12};  // Franka's published

struct TorqueSetup {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

TorqueSetup make(const std::string& traj, const std::string& tparams, double torque_margin,
                 const std::vector<double>& torque_max = kPandaTauMax,
                 const std::string& robot = "panda") {
  TorqueSetup s;
  exid::RunContext ctx;
  ctx.seed = 5;
  s.robot = exid_test::robot(robot);
  s.model =
      exid_test::create<exid::ObservationModel>("differential", "{coulomb: true, viscous: true}");
  s.model->bind(s.robot, ctx);
  s.traj = exid_test::create<exid::Trajectory>(traj, tparams);
  s.traj->bind(s.robot, ctx);
  auto crit = exid_test::create<exid::Criterion>("cond", "{}");
  exid::ExcitationOptions xo;
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  xo.torque_margin = torque_margin;
  xo.torque_max = torque_max;
  s.problem = exid::makeExcitationProblem(s.traj, s.model, crit, xo);
  return s;
}

// max_j,k |tau_j(t_k)| / tau_max,j of the full model along samples.
double torqueRatio(const exid::RobotModel& r, const exid::Samples& s,
                   const std::vector<double>& tau_max) {
  const Eigen::MatrixXd tau = exid::predictedTorques(r, s);
  double m = 0;
  for (int j = 0; j < tau.cols(); ++j)
    m = std::max(m, tau.col(j).cwiseAbs().maxCoeff() / tau_max[static_cast<std::size_t>(j)]);
  return m;
}

const char* kFourier =
    "{period_s: 10, harmonics: 5, sample_period_s: 0.1, position_margin_rad: 0.1, "
    "acceleration_limits: false, init: random, init_scale: 0.5}";

}  // namespace

TEST(TorqueLimits, JacobianMatchesCentralDifferences) {
  for (const auto& [traj, params] : std::vector<std::pair<std::string, std::string>>{
           {"fourier", kFourier},
           {"spline",
            "{duration_s: 4, knots: 6, degree: 5, boundary: periodic, sample_period_s: 0.1, "
            "init: random, init_scale: 0.5}"}}) {
    TorqueSetup s = make(traj, params, 0.8);
    exid::ExcitationProblem& p = *s.problem;
    const int nl = p.numNonlinearConstraints();
    const int K = s.traj->evaluate(p.initial()).size();
    ASSERT_EQ(nl, 2 * 7 * K) << traj;
    const Eigen::VectorXd z = p.initial();
    Eigen::VectorXd g;
    Eigen::MatrixXd J;
    p.constraints(z, &g, &J);
    ASSERT_EQ(g.size(), p.numConstraints());
    // the torque rows alone agree with the tail of the whole set
    Eigen::VectorXd gt;
    Eigen::MatrixXd Jtail;
    p.nonlinearConstraints(z, &gt, &Jtail);
    EXPECT_EQ((gt - g.tail(nl)).cwiseAbs().maxCoeff(), 0.0) << traj;
    EXPECT_EQ((Jtail - J.bottomRows(nl)).cwiseAbs().maxCoeff(), 0.0) << traj;
    // the rows are +-tau / tau_max - margin
    const Eigen::MatrixXd tau = exid::predictedTorques(*s.robot, s.traj->evaluate(z));
    EXPECT_NEAR(gt(3), tau(3, 0) / 87.0 - 0.8, 1e-14);
    EXPECT_NEAR(gt(K + 3), -tau(3, 0) / 87.0 - 0.8, 1e-14);
    EXPECT_NEAR(gt(2 * 6 * K + 4), tau(4, 6) / 12.0 - 0.8, 1e-14);
    // central differences of every torque row along every variable
    const double worst =
        (exid_test::nonlinearConstraintDifferences(p, z, 1e-6) - Jtail).cwiseAbs().maxCoeff();
    const double scale = Jtail.cwiseAbs().maxCoeff();
    EXPECT_GT(scale, 0.0);
    EXPECT_LE(worst, 1e-6 * scale) << traj << ": worst " << worst << " of " << scale;
  }
}

TEST(TorqueLimits, RefusedWhenTorquesOrLimitsAreUnknown) {
  // The Panda's description has no effort limits: they must be given.
  try {
    make("fourier", kFourier, 0.8, {});
    FAIL() << "no torque limit: expected an error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("no torque limit (URDF effort) for joint(s) 1"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("torque_max_Nm"), std::string::npos) << e.what();
  }
  EXPECT_THROW(make("fourier", kFourier, 0.8, {87, 87}), exid::Error);
  EXPECT_THROW(make("fourier", kFourier, 0.8, {87, 87, 87, 87, 12, 12, -1}), exid::Error);
  // A robot without dynamic parameters: its torques cannot be predicted.
  exid::RobotModel bare = *exid_test::robot("panda");
  for (auto& b : bare.bodies) b.inertia.setZero();
  try {
    exid::torqueLimits(bare, kPandaTauMax, "test");
    FAIL() << "no inertial parameters: expected an error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("carries no inertial parameters"), std::string::npos)
        << e.what();
  }
  // Off: no torque rows.
  EXPECT_EQ(make("fourier", kFourier, 0.0, {}).problem->numNonlinearConstraints(), 0);
}

TEST(TorqueLimits, OptimisersEndWithinTheLimitsTheUnconstrainedDesignExceeds) {
  const std::string nlopt =
      "{algorithm: LD_SLSQP, objective: log, constraint_mode: aggregated, ks_rho: 300, "
      "final_polish: 0.3, starts: 1, max_evaluations: 300}";
  exid::RunContext ctx;
  ctx.seed = 3;
  TorqueSetup unlimited = make("fourier", kFourier, 0.0, {});
  const exid::OptimizerResult r0 =
      exid_test::create<exid::Optimizer>("nlopt", nlopt)->minimize(*unlimited.problem, ctx);
  ASSERT_TRUE(r0.feasible);
  const double ratio0 = torqueRatio(*unlimited.robot, unlimited.traj->evaluate(r0.z), kPandaTauMax);
  // a limit the unconstrained design exceeds
  const double margin = 0.8 * ratio0;
  for (const auto& [name, params] : std::vector<std::pair<std::string, std::string>>{
           {"nlopt", nlopt},
           {"adjoint_gradient", "{constraints: augmented_lagrangian, max_iterations: 300}"},
           {"sundials", "{max_iterations: 20}"}}) {
    TorqueSetup s = make("fourier", kFourier, margin);
    const exid::OptimizerResult r =
        exid_test::create<exid::Optimizer>(name, params)->minimize(*s.problem, ctx);
    EXPECT_TRUE(r.feasible) << name << ": " << exid::stopReasonText(r);
    EXPECT_LE(r.max_violation, 1e-9) << name;
    EXPECT_LE(torqueRatio(*s.robot, s.traj->evaluate(r.z), kPandaTauMax), margin + 1e-9)
        << name << " at the design samples";
    // between the samples (1 kHz over the period): within the limit to 1 % of it
    Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(10000, 0.0, 10.0 - 1e-3);
    const double fine = torqueRatio(*s.robot, s.traj->evaluateAt(r.z, t), kPandaTauMax);
    EXPECT_LE(fine, 1.01 * margin) << name << " at 1 kHz";
    EXPECT_LT(r.criterion_final, r.criterion_initial) << name;
  }
}
