// TEMPLATE (optimizer): a seeded random search with an evaluation budget, a (1+1) strategy:
// perturb the best point by U(-1, 1) times `step` times the bound range, clip to the bounds,
// keep the candidate when it is feasible (g(z) <= feasibility_tol) and better; the step doubles
// on success and shrinks by 0.84 on failure (about one success in five keeps it). Infeasible
// candidates are discarded before the criterion is evaluated, so only feasible points are kept
// (from an infeasible start the least violation is sought first). No gradient is used.
// Shows: the ExcitationProblem interface (initial, bounds, value, constraints) and the installed
// optimiser helpers (exid::optimizers_common, "exid/optimizers/optim_common.hpp"): the standard
// budget parameters, Limits (g(z)), Tracker (best feasible point, history, budgets, deadline,
// cancellation) and a proper OptimizerResult with its StopReason.
// To make it yours: change how a candidate is drawn and accepted in minimize().
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/optimizers/optim_common.hpp"

namespace {

class TemplateRandomSearch final : public exid::Optimizer {
 public:
  static constexpr const char* kName = "template_random_search";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "seeded (1+1) random search within the bounds, feasible points only, evaluation budget "
      "(out-of-tree template)";
  static std::vector<exid::ParamDecl> params() {
    auto p =
        exid::optimizers::budgetParams(0.0, 500);  // max_time_s, max_cpu_s, max_evaluations, ...
    p.push_back(exid::param_int("seed", 0, "random seed (0: the study seed)", 0.0));
    p.push_back(exid::param_double("initial_step", 0.1, "",
                                   "first step as a fraction of each variable's bound range", 0.0,
                                   1.0, true));
    p.push_back(exid::param_double("min_step", 1e-6, "", "stop (converged) below this step", 0.0,
                                   1.0, true));
    p.push_back(exid::param_int("max_iterations", 100000,
                                "candidates drawn at most (infeasible ones included)", 1.0));
    return p;
  }
  explicit TemplateRandomSearch(const exid::ParamSet& p)
      : budget_(exid::optimizers::readBudget(p)),
        seed_(static_cast<std::uint64_t>(p.getInt("seed"))),
        step0_(p.getDouble("initial_step")),
        min_step_(p.getDouble("min_step")),
        max_iter_(static_cast<int>(p.getInt("max_iterations"))) {}

  exid::OptimizerResult minimize(exid::ExcitationProblem& problem,
                                 const exid::RunContext& ctx) override {
    const std::string who = fmt::format("optimizer '{}'", kName);
    exid::optimizers::Limits limits(problem);  // g(z) <= 0: joint, velocity, acceleration, torque
    exid::optimizers::Tracker tracker(problem, limits, ctx, budget_, who);
    Eigen::VectorXd lo, hi;  // the bounds, infinite ones replaced by z0 -+ max(1, |z0_i|)
    const Eigen::VectorXd z0 = problem.initial();
    exid::optimizers::finiteBounds(problem, z0, 1.0, &lo, &hi);
    const Eigen::VectorXd range = hi - lo;
    const double J0 = tracker.evaluateAndOffer(z0);
    std::mt19937_64 rng(seed_ ? seed_ : ctx.seed);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    double step = step0_;
    long accepted = 0, infeasible = 0;
    int it = 0;
    exid::StopReason stop = exid::StopReason::None;
    for (;; ++it) {
      if ((stop = tracker.stopCause()) != exid::StopReason::None) break;  // budget, deadline
      if (it >= max_iter_) {
        stop = exid::StopReason::MaxIterations;
        break;
      }
      if (step < min_step_) {
        stop = exid::StopReason::Converged;
        break;
      }
      // the centre: the best point so far (z0 while none has a finite criterion)
      const Eigen::VectorXd best = tracker.best().size() ? tracker.best() : z0;
      Eigen::VectorXd z = best;
      for (Eigen::Index i = 0; i < z.size(); ++i)
        z(i) = std::clamp(z(i) + step * range(i) * U(rng), lo(i), hi(i));
      const double violation = limits.maxViolation(z);
      bool better = false;
      if (violation <= budget_.feasibility_tol || !tracker.hasFeasible()) {
        double J = HUGE_VAL;
        try {
          J = problem.value(z, nullptr);  // one evaluation of the budget
        } catch (const exid::Error&) {    // e.g. a singular information matrix: not a candidate
        }
        tracker.offer(z, J, violation);
        better = tracker.best().size() == best.size() && tracker.best() != best;
      } else {
        ++infeasible;  // discarded without evaluating the criterion
      }
      accepted += better;
      step = better ? std::min(1.0, 2.0 * step) : 0.84 * step;
      if (it % 100 == 0) tracker.progress(fmt::format("step {:.3g}", step));
    }
    exid::OptimizerResult r = tracker.finish(J0, it, stop);  // z, values, violation, history
    r.details["algorithm"] = "(1+1) random search, step doubled on success, x0.84 on failure";
    r.details["seed"] = exid::Json(static_cast<long long>(seed_ ? seed_ : ctx.seed));
    r.details["accepted"] = exid::Json(static_cast<long long>(accepted));
    r.details["discarded_infeasible"] = exid::Json(static_cast<long long>(infeasible));
    r.details["final_step"] = step;
    return r;
  }

 private:
  exid::optimizers::Budget budget_;
  std::uint64_t seed_;
  double step0_, min_step_;
  int max_iter_;
};

}  // namespace

EXID_REGISTER_PLUGIN(TemplateRandomSearch)
