// exid — the closed loop of a robot described by a model's rows at estimated base parameters,
// for the estimators that simulate it (`iv`, `didim`): the commanded trajectory read from a
// file, the PD + feed-forward controller, and the acceleration from the model's own rows
// (docs/estimators.md, "iv").
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/interfaces.hpp"

namespace exid::estimators {

/// The commanded trajectory: samples of (q, qd, qdd) in measured coordinates, read between
/// them by quintic Hermite interpolation (exid::quinticHermite, as the `simulate` experiment
/// reads a sampled reference).
struct Reference {
  Samples s;
  /// At time `at` (clamped to the samples' span).
  void eval(double at, Eigen::VectorXd* q, Eigen::VectorXd* qd, Eigen::VectorXd* qdd) const;
  double t0() const { return s.t[0]; }
  double t1() const { return s.t[s.size() - 1]; }
};

/// A CSV of t, q1..qn, qd1..qdn, qdd1..qddn in joint coordinates (`exid excite --export`'s
/// trajectory.csv), mapped to measured coordinates. `who` starts the messages.
Reference readReference(const std::filesystem::path& file, const RobotModel& robot,
                        const std::string& who);

/// The closed loop tau_c = tau_ff(qr, qdr, qddr) + Kp (qr - q) + Kd (qdr - qd) of the robot
/// whose torque is w(q, qd, qdd) theta (the model's design rows, one per joint, all joints):
/// M e_i = w(q, qd, e_i) theta - w(q, qd, 0) theta, h = w(q, qd, 0) theta.
/// Columns that hold the recorded torque (exid::torqueColumnKind: the `differential` model's
/// drive gains dK<j> and load-dependent Coulomb FcL<j>) are not part of w: the recorded torque
/// is the controller's command tau_c, and the drive delivers
///   u_j(tau_c) = tau_c,j (1 + dK_j) - FcL_j |tau_c,j| sign(qd_j)
/// (a drive's true torque constant over the controller's nominal one; the gear's friction
/// growing with the torque it carries), so M a + h = u(tau_c) with theta's other entries.
///
/// On a floating base (a model with ModelSpecs::floating_base, e.g. `floating_base` with rows
/// all or joints) the base's motion is measured, not simulated: the loop is the joints'
/// dynamics on a base moving as recorded (a manipulator on a moving platform),
///   M_jj(q) qdd = u(tau_c) + c(q, t) - h_j(q, qd, b(t)),
/// M_jj and h_j the model's joint rows with the base motion b(t) (Dataset::base) prescribed,
/// c(q, t) the recorded contact wrenches' joint torque (sum_c J_c(q)^T w_c(t): the joint rows'
/// measured side at zero torque, as the model's rows give it), b(t) and w_c(t) read between the
/// recorded samples by the degree-5 Lagrange polynomial through the six nearest samples
/// (sixth-order accurate; exact at the samples). The state is the joints' (q, qd) alone; the
/// feed-forward is the joint rows of exid::floatingInverseDynamics at the reference with b(t)
/// (the robot description's rigid bodies). The derivatives in theta are exact (the joint rows);
/// those in q and qd are central differences of the joint rows' torque (floating models give
/// no design VJP).
class ClosedLoop {
 public:
  /// The controller and its inputs (parameters of the estimator `who`): reference_file,
  /// kp_Nm_per_rad, kd_Nm_s_per_rad, feedforward. Checks the model (per sample, one row per
  /// joint of every joint) and that the recording's times lie within the reference.
  ClosedLoop(const ObservationModel& model, const ParamSet& p, const Dataset& data,
             const RunContext& ctx, const std::string& who);
  /// The torque-driven (open) loop: the drives' command is the recorded torque, read between
  /// the samples by the cubic Hermite spline of exid::shiftedRows (slopes from the five-point
  /// derivative: fourth order); no reference, no gains. Defined from the fourth to the
  /// fifth-to-last sample (firstTime(), lastTime()). On a floating base, the joints driven by
  /// the recorded torque on the recorded base motion and contact wrenches (as above).
  ClosedLoop(const ObservationModel& model, const Dataset& data, const std::string& who);
  bool torqueDriven() const { return open_; }
  /// Whether the loop runs on a floating base (the base's recorded motion prescribed).
  bool floatingBase() const { return floating_; }
  /// The model's base rows per sample on a floating base (6 with rows: all; else 0): they are
  /// the first of each sample's rows.
  int baseRowCount() const { return floating_ ? rows_per_sample_ - n_ : 0; }
  /// On a floating base with base rows: their torque side at the simulated state x = (q, qd) at
  /// t, w_b(q, qd, a) theta with a the loop's acceleration there (the measured side, the
  /// contact wrenches, does not depend on theta); with S = dx/dtheta (not null) its derivative
  /// in theta, *J = w_b + d(w_b theta)/d(q, qd) S + d(w_b theta)/dqdd da/dtheta (da/dtheta =
  /// A_q S_q + A_qd S_qd + B: linearize()), the derivatives in q and qd by central
  /// differences, in qdd exact (the rows are affine in it).
  Eigen::VectorXd baseRows(const Eigen::VectorXd& theta, double t, const Eigen::VectorXd& x,
                           const Eigen::MatrixXd* S, Eigen::MatrixXd* J) const;
  /// A stop request (RunContext::shouldStop) polled along every simulation and sensitivity
  /// pass, every few steps: when it turns true, the pass throws exid::Error("WHO: stopped").
  /// (One simulation of a long recording runs for seconds; a stop must not wait for it.)
  void setStop(std::function<bool()> stop) { stop_ = std::move(stop); }
  /// The span where the torque-driven loop's command is defined.
  double firstTime() const;
  double lastTime() const;
  /// The estimator parameters of the controller and of the simulation's tolerances
  /// (reference_file, kp_Nm_per_rad, kd_Nm_s_per_rad, feedforward, rtol, atol, max_steps).
  static std::vector<ParamDecl> params();
  /// Refuses, naming them, the required parameters left out (at construction of `who`).
  static void checkParams(const ParamSet& p, const std::string& who);

