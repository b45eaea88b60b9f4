// Optimizer `adjoint_gradient`: the paper's method (section 3, eqns 10-16). Each iteration is a
// forward pass (trajectory -> samples -> design rows -> M -> J) and a backward pass: dJ/dM from
// the criterion, dJ/dW = 2 W dJ/dM, the model's VJP to dJ/d(q, qd, qdd), and the trajectory's
// VJP — for `pointwise` the costate recursion lambda_k = dJ/dX_k + A^T lambda_{k+1},
// g_k = dJ/du_k + B^T lambda_{k+1} — giving the gradient with respect to every variable
// (ExcitationProblem::value(z, &grad)).
//
// Step rules (`step`):
//   paper — z <- z - gain * grad / max|grad| (the paper's mu = 1/max|lambda|), the gain halved
//           while the merit increases (backtracking) and grown by 1.5 after a success;
//   lbfgs — (default) L-BFGS two-loop recursion (memory `memory`), Armijo backtracking line
//           search; the pair (s, y) is kept only when the curvature condition s'y > 0 holds.
// Limits (`constraints`), g(z) <= 0 at every sample (plus the trajectory's own caps):
//   augmented_lagrangian — (default) PHR augmented Lagrangian
//           L = J + 1/(2 rho) sum(max(0, mu + rho g)^2 - mu^2), multipliers mu <- max(0, mu + rho
//           g) after each inner solve, rho x10 when the violation did not fall by 4;
//   penalty — quadratic penalty rho/2 sum max(0, g)^2 (bounds on z too), rho x10 per outer pass
//           while infeasible;
//   projection — bounds on z by clipping (projection) and sample limits by a quadratic penalty
//           of fixed weight.
// Bounds on z are always enforced by projection except with `penalty`. The best FEASIBLE point
// evaluated is returned.
// Jumps: with Coulomb columns (sign(qd)) J is discontinuous where a sample velocity crosses
// zero, and the gradient does not see the jump. Backtracking then creeps up to the jump and
// stalls with a large gradient (before this was handled, L-BFGS stopped after a 5% decrease on
// the planar 2R test). When a line search fails, the velocities that change sign over the first
// trial step and sit (relative to it) on zero are held: later steps stay in the tangent space
// A dz = 0 of those samples (projected gradient, L-BFGS memory reset) for the rest of the pass.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/optimizers/optim_common.hpp"

namespace {

using exid::optimizers::Limits;
using exid::optimizers::PassEnd;
using exid::optimizers::passEndText;
using exid::optimizers::Tracker;

class AdjointGradient final : public exid::Optimizer {
 public:
  static constexpr const char* kName = "adjoint_gradient";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "the paper's adjoint (costate) gradient method: exact gradient by a backward sweep; step: "
      "lbfgs (default, L-BFGS + Armijo) or paper (gain/max|gradient| with backtracking); "
      "constraints: augmented_lagrangian (default), penalty, or projection (bounds clipped, "
      "sample limits penalised)";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::optimizers::budgetParams(0.0, 0);
    p.push_back(exid::param_string("step", std::string("lbfgs"), "step rule", {"lbfgs", "paper"}));
    p.push_back(exid::param_string("constraints", std::string("augmented_lagrangian"),
                                   "how the limits are handled",
                                   {"augmented_lagrangian", "penalty", "projection"}));
    p.push_back(
        exid::param_int("max_iterations", 2000, "iterations (accepted steps) in total", 1.0));
    p.push_back(exid::param_int("inner_iterations", 40,
                                "iterations per augmented-Lagrangian/penalty pass", 1.0));
    p.push_back(exid::param_int("memory", 10, "L-BFGS memory", 1.0, 100.0));
    p.push_back(
        exid::param_double("step_gain", 1.0, "",
                           "largest change of any variable in the first (lbfgs) or every "
                           "(paper) step: gain / max|gradient| (the paper's mu = 1/max|lambda|)",
                           0.0, std::nullopt, true));
    p.push_back(
        exid::param_double("penalty_weight", 100.0, "",
                           "initial rho as a multiple of |J(z0)| (per unit violation squared)", 0.0,
                           std::nullopt, true));
    p.push_back(
        exid::param_double("ftol_rel", 1e-7, "",
                           "stop when an outer pass improves J by less than this (relative)", 0.0));
    p.push_back(exid::param_double(
        "gtol", 1e-8, "", "inner stop: max|projected gradient| <= gtol max(1, |merit|)", 0.0));
    return p;
  }

