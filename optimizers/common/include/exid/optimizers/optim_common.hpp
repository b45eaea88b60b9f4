// Shared by the optimiser plugins (nlopt, adjoint_gradient): the full constraint set, the
// best-feasible tracker (history, budget, progress) and small helpers.
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <deque>
#include <random>
#include <string>
#include <vector>

#include "exid/interfaces.hpp"

namespace exid::optimizers {

/// g(z) <= 0: the problem's constraints (joint limits less the margin, velocity and
/// acceleration limits at every sample; a trajectory's own caps are part of them through
/// Trajectory::adjustLimits; the torque limits when the study sets them). The dense Jacobian of
/// the sample limits is computed once and cached when the trajectory says it is linear
/// (specs().linear); the torque rows (ExcitationProblem::numNonlinearConstraints) are computed
/// again at every z.
class Limits {
 public:
  explicit Limits(ExcitationProblem& p);
  int size() const { return m_; }
  /// Rows come in groups of K consecutive samples (one limit of one joint per group).
  int samples() const { return K_; }
  int groups() const { return K_ > 0 ? size() / K_ : 0; }
  /// g(z) (and the Jacobian, size() x numVariables, when jac is given).
  void eval(const Eigen::VectorXd& z, Eigen::VectorXd* g, Eigen::MatrixXd* jac = nullptr);
  /// The Jacobian (reference to the cache when linear).
  const Eigen::MatrixXd& jacobian(const Eigen::VectorXd& z);
  /// max(0, max_i g_i(z)).
  double maxViolation(const Eigen::VectorXd& z);
  bool linear() const { return linear_; }

 private:
  ExcitationProblem& p_;
  int m_ = 0, nl_ = 0, K_ = 0;
  bool linear_ = false;
  Eigen::MatrixXd jac_;
  bool jac_valid_ = false;
};

/// Common optimiser settings (parameters every exid optimiser declares).
struct Budget {
  double max_time_s = 0;     // 0: none (the study's deadline still applies)
  double max_cpu_s = 0;      // CPU time of the calling thread; 0: none
  long max_evaluations = 0;  // 0: none
  double feasibility_tol = 1e-9;
};
std::vector<ParamDecl> budgetParams(double default_time_s, long default_evals);
Budget readBudget(const ParamSet& p);

/// Keeps the best feasible point seen (and the best infeasible one with the least violation,
/// returned only when no feasible point was found), the history and the stopping rules.
class Tracker {
 public:
  Tracker(ExcitationProblem& p, Limits& lim, const RunContext& ctx, const Budget& b,
          std::string who);
  /// Records an evaluated point (J at z, violation v). Returns true when it is a new best.
  bool offer(const Eigen::VectorXd& z, double J, double violation);
  /// Evaluates J (no gradient) and the violation at z, then offers it.
  double evaluateAndOffer(const Eigen::VectorXd& z);
  bool shouldStop() const;       // time budget, evaluations, ctx.shouldStop()
  StopReason stopCause() const;  // Cancelled, Deadline, MaxTime, MaxCpu, MaxEvaluations or None
  double elapsed() const;        // wall time since construction [s]
  double cpuElapsed() const;     // CPU time of the calling thread since construction [s]
  double remaining() const;      // seconds left: min(wallRemaining, cpuRemaining)
  double wallRemaining() const;  // max_time_s and the study deadline (inf without)
  double cpuRemaining() const;   // max_cpu_s (inf without)
  bool hasFeasible() const { return have_feasible_; }
  double bestValue() const { return have_feasible_ ? best_J_ : best_inf_J_; }
  const Eigen::VectorXd& best() const { return have_feasible_ ? best_z_ : best_inf_z_; }
  void progress(const std::string& text) const;
  /// Fills the result: z, criterion_final (re-evaluated), max_violation, wall, history,
  /// feasible.
  OptimizerResult finish(double J0, int iterations, StopReason stop_reason);
  const Budget& budget() const { return b_; }
  ExcitationProblem& problem() { return p_; }
  Limits& limits() { return lim_; }
  long evaluations0() const { return evals0_; }

