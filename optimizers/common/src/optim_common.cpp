#include "exid/optimizers/optim_common.hpp"

#include <fmt/format.h>
#include <time.h>

#include <algorithm>
#include <cmath>

#include "exid/error.hpp"

namespace exid::optimizers {

// ---------------------------------------------------------------- Limits
Limits::Limits(ExcitationProblem& p) : p_(p) {
  m_ = p.numConstraints();
  nl_ = p.numNonlinearConstraints();
  linear_ = p.trajectory().specs().linear;
  K_ = p.trajectory().evaluate(p.initial()).size();
}

void Limits::eval(const Eigen::VectorXd& z, Eigen::VectorXd* g, Eigen::MatrixXd* jac) {
  if (g) {
    if (m_ > 0)
      p_.constraints(z, g, nullptr);
    else
      g->resize(0);
  }
  if (jac) *jac = jacobian(z);
}

const Eigen::MatrixXd& Limits::jacobian(const Eigen::VectorXd& z) {
  if (jac_valid_ && linear_ && nl_ == 0) return jac_;
  if (m_ == 0) {
    jac_.resize(0, z.size());
  } else if (jac_valid_ && linear_) {
    // the rows of the sample limits are constant; only the torque rows change with z
    Eigen::MatrixXd tail;
    p_.nonlinearConstraints(z, nullptr, &tail);
    jac_.bottomRows(nl_) = tail;
  } else {
    p_.constraints(z, nullptr, &jac_);
  }
  jac_valid_ = true;
  return jac_;
}

double Limits::maxViolation(const Eigen::VectorXd& z) {
  if (size() == 0) return 0.0;
  Eigen::VectorXd g;
  eval(z, &g);
  return std::max(0.0, g.maxCoeff());
}

// ---------------------------------------------------------------- budget
std::vector<ParamDecl> budgetParams(double default_time_s, long default_evals) {
  return {
      param_double("max_time_s", default_time_s, "s",
                   "wall-time budget (0: none; the study deadline still applies). A run stopped "
                   "by a time budget depends on the machine's speed and load, and says so "
                   "(summary warning); evaluation and iteration budgets are reproducible",
                   0.0),
      param_double("max_cpu_s", 0.0, "s",
                   "CPU-time budget of the optimising thread (0: none); with a loaded machine this "
                   "is the budget that means 'on one core' (not reproducible either)",
                   0.0),
      param_int("max_evaluations", default_evals,
                "criterion evaluations budget (0: none): the same answer on any machine", 0.0),
      param_double("feasibility_tol", 1e-9, "rad",
                   "a point is feasible when every g(z) <= this (limits in rad, rad/s, rad/s^2)",
                   0.0),
  };
}

Budget readBudget(const ParamSet& p) {
  Budget b;
  b.max_time_s = p.getDouble("max_time_s");
  b.max_cpu_s = p.getDouble("max_cpu_s");
  b.max_evaluations = p.getInt("max_evaluations");
  b.feasibility_tol = p.getDouble("feasibility_tol");
  return b;
}

// ---------------------------------------------------------------- Tracker
Tracker::Tracker(ExcitationProblem& p, Limits& lim, const RunContext& ctx, const Budget& b,
                 std::string who)
    : p_(p),
      lim_(lim),
      ctx_(ctx),
      b_(b),
      who_(std::move(who)),
      t0_(std::chrono::steady_clock::now()),
      cpu0_(threadCpuSeconds()),
      evals0_(p.evaluations()) {}

double threadCpuSeconds() {
  timespec ts{};
  if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts) != 0) return 0.0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double Tracker::elapsed() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
}

double Tracker::cpuElapsed() const { return threadCpuSeconds() - cpu0_; }

double Tracker::wallRemaining() const {
  double r = ctx_.deadline.remaining_s();
  if (b_.max_time_s > 0) r = std::min(r, b_.max_time_s - elapsed());
  return r;
}

double Tracker::cpuRemaining() const {
  return b_.max_cpu_s > 0 ? b_.max_cpu_s - cpuElapsed() : HUGE_VAL;
}

double Tracker::remaining() const { return std::min(wallRemaining(), cpuRemaining()); }

