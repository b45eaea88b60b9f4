// Optimizer `nlopt`: any NLopt 2.7 algorithm by name on the excitation problem
//   min J(z)  s.t.  g(z) <= 0 (limits at every sample; NLopt vector inequality constraint with
//   the exact Jacobian), lo <= z <= hi,
// with the exact gradient J'(z) (reverse accumulation through criterion, model and trajectory;
// for `pointwise` the costate recursion). Multi-start from perturbed initial points; global
// algorithms are followed by a local polish (local_algorithm, default LD_SLSQP). Algorithms that
// do not take nonlinear constraints run inside NLopt's augmented Lagrangian (AUGLAG). The best
// FEASIBLE point seen at any evaluation is returned.
#include <fmt/format.h>
#include <nlopt.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <nlopt.hpp>
#include <random>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/fmath.hpp"
#include "exid/optimizers/optim_common.hpp"

namespace {

using exid::optimizers::Limits;
using exid::optimizers::Tracker;

std::string validNames() {
  std::string s;
  for (int a = 0; a < NLOPT_NUM_ALGORITHMS; ++a) {
    const char* name = nlopt_algorithm_to_string(static_cast<nlopt_algorithm>(a));
    if (!name) continue;
    if (!s.empty()) s += ", ";
    s += name;
  }
  return s;
}

nlopt::algorithm algorithmFromName(const std::string& name, const char* param) {
  const nlopt_algorithm a = nlopt_algorithm_from_string(name.c_str());
  exid::check(static_cast<int>(a) >= 0 && static_cast<int>(a) < NLOPT_NUM_ALGORITHMS,
              fmt::format("optimizer 'nlopt': {}: unknown NLopt algorithm '{}'; valid: {}", param,
                          name, validNames()));
  return static_cast<nlopt::algorithm>(a);
}

bool isGlobal(const std::string& name) {
  return name.rfind("GN_", 0) == 0 || name.rfind("GD_", 0) == 0 || name.rfind("G_", 0) == 0;
}

struct Ctx {
  exid::ExcitationProblem* p;
  Limits* lim;
  Tracker* tr;
  double tighten;
  int slots = 0;  // per group of K samples: the `slots` largest g values (0: every sample)
  const std::vector<int>* rows = nullptr;  // working set: only these rows of g
  double ks_rho = 0;                       // > 0: one Kreisselmeier-Steinhauser aggregate per group
  bool log_objective = false;
  int epigraph_k = 0;  // > 0: epigraph form of log cond with this many eigenvalues at each end
  double wall_end = HUGE_VAL, cpu_end = HUGE_VAL;  // this run's share of the budget
  long evals = 0;
};

bool runOver(const Ctx* c) {
  return c->tr->shouldStop() || c->tr->elapsed() >= c->wall_end ||
         c->tr->cpuElapsed() >= c->cpu_end;
}

// Number of constraints NLopt sees.
int nloptConstraints(const Limits& lim, int slots, double ks_rho) {
  if (lim.size() == 0) return 0;
  if (ks_rho > 0) return lim.groups();
  if (slots <= 0 || slots >= lim.samples()) return lim.size();
  return lim.groups() * slots;
}

double objective(unsigned n, const double* x, double* grad, void* data) {
  auto* c = static_cast<Ctx*>(data);
  if (runOver(c)) throw nlopt::forced_stop();
  Eigen::Map<const Eigen::VectorXd> z(x, n);
  Eigen::VectorXd zz = z, g;
  double J;
  bool failed = false;
  try {
    J = c->p->value(zz, grad ? &g : nullptr);
  } catch (const exid::Error&) {
    J = 1e30;  // singular information matrix: a very bad point for NLopt...
    g = Eigen::VectorXd::Zero(n);
    failed = true;
  }
  // ...but never a result: the tracker ignores non-finite values (a least-violation point that
  // could not be evaluated must not be returned with the stand-in 1e30)
  c->tr->offer(zz, failed ? HUGE_VAL : J, c->lim->maxViolation(zz));
  ++c->evals;
  if (c->log_objective && J > 0 && J < 1e30) {
    // log J: the same minimisers, better scaled (cond spans decades between starts and optima)
    if (grad) Eigen::Map<Eigen::VectorXd>(grad, n) = g / J;
    return exid::fmath::log(J);
  }
  if (grad) Eigen::Map<Eigen::VectorXd>(grad, n) = g;
  return J;
}

void mconstraint(unsigned m, double* result, unsigned n, const double* x, double* grad,
                 void* data) {
  auto* c = static_cast<Ctx*>(data);
  Eigen::Map<const Eigen::VectorXd> z(x, n);
  Eigen::VectorXd zz = z, g;
  c->lim->eval(zz, &g);
  using RM = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  if (c->rows) {
    const Eigen::MatrixXd* J = grad ? &c->lim->jacobian(zz) : nullptr;
    for (unsigned i = 0; i < m; ++i) {
      const int row = (*c->rows)[i];
      result[i] = g(row) + c->tighten;
      if (grad)
        Eigen::Map<Eigen::RowVectorXd>(grad + static_cast<std::ptrdiff_t>(i) * n, n) = J->row(row);
    }
    return;
  }
  if (c->ks_rho > 0) {
    // Kreisselmeier-Steinhauser aggregate per group (one limit of one joint over the K samples):
    // KS = max + log(sum exp(rho (g_i - max))) / rho, smooth, and max <= KS <= max + log(K)/rho,
    // so KS <= 0 implies g <= 0 at every sample (conservative by at most log(K)/rho).
    const int K = c->lim->samples();
    const double rho = c->ks_rho;
    const Eigen::MatrixXd* J = grad ? &c->lim->jacobian(zz) : nullptr;
    Eigen::VectorXd w(K);
    for (int grp = 0; grp < c->lim->groups(); ++grp) {
      auto gg = g.segment(static_cast<Eigen::Index>(grp) * K, K);
      const double gmax = gg.maxCoeff();
      for (int k = 0; k < K; ++k) w(k) = exid::fmath::exp((gg(k) - gmax) * rho);
      const double S = w.sum();
      result[grp] = gmax + exid::fmath::log(S) / rho + c->tighten;
      if (grad)
        Eigen::Map<Eigen::RowVectorXd>(grad + static_cast<std::ptrdiff_t>(grp) * n, n) =
            (w / S).transpose() * J->middleRows(static_cast<Eigen::Index>(grp) * K, K);
    }
    return;
  }
  if (static_cast<int>(m) == c->lim->size()) {
    Eigen::Map<Eigen::VectorXd>(result, m) = g.array() + c->tighten;
    if (grad) Eigen::Map<RM>(grad, m, n) = c->lim->jacobian(zz);
    return;
  }
  // Order statistics per group (one limit of one joint over the K samples): slot i holds the
  // i-th largest g of the group. Slot 0 is the group's maximum, so g <= 0 at every sample iff
  // every slot is <= 0; the values are continuous in z, differentiable almost everywhere.
  const int K = c->lim->samples(), r = c->slots;
  const Eigen::MatrixXd* J = grad ? &c->lim->jacobian(zz) : nullptr;
  std::vector<int> idx(static_cast<std::size_t>(K));
  for (int grp = 0; grp < c->lim->groups(); ++grp) {
    for (int k = 0; k < K; ++k) idx[static_cast<std::size_t>(k)] = grp * K + k;
    std::partial_sort(idx.begin(), idx.begin() + r, idx.end(),
                      [&](int a, int b) { return g(a) > g(b); });
    for (int i = 0; i < r; ++i) {
      const int row = idx[static_cast<std::size_t>(i)], out = grp * r + i;
      result[out] = g(row) + c->tighten;
      if (grad)
        Eigen::Map<Eigen::RowVectorXd>(grad + static_cast<std::ptrdiff_t>(out) * n, n) =
            J->row(row);
    }
  }
}

// ---------------------------------------------------------------- epigraph form of log cond
// Variables x = [z; a; b]. cond(W) = sqrt(lambda_max / lambda_min) of M = W^T W, so
//   min log cond  <=>  min (a - b) / 2  s.t.  log lambda_i(M(z)) <= a  (the k largest),
//                                             log lambda_i(M(z)) >= b  (the k smallest).
// Each constraint is one eigenvalue, smooth while it is simple; where the extreme eigenvalues
// coalesce (as they do at the optimum of cond) the max is not differentiable but every
// eigenvalue involved is its own constraint, so the SQP model sees the whole cluster instead of
// one arbitrary eigenvector of it (Overton's approach to eigenvalue optimisation).
double epiObjective(unsigned n2, const double* x, double* grad, void* data) {
  auto* c = static_cast<Ctx*>(data);
  if (runOver(c)) throw nlopt::forced_stop();
  const unsigned n = n2 - 2;
  if (grad) {
    std::fill(grad, grad + n, 0.0);
    grad[n] = 0.5;
    grad[n + 1] = -0.5;
  }
  return 0.5 * (x[n] - x[n + 1]);
}

void epiEigen(unsigned m, double* result, unsigned n2, const double* x, double* grad, void* data) {
  auto* c = static_cast<Ctx*>(data);
  if (runOver(c)) throw nlopt::forced_stop();
  const unsigned n = n2 - 2;
  const int k = static_cast<int>(m) / 2;
  const Eigen::VectorXd z = Eigen::Map<const Eigen::VectorXd>(x, n);
  const Eigen::MatrixXd M = c->p->information(z);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(M);
  const Eigen::VectorXd& lam = es.eigenvalues();  // ascending
  const auto p = static_cast<int>(lam.size());
  const double floor = 1e-300;
  const double J = lam(0) > 0.0 ? std::sqrt(lam(p - 1) / lam(0)) : 1e30;
  c->tr->offer(z, J, c->lim->maxViolation(z));
  ++c->evals;
  // rows 0..k-1: log lambda_(p-1-i) - a <= 0; rows k..2k-1: b - log lambda_i <= 0
  std::vector<Eigen::MatrixXd> dM;
  for (int i = 0; i < k; ++i) {
    const int top = p - 1 - i;
    result[i] = exid::fmath::log(std::max(lam(top), floor)) - x[n] + c->tighten;
    result[k + i] = x[n + 1] - exid::fmath::log(std::max(lam(i), floor)) + c->tighten;
    if (grad) {
      dM.push_back(es.eigenvectors().col(top) * es.eigenvectors().col(top).transpose());
    }
  }
  if (!grad) return;
  for (int i = 0; i < k; ++i)
    dM.push_back(es.eigenvectors().col(i) * es.eigenvectors().col(i).transpose());
  const Eigen::MatrixXd G = c->p->informationGradients(z, dM);
  for (int r = 0; r < 2 * k; ++r) {
    double* row = grad + static_cast<std::ptrdiff_t>(r) * n2;
    const bool upper = r < k;
    const int idx = upper ? p - 1 - r : r - k;
    const double inv = 1.0 / std::max(lam(idx), floor);
    Eigen::Map<Eigen::RowVectorXd>(row, n) = (upper ? inv : -inv) * G.col(r).transpose();
    row[n] = upper ? -1.0 : 0.0;
    row[n + 1] = upper ? 0.0 : 1.0;
  }
}

void mconstraint(unsigned m, double* result, unsigned n, const double* x, double* grad, void* data);

// The limits of z in the epigraph variables: the same constraints, zero columns for a and b.
void epiLimits(unsigned m, double* result, unsigned n2, const double* x, double* grad, void* data) {
  const unsigned n = n2 - 2;
  if (!grad) return mconstraint(m, result, n, x, nullptr, data);
  std::vector<double> g(static_cast<std::size_t>(m) * n);
  mconstraint(m, result, n, x, g.data(), data);
  for (unsigned i = 0; i < m; ++i) {
    std::copy(g.begin() + static_cast<std::ptrdiff_t>(i) * n,
              g.begin() + static_cast<std::ptrdiff_t>(i + 1) * n,
              grad + static_cast<std::ptrdiff_t>(i) * n2);
    grad[static_cast<std::ptrdiff_t>(i) * n2 + n] = 0.0;
    grad[static_cast<std::ptrdiff_t>(i) * n2 + n + 1] = 0.0;
  }
}

class NloptOptimizer final : public exid::Optimizer {
 public:
  static constexpr const char* kName = "nlopt";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "NLopt 2.7, any algorithm by name (LD_SLSQP default, LD_MMA, LN_COBYLA, GN_ISRES, "
      "GN_DIRECT_L, G_MLSL_LDS, ...), exact gradient and constraint Jacobian, multi-start, "
      "local polish after global algorithms, best feasible point returned";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::optimizers::budgetParams(0.0, 20000);
    p.push_back(exid::param_string(
        "algorithm", std::string("LD_SLSQP"),
        "NLopt algorithm name (NLOPT_ prefix dropped); an unknown name lists the valid ones"));
    p.push_back(exid::param_string(
        "local_algorithm", std::string("LD_SLSQP"),
        "local algorithm for the polish after a global one (and MLSL's local searches)"));
    p.push_back(exid::param_bool(
        "polish", true, "after a global algorithm, polish its best point with local_algorithm"));
    p.push_back(exid::param_int(
        "starts", 1, "starts: the initial point, then perturbed ones; the best feasible is kept",
        1.0));
    p.push_back(
        exid::param_string("start_mode", std::string("random"),
                           "later starts: random — from the centre of the bound box along a "
                           "random direction, start_perturbation times the largest feasible "
                           "step; perturb — the initial point plus start_perturbation times "
                           "half the bound range, pulled back towards it until feasible",
                           {"random", "perturb"}));
    p.push_back(exid::param_double("start_perturbation", 0.5, "", "see start_mode", 0.0));
    p.push_back(exid::param_int(
        "seed", 0, "nlopt::srand and the start perturbations (0: the study seed)", 0.0));
    p.push_back(exid::param_double("xtol_rel", 1e-6, "", "relative tolerance on z (0: off)", 0.0));
    p.push_back(exid::param_double("ftol_rel", 1e-9, "", "relative tolerance on J (0: off)", 0.0));
    p.push_back(exid::param_double(
        "bound_scale", 2.0, "",
        "global algorithms: infinite bounds become z0 -+ bound_scale max(1, |z0_i|)", 0.0,
        std::nullopt, true));
    p.push_back(
        exid::param_double("constraint_tightening", 1e-7, "rad",
                           "the optimiser sees g(z) + this <= 0, so that its nearly-feasible "
                           "iterates are feasible",
                           0.0));
    p.push_back(
        exid::param_string("constraint_mode", std::string("all"),
                           "how g reaches NLopt: all — every sample; slots — per limit and "
                           "joint the constraint_slots largest values; working_set — rows "
                           "within working_set_margin of their limit, grown and re-run "
                           "while the result violates others (the returned point is always "
                           "checked at every sample); aggregated — per limit and joint one "
                           "smooth Kreisselmeier-Steinhauser aggregate of the K samples "
                           "(conservative: KS <= 0 implies every sample within its limit), "
                           "then a polish of the best point with every sample (final_polish)",
                           {"all", "slots", "working_set", "aggregated"}));
    p.push_back(
        exid::param_double("ks_rho", 100.0, "1/rad",
                           "aggregated: KS sharpness rho; the aggregate exceeds the largest "
                           "g by at most log(K)/rho (limits in rad, rad/s, rad/s^2)",
                           0.0, std::nullopt, true));
    p.push_back(exid::param_double("final_polish", 0.1, "",
                                   "aggregated: share of the budget kept for polishing the best "
                                   "point with every sample's constraint (0: none)",
                                   0.0, 0.9));
    p.push_back(exid::param_string(
        "objective", std::string("value"),
        "what NLopt minimises: value — J; log — log J (same minimisers, better scaled for "
        "cond); epigraph — criterion cond only: (a - b)/2 over [z; a; b] with log lambda_i(M) "
        "<= a for the epigraph_eigenvalues largest and >= b for as many smallest eigenvalues "
        "of M = W^T W (smooth where cond is not: coalescing extreme eigenvalues); the "
        "reported criterion is J",
        {"value", "log", "epigraph"}));
    p.push_back(exid::param_string(
        "polish_objective", std::string("same"),
        "objective of the polish runs after the starts (aggregated mode) and after a global "
        "algorithm: same — as objective; or value, log, epigraph",
        {"same", "value", "log", "epigraph"}));
    p.push_back(exid::param_int("epigraph_eigenvalues", 4,
                                "epigraph: eigenvalues constrained at each end of the spectrum",
                                1.0));
    p.push_back(exid::param_double("working_set_margin", 0.3, "rad",
                                   "working_set: rows with g > -this join", 0.0));
    p.push_back(exid::param_int("constraint_slots", 10,
                                "NLopt sees, per limit and joint, the this-many largest g over the "
                                "samples (order statistics; the largest is the exact max) instead "
                                "of every sample: far smaller SQP subproblems. 0: every sample",
                                0.0));
    p.push_back(exid::param_int("start_evaluations", 0,
                                "evaluations per start (0: the budget split evenly)", 0.0));
    return p;
  }