 private:
  ExcitationProblem& p_;
  Limits& lim_;
  const RunContext& ctx_;
  Budget b_;
  std::string who_;
  std::chrono::steady_clock::time_point t0_;
  double cpu0_ = 0.0;
  long evals0_ = 0;
  bool have_feasible_ = false, have_any_ = false;
  double best_J_ = HUGE_VAL, best_inf_J_ = HUGE_VAL, best_inf_v_ = HUGE_VAL;
  Eigen::VectorXd best_z_, best_inf_z_;
  std::vector<double> ht_, hv_, hc_;
};

/// CPU time of the calling thread [s] (CLOCK_THREAD_CPUTIME_ID).
double threadCpuSeconds();

/// A start point: z0 + perturbation * width * U(-1, 1) (width = half the bound range when
/// finite, else max(1, |z0|_inf)), clipped to the bounds, then pulled back towards z0
/// (z0 + alpha (z - z0), alpha halved) until it satisfies g <= 0 when z0 does.
/// L-BFGS memory: the last `capacity` curvature pairs (s, y) and the two-loop recursion.
class LbfgsMemory {
 public:
  explicit LbfgsMemory(int capacity) : capacity_(capacity) {}
  bool empty() const { return S_.empty(); }
  void clear();
  /// Stores (s, y) when s^T y > 1e-12 |s| |y| (curvature condition), dropping the oldest pair
  /// beyond the capacity.
  void update(const Eigen::VectorXd& s, const Eigen::VectorXd& y);
  /// H g by the two-loop recursion (initial H = s^T y / y^T y of the newest pair); not empty.
  Eigen::VectorXd apply(const Eigen::VectorXd& g) const;

 private:
  int capacity_;
  std::deque<Eigen::VectorXd> S_, Y_;
  std::deque<double> R_;
};

/// Takes an accepted step of a descent on phi: the curvature pair (zn - z, gn - g) into mem,
/// then z, g, phi := zn, gn, phin. Returns true when the relative decrease
/// (phi - phin) / max(1, |phi|) is below 1e-12 (converged).
bool takeStep(LbfgsMemory& mem, Eigen::VectorXd& z, Eigen::VectorXd& g, double& phi,
              const Eigen::VectorXd& zn, const Eigen::VectorXd& gn, double phin);

/// How an inner pass of the projected L-BFGS optimisers (adjoint_gradient, sundials) ended:
/// only Stationary passed the first-order test (max|projected gradient| <= gtol max(1, |merit|)).
/// Their results say "converged (gtol)" after a Stationary pass alone.
enum class PassEnd { Running, Stationary, NoDecrease, TinyDecrease, NotFinite };
/// The text of a PassEnd (the results' details.last_pass_end).
const char* passEndText(PassEnd e);

Eigen::VectorXd perturbedStart(ExcitationProblem& p, Limits& lim, const Eigen::VectorXd& z0,
                               double perturbation, std::mt19937_64& rng);

/// An NLopt failure (the text of the std::runtime_error its C++ interface throws) in exid's
/// words: what stopped, and that the best point found so far is kept; NLopt's text quoted.
std::string nloptFailureText(const std::string& what);

/// A random start: from the centre c of the bound box (z0 where a bound is infinite) along a
/// random direction d (U(-1, 1) times half the bound range), c + scale * s_max * d, with s_max
/// <= 1 the largest feasible step (bisection; feasible set convex along the ray for linear
/// trajectories). Falls back to perturbedStart when c is infeasible.
Eigen::VectorXd randomStart(ExcitationProblem& p, Limits& lim, const Eigen::VectorXd& z0,
                            double scale, std::mt19937_64& rng);

/// Finite bounds for algorithms that need them: the problem's, with infinite entries replaced
/// by z0 -+ scale * max(1, |z0_i|).
void finiteBounds(ExcitationProblem& p, const Eigen::VectorXd& z0, double scale,
                  Eigen::VectorXd* lo, Eigen::VectorXd* hi);

}  // namespace exid::optimizers