  int dof() const { return n_; }
  /// The model's nonlinear parameters (ObservationModel::nonlinearParameters) at which the
  /// rows are taken: the model's own values until set. With `sensitivities`, simulate()'s
  /// sensitivities are with respect to (theta, eta): S is 2n x (p + L).
  void setNonlinear(const Eigen::VectorXd& eta, bool sensitivities);
  const Eigen::VectorXd& nonlinear() const { return eta_; }
  const Reference& reference() const { return ref_; }
  std::string describe() const;
  /// The controller's torque at (t, q, qd): the command, which the drives record.
  Eigen::VectorXd control(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd) const;
  /// d tau_c / dt along the motion (q, qd, qdd = a) at t, exact: Kp (qdr - qd) + Kd (qddr - a)
  /// plus the feed-forward's rate (its partial derivatives times the reference's qd, qdd and
  /// jerk; sign(qd) has zero derivative).
  Eigen::VectorXd controlRate(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                              const Eigen::VectorXd& a) const;
  /// Whether the model has drive-gain columns (dK<j>).
  bool hasDriveGains() const;
  /// The base indices of the drive-gain columns (dK<j>), in base order.
  std::vector<int> driveGainColumns() const;
  /// qdd of the loop at theta; *M (if not null) the mass matrix there, *command (if not null)
  /// the controller's torque. exid::Error when M is not positive definite.
  Eigen::VectorXd acceleration(const Eigen::VectorXd& theta, double t, const Eigen::VectorXd& q,
                               const Eigen::VectorXd& qd, Eigen::MatrixXd* M = nullptr,
                               Eigen::VectorXd* command = nullptr) const;
  const Eigen::VectorXd& kp() const { return Kp_; }
  const Eigen::VectorXd& kd() const { return Kd_; }
  /// The loop's linearisation at theta: da/dq, da/dqd (n x n) and da/dtheta (n x p), exact
  /// (ObservationModel::fullTorqueAt's derivatives, else the model's design VJP, one per
  /// joint): with w theta = M a + h, da/dtheta = -M^-1 w(q, qd, a),
  /// da/dq = M^-1 (-Kp - d(w theta)/dq |a), and likewise qd. With the nonlinear parameters'
  /// sensitivities on, B has L more columns, da/deta = -M^-1 d(w(q, qd, a) theta)/deta (the
  /// model's exact column derivatives). B may be null (the state's Jacobian alone).
  void linearize(const Eigen::VectorXd& theta, double t, const Eigen::VectorXd& q,
                 const Eigen::VectorXd& qd, Eigen::MatrixXd* A_q, Eigen::MatrixXd* A_qd,
                 Eigen::MatrixXd* B) const;