  explicit AdjointGradient(const exid::ParamSet& p)
      : budget_(exid::optimizers::readBudget(p)),
        paper_(p.getString("step") == "paper"),
        mode_(p.getString("constraints")),
        max_iter_(static_cast<int>(p.getInt("max_iterations"))),
        inner_(static_cast<int>(p.getInt("inner_iterations"))),
        mem_(static_cast<int>(p.getInt("memory"))),
        gain_(p.getDouble("step_gain")),
        rho_rel_(p.getDouble("penalty_weight")),
        ftol_(p.getDouble("ftol_rel")),
        gtol_(p.getDouble("gtol")) {}

  exid::OptimizerResult minimize(exid::ExcitationProblem& problem,
                                 const exid::RunContext& ctx) override {
    Limits lim(problem);
    Tracker tr(problem, lim, ctx, budget_, "adjoint_gradient");
    problem.bounds(&lo_, &hi_);
    paper_gain_ = gain_;
    Eigen::VectorXd z = project(problem.initial());
    const double J0 = tr.evaluateAndOffer(problem.initial());
    const int m = lim.size();
    mu_ = Eigen::VectorXd::Zero(m);
    rho_ = rho_rel_ * std::max(1e-12, std::abs(J0));
    int iters = 0;
    exid::StopReason reason = exid::StopReason::MaxIterations;
    double prev_J = HUGE_VAL, prev_v = HUGE_VAL;
    for (int outer = 0; iters < max_iter_; ++outer) {
      if (tr.shouldStop()) {
        reason = tr.stopCause();
        break;
      }
      const bool inner_converged = innerSolve(problem, lim, tr, &z, &iters);
      const bool stationary = pass_end_ == PassEnd::Stationary;
      if (tr.shouldStop()) {
        reason = tr.stopCause();
        break;
      }
      Eigen::VectorXd g;
      lim.eval(z, &g);
      const double v = m ? std::max(0.0, g.maxCoeff()) : 0.0;
      const double J = cur_J_;
      tr.progress(
          fmt::format("pass {} J {:.6g} violation {:.3g} rho {:.3g}", outer + 1, J, v, rho_));
      const bool feasible = v <= budget_.feasibility_tol;
      if (mode_ == "augmented_lagrangian" && m) {
        mu_ = (mu_ + rho_ * g).cwiseMax(0.0);
        if (v > 0.25 * prev_v && !feasible) rho_ *= 10.0;
      } else if (m && !feasible) {
        rho_ *= 10.0;
      }
      if (feasible && std::abs(prev_J - J) <= ftol_ * std::max(1.0, std::abs(J)) &&
          inner_converged) {
        reason = exid::StopReason::ConvergedFtol;
        break;
      }
      prev_J = feasible ? J : prev_J;
      prev_v = v;
      if (m == 0 && inner_converged) {
        // "converged (gtol)" says the projected gradient is within gtol: only where the pass
        // ended on that test; a pass that ended without decrease (or below 1e-12 relative) ends
        // the run too, on the ftol kind of test, and says so
        reason = stationary ? exid::StopReason::ConvergedGtol : exid::StopReason::ConvergedFtol;
        break;
      }
    }
    auto r = tr.finish(J0, iters, reason);
    r.details["step"] = paper_ ? "paper" : "lbfgs";
    r.details["constraints"] = mode_;
    r.details["rho"] = rho_;
    // how the last pass ended, and its first-order test (the merit: J with the constraint terms)
    r.details["last_pass_end"] = passEndText(pass_end_);
    r.details["projected_gradient_max"] = pg_max_;
    r.details["stationarity_tol"] = pg_tol_;
    return r;
  }

 private:
  Eigen::VectorXd project(const Eigen::VectorXd& z) const {
    if (mode_ == "penalty") return z;
    return z.cwiseMax(lo_).cwiseMin(hi_);
  }

