// Optimizer `sundials`: excitation design in CONTINUOUS time with CVODES.
//
// The trajectory is read as a function of time, q(t; z), through the Trajectory interface: a
// trajectory whose specs() declare it `continuous` (fourier, spline) gives its signals at any
// time (evaluateAt) and their VJP (vjpAt); one defined on its sample grid only (pointwise) is
// refused with a message.
//
// Forward problem (CVODES, Adams, fixed-point iteration), state y = [q; qd] of the moving
// joints driven by the parameterised acceleration:
//     y' = f(t, y; z) = [qd; qdd(t; z)],    y(0) = [q(0; z); qd(0; z)],
// with the information matrix as quadratures under error control:
//     M = (1/dt) int_0^T S Phi(t) Phi(t)^T S dt,    Phi^T = model.design(one sample at t)
// (dt = the trajectory's sample period, so that M matches sum_k Phi_k Phi_k^T of the discrete
// problem; S = the criterion's optional column scaling). J = F(M) (the criterion plugin).
//
// Gradient by CVODES's adjoint sensitivity (CVodeAdjInit, checkpoints, Hermite interpolation of
// the forward solution). With G = dF/dM and w(t) = <G, S Phi Phi^T S>/dt, the costate
//     lambda' = -(df/dy)^T lambda - (dw/dy)^T,  lambda(T) = 0   (lambda = [lq; lqd]:
//     lq' = -dw/dq, lqd' = -lq - dw/dqd)
// and the backward quadrature give
//     dJ/dz = lambda(0)^T dy0/dz + int_0^T (dw/dqdd + lqd)^T dqdd/dz dt,
// dw/d(q, qd, qdd) being the model's exact VJP with dW = 2 W S G S / dt. This is the
// continuous-time form of the paper's costate recursion (eqn 15). Where a moving joint's velocity
// changes sign, the integrand may jump (a Coulomb column sign(qd)); the crossing time moves with
// z and adds <G, P(t*-) - P(t*+)> dt*/dz (crossingTerms), which the costates do not carry.
// The quadratures' absolute tolerances are per entry of M, on the scale of the criterion's
// (scaled) M (setQuadScale).
//
// Update: projected L-BFGS with Armijo backtracking on the merit J + rho/2 sum max(0, g)^2,
// g(z) <= 0 the excitation problem's limits at the sample grid plus the trajectory's own caps
// (exid::optimizers::Limits); rho grows x10 per pass while the point is infeasible. Bounds on z by
// projection. The best FEASIBLE point is returned.
#include <cvodes/cvodes.h>
#include <fmt/format.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/gradient_check.hpp"
#include "exid/optimizers/optim_common.hpp"

namespace {

using exid::optimizers::PassEnd;
using exid::optimizers::passEndText;

// ---------------------------------------------------------------- the trajectory in time
/// The trajectory as a function of time, through the Trajectory interface (a trajectory whose
/// specs() say `continuous`: evaluateAt, vjpAt). The moving joints are the ODE's state; the held
/// joints stay at their rest positions.
class TimeTrajectory {
 public:
  void build(const exid::Trajectory& traj, const std::string& who) {
    traj_ = &traj;
    const std::string& name = traj.pluginName();
    const exid::TrajectorySpecs sp = traj.specs();
    exid::check(
        sp.continuous,
        fmt::format("{}: trajectory '{}' is not supported: it is defined on its sample grid "
                    "only, and the continuous-time optimiser needs a trajectory evaluated "
                    "at any time (fourier, spline; for 'pointwise' use adjoint_gradient or "
                    "nlopt)",
                    who, name));
    exid::check(sp.duration_s > 0,
                fmt::format("{}: trajectory '{}' declares no duration", who, name));
    const exid::Samples s0 = traj.evaluate(traj.initial());
    n_ = s0.dof();
    exid::check(s0.size() >= 2, fmt::format("{}: the trajectory has fewer than 2 samples", who));
    moving_ = sp.moving_joints;
    if (moving_.empty())
      for (int j = 0; j < n_; ++j) moving_.push_back(j);
    T_ = sp.duration_s;
    dt_ = s0.t(1) - s0.t(0);
    rest_ = s0.q.row(0).transpose();
    t1_ = Eigen::VectorXd::Zero(1);
  }

  int n() const { return n_; }
  int nm() const { return static_cast<int>(moving_.size()); }
  const std::vector<int>& moving() const { return moving_; }
  double duration() const { return T_; }
  double dt() const { return dt_; }
  const Eigen::VectorXd& rest() const { return rest_; }

  /// q, qd, qdd at time t (one sample).
  exid::Samples at(const Eigen::VectorXd& z, double t) const {
    t1_(0) = t;
    return traj_->evaluateAt(z, t1_);
  }
  /// q, qd, qdd at the times t.
  exid::Samples atTimes(const Eigen::VectorXd& z, const Eigen::VectorXd& t) const {
    return traj_->evaluateAt(z, t);
  }
  /// Gradient with respect to z of <adj, signals at time t> (adj: one sample).
  Eigen::VectorXd vjpAt(const Eigen::VectorXd& z, double t, const exid::Samples& adj) const {
    t1_(0) = t;
    return traj_->vjpAt(z, t1_, adj);
  }