  struct Tolerances {
    double rtol = 1e-8, atol = 1e-10;
    std::int64_t max_steps = 20000;
    bool cvodes_sensitivities = false;  // CVODES's forward sensitivities, not BDF2 along its steps
    static Tolerances from(const ParamSet& p) {
      return {p.getDouble("rtol"), p.getDouble("atol"), p.getInt("max_steps"), false};
    }
  };
  /// The loop at theta from the reference's start, integrated by CVODES (BDF), and at each of
  /// `times` (increasing, within the reference): at(k, x, S), x = (q, qd) and, with
  /// `sensitivities`, S = dx/dtheta (2n x p, or 2n x (p + L): setNonlinear), else S is null.
  /// CVODES's Newton iterations use the exact Jacobian (linearize()). The sensitivities
  /// S' = J S + B are integrated as one matrix along CVODES's own steps of the state, which
  /// they never change (the state's path is the same with them or without), by the
  /// variable-step BDF2 formula (L-stable; backward Euler on a first step and where a step
  /// grows more than twice), and read between steps by cubic Hermite interpolation: second
  /// order in the steps, to about 1e-4 of central differences in the tests. With
  /// tol.cvodes_sensitivities, CVODES's own forward sensitivities instead (staggered, their
  /// right-hand side from linearize(), outside the steps' error control). A failure is an
  /// exid::Error naming the time.
  /// The path of a simulation: CVODES's steps (their ends' times and states) and the states at
  /// the samples. Recorded by simulate()/simulateFrom() (path not null), it gives that
  /// simulation's sensitivities by sensitivitiesAlong() without integrating the state again.
  struct Path {
    double t0 = 0.0;
    Eigen::VectorXd x0, times;
    std::vector<double> t;    // the steps' ends
    std::vector<double> x;    // the states there, 2n each
    Eigen::MatrixXd samples;  // the states at `times`, one column each
  };
  void simulate(const Eigen::VectorXd& theta, const Eigen::VectorXd& times, const Tolerances& tol,
                bool sensitivities,
                const std::function<void(int, const Eigen::VectorXd&, const Eigen::MatrixXd*)>& at,
                Path* path = nullptr) const;
  /// The same from the state x0 = (q, qd) at t0 (which does not depend on theta: S starts at
  /// 0); `times` after t0.
  void simulateFrom(
      const Eigen::VectorXd& theta, double t0, const Eigen::VectorXd& x0,
      const Eigen::VectorXd& times, const Tolerances& tol, bool sensitivities,
      const std::function<void(int, const Eigen::VectorXd&, const Eigen::MatrixXd*)>& at,
      Path* path = nullptr) const;
  /// The sensitivities of the simulation at theta that recorded `path` (with the same
  /// nonlinear parameters and setNonlinear's sensitivities), as simulateFrom() gives them:
  /// at(k, x, S) for each of its samples, in order.
  void sensitivitiesAlong(
      const Eigen::VectorXd& theta, const Path& path,
      const std::function<void(int, const Eigen::VectorXd&, const Eigen::MatrixXd*)>& at) const;

