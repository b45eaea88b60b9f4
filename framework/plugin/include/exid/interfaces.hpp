// exid — the seven plugin interfaces. Each is a small abstract class with one or two pure
// virtual methods and defaults for the rest (OMPL's Planner style). Plugins derive from one of
// them and register with EXID_REGISTER_PLUGIN (plugin.hpp).
#pragma once

#include <Eigen/Core>
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "exid/base_parameters.hpp"
#include "exid/context.hpp"
#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/plugin.hpp"
#include "exid/robot_model.hpp"

namespace exid {

// ---------------------------------------------------------------- robot
/// Builds a RobotModel (from a file, or from data compiled into the plugin).
class EXID_API Robot : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Robot;
  virtual std::shared_ptr<const RobotModel> build(const RunContext& ctx) = 0;
};

// ---------------------------------------------------------------- observation model
/// What an observation model can do, declared by the model itself (ObservationModel::specs()).
struct EXID_API ModelSpecs {
  /// The rows of sample k depend on sample k alone, so rows() may be computed on consecutive
  /// slices of a dataset and stacked (streamed in chunks). False: the rows need the whole
  /// dataset at once (e.g. windows of samples).
  bool per_sample = false;
  /// Signals a dataset must carry: any of "q", "qd", "qdd", "tau", "wrench".
  std::vector<std::string> required_signals{"q", "qd", "qdd", "tau"};
  /// The model handles a floating-base robot (RobotModel::floating_base): its rows are the
  /// floating-base ones (exid/floating_base.hpp). False: bind() refuses a floating robot (the
  /// fixed-base rows would be wrong for it).
  bool floating_base = false;
};

/// Turns a Dataset (or, for excitation design, bare trajectory samples) into observation rows.
/// A model works on FULL columns (fullNames); bind() finds its base parameters (QR with column
/// pivoting over random samples) and the base-column methods below follow from that.
/// A parameter on which some of a model's columns depend nonlinearly (a Stribeck velocity, the
/// width of a smoothed sign): rows() uses `value` (the study's); the `varpro` estimator fits it
/// together with the linear parameters (docs/estimators.md, "Variable projection").
struct EXID_API NonlinearParameter {
  std::string name;          // e.g. "vs2"
  std::string unit;          // e.g. "rad/s"
  double value = 0.0;        // the study's value: rows() uses it; varpro starts from it
  std::vector<int> columns;  // the full columns it moves (indices into fullNames())
};

