// Excitation problem gradient (through the real differential model and every criterion) against
// finite differences; the optimisers reduce cond and return feasible points.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/optimizers/optim_common.hpp"
#include "exid_test.hpp"

namespace {

struct XSetup {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
  std::shared_ptr<exid::Criterion> crit;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

XSetup make(const std::string& robot, const std::string& traj, const std::string& tparams,
            const std::string& crit = "cond", const std::string& mparams = "{coulomb: false}") {
  XSetup s;
  exid::RunContext ctx;
  ctx.seed = 11;
  s.robot = exid_test::robot(robot);
  s.model = exid_test::create<exid::ObservationModel>("differential", mparams);
  s.model->bind(s.robot, ctx);
  s.traj = exid_test::create<exid::Trajectory>(traj, tparams);
  s.traj->bind(s.robot, ctx);
  s.crit = exid_test::create<exid::Criterion>(crit, "{}");
  exid::ExcitationOptions xo;
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  xo.scale_columns = s.crit->specs().scale_columns;
  s.problem = exid::makeExcitationProblem(s.traj, s.model, s.crit, xo);
  return s;
}

// Largest violation of the robot's limits (and the caps) recomputed from the samples.
double violation(const exid::Samples& s, const exid::RobotModel& r, double margin, bool vel,
                 bool acc, double vcap = 0) {
  double v = 0;
  for (int j = 0; j < s.dof(); ++j) {
    const auto& L = r.limits[static_cast<std::size_t>(j)];
    v = std::max(v, s.q.col(j).maxCoeff() - (L.q_max - margin));
    v = std::max(v, (L.q_min + margin) - s.q.col(j).minCoeff());
    if (vel && L.qd_max < 1e299) v = std::max(v, s.qd.col(j).cwiseAbs().maxCoeff() - L.qd_max);
    if (acc && L.qdd_max < 1e299) v = std::max(v, s.qdd.col(j).cwiseAbs().maxCoeff() - L.qdd_max);
    if (vcap > 0) v = std::max(v, s.qd.col(j).cwiseAbs().maxCoeff() - vcap);
  }
  return v;
}

struct GradCase {
  std::string robot, traj, tparams, crit;
  // pointwise: start from the accelerations of this random Fourier trajectory (written to a CSV,
  // init: csv) rather than the one-cosine-per-joint start, whose information matrix is nearly
  // singular (cond(M) ~ 1e8: J then carries roundoff that no finite difference resolves)
  std::string fourier_start = "";
};

// A CSV (t, q, qd, qdd) of a random Fourier trajectory of the robot.
std::string fourierStartCsv(const std::string& robot, const std::string& fparams,
                            const std::string& tag) {
  exid::RunContext ctx;
  ctx.seed = 7;
  auto f = exid_test::create<exid::Trajectory>("fourier", fparams);
  f->bind(exid_test::robot(robot), ctx);
  const exid::Samples smp = f->evaluate(f->initial());
  exid::CsvTable T;
  const int n = smp.dof();
  T.columns.push_back("t");
  for (const char* sig : {"q", "qd", "qdd"})
    for (int j = 0; j < n; ++j) T.columns.push_back(sig + std::to_string(j + 1));
  T.data.resize(smp.size(), 1 + 3 * n);
  T.data.col(0) = smp.t;
  T.data.middleCols(1, n) = smp.q;
  T.data.middleCols(1 + n, n) = smp.qd;
  T.data.middleCols(1 + 2 * n, n) = smp.qdd;
  const auto path =
      std::filesystem::temp_directory_path() / ("exid_gradtest_start_" + tag + ".csv");
  exid::writeCsvAtomic(path, T);
  return path.string();
}

class GradientTest : public ::testing::TestWithParam<GradCase> {};

TEST_P(GradientTest, MatchesCentralDifferences) {
  const auto& c = GetParam();
  std::string tparams = c.tparams;
  if (!c.fourier_start.empty()) {
    const std::string csv = fourierStartCsv(c.robot, c.fourier_start, c.robot + "_" + c.crit);
    tparams = tparams.substr(0, tparams.size() - 1) + ", init: csv, init_csv: \"" + csv + "\"}";
  }
  XSetup s = make(c.robot, c.traj, tparams, c.crit);
  const Eigen::VectorXd z = s.problem->initial();
  const double condW = exid::conditionNumber(s.model->design(s.traj->evaluate(z)));
  ASSERT_LT(condW, 1e3) << "the start should be well conditioned";
  Eigen::VectorXd g;
  const double J = s.problem->value(z, &g);
  ASSERT_TRUE(std::isfinite(J));
  ASSERT_EQ(g.size(), z.size());
  // Central differences extrapolated (Richardson, h and h/2: error O(h^4)) so that a step
  // large enough to keep the roundoff of J small still has a negligible truncation error. The
  // roundoff matters on badly conditioned starts (pointwise: cond(M) ~ 1e8, where J carries
  // ~1e-9 relative noise): with a plain central difference no step was accurate to better than
  // ~1e-3 there. The error is relative to the size of the directional derivative, floored at
  // 1e-3 |grad| (a direction orthogonal to the gradient is not a relative test).
  const double hstep = std::getenv("EXID_FD_H") ? std::atof(std::getenv("EXID_FD_H")) : 1e-3;
  const double rtol = std::getenv("EXID_FD_RTOL") ? std::atof(std::getenv("EXID_FD_RTOL")) : 1e-6;
  auto derivative = [&](const Eigen::VectorXd& d, double h) {
    auto central = [&](double hh) {
      return (s.problem->value(z + hh * d, nullptr) - s.problem->value(z - hh * d, nullptr)) /
             (2 * hh);
    };
    return (4.0 * central(0.5 * h) - central(h)) / 3.0;
  };
  // random directions (scaled like z) and a few coordinates
  std::mt19937_64 rng(2);
  std::normal_distribution<double> N(0.0, 1.0);
  const double zscale = std::max(1.0, z.cwiseAbs().maxCoeff());
  for (int trial = 0; trial < 4; ++trial) {
    Eigen::VectorXd d(z.size());
    for (Eigen::Index i = 0; i < d.size(); ++i) d(i) = N(rng);
    d /= d.norm();
    const double fd = derivative(d, hstep * zscale);
    EXPECT_NEAR(g.dot(d), fd, rtol * std::max(std::abs(fd), 1e-3 * g.norm()))
        << c.crit << " direction " << trial;
  }
  for (Eigen::Index i : {Eigen::Index(0), z.size() / 2, z.size() - 1}) {
    const Eigen::VectorXd e = Eigen::VectorXd::Unit(z.size(), i);
    const double fd = derivative(e, hstep * std::max(1.0, std::abs(z(i))));
    EXPECT_NEAR(g(i), fd, rtol * std::max(std::abs(fd), 1e-3 * g.cwiseAbs().maxCoeff()))
        << c.crit << " variable " << i;
  }
}

INSTANTIATE_TEST_SUITE_P(
    All, GradientTest,
    ::testing::Values(
        GradCase{"planar2r", "fourier", "{period_s: 4, harmonics: 3}", "cond"},
        GradCase{"planar2r", "fourier", "{period_s: 4, harmonics: 3}", "min_sv"},
        GradCase{"planar2r", "fourier", "{period_s: 4, harmonics: 3}", "frobenius_cond"},
        GradCase{"planar2r", "fourier", "{period_s: 4, harmonics: 3}", "log_det"},
        GradCase{"planar2r", "pointwise", "{duration_s: 4, sample_period_s: 0.05}", "cond",
                 "{period_s: 4, harmonics: 5, sample_period_s: 0.05}"},
        GradCase{"planar2r", "spline", "{duration_s: 4, knots: 6, degree: 5}", "log_det"},
        GradCase{"puma560", "fourier", "{period_s: 6, harmonics: 3, sample_period_s: 0.1}", "cond"},
        GradCase{"puma560", "fourier", "{period_s: 6, harmonics: 3, sample_period_s: 0.1}",
                 "min_sv"},
        GradCase{"puma560", "fourier", "{period_s: 6, harmonics: 3, sample_period_s: 0.1}",
                 "frobenius_cond"},
        GradCase{"puma560", "fourier", "{period_s: 6, harmonics: 3, sample_period_s: 0.1}",
                 "log_det"},
        GradCase{"puma560", "pointwise", "{duration_s: 4, sample_period_s: 0.05}", "cond",
                 "{period_s: 4, harmonics: 5, sample_period_s: 0.05}"},
        GradCase{"puma560", "pointwise", "{duration_s: 4, sample_period_s: 0.05}", "log_det",
                 "{period_s: 4, harmonics: 5, sample_period_s: 0.05}"}),
    [](const auto& param_info) {
      return param_info.param.robot + "_" + param_info.param.traj + "_" + param_info.param.crit;
    });

TEST(Limits, TheTrajectorysCapsArePartOfTheProblem) {
  // velocity_limit_rad_s reaches the excitation problem's g through Trajectory::adjustLimits
  // (the PUMA 560 description has no velocity limits); with velocity_limits: false the cap
  // alone is imposed. max g equals the violation recomputed from the samples.
  for (const char* vl : {"true", "false"}) {
    XSetup s = make("puma560", "fourier",
                    std::string("{period_s: 4, harmonics: 3, velocity_limit_rad_s: 0.5, "
                                "init_scale: 0.9, velocity_limits: ") +
                        vl + "}",
                    "cond", "{rotor_inertia: false, viscous: false, coulomb: false}");
    EXPECT_TRUE(s.traj->velocityLimits());
    const bool acc = s.traj->accelerationLimits();
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    const Eigen::VectorXd z0 = s.problem->initial();
    Eigen::VectorXd g;
    s.problem->constraints(z0, &g, nullptr);
    EXPECT_LE(g.maxCoeff(), 0.0);
    int violated = 0;
    for (int trial = 0; trial < 5; ++trial) {
      Eigen::VectorXd z = z0;
      for (Eigen::Index i = 0; i < z.size(); ++i) z(i) += 0.3 * U(rng);
      s.problem->constraints(z, &g, nullptr);
      const exid::Samples smp = s.traj->evaluate(z);
      const double v = violation(smp, *s.robot, 0, false, acc, 0.5);
      EXPECT_NEAR(std::max(0.0, g.maxCoeff()), v, 1e-12) << vl;
      violated += v > 0;
    }
    EXPECT_GT(violated, 0);
  }
}

TEST(Limits, OptimisersRespectTheCaps) {
  XSetup s = make("puma560", "fourier",
                  "{period_s: 4, harmonics: 3, velocity_limit_rad_s: 0.5, init_scale: 0.9}", "cond",
                  "{rotor_inertia: false, viscous: false, coulomb: false}");
  for (const char* p :
       {"{algorithm: LD_SLSQP}", "{algorithm: LD_SLSQP, constraint_mode: aggregated, starts: 2}"}) {
    auto opt = exid_test::create<exid::Optimizer>("nlopt", p);
    exid::RunContext ctx;
    auto r = opt->minimize(*s.problem, ctx);
    const exid::Samples best = s.traj->evaluate(r.z);
    EXPECT_LE(best.qd.cwiseAbs().maxCoeff(), 0.5 + 1e-9) << p;
    EXPECT_LE(violation(best, *s.robot, 0, true, true, 0.5), 1e-9) << p;
    EXPECT_LE(r.max_violation, 1e-9) << p;
    EXPECT_LT(r.criterion_final, r.criterion_initial) << p;
  }
}

struct OptCase {
  std::string optimizer, params, traj, tparams;
};

class OptimizerTest : public ::testing::TestWithParam<OptCase> {};

// The epigraph objective's constraints are eigenvalues of M(z): their gradients come from
// informationGradients with G = v v^T. Checked against central differences of the eigenvalue
// (simple eigenvalues at a random Fourier start), and <G, M> for a random symmetric G.
TEST(Excitation, EigenvalueGradientsMatchCentralDifferences) {
  XSetup s = make("puma560", "fourier", "{period_s: 6, harmonics: 3, sample_period_s: 0.1}");
  const Eigen::VectorXd z = s.problem->initial();
  const Eigen::MatrixXd M = s.problem->information(z);
  const int p = static_cast<int>(M.rows());
  ASSERT_EQ(p, s.model->numBase());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(M);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::MatrixXd R(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) R(i, j) = N(rng);
  const std::vector<int> which = {0, 1, p - 2, p - 1};
  std::vector<Eigen::MatrixXd> dM;
  for (int i : which) dM.push_back(es.eigenvectors().col(i) * es.eigenvectors().col(i).transpose());
  dM.push_back(R + R.transpose());
  const Eigen::MatrixXd G = s.problem->informationGradients(z, dM);
  ASSERT_EQ(G.rows(), z.size());
  ASSERT_EQ(G.cols(), 5);
  auto eig = [&](const Eigen::VectorXd& x, int i) {
    return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(s.problem->information(x),
                                                          Eigen::EigenvaluesOnly)
        .eigenvalues()(i);
  };
  auto inner = [&](const Eigen::VectorXd& x) {
    return (dM.back().array() * s.problem->information(x).array()).sum();
  };
  Eigen::VectorXd d(z.size());
  for (Eigen::Index i = 0; i < d.size(); ++i) d(i) = N(rng);
  d /= d.norm();
  const double h = 1e-4 * std::max(1.0, z.cwiseAbs().maxCoeff());
  for (std::size_t k = 0; k < which.size(); ++k) {
    const double fd = (eig(z + h * d, which[k]) - eig(z - h * d, which[k])) / (2 * h);
    EXPECT_NEAR(G.col(static_cast<Eigen::Index>(k)).dot(d), fd, 1e-5 * std::abs(fd) + 1e-9)
        << "eigenvalue " << which[k];
  }
  const double fd = (inner(z + h * d) - inner(z - h * d)) / (2 * h);
  EXPECT_NEAR(G.col(4).dot(d), fd, 1e-6 * std::abs(fd));
}

TEST(Nlopt, EpigraphObjectiveNeedsTheCondCriterion) {
  XSetup s =
      make("planar2r", "fourier", "{period_s: 4, harmonics: 3, sample_period_s: 0.05}", "log_det");
  auto opt =
      exid_test::create<exid::Optimizer>("nlopt", "{algorithm: LD_SLSQP, objective: epigraph}");
  exid::RunContext ctx;
  try {
    opt->minimize(*s.problem, ctx);
    FAIL() << "expected an error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("needs criterion 'cond'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("log_det"), std::string::npos) << e.what();
  }
}

TEST_P(OptimizerTest, ReducesCondAndReturnsAFeasiblePoint) {
  const auto& c = GetParam();
  XSetup s = make("planar2r", c.traj, c.tparams, "cond", "{}");
  auto opt = exid_test::create<exid::Optimizer>(c.optimizer, c.params);
  exid::RunContext ctx;
  ctx.seed = 3;
  std::vector<double> progress;
  ctx.progress = [&](double f, const std::string&) { progress.push_back(f); };
  const double J0 = s.problem->value(s.problem->initial(), nullptr);
  {
    Eigen::VectorXd g0;
    s.problem->constraints(s.problem->initial(), &g0, nullptr);
    ASSERT_LE(g0.maxCoeff(), 0.0) << "initial point infeasible";
  }
  auto r = opt->minimize(*s.problem, ctx);
  EXPECT_NEAR(r.criterion_initial, J0, 1e-9 * J0);
  // (the model has Coulomb columns sign(qd): J jumps where a sample velocity crosses zero)
  EXPECT_LT(r.criterion_final, 0.8 * J0) << c.optimizer << " " << c.params << ": J0 " << J0 << ", "
                                         << r.stop_reason << "; " << r.details.dump(0);
  // the reported value is the criterion at the returned point
  EXPECT_NEAR(s.problem->value(r.z, nullptr), r.criterion_final, 1e-9 * r.criterion_final);
  // feasible: recomputed from the trajectory at every sample
  const exid::Samples best = s.traj->evaluate(r.z);
  EXPECT_LE(violation(best, *s.robot, s.traj->positionMargin(), s.traj->velocityLimits(),
                      s.traj->accelerationLimits()),
            1e-9);
  EXPECT_LE(r.max_violation, 1e-9);
  EXPECT_GT(r.evaluations, 0);
  EXPECT_NE(r.stop_reason, exid::StopReason::None);
  ASSERT_FALSE(r.history_value.empty());
  EXPECT_EQ(r.history_value.size(), r.history_t_s.size());
  EXPECT_NEAR(r.history_value.back(), r.criterion_final, 1e-9 * r.criterion_final);
  for (std::size_t i = 1; i < r.history_value.size(); ++i)
    EXPECT_LE(r.history_value[i], r.history_value[i - 1]);
  EXPECT_FALSE(progress.empty());
}

const char* kFourier =
    "{period_s: 4, harmonics: 3, sample_period_s: 0.05, position_margin_rad: 0.1}";

INSTANTIATE_TEST_SUITE_P(
    All, OptimizerTest,
    ::testing::Values(
        OptCase{"nlopt", "{algorithm: LD_SLSQP}", "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: LD_MMA, max_evaluations: 300}", "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: LN_COBYLA, max_evaluations: 400}", "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: GN_ISRES, start_evaluations: 600, max_evaluations: 2000}",
                "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: GN_DIRECT_L, max_evaluations: 400}", "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: LD_SLSQP, starts: 3}", "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: LD_SLSQP, objective: epigraph}", "fourier", kFourier},
        OptCase{"nlopt",
                "{algorithm: LD_SLSQP, objective: log, constraint_mode: aggregated, "
                "polish_objective: epigraph, starts: 2}",
                "fourier", kFourier},
        OptCase{"nlopt", "{algorithm: LD_SLSQP}", "spline", "{duration_s: 4, knots: 6, degree: 5}"},
        OptCase{"adjoint_gradient", "{max_iterations: 400}", "fourier", kFourier},
        OptCase{"adjoint_gradient", "{step: paper, max_iterations: 300}", "fourier", kFourier},
        OptCase{"adjoint_gradient", "{constraints: penalty, max_iterations: 400}", "fourier",
                kFourier},
        OptCase{"adjoint_gradient", "{constraints: projection, max_iterations: 400}", "fourier",
                kFourier},
        OptCase{"adjoint_gradient", "{max_iterations: 400}", "pointwise",
                "{duration_s: 4, sample_period_s: 0.05}"},
        OptCase{"adjoint_gradient", "{step: paper, max_iterations: 300}", "pointwise",
                "{duration_s: 4, sample_period_s: 0.05}"}),
    [](const auto& param_info) {
      return param_info.param.optimizer + "_" + param_info.param.traj + "_" +
             std::to_string(param_info.index);
    });

TEST(Nlopt, UnknownAlgorithmListsTheValidOnes) {
  try {
    exid_test::create<exid::Optimizer>("nlopt", "{algorithm: LD_NOPE}");
    FAIL() << "no error";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("LD_NOPE"), std::string::npos) << m;
    EXPECT_NE(m.find("LD_SLSQP"), std::string::npos) << m;
    EXPECT_NE(m.find("GN_ISRES"), std::string::npos) << m;
  }
}

