// exid — experiment `simulate`: the SUNDIALS integrator of the closed loop (CVODE BDF with a
// dense Newton solver, or ARKODE ERKStep explicit Runge-Kutta) over a state x, its right-hand
// side a function the experiment gives.
#pragma once

#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>

namespace exid::simulate_experiment {

/// xdot = rhs(t, x): rhs(t, x, xdot) writes xdot (an exception in it stops the integration
/// and is the error of advance()).
using Rhs = std::function<void(double t, const double* x, double* xdot)>;

// ---------------------------------------------------------------- SUNDIALS wrapper
class Integrator {
 public:
  Integrator(Rhs rhs, const Eigen::VectorXd& x0, double t0, const std::string& kind, double rtol,
             double atol, std::int64_t max_steps);
  ~Integrator();
  Integrator(const Integrator&) = delete;
  Integrator& operator=(const Integrator&) = delete;

  void advance(double tout, Eigen::VectorXd* x);
  long steps() const;
  long rhsEvals() const;
  std::string description() const {
    return cvode_ ? "CVODE BDF (variable order 1-5), dense Newton, difference-quotient Jacobian"
                  : "ARKODE ERKStep explicit Runge-Kutta (default order-4 table), adaptive step";
  }

 private:
  static int f(realtype t, N_Vector y, N_Vector ydot, void* user);
  static void check(int flag, const char* what);
  // SUNDIALS' messages kept (never printed): the last one goes into exid's error, in its words.
  static void onSolverMessage(int code, const char* module, const char* function, char* msg,
                              void* self);
  std::string failureText(int flag, double t) const;
  Rhs rhs_;
  bool cvode_;
  int n2_;
  double t_;
  SUNContext sctx_ = nullptr;
  N_Vector y_ = nullptr;
  void* mem_ = nullptr;
  SUNMatrix A_ = nullptr;
  SUNLinearSolver LS_ = nullptr;
  std::string error_;
  std::string solver_msg_;  // SUNDIALS' last message
};

}  // namespace exid::simulate_experiment