 private:
  const exid::Trajectory* traj_ = nullptr;
  std::vector<int> moving_;
  int n_ = 0;
  double T_ = 0, dt_ = 0.1;
  Eigen::VectorXd rest_;
  mutable Eigen::VectorXd t1_;
};

// ---------------------------------------------------------------- CVODES forward + adjoint
struct CvodesSettings {
  double rtol = 1e-6, atol_state = 1e-9, atol_quad_rel = 1e-9;
  int checkpoint_steps = 200;
  long max_steps = 200000;
};

class ContinuousCriterion {
 public:
  ContinuousCriterion(const exid::ExcitationProblem& p, const TimeTrajectory& par,
                      CvodesSettings cs)
      : model_(p.model()), crit_(p.criterion()), par_(par), cs_(cs) {
    nb_ = model_.numBase();
    scale_ = Eigen::VectorXd::Ones(nb_);
    if (crit_.specs().scale_columns) {  // as framework/excitation/src/excitation.cpp
      Eigen::VectorXd nom = model_.baseNominal().cwiseAbs();
      const double floor = std::max(1e-6, 1e-3 * nom.maxCoeff());
      for (int i = 0; i < nb_; ++i) scale_(i) = std::max(nom(i), floor);
    }
    nq_ = nb_ * (nb_ + 1) / 2;
    sample_.t = Eigen::VectorXd::Zero(1);
    sample_.q = par_.rest().transpose();
    sample_.qd = Eigen::MatrixXd::Zero(1, par_.n());
    sample_.qdd = Eigen::MatrixXd::Zero(1, par_.n());
    // One sample must give design rows (models with one row set per instant).
    const Eigen::MatrixXd W = model_.design(sample_);
    exid::check(
        W.rows() > 0 && W.cols() == nb_,
        fmt::format(
            "optimizer 'sundials': the model '{}' gives no design rows for a single "
            "instant (the integral model's rows are windows): use adjoint_gradient or nlopt",
            model_.pluginName()));
    // Last: nothing after it may throw (the destructor, which frees it, does not run when the
    // constructor throws).
    exid::check(SUNContext_Create(nullptr, &sctx_) == 0,
                "optimizer 'sundials': SUNContext_Create failed");
  }
  ~ContinuousCriterion() { SUNContext_Free(&sctx_); }
  ContinuousCriterion(const ContinuousCriterion&) = delete;
  ContinuousCriterion& operator=(const ContinuousCriterion&) = delete;

  /// The quadrature tolerances from the discrete information matrix at the start (unscaled
  /// base columns): entry (r, c) of M is integrated to an absolute tolerance of atol_quad_rel *
  /// sqrt(M_rr M_cc), M scaled like the criterion's (S M S): each entry on its own scale, so
  /// that the columns the scaling makes small are integrated as accurately as the others.
  void setQuadScale(const Eigen::MatrixXd& M_unscaled) {
    const Eigen::VectorXd d =
        (scale_.asDiagonal() * M_unscaled * scale_.asDiagonal()).diagonal().cwiseAbs();
    const double floor = std::max(1e-300, 1e-12 * d.maxCoeff());
    quad_atol_.resize(nq_);
    for (int c = 0, idx = 0; c < nb_; ++c)
      for (int r = 0; r <= c; ++r, ++idx)
        quad_atol_(idx) =
            cs_.atol_quad_rel * std::sqrt(std::max(d(r), floor) * std::max(d(c), floor));
  }
  long stepsForward() const { return steps_f_; }
  long stepsBackward() const { return steps_b_; }