TEST(Optimizers, RespectTheTimeBudgetAndCancellation) {
  XSetup s = make("planar2r", "fourier", kFourier, "cond", "{}");
  for (const char* name : {"nlopt", "adjoint_gradient"}) {
    auto opt = exid_test::create<exid::Optimizer>(name, "{max_time_s: 0.3}");
    (void)opt;
  }
  auto opt = exid_test::create<exid::Optimizer>(
      "nlopt", "{algorithm: GN_ISRES, max_time_s: 0.3, max_evaluations: 0}");
  exid::RunContext ctx;
  // No evaluation budget: only the time budget can end this run, so its returning is the check
  // (a run that ignored it would hit ctest's timeout), whatever the machine's speed. It says
  // why, also when the polish after the time-cut global run converged: a time budget is not
  // reproducible.
  auto r = opt->minimize(*s.problem, ctx);
  EXPECT_EQ(r.stop_reason, exid::StopReason::MaxTime) << r.details.dump(0);
  EXPECT_LE(r.max_violation, 1e-9);
  int calls = 0;
  ctx.cancelled = [&] { return ++calls > 5; };
  auto opt2 = exid_test::create<exid::Optimizer>("adjoint_gradient", "{}");
  auto r2 = opt2->minimize(*s.problem, ctx);
  EXPECT_EQ(r2.stop_reason, exid::StopReason::Cancelled) << exid::stopReasonText(r2);
}