bool Tracker::offer(const Eigen::VectorXd& z, double J, double v) {
  if (!std::isfinite(J)) return false;
  const bool feasible = v <= b_.feasibility_tol;
  bool improved = false;
  if (feasible && J < best_J_) {
    best_J_ = J;
    best_z_ = z;
    have_feasible_ = true;
    improved = true;
  } else if (!have_feasible_ && (v < best_inf_v_ || (v == best_inf_v_ && J < best_inf_J_))) {
    best_inf_v_ = v;
    best_inf_J_ = J;
    best_inf_z_ = z;
    improved = !have_any_;
  }
  have_any_ = true;
  if (improved) {
    ht_.push_back(elapsed());
    hc_.push_back(cpuElapsed());
    hv_.push_back(bestValue());
  }
  return improved;
}

double Tracker::evaluateAndOffer(const Eigen::VectorXd& z) {
  double J;
  try {
    J = p_.value(z, nullptr);
  } catch (const Error&) {
    J = HUGE_VAL;  // singular information matrix
  }
  offer(z, J, lim_.maxViolation(z));
  return J;
}

StopReason Tracker::stopCause() const {
  if (ctx_.cancelled && ctx_.cancelled()) return StopReason::Cancelled;
  if (ctx_.deadline.expired()) return StopReason::Deadline;
  if (b_.max_time_s > 0 && elapsed() >= b_.max_time_s) return StopReason::MaxTime;
  if (b_.max_cpu_s > 0 && cpuElapsed() >= b_.max_cpu_s) return StopReason::MaxCpu;
  if (b_.max_evaluations > 0 && p_.evaluations() - evals0_ >= b_.max_evaluations)
    return StopReason::MaxEvaluations;
  return StopReason::None;
}

bool Tracker::shouldStop() const { return stopCause() != StopReason::None; }

void Tracker::progress(const std::string& text) const {
  double f = 0.0;
  if (b_.max_time_s > 0) f = std::min(1.0, elapsed() / b_.max_time_s);
  if (b_.max_cpu_s > 0) f = std::max(f, std::min(1.0, cpuElapsed() / b_.max_cpu_s));
  if (b_.max_evaluations > 0)
    f = std::max(f, std::min(1.0, static_cast<double>(p_.evaluations() - evals0_) /
                                      static_cast<double>(b_.max_evaluations)));
  ctx_.report(f, fmt::format("{}: best {:.6g}{} {}", who_, bestValue(),
                             have_feasible_ ? "" : " (infeasible)", text));
}

OptimizerResult Tracker::finish(double J0, int iterations, StopReason stop_reason) {
  OptimizerResult r;
  check(have_any_, fmt::format("{}: no point could be evaluated", who_));
  r.z = best();
  r.criterion_initial = J0;
  r.criterion_final = bestValue();
  r.max_violation = lim_.maxViolation(r.z);
  r.iterations = iterations;
  r.evaluations = p_.evaluations() - evals0_;
  r.wall_s = elapsed();
  r.stop_reason = stop_reason;
  r.feasible = have_feasible_;
  r.history_t_s = ht_;
  r.history_value = hv_;
  r.details["feasible"] = have_feasible_;
  r.details["cpu_s"] = cpuElapsed();
  r.details["history_cpu_s"] = Json(hc_);
  r.details["constraints"] = lim_.size();
  return r;
}

// ---------------------------------------------------------------- L-BFGS memory
void LbfgsMemory::clear() {
  S_.clear();
  Y_.clear();
  R_.clear();
}

void LbfgsMemory::update(const Eigen::VectorXd& s, const Eigen::VectorXd& y) {
  const double sy = s.dot(y);
  if (!(sy > 1e-12 * s.norm() * y.norm())) return;
  S_.push_back(s);
  Y_.push_back(y);
  R_.push_back(1.0 / sy);
  if (static_cast<int>(S_.size()) > capacity_) {
    S_.pop_front();
    Y_.pop_front();
    R_.pop_front();
  }
}

Eigen::VectorXd LbfgsMemory::apply(const Eigen::VectorXd& g) const {
  Eigen::VectorXd q = g;
  std::vector<double> a(S_.size());
  for (std::size_t k = S_.size(); k-- > 0;) {
    a[k] = R_[k] * S_[k].dot(q);
    q -= a[k] * Y_[k];
  }
  q *= S_.back().dot(Y_.back()) / Y_.back().squaredNorm();
  for (std::size_t k = 0; k < S_.size(); ++k) q += (a[k] - R_[k] * Y_[k].dot(q)) * S_[k];
  return q;
}