  /// J(z) and (if grad) dJ/dz by the adjoint. Throws exid::Error when CVODES fails.
  double evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* grad,
                  Eigen::MatrixXd* M_out = nullptr) {
    z_ = z;
    const int nm = par_.nm(), ny = 2 * nm;
    const double T = par_.duration();
    Holder h;
    h.y = N_VNew_Serial(std::max(ny, 1), sctx_);
    h.q = N_VNew_Serial(nq_, sctx_);
    const exid::Samples s0 = par_.at(z, 0.0);
    double* y = N_VGetArrayPointer(h.y);
    for (int i = 0; i < nm; ++i) {
      const int j = par_.moving()[static_cast<std::size_t>(i)];
      y[i] = s0.q(0, j);
      y[nm + i] = s0.qd(0, j);
    }
    if (ny == 0) y[0] = 0.0;
    N_VConst(0.0, h.q);
    h.mem = CVodeCreate(CV_ADAMS, sctx_);
    check(h.mem != nullptr, "CVodeCreate");
    check(CVodeInit(h.mem, &ContinuousCriterion::rhs, 0.0, h.y), "CVodeInit");
    check(CVodeSetUserData(h.mem, this), "CVodeSetUserData");
    check(CVodeSStolerances(h.mem, cs_.rtol, cs_.atol_state), "CVodeSStolerances");
    check(CVodeSetMaxNumSteps(h.mem, cs_.max_steps), "CVodeSetMaxNumSteps");
    h.nls = SUNNonlinSol_FixedPoint(h.y, 0, sctx_);
    check(CVodeSetNonlinearSolver(h.mem, h.nls), "CVodeSetNonlinearSolver");
    check(CVodeQuadInit(h.mem, &ContinuousCriterion::rhsQuad, h.q), "CVodeQuadInit");
    h.qatol = N_VNew_Serial(nq_, sctx_);
    for (int i = 0; i < nq_; ++i)
      N_VGetArrayPointer(h.qatol)[i] = quad_atol_.size() == nq_ ? quad_atol_(i) : cs_.atol_quad_rel;
    check(CVodeQuadSVtolerances(h.mem, cs_.rtol, h.qatol), "CVodeQuadSVtolerances");
    check(CVodeSetQuadErrCon(h.mem, SUNTRUE), "CVodeSetQuadErrCon");
    check(CVodeSetStopTime(h.mem, T), "CVodeSetStopTime");
    if (grad) check(CVodeAdjInit(h.mem, cs_.checkpoint_steps, CV_HERMITE), "CVodeAdjInit");
    double t = 0.0;
    int ncheck = 0;
    const int flag =
        grad ? CVodeF(h.mem, T, h.y, &t, CV_NORMAL, &ncheck) : CVode(h.mem, T, h.y, &t, CV_NORMAL);
    check(flag >= 0, grad ? "CVodeF" : "CVode", flag);
    check(CVodeGetQuad(h.mem, &t, h.q) >= 0, "CVodeGetQuad");
    long ns = 0;
    CVodeGetNumSteps(h.mem, &ns);
    steps_f_ += ns;
    const double* q = N_VGetArrayPointer(h.q);
    Eigen::MatrixXd M(nb_, nb_);
    for (int c = 0, idx = 0; c < nb_; ++c)
      for (int r = 0; r <= c; ++r, ++idx) M(r, c) = M(c, r) = q[idx];
    if (M_out) *M_out = M;
    Eigen::MatrixXd dM;
    const double J = crit_.evaluate(M, grad ? &dM : nullptr);
    if (!grad) return J;
    G_ = 0.5 * (dM + dM.transpose());
    // backward problem
    const int nz = static_cast<int>(z.size());
    h.yB = N_VNew_Serial(std::max(ny, 1), sctx_);
    h.qB = N_VNew_Serial(std::max(nz, 1), sctx_);
    N_VConst(0.0, h.yB);
    N_VConst(0.0, h.qB);
    int which = -1;
    check(CVodeCreateB(h.mem, CV_ADAMS, &which), "CVodeCreateB");
    check(CVodeInitB(h.mem, which, &ContinuousCriterion::rhsB, T, h.yB), "CVodeInitB");
    check(CVodeSetUserDataB(h.mem, which, this), "CVodeSetUserDataB");
    check(CVodeSStolerancesB(h.mem, which, cs_.rtol, cs_.atol_state * std::max(1.0, std::abs(J))),
          "CVodeSStolerancesB");
    check(CVodeSetMaxNumStepsB(h.mem, which, cs_.max_steps), "CVodeSetMaxNumStepsB");
    h.nlsB = SUNNonlinSol_FixedPoint(h.yB, 0, sctx_);
    check(CVodeSetNonlinearSolverB(h.mem, which, h.nlsB), "CVodeSetNonlinearSolverB");
    check(CVodeQuadInitB(h.mem, which, &ContinuousCriterion::rhsQuadB, h.qB), "CVodeQuadInitB");
    check(
        CVodeQuadSStolerancesB(h.mem, which, cs_.rtol, cs_.atol_state * std::max(1.0, std::abs(J))),
        "CVodeQuadSStolerancesB");
    check(CVodeSetQuadErrConB(h.mem, which, SUNTRUE), "CVodeSetQuadErrConB");
    check(CVodeB(h.mem, 0.0, CV_NORMAL) >= 0, "CVodeB");
    check(CVodeGetB(h.mem, which, &t, h.yB) >= 0, "CVodeGetB");
    check(CVodeGetQuadB(h.mem, which, &t, h.qB) >= 0, "CVodeGetQuadB");
    void* memB = CVodeGetAdjCVodeBmem(h.mem, which);
    if (memB) {
      CVodeGetNumSteps(memB, &ns);
      steps_b_ += ns;
    }
    const double* lam = N_VGetArrayPointer(h.yB);
    const double* qb = N_VGetArrayPointer(h.qB);
    grad->resize(nz);
    for (int i = 0; i < nz; ++i) (*grad)(i) = qb[i];
    // lambda(0)^T dy0/dz: the trajectory's VJP at t = 0 with adjoints lq on q, lqd on qd.
    exid::Samples adj0 = zeroSample();
    for (int i = 0; i < nm; ++i) {
      const int j = par_.moving()[static_cast<std::size_t>(i)];
      adj0.q(0, j) = lam[i];
      adj0.qd(0, j) = lam[nm + i];
    }
    *grad += par_.vjpAt(z, 0.0, adj0);
    *grad += crossingTerms(z);
    return J;
  }