// The stop reasons read in summaries and reports: the texts of the enum, the feasibility note,
// and which of them depend on the machine's speed.
TEST(Optimizers, StopReasonTexts) {
  using exid::StopReason;
  const std::vector<std::pair<StopReason, std::string>> texts = {
      {StopReason::None, ""},
      {StopReason::Converged, "converged"},
      {StopReason::ConvergedFtol, "converged (ftol_rel)"},
      {StopReason::ConvergedGtol, "converged (gtol)"},
      {StopReason::MaxIterations, "max_iterations"},
      {StopReason::StartOnly, "max_iterations (0: start evaluated only)"},
      {StopReason::OuterPasses, "outer passes"},
      {StopReason::MaxEvaluations, "max_evaluations"},
      {StopReason::MaxTime, "max_time_s"},
      {StopReason::MaxCpu, "max_cpu_s"},
      {StopReason::Deadline, "deadline"},
      {StopReason::Cancelled, "cancelled"},
      {StopReason::NoProgress,
       "no progress (stopped at the start: its first search direction did not descend)"},
      {StopReason::ConvergedXtol, "converged (xtol_rel)"},
      {StopReason::Stalled, "stalled (no convergence test passed)"}};
  for (const auto& [r, text] : texts) {
    EXPECT_EQ(exid::toString(r), text);
    EXPECT_EQ(exid::stoppedByTime(r),
              r == StopReason::MaxTime || r == StopReason::MaxCpu || r == StopReason::Deadline)
        << text;
  }
  exid::OptimizerResult res;
  res.stop_reason = StopReason::MaxEvaluations;
  EXPECT_EQ(exid::stopReasonText(res), "max_evaluations");
  res.feasible = false;
  EXPECT_EQ(exid::stopReasonText(res),
            "max_evaluations (no feasible point found; least violation returned)");
}