  // Merit phi(z) = J + constraint term and its gradient; offers (J, violation) to the tracker.
  double merit(exid::ExcitationProblem& p, Limits& lim, Tracker& tr, const Eigen::VectorXd& z,
               Eigen::VectorXd* grad) {
    Eigen::VectorXd gJ;
    double J;
    try {
      J = p.value(z, &gJ);
    } catch (const exid::Error&) {
      return HUGE_VAL;
    }
    if (!std::isfinite(J)) return HUGE_VAL;
    Eigen::VectorXd g;
    double phi = J;
    *grad = gJ;
    double v = 0.0;
    if (lim.size()) {
      lim.eval(z, &g);
      v = std::max(0.0, g.maxCoeff());
      Eigen::VectorXd w;  // dphi/dg
      if (mode_ == "augmented_lagrangian") {
        Eigen::VectorXd a = (mu_ + rho_ * g).cwiseMax(0.0);
        phi += (a.squaredNorm() - mu_.squaredNorm()) / (2.0 * rho_);
        w = a;
      } else {
        Eigen::VectorXd a = g.cwiseMax(0.0);
        phi += 0.5 * rho_ * a.squaredNorm();
        w = rho_ * a;
      }
      if ((w.array() != 0.0).any()) grad->noalias() += lim.jacobian(z).transpose() * w;
    }
    if (mode_ == "penalty") {  // bounds as penalty too
      Eigen::VectorXd a = (z - hi_).cwiseMax(0.0), b = (lo_ - z).cwiseMax(0.0);
      a = a.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
      b = b.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
      phi += 0.5 * rho_ * (a.squaredNorm() + b.squaredNorm());
      *grad += rho_ * (a - b);
      v = std::max({v, a.size() ? a.maxCoeff() : 0.0, b.size() ? b.maxCoeff() : 0.0});
    }
    tr.offer(z, J, v);
    cur_J_trial_ = J;
    return phi;
  }

  // Gradient projected on the box (components pushing out of an active bound are zeroed).
  Eigen::VectorXd projectedGradient(const Eigen::VectorXd& z, const Eigen::VectorXd& g) const {
    Eigen::VectorXd pg = g;
    if (mode_ == "penalty") return pg;
    for (Eigen::Index i = 0; i < z.size(); ++i)
      if ((z(i) <= lo_(i) && g(i) > 0) || (z(i) >= hi_(i) && g(i) < 0)) pg(i) = 0.0;
    return pg;
  }

  // v less its component in the row space of A (A's rows: held constraint gradients).
  static Eigen::VectorXd tangent(const Eigen::MatrixXd& A, const Eigen::VectorXd& v) {
    if (A.rows() == 0) return v;
    const Eigen::VectorXd y = A.transpose().colPivHouseholderQr().solve(v);
    return v - A.transpose() * y;
  }