class EXID_API ObservationModel : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Model;

  /// Binds the robot and computes the base parameters. Call once before anything else.
  void bind(std::shared_ptr<const RobotModel> robot, const RunContext& ctx);
  /// Restricts the motion from which bind() finds the base parameters: the measured
  /// coordinates not in `moving` (0-based) are held at `held` (zero velocity and acceleration),
  /// so the base parameters are those a motion of the `moving` joints alone can identify (the
  /// paper's one-joint-at-a-time experiments). Empty `moving` (the default): every coordinate
  /// moves. Call before bind(); the runner sets it from the excitation trajectory's joints.
  void restrictMotion(std::vector<int> moving, Eigen::VectorXd held);
  const std::vector<int>& movingJoints() const { return moving_; }
  /// Full parameters bind() keeps as base columns, in this order before the others (the study
  /// key `base_columns`; BaseParameterOptions::preferred). Call before bind().
  void preferBaseColumns(std::vector<std::string> names) {
    base_options_.preferred = std::move(names);
  }
  /// How bind() chooses the base columns when none are named (the study key `base_columns:
  /// pivoted`; BaseParameterOptions::rule). Call before bind().
  void baseColumnRule(BaseParameterOptions::Rule rule) { base_options_.rule = rule; }
  const Eigen::VectorXd& heldPositions() const { return held_; }
  const RobotModel& robot() const { return *robot_; }
  std::shared_ptr<const RobotModel> robotPtr() const { return robot_; }
  const BaseParameters& base() const { return base_; }
  int numBase() const { return base_.rank(); }

  /// Names and nominal values (from the robot description) of the full parameter vector.
  virtual std::vector<std::string> fullNames() const = 0;
  virtual Eigen::VectorXd fullNominal() const = 0;
  /// The full parameters of the simulated plant that produced a dataset
  /// (Dataset::facts.simulated: its payload, drive terms, gains, friction); by default the
  /// nominal ones. The runner compares a simulated study's estimate with this, never with a
  /// nominal value the simulation did not use.
  virtual Eigen::VectorXd fullTruth(const PlantTruth& plant) const {
    (void)plant;
    return fullNominal();
  }
  /// Full-column rows from a dataset (W_full * pi_full ~= y).
  virtual Rows fullRows(const Dataset& data, const RunContext& ctx) const = 0;
  /// Full-column design rows from trajectory samples (no measurements), for excitation design
  /// and base-parameter detection.
  virtual Eigen::MatrixXd fullDesign(const Samples& s) const = 0;
  /// Given dJ/dW_full (shape of fullDesign(s)), the gradient with respect to s.q, s.qd, s.qdd
  /// (written into grad, same shapes as s). Exact.
  virtual void fullDesignVjp(const Samples& s, const Eigen::MatrixXd& dW, Samples* grad) const = 0;
  /// The parameters some full columns depend on nonlinearly (none by default); fullRows and
  /// fullDesign use their `value`.
  virtual std::vector<NonlinearParameter> nonlinearParameters() const { return {}; }
  /// fullRows with the nonlinear parameters at eta (one per nonlinearParameters(), same order)
  /// and, when dW is given, the derivatives of the columns they move: dW is rows x L, column l
  /// the derivative of full column nonlinearParameters()[k].columns[i] with respect to eta_k,
  /// for k in order and i in order within k. Exact. Default (no nonlinear parameter): fullRows,
  /// eta empty.
  virtual Rows fullRowsAt(const Dataset& data, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW,
                          const RunContext& ctx) const;
  /// The full columns `columns` (indices into fullNames()) of fullRowsAt(data, eta): rows x
  /// columns.size(), the same numbers in the same rows; with dW, also fullRowsAt's dW (rows x
  /// L, every moved column's derivatives). For an estimator that needs only the columns the
  /// nonlinear parameters move (varpro's trial points and evaluations). Default: fullRowsAt's;
  /// a model whose moved columns cost far less than its rows gives them alone (the
  /// `differential` model's friction columns).
  virtual Eigen::MatrixXd fullColumnsAt(const Dataset& data, const Eigen::VectorXd& eta,
                                        const std::vector<int>& columns, const RunContext& ctx,
                                        Eigen::MatrixXd* dW = nullptr) const;
  /// fullDesign with the nonlinear parameters at eta and, when dW is given, the derivatives of
  /// the columns they move (as fullRowsAt: rows x L). Exact. Default (no nonlinear parameter):
  /// fullDesign, eta empty.
  virtual Eigen::MatrixXd fullDesignAt(const Samples& s, const Eigen::VectorXd& eta,
                                       Eigen::MatrixXd* dW) const;
  /// fullDesignVjp of fullDesignAt(s, eta). Exact. Default (no nonlinear parameter):
  /// fullDesignVjp, eta empty.
  virtual void fullDesignVjpAt(const Samples& s, const Eigen::VectorXd& eta,
                               const Eigen::MatrixXd& dW, Samples* grad) const;
  /// For a simulation of the model's robot (the estimators' closed loop): at one sample (q, qd,
  /// qdd) of a model whose rows are one per joint, all joints, the rows times the full
  /// parameters phi, tau = fullDesignAt(s, eta) phi, and (outputs not null) its exact partial
  /// derivatives with respect to q, qd and qdd (n x n, row i the gradient of tau_i). phi is
  /// zero in the torque columns (exid::torqueColumnKind). False when the model does not give
  /// it; the caller then uses fullDesignAt and fullDesignVjpAt. The `differential` model gives
  /// it by recursive Newton-Euler and the composite rigid body algorithm, without a regressor.
  virtual bool fullTorqueAt(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                            const Eigen::VectorXd& qdd, const Eigen::VectorXd& eta,
                            const Eigen::VectorXd& phi, Eigen::VectorXd* tau, Eigen::MatrixXd* d_q,
                            Eigen::MatrixXd* d_qd, Eigen::MatrixXd* d_qdd) const {
    (void)q, (void)qd, (void)qdd, (void)eta, (void)phi, (void)tau, (void)d_q, (void)d_qd,
        (void)d_qdd;
    return false;
  }
  /// Random samples within the robot's limits used by bind() to find the base parameters.
  virtual Samples randomSamples(int count, std::uint64_t seed) const;
  /// The model's capabilities (per-sample rows, required signals).
  virtual ModelSpecs specs() const { return {}; }
  /// Free-form description for the summary and the report; never read as a capability.
  virtual Json describe() const { return Json::object(); }

  // Base-column forms (defined once here from the full forms).
  Rows rows(const Dataset& data, const RunContext& ctx) const;
  /// rows() with the nonlinear parameters at eta: W in base columns, dW (rows x L) as
  /// fullRowsAt gives it (the full columns moved by eta; nonlinearColumnsInBase() says which
  /// base column each is, or -1).
  Rows rowsAt(const Dataset& data, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW,
              const RunContext& ctx) const;
  /// For each column of fullRowsAt's dW: the base column it is (-1: not a base column).
  std::vector<int> nonlinearColumnsInBase() const;
  Eigen::MatrixXd design(const Samples& s) const;
  void designVjp(const Samples& s, const Eigen::MatrixXd& dW_base, Samples* grad) const;
  /// design() and designVjp() with the nonlinear parameters at eta; dW (optional) as
  /// fullDesignAt gives it (full columns; nonlinearColumnsInBase() maps them). Not blocked:
  /// for the few samples of a simulation step.
  Eigen::MatrixXd designAt(const Samples& s, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW) const;
  void designVjpAt(const Samples& s, const Eigen::VectorXd& eta, const Eigen::MatrixXd& dW_base,
                   Samples* grad) const;
  Eigen::VectorXd baseNominal() const { return base_.reduce(fullNominal()); }

 protected:
  /// Hook called by bind() before the base parameters are computed.
  virtual void onBind(const RunContext&) {}
  /// Samples and options used by bind(); models may override.
  virtual int baseSamples() const { return 200; }
  BaseParameterOptions base_options_;

 private:
  std::shared_ptr<const RobotModel> robot_;
  BaseParameters base_;
  std::vector<int> moving_;
  Eigen::VectorXd held_;
};