  explicit NloptOptimizer(const exid::ParamSet& p)
      : budget_(exid::optimizers::readBudget(p)),
        alg_name_(p.getString("algorithm")),
        local_name_(p.getString("local_algorithm")),
        polish_(p.getBool("polish")),
        starts_(static_cast<int>(p.getInt("starts"))),
        random_starts_(p.getString("start_mode") == "random"),
        perturb_(p.getDouble("start_perturbation")),
        seed_(static_cast<std::uint64_t>(p.getInt("seed"))),
        xtol_(p.getDouble("xtol_rel")),
        ftol_(p.getDouble("ftol_rel")),
        bound_scale_(p.getDouble("bound_scale")),
        tighten_(p.getDouble("constraint_tightening")),
        cmode_(p.getString("constraint_mode")),
        ws_margin_(p.getDouble("working_set_margin")),
        slots_(p.getString("constraint_mode") == "slots"
                   ? static_cast<int>(p.getInt("constraint_slots"))
                   : 0),
        start_evals_(p.getInt("start_evaluations")),
        ks_rho_(p.getDouble("ks_rho")),
        final_polish_(p.getDouble("final_polish")),
        objective_(p.getString("objective")),
        polish_objective_(p.getString("polish_objective") == "same"
                              ? p.getString("objective")
                              : p.getString("polish_objective")),
        epigraph_k_(static_cast<int>(p.getInt("epigraph_eigenvalues"))) {
    alg_ = algorithmFromName(alg_name_, "algorithm");
    local_ = algorithmFromName(local_name_, "local_algorithm");
  }

