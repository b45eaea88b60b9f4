// exid — derivative checks for plugin authors (as Ceres' GradientChecker): a plugin's exact
// derivatives against central differences of its own values, with a structured result (the
// largest relative error, the component where it occurs, the step used). docs/plugins.md,
// "Testing your derivatives".
//
//   exid::DerivativeCheck c = exid::checkCriterion(*criterion, M);
//   EXPECT_TRUE(c.ok) << c.message();
//
// Error measure: for each output (a row of the Jacobian: the criterion J, one signal at one
// sample), the error of a component is |analytic - numeric| divided by the largest derivative
// of that output, analytic or numeric (so a derivative 25 % off reads 0.25 whatever its units),
// or by the differences' rounding noise when that is larger (an output whose derivative is zero).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"

namespace exid {

struct EXID_API DerivativeCheckOptions {
  /// Central-difference step, relative to the scale each check states (0: the check's default).
  double relative_step = 0.0;
  /// The check passes when max_rel_error <= tolerance.
  double tolerance = 1e-6;
  /// Random adjoints (vector-Jacobian products) checked per VJP; their seed.
  int directions = 2;
  std::uint64_t seed = 1;
};

struct EXID_API DerivativeCheck {
  std::string what;  // what was checked, e.g. "criterion 'cond': dJ/dM"
  bool ok = false;   // every value finite and max_rel_error <= tolerance
  double tolerance = 0.0;
  double max_rel_error = 0.0;  // see the file's header
  double max_abs_error = 0.0;  // max |analytic - numeric| [the output's unit / the input's]
  std::string worst;           // the component of max_rel_error, e.g. "M(2, 3)", "qd(4, 2) / z_7"
  double worst_analytic = 0.0, worst_numeric = 0.0;
  double step = 0.0;     // the relative step used
  long evaluations = 0;  // evaluations of the plugin's value (the differences)
  /// The derivatives compared (rows: outputs, columns: inputs); for an aggregate, the part with
  /// the largest error.
  Eigen::MatrixXd analytic, numeric;
  /// The checks an aggregate is made of (a trajectory's Jacobian, its VJP, ...); empty otherwise.
  std::vector<DerivativeCheck> parts;

  /// One line: ok or FAILED, the error, the worst component and its two values, the step.
  std::string message() const;
  /// The fields above (matrices of one row as arrays; parts by their own toJson).
  Json toJson() const;
};

/// A scalar function's gradient: f(x) against `gradient` by central differences with steps
/// h_i = relative_step * max(1, |x_i|) (default relative_step 1e-6). `names` (optional) names
/// the components of x in the result ("x_i" otherwise).
EXID_API DerivativeCheck checkGradient(const std::function<double(const Eigen::VectorXd&)>& f,
                                       const Eigen::VectorXd& x, const Eigen::VectorXd& gradient,
                                       const DerivativeCheckOptions& options = {},
                                       const std::string& what = "gradient",
                                       const std::vector<std::string>& names = {});

/// A vector function's Jacobian (outputs x inputs), steps as checkGradient.
EXID_API DerivativeCheck checkJacobian(
    const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f, const Eigen::VectorXd& x,
    const Eigen::MatrixXd& jacobian, const DerivativeCheckOptions& options = {},
    const std::string& what = "jacobian", const std::vector<std::string>& output_names = {},
    const std::vector<std::string>& input_names = {});

/// A criterion's dJ/dM at the information matrix M (symmetric positive definite): for every
/// i <= j, the change of J when M(i, j) and M(j, i) move together by h (the derivative along
/// E_ij + E_ji, analytic dJ/dM(i, j) + dJ/dM(j, i); along E_ii for i = j), h = relative_step *
/// lambda_min(M) (default relative_step 1e-4: a criterion of the spectrum curves on the scale
/// of the smallest eigenvalue). A criterion of the extreme eigenvalues (cond, min_sv) needs
/// them simple: separated from the next by much more than h.
EXID_API DerivativeCheck checkCriterion(const Criterion& criterion, const Eigen::MatrixXd& M,
                                        const DerivativeCheckOptions& options = {});

/// A bound trajectory's derivatives at z: its jacobian(z) (d[vec q; vec qd; vec qdd]/dz,
/// column-major vec) against central differences of evaluate(), its vjp() with random adjoints,
/// and, when specs().continuous, vjpAt() against differences of evaluateAt() at the sample
/// times. Steps as checkGradient (relative to max(1, |z_i|)).
EXID_API DerivativeCheck checkTrajectory(const Trajectory& trajectory, const Eigen::VectorXd& z,
                                         const DerivativeCheckOptions& options = {});

/// A bound observation model's derivatives at samples s (a few: every entry of q, qd and qdd is
/// moved in turn): fullDesignVjp() with random dW against central differences of <dW,
/// fullDesign(s)>; when the model has nonlinear parameters (at their values), fullDesignAt()'s
/// dW and fullDesignVjpAt() likewise. Steps relative to max(1, |entry|) for the samples, to
/// |eta_k| for a nonlinear parameter (a velocity of 0.01 rad/s is moved by 1e-8 rad/s).
EXID_API DerivativeCheck checkModel(const ObservationModel& model, const Samples& s,
                                    const DerivativeCheckOptions& options = {});

}  // namespace exid