// ---------------------------------------------------------------- criterion
/// A scalar of the information matrix M = W^T W (base columns) and its exact gradient dJ/dM
/// (symmetric). Smaller is better.
/// What a criterion is, declared by the criterion itself (Criterion::specs()).
struct EXID_API CriterionSpecs {
  /// The base columns are scaled by the nominal parameter magnitudes before M is formed.
  bool scale_columns = false;
  /// The value is the condition number sqrt(lambda_max(M) / lambda_min(M)), so an optimiser may
  /// minimise an equivalent form of log(lambda_max / lambda_min) instead (nlopt's epigraph).
  bool condition_number = false;
};

class EXID_API Criterion : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Criterion;
  virtual double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dJ_dM) const = 0;
  virtual CriterionSpecs specs() const { return {}; }
};

// ---------------------------------------------------------------- trajectory
/// What a trajectory can do, declared by the trajectory itself (Trajectory::specs(), valid after
/// bind()).
struct EXID_API TrajectorySpecs {
  /// 0-based measured coordinates that move; the others stay at their rest position. Empty:
  /// not declared (every coordinate may move).
  std::vector<int> moving_joints;
  /// The samples are affine in z: the Jacobian is constant.
  bool linear = false;
  /// evaluateAt() and vjpAt() give the signals at any time in [0, duration_s].
  bool continuous = false;
  /// The motion repeats with period duration_s (the sample grid covers one period).
  bool periodic = false;
  /// Length of the motion [s] (the period when periodic); 0 when not declared.
  double duration_s = 0.0;
  /// Starts and ends at rest: qd = qdd = 0 at t = 0 and t = duration_s (exactly, by
  /// construction), so the motion can follow a move to its start.
  bool rest_to_rest = false;
  /// Ends in the state it starts in (q, qd, qdd): repetitions of it join continuously (periodic,
  /// or rest to rest back to the start position).
  bool repeatable = false;
};

