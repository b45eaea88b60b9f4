// exid — the excitation-design problem assembled from plugins:
//   J(z) = F(M),  M = S W(z)^T W(z) S,  W = model.design(trajectory.evaluate(z))
// (S = optional diagonal column scaling by nominal parameter magnitudes), with the exact
// gradient by reverse accumulation: dJ/dW = 2 W S dF/dM S, then the model's and the
// trajectory's vector-Jacobian products (the paper's adjoint, eqns 10-15, generalised).
// Constraints g(z) <= 0: joint positions within limits less a margin, velocities and
// accelerations within limits, at every sample (only limits that are finite); optionally the
// predicted actuator torques within a fraction of their limits, |tau_j| <= margin tau_max,j, with
// tau the robot's full model (rigid body + drives, its own nominal parameters); optionally
// collision avoidance, d_p(q(t_k)) >= margin for every checked pair p (exid/collision.hpp).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "exid/collision.hpp"
#include "exid/export.hpp"
#include "exid/interfaces.hpp"

namespace exid {

struct EXID_API ExcitationOptions {
  double position_margin = 0.0;  // [rad or m] kept inside the position limits
  bool velocity_limits = true;
  bool acceleration_limits = true;
  bool scale_columns = false;  // scale base columns by |nominal base parameter|
  /// Torque limits: |tau_j(t_k)| <= torque_margin * tau_max,j at every sample, tau the predicted
  /// actuator torque (measured coordinates) of the robot's full model with its nominal parameters.
  /// 0: no torque constraint.
  double torque_margin = 0.0;
  /// tau_max per measured coordinate [N m or N]; empty: the robot's limits (tau_max, the URDF
  /// `effort`), which must then be finite for every joint.
  std::vector<double> torque_max;
  /// Information already known (base x base, the model's base columns, unscaled), added to the
  /// trajectory's W^T W before the criterion: M = W^T W + prior_information (docs/excitation.md
  /// §11). Empty: none.
  Eigen::MatrixXd prior_information;
  /// Collision avoidance: at every sample, the signed distance of every checked pair is at least
  /// collision->margin_m (docs/excitation.md §12). Null: none.
  std::shared_ptr<const CollisionOptions> collision;
};

/// The torque model the torque constraint and the exported trajectory use: the robot's full
/// model with its nominal parameters (rigid body + every drive term), in measured coordinates,
/// and the limits it is held to. Throws exid::Error, saying what is missing, when the robot has
/// no inertial parameters or a limit is unknown.
struct EXID_API TorqueLimits {
  Eigen::VectorXd tau_max;  // per measured coordinate [N m or N]
};
EXID_API TorqueLimits torqueLimits(const RobotModel& robot, const std::vector<double>& torque_max,
                                   const std::string& who);
/// Predicted actuator torques (K x n) along samples (measured coordinates).
EXID_API Eigen::MatrixXd predictedTorques(const RobotModel& robot, const Samples& s);

EXID_API std::unique_ptr<ExcitationProblem> makeExcitationProblem(
    std::shared_ptr<Trajectory> trajectory, std::shared_ptr<ObservationModel> model,
    std::shared_ptr<Criterion> criterion, const ExcitationOptions& options = {});

/// cond(W) = sigma_max / sigma_min of the base design rows of a trajectory (for reports).
EXID_API double conditionNumber(const Eigen::MatrixXd& W);

}  // namespace exid