// "converged" needs a step: NLopt's SLSQP returns FTOL_REACHED after its first evaluation when
// its first search direction does not descend (its relaxed ftol test compares the start with
// itself). From the palletiser's start below, on J itself, it does so (every CPU: the kernels'
// bits are the same on all): exid says "no progress", not "converged"; with objective: log the
// same start descends and the verdict is not "no progress". A run that converges after steps
// of its own is "converged".
TEST(Nlopt, ConvergedOnlyAfterAStep) {
  exid::RunContext ctx;
  ctx.seed = 1;
  auto robot = exid_test::robot("palletizer");
  auto model = exid_test::create<exid::ObservationModel>(
      "differential", "{rotor_inertia: true, coulomb: true, viscous: true, offset: true}");
  model->bind(robot, ctx);
  auto traj = exid_test::create<exid::Trajectory>("fourier", "{period_s: 4, harmonics: 2}");
  traj->bind(robot, ctx);
  exid::ExcitationOptions xo;
  xo.position_margin = traj->positionMargin();
  xo.velocity_limits = traj->velocityLimits();
  xo.acceleration_limits = traj->accelerationLimits();
  auto run = [&](const std::string& params) {
    auto problem = exid::makeExcitationProblem(
        traj, model, exid_test::create<exid::Criterion>("cond", "{}"), xo);
    return exid_test::create<exid::Optimizer>("nlopt", params)->minimize(*problem, ctx);
  };
  const exid::OptimizerResult stuck = run("{max_evaluations: 20}");
  EXPECT_EQ(stuck.stop_reason, exid::StopReason::NoProgress) << exid::toString(stuck.stop_reason);
  EXPECT_EQ(stuck.criterion_final, stuck.criterion_initial);
  const std::string said = stuck.details.dump();
  EXPECT_NE(said.find("NLopt's FTOL_REACHED after one evaluation"), std::string::npos) << said;
  const exid::OptimizerResult moved = run("{max_evaluations: 20, objective: log}");
  EXPECT_NE(moved.stop_reason, exid::StopReason::NoProgress);
  EXPECT_LT(moved.criterion_final, 0.1 * moved.criterion_initial);
  // converged after steps of its own: a short design on the planar 2R
  XSetup s = make("planar2r", "fourier", "{period_s: 4, harmonics: 2, sample_period_s: 0.05}");
  const exid::OptimizerResult done =
      exid_test::create<exid::Optimizer>("nlopt", "{max_evaluations: 500, objective: log}")
          ->minimize(*s.problem, ctx);
  EXPECT_TRUE(done.stop_reason == exid::StopReason::ConvergedFtol ||
              done.stop_reason == exid::StopReason::ConvergedXtol)
      << exid::toString(done.stop_reason);
  EXPECT_GT(done.evaluations, 2);
  EXPECT_LT(done.criterion_final, done.criterion_initial);
}