 private:
  const ObservationModel* model_;
  std::shared_ptr<const RobotModel> robot_;
  int n_ = 0;
  std::string who_;
  std::function<bool()> stop_;
  // Throws when a stop was requested (polled every 32nd call).
  void pollStop(unsigned long* count) const;
  Reference ref_;
  std::string file_;
  Eigen::VectorXd Kp_, Kd_;
  bool ff_ = true;
  DynamicsDataPtr dyn_;
  mutable Samples s_;                    // n + 1 samples: the rows at one state
  Eigen::VectorXd eta_;                  // the nonlinear parameters the rows are taken at
  bool eta_sens_ = false;                // sensitivities with respect to them too
  std::vector<int> nl_base_, nl_param_;  // per column of fullDesignAt's dW: base column, eta
  struct TorqueColumn {
    int base = 0;   // base index
    int joint = 0;  // the drive (row) it acts on
    int kind = 0;   // 1: dK, 2: FcL (exid::torqueColumnKind)
  };
  std::vector<TorqueColumn> tcol_;
  bool open_ = false;        // torque-driven: the command is the recorded torque
  Eigen::VectorXd rec_t_;    // its time stamps
  Eigen::MatrixXd rec_tau_;  // and torques (K x n)
  Eigen::VectorXd recordedTorque(double t) const;
  mutable Eigen::VectorXd rec_tl_;  // recordedTorque's scratch: the eight samples about t
  mutable Eigen::MatrixXd rec_Xl_, rec_out_;
  // floating base: the recorded base motion (K x 9) and contact wrenches (K x 6C) at their
  // times, and the rows per sample of the model (the joint rows are the last n of them)
  bool floating_ = false;
  Eigen::VectorXd fb_t_;
  Eigen::MatrixXd fb_base_, fb_contact_;
  int rows_per_sample_ = 0;
  // the recorded signal X (rows at fb_t_) at t: the degree-5 Lagrange polynomial through the
  // six nearest samples
  Eigen::RowVectorXd recordedAt(const Eigen::MatrixXd& X, double t) const;
  // the floating base's recording checked and kept
  void setUpFloating(const Dataset& data);
  // the model's joint rows of W (the last n of each sample's rows_per_sample_)
  Eigen::MatrixXd jointRows(const Eigen::MatrixXd& W) const;
  // floating base: the recorded contact wrenches' joint torque at (q, t) (zero without contacts)
  Eigen::VectorXd contactTorque(const Eigen::VectorXd& q, double t) const;
  // floating base: the joint rows' torque at (q, qd, qdd) times rest(theta), minus the contact
  // torque: w(q, qd, qdd) theta - c(q, t) (without c: with_contact false)
  Eigen::VectorXd floatingTorque(const Eigen::VectorXd& rest, double t, const Eigen::VectorXd& q,
                                 const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                 bool with_contact = true) const;
  // floating base: the feed-forward, floatingInverseDynamics' joint rows at the reference on the
  // recorded base motion plus the description's drive terms
  Eigen::VectorXd floatingFeedforward(double t, const Eigen::VectorXd& qr,
                                      const Eigen::VectorXd& qdr,
                                      const Eigen::VectorXd& qddr) const;
  // the model checked (per sample, every joint's row) and the one-state samples s_
  void setUpRows(const ObservationModel& model);
  // the nonlinear parameters' and the torque columns' bookkeeping; a payload part refused
  void setUpColumns(const ObservationModel& model, const Dataset& data);
  // theta without the torque columns (w's part), and the drives' torque u(tau_c) with
  // du_j/dtau_c,j in *slope
  Eigen::VectorXd restOf(const Eigen::VectorXd& theta) const;
  /// The full parameters of restOf(theta): its base columns' entries, zero elsewhere (the model's
  /// rows times it are the rows in base columns times restOf(theta)).
  const Eigen::VectorXd& fullOf(const Eigen::VectorXd& theta) const;
  mutable Eigen::VectorXd full_key_, full_phi_;  // fullOf's last theta and its answer
  Eigen::VectorXd delivered(const Eigen::VectorXd& theta, const Eigen::VectorXd& tau_c,
                            const Eigen::VectorXd& qd, Eigen::VectorXd* slope) const;
  // The linearisation before its solves with M: A_q = -M^-1 Gq, A_qd = -M^-1 Gqd, B = -M^-1 W
  // (G = d(w theta)/d(q, qd) at fixed a plus the command's slope times Kp, Kd; W = w with the
  // torque columns' and, with eta's sensitivities, eta's columns: linearize()).
  // a and tau_c: the loop's acceleration and command there.
  struct LinearParts {
    Eigen::MatrixXd M, Gq, Gqd, W;
    Eigen::VectorXd a, tau_c;
  };
  void linearParts(const Eigen::VectorXd& theta, double t, const Eigen::VectorXd& q,
                   const Eigen::VectorXd& qd, bool with_w, LinearParts* out) const;
  // W of several states at once (one per row of q, qd, a, the commands tau_c; times t): n rows
  // each, the model's rows of all of them from one call.
  Eigen::MatrixXd sensitivityRows(const Eigen::VectorXd& theta, const Eigen::VectorXd& t,
                                  const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd,
                                  const Eigen::MatrixXd& a, const Eigen::MatrixXd& tau_c) const;
};

}  // namespace exid::estimators
