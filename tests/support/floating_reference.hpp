// exid tests — the independent reference for floating-base robots: the same robot written as a
// FIXED-base chain with six massless virtual joints (prismatic x, y, z along the world axes, then
// revolute z, y, x: R_wb = Rz(q4) Ry(q5) Rx(q6)), the base link as the seventh body, then the
// robot's bodies. The fixed-base algorithms (and tests/support/dyn_reference) then compute the
// floating robot's dynamics with no floating-base code.
#pragma once

#include <Eigen/Core>

#include "exid/floating_base.hpp"
#include "exid/robot_model.hpp"

namespace exid::testing {

/// The virtual chain of a floating robot; gravity = world gravity g_w. Its parameters are
/// [0 (60, the virtual bodies); pi_f].
RobotModel virtualChain(const RobotModel& floating, const Eigen::Vector3d& g_w);

/// The virtual chain's coordinate vector [x y z yaw pitch roll; q] from the six virtual ones and q.
Eigen::VectorXd virtualCoordinates(const Eigen::Matrix<double, 6, 1>& v, const Eigen::VectorXd& q);

/// The base motion (omega, alpha, f in the base frame) of a virtual-chain state, from the
/// independent reference kinematics (dyn_reference) of the base link (body 7).
BaseMotion virtualBaseMotion(const RobotModel& chain, const Eigen::VectorXd& qv,
                             const Eigen::VectorXd& qdv, const Eigen::VectorXd& qddv);

/// T (6 x 6) mapping the floating base rows [F; N] (base frame, moment about the base origin) to
/// the six virtual joints' torques at virtual coordinates v: prismatic rows e_i^T R F, revolute
/// rows a_k^T R N with a_k the Euler axes in the world frame.
Eigen::Matrix<double, 6, 6> virtualRowMap(const Eigen::Matrix<double, 6, 1>& v);

}  // namespace exid::testing