/// Decision variables z -> q, qd, qdd at the sample times (measured coordinates).
class EXID_API Trajectory : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Trajectory;
  /// Binds the robot (dof, limits). Call once before anything else.
  virtual void bind(std::shared_ptr<const RobotModel> robot, const RunContext& ctx) = 0;
  virtual int numVariables() const = 0;
  virtual Eigen::VectorXd initial() const = 0;
  virtual Samples evaluate(const Eigen::VectorXd& z) const = 0;
  /// Gradient with respect to z of <adj.q, q> + <adj.qd, qd> + <adj.qdd, qdd>.
  virtual Eigen::VectorXd vjp(const Eigen::VectorXd& z, const Samples& adj) const = 0;
  /// Bounds on z (infinite by default).
  virtual void bounds(Eigen::VectorXd* lower, Eigen::VectorXd* upper) const;
  /// Dense Jacobian d[vec(q); vec(qd); vec(qdd)]/dz (column-major vec), by default from vjp.
  virtual Eigen::MatrixXd jacobian(const Eigen::VectorXd& z) const;
  /// The trajectory's capabilities (moving joints, linearity, continuous time, period).
  virtual TrajectorySpecs specs() const { return {}; }
  /// q, qd, qdd at the times t (any times in [0, specs().duration_s]) for a trajectory with
  /// specs().continuous; at the sample times it agrees with evaluate(). Default: throws
  /// exid::Error (a trajectory defined on its sample grid only).
  virtual Samples evaluateAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t) const;
  /// Gradient with respect to z of <adj.q, q> + <adj.qd, qd> + <adj.qdd, qdd>, the signals being
  /// evaluateAt(z, t) (adj has their shape). Default: throws exid::Error.
  virtual Eigen::VectorXd vjpAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t,
                                const Samples& adj) const;
  /// Free-form description for the summary and the report; never read as a capability.
  virtual Json describe() const { return Json::object(); }
  /// The trajectory's own parameters at z in its own terms (Fourier coefficients, spline knots),
  /// per moving joint, for the exported parameter file; never read back as a capability.
  /// Default: an empty object (the exporter always writes z itself).
  virtual Json parametersAt(const Eigen::VectorXd& z) const {
    (void)z;
    return Json::object();
  }
  /// Margin kept inside the position limits, and whether velocity/acceleration limits are
  /// imposed as constraints by the excitation problem.
  virtual double positionMargin() const { return 0.0; }
  /// Lets a trajectory tighten the joint limits the excitation problem imposes (e.g. a velocity
  /// cap below the robot's own limit). Called with the robot's limits (joint coordinates).
  virtual void adjustLimits(std::vector<JointLimits>* limits) const { (void)limits; }
  virtual bool velocityLimits() const { return true; }
  virtual bool accelerationLimits() const { return true; }
};

