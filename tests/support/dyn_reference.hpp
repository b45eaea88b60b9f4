// exid tests — an independent reference for the rigid-body algorithms: plain Newton-Euler in the
// BASE frame with 3x3 rotations (Rodrigues), computed from the Body definitions only. It shares
// no code with framework/dynamics/src (deliberately slow and simple).
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "exid/robot_model.hpp"

namespace exid::testing {

struct RefBodyState {
  Eigen::Matrix3d R;  // body frame in base
  Eigen::Vector3d o;  // body origin in base
  Eigen::Vector3d w, wd,
      a;  // angular velocity, angular acceleration, acceleration of the origin (base frame)
  Eigen::Vector3d v;  // velocity of the origin
};

/// Kinematics of all bodies (base frame). The base accelerates with -gravity when with_gravity.
std::vector<RefBodyState> refKinematics(const RobotModel& m, const Eigen::VectorXd& q,
                                        const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                        bool with_gravity = true);
/// Joint torques for stacked standard parameters pi (10n), by Newton-Euler about the centres of
/// mass.
Eigen::VectorXd refTorques(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                           const Eigen::VectorXd& qdd, const Eigen::VectorXd& pi);
/// Kinetic and potential energy (U = -sum M g^T c).
void refEnergy(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
               const Eigen::VectorXd& pi, double* T, double* U);
/// Wrench (fx fy fz mx my mz, in the sensor frame, moment about the sensor origin) exerted on a
/// payload with parameters phi (M MX MY MZ XX XY XZ YY YZ ZZ, sensor frame) rigidly attached.
Eigen::Matrix<double, 6, 1> refPayloadWrench(const RobotModel& m, const Eigen::VectorXd& q,
                                             const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                             const Eigen::Matrix<double, 10, 1>& phi);

/// Rotation about a unit axis (Rodrigues).
Eigen::Matrix3d refRot(const Eigen::Vector3d& axis, double angle);

/// Random physically consistent parameters (point-mass clouds).
Eigen::Matrix<double, 10, 1> randomInertia(std::mt19937& rng, double size = 0.3);
Pose randomPose(std::mt19937& rng, double scale = 0.5);
/// Random tree: random parents (parent < index), axes, pre/post poses, ~25% prismatic joints,
/// random gravity direction, random sensor pose.
RobotModel randomTree(std::mt19937& rng, int n, bool identity_post = false);
/// Random vector with entries uniform in [-s, s].
Eigen::VectorXd randomVec(std::mt19937& rng, int n, double s = 1.0);

}  // namespace exid::testing