 private:
  struct Holder {
    ~Holder() {
      if (mem) CVodeFree(&mem);
      if (nls) SUNNonlinSolFree(nls);
      if (nlsB) SUNNonlinSolFree(nlsB);
      for (N_Vector v : {y, q, yB, qB, qatol})
        if (v) N_VDestroy(v);
    }
    void* mem = nullptr;
    SUNNonlinearSolver nls = nullptr, nlsB = nullptr;
    N_Vector y = nullptr, q = nullptr, yB = nullptr, qB = nullptr, qatol = nullptr;
  };
  static void check(int flag, const char* what, int code = 0) {
    if (flag < 0)
      throw exid::Error(
          fmt::format("optimizer 'sundials': {} failed (flag {})", what, code ? code : flag));
  }
  static void check(bool ok, const char* what) {
    if (!ok) throw exid::Error(fmt::format("optimizer 'sundials': {} failed", what));
  }

  // The terms of dJ/dz the costates do not carry: where a moving joint's velocity changes sign,
  // the integrand S Phi Phi^T S / dt may jump (a Coulomb column sign(qd)); the crossing time t*
  // moves with z, dt*/dz = -(dqd_j(t*)/dz) / qdd_j(t*), and dM/dz gains (P(t*-) - P(t*+))
  // dt*/dz (Leibniz's rule at the discontinuity). Crossings are bracketed on a grid of 8 points
  // per sample period and bisected; P(t*-+) is the model's design at t* -+ 1e-9 T. A model
  // whose rows are continuous in qd (no Coulomb column, or a smoothed one) has no jump, and these
  // terms vanish.
  Eigen::VectorXd crossingTerms(const Eigen::VectorXd& z) {
    Eigen::VectorXd g = Eigen::VectorXd::Zero(z.size());
    const double T = par_.duration();
    const int steps = std::max(64, static_cast<int>(std::ceil(8.0 * T / par_.dt())));
    const Eigen::VectorXd grid = Eigen::VectorXd::LinSpaced(steps + 1, 0.0, T);
    const exid::Samples s = par_.atTimes(z, grid);
    const double delta = 1e-9 * T;
    for (int j : par_.moving()) {
      for (int k = 0; k < steps; ++k) {
        double a = grid(k), b = grid(k + 1);
        double va = s.qd(k, j);
        if (!(va * s.qd(k + 1, j) < 0.0)) continue;
        for (int it = 0; it < 60 && b - a > 4.0 * std::numeric_limits<double>::epsilon() * T;
             ++it) {
          const double m = 0.5 * (a + b), vm = par_.at(z, m).qd(0, j);
          if (vm == 0.0) {
            a = b = m;
            break;
          }
          if ((vm < 0.0) == (va < 0.0)) {
            a = m;
            va = vm;
          } else {
            b = m;
          }
        }
        const double ts = 0.5 * (a + b);
        const exid::Samples at = par_.at(z, ts);
        const double qdd = at.qdd(0, j);
        if (!(std::abs(qdd) > 0.0) || ts - delta <= 0.0 || ts + delta >= T) continue;
        const Eigen::MatrixXd Wm = model_.design(par_.at(z, ts - delta)) * scale_.asDiagonal();
        const Eigen::MatrixXd Wp = model_.design(par_.at(z, ts + delta)) * scale_.asDiagonal();
        const double jump =
            (G_.cwiseProduct(Wm.transpose() * Wm - Wp.transpose() * Wp)).sum() / par_.dt();
        if (jump == 0.0) continue;
        exid::Samples e = zeroSample();
        e.qd(0, j) = 1.0;
        g -= (jump / qdd) * par_.vjpAt(z, ts, e);  // dt*/dz = -(dqd_j/dz) / qdd_j
      }
    }
    return g;
  }

  // One sample of zeros (n joints).
  exid::Samples zeroSample() const {
    exid::Samples s;
    s.t = Eigen::VectorXd::Zero(1);
    s.q = Eigen::MatrixXd::Zero(1, par_.n());
    s.qd = s.q;
    s.qdd = s.q;
    return s;
  }

  // Fills sample_: q, qd of the moving joints from y, qdd from the trajectory at t.
  void fillSample(double t, const double* y) {
    const exid::Samples st = par_.at(z_, t);
    const int nm = par_.nm();
    sample_.t(0) = t;
    for (int i = 0; i < nm; ++i) {
      const int j = par_.moving()[static_cast<std::size_t>(i)];
      sample_.q(0, j) = y[i];
      sample_.qd(0, j) = y[nm + i];
      sample_.qdd(0, j) = st.qdd(0, j);
    }
  }

  static int rhs(double t, N_Vector yv, N_Vector ydv, void* ud) {
    auto* self = static_cast<ContinuousCriterion*>(ud);
    const int nm = self->par_.nm();
    const double* y = N_VGetArrayPointer(yv);
    double* yd = N_VGetArrayPointer(ydv);
    if (nm == 0) {
      yd[0] = 0.0;
      return 0;
    }
    try {
      const exid::Samples st = self->par_.at(self->z_, t);
      for (int i = 0; i < nm; ++i) {
        yd[i] = y[nm + i];
        yd[nm + i] = st.qdd(0, self->par_.moving()[static_cast<std::size_t>(i)]);
      }
    } catch (...) {
      return -1;
    }
    return 0;
  }