// ---------------------------------------------------------------- optimizer
/// The problem an optimiser sees: minimise J(z) subject to g(z) <= 0 and bounds. Built by the
/// framework from a Trajectory, an ObservationModel and a Criterion.
class EXID_API ExcitationProblem {
 public:
  virtual ~ExcitationProblem() = default;
  virtual int numVariables() const = 0;
  virtual Eigen::VectorXd initial() const = 0;
  virtual void bounds(Eigen::VectorXd* lower, Eigen::VectorXd* upper) const = 0;
  /// Criterion value and (if grad) its exact gradient with respect to z.
  virtual double value(const Eigen::VectorXd& z, Eigen::VectorXd* grad) = 0;
  /// The information matrix M(z) the criterion sees (base columns, scaled when the criterion
  /// scales columns), and counts as one evaluation.
  virtual Eigen::MatrixXd information(const Eigen::VectorXd& z) = 0;
  /// For each symmetric G_i in dM, the exact gradient of <G_i, M(z)> with respect to z (column
  /// i of the result; one reverse pass each through model and trajectory). With G = v v^T for
  /// an eigenvector v of M this is the gradient of that (simple) eigenvalue.
  virtual Eigen::MatrixXd informationGradients(const Eigen::VectorXd& z,
                                               const std::vector<Eigen::MatrixXd>& dM) = 0;
  /// Inequality constraints g(z) <= 0 (joint, velocity, acceleration, torque limits; rest).
  virtual int numConstraints() const = 0;
  virtual void constraints(const Eigen::VectorXd& z, Eigen::VectorXd* g, Eigen::MatrixXd* jac) = 0;
  /// The last numNonlinearConstraints() rows of g are nonlinear in the samples (the torque
  /// limits): their Jacobian changes with z even for a linear trajectory, while the rows before
  /// them (limits on q, qd, qdd) are affine in the samples and then have a constant Jacobian.
  virtual int numNonlinearConstraints() const { return 0; }
  /// g and the Jacobian (numNonlinearConstraints() x numVariables) of those last rows alone.
  virtual void nonlinearConstraints(const Eigen::VectorXd& z, Eigen::VectorXd* g,
                                    Eigen::MatrixXd* jac);
  virtual const Trajectory& trajectory() const = 0;
  virtual const ObservationModel& model() const = 0;
  virtual const Criterion& criterion() const = 0;
  virtual long evaluations() const = 0;
  /// Information already known that value() and information() add to W^T W (base columns,
  /// scaled like them); empty when none. An optimiser that forms its own information matrix
  /// must add it too, or refuse the problem.
  virtual const Eigen::MatrixXd& priorInformation() const {
    static const Eigen::MatrixXd none;
    return none;
  }
};

/// Why an optimiser stopped (OptimizerResult::stop_reason); toString() gives the text the
/// summary and the report show.
enum class StopReason {
  None,            // "": not stopped (a budget check that finds nothing to stop for)
  Converged,       // "converged"
  ConvergedFtol,   // "converged (ftol_rel)": a pass improved J by less than ftol_rel
  ConvergedGtol,   // "converged (gtol)": projected gradient below tolerance, no constraints
  MaxIterations,   // "max_iterations"
  StartOnly,       // "max_iterations (0: start evaluated only)"
  OuterPasses,     // "outer passes": the penalty passes ran out
  MaxEvaluations,  // "max_evaluations"
  MaxTime,         // "max_time_s"
  MaxCpu,          // "max_cpu_s"
  Deadline,        // "deadline": the study's time budget
  Cancelled,       // "cancelled"
  NoProgress,      // "no progress": every run ended at its start, claiming convergence without a
                   // step (NLopt's SLSQP when its first search direction does not descend)
  ConvergedXtol,   // "converged (xtol_rel)": the last step changed z by less than xtol_rel
  Stalled,         // "stalled": the run whose point is returned ended on none of the tests above
                   // (NLopt's ROUNDOFF_LIMITED or a failure after steps)
};
EXID_API std::string toString(StopReason r);
EXID_API std::ostream& operator<<(std::ostream& os, StopReason r);
/// Stopped by wall or CPU time (max_time_s, max_cpu_s, deadline): the result depends on the
/// speed and load of the machine.
EXID_API bool stoppedByTime(StopReason r);

struct EXID_API OptimizerResult {
  Eigen::VectorXd z;
  double criterion_initial = 0.0, criterion_final = 0.0;
  double max_violation = 0.0;  // of g(z) <= 0 at the returned point
  int iterations = 0;
  long evaluations = 0;
  double wall_s = 0.0;
  StopReason stop_reason = StopReason::None;
  /// False when no feasible point was found (z is then the point of least violation).
  bool feasible = true;
  std::vector<double> history_t_s, history_value;  // criterion over wall time
  Json details = Json::object();
};

