// exid — robot description: an immutable kinematic tree with standard inertial parameters,
// limits and drive data. Algorithms are free functions (see dynamics.hpp); this is data only.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/export.hpp"

namespace exid {

enum class JointType { Revolute, Prismatic };

/// Rigid transform of frame B relative to frame A: R = R_AB (columns are B's axes in A),
/// p = p_AB (B's origin in A). A point x_B maps to x_A = R x_B + p.
struct EXID_API Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Pose operator*(const Pose& o) const { return {R * o.R, R * o.p + p}; }
  Pose inverse() const { return {R.transpose(), -(R.transpose() * p)}; }
  bool isIdentity(double tol = 0.0) const {
    return (R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <= tol &&
           p.cwiseAbs().maxCoeff() <= tol;
  }
};

/// One moving body and the joint that moves it (fixed joints are merged into their parent by
/// the loaders). Frames: parent body frame --pre--> joint frame --joint motion--> moved joint
/// frame --post--> body frame. URDF and modified DH have post = identity; standard DH uses post
/// to keep the published parameters in the published link frame.
struct EXID_API Body {
  std::string name;        // link name
  std::string joint_name;  // joint name
  int parent = -1;         // index of the parent body, -1 for the fixed base; parent < own index
  Pose pre;                // joint frame in the parent body frame (q = 0)
  Pose post;               // body frame in the moved joint frame
  JointType type = JointType::Revolute;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit, in the joint frame
  /// Standard inertial parameters about the body frame origin, in the body frame:
  /// XX XY XZ YY YZ ZZ MX MY MZ M (second moments, first moments M*c, mass). SI.
  Eigen::Matrix<double, 10, 1> inertia = Eigen::Matrix<double, 10, 1>::Zero();
};

/// Limits of one joint (joint coordinates), SI. Infinite where unknown.
struct EXID_API JointLimits {
  double q_min = -1e300, q_max = 1e300;
  double qd_max = 1e300, qdd_max = 1e300, tau_max = 1e300;
};

/// Drive of one actuated coordinate (measured coordinates, see RobotModel::transmission).
/// tau_drive = Ia*qdd + Fc*sign(qd) + Fv*qd + OFF, added to the rigid-body torque.
struct EXID_API Drive {
  double gear_ratio = 1.0;     // motor angle / joint angle (informative)
  double rotor_inertia = 0.0;  // Ia, reflected to the coordinate [kg m^2 or kg]
  double coulomb = 0.0;        // Fc [N m or N]
  double viscous = 0.0;        // Fv [N m s/rad or N s/m]
  double offset = 0.0;         // OFF [N m or N]
};

/// Collision geometry of one body (or of the fixed base) for collision-free excitation design
/// (exid/collision.hpp). A capsule is the set of points within `radius` of a segment of `length`
/// along the shape frame's z axis, centred at its origin; a cylinder is `length` long along z,
/// centred; a box has edge lengths `size`, centred; a mesh is a triangle mesh read from
/// `mesh_file` (STL, binary or ASCII; relative paths from the robot description's folder),
/// scaled by `mesh_scale` in its own frame.
struct EXID_API CollisionShape {
  enum class Kind { Sphere, Capsule, Cylinder, Box, Mesh };
  Kind kind = Kind::Sphere;
  int body = -1;        // the body it moves with; -1: fixed to the base
  Pose pose;            // shape frame in the body frame (in the base frame when body is -1)
  double radius = 0.0;  // sphere, capsule, cylinder [m]
  double length = 0.0;  // capsule (between the end-cap centres), cylinder [m]
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // box edge lengths [m]
  std::string mesh_file;
  Eigen::Vector3d mesh_scale = Eigen::Vector3d::Ones();
  std::string where;  // where it was given (file:line, YAML key), for messages
};

/// A loop-closure (cut) joint of a closed kinematic chain: a joint between two bodies of the
/// spanning tree that the tree leaves out. Its frame is fixed in body `body_a` at `pose_a` and in
/// body `body_b` at `pose_b` (-1: the fixed base); the mechanism is assembled when the two frames
/// coincide up to the joint's own motion: a revolute cut joint lets them turn about `axis` (unit,
/// in the cut frame) and keeps the origins together and the axes aligned (5 constraints); a
/// spherical one keeps only the origins together (3 constraints). See exid/closed_chain.hpp.
struct EXID_API LoopJoint {
  enum class Kind { Revolute, Spherical };
  std::string name;
  Kind kind = Kind::Revolute;
  int body_a = -1, body_b = -1;
  Pose pose_a, pose_b;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  std::string where;  // where it was given (file:line, YAML key), for messages
};

/// The loop description of a closed-chain robot: the cut joints that close its loops, the
/// actuated (measured) tree joints, and a reference configuration of the whole tree near which
/// the mechanism assembles (the first guess of the position solve).
struct EXID_API ClosedChain {
  std::vector<LoopJoint> loops;
  std::vector<int> actuated;             // tree joint (body) indices of measured coordinates 1..dof
  Eigen::VectorXd reference;             // tree coordinates (numJoints); empty: zeros
  std::vector<JointLimits> tree_limits;  // one per tree joint (passive ones checked by the solve)
};

/// The free-floating base link of a floating-base robot (docs/robots.md, "Floating base"): its
/// frame is the base frame, its 10 standard parameters (about the base frame origin, in the base
/// frame, order XX XY XZ YY YZ ZZ MX MY MZ M) come first in the floating parameter vector, named
/// XX0 ... M0 (exid/floating_base.hpp). The link itself is not one of `bodies`: the bodies with
/// parent = -1 are attached to it.
struct EXID_API FloatingBase {
  std::string link;  // the base link's name
  std::string
      joint_name;  // the floating joint's name (URDF), empty when the description gives none
  Eigen::Matrix<double, 10, 1> inertia = Eigen::Matrix<double, 10, 1>::Zero();
};

struct EXID_API RobotModel {
  std::string name;
  std::string source;  // file it came from (for messages), or the plugin that built it
  std::vector<Body> bodies;
  std::vector<JointLimits> limits;           // one per measured coordinate (tree: per joint)
  std::vector<Drive> drives;                 // one per measured coordinate
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};  // in the base frame [m/s^2]
  /// Measured (motor or absolute) coordinates qm relate to joint coordinates by
  /// q = transmission * qm + transmission_offset; torques by tau_m = transmission^T tau.
  /// Empty means identity.
  Eigen::MatrixXd transmission;
  Eigen::VectorXd transmission_offset;
  /// Frame of a wrist force/torque sensor (and payload), attached to body `sensor_body`.
  int sensor_body = -1;  // -1: the last body
  Pose sensor_pose;      // sensor frame in that body's frame
  /// What loading found and the user may act on (physically impossible inertia in their own
  /// file, ...): also logged; the runner puts them in summary.json's `warnings`.
  std::vector<std::string> warnings;
  /// Collision geometry (URDF <collision>, a DH description's `collision` keys); empty when the
  /// description gives none. Used only when a study asks for collision avoidance.
  std::vector<CollisionShape> collision;
  /// Facts about a shipped description worth stating once in a report (known defects of
  /// published data, kept as published): summary.json `robot.notes` and the report, not logged.
  std::vector<std::string> notes;
  /// Closed kinematic chains: empty `closed.loops` for a tree (the usual case). With loops,
  /// `bodies` is the spanning tree, the measured coordinates are the actuated tree joints
  /// `closed.actuated` (dof() of them), `limits` and `drives` are per measured coordinate and
  /// the passive joints follow from the loop constraints (exid/closed_chain.hpp).
  ClosedChain closed;
  /// A floating-base robot: the base link moves freely (its motion is a signal, see
  /// exid/floating_base.hpp) and `base` describes it. false: the base is fixed to the world
  /// (every fixed-base algorithm refuses a floating robot: requireFixedBase).
  bool floating_base = false;
  FloatingBase base;

