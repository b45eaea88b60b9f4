// exid — Denavit-Hartenberg tables to RobotModel bodies.
//
// Standard DH (Denavit-Hartenberg 1955, as in Corke's Robotics Toolbox):
//   A_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)          (revolute)
//   A_i = Rz(theta_i) Tz(d_i + q_i) Tx(a_i) Rx(alpha_i)          (prismatic)
// Body i's frame is DH frame i (the published link frame, where published inertial data live);
// joint i moves about / along z_{i-1}, the z axis of the PARENT body frame. Split used here:
//   pre = Rz(theta) Tz(d),  joint motion about/along z,  post = Tx(a) Rx(alpha).
// (Rz(q) commutes with Rz(theta) and Tz(d), Tz(q) with Tz(d), so the product is A_i.)
//
// Modified DH (Craig 1986 / Khalil-Kleinfinger 1986), row i holds alpha_{i-1}, a_{i-1}, d_i,
// theta_i:
//   A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i + q_i) Tz(d_i)   (revolute; prismatic: d_i + q_i)
// Split: pre = Rx(alpha) Tx(a) Rz(theta) Tz(d), joint motion about/along z, post = identity.
//
// theta (revolute) and d (prismatic) are offsets added to the joint variable; for the other joint
// type they are constants.
#pragma once

#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

enum class DhConvention { Standard, Modified };

struct EXID_API DhRow {
  JointType type = JointType::Revolute;
  double a = 0, alpha = 0, d = 0, theta = 0;
};

/// One body from one DH row: fills pre, post, type, axis (= z), parent. Name and inertia empty.
EXID_API Body dhBody(const DhRow& row, DhConvention conv, int parent);

/// A serial chain (body i's parent is i-1): bodies "link1".., joints "joint1"..; inertia zero;
/// limits infinite; drives default; gravity (0, 0, -9.81).
EXID_API RobotModel serialDh(const std::vector<DhRow>& rows, DhConvention conv);

/// Elementary transforms used above (exposed for loaders and tests).
EXID_API Pose rotX(double angle);
EXID_API Pose rotZ(double angle);
EXID_API Pose transX(double d);
EXID_API Pose transZ(double d);

}  // namespace exid