/// The stop reason as the summary and the report show it: toString(stop_reason), followed by
/// " (no feasible point found; least violation returned)" when r.feasible is false.
EXID_API std::string stopReasonText(const OptimizerResult& r);

class EXID_API Optimizer : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Optimizer;
  virtual OptimizerResult minimize(ExcitationProblem& problem, const RunContext& ctx) = 0;
};

// ---------------------------------------------------------------- experiment
/// Produces a Dataset: simulated along a reference trajectory, or read from a recording.
class EXID_API Experiment : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Experiment;
  /// reference: the excitation stage's trajectory, or null when the study has none.
  virtual Dataset run(std::shared_ptr<const RobotModel> robot, const Samples* reference,
                      const RunContext& ctx) = 0;
  /// The same data, possibly streamed (Dataset::stream: read in chunks, never held whole) when
  /// the experiment can read it so (a long recording); by default run(). The runner asks for it
  /// when every consumer of the data streams (EstimatorSpecs::streams).
  virtual Dataset stream(std::shared_ptr<const RobotModel> robot, const Samples* reference,
                         const RunContext& ctx) {
    return run(std::move(robot), reference, ctx);
  }
};

// ---------------------------------------------------------------- estimator
struct EXID_API Prior {
  Eigen::VectorXd value;       // base parameters
  Eigen::MatrixXd covariance;  // base x base
  // A prior from the robot description also keeps the independent prior on the STANDARD
  // parameters behind it (model.fullNames() order): value = K standard_value, covariance =
  // K diag(standard_std^2) K^T. Empty for a prior from an earlier study (base parameters only).
  Eigen::VectorXd standard_value, standard_std;
};

struct EXID_API EstimatorSpecs {
  bool recursive = false;          // produces a history
  bool needs_raw_dataset = false;  // filters or differentiates the signals itself
  bool accepts_prior = false;
  bool streams = false;  // reads a streamed dataset in chunks (never holds it whole)
};

struct EXID_API Estimate {
  std::vector<std::string> names;        // base parameter names
  std::vector<std::string> expressions;  // their expressions in standard parameters
  Eigen::VectorXd value, std;
  Eigen::MatrixXd covariance;
  double sigma = 0.0;         // residual standard deviation (weighted)
  double cond_W = 0.0;        // of the (weighted) base regressor
  double residual_rms = 0.0;  // unweighted
  long rows = 0;
  // Nonlinear parameters fitted with the linear ones (ObservationModel::nonlinearParameters,
  // the `varpro` estimator): names, values and standard deviations. The held-out rows are
  // built at these values (ObservationModel::rowsAt). Empty: the model's own values.
  std::vector<std::string> nonlinear_names;
  Eigen::VectorXd nonlinear, nonlinear_std;
  // Recursive estimators: estimate and diag(P) at each step (time in s).
  Eigen::VectorXd history_t;
  Eigen::MatrixXd history_value, history_pdiag;
  Json details = Json::object();
};

class EXID_API Estimator : public PluginObject {
 public:
  static constexpr PluginKind kKind = PluginKind::Estimator;
  virtual EstimatorSpecs specs() const { return {}; }
  virtual Estimate estimate(const ObservationModel& model, const Dataset& data, const Prior* prior,
                            const RunContext& ctx) = 0;
  /// The rows the identified model is validated on, for a validation dataset as raw as the
  /// estimator's own (specs().needs_raw_dataset: no q̇/q̈ yet). An estimator that filters,
  /// differentiates or decimates does the same to them, so that the held-out error is measured
  /// on rows processed exactly like the identification rows. Default: the model's rows.
  virtual Rows validationRows(const ObservationModel& model, const Dataset& data,
                              const RunContext& ctx) const {
    return model.rows(data, ctx);
  }
};

}  // namespace exid