  static int rhsQuad(double t, N_Vector yv, N_Vector qdv, void* ud) {
    auto* self = static_cast<ContinuousCriterion*>(ud);
    try {
      self->fillSample(t, N_VGetArrayPointer(yv));
      const Eigen::MatrixXd W = self->model_.design(self->sample_) * self->scale_.asDiagonal();
      const Eigen::MatrixXd P = (W.transpose() * W) / self->par_.dt();
      double* qd = N_VGetArrayPointer(qdv);
      for (int c = 0, idx = 0; c < self->nb_; ++c)
        for (int r = 0; r <= c; ++r, ++idx) qd[idx] = P(r, c);
    } catch (...) {
      return -1;
    }
    return 0;
  }

  // The model's VJP at (t, y), cached for the pair rhsB / rhsQuadB at the same point.
  void adjointAt(double t, const double* y) {
    const int ny = 2 * par_.nm();
    bool same = have_adj_ && t == adj_t_;
    for (int i = 0; same && i < ny; ++i) same = adj_y_[static_cast<std::size_t>(i)] == y[i];
    if (same) return;
    fillSample(t, y);
    const Eigen::MatrixXd W = model_.design(sample_) * scale_.asDiagonal();
    const Eigen::MatrixXd dW = (2.0 / par_.dt()) * W * G_ * scale_.asDiagonal();
    model_.designVjp(sample_, dW, &adj_);
    adj_t_ = t;
    adj_y_.assign(y, y + ny);
    have_adj_ = true;
  }

  static int rhsB(double t, N_Vector yv, N_Vector yBv, N_Vector yBdv, void* ud) {
    auto* self = static_cast<ContinuousCriterion*>(ud);
    const int nm = self->par_.nm();
    const double* lam = N_VGetArrayPointer(yBv);
    double* out = N_VGetArrayPointer(yBdv);
    if (nm == 0) {
      out[0] = 0.0;
      return 0;
    }
    try {
      self->adjointAt(t, N_VGetArrayPointer(yv));
    } catch (...) {
      return -1;
    }
    for (int i = 0; i < nm; ++i) {
      const int j = self->par_.moving()[static_cast<std::size_t>(i)];
      out[i] = -self->adj_.q(0, j);
      out[nm + i] = -lam[i] - self->adj_.qd(0, j);
    }
    return 0;
  }

  static int rhsQuadB(double t, N_Vector yv, N_Vector yBv, N_Vector qBdv, void* ud) {
    auto* self = static_cast<ContinuousCriterion*>(ud);
    const int nm = self->par_.nm();
    const double* lam = N_VGetArrayPointer(yBv);
    double* out = N_VGetArrayPointer(qBdv);
    try {
      self->adjointAt(t, N_VGetArrayPointer(yv));
      // -(dw/dqdd + lqd)^T dqdd/dz: the trajectory's VJP with that adjoint on qdd alone.
      exid::Samples& a = self->adjB_;
      if (a.q.cols() != self->par_.n()) a = self->zeroSample();
      for (int i = 0; i < nm; ++i) {
        const int j = self->par_.moving()[static_cast<std::size_t>(i)];
        a.qdd(0, j) = -(self->adj_.qdd(0, j) + lam[nm + i]);
      }
      const Eigen::VectorXd g = self->par_.vjpAt(self->z_, t, a);
      for (Eigen::Index c = 0; c < g.size(); ++c) out[c] = g(c);
    } catch (...) {
      return -1;
    }
    return 0;
  }

  const exid::ObservationModel& model_;
  const exid::Criterion& crit_;
  const TimeTrajectory& par_;
  CvodesSettings cs_;
  SUNContext sctx_ = nullptr;
  int nb_ = 0, nq_ = 0;
  Eigen::VectorXd quad_atol_;  // per entry of M's upper triangle (setQuadScale)
  Eigen::VectorXd scale_, z_;
  Eigen::MatrixXd G_;
  exid::Samples sample_, adj_, adjB_;
  bool have_adj_ = false;
  double adj_t_ = 0.0;
  std::vector<double> adj_y_;
  long steps_f_ = 0, steps_b_ = 0;
};

