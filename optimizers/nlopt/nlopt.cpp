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
#include <nlopt.hpp>
#include <random>

#include "exid/error.hpp"
#include "optim_common.hpp"

namespace {

using exid::optim::Limits;
using exid::optim::Tracker;

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
              fmt::format("optimizer 'nlopt': {}: unknown NLopt algorithm '{}'; valid: {}", param, name, validNames()));
  return static_cast<nlopt::algorithm>(a);
}

bool isGlobal(const std::string& name) { return name.rfind("GN_", 0) == 0 || name.rfind("GD_", 0) == 0 || name.rfind("G_", 0) == 0; }

struct Ctx {
  exid::ExcitationProblem* p;
  Limits* lim;
  Tracker* tr;
  double tighten;
  int slots = 0;  // per group of K samples: the `slots` largest g values (0: every sample)
  const std::vector<int>* rows = nullptr;  // working set: only these rows of g
  long evals = 0;
};

// Number of constraints NLopt sees.
int nloptConstraints(const Limits& lim, int slots) {
  if (slots <= 0 || lim.size() == 0 || slots >= lim.samples()) return lim.size();
  return lim.groups() * slots;
}

double objective(unsigned n, const double* x, double* grad, void* data) {
  auto* c = static_cast<Ctx*>(data);
  if (c->tr->shouldStop()) throw nlopt::forced_stop();
  Eigen::Map<const Eigen::VectorXd> z(x, n);
  Eigen::VectorXd zz = z, g;
  double J;
  try {
    J = c->p->value(zz, grad ? &g : nullptr);
  } catch (const exid::Error&) {
    J = 1e30;  // singular information matrix: a very bad point
    g = Eigen::VectorXd::Zero(n);
  }
  if (grad) Eigen::Map<Eigen::VectorXd>(grad, n) = g;
  c->tr->offer(zz, J, c->lim->maxViolation(zz));
  ++c->evals;
  return J;
}

