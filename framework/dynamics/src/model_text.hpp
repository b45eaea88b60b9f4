// exid — what the robot description writers (URDF, MJCF, SDF) share: number and pose text, XML
// escaping, and the drive terms that a single joint can carry. Internal (not installed).
#pragma once

#include <Eigen/Core>
#include <set>
#include <string>
#include <vector>

#include "exid/robot_model.hpp"

namespace exid::detail {

/// A double as the shortest text that reads back to the same double ("%.17g").
std::string num(double v);
/// "x y z" with num().
std::string vec3(const Eigen::Vector3d& v);
/// Roll-pitch-yaw of URDF and SDF (R = Rz(yaw) Ry(pitch) Rx(roll)).
Eigen::Vector3d rpy(const Eigen::Matrix3d& R);
/// Text as an XML attribute value or element content.
std::string xmlEscape(const std::string& s);
/// An XML comment ("<!--\n...\n-->\n") holding `text` ("--", which XML forbids there, broken
/// up); empty text: nothing.
std::string xmlComment(const std::string& text);
/// A limit that is given (finite and not exid's 1e300 "none").
bool finiteLimit(double v);
/// `base`, made unique among `taken` by appending '_'.
std::string freeName(std::string base, const std::set<std::string>& taken);

/// Drive terms acting on one joint coordinate: reflected rotor inertia [kg m^2 or kg], viscous
/// [N m s/rad or N s/m] and Coulomb friction [N m or N].
struct JointDriveTerms {
  double rotor_inertia = 0.0;
  double viscous = 0.0;
  double coulomb = 0.0;
};

/// The model's drives (measured coordinates qm, q = T qm + q0) as terms of single joints: a
/// measured coordinate j whose row of T^-1 has one non-zero entry r, at joint i (qm_j = r q_i +
/// const), puts Ia_j r^2, Fv_j r^2 and Fc_j |r| on joint i. Without a transmission r = 1, i = j.
/// A coordinate that moves several joints (a coupled wrist, absolute angles) has no such terms:
/// its index goes to `coupled` (0-based), as do all when T is singular.
std::vector<JointDriveTerms> jointDriveTerms(const RobotModel& m, std::vector<int>* coupled);

/// What a writer of `format` leaves out of every description format but URDF's <exid> element:
/// drive offsets, the drives of coupled coordinates (`coupled`, from jointDriveTerms), the
/// transmission, acceleration limits, gear ratios and collision geometry; one sentence each,
/// appended to `out`, only for what the model has.
void leftOutOfEveryFormat(const RobotModel& m, const std::vector<int>& coupled,
                          const std::string& format, std::vector<std::string>* out);

/// "1, 3, 4" (0-based indices written 1-based).
std::string joinNumbers(const std::vector<int>& zero_based);

/// Refuses (exid::Error) a body whose parameters are not physically consistent
/// (exid::checkPhysical), naming the body and the rule, and `format`.
void requirePhysical(const RobotModel& m, const std::string& format);

/// A body's mass, centre of mass and (symmetric) inertia about it, from its inertial parameters;
/// a body without mass (and so, consistent, without first moment) gets c = 0 and the tensor
/// about its frame's origin.
void massCentreInertia(const Eigen::Matrix<double, 10, 1>& pi, double* mass, Eigen::Vector3d* c,
                       Eigen::Matrix3d* Ic);

/// Body b's frame in its parent body's frame with its joint at q: pre · motion(q) · post (at
/// q = 0 exactly pre · post).
Pose bodyFrameAt(const Body& b, double q);

/// The kinematic tree a writer writes, and the configuration it writes it at. A tree: the model
/// itself at q = 0. A closed chain: its spanning tree with limits per tree joint (the actuated
/// joints' own, the passive ones' closed.tree_limits) and drives on the actuated joints, written
/// at the loops' reference configuration (an assembled one: the formats close their loops in the
/// configuration the file is written at). `reference` gets that configuration (numJoints).
RobotModel writtenTree(const RobotModel& m, Eigen::VectorXd* reference);

}  // namespace exid::detail
