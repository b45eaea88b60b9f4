// exid — experiment `simulate`: the SUNDIALS integrator (integrator.hpp).
#include "integrator.hpp"

#include <arkode/arkode_erkstep.h>
#include <cvode/cvode.h>
#include <fmt/format.h>

#include <cstdlib>
#include <exception>
#include <utility>

#include "exid/error.hpp"

namespace exid::simulate_experiment {

Integrator::Integrator(Rhs rhs, const Eigen::VectorXd& x0, double t0, const std::string& kind,
                       double rtol, double atol, std::int64_t max_steps)
    : rhs_(std::move(rhs)), cvode_(kind == "cvode"), n2_(static_cast<int>(x0.size())), t_(t0) {
  check(SUNContext_Create(nullptr, &sctx_), "SUNContext_Create");
  y_ = N_VNew_Serial(n2_, sctx_);
  for (int i = 0; i < n2_; ++i) NV_Ith_S(y_, i) = x0[i];
  if (cvode_) {
    mem_ = CVodeCreate(CV_BDF, sctx_);
    exid::check(mem_ != nullptr, "experiment 'simulate': CVodeCreate failed");
    check(CVodeInit(mem_, &Integrator::f, t0, y_), "CVodeInit");
    check(CVodeSStolerances(mem_, rtol, atol), "CVodeSStolerances");
    check(CVodeSetUserData(mem_, this), "CVodeSetUserData");
    A_ = SUNDenseMatrix(n2_, n2_, sctx_);
    LS_ = SUNLinSol_Dense(y_, A_, sctx_);
    check(CVodeSetLinearSolver(mem_, LS_, A_), "CVodeSetLinearSolver");
    check(CVodeSetMaxNumSteps(mem_, static_cast<long>(max_steps)), "CVodeSetMaxNumSteps");
    check(CVodeSetErrHandlerFn(mem_, &Integrator::onSolverMessage, this), "CVodeSetErrHandlerFn");
  } else {
    mem_ = ERKStepCreate(&Integrator::f, t0, y_, sctx_);
    exid::check(mem_ != nullptr, "experiment 'simulate': ERKStepCreate failed");
    check(ERKStepSStolerances(mem_, rtol, atol), "ERKStepSStolerances");
    check(ERKStepSetUserData(mem_, this), "ERKStepSetUserData");
    check(ERKStepSetMaxNumSteps(mem_, static_cast<long>(max_steps)), "ERKStepSetMaxNumSteps");
    check(ERKStepSetErrHandlerFn(mem_, &Integrator::onSolverMessage, this),
          "ERKStepSetErrHandlerFn");
  }
}

void Integrator::onSolverMessage(int, const char*, const char*, char* msg, void* self) {
  static_cast<Integrator*>(self)->solver_msg_ = msg ? msg : "";
}

// A failed step in exid's words: what happened, what to change; SUNDIALS' own text in quotes.
std::string Integrator::failureText(int flag, double t) const {
  const char* solver = cvode_ ? "CVODE" : "ARKODE";
  std::string what;
  switch (flag) {
    case -1:  // CV_TOO_MUCH_WORK, ARK_TOO_MUCH_WORK
      what =
          "max_steps internal steps did not reach the next sample: raise max_steps, loosen "
          "rtol/atol, or use a smoother Coulomb law (coulomb: tanh)";
      break;
    case -2:  // CV_TOO_MUCH_ACC, ARK_TOO_MUCH_ACC
      what = "rtol/atol ask for more accuracy than double precision gives: loosen them";
      break;
    case -3:  // CV_ERR_FAILURE, ARK_ERR_FAILURE
    case -4:  // CV_CONV_FAILURE, ARK_CONV_FAILURE
      what =
          "the step's error or convergence test failed repeatedly (stiff or discontinuous "
          "dynamics, e.g. Coulomb friction's sign): try integrator cvode, coulomb: tanh, or "
          "larger tolerances";
      break;
    default:
      what = "try larger tolerances, max_steps, or the other integrator";
  }
  // (the name is allocated by SUNDIALS: freed here)
  char* name = cvode_ ? CVodeGetReturnFlagName(flag) : ERKStepGetReturnFlagName(flag);
  const std::string flag_name = name ? name : std::to_string(flag);
  std::free(name);
  return fmt::format("experiment 'simulate': the integrator ({}) failed at t = {} s: {} ({}{})",
                     solver, t, what, flag_name,
                     solver_msg_.empty() ? std::string() : fmt::format(": \"{}\"", solver_msg_));
}

Integrator::~Integrator() {
  if (cvode_) {
    CVodeFree(&mem_);
  } else {
    ERKStepFree(&mem_);
  }
  if (LS_) SUNLinSolFree(LS_);
  if (A_) SUNMatDestroy(A_);
  N_VDestroy(y_);
  SUNContext_Free(&sctx_);
}

void Integrator::advance(double tout, Eigen::VectorXd* x) {
  double tret = t_;
  const int flag = cvode_ ? CVode(mem_, tout, y_, &tret, CV_NORMAL)
                          : ERKStepEvolve(mem_, tout, y_, &tret, ARK_NORMAL);
  if (!error_.empty()) throw exid::Error(error_);
  exid::check(flag >= 0, failureText(flag, tret));
  t_ = tret;
  for (int i = 0; i < n2_; ++i) (*x)[i] = NV_Ith_S(y_, i);
}

long Integrator::steps() const {
  long s = 0;
  if (cvode_)
    CVodeGetNumSteps(mem_, &s);
  else
    ERKStepGetNumSteps(mem_, &s);
  return s;
}

long Integrator::rhsEvals() const {
  long s = 0;
  if (cvode_)
    CVodeGetNumRhsEvals(mem_, &s);
  else
    ERKStepGetNumRhsEvals(mem_, &s);
  return s;
}

int Integrator::f(realtype t, N_Vector y, N_Vector ydot, void* user) {
  auto* self = static_cast<Integrator*>(user);
  try {
    self->rhs_(t, N_VGetArrayPointer(y), N_VGetArrayPointer(ydot));
    return 0;
  } catch (const std::exception& e) {
    self->error_ = e.what();
    return -1;
  }
}

void Integrator::check(int flag, const char* what) {
  exid::check(flag >= 0, fmt::format("experiment 'simulate': {} failed (flag {})", what, flag));
}

}  // namespace exid::simulate_experiment
