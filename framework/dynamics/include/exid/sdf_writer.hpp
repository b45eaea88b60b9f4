// exid — a RobotModel written as SDFormat 1.9 (Gazebo; libsdformat 12 reads it), exid export
// --format sdf. Library exid_dynamics.
//
// One <model>: a massless root link welded to `world` by a fixed joint, one <link> per exid body
// whose frame is the exid BODY frame (<pose relative_to> its parent link at q = 0), one
// <joint> per body whose frame is the moved joint frame (<pose> in the child link), so a
// standard-DH `post` pose needs no change of the inertial parameters. <inertial>: <pose> of the
// centre of mass (link axes), <mass>, ixx..izz about the centre of mass. Joints: revolute (with
// finite position limits), continuous or prismatic, <axis><xyz> in the joint frame, <limit>
// (lower, upper, effort, velocity when given), <dynamics> (damping = viscous friction, friction
// = Coulomb friction: the drive terms that a single joint carries). A <frame> "exid_sensor" at
// the sensor frame. What SDF cannot carry (rotor inertias, drive offsets, coupled drives,
// acceleration limits, the transmission, collision geometry, gravity) is listed in `left_out` and
// in a comment of the file.
#pragma once

#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

struct EXID_API SdfWriteOptions {
  std::string comment;         // written as an XML comment at the top
  std::string root_link = "";  // name of the massless root link ("" = "base_link" or a free name)
};

/// Throws exid::Error when a body's parameters are not physically consistent
/// (exid::checkPhysical) or when a link and a joint share a name (SDFormat frames share one
/// namespace). `left_out` (may be null) receives one sentence per thing of the model that the
/// SDF does not carry.
EXID_API std::string writeSdf(const RobotModel& model, const SdfWriteOptions& options = {},
                              std::vector<std::string>* left_out = nullptr);

}  // namespace exid