  exid::OptimizerResult minimize(exid::ExcitationProblem& problem,
                                 const exid::RunContext& ctx) override {
    Limits lim(problem);
    Tracker tr(problem, lim, ctx, budget_, "nlopt");
    const Eigen::VectorXd z0 = problem.initial();
    const double J0 = tr.evaluateAndOffer(z0);
    const std::uint64_t seed = seed_ ? seed_ : ctx.seed;
    nlopt::srand(static_cast<unsigned long>(seed));
    std::mt19937_64 rng(seed);
    exid::StopReason reason = exid::StopReason::Converged;
    bool stepped = false;  // a start's run that took a step (not "no progress")
    // NLopt's result of the run whose point is returned (the last run that lowered the best
    // value): the verdict names the test that ended it.
    std::string best_end;
    auto noteBest = [&](double before, const std::string& r) {
      if (tr.bestValue() < before)
        best_end = noProgress(r) ? std::string("no progress") : nlopt_result_;
    };
    int iterations = 0;
    exid::Json runs = exid::Json::array();
    const bool aggregated = cmode_ == "aggregated" && lim.size() > 0;
    // Budget: the starts run one after the other in (1 - final_polish) of the budget (aggregated
    // mode keeps final_polish of it for the polish of the best point); later starts are skipped
    // when that share is used up. The shares apply alike to an evaluation budget (reproducible
    // on any machine) and to wall or CPU time.
    const double W0 = tr.wallRemaining(), C0 = tr.cpuRemaining();
    time_cut_ = false;
    const double f_starts = aggregated && final_polish_ > 0 ? 1.0 - final_polish_ : 1.0;
    const long E0 = budget_.max_evaluations;
    const long starts_evals =
        E0 > 0 ? std::max<long>(1, static_cast<long>(f_starts * static_cast<double>(E0)))
               : std::numeric_limits<long>::max();
    for (int s = 0; s < starts_; ++s) {
      if (tr.shouldStop()) {
        reason = tr.stopCause();
        break;
      }
      if ((std::isfinite(W0) && tr.elapsed() >= f_starts * W0) ||
          (std::isfinite(C0) && tr.cpuElapsed() >= f_starts * C0)) {
        time_cut_ = true;  // the remaining starts were skipped for time
        break;
      }
      if (problem.evaluations() - tr.evaluations0() >= starts_evals) break;
      Eigen::VectorXd x0 =
          s == 0 ? z0
                 : (random_starts_
                        ? exid::optimizers::randomStart(problem, lim, z0, perturb_, rng)
                        : exid::optimizers::perturbedStart(problem, lim, z0, perturb_, rng));
      // A start may use up to max(1/starts, 0.3) of the starts' time (a local run usually
      // converges well before), never beyond the starts' time.
      // With start_evaluations the starts are bounded by evaluations (reproducible) instead.
      // An evaluation budget is shared by the same rule: a start may use up to
      // max(1/starts, 0.3) of the starts' evaluations (or start_evaluations).
      const double cap = start_evals_ > 0 ? f_starts : f_starts * std::max(1.0 / starts_, 0.3);
      long eval_end = starts_evals;
      if (E0 > 0 && start_evals_ <= 0) {
        const long used = problem.evaluations() - tr.evaluations0();
        const long share = static_cast<long>(
            std::ceil(std::max(1.0 / starts_, 0.3) * static_cast<double>(starts_evals)));
        eval_end = std::min(starts_evals, used + share);
      }
      RunEnd end{std::isfinite(W0) ? std::min(f_starts * W0, tr.elapsed() + cap * W0) : HUGE_VAL,
                 std::isfinite(C0) ? std::min(f_starts * C0, tr.cpuElapsed() + cap * C0) : HUGE_VAL,
                 1.0, eval_end};
      double before = tr.bestValue();
      std::string r = run(problem, lim, tr, alg_, alg_name_, x0, end, &iterations,
                          aggregated ? ks_rho_ : 0.0, objective_);
      noteBest(before, r);
      noteTimeCut(r);
      exid::Json run_info = exid::Json::object();
      run_info["start"] = s;
      run_info["result"] = r;
      if (isGlobal(alg_name_) && polish_ && !tr.shouldStop() && tr.hasFeasible()) {
        before = tr.bestValue();
        r = run(problem, lim, tr, local_, local_name_, tr.best(), end, &iterations,
                aggregated ? ks_rho_ : 0.0, polish_objective_);
        noteBest(before, r);
        noteTimeCut(r);
        run_info["polish"] = r;
      }
      run_info["best_so_far"] = tr.bestValue();
      run_info["cpu_s"] = tr.cpuElapsed();
      runs.push_back(run_info);
      tr.progress(fmt::format("start {}/{} {}", s + 1, starts_, r));
      if (const exid::StopReason b = budgetNamed(r); b != exid::StopReason::None) reason = b;
      stepped = stepped || !noProgress(r);
    }
    // "converged" only when some start's run converged after a step of its own
    if (reason == exid::StopReason::Converged && !stepped && runs.size() > 0)
      reason = exid::StopReason::NoProgress;
    if (aggregated && final_polish_ > 0 && !tr.shouldStop() && tr.hasFeasible()) {
      // The KS aggregate keeps the iterates a little inside the limits (up to log(K)/rho):
      // polish the best point first with a 10x sharper aggregate (half the polish time), then
      // with every sample's constraint (the exact feasible set) in the time left.
      const double f_mid = 1.0 - 0.5 * final_polish_;
      const RunEnd mid{std::isfinite(W0) ? f_mid * W0 : HUGE_VAL,
                       std::isfinite(C0) ? f_mid * C0 : HUGE_VAL, 0.5};
      const RunEnd last{HUGE_VAL, HUGE_VAL, 1.0};
      exid::Json run_info = exid::Json::object();
      double before = tr.bestValue();
      run_info["polish_sharper_ks"] =
          runOnce(problem, lim, tr, local_, local_name_, tr.best(), mid, &iterations, nullptr,
                  nullptr, 10.0 * ks_rho_, polish_objective_);
      noteBest(before, run_info["polish_sharper_ks"].asString());
      noteTimeCut(run_info["polish_sharper_ks"].asString());
      if (!tr.shouldStop()) {
        before = tr.bestValue();
        run_info["final_polish"] = runOnce(problem, lim, tr, local_, local_name_, tr.best(), last,
                                           &iterations, nullptr, nullptr, 0.0, polish_objective_);
        noteBest(before, run_info["final_polish"].asString());
        noteTimeCut(run_info["final_polish"].asString());
      }
      run_info["best_so_far"] = tr.bestValue();
      run_info["cpu_s"] = tr.cpuElapsed();
      runs.push_back(run_info);
    }
    // "converged" names NLopt's test that ended the run whose point is returned; that run cut by
    // its share of the evaluations, ended on rounding or a failure, or no run that lowered the
    // start's value, is not "converged".
    if (reason == exid::StopReason::Converged) reason = verdictOf(best_end);
    if (tr.shouldStop()) reason = tr.stopCause();
    // A run cut by time (NLopt's own time limit, or a start's share of the time) makes the
    // result depend on the machine even when a later run converged: say so.
    if (time_cut_ && reason != exid::StopReason::Cancelled && !exid::stoppedByTime(reason))
      reason = budget_.max_cpu_s > 0    ? exid::StopReason::MaxCpu
               : budget_.max_time_s > 0 ? exid::StopReason::MaxTime
                                        : exid::StopReason::Deadline;
    auto res = tr.finish(J0, iterations, reason);
    res.details["algorithm"] = alg_name_;
    res.details["constraint_mode"] = cmode_;
    res.details["objective"] = objective_;
    res.details["polish_objective"] = polish_objective_;
    res.details["runs"] = runs;
    res.details["ending"] =
        best_end.empty() ? std::string("no run lowered the start's value") : best_end;
    return res;
  }