// nlopt's "converged" names the test NLopt ended the returned point's run on: "(ftol_rel)" where
// J changed by less than ftol_rel, "(xtol_rel)" where z moved by less than xtol_rel. A run cut
// by its share of the evaluations is not converged, though the budget is far from used (it said
// the generic "converged" after any run that was not cut by the whole budget).
TEST(Nlopt, ConvergedNamesTheTestThatEndedTheReturnedRun) {
  exid::RunContext ctx;
  ctx.seed = 1;
  XSetup s = make("planar2r", "fourier", "{period_s: 4, harmonics: 2, sample_period_s: 0.05}");
  auto run = [&](const std::string& params) {
    return exid_test::create<exid::Optimizer>("nlopt", params)->minimize(*s.problem, ctx);
  };
  const exid::OptimizerResult f =
      run("{max_evaluations: 500, objective: log, xtol_rel: 0, ftol_rel: 1e-3}");
  EXPECT_EQ(f.stop_reason, exid::StopReason::ConvergedFtol) << exid::toString(f.stop_reason);
  EXPECT_EQ(f.details.find("ending")->asString(), "FTOL_REACHED");
  const exid::OptimizerResult x =
      run("{max_evaluations: 500, objective: log, xtol_rel: 1e-2, ftol_rel: 0}");
  EXPECT_EQ(x.stop_reason, exid::StopReason::ConvergedXtol) << exid::toString(x.stop_reason);
  EXPECT_EQ(x.details.find("ending")->asString(), "XTOL_REACHED");
  const exid::OptimizerResult cut =
      run("{max_evaluations: 500, objective: log, starts: 2, start_evaluations: 6}");
  EXPECT_LT(cut.evaluations, 500);
  EXPECT_LT(cut.criterion_final, cut.criterion_initial);
  EXPECT_EQ(cut.stop_reason, exid::StopReason::MaxEvaluations) << exid::toString(cut.stop_reason);
  EXPECT_EQ(cut.details.find("ending")->asString(), "MAXEVAL_REACHED");
}

