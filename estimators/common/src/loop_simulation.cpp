// exid — the closed loop integrated by CVODES, with forward sensitivities on request
// (exid/estimators/closed_loop.hpp: ClosedLoop::simulate, ClosedLoop::linearize).
#include <cvodes/cvodes.h>
#include <fmt/format.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <vector>

#include "exid/error.hpp"
#include "exid/estimators/closed_loop.hpp"

namespace exid::estimators {

using Eigen::MatrixXd;
using Eigen::VectorXd;

void ClosedLoop::linearize(const VectorXd& theta, double t, const VectorXd& q, const VectorXd& qd,
                           MatrixXd* A_q, MatrixXd* A_qd, MatrixXd* B) const {
  const int n = n_;
  MatrixXd M;
  VectorXd tau_c;
  const VectorXd a = acceleration(theta, t, q, qd, &M, &tau_c);
  Samples s;
  s.t = VectorXd::Zero(1);
  s.q = q.transpose();
  s.qd = qd.transpose();
  s.qdd = a.transpose();
  MatrixXd dWn;
  MatrixXd w = model_->designAt(s, eta_, eta_sens_ ? &dWn : nullptr);  // n x p at (q, qd, a)
  const Eigen::LDLT<MatrixXd> ldlt(M);
  // The torque columns: M a + h = u(tau_c); d/dtheta of -(M a + h - u) = u's column, minus w's.
  VectorXd slope;
  delivered(theta, tau_c, qd, &slope);
  for (const TorqueColumn& c : tcol_) {
    w.col(c.base).setZero();
    const double sq = qd[c.joint] > 0 ? 1.0 : (qd[c.joint] < 0 ? -1.0 : 0.0);
    w(c.joint, c.base) = c.kind == 1 ? -tau_c[c.joint] : std::abs(tau_c[c.joint]) * sq;
  }
  const VectorXd rest = restOf(theta);
  if (eta_sens_) {
    // d(w theta)/d eta_k: the moved full columns that are base columns, times their theta
    MatrixXd wn(n, theta.size() + eta_.size());
    wn.leftCols(theta.size()) = w;
    wn.rightCols(eta_.size()).setZero();
    for (Eigen::Index l = 0; l < dWn.cols(); ++l) {
      const int b = nl_base_[static_cast<std::size_t>(l)];
      if (b >= 0)
        wn.col(theta.size() + nl_param_[static_cast<std::size_t>(l)]) += dWn.col(l) * rest[b];
    }
    *B = -ldlt.solve(wn);
  } else {
    *B = -ldlt.solve(w);
  }
  // d(w theta)_i / d(q, qd) at fixed a: the model's torque derivatives at theta when it gives
  // them, else the design's VJP with row i = theta (its part in w)
  MatrixXd Tq(n, n), Tqd(n, n);
  VectorXd tau;
  if (!model_->fullTorqueAt(q, qd, a, eta_, fullOf(theta), &tau, &Tq, &Tqd, nullptr)) {
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
  // du/d(q, qd) = du/dtau_c dtau_c/d(q, qd) (sign(qd) has zero derivative)
  *A_q = ldlt.solve(MatrixXd(-MatrixXd(slope.cwiseProduct(Kp_).asDiagonal()) - Tq));
  *A_qd = ldlt.solve(MatrixXd(-MatrixXd(slope.cwiseProduct(Kd_).asDiagonal()) - Tqd));
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

// The sensitivity equations' right-hand side: S' = (df/dx) S + df/dtheta, exact.
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

}  // namespace

void ClosedLoop::simulate(
    const VectorXd& theta, const VectorXd& times, const Tolerances& tol, bool sens,
    const std::function<void(int, const VectorXd&, const MatrixXd*)>& at_sample) const {
  check(!open_, who_ + ": the torque-driven loop has no reference to start from");
  VectorXd qr, qdr, qddr;
  ref_.eval(ref_.t0(), &qr, &qdr, &qddr);
  VectorXd x0(2 * n_);
  x0 << qr, qdr;
  simulateFrom(theta, ref_.t0(), x0, times, tol, sens, at_sample);
}

void ClosedLoop::simulateFrom(
    const VectorXd& theta, double t0, const VectorXd& x0, const VectorXd& times,
    const Tolerances& tol, bool sens,
    const std::function<void(int, const VectorXd&, const MatrixXd*)>& at_sample) const {
  const int n = n_, p = static_cast<int>(theta.size() + (eta_sens_ ? eta_.size() : 0));
  check(x0.size() == 2 * n,
        fmt::format("{}: a start state of {} values, expected {}", who_, x0.size(), 2 * n));
  User U{this, &theta, {}, false, 0.0, {}, {}, {}, {}};
  SUNContext sctx = nullptr;
  check(SUNContext_Create(nullptr, &sctx) == 0, who_ + ": SUNContext_Create failed");
  N_Vector y = N_VNew_Serial(2 * n, sctx);
  N_VEnableFusedOps_Serial(y, SUNTRUE);
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
    N_VDestroy(y);
    SUNContext_Free(&sctx);
  };
  try {
    check(mem != nullptr && CVodeInit(mem, &rhs, t0, y) == 0 &&
              CVodeSStolerances(mem, tol.rtol, tol.atol) == 0 && CVodeSetUserData(mem, &U) == 0 &&
              CVodeSetErrHandlerFn(mem, &silent, nullptr) == 0 &&
              CVodeSetLinearSolver(mem, LS, A) == 0 &&
              CVodeSetMaxNumSteps(mem, static_cast<long>(tol.max_steps)) == 0 &&
              // (the torque-driven loop: no step past the last time, where its input may end;
              // the closed loop keeps its free steps, which the stop time changes)
              (!open_ || times.size() == 0 || CVodeSetStopTime(mem, times[times.size() - 1]) == 0),
          who_ + ": setting up CVODES failed");
    MatrixXd S;
    if (sens) {
      yS = N_VCloneVectorArray(p, y);
      for (int j = 0; j < p; ++j) N_VConst(0.0, yS[j]);  // the start does not depend on theta
      std::vector<double> abstol(static_cast<std::size_t>(p), tol.atol);
      // staggered: the sensitivities are corrected once the state has converged, and they do
      // not shorten the state's steps
      check(CVodeSensInit(mem, p, CV_STAGGERED, &sensRhs, yS) == 0 &&
                CVodeSensSStolerances(mem, std::sqrt(tol.rtol), abstol.data()) == 0 &&
                CVodeSetSensErrCon(mem, SUNFALSE) == 0,
            who_ + ": setting up the CVODES sensitivities failed");
      S = MatrixXd::Zero(2 * n, p);
    }
    double at = t0;
    for (Eigen::Index k = 0; k < times.size(); ++k) {
      const double tk = times[k];
      if (tk > at) {
        double tret = at;
        const int flag = CVode(mem, tk, y, &tret, CV_NORMAL);
        if (!U.error.empty()) throw Error(U.error);
        check(flag >= 0,
              fmt::format("{}: the simulation failed at t = {} s (CVODES flag {}; a Coulomb "
                          "friction through sign(qd) can make the closed loop chatter where a "
                          "joint sticks: differential's coulomb_smoothing_rad_s smooths it; else "
                          "try other rtol, atol, max_steps)",
                          who_, tret, flag));
        at = tk;
        if (sens) {
          CVodeGetSens(mem, &tret, yS);
          for (int j = 0; j < p; ++j)
            S.col(j) = Eigen::Map<const VectorXd>(NV_DATA_S(yS[j]), 2 * n);
        }
      }
      const VectorXd x = Eigen::Map<const VectorXd>(NV_DATA_S(y), 2 * n);
      at_sample(static_cast<int>(k), x, sens ? &S : nullptr);
    }
  } catch (...) {
    cleanup();
    throw;
  }
  cleanup();
}

}  // namespace exid::estimators