 private:
  // When a run must end: wall and CPU time since the tracker started (inf: no limit), and the
  // share of the remaining evaluation budget it may use.
  struct RunEnd {
    double wall = HUGE_VAL, cpu = HUGE_VAL, eval_share = 1.0;
    long eval_end = std::numeric_limits<long>::max();  // evaluations since the start, at most
  };

  // One NLopt run from x0 until `end`. Returns a short result text.
  std::string run(exid::ExcitationProblem& problem, Limits& lim, Tracker& tr, nlopt::algorithm alg,
                  const std::string& name, const Eigen::VectorXd& x0, const RunEnd& end,
                  int* iterations, double ks_rho, const std::string& obj) {
    if (cmode_ != "working_set" || lim.size() == 0)
      return runOnce(problem, lim, tr, alg, name, x0, end, iterations, nullptr, nullptr, ks_rho,
                     obj);
    // Working set: NLopt sees the rows with g > -working_set_margin at the start of a round
    // (and every row seen so far); a round that ends infeasible adds the rows then near or
    // above their limit and runs again from there.
    std::vector<int> rows;
    std::vector<bool> in(static_cast<std::size_t>(lim.size()), false);
    Eigen::VectorXd x = x0, g;
    std::string r;
    bool stepped = false;  // (a later round that stops at an earlier one's end is no start)
    for (int round = 0; round < 30; ++round) {
      lim.eval(x, &g);
      const std::size_t before = rows.size();
      for (int i = 0; i < lim.size(); ++i)
        if (!in[static_cast<std::size_t>(i)] && g(i) > -ws_margin_) {
          in[static_cast<std::size_t>(i)] = true;
          rows.push_back(i);
        }
      if (rows.empty()) {  // nothing near: the maximum of every group
        const int K = lim.samples();
        for (int grp = 0; grp < lim.groups(); ++grp) {
          Eigen::Index k;
          g.segment(static_cast<Eigen::Index>(grp) * K, K).maxCoeff(&k);
          rows.push_back(grp * K + static_cast<int>(k));
          in[static_cast<std::size_t>(rows.back())] = true;
        }
      }
      if (round > 0 && rows.size() == before) break;  // feasible, or nothing new to add
      if (tr.elapsed() >= end.wall || tr.cpuElapsed() >= end.cpu || tr.shouldStop()) break;
      r = runOnce(problem, lim, tr, alg, name, x, end, iterations, &rows, &x, 0.0, obj);
      stepped = stepped || !noProgress(r);
      if (lim.maxViolation(x) <= budget_.feasibility_tol && r != "roundoff_limited") {
        lim.eval(x, &g);
        bool near_new = false;
        for (int i = 0; i < lim.size() && !near_new; ++i)
          near_new = !in[static_cast<std::size_t>(i)] && g(i) > -0.1 * ws_margin_;
        if (!near_new) break;
      }
    }
    if (stepped && noProgress(r)) r = nlopt_result_;  // NLopt's own, as before the relabelling
    return r + fmt::format(" (working set {} of {} rows)", rows.size(), lim.size());
  }