// A problem without constraints whose J is given (a wrapper of a real problem for its
// trajectory, model and criterion, which the optimisers may ask for): J = 1e6 + sum_i w_i f(z_i
// - c_i), f smooth (x^2) or with a kink at the minimum (|x|).
class GivenProblem : public exid::ExcitationProblem {
 public:
  // offset: the minimum c lies at the initial point plus offset in every coordinate
  GivenProblem(exid::ExcitationProblem& real, bool kink, double offset = 0.3)
      : real_(real), kink_(kink) {
    c_ = real.initial().array() + offset;
    w_ = Eigen::VectorXd::LinSpaced(c_.size(), 1.0, 10.0);
  }
  int numVariables() const override { return real_.numVariables(); }
  Eigen::VectorXd initial() const override { return real_.initial(); }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override {
    *lo = Eigen::VectorXd::Constant(numVariables(), -1e9);
    *hi = Eigen::VectorXd::Constant(numVariables(), 1e9);
  }
  double value(const Eigen::VectorXd& z, Eigen::VectorXd* grad) override {
    ++evaluations_;
    const Eigen::ArrayXd d = z - c_;
    if (grad) {
      if (kink_)
        *grad = (w_.array() * d.sign()).matrix();
      else
        *grad = (2.0 * w_.array() * d).matrix();
    }
    return 1e6 + (kink_ ? (w_.array() * d.abs()).sum() : (w_.array() * d.square()).sum());
  }
  Eigen::MatrixXd information(const Eigen::VectorXd& z) override { return real_.information(z); }
  Eigen::MatrixXd informationGradients(const Eigen::VectorXd& z,
                                       const std::vector<Eigen::MatrixXd>& dM) override {
    return real_.informationGradients(z, dM);
  }
  int numConstraints() const override { return 0; }
  void constraints(const Eigen::VectorXd&, Eigen::VectorXd* g, Eigen::MatrixXd* jac) override {
    if (g) g->resize(0);
    if (jac) jac->resize(0, numVariables());
  }
  const exid::Trajectory& trajectory() const override { return real_.trajectory(); }
  const exid::ObservationModel& model() const override { return real_.model(); }
  const exid::Criterion& criterion() const override { return real_.criterion(); }
  long evaluations() const override { return evaluations_; }

