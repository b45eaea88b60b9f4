// exid — floating-base rigid-body dynamics (docs/robots.md, "Floating base"; docs/dynamics.md).
//
// A floating-base robot (RobotModel::floating_base) has a base link that moves freely; its
// bodies are attached to it as to a fixed base. At one instant the body forces depend on the
// base's motion only through nine numbers, all in the BASE frame (the base link's frame):
//   omega  angular velocity of the base [rad/s]
//   alpha  angular acceleration of the base [rad/s^2]
//   f      specific force of the base origin, f = a - g: the classical linear acceleration of the
//          base origin minus gravity [m/s^2] (what an accelerometer at the base origin measures;
//          at rest f = -g, e.g. (0, 0, +9.81) with the base upright)
// (not on the base's position nor on its linear velocity: Galilean invariance). BaseMotion
// stacks them: omega(0..2), alpha(3..5), f(6..8).
//
// Parameters: pi_f = [pi_base (10, named XX0 ... M0); pi_1; ...; pi_n] (10(n+1)), each in the
// order XX XY XZ YY YZ ZZ MX MY MZ M about its own frame's origin, in its own frame.
//
// The floating regressor Y (6+n x 10(n+1)) gives Y * pi_f = [w_base; tau]:
//   rows 0..5  w_base: the total wrench (fx fy fz mx my mz; moment about the base origin, base
//              frame) the environment must exert on the robot for this motion: the base
//              link's six Newton-Euler rows with everything moving above it (rate of change of the
//              whole robot's momentum, gravity included through f);
//   rows 6..   tau: the joint torques (forces) with the robot in this motion and no external
//              wrench on the bodies.
// With contact wrenches w_c (exerted BY the environment ON the robot, force then moment about
// the sensor origin, sensor frame), the equations of motion read
//   Y * pi_f = [0; tau] + sum_c C_c w_c,    C_c = contactMap(...)  (6+n x 6)
// whose top six rows are the wrench transform to the base origin and frame (X*) and the bottom n
// rows the transposed Jacobian of the sensor frame (J^T). Speed is not optimised (plain
// recursions over the tree, O(n^2) per sample; not the ISA-compiled kernels).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

using BaseMotion = Eigen::Matrix<double, 9, 1>;  // omega, alpha, f (base frame)

/// Names of the floating parameter vector: "XX0" ... "M0", then "XX1" ... (10(n+1)).
EXID_API std::vector<std::string> floatingParameterNames(const RobotModel& model);
/// The model's floating parameter vector [base.inertia; bodies' inertia] (10(n+1)).
EXID_API Eigen::VectorXd floatingParameters(const RobotModel& model);
/// Throws exid::Error naming `what` unless the model has a floating base.
EXID_API void requireFloatingBase(const RobotModel& model, const std::string& what);

/// The floating regressor (6+n x 10(n+1)); see the file comment. Y is resized.
EXID_API void floatingRegressor(const RobotModel& model, const Eigen::VectorXd& q,
                                const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                const BaseMotion& base, Eigen::MatrixXd& Y);

/// [w_base; tau] (6+n) by a recursive Newton-Euler pass (independent of floatingRegressor's
/// assembly) with the model's parameters, or pi_f (10(n+1)) when given.
EXID_API Eigen::VectorXd floatingInverseDynamics(const RobotModel& model, const Eigen::VectorXd& q,
                                                 const Eigen::VectorXd& qd,
                                                 const Eigen::VectorXd& qdd, const BaseMotion& base,
                                                 const Eigen::VectorXd* pi_f = nullptr);

/// Contact map C (6+n x 6) of a wrench measured in a sensor frame at `sensor` (pose in the frame
/// of body `body`; body = -1: the base link): the wrench w (fx fy fz mx my mz, sensor frame,
/// moment about the sensor origin, exerted on the robot) contributes C.topRows(6) * w to the base
/// rows (the same wrench at the base origin, base frame) and C.bottomRows(n) * w = J^T w to the
/// joint rows (J: the sensor frame's twist [v; omega] in the sensor frame per joint velocity;
/// zero for joints not between the base and `body`).
EXID_API Eigen::MatrixXd contactMap(const RobotModel& model, const Eigen::VectorXd& q, int body,
                                    const Pose& sensor);

/// The body index of a link of a floating robot: -1 for the base link, else the body named
/// `link`; an exid::Error starting with `who` lists the names otherwise.
EXID_API int floatingBodyIndex(const RobotModel& model, const std::string& link,
                               const std::string& who);
/// A pose from x y z [m] and roll pitch yaw [rad] (URDF: R = Rz(yaw) Ry(pitch) Rx(roll)).
EXID_API Pose poseFromXyzRpy(const double* xyz_rpy);

/// Pose of body i's frame (i = -1: the base link, identity) in the base frame.
EXID_API Pose floatingBodyPose(const RobotModel& model, const Eigen::VectorXd& q, int body);

/// Base motion from world-frame data (motion capture, or a state estimate): R_wb the base's
/// orientation (columns: base axes in the world frame), omega_w and alpha_w the base's angular
/// velocity and acceleration in the WORLD frame, a_w the classical acceleration of the base
/// origin in the world frame, g_w gravity in the world frame (e.g. (0, 0, -9.81)).
EXID_API BaseMotion baseMotionFromWorld(const Eigen::Matrix3d& R_wb, const Eigen::Vector3d& omega_w,
                                        const Eigen::Vector3d& alpha_w, const Eigen::Vector3d& a_w,
                                        const Eigen::Vector3d& g_w);

/// Base motion from an IMU rigidly mounted on the base link at pose `imu` (in the base frame):
/// gyro (angular velocity) and accelerometer (specific force) readings in the IMU frame, and the
/// angular acceleration in the IMU frame (e.g. the gyro's derivative). The accelerometer's
/// lever arm is removed: f_origin = f_imu - alpha x r - omega x (omega x r), with r the IMU
/// position in the base frame.
EXID_API BaseMotion baseMotionFromImu(const Pose& imu, const Eigen::Vector3d& gyro,
                                      const Eigen::Vector3d& alpha_imu,
                                      const Eigen::Vector3d& accel);

}  // namespace exid