// ---------------------------------------------------------------- the plugin
class SundialsOptimizer final : public exid::Optimizer {
 public:
  static constexpr const char* kName = "sundials";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "continuous-time design: trajectory ODE and information matrix int Phi Phi^T dt by CVODES "
      "(quadratures with error control), gradient by CVODES adjoint sensitivity, projected "
      "L-BFGS + Armijo; limits by a quadratic penalty; trajectories defined at any time (fourier, "
      "spline), models with rows per instant";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::optimizers::budgetParams(0.0, 0);
    p.push_back(exid::param_int("max_iterations", 500,
                                "accepted steps in total (0: evaluate the start only)", 0.0));
    p.push_back(exid::param_int("inner_iterations", 60, "iterations per penalty pass", 1.0));
    p.push_back(exid::param_int("memory", 10, "L-BFGS memory", 1.0, 100.0));
    p.push_back(exid::param_double("rtol", 1e-6, "",
                                   "CVODES relative tolerance (state, quadratures, adjoint)", 0.0,
                                   1.0, true));
    p.push_back(
        exid::param_double("step_gain", 0.1, "",
                           "largest change of any variable in the first step: gain / max|gradient|",
                           0.0, std::nullopt, true));
    p.push_back(exid::param_double("penalty_weight", 100.0, "",
                                   "initial rho as a multiple of |J(z0)|", 0.0, std::nullopt,
                                   true));
    p.push_back(exid::param_double(
        "ftol_rel", 1e-7, "", "stop when a pass improves J by less than this (relative)", 0.0));
    p.push_back(exid::param_double(
        "gtol", 1e-12, "", "inner stop: max|projected gradient| <= gtol max(1, |merit|)", 0.0));
    p.push_back(
        exid::param_int("checkpoint_steps", 200, "CVODES adjoint: steps between checkpoints", 1.0));
    p.push_back(
        exid::param_bool("check_gradient", false,
                         "at the start, compare the adjoint gradient with central finite "
                         "differences of the continuous criterion and time J vs J + gradient "
                         "(details: gradient_check)"));
    p.push_back(exid::param_double("fd_step", 1e-5, "",
                                   "check_gradient: relative central-difference step", 0.0,
                                   std::nullopt, true));
    return p;
  }

  explicit SundialsOptimizer(const exid::ParamSet& p)
      : budget_(exid::optimizers::readBudget(p)),
        max_iter_(static_cast<int>(p.getInt("max_iterations"))),
        inner_(static_cast<int>(p.getInt("inner_iterations"))),
        mem_(static_cast<int>(p.getInt("memory"))),
        gain_(p.getDouble("step_gain")),
        rho_rel_(p.getDouble("penalty_weight")),
        ftol_(p.getDouble("ftol_rel")),
        gtol_(p.getDouble("gtol")),
        check_grad_(p.getBool("check_gradient")),
        fd_step_(p.getDouble("fd_step")) {
    cs_.rtol = p.getDouble("rtol");
    cs_.checkpoint_steps = static_cast<int>(p.getInt("checkpoint_steps"));
  }

  exid::OptimizerResult minimize(exid::ExcitationProblem& problem,
                                 const exid::RunContext& ctx) override {
    // Its information matrix is the integral of Phi Phi^T over time, not the sum over the
    // samples to which the information already known is scaled: refused rather than mixed.
    exid::check(problem.priorInformation().size() == 0,
                "optimizer 'sundials': excitation.information (an earlier study or a prior) is "
                "not supported by the continuous-time design; use nlopt or adjoint_gradient");
    t0_ = std::chrono::steady_clock::now();
    ctx_ = &ctx;
    evals_ = 0;
    grads_ = 0;
    TimeTrajectory par;
    par.build(problem.trajectory(), "optimizer 'sundials'");
    ContinuousCriterion cc(problem, par, cs_);
    exid::optimizers::Limits lim(problem);
    problem.bounds(&lo_, &hi_);
    const Eigen::VectorXd zs = problem.initial();
    // quadrature tolerance scale from the discrete M at the start
    {
      const exid::Samples s = problem.trajectory().evaluate(zs);
      const Eigen::MatrixXd W = problem.model().design(s);
      cc.setQuadScale(W.transpose() * W);
    }
    Eigen::VectorXd z = project(zs);
    Json gcheck;
    if (check_grad_) gcheck = gradientCheck(cc, zs);
    const double J0 = cc.evaluate(zs, nullptr);
    ++evals_;
    offer(zs, J0, lim.size() ? std::max(0.0, maxOf(lim, zs)) : 0.0);
    rho_ = rho_rel_ * std::max(1e-12, std::abs(J0));
    int iters = 0;
    exid::StopReason reason =
        max_iter_ == 0 ? exid::StopReason::StartOnly : exid::StopReason::MaxIterations;
    double prev_J = HUGE_VAL;
    for (int outer = 0; iters < max_iter_; ++outer) {
      if (stop()) {
        reason = stopCause();
        break;
      }
      const bool converged = inner(cc, lim, &z, &iters);
      if (stop()) {
        reason = stopCause();
        break;
      }
      const double v = lim.size() ? std::max(0.0, maxOf(lim, z)) : 0.0;
      const bool feasible = v <= budget_.feasibility_tol;
      ctx.report(std::min(1.0, static_cast<double>(iters) / std::max(1, max_iter_)),
                 fmt::format("sundials pass {} J {:.6g} violation {:.3g}", outer + 1, cur_J_, v));
      if (!feasible) rho_ *= 10.0;
      if (feasible && converged &&
          std::abs(prev_J - cur_J_) <= ftol_ * std::max(1.0, std::abs(cur_J_))) {
        reason = exid::StopReason::ConvergedFtol;
        break;
      }
      if (feasible && converged && lim.size() == 0) {
        // "converged (gtol)" says the projected gradient is within gtol: only where the pass
        // ended on that test; a pass that ended without decrease (or below 1e-12 relative)
        // ends the run too, on the ftol kind of test, and says so (adjoint_gradient's rule)
        reason = pass_end_ == PassEnd::Stationary ? exid::StopReason::ConvergedGtol
                                                  : exid::StopReason::ConvergedFtol;
        break;
      }
      if (feasible) prev_J = cur_J_;
      if (outer > 50) {
        reason = exid::StopReason::OuterPasses;
        break;
      }
    }
    // Like the other optimisers: a criterion that is never finite leaves no point to return.
    exid::check(have_feasible_ || best_inf_z_.size() == problem.numVariables(),
                fmt::format("sundials: no point could be evaluated (the criterion was not finite "
                            "at any of the {} points tried)",
                            evals_));
    exid::OptimizerResult r;
    r.z = have_feasible_ ? best_z_ : best_inf_z_;
    r.criterion_initial = J0;
    r.criterion_final = have_feasible_ ? best_J_ : best_inf_J_;
    r.max_violation = lim.size() ? std::max(0.0, maxOf(lim, r.z)) : 0.0;
    r.iterations = iters;
    r.evaluations = evals_;
    r.wall_s = elapsed();
    r.stop_reason = reason;
    r.feasible = have_feasible_;
    r.history_t_s = ht_;
    r.history_value = hv_;
    r.details["continuous"] = true;
    r.details["criterion_is"] = "F((1/dt) int_0^T S Phi Phi^T S dt), CVODES quadratures";
    r.details["gradient_evaluations"] = Json(static_cast<long long>(grads_));
    r.details["cvodes_steps_forward"] = Json(static_cast<long long>(cc.stepsForward()));
    r.details["cvodes_steps_backward"] = Json(static_cast<long long>(cc.stepsBackward()));
    r.details["rtol"] = cs_.rtol;
    r.details["rho"] = rho_;
    // how the last pass ended, and its first-order test (the merit: J with the penalty)
    r.details["last_pass_end"] = passEndText(pass_end_);
    r.details["projected_gradient_max"] = pg_max_;
    r.details["stationarity_tol"] = pg_tol_;
    if (check_grad_) r.details["gradient_check"] = gcheck;
    r.details["discrete_criterion_initial"] = problem.value(zs, nullptr);
    r.details["discrete_criterion_final"] = problem.value(r.z, nullptr);
    return r;
  }

 private:
  using Json = exid::Json;
  double elapsed() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  }
  bool stop() const { return stopCause() != exid::StopReason::None; }
  exid::StopReason stopCause() const {
    if (budget_.max_time_s > 0 && elapsed() >= budget_.max_time_s) return exid::StopReason::MaxTime;
    if (budget_.max_evaluations > 0 && evals_ >= budget_.max_evaluations)
      return exid::StopReason::MaxEvaluations;
    if (ctx_ && ctx_->shouldStop()) return exid::StopReason::Cancelled;
    return exid::StopReason::None;
  }
  // Adjoint gradient vs central differences (exid::checkGradient, steps fd_step * max(1, |z_i|));
  // cost of J + gradient relative to J alone.
  Json gradientCheck(ContinuousCriterion& cc, const Eigen::VectorXd& z) {
    using clock = std::chrono::steady_clock;
    Eigen::VectorXd g;
    const int reps = 3;
    auto t0 = clock::now();
    for (int i = 0; i < reps; ++i) cc.evaluate(z, nullptr);
    const double tJ = std::chrono::duration<double>(clock::now() - t0).count() / reps;
    t0 = clock::now();
    for (int i = 0; i < reps; ++i) cc.evaluate(z, &g);
    const double tG = std::chrono::duration<double>(clock::now() - t0).count() / reps;
    exid::DerivativeCheckOptions o;
    o.relative_step = fd_step_;
    o.tolerance = kGradientTolerance;
    const exid::DerivativeCheck c = exid::checkGradient(
        [&](const Eigen::VectorXd& v) { return cc.evaluate(v, nullptr); }, z, g, o,
        "optimizer 'sundials': adjoint gradient of the continuous criterion");
    evals_ += 2 * reps + c.evaluations;
    Json j = c.toJson();
    const Eigen::VectorXd fd = c.numeric.row(0).transpose();
    j["max_abs_gradient"] = std::max(1e-300, fd.cwiseAbs().maxCoeff());
    j["adjoint"] = Json(std::vector<double>(g.data(), g.data() + g.size()));
    j["finite_difference"] = Json(std::vector<double>(fd.data(), fd.data() + fd.size()));
    j["time_value_s"] = tJ;
    j["time_value_and_gradient_s"] = tG;
    j["cost_ratio"] = tG / std::max(1e-300, tJ);
    return j;
  }

  static double maxOf(exid::optimizers::Limits& lim, const Eigen::VectorXd& z) {
    Eigen::VectorXd g;
    lim.eval(z, &g);
    return g.size() ? g.maxCoeff() : 0.0;
  }
  Eigen::VectorXd project(const Eigen::VectorXd& z) const { return z.cwiseMax(lo_).cwiseMin(hi_); }
  void offer(const Eigen::VectorXd& z, double J, double v) {
    if (!std::isfinite(J)) return;
    if (v <= budget_.feasibility_tol) {
      if (!have_feasible_ || J < best_J_) {
        have_feasible_ = true;
        best_J_ = J;
        best_z_ = z;
        ht_.push_back(elapsed());
        hv_.push_back(J);
      }
    } else if (!have_feasible_ && v < best_inf_v_) {
      best_inf_v_ = v;
      best_inf_J_ = J;
      best_inf_z_ = z;
    }
  }

  double merit(ContinuousCriterion& cc, exid::optimizers::Limits& lim, const Eigen::VectorXd& z,
               Eigen::VectorXd* grad) {
    double J;
    try {
      J = cc.evaluate(z, grad);
    } catch (const exid::Error&) {
      return HUGE_VAL;
    }
    ++evals_;
    ++grads_;
    if (!std::isfinite(J)) return HUGE_VAL;
    double phi = J, v = 0.0;
    if (lim.size()) {
      Eigen::VectorXd g;
      lim.eval(z, &g);
      v = std::max(0.0, g.maxCoeff());
      const Eigen::VectorXd a = g.cwiseMax(0.0);
      phi += 0.5 * rho_ * a.squaredNorm();
      if ((a.array() > 0.0).any()) grad->noalias() += rho_ * (lim.jacobian(z).transpose() * a);
    }
    offer(z, J, v);
    trial_J_ = J;
    return phi;
  }

  // One pass of at most inner_ iterations on the current merit. Returns true when the pass ended
  // (stationary, or no further decrease: pass_end_ says which, pg_max_ and pg_tol_ its last
  // first-order test), false when its iterations ran out or a stop was asked for.
  bool inner(ContinuousCriterion& cc, exid::optimizers::Limits& lim, Eigen::VectorXd* zp,
             int* iters) {
    Eigen::VectorXd& z = *zp;
    Eigen::VectorXd g;
    double phi = merit(cc, lim, z, &g);
    cur_J_ = trial_J_;
    pass_end_ = PassEnd::NotFinite;
    pg_max_ = HUGE_VAL;
    pg_tol_ = gtol_ * std::max(1.0, std::abs(phi));
    if (!std::isfinite(phi)) return true;
    // the gradient at z projected on the box, and its first-order test (pg_max_, pg_tol_)
    const auto projected = [&]() {
      Eigen::VectorXd pg = g;
      for (Eigen::Index i = 0; i < z.size(); ++i)
        if ((z(i) <= lo_(i) && g(i) > 0) || (z(i) >= hi_(i) && g(i) < 0)) pg(i) = 0.0;
      return pg;
    };
    const auto firstOrder = [&](const Eigen::VectorXd& pg) {
      pg_max_ = pg.cwiseAbs().maxCoeff();
      pg_tol_ = gtol_ * std::max(1.0, std::abs(phi));
      return pg_max_ <= pg_tol_;  // false for a NaN
    };
    exid::optimizers::LbfgsMemory mem(mem_);
    pass_end_ = PassEnd::Running;
    for (int it = 0; it < inner_ && *iters < max_iter_; ++it) {
      if (stop()) return false;
      const Eigen::VectorXd pg = projected();
      if (firstOrder(pg)) {
        pass_end_ = PassEnd::Stationary;
        return true;
      }
      const double gmax = pg_max_;
      Eigen::VectorXd d;
      double alpha = 1.0;
      if (mem.empty()) {
        d = -pg;
        alpha = gain_ / gmax;
      } else {
        d = -mem.apply(pg);  // two-loop recursion
        if (d.dot(pg) >= 0) {
          mem.clear();
          d = -pg;
          alpha = gain_ / gmax;
        }
      }
      bool accepted = false;
      Eigen::VectorXd zn, gn;
      double phin = HUGE_VAL;
      for (int ls = 0; ls < 30; ++ls) {
        zn = project(z + alpha * d);
        phin = merit(cc, lim, zn, &gn);
        if (std::isfinite(phin) && phin <= phi + 1e-4 * std::min(g.dot(zn - z), 0.0) &&
            phin < phi) {
          accepted = true;
          break;
        }
        if (stop()) return false;
        alpha *= 0.5;
      }
      if (!accepted) {
        pass_end_ = PassEnd::NoDecrease;  // (pg_max_: z's test above, not passed)
        return true;
      }
      ++*iters;
      cur_J_ = trial_J_;
      if (exid::optimizers::takeStep(mem, z, g, phi, zn, gn, phin)) {
        pass_end_ = firstOrder(projected()) ? PassEnd::Stationary : PassEnd::TinyDecrease;
        return true;
      }
    }
    firstOrder(projected());
    return false;
  }

  // check_gradient: the relative error (exid::checkGradient) above which `ok` is false.
  static constexpr double kGradientTolerance = 1e-4;
  exid::optimizers::Budget budget_;
  int max_iter_, inner_, mem_;
  double gain_, rho_rel_, ftol_, gtol_;
  bool check_grad_;
  double fd_step_;
  CvodesSettings cs_;
  std::chrono::steady_clock::time_point t0_;
  const exid::RunContext* ctx_ = nullptr;
  long evals_ = 0, grads_ = 0;
  Eigen::VectorXd lo_, hi_;
  double rho_ = 1.0, cur_J_ = 0.0, trial_J_ = 0.0;
  bool have_feasible_ = false;
  double best_J_ = HUGE_VAL, best_inf_J_ = HUGE_VAL, best_inf_v_ = HUGE_VAL;
  Eigen::VectorXd best_z_, best_inf_z_;
  std::vector<double> ht_, hv_;
  PassEnd pass_end_ = PassEnd::Running;
  double pg_max_ = HUGE_VAL, pg_tol_ = 0.0;  // the last first-order test
};

}  // namespace

EXID_REGISTER_PLUGIN(SundialsOptimizer)