 private:
  exid::ExcitationProblem& real_;
  bool kink_;
  Eigen::VectorXd c_, w_;
  long evaluations_ = 0;
};

// adjoint_gradient says "converged (gtol)" only where its first-order test passed: on a smooth J
// it ends at a point whose projected gradient is within gtol max(1, |J|) and says so; on a J
// with a kink at its minimum its line search stops with the gradient's entries at w_i (1..10),
// and it says "converged (ftol_rel)" with how the pass ended, never "gtol".
TEST(AdjointGradient, ConvergedGtolOnlyWhereTheProjectedGradientIsWithinGtol) {
  XSetup s = make("planar2r", "fourier", kFourier, "cond", "{}");
  exid::RunContext ctx;
  ctx.seed = 3;
  const auto run = [&](bool kink) {
    GivenProblem p(*s.problem, kink);
    // one pass (no constraints: the run ends with its first pass's end)
    return exid_test::create<exid::Optimizer>("adjoint_gradient",
                                              "{max_iterations: 2000, inner_iterations: 2000}")
        ->minimize(p, ctx);
  };
  const exid::OptimizerResult smooth = run(false);
  ASSERT_TRUE(smooth.details.find("projected_gradient_max") &&
              smooth.details.find("stationarity_tol") && smooth.details.find("last_pass_end"))
      << smooth.details.dump();
  ASSERT_EQ(smooth.stop_reason, exid::StopReason::ConvergedGtol) << smooth.details.dump();
  const double pg = smooth.details.find("projected_gradient_max")->asDouble();
  const double tol = smooth.details.find("stationarity_tol")->asDouble();
  EXPECT_LE(pg, tol);
  EXPECT_NEAR(tol, 1e-8 * smooth.criterion_final, 1e-12);
  EXPECT_NE(smooth.details.find("last_pass_end")->asString().find("stationary"), std::string::npos);
  // within gtol of a convex quadratic's minimum: J - J* = sum_i g_i^2 / (4 w_i) <= n tol^2 / 4
  EXPECT_LE(smooth.criterion_final - 1e6, s.problem->numVariables() * tol * tol / 4.0);
  EXPECT_LT(smooth.criterion_final, smooth.criterion_initial);

  const exid::OptimizerResult kinked = run(true);
  ASSERT_TRUE(kinked.details.find("projected_gradient_max") &&
              kinked.details.find("stationarity_tol") && kinked.details.find("last_pass_end"))
      << kinked.details.dump();
  EXPECT_EQ(kinked.stop_reason, exid::StopReason::ConvergedFtol) << kinked.details.dump();
  EXPECT_GE(kinked.details.find("projected_gradient_max")->asDouble(), 1.0);
  EXPECT_GT(kinked.details.find("projected_gradient_max")->asDouble(),
            kinked.details.find("stationarity_tol")->asDouble());
  EXPECT_EQ(kinked.details.find("last_pass_end")->asString().find("stationary"), std::string::npos)
      << kinked.details.find("last_pass_end")->asString();
  EXPECT_LT(kinked.criterion_final, kinked.criterion_initial);
  EXPECT_LT(kinked.iterations, 2000);  // ended by its pass, not by the iterations
}

