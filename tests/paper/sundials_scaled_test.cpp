// Optimizer `sundials`: the adjoint gradient of the spectral criteria with and without
// `scale_columns` against central differences computed HERE, outside the optimiser's own check:
// the continuous criterion J(z0 + h e_i) is the optimiser's criterion_initial for a problem that
// starts at z0 + h e_i (max_iterations: 0). log_det's scaled gradient equals its unscaled one
// (-log det(S M S) = -log det M - 2 log det S, S constant).
#include <gtest/gtest.h>

#include <cstdlib>
#include <iostream>

#include "exid/excitation.hpp"
#include "exid_test.hpp"

namespace {

/// An excitation problem that starts where it is told (everything else forwarded).
class StartAt final : public exid::ExcitationProblem {
 public:
  StartAt(exid::ExcitationProblem& p, Eigen::VectorXd z0) : p_(p), z0_(std::move(z0)) {}
  int numVariables() const override { return p_.numVariables(); }
  Eigen::VectorXd initial() const override { return z0_; }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override { p_.bounds(lo, hi); }
  double value(const Eigen::VectorXd& z, Eigen::VectorXd* g) override { return p_.value(z, g); }
  Eigen::MatrixXd information(const Eigen::VectorXd& z) override { return p_.information(z); }
  Eigen::MatrixXd informationGradients(const Eigen::VectorXd& z,
                                       const std::vector<Eigen::MatrixXd>& dM) override {
    return p_.informationGradients(z, dM);
  }
  int numConstraints() const override { return p_.numConstraints(); }
  void constraints(const Eigen::VectorXd& z, Eigen::VectorXd* g, Eigen::MatrixXd* jac) override {
    p_.constraints(z, g, jac);
  }
  int numNonlinearConstraints() const override { return p_.numNonlinearConstraints(); }
  void nonlinearConstraints(const Eigen::VectorXd& z, Eigen::VectorXd* g,
                            Eigen::MatrixXd* jac) override {
    p_.nonlinearConstraints(z, g, jac);
  }
  const exid::Trajectory& trajectory() const override { return p_.trajectory(); }
  const exid::ObservationModel& model() const override { return p_.model(); }
  const exid::Criterion& criterion() const override { return p_.criterion(); }
  long evaluations() const override { return p_.evaluations(); }

 private:
  exid::ExcitationProblem& p_;
  Eigen::VectorXd z0_;
};

struct Problem {
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
  std::shared_ptr<exid::Criterion> crit;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

Problem make(const std::string& crit, bool scaled) {
  Problem s;
  auto r = exid_test::robot("puma560");
  exid::RunContext ctx;
  s.traj = exid_test::create<exid::Trajectory>(
      "fourier",
      "{period_s: 4, harmonics: 2, joints: [1, 2, 3], sample_period_s: 0.01, init_scale: 0.4}");
  s.traj->bind(r, ctx);
  // The model's own friction columns: Coulomb sign(qd) jumps where a velocity changes sign.
  s.model = exid_test::create<exid::ObservationModel>("differential", "{joints: [1, 2, 3]}");
  s.model->restrictMotion({0, 1, 2}, s.traj->evaluate(s.traj->initial()).q.row(0).transpose());
  s.model->bind(r, ctx);
  s.crit = exid_test::create<exid::Criterion>(
      crit, std::string("{scale_columns: ") + (scaled ? "true" : "false") + "}");
  exid::ExcitationOptions xo;  // as the runner
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  xo.scale_columns = s.crit->specs().scale_columns;
  s.problem = exid::makeExcitationProblem(s.traj, s.model, s.crit, xo);
  return s;
}

const char* kOptions = "max_iterations: 0, rtol: 1.0e-10";
// Central differences of a criterion whose integrand jumps (at the velocity zero crossings) are
// good to about 1e-4 here with a step of 1e-2 (the quadrature steps over the jumps: smaller
// steps see that noise); the gradient without the crossings' terms is 2-30 % off.
constexpr double kTolerance = 2e-3;

/// The adjoint gradient at the start (the optimiser's check_gradient details) and its own
/// relative error.
Eigen::VectorXd adjoint(exid::ExcitationProblem& p, double* own_rel) {
  auto opt = exid_test::create<exid::Optimizer>(
      "sundials", std::string("{") + kOptions + ", check_gradient: true, fd_step: 1.0e-2}");
  exid::RunContext ctx;
  const exid::OptimizerResult r = opt->minimize(p, ctx);
  const exid::Json& gc = *r.details.find("gradient_check");
  *own_rel = gc.find("max_rel_error")->asDouble();
  const exid::Json& a = *gc.find("adjoint");
  Eigen::VectorXd g(static_cast<Eigen::Index>(a.size()));
  for (std::size_t i = 0; i < a.size(); ++i) g(static_cast<Eigen::Index>(i)) = a.at(i).asDouble();
  return g;
}

/// The continuous criterion at z: criterion_initial of a start at z.
double J(exid::ExcitationProblem& p, const Eigen::VectorXd& z) {
  auto opt = exid_test::create<exid::Optimizer>("sundials", std::string("{") + kOptions + "}");
  StartAt at(p, z);
  exid::RunContext ctx;
  return opt->minimize(at, ctx).criterion_initial;
}

/// Central differences of J, relative steps h (max(1, |z_i|)).
Eigen::VectorXd differences(exid::ExcitationProblem& p, const Eigen::VectorXd& z, double h) {
  Eigen::VectorXd d(z.size());
  for (Eigen::Index i = 0; i < z.size(); ++i) {
    const double hi = h * std::max(1.0, std::abs(z(i)));
    Eigen::VectorXd zp = z, zm = z;
    zp(i) += hi;
    zm(i) -= hi;
    d(i) = (J(p, zp) - J(p, zm)) / (2 * hi);
  }
  return d;
}

double relError(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff());
}

void expectMatches(const std::string& crit, bool scaled) {
  Problem s = make(crit, scaled);
  const Eigen::VectorXd z0 = s.problem->initial();
  double own = 0;
  const Eigen::VectorXd g = adjoint(*s.problem, &own);
  const Eigen::VectorXd d = differences(*s.problem, z0, 1e-2);
  const double rel = relError(g, d);
  std::cout << "  " << crit << (scaled ? " scaled" : " unscaled") << ": adjoint vs central "
            << "differences here " << rel << ", the optimiser's own check " << own << "\n";
  EXPECT_LT(rel, kTolerance) << crit << (scaled ? " scaled" : " unscaled");
  EXPECT_LT(own, kTolerance) << crit << (scaled ? " scaled" : " unscaled");
}

TEST(SundialsScaled, CondGradientMatchesDifferences) {
  expectMatches("cond", false);
  expectMatches("cond", true);
}
TEST(SundialsScaled, MinSvGradientMatchesDifferences) {
  expectMatches("min_sv", false);
  expectMatches("min_sv", true);
}
TEST(SundialsScaled, LogDetGradientMatchesDifferences) {
  expectMatches("log_det", false);
  expectMatches("log_det", true);
}

TEST(SundialsScaled, LogDetScaledGradientIsTheUnscaledOne) {
  Problem a = make("log_det", false), b = make("log_det", true);
  double own = 0;
  const Eigen::VectorXd ga = adjoint(*a.problem, &own), gb = adjoint(*b.problem, &own);
  const double rel = relError(ga, gb);
  std::cout << "  log_det scaled vs unscaled adjoint gradient: " << rel << "\n";
  EXPECT_LT(rel, 2e-4);  // the two integrations step over the jumps differently
}

}  // namespace
