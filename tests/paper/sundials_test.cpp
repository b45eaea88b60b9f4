// Optimizer `sundials` (continuous time, CVODES): the adjoint gradient against central finite
// differences of the same continuous criterion (fourier and spline, differential and load_wrench
// models; friction subtracted: the Coulomb column sign(qd) makes the continuous criterion depend
// on the zero-crossing times of qd, whose terms the adjoint adds (checked with the friction
// columns in sundials_scaled_test.cpp, with a larger step), the
// continuous criterion against the discrete one on a fine grid, and a short
// optimisation that lowers the criterion and keeps the limits.
#include <gtest/gtest.h>

#include <cstdlib>
#include <iostream>

#include "exid/excitation.hpp"
#include "exid_test.hpp"

namespace {

struct Problem {
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
  std::shared_ptr<exid::Criterion> crit;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

Problem make(const std::string& robot, const std::string& model, const std::string& model_params,
             const std::string& traj, const std::string& traj_params,
             const std::string& crit = "cond") {
  Problem s;
  auto r = exid_test::robot(robot);
  exid::RunContext ctx;
  s.traj = exid_test::create<exid::Trajectory>(traj, traj_params);
  s.traj->bind(r, ctx);
  s.model = exid_test::create<exid::ObservationModel>(model, model_params);
  // As the runner: joints the trajectory holds still restrict the model's base parameters.
  const exid::Json d = s.traj->describe();
  if (const exid::Json* js = d.find("joints"); js && static_cast<int>(js->size()) < r->dof()) {
    std::vector<int> moving;
    for (std::size_t i = 0; i < js->size(); ++i)
      moving.push_back(static_cast<int>(js->at(i).asInt()) - 1);
    s.model->restrictMotion(moving, s.traj->evaluate(s.traj->initial()).q.row(0).transpose());
  }
  s.model->bind(r, ctx);
  s.crit = exid_test::create<exid::Criterion>(crit);
  exid::ExcitationOptions xo;
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  s.problem = exid::makeExcitationProblem(s.traj, s.model, s.crit, xo);
  return s;
}

exid::OptimizerResult check(Problem& s, double tol, const char* fd_step = "1.0e-5") {
  auto opt = exid_test::create<exid::Optimizer>(
      "sundials",
      std::string("{max_iterations: 0, check_gradient: true, rtol: 1.0e-10, fd_step: ") +
          (std::getenv("EXID_FD_STEP") ? std::getenv("EXID_FD_STEP") : fd_step) + "}");
  exid::RunContext ctx;
  exid::OptimizerResult r = opt->minimize(*s.problem, ctx);
  const exid::Json* gc = r.details.find("gradient_check");
  EXPECT_TRUE(gc != nullptr);
  if (!gc) return r;
  const double rel = gc->find("max_rel_error")->asDouble();
  std::cout << "  adjoint vs FD: max rel error " << rel << " (max |grad| "
            << gc->find("max_abs_gradient")->asDouble()
            << "), cost J+grad / J = " << gc->find("cost_ratio")->asDouble() << ", J continuous "
            << r.criterion_initial << ", discrete "
            << r.details.find("discrete_criterion_initial")->asDouble() << "\n";
  EXPECT_LT(rel, tol);
  return r;
}

TEST(Sundials, AdjointGradientMatchesFiniteDifferencesFourierDifferential) {
  Problem s = make(
      "puma560", "differential", "{joints: [1, 2, 3], friction: subtract}", "fourier",
      "{period_s: 4, harmonics: 3, joints: [1, 2, 3], sample_period_s: 0.01, init_scale: 0.4}");
  auto r = check(s, 1e-4);
  // continuous (1/dt) int Phi Phi^T dt against the discrete sum on a 10 ms grid
  const double disc = r.details.find("discrete_criterion_initial")->asDouble();
  EXPECT_NEAR(r.criterion_initial / disc, 1.0, 0.02);
}

TEST(Sundials, AdjointGradientMatchesFiniteDifferencesSplineLogDet) {
  // A well-conditioned case: with cond(W) ~ 1e5 the quadrature error (rtol) is amplified by
  // cond(M) = cond(W)^2 and finite differences become meaningless.
  Problem s =
      make("puma560", "differential", "{joints: [1, 2, 3], friction: subtract}", "spline",
           "{duration_s: 3, knots: 6, joints: [1, 2, 3], sample_period_s: 0.01, init_scale: 0.6}",
           "log_det");
  // The spline's qdd has kinks at the knots, which the forward integration steps over: J then
  // carries ~1e-9 relative noise, which a central difference divides by its step. Measured (max
  // relative error of the adjoint gradient against central differences, step h relative):
  // h = 1e-5: 4.7e-3, 1e-4: 9.8e-4, 1e-3: 8.4e-5, 1e-2: 1.0e-4 (truncation) — the error falls
  // like 1/h, so it is the differences' noise, not the adjoint. Checked at h = 1e-3.
  check(s, 2e-4, "1.0e-3");
}

TEST(Sundials, AdjointGradientMatchesFiniteDifferencesLoadWrench) {
  Problem s =
      make("irp6", "load_wrench",
           "{payload_mass_kg: 2.0, payload_com_m: [0.01, -0.02, 0.08], "
           "payload_inertia_kg_m2: [0.004, 0.0, 0.0, 0.005, 0.0, 0.003]}",
           "fourier", "{period_s: 4, harmonics: 2, sample_period_s: 0.02, init_scale: 0.3}");
  check(s, 1e-4);
}

TEST(Sundials, OptimisationLowersTheCriterionWithinLimits) {
  Problem s = make("puma560", "differential", "{joints: [1, 2, 3]}", "fourier",
                   "{period_s: 2, harmonics: 2, joints: [1, 2, 3], sample_period_s: 0.02, "
                   "init_scale: 0.3, velocity_limit_rad_s: 2.0}");
  auto opt = exid_test::create<exid::Optimizer>("sundials", "{max_iterations: 15}");
  exid::RunContext ctx;
  const auto r = opt->minimize(*s.problem, ctx);
  std::cout << "  sundials: " << r.criterion_initial << " -> " << r.criterion_final << " in "
            << r.iterations << " iterations, " << r.evaluations << " evaluations, " << r.wall_s
            << " s, " << r.stop_reason << "\n";
  EXPECT_LT(r.criterion_final, 0.8 * r.criterion_initial);
  EXPECT_LE(r.max_violation, 1e-9);
  EXPECT_FALSE(r.history_value.empty());
  EXPECT_LE(r.iterations,
            15);  // the budget is iterations, never seconds (bench_excitation times it)
}

TEST(Sundials, RefusesPointwiseAndWindowModels) {
  Problem s =
      make("planar2r", "differential", "{}", "pointwise", "{duration_s: 1, sample_period_s: 0.05}");
  auto opt = exid_test::create<exid::Optimizer>("sundials", "{max_iterations: 1}");
  exid::RunContext ctx;
  EXPECT_THROW(opt->minimize(*s.problem, ctx), exid::Error);
  Problem w = make("planar2r", "integral", "{window_s: 0.2}", "fourier",
                   "{period_s: 2, harmonics: 2, sample_period_s: 0.02}");
  EXPECT_THROW(opt->minimize(*w.problem, ctx), exid::Error);
}

}  // namespace