// sundials says "converged (gtol)" on the same rule (before, every ending of its pass without
// constraints was the generic "converged"). The real continuous criteria of the planar 2R,
// without constraints (GivenProblem's bounds and constraints; the real trajectory, model and
// criterion, which sundials integrates itself):
// - frobenius_cond (smooth) with gtol 1e-3: its L-BFGS reaches the test and says "gtol";
// - the same at the default gtol (1e-12 of the merit, below what CVODES's quadratures resolve):
//   the line search stops first, "converged (ftol_rel)", the gradient above the tolerance;
// - cond with gtol 1e-3: the line search stalls at a gradient of about 8 (cond is not smooth
//   where singular values meet), which it called "converged" before: "converged (ftol_rel)",
//   never "gtol".
TEST(Sundials, ConvergedGtolOnlyWhereTheProjectedGradientIsWithinGtol) {
  exid::RunContext ctx;
  const auto run = [&](const std::string& crit, const std::string& gtol, bool stationary) {
    XSetup s = make("planar2r", "fourier", kFourier, crit, "{}");
    GivenProblem p(*s.problem, false);
    const exid::OptimizerResult r =
        exid_test::create<exid::Optimizer>(
            "sundials", "{max_iterations: 400, inner_iterations: 400" + gtol + "}")
            ->minimize(p, ctx);
    ASSERT_TRUE(r.details.find("projected_gradient_max") && r.details.find("stationarity_tol") &&
                r.details.find("last_pass_end"))
        << r.details.dump();
    const double pg = r.details.find("projected_gradient_max")->asDouble();
    const double tol = r.details.find("stationarity_tol")->asDouble();
    const std::string end = r.details.find("last_pass_end")->asString();
    std::printf("[sundials] %s%s: %s, %d iterations, J %.6g -> %.6g, max|pg| %.3g, tol %.3g: %s\n",
                crit.c_str(), gtol.c_str(), exid::toString(r.stop_reason).c_str(), r.iterations,
                r.criterion_initial, r.criterion_final, pg, tol, end.c_str());
    EXPECT_LT(r.criterion_final, r.criterion_initial);
    EXPECT_LT(r.iterations, 400);  // ended by its pass, not by the iterations
    if (stationary) {
      EXPECT_EQ(r.stop_reason, exid::StopReason::ConvergedGtol) << end;
      EXPECT_LE(pg, tol);
      EXPECT_NE(end.find("stationary"), std::string::npos) << end;
    } else {
      EXPECT_EQ(r.stop_reason, exid::StopReason::ConvergedFtol) << end;
      EXPECT_GT(pg, tol);
      EXPECT_EQ(end.find("stationary"), std::string::npos) << end;
    }
  };
  run("frobenius_cond", ", gtol: 1.0e-3", true);
  run("frobenius_cond", "", false);
  run("cond", ", gtol: 1.0e-3", false);
}

}  // namespace

// NLopt's failure texts are said in exid's words, NLopt's own quoted, never as a bare
// "failure: bug: ..." (what `exid run` printed before).
TEST(NloptWords, AFailureIsSaidInExidsWords) {
  const std::string sqp = exid::optimizers::nloptFailureText("bug: more than iter SQP iterations");
  EXPECT_EQ(sqp.rfind("stopped: SLSQP's quadratic subproblem did not converge", 0), 0u) << sqp;
  EXPECT_NE(sqp.find("\"bug: more than iter SQP iterations\""), std::string::npos) << sqp;
  EXPECT_NE(sqp.find("the best point found so far is kept"), std::string::npos) << sqp;
  const std::string generic = exid::optimizers::nloptFailureText("nlopt failure");
  EXPECT_EQ(generic.find("nlopt failure"), std::string::npos) << generic;  // said, not quoted
  EXPECT_NE(generic.find("could not continue"), std::string::npos) << generic;
  const std::string other = exid::optimizers::nloptFailureText("nlopt invalid argument");
  EXPECT_EQ(other.rfind("stopped: NLopt failed (\"nlopt invalid argument\")", 0), 0u) << other;
  for (const std::string& t : {sqp, generic, other})
    EXPECT_EQ(t.find("failure: "), std::string::npos) << t;
}

// "stalled" where no run lowered the start's value though runs took steps: J's minimum is the
// initial point itself; the first start ends there at once ("no progress"), the second, from a
// perturbed point, steps towards it and ends above it. The point returned is the start, and no
// convergence test ended a run that produced it: neither "converged" nor "no progress".
TEST(Nlopt, StalledWhereNoRunLoweredTheStart) {
  exid::RunContext ctx;
  ctx.seed = 1;
  XSetup s = make("planar2r", "fourier", "{period_s: 4, harmonics: 2, sample_period_s: 0.05}");
  GivenProblem at_start(*s.problem, false, 0.0);
  const exid::OptimizerResult r =
      exid_test::create<exid::Optimizer>(
          "nlopt",
          "{max_evaluations: 500, starts: 2, start_mode: perturb, start_perturbation: 0.01}")
          ->minimize(at_start, ctx);
  EXPECT_EQ(r.stop_reason, exid::StopReason::Stalled)
      << exid::toString(r.stop_reason) << " " << r.details.dump();
  EXPECT_EQ(r.details.find("ending")->asString(), "no run lowered the start's value");
  EXPECT_EQ(r.criterion_final, r.criterion_initial);
  EXPECT_GT(r.evaluations, 3) << r.details.dump();  // the second start stepped
}