  std::string runOnce(exid::ExcitationProblem& problem, Limits& lim, Tracker& tr,
                      nlopt::algorithm alg, const std::string& name, const Eigen::VectorXd& x0,
                      const RunEnd& end, int* iterations, const std::vector<int>* rows,
                      Eigen::VectorXd* xout, double ks_rho, const std::string& obj) {
    const unsigned n = static_cast<unsigned>(x0.size());
    Ctx c{&problem, &lim, &tr, tighten_, rows || ks_rho > 0 ? 0 : slots_};
    c.rows = rows;
    c.ks_rho = rows ? 0.0 : ks_rho;
    c.log_objective = obj == "log";
    const bool epi = obj == "epigraph";
    if (epi) {
      exid::check(problem.criterion().specs().condition_number,
                  fmt::format("optimizer 'nlopt': objective: epigraph is the epigraph form of "
                              "log cond and needs criterion 'cond' (the study has '{}')",
                              problem.criterion().pluginName()));
      c.epigraph_k = std::max(1, std::min(epigraph_k_, problem.model().numBase() / 2));
    }
    const unsigned nv = epi ? n + 2 : n;
    c.wall_end = end.wall;
    c.cpu_end = end.cpu;
    Eigen::VectorXd lo, hi;
    if (isGlobal(name))
      exid::optimizers::finiteBounds(problem, x0, bound_scale_, &lo, &hi);
    else
      problem.bounds(&lo, &hi);
    std::vector<double> vlo(lo.data(), lo.data() + n), vhi(hi.data(), hi.data() + n);
    if (epi) {
      vlo.insert(vlo.end(), 2, -HUGE_VAL);
      vhi.insert(vhi.end(), 2, HUGE_VAL);
    }
    auto configure = [&](nlopt::opt& o) {
      o.set_lower_bounds(vlo);
      o.set_upper_bounds(vhi);
      if (xtol_ > 0) o.set_xtol_rel(xtol_);
      if (ftol_ > 0) o.set_ftol_rel(ftol_);
    };
    nlopt::opt main(alg, nv);
    configure(main);
    main.set_min_objective(epi ? epiObjective : objective, &c);
    if (name.rfind("G_MLSL", 0) == 0 || name == "AUGLAG" || name == "AUGLAG_EQ") {
      nlopt::opt loc(local_, nv);
      configure(loc);
      main.set_local_optimizer(loc);
    }
    nlopt::opt* top = &main;
    nlopt::opt wrapper;
    const int m = rows ? static_cast<int>(rows->size()) : nloptConstraints(lim, c.slots, c.ks_rho);
    std::vector<double> tol(static_cast<std::size_t>(m), 0.0);
    const std::vector<double> etol(static_cast<std::size_t>(2 * c.epigraph_k), 0.0);
    auto limits_fn = epi ? epiLimits : mconstraint;
    if (m > 0 || epi) {
      try {
        if (epi) main.add_inequality_mconstraint(epiEigen, &c, etol);
        if (m > 0) main.add_inequality_mconstraint(limits_fn, &c, tol);
      } catch (const std::invalid_argument&) {
        // no nonlinear constraints in this algorithm: NLopt's augmented Lagrangian around it
        main.remove_inequality_constraints();
        wrapper = nlopt::opt(nlopt::AUGLAG, nv);
        configure(wrapper);
        wrapper.set_min_objective(epi ? epiObjective : objective, &c);
        if (epi) wrapper.add_inequality_mconstraint(epiEigen, &c, etol);
        if (m > 0) wrapper.add_inequality_mconstraint(limits_fn, &c, tol);
        nlopt::opt sub(alg, nv);
        configure(sub);
        wrapper.set_local_optimizer(sub);
        top = &wrapper;
      }
    }
    // Wall-time limit for NLopt itself (the objective also stops at the run's wall/CPU end).
    const double left = std::min(tr.wallRemaining(), end.wall - tr.elapsed());
    if (std::isfinite(left)) top->set_maxtime(std::max(1e-3, left));
    const bool time_limited =
        std::isfinite(left) || std::isfinite(std::min(tr.cpuRemaining(), end.cpu));
    long evals_left = 0;
    if (budget_.max_evaluations > 0) {
      const long used = problem.evaluations() - tr.evaluations0();
      const long share = std::min(
          static_cast<long>(static_cast<double>(budget_.max_evaluations - used) * end.eval_share),
          end.eval_end - used);
      evals_left = std::max<long>(1, share);
    }
    if (start_evals_ > 0)
      evals_left = evals_left > 0 ? std::min<long>(evals_left, start_evals_) : start_evals_;
    if (evals_left > 0) top->set_maxeval(static_cast<int>(evals_left));
    if (isGlobal(name) && evals_left <= 0 && !time_limited)
      throw exid::Error(fmt::format(
          "optimizer 'nlopt': global algorithm {} needs max_time_s or max_evaluations", name));
    std::vector<double> x(x0.data(), x0.data() + n);
    for (unsigned i = 0; i < n; ++i) x[i] = std::clamp(x[i], vlo[i], vhi[i]);
    if (epi) {
      // a, b start on the extreme eigenvalues' logarithms: the start is feasible.
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(
          problem.information(Eigen::Map<const Eigen::VectorXd>(x.data(), n)),
          Eigen::EigenvaluesOnly);
      const Eigen::VectorXd& lam = es.eigenvalues();
      x.push_back(exid::fmath::log(std::max(lam(lam.size() - 1), 1e-300)));
      x.push_back(exid::fmath::log(std::max(lam(0), 1e-300)));
    }
    double f = 0;
    std::string r;
    try {
      nlopt::result res = top->optimize(x, f);
      r = nlopt_result_to_string(static_cast<nlopt_result>(res));
    } catch (const nlopt::forced_stop&) {
      const exid::StopReason cause = tr.stopCause();
      r = cause == exid::StopReason::None ? "run time share used" : exid::toString(cause);
    } catch (const nlopt::roundoff_limited&) {
      r = "roundoff_limited";
    } catch (const std::runtime_error& e) {
      r = exid::optimizers::nloptFailureText(e.what());
    }
    *iterations += static_cast<int>(c.evals);
    if (xout) *xout = Eigen::Map<const Eigen::VectorXd>(x.data(), n);  // z without a, b
    // A convergence result after the run's first evaluation is none: NLopt's ftol and xtol tests
    // compare successive iterates, and its SLSQP returns FTOL_REACHED there (its relaxed test of
    // the start against itself) when the first search direction does not descend.
    nlopt_result_ = r;
    if (c.evals <= 1 && (r == "SUCCESS" || r == "FTOL_REACHED" || r == "XTOL_REACHED"))
      r = fmt::format("{}: NLopt's {} after one evaluation",
                      exid::toString(exid::StopReason::NoProgress), r);
    return r;
  }

