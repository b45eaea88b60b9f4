// exid — the closed loop integrated by CVODES, with forward sensitivities on request
// (exid/estimators/closed_loop.hpp: ClosedLoop::simulate, ClosedLoop::linearize).
#include <cvodes/cvodes.h>
#include <fmt/format.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <cmath>
#include <vector>

#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/closed_loop.hpp"

namespace exid::estimators {

using Eigen::MatrixXd;
using Eigen::VectorXd;

MatrixXd ClosedLoop::sensitivityRows(const VectorXd& theta, const VectorXd& t, const MatrixXd& q,
                                     const MatrixXd& qd, const MatrixXd& a,
                                     const MatrixXd& tau_c) const {
  const int n = n_;
  const Eigen::Index N = q.rows();
  Samples s;
  s.t = t;
  s.q = q;
  s.qd = qd;
  s.qdd = a;
  if (floating_) {
    s.base.resize(N, fb_base_.cols());
    for (Eigen::Index k = 0; k < N; ++k) s.base.row(k) = recordedAt(fb_base_, t[k]);
  }
  MatrixXd dWn;
  MatrixXd w = model_->designAt(s, eta_, eta_sens_ ? &dWn : nullptr);  // N n x p at (q, qd, a)
  if (floating_) {                                                     // the joint rows
    w = jointRows(w);
    if (eta_sens_) dWn = jointRows(dWn);
  }
  // The torque columns: M a + h = u(tau_c); d/dtheta of -(M a + h - u) = u's column, minus w's.
  for (const TorqueColumn& c : tcol_) {
    w.col(c.base).setZero();
    for (Eigen::Index k = 0; k < N; ++k) {
      const double sq = exid::coulombSign(qd(k, c.joint)), tj = tau_c(k, c.joint);
      w(k * n + c.joint, c.base) = c.kind == 1 ? -tj : std::abs(tj) * sq;
    }
  }
  if (!eta_sens_) return w;
  // d(w theta)/d eta_k: the moved full columns that are base columns, times their theta
  const VectorXd rest = restOf(theta);
  MatrixXd wn(w.rows(), theta.size() + eta_.size());
  wn.leftCols(theta.size()) = w;
  wn.rightCols(eta_.size()).setZero();
  for (Eigen::Index l = 0; l < dWn.cols(); ++l) {
    const int b = nl_base_[static_cast<std::size_t>(l)];
    if (b >= 0)
      wn.col(theta.size() + nl_param_[static_cast<std::size_t>(l)]) += dWn.col(l) * rest[b];
  }
  return wn;
}

void ClosedLoop::linearParts(const VectorXd& theta, double t, const VectorXd& q, const VectorXd& qd,
                             bool with_w, LinearParts* out) const {
  const int n = n_;
  MatrixXd& M = out->M;
  VectorXd& tau_c = out->tau_c;
  VectorXd& a = out->a;
  a = acceleration(theta, t, q, qd, &M, &tau_c);
  VectorXd slope;
  delivered(theta, tau_c, qd, &slope);
  if (with_w)
    out->W = sensitivityRows(theta, VectorXd::Constant(1, t), q.transpose(), qd.transpose(),
                             a.transpose(), tau_c.transpose());
  // d(w theta)_i / d(q, qd) at fixed a: the model's torque derivatives at theta when it gives
  // them, else the design's VJP with row i = theta (its part in w)
  MatrixXd& Tq = out->Gq;
  MatrixXd& Tqd = out->Gqd;
  Tq.resize(n, n);
  Tqd.resize(n, n);
  VectorXd tau;
  if (floating_) {
    // central differences of w(q, qd, a) theta - c(q, t) (a floating model gives no design
    // VJP): steps of cbrt(eps) times the coordinate's size, error ~1e-10 of the torque
    const VectorXd rest = restOf(theta);
    const double e = std::cbrt(2.2e-16);
    for (int j = 0; j < n; ++j) {
      VectorXd qp = q, qm = q, vp = qd, vm = qd;
      const double hq = e * std::max(1.0, std::abs(q[j])), hv = e * std::max(1.0, std::abs(qd[j]));
      qp[j] += hq;
      qm[j] -= hq;
      vp[j] += hv;
      vm[j] -= hv;
      Tq.col(j) = (floatingTorque(rest, t, qp, qd, a) - floatingTorque(rest, t, qm, qd, a)) /
                  (qp[j] - qm[j]);
      // (the contact torque does not depend on qd)
      Tqd.col(j) =
          (floatingTorque(rest, t, q, vp, a, false) - floatingTorque(rest, t, q, vm, a, false)) /
          (vp[j] - vm[j]);
    }
  } else if (!model_->fullTorqueAt(q, qd, a, eta_, fullOf(theta), &tau, &Tq, &Tqd, nullptr)) {
    Samples s;
    s.t = VectorXd::Zero(1);
    s.q = q.transpose();
    s.qd = qd.transpose();
    s.qdd = a.transpose();
    const VectorXd rest = restOf(theta);
    MatrixXd G = MatrixXd::Zero(n, theta.size());
    Samples grad;
    for (int i = 0; i < n; ++i) {
      G.setZero();
      G.row(i) = rest.transpose();
      model_->designVjpAt(s, eta_, G, &grad);
      Tq.row(i) = grad.q.row(0);
      Tqd.row(i) = grad.qd.row(0);
    }
  }
  // du/d(q, qd) = du/dtau_c dtau_c/d(q, qd) (sign(qd) has zero derivative): G = T + slope K
  Tq.diagonal() += slope.cwiseProduct(Kp_);
  Tqd.diagonal() += slope.cwiseProduct(Kd_);
}

void ClosedLoop::linearize(const VectorXd& theta, double t, const VectorXd& q, const VectorXd& qd,
                           MatrixXd* A_q, MatrixXd* A_qd, MatrixXd* B) const {
  LinearParts P;
  linearParts(theta, t, q, qd, B != nullptr, &P);
  const Eigen::LDLT<MatrixXd> ldlt(P.M);
  if (B) *B = -ldlt.solve(P.W);
  *A_q = -ldlt.solve(P.Gq);
  *A_qd = -ldlt.solve(P.Gqd);
}

VectorXd ClosedLoop::baseRows(const VectorXd& theta, double t, const VectorXd& x, const MatrixXd* S,
                              MatrixXd* J) const {
  const int n = n_, nb = baseRowCount();
  check(nb > 0, who_ + ": the model gives no base rows (rows: all on a floating base)");
  const VectorXd q = x.head(n), qd = x.tail(n);
  const VectorXd a = acceleration(theta, t, q, qd);
  const VectorXd rest = restOf(theta);
  const Eigen::RowVectorXd b = recordedAt(fb_base_, t);
  auto rows = [&](const VectorXd& qq, const VectorXd& vv, const VectorXd& aa) {
    Samples s;
    s.t = VectorXd::Constant(1, t);
    s.q = qq.transpose();
    s.qd = vv.transpose();
    s.qdd = aa.transpose();
    s.base = b;
    return MatrixXd(model_->designAt(s, eta_, nullptr).topRows(nb));
  };
  MatrixXd Wb = rows(q, qd, a);
  const VectorXd yb = Wb * rest;
  if (S) {
    check(!eta_sens_, who_ +
                          ": the base rows' sensitivities to the model's nonlinear parameters "
                          "are not available on a floating base");
    MatrixXd A_q, A_qd, B;
    linearize(theta, t, q, qd, &A_q, &A_qd, &B);
    const MatrixXd da = A_q * S->topRows(n) + A_qd * S->bottomRows(n) + B;
    MatrixXd Tq(nb, n), Tqd(nb, n), Ta(nb, n);
    const VectorXd y0 = rows(q, qd, VectorXd::Zero(n)) * rest;
    const double e = std::cbrt(2.2e-16);
    for (int j = 0; j < n; ++j) {
      VectorXd qp = q, qm = q, vp = qd, vm = qd;
      qp[j] += e * std::max(1.0, std::abs(q[j]));
      qm[j] -= e * std::max(1.0, std::abs(q[j]));
      vp[j] += e * std::max(1.0, std::abs(qd[j]));
      vm[j] -= e * std::max(1.0, std::abs(qd[j]));
      Tq.col(j) = (rows(qp, qd, a) - rows(qm, qd, a)) * rest / (qp[j] - qm[j]);
      Tqd.col(j) = (rows(q, vp, a) - rows(q, vm, a)) * rest / (vp[j] - vm[j]);
      Ta.col(j) = rows(q, qd, VectorXd::Unit(n, j)) * rest - y0;
    }
    for (const TorqueColumn& c : tcol_) Wb.col(c.base).setZero();  // (not in w)
    *J = Tq * S->topRows(n) + Tqd * S->bottomRows(n) + Ta * da;
    J->leftCols(theta.size()) += Wb;
  }
  return yb;
}

namespace {

struct User {
  const ClosedLoop* loop;
  const VectorXd* theta;
  std::string error;
  bool lin_valid = false;  // the last linearisation (sensRhs)
  double lin_t = 0.0;
  VectorXd lin_x;
  MatrixXd A_q, A_qd, B;
};

// The state's Jacobian for CVODES's Newton iterations: [0 I; A_q A_qd] (linearize(), exact).
int jacobian(double t, N_Vector y, N_Vector, SUNMatrix J, void* user, N_Vector, N_Vector,
             N_Vector) {
  auto* U = static_cast<User*>(user);
  const int n = U->loop->dof();
  try {
    Eigen::Map<const VectorXd> x(NV_DATA_S(y), 2 * n);
    MatrixXd A_q, A_qd;
    U->loop->linearize(*U->theta, t, x.head(n), x.tail(n), &A_q, &A_qd, nullptr);
    if (!A_q.allFinite() || !A_qd.allFinite()) return 1;
    SUNMatZero(J);
    for (int i = 0; i < n; ++i) {
      SM_ELEMENT_D(J, i, n + i) = 1.0;
      for (int j = 0; j < n; ++j) {
        SM_ELEMENT_D(J, n + i, j) = A_q(i, j);
        SM_ELEMENT_D(J, n + i, n + j) = A_qd(i, j);
      }
    }
    return 0;
  } catch (const std::exception& e) {
    U->error = e.what();
    return -1;
  }
}

// CVODES's forward sensitivities' right-hand side: S' = (df/dx) S + df/dtheta, exact.
int sensRhs(int Ns, double t, N_Vector y, N_Vector, N_Vector* yS, N_Vector* ySdot, void* user,
            N_Vector, N_Vector) {
  auto* U = static_cast<User*>(user);
  const int n = U->loop->dof();
  try {
    Eigen::Map<const VectorXd> x(NV_DATA_S(y), 2 * n);
    // (the corrector asks again at the same point: the linearisation is kept)
    if (!(U->lin_valid && U->lin_t == t && U->lin_x == x)) {
      U->loop->linearize(*U->theta, t, x.head(n), x.tail(n), &U->A_q, &U->A_qd, &U->B);
      U->lin_t = t;
      U->lin_x = x;
      U->lin_valid = true;
    }
    for (int j = 0; j < Ns; ++j) {
      Eigen::Map<const VectorXd> s(NV_DATA_S(yS[j]), 2 * n);
      Eigen::Map<VectorXd> sd(NV_DATA_S(ySdot[j]), 2 * n);
      sd.head(n) = s.tail(n);
      sd.tail(n) = U->A_q * s.head(n) + U->A_qd * s.tail(n) + U->B.col(j);
    }
    return 0;
  } catch (const std::exception& e) {
    U->error = e.what();
    return -1;
  }
}

// CVODES's own messages: the failure is reported once, as an exid::Error with the time.
void silent(int, const char*, const char*, char*, void*) {}

int rhs(double t, N_Vector y, N_Vector yd, void* user) {
  auto* U = static_cast<User*>(user);
  const int n = U->loop->dof();
  try {
    Eigen::Map<const VectorXd> x(NV_DATA_S(y), 2 * n);
    const VectorXd a = U->loop->acceleration(*U->theta, t, x.head(n), x.tail(n));
    Eigen::Map<VectorXd> xd(NV_DATA_S(yd), 2 * n);
    xd.head(n) = x.tail(n);
    xd.tail(n) = a;
    return a.allFinite() ? 0 : 1;
  } catch (const std::exception& e) {
    U->error = e.what();
    return -1;
  }
}

}  // namespace

void ClosedLoop::pollStop(unsigned long* count) const {
  if (stop_ && (++*count & 31u) == 0 && stop_()) throw Error(who_ + ": stopped");
}

void ClosedLoop::simulate(
    const VectorXd& theta, const VectorXd& times, const Tolerances& tol, bool sens,
    const std::function<void(int, const VectorXd&, const MatrixXd*)>& at_sample, Path* path) const {
  check(!open_, who_ + ": the torque-driven loop has no reference to start from");
  VectorXd qr, qdr, qddr;
  ref_.eval(ref_.t0(), &qr, &qdr, &qddr);
  VectorXd x0(2 * n_);
  x0 << qr, qdr;
  simulateFrom(theta, ref_.t0(), x0, times, tol, sens, at_sample, path);
}

// The sensitivities S = dx/dtheta obey S' = J(t) S + B(t), J = [0 I; A_q A_qd], B = [0; da/dtheta]
// (linearize(), exact). They are integrated along CVODES's own steps of the state (which the
// sensitivities never change: the state's path is the same with them or without), as one
// 2n x p matrix, by the variable-step BDF2 formula (backward Euler on a first step and where a
// step grows more than twice: BDF2's stability bound is 1 + sqrt 2), both L-stable: the loop's
// fast modes (the friction's slope through a light link) are damped as they are, at any step.
// Between steps S is read by the cubic Hermite interpolant of S and S' at the steps' ends. Each
// step is solved multiplied through by M (no M^-1 W: sensitivitiesAlong), and S' at its end is
// the formula's own (S - R0) / g.
namespace {

// A step's end: S and S' there (row-major: the products with n x n matrices run along rows of
// p entries).
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
struct SensStep {
  RowMatrix S, Sd;
};

// Y (+)= alpha A X for a small A (n x n) and X, Y n x p row-major: each row of Y is summed in
// registers eight entries at a time over the n rows of X (contiguous; a coefficient-wise product
// runs down X's strided columns, Eigen's blocked product packs its operands first).
template <class XBlock>
void rowProduct(double alpha, const MatrixXd& A, const XBlock& X, RowMatrix* Y, bool accumulate) {
  const Eigen::Index n = A.rows(), m = A.cols(), p = X.cols();
  if (!accumulate) Y->resize(n, p);
  for (Eigen::Index i = 0; i < n; ++i) {
    double* y = Y->row(i).data();
    Eigen::Index c = 0;
    for (; c + 8 <= p; c += 8) {
      double acc[8];
      for (int j = 0; j < 8; ++j) acc[j] = accumulate ? y[c + j] : 0.0;
      for (Eigen::Index k = 0; k < m; ++k) {
        const double a = alpha * A(i, k);
        const double* x = X.row(k).data() + c;
        for (int j = 0; j < 8; ++j) acc[j] += a * x[j];
      }
      for (int j = 0; j < 8; ++j) y[c + j] = acc[j];
    }
    for (; c < p; ++c) {
      double acc = accumulate ? y[c] : 0.0;
      for (Eigen::Index k = 0; k < m; ++k) acc += (alpha * A(i, k)) * X(k, c);
      y[c] = acc;
    }
  }
}

// CVODES set up for the state from t0 (BDF, dense Newton with the exact Jacobian, silent: the
// errors are thrown with their context); torque_driven: no step past t_end, the last time.
void setUpCvodes(void* mem, N_Vector y, SUNMatrix A, SUNLinearSolver LS, User* U, double t0,
                 double t_end, bool no_times, const ClosedLoop::Tolerances& tol, bool torque_driven,
                 const std::string& who) {
  check(mem != nullptr && CVodeInit(mem, &rhs, t0, y) == 0 &&
            CVodeSStolerances(mem, tol.rtol, tol.atol) == 0 && CVodeSetUserData(mem, U) == 0 &&
            CVodeSetErrHandlerFn(mem, &silent, nullptr) == 0 &&
            CVodeSetLinearSolver(mem, LS, A) == 0 && CVodeSetJacFn(mem, &jacobian) == 0 &&
            CVodeSetMaxNumSteps(mem, static_cast<long>(tol.max_steps)) == 0 &&
            // (the torque-driven loop: no step past the last time, where its input may end;
            // the closed loop keeps its free steps, which the stop time changes)
            (!torque_driven || no_times || CVodeSetStopTime(mem, t_end) == 0),
        who + ": setting up CVODES failed");
}

// CVODES's own forward sensitivities of p parameters (staggered), zero at the start; *yS: their
// vectors (the caller frees them).
void setUpSensitivities(void* mem, N_Vector y, int p, const ClosedLoop::Tolerances& tol,
                        const std::string& who, N_Vector** yS_out) {
  N_Vector*& yS = *yS_out;
  N_VEnableFusedOps_Serial(y, SUNTRUE);
  yS = N_VCloneVectorArray(p, y);
  for (int j = 0; j < p; ++j) N_VConst(0.0, yS[j]);  // the start does not depend on theta
  std::vector<double> abstol(static_cast<std::size_t>(p), tol.atol);
  check(CVodeSensInit(mem, p, CV_STAGGERED, &sensRhs, yS) == 0 &&
            CVodeSensSStolerances(mem, std::sqrt(tol.rtol), abstol.data()) == 0 &&
            CVodeSetSensErrCon(mem, SUNFALSE) == 0,
        who + ": setting up the CVODES sensitivities failed");
}

// One CVODES step from tn to tret checked: the right-hand side's error, a failed step, a step
// that made no progress.
void checkStep(const User& U, int flag, double tret, double tn, const std::string& who) {
  if (!U.error.empty()) throw Error(U.error);
  if (flag < 0)
    throw Error(
        fmt::format("{}: the simulation failed at t = {} s (CVODES flag {}; a Coulomb "
                    "friction through sign(qd) can make the closed loop chatter where a "
                    "joint sticks: differential's coulomb_smoothing_rad_s smooths it; else "
                    "try other rtol, atol, max_steps)",
                    who, tret, flag));
  if (!(tret > tn))
    throw Error(fmt::format("{}: the simulation made no progress at t = {} s", who, tret));
}

}  // namespace

void ClosedLoop::simulateFrom(
    const VectorXd& theta, double t0, const VectorXd& x0, const VectorXd& times,
    const Tolerances& tol, bool sens,
    const std::function<void(int, const VectorXd&, const MatrixXd*)>& at_sample, Path* path) const {
  const int n = n_;
  check(x0.size() == 2 * n,
        fmt::format("{}: a start state of {} values, expected {}", who_, x0.size(), 2 * n));
  // with the sensitivities: the state's path first, then the sensitivities along it (or
  // CVODES's forward sensitivities with it)
  const bool cv = sens && tol.cvodes_sensitivities;
  const int p = static_cast<int>(theta.size() + (eta_sens_ ? eta_.size() : 0));
  Path own;
  Path* rec = sens && !cv ? &own : (sens ? nullptr : path);
  if (rec) {
    rec->t0 = t0;
    rec->x0 = x0;
    rec->t.clear();
    rec->x.clear();
    rec->samples.resize(2 * n, times.size());
    rec->times = times;
  }
  User U{this, &theta, {}, false, 0.0, {}, {}, {}, {}};
  SUNContext sctx = nullptr;
  check(SUNContext_Create(nullptr, &sctx) == 0, who_ + ": SUNContext_Create failed");
  N_Vector y = N_VNew_Serial(2 * n, sctx);
  N_Vector yk = N_VNew_Serial(2 * n, sctx);
  for (int j = 0; j < 2 * n; ++j) NV_Ith_S(y, j) = x0[j];
  void* mem = CVodeCreate(CV_BDF, sctx);
  SUNMatrix A = SUNDenseMatrix(2 * n, 2 * n, sctx);
  SUNLinearSolver LS = SUNLinSol_Dense(y, A, sctx);
  N_Vector* yS = nullptr;
  auto cleanup = [&] {
    CVodeFree(&mem);
    if (yS) N_VDestroyVectorArray(yS, p);
    SUNLinSolFree(LS);
    SUNMatDestroy(A);
    N_VDestroy(yk);
    N_VDestroy(y);
    SUNContext_Free(&sctx);
  };
  try {
    const double t_end = times.size() > 0 ? times[times.size() - 1] : t0;
    setUpCvodes(mem, y, A, LS, &U, t0, t_end, times.size() == 0, tol, open_, who_);
    MatrixXd S;
    if (cv) {
      setUpSensitivities(mem, y, p, tol, who_, &yS);
      S = MatrixXd::Zero(2 * n, p);
    }
    double tn = t0;
    Eigen::Index k = 0;
    VectorXd x = x0;
    auto emit = [&](double t1) {  // the samples up to t1 (interpolated by CVODES)
      for (; k < times.size() && times[k] <= t1; ++k) {
        const double tk = times[k];
        if (tk == t1) {
          x = Eigen::Map<const VectorXd>(NV_DATA_S(y), 2 * n);
        } else if (tk == t0) {
          x = x0;
        } else {
          if (CVodeGetDky(mem, tk, 0, yk) != 0)
            throw Error(fmt::format("{}: the state at t = {} s cannot be read", who_, tk));
          x = Eigen::Map<const VectorXd>(NV_DATA_S(yk), 2 * n);
        }
        if (rec) rec->samples.col(k) = x;
        if (cv && tk > t0) {
          if (CVodeGetSensDky(mem, tk, 0, yS) != 0)
            throw Error(fmt::format("{}: the sensitivities at t = {} s cannot be read", who_, tk));
          for (int j = 0; j < p; ++j)
            S.col(j) = Eigen::Map<const VectorXd>(NV_DATA_S(yS[j]), 2 * n);
        }
        if (!sens || cv) at_sample(static_cast<int>(k), x, cv ? &S : nullptr);
      }
    };
    emit(t0);  // (samples at the start)
    // CV_ONE_STEP returns after each step, so CVodeSetMaxNumSteps bounds nothing here: the
    // steps between two samples are counted (a diverging loop took ever smaller steps, for
    // ever).
    std::int64_t steps_since_sample = 0;
    unsigned long steps = 0;
    while (k < times.size()) {
      pollStop(&steps);
      if (++steps_since_sample > tol.max_steps)
        throw Error(fmt::format(
            "{}: the simulation took more than max_steps = {} steps between the samples at t = "
            "{} s and t = {} s (reached t = {} s): the simulated loop diverges or is too stiff "
            "(check the gains kp_Nm_per_rad, kd_Nm_s_per_rad; or raise max_steps)",
            who_, tol.max_steps, k > 0 ? times[k - 1] : t0, times[k], tn));
      const Eigen::Index k_before = k;
      double tret = tn;
      // (tout, the next sample, sets the first step's size and the direction)
      const int flag = CVode(mem, times[k], y, &tret, CV_ONE_STEP);
      checkStep(U, flag, tret, tn, who_);
      if (rec) {
        rec->t.push_back(tret);
        rec->x.insert(rec->x.end(), NV_DATA_S(y), NV_DATA_S(y) + 2 * n);
      }
      emit(tret);
      if (k != k_before) steps_since_sample = 0;
      tn = tret;
    }
  } catch (...) {
    cleanup();
    throw;
  }
  cleanup();
  if (sens && !cv) sensitivitiesAlong(theta, own, at_sample);
}

void ClosedLoop::sensitivitiesAlong(
    const VectorXd& theta, const Path& path,
    const std::function<void(int, const VectorXd&, const MatrixXd*)>& at_sample) const {
  const int n = n_, p = static_cast<int>(theta.size() + (eta_sens_ ? eta_.size() : 0));
  const VectorXd& times = path.times;
  check(path.x0.size() == 2 * n && path.x.size() == path.t.size() * 2 * n &&
            path.samples.rows() == 2 * n && path.samples.cols() == times.size(),
        who_ + ": sensitivitiesAlong: not the path of a whole simulation");
  SensStep cur, next;
  RowMatrix S_prev, R0, rhs, Xv;
  MatrixXd S_k;
  // the start does not depend on theta: S = 0, S' = (0; B) = (0; -M^-1 W)
  cur.S = RowMatrix::Zero(2 * n, p);
  {
    LinearParts P0;
    linearParts(theta, path.t0, path.x0.head(n), path.x0.tail(n), true, &P0);
    cur.Sd = RowMatrix::Zero(2 * n, p);
    cur.Sd.bottomRows(n) = -Eigen::LDLT<MatrixXd>(P0.M).solve(P0.W);
  }
  double tn = path.t0, h_prev = 0.0;
  Eigen::Index k = 0;
  S_k = MatrixXd::Zero(2 * n, p);
  for (; k < times.size() && times[k] <= path.t0; ++k)
    at_sample(static_cast<int>(k), path.samples.col(k), &S_k);
  unsigned long steps = 0;
  next.S.resize(2 * n, p);
  next.Sd.resize(2 * n, p);
  // The steps in blocks: each step's state part (M, G, a, the command), then the model's rows
  // of the whole block in one call (its kernels take several samples at once).
  constexpr std::size_t kBlock = 32;
  std::vector<LinearParts> parts(kBlock);
  MatrixXd Wb, qb, qdb, ab, cb;
  VectorXd tb;
  std::size_t block_start = 0, block_end = 0;
  for (std::size_t i = 0; i < path.t.size() && k < times.size(); ++i) {
    pollStop(&steps);
    if (i == block_end) {
      block_start = i;
      block_end = std::min(path.t.size(), i + kBlock);
      const Eigen::Index N = static_cast<Eigen::Index>(block_end - block_start);
      qb.resize(N, n);
      qdb.resize(N, n);
      ab.resize(N, n);
      cb.resize(N, n);
      tb.resize(N);
      for (std::size_t j = block_start; j < block_end; ++j) {
        const Eigen::Index r = static_cast<Eigen::Index>(j - block_start);
        const Eigen::Map<const VectorXd> xj(path.x.data() + 2 * n * j, 2 * n);
        LinearParts& Pj = parts[j - block_start];
        linearParts(theta, path.t[j], xj.head(n), xj.tail(n), false, &Pj);
        tb[r] = path.t[j];
        qb.row(r) = xj.head(n).transpose();
        qdb.row(r) = xj.tail(n).transpose();
        ab.row(r) = Pj.a.transpose();
        cb.row(r) = Pj.tau_c.transpose();
      }
      Wb = sensitivityRows(theta, tb, qb, qdb, ab, cb);
    }
    const LinearParts& P = parts[i - block_start];
    const auto W = Wb.middleRows(static_cast<Eigen::Index>(i - block_start) * n, n);
    const double t1 = path.t[i], h = t1 - tn;
    // S_1 = R0 + g f(S_1), f(S) = J S + B: BDF2 with steps h_prev, h (R0 = c S_0 - d S_-1,
    // g = beta h), else backward Euler (R0 = S_0, g = h)
    const double w = h_prev > 0.0 ? h / h_prev : 0.0;
    double g = h;
    if (w > 0.0 && w <= 2.0) {
      const double c = (1 + w) * (1 + w) / (1 + 2 * w), d = w * w / (1 + 2 * w);
      g = (1 + w) / (1 + 2 * w) * h;
      R0 = c * cur.S - d * S_prev;
    } else {
      R0 = cur.S;
    }
    // With M: S_1v = R0v + g M^-1 (-Gq S_1q - Gqd S_1v - W) and S_1q = R0q + g S_1v, so
    // (M + g Gqd + g^2 Gq) S_1v = M R0v - g (W + Gq R0q): one n x n solve, no M^-1 W.
    const MatrixXd Kg = P.M + g * P.Gqd + (g * g) * P.Gq;
    rhs = -g * W;
    rowProduct(1.0, P.M, R0.bottomRows(n), &rhs, true);
    rowProduct(-g, P.Gq, R0.topRows(n), &rhs, true);
    rowProduct(1.0, Kg.partialPivLu().inverse(), rhs, &Xv, false);
    next.S.topRows(n) = R0.topRows(n) + g * Xv;
    next.S.bottomRows(n) = Xv;
    // S' there from the formula itself: f(S_1) = (S_1 - R0) / g
    next.Sd.topRows(n) = Xv;
    next.Sd.bottomRows(n) = (Xv - R0.bottomRows(n)) / g;
    for (; k < times.size() && times[k] <= t1; ++k) {  // S between the steps' ends: Hermite
      const double tk = times[k];
      if (tk == t1) {
        S_k = next.S;
      } else {
        const double u = (tk - tn) / h, u2 = u * u, u3 = u2 * u;
        S_k = (2 * u3 - 3 * u2 + 1) * cur.S + ((u3 - 2 * u2 + u) * h) * cur.Sd +
              (3 * u2 - 2 * u3) * next.S + ((u3 - u2) * h) * next.Sd;
      }
      at_sample(static_cast<int>(k), path.samples.col(k), &S_k);
    }
    S_prev.swap(cur.S);
    std::swap(cur, next);
    if (next.S.rows() != 2 * n) next.S.resize(2 * n, p);
    if (next.Sd.rows() != 2 * n) next.Sd.resize(2 * n, p);
    tn = t1;
    h_prev = h;
  }
  check(k == times.size(), who_ + ": sensitivitiesAlong: the path ends before the last sample");
}

}  // namespace exid::estimators