// ---------------------------------------------------------------- starts and bounds
Eigen::VectorXd perturbedStart(ExcitationProblem& p, Limits& lim, const Eigen::VectorXd& z0,
                               double perturbation, std::mt19937_64& rng) {
  Eigen::VectorXd lo, hi;
  p.bounds(&lo, &hi);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const double zinf = std::max(1.0, z0.cwiseAbs().maxCoeff());
  Eigen::VectorXd z = z0;
  for (Eigen::Index i = 0; i < z.size(); ++i) {
    const bool fin = std::isfinite(lo(i)) && std::isfinite(hi(i));
    const double w = fin ? 0.5 * (hi(i) - lo(i)) : zinf;
    z(i) = std::clamp(z0(i) + perturbation * w * U(rng), lo(i), hi(i));
  }
  if (lim.size() == 0 || lim.maxViolation(z0) > 0) return z;
  double a = 1.0;
  Eigen::VectorXd zt = z;
  for (int it = 0; it < 30 && lim.maxViolation(zt) > 0; ++it) {
    a *= 0.5;
    zt = z0 + a * (z - z0);
  }
  return zt;
}

Eigen::VectorXd randomStart(ExcitationProblem& p, Limits& lim, const Eigen::VectorXd& z0,
                            double scale, std::mt19937_64& rng) {
  Eigen::VectorXd lo, hi;
  p.bounds(&lo, &hi);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const double zinf = std::max(1.0, z0.cwiseAbs().maxCoeff());
  Eigen::VectorXd c = z0, d(z0.size());
  for (Eigen::Index i = 0; i < z0.size(); ++i) {
    const bool fin = std::isfinite(lo(i)) && std::isfinite(hi(i));
    if (fin) c(i) = 0.5 * (lo(i) + hi(i));
    d(i) = U(rng) * (fin ? 0.5 * (hi(i) - lo(i)) : zinf);
  }
  if (lim.size() > 0 && lim.maxViolation(c) > 0) return perturbedStart(p, lim, z0, scale, rng);
  double a = 0.0, b = 1.0;
  if (lim.size() > 0 && lim.maxViolation(c + d) > 0) {
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (a + b);
      (lim.maxViolation(c + mid * d) > 0 ? b : a) = mid;
    }
  } else {
    a = 1.0;
  }
  return c + scale * a * d;
}

void finiteBounds(ExcitationProblem& p, const Eigen::VectorXd& z0, double scale,
                  Eigen::VectorXd* lo, Eigen::VectorXd* hi) {
  p.bounds(lo, hi);
  for (Eigen::Index i = 0; i < z0.size(); ++i) {
    const double w = scale * std::max(1.0, std::abs(z0(i)));
    if (!std::isfinite((*lo)(i))) (*lo)(i) = z0(i) - w;
    if (!std::isfinite((*hi)(i))) (*hi)(i) = z0(i) + w;
  }
}

bool takeStep(LbfgsMemory& mem, Eigen::VectorXd& z, Eigen::VectorXd& g, double& phi,
              const Eigen::VectorXd& zn, const Eigen::VectorXd& gn, double phin) {
  mem.update(zn - z, gn - g);
  const double rel = (phi - phin) / std::max(1.0, std::abs(phi));
  z = zn;
  g = gn;
  phi = phin;
  return rel < 1e-12;
}

const char* passEndText(PassEnd e) {
  switch (e) {
    case PassEnd::Running:
      return "iterations or budget ran out";
    case PassEnd::Stationary:
      return "stationary: max|projected gradient| <= gtol max(1, |merit|)";
    case PassEnd::NoDecrease:
      return "no decrease along the search direction (projected gradient above gtol)";
    case PassEnd::TinyDecrease:
      return "a step decreased the merit by less than 1e-12 relative (projected gradient above "
             "gtol)";
    case PassEnd::NotFinite:
      return "the merit is not finite at the pass's start";
  }
  return "";
}

std::string nloptFailureText(const std::string& what) {
  if (what.rfind("bug: more than iter SQP iterations", 0) == 0)
    return fmt::format(
        "stopped: SLSQP's quadratic subproblem did not converge within its "
        "iterations (NLopt: \"{}\"); the best point found so far is kept",
        what);
  if (what == "nlopt failure")
    return "stopped: NLopt could not continue from the point reached (its generic failure, often "
           "a criterion or constraint that is not smooth there); the best point found so far is "
           "kept";
  return fmt::format("stopped: NLopt failed (\"{}\"); the best point found so far is kept", what);
}

}  // namespace exid::optimizers