  static exid::StopReason verdictOf(const std::string& ending) {
    if (ending == "FTOL_REACHED") return exid::StopReason::ConvergedFtol;
    if (ending == "XTOL_REACHED") return exid::StopReason::ConvergedXtol;
    if (ending == "SUCCESS" || ending == "STOPVAL_REACHED") return exid::StopReason::Converged;
    if (ending == "MAXEVAL_REACHED") return exid::StopReason::MaxEvaluations;
    return exid::StopReason::Stalled;
  }

  static bool noProgress(const std::string& r) {
    return r.rfind(exid::toString(exid::StopReason::NoProgress), 0) == 0;
  }

  // The budget a run's result text names: runOnce reports a run ended by a budget by the
  // budget's own text (the other texts are NLopt's results, kept in details).
  static exid::StopReason budgetNamed(const std::string& r) {
    for (exid::StopReason s :
         {exid::StopReason::Cancelled, exid::StopReason::MaxTime, exid::StopReason::MaxCpu,
          exid::StopReason::Deadline, exid::StopReason::MaxEvaluations})
      if (r == exid::toString(s)) return s;
    return exid::StopReason::None;
  }

  void noteTimeCut(const std::string& r) {
    for (const std::string& t :
         {std::string("MAXTIME_REACHED"), std::string("run time share used"),
          exid::toString(exid::StopReason::MaxTime), exid::toString(exid::StopReason::MaxCpu),
          exid::toString(exid::StopReason::Deadline)})
      if (r.rfind(t, 0) == 0) time_cut_ = true;
  }

  bool time_cut_ = false;
  std::string nlopt_result_;  // the last runOnce's result as NLopt gave it
  exid::optimizers::Budget budget_;
  std::string alg_name_, local_name_;
  nlopt::algorithm alg_, local_;
  bool polish_;
  int starts_;
  bool random_starts_;
  double perturb_;
  std::uint64_t seed_;
  double xtol_, ftol_, bound_scale_, tighten_;
  std::string cmode_;
  double ws_margin_;
  int slots_;
  long start_evals_;
  double ks_rho_, final_polish_;
  std::string objective_, polish_objective_;
  int epigraph_k_;
};

}  // namespace

EXID_REGISTER_PLUGIN(NloptOptimizer)