void mconstraint(unsigned m, double* result, unsigned n, const double* x, double* grad, void* data) {
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
      if (grad) Eigen::Map<Eigen::RowVectorXd>(grad + static_cast<std::ptrdiff_t>(i) * n, n) = J->row(row);
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
    std::partial_sort(idx.begin(), idx.begin() + r, idx.end(), [&](int a, int b) { return g(a) > g(b); });
    for (int i = 0; i < r; ++i) {
      const int row = idx[static_cast<std::size_t>(i)], out = grp * r + i;
      result[out] = g(row) + c->tighten;
      if (grad) Eigen::Map<Eigen::RowVectorXd>(grad + static_cast<std::ptrdiff_t>(out) * n, n) = J->row(row);
    }
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
    auto p = exid::optim::budgetParams(60.0, 0);
    p.push_back(exid::param_string("algorithm", std::string("LD_SLSQP"),
                                   "NLopt algorithm name (NLOPT_ prefix dropped); an unknown name lists the valid ones"));
    p.push_back(exid::param_string("local_algorithm", std::string("LD_SLSQP"),
                                   "local algorithm for the polish after a global one (and MLSL's local searches)"));
    p.push_back(exid::param_bool("polish", true, "after a global algorithm, polish its best point with local_algorithm"));
    p.push_back(exid::param_int("starts", 1, "starts: the initial point, then perturbed ones; the best feasible is kept", 1.0));
    p.push_back(exid::param_string("start_mode", std::string("random"),
                                   "later starts: random — from the centre of the bound box along a "
                                   "random direction, start_perturbation times the largest feasible "
                                   "step; perturb — the initial point plus start_perturbation times "
                                   "half the bound range, pulled back towards it until feasible",
                                   {"random", "perturb"}));
    p.push_back(exid::param_double("start_perturbation", 0.5, "", "see start_mode", 0.0));
    p.push_back(exid::param_int("seed", 0, "nlopt::srand and the start perturbations (0: the study seed)", 0.0));
    p.push_back(exid::param_double("xtol_rel", 1e-6, "", "relative tolerance on z (0: off)", 0.0));
    p.push_back(exid::param_double("ftol_rel", 1e-9, "", "relative tolerance on J (0: off)", 0.0));
    p.push_back(exid::param_double("bound_scale", 2.0, "",
                                   "global algorithms: infinite bounds become z0 -+ bound_scale max(1, |z0_i|)", 0.0, std::nullopt, true));
    p.push_back(exid::param_double("constraint_tightening", 1e-7, "rad",
                                   "the optimiser sees g(z) + this <= 0, so that its nearly-feasible "
                                   "iterates are feasible", 0.0));
    p.push_back(exid::param_string("constraint_mode", std::string("all"),
                                   "how g reaches NLopt: all — every sample; slots — per limit and "
                                   "joint the constraint_slots largest values; working_set — rows "
                                   "within working_set_margin of their limit, grown and re-run "
                                   "while the result violates others (the returned point is always "
                                   "checked at every sample)", {"all", "slots", "working_set"}));
    p.push_back(exid::param_double("working_set_margin", 0.3, "rad", "working_set: rows with g > -this join", 0.0));
    p.push_back(exid::param_int("constraint_slots", 10,
                                   "NLopt sees, per limit and joint, the this-many largest g over the "
                                   "samples (order statistics; the largest is the exact max) instead "
                                   "of every sample: far smaller SQP subproblems. 0: every sample", 0.0));
    p.push_back(exid::param_int("start_evaluations", 0, "evaluations per start (0: the budget split evenly)", 0.0));
    return p;
  }

  explicit NloptOptimizer(const exid::ParamSet& p)
      : budget_(exid::optim::readBudget(p)), alg_name_(p.getString("algorithm")),
        local_name_(p.getString("local_algorithm")), polish_(p.getBool("polish")),
        starts_(static_cast<int>(p.getInt("starts"))), random_starts_(p.getString("start_mode") == "random"),
        perturb_(p.getDouble("start_perturbation")),
        seed_(static_cast<std::uint64_t>(p.getInt("seed"))), xtol_(p.getDouble("xtol_rel")),
        ftol_(p.getDouble("ftol_rel")), bound_scale_(p.getDouble("bound_scale")),
        tighten_(p.getDouble("constraint_tightening")),
        cmode_(p.getString("constraint_mode")), ws_margin_(p.getDouble("working_set_margin")),
        slots_(p.getString("constraint_mode") == "slots" ? static_cast<int>(p.getInt("constraint_slots")) : 0),
        start_evals_(p.getInt("start_evaluations")) {
    alg_ = algorithmFromName(alg_name_, "algorithm");
    local_ = algorithmFromName(local_name_, "local_algorithm");
  }

  exid::OptimizerResult minimize(exid::ExcitationProblem& problem, const exid::RunContext& ctx) override {
    Limits lim(problem);
    Tracker tr(problem, lim, ctx, budget_, "nlopt");
    const Eigen::VectorXd z0 = problem.initial();
    const double J0 = tr.evaluateAndOffer(z0);
    const std::uint64_t seed = seed_ ? seed_ : ctx.seed;
    nlopt::srand(static_cast<unsigned long>(seed));
    std::mt19937_64 rng(seed);
    std::string reason = "converged";
    int iterations = 0;
    exid::Json runs = exid::Json::array();
    for (int s = 0; s < starts_; ++s) {
      if (tr.shouldStop()) { reason = tr.stopCause(); break; }
      Eigen::VectorXd x0 = s == 0 ? z0
                           : (random_starts_ ? exid::optim::randomStart(problem, lim, z0, perturb_, rng)
                                             : exid::optim::perturbedStart(problem, lim, z0, perturb_, rng));
      const double share = 1.0 / (starts_ - s);
      std::string r = run(problem, lim, tr, alg_, alg_name_, x0, share, &iterations);
      exid::Json run_info = exid::Json::object();
      run_info["start"] = s;
      run_info["result"] = r;
      if (isGlobal(alg_name_) && polish_ && !tr.shouldStop() && tr.hasFeasible()) {
        r = run(problem, lim, tr, local_, local_name_, tr.best(), share, &iterations);
        run_info["polish"] = r;
      }
      run_info["best_so_far"] = tr.bestValue();
      runs.push_back(run_info);
      tr.progress(fmt::format("start {}/{} {}", s + 1, starts_, r));
      if (r == "cancelled" || r == "max_time_s" || r == "deadline" || r == "max_evaluations") reason = r;
    }
    if (tr.shouldStop()) reason = tr.stopCause();
    auto res = tr.finish(J0, iterations, reason);
    res.details["algorithm"] = alg_name_;
    res.details["runs"] = runs;
    return res;
  }

 private:
  // One NLopt run from x0 with a share of the remaining budget. Returns a short result text.
  std::string run(exid::ExcitationProblem& problem, Limits& lim, Tracker& tr, nlopt::algorithm alg,
                  const std::string& name, const Eigen::VectorXd& x0, double share, int* iterations) {
    if (cmode_ != "working_set" || lim.size() == 0) return runOnce(problem, lim, tr, alg, name, x0, share, iterations, nullptr, nullptr);
    // Working set: NLopt sees the rows with g > -working_set_margin at the start of a round
    // (and every row seen so far); a round that ends infeasible adds the rows then near or
    // above their limit and runs again from there.
    std::vector<int> rows;
    std::vector<bool> in(static_cast<std::size_t>(lim.size()), false);
    Eigen::VectorXd x = x0, g;
    std::string r;
    const double t_end = tr.elapsed() + (std::isfinite(tr.remaining()) ? tr.remaining() * share : HUGE_VAL);
    for (int round = 0; round < 30; ++round) {
      lim.eval(x, &g);
      const std::size_t before = rows.size();
      for (int i = 0; i < lim.size(); ++i)
        if (!in[static_cast<std::size_t>(i)] && g(i) > -ws_margin_) { in[static_cast<std::size_t>(i)] = true; rows.push_back(i); }
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
      const double left = t_end - tr.elapsed();
      if (left <= 0 || tr.shouldStop()) break;
      const double sh = std::isfinite(left) && std::isfinite(tr.remaining()) ? std::min(1.0, left / std::max(1e-9, tr.remaining())) : share;
      r = runOnce(problem, lim, tr, alg, name, x, sh, iterations, &rows, &x);
      if (lim.maxViolation(x) <= budget_.feasibility_tol && r != "roundoff_limited") {
        lim.eval(x, &g);
        bool near_new = false;
        for (int i = 0; i < lim.size() && !near_new; ++i) near_new = !in[static_cast<std::size_t>(i)] && g(i) > -0.1 * ws_margin_;
        if (!near_new) break;
      }
    }
    return r + fmt::format(" (working set {} of {} rows)", rows.size(), lim.size());
  }

  std::string runOnce(exid::ExcitationProblem& problem, Limits& lim, Tracker& tr, nlopt::algorithm alg,
                      const std::string& name, const Eigen::VectorXd& x0, double share, int* iterations,
                      const std::vector<int>* rows, Eigen::VectorXd* xout) {
    const unsigned n = static_cast<unsigned>(x0.size());
    Ctx c{&problem, &lim, &tr, tighten_, slots_};
    c.rows = rows;
    Eigen::VectorXd lo, hi;
    if (isGlobal(name)) exid::optim::finiteBounds(problem, x0, bound_scale_, &lo, &hi);
    else problem.bounds(&lo, &hi);
    std::vector<double> vlo(lo.data(), lo.data() + n), vhi(hi.data(), hi.data() + n);
    auto configure = [&](nlopt::opt& o) {
      o.set_lower_bounds(vlo);
      o.set_upper_bounds(vhi);
      if (xtol_ > 0) o.set_xtol_rel(xtol_);
      if (ftol_ > 0) o.set_ftol_rel(ftol_);
    };
    nlopt::opt main(alg, n);
    configure(main);
    main.set_min_objective(objective, &c);
    if (name.rfind("G_MLSL", 0) == 0 || name == "AUGLAG" || name == "AUGLAG_EQ") {
      nlopt::opt loc(local_, n);
      configure(loc);
      main.set_local_optimizer(loc);
    }
    nlopt::opt* top = &main;
    nlopt::opt wrapper;
    const int m = rows ? static_cast<int>(rows->size()) : nloptConstraints(lim, slots_);
    std::vector<double> tol(static_cast<std::size_t>(m), 0.0);
    if (m > 0) {
      try {
        main.add_inequality_mconstraint(mconstraint, &c, tol);
      } catch (const std::invalid_argument&) {
        // no nonlinear constraints in this algorithm: NLopt's augmented Lagrangian around it
        wrapper = nlopt::opt(nlopt::AUGLAG, n);
        configure(wrapper);
        wrapper.set_min_objective(objective, &c);
        wrapper.add_inequality_mconstraint(mconstraint, &c, tol);
        nlopt::opt sub(alg, n);
        configure(sub);
        wrapper.set_local_optimizer(sub);
        top = &wrapper;
      }
    }
    const double left = tr.remaining();
    if (std::isfinite(left)) top->set_maxtime(std::max(1e-3, left * share));
    long evals_left = 0;
    if (budget_.max_evaluations > 0)
      evals_left = std::max<long>(1, static_cast<long>((budget_.max_evaluations - (problem.evaluations() - tr.evaluations0())) * share));
    if (start_evals_ > 0) evals_left = evals_left > 0 ? std::min<long>(evals_left, start_evals_) : start_evals_;
    if (evals_left > 0) top->set_maxeval(static_cast<int>(evals_left));
    if (isGlobal(name) && evals_left <= 0 && !std::isfinite(left))
      throw exid::Error(fmt::format("optimizer 'nlopt': global algorithm {} needs max_time_s or max_evaluations", name));
    std::vector<double> x(x0.data(), x0.data() + n);
    for (unsigned i = 0; i < n; ++i) x[i] = std::clamp(x[i], vlo[i], vhi[i]);
    double f = 0;
    std::string r;
    try {
      nlopt::result res = top->optimize(x, f);
      r = nlopt_result_to_string(static_cast<nlopt_result>(res));
    } catch (const nlopt::forced_stop&) {
      r = tr.stopCause().empty() ? "forced_stop" : tr.stopCause();
    } catch (const nlopt::roundoff_limited&) {
      r = "roundoff_limited";
    } catch (const std::runtime_error& e) {
      r = std::string("failure: ") + e.what();
    }
    *iterations += static_cast<int>(c.evals);
    if (xout) *xout = Eigen::Map<const Eigen::VectorXd>(x.data(), n);
    return r;
  }

  exid::optim::Budget budget_;
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
};

}  // namespace

EXID_REGISTER_PLUGIN(NloptOptimizer)