  /// Number of measured (actuated) coordinates: what data, trajectories, drives and limits
  /// count. For a tree it equals numJoints().
  int dof() const {
    return closed.loops.empty() ? static_cast<int>(bodies.size())
                                : static_cast<int>(closed.actuated.size());
  }
  /// Number of joints (bodies) of the kinematic tree (the spanning tree of a closed chain).
  int numJoints() const { return static_cast<int>(bodies.size()); }
  bool hasLoops() const { return !closed.loops.empty(); }
  /// Tree joint index of measured coordinate k (k itself for a tree).
  int actuatedJoint(int k) const {
    return closed.loops.empty() ? k : closed.actuated[static_cast<size_t>(k)];
  }
  int numInertialParameters() const { return 10 * numJoints(); }
  bool hasTransmission() const { return transmission.size() > 0; }
  int sensorBody() const { return sensor_body < 0 ? numJoints() - 1 : sensor_body; }

  /// Names of the standard inertial parameters, e.g. "XX1" ... "M1" (1-based body index).
  std::vector<std::string> inertialParameterNames() const;
  /// All standard inertial parameters, stacked body by body (10 * numJoints).
  Eigen::VectorXd inertialParameters() const;
  /// Throws exid::Error naming the body and rule if the structure is invalid
  /// (parent order, unit axes, orthonormal rotations, finite numbers, sizes).
  void validateStructure() const;
  /// Throws exid::Error naming `what` (the consumer) when the robot has a floating base: the
  /// fixed-base algorithms (differential/integral/load models, excitation design, collision,
  /// export writers, ...) would compute something wrong for it.
  void requireFixedBase(const std::string& what) const;
};

/// Parameter order of one body: XX XY XZ YY YZ ZZ MX MY MZ M.
inline constexpr const char* kInertialNames[10] = {"XX", "XY", "XZ", "YY", "YZ",
                                                   "ZZ", "MX", "MY", "MZ", "M"};

/// Converts mass, centre of mass (in the body frame) and the inertia tensor about the centre of
/// mass (axes of the body frame) into the 10 standard parameters about the body frame origin.
EXID_API Eigen::Matrix<double, 10, 1> inertialFromCom(double mass, const Eigen::Vector3d& com,
                                                      const Eigen::Matrix3d& I_com);
/// The inverse map; mass must be positive for the centre of mass to exist.
EXID_API void comFromInertial(const Eigen::Matrix<double, 10, 1>& pi, double* mass,
                              Eigen::Vector3d* com, Eigen::Matrix3d* I_com);
/// The standard parameters of the same body expressed in frame A, given frame B (where pi is
/// expressed) relative to A.
EXID_API Eigen::Matrix<double, 10, 1> transformInertial(const Eigen::Matrix<double, 10, 1>& pi_B,
                                                        const Pose& X_AB);

/// Physical consistency of one body's parameters.
struct EXID_API InertiaCheck {
  bool ok = true;
  std::string rule;  // empty when ok: "negative mass", "inertia not positive semi-definite", ...
};
EXID_API InertiaCheck checkPhysical(const Eigen::Matrix<double, 10, 1>& pi, double tol = 1e-12);

}  // namespace exid
