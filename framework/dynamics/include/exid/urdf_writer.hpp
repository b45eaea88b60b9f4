// exid — a RobotModel written as URDF (exid export). Library exid_dynamics.
//
// One <link> per body and one movable <joint> per body, plus a massless root link. Each link
// frame is the body's MOVED JOINT frame (URDF has no post-joint transform), so a body with a
// standard-DH `post` pose gets its inertial parameters transformed into that frame and its
// children's joint origins composed with it: the dynamics are unchanged. <inertial>: mass,
// centre of mass (origin xyz, rpy 0) and the inertia about the centre of mass in the link axes.
// Drives (rotor inertia, Coulomb, viscous, offset, gear ratio), acceleration limits, gravity,
// transmission and the sensor frame go into the <exid> extension element (docs/robots.md).
#pragma once

#include <string>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

struct EXID_API UrdfWriteOptions {
  std::string comment;         // written as an XML comment at the top (no "--")
  std::string root_link = "";  // name of the massless root link ("" = "base_link" or a free name)
};

/// Throws exid::Error when a body cannot be written (mass <= 0 with non-zero parameters, or
/// non-finite numbers).
EXID_API std::string writeUrdf(const RobotModel& model, const UrdfWriteOptions& options = {});

}  // namespace exid