  // After a failed line search from z along the step to z_far: the samples whose velocity
  // changes sign on the way and sits (relative to that change) on zero at z are the jumps of
  // sign(qd) the search ran into; their rows d qd_kj / dz are appended to A (held from then on:
  // the search continues along the jump). Returns true when a row was added.
  static bool holdVelocitySigns(exid::ExcitationProblem& p, const Eigen::VectorXd& z,
                                const Eigen::VectorXd& z_far, Eigen::MatrixXd* A) {
    const exid::Samples a = p.trajectory().evaluate(z), b = p.trajectory().evaluate(z_far);
    if (a.qd.size() == 0 || a.qd.rows() != b.qd.rows()) return false;
    const Eigen::Index K = a.qd.rows(), n = a.qd.cols();
    std::vector<Eigen::Index> rows;
    for (Eigen::Index j = 0; j < n; ++j)
      for (Eigen::Index k = 0; k < K; ++k) {
        const double va = a.qd(k, j), vb = b.qd(k, j);
        if ((va > 0) != (vb > 0) && std::abs(va) <= 1e-6 * std::abs(vb - va))
          rows.push_back(K * n + j * K + k);
      }
    if (rows.empty()) return false;
    const Eigen::MatrixXd Jt = p.trajectory().jacobian(z);
    const Eigen::Index r0 = A->rows();
    A->conservativeResize(r0 + static_cast<Eigen::Index>(rows.size()), Eigen::NoChange);
    for (std::size_t i = 0; i < rows.size(); ++i)
      A->row(r0 + static_cast<Eigen::Index>(i)) = Jt.row(rows[i]);
    // drop rows that add nothing (already held, or zero for joints that do not move)
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A->transpose());
    return qr.rank() >
           (r0 > 0 ? Eigen::ColPivHouseholderQR<Eigen::MatrixXd>(A->topRows(r0).transpose()).rank()
                   : 0);
  }

  // One pass of at most inner_ iterations on the current merit. Returns true when the pass ended
  // (stationary, or no further decrease: pass_end_ says which, pg_max_ and pg_tol_ its last
  // first-order test), false when its iterations ran out or a stop was asked for.
  bool innerSolve(exid::ExcitationProblem& p, Limits& lim, Tracker& tr, Eigen::VectorXd* zp,
                  int* iters) {
    Eigen::VectorXd& z = *zp;
    Eigen::VectorXd g;
    double phi = merit(p, lim, tr, z, &g);
    cur_J_ = cur_J_trial_;
    pass_end_ = PassEnd::NotFinite;
    pg_max_ = HUGE_VAL;
    pg_tol_ = gtol_ * std::max(1.0, std::abs(phi));
    if (!std::isfinite(phi)) return true;
    exid::optimizers::LbfgsMemory mem(mem_);
    Eigen::MatrixXd A(0, z.size());  // held velocity rows: steps keep A dz = 0
    // the gradient at z projected on the box and the tangent space of the held velocity rows
    const auto projected = [&]() { return Eigen::VectorXd(tangent(A, projectedGradient(z, g))); };
    // the first-order test of such a gradient (recorded in pg_max_, pg_tol_)
    const auto firstOrder = [&](const Eigen::VectorXd& pg) {
      pg_max_ = pg.cwiseAbs().maxCoeff();
      pg_tol_ = gtol_ * std::max(1.0, std::abs(phi));
      return pg_max_ <= pg_tol_;  // false for a NaN
    };
    pass_end_ = PassEnd::Running;
    for (int it = 0; it < inner_ && *iters < max_iter_; ++it) {
      if (tr.shouldStop()) return false;
      Eigen::VectorXd pg = projected();
      if (firstOrder(pg)) {
        pass_end_ = PassEnd::Stationary;
        return true;
      }
      const double gmax = pg_max_;
      Eigen::VectorXd d;
      double alpha;
      if (paper_ || mem.empty()) {
        d = -pg;
        alpha = (paper_ ? paper_gain_ : gain_) / gmax;
      } else {
        d = -tangent(A, mem.apply(pg));  // two-loop recursion
        if (d.dot(pg) >= 0) {            // not a descent direction: restart
          mem.clear();
          d = -pg;
          alpha = gain_ / gmax;
        } else {
          alpha = 1.0;
        }
      }
      // backtracking (Armijo on the projected step)
      bool accepted = false;
      Eigen::VectorXd zn, gn;
      double phin = HUGE_VAL;
      const double alpha0 = alpha;
      for (int ls = 0; ls < 40; ++ls) {
        zn = project(z + alpha * d);
        phin = merit(p, lim, tr, zn, &gn);
        const double decrease = g.dot(zn - z);
        if (std::isfinite(phin) && phin <= phi + 1e-4 * std::min(decrease, 0.0) && phin < phi) {
          accepted = true;
          break;
        }
        if (tr.shouldStop()) return false;
        alpha *= 0.5;
        if (paper_) paper_gain_ *= 0.5;
      }
      if (!accepted) {
        // No decrease along d. Where the criterion jumps (Coulomb columns sign(qd): a sample
        // velocity crossing zero), backtracking walks up to the jump and stalls there with a
        // large gradient. Hold the velocities that sit on the jump (tangent space) and go on.
        if (holdVelocitySigns(p, z, z + alpha0 * d, &A)) {
          mem.clear();
          continue;
        }
        pass_end_ = PassEnd::NoDecrease;  // (pg_max_: z's test above, not passed)
        return true;
      }
      ++*iters;
      if (paper_) paper_gain_ = std::min(paper_gain_ * 1.5, 1e6 * gain_);
      cur_J_ = cur_J_trial_;
      if (exid::optimizers::takeStep(mem, z, g, phi, zn, gn, phin)) {
        pass_end_ = firstOrder(projected()) ? PassEnd::Stationary : PassEnd::TinyDecrease;
        return true;
      }
    }
    firstOrder(projected());
    return false;
  }

  exid::optimizers::Budget budget_;
  bool paper_;
  std::string mode_;
  int max_iter_, inner_, mem_;
  double gain_, rho_rel_, ftol_, gtol_;
  double paper_gain_ = 1.0;
  Eigen::VectorXd lo_, hi_, mu_;
  double rho_ = 1.0, cur_J_ = 0.0, cur_J_trial_ = 0.0;
  PassEnd pass_end_ = PassEnd::Running;
  double pg_max_ = HUGE_VAL, pg_tol_ = 0.0;  // the last first-order test
};

}  // namespace

EXID_REGISTER_PLUGIN(AdjointGradient)
