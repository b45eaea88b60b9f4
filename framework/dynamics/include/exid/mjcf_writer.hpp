// exid — a RobotModel written as MJCF, MuJoCo's XML (exid export --format mjcf). Library
// exid_dynamics.
//
// One nested <body> per exid body, its frame the exid BODY frame (at q = 0): the joint sits in
// it at the moved joint frame's origin (pos) with the axis in body axes, so a standard-DH `post`
// pose needs no change of the inertial parameters. <inertial>: mass, centre of mass and the
// principal moments (diaginertia) with the principal axes (quat; none when the tensor is
// diagonal in the body axes). Joints: hinge or slide, `range` from finite position limits, and
// the drive terms that a single joint carries (exid's drives act on the measured coordinates,
// docs/consistent.md "exid export"): `armature` = reflected rotor inertia, `damping` = viscous
// friction, `frictionloss` = Coulomb friction (MuJoCo's dry-friction constraint: equal to
// Fc sign(qd) in motion, a ramp through rest). One <motor> per joint (gear 1, ctrlrange from
// the torque limit), a <site> "exid_sensor" at the sensor frame, <option> with the gravity.
// What MJCF cannot carry (drive offsets, coupled drives, velocity and acceleration limits, the
// transmission, collision geometry, ...) is listed in `left_out` and in a comment of the file.
#pragma once

#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

struct EXID_API MjcfWriteOptions {
  std::string comment;        // written as an XML comment at the top
  double timestep_s = 0.002;  // <option timestep> (MuJoCo's default)
};

/// Throws exid::Error when a body's parameters are not physically consistent
/// (exid::checkPhysical: MuJoCo refuses them) or not finite. `left_out` (may be null) receives
/// one sentence per thing of the model that the MJCF does not carry.
EXID_API std::string writeMjcf(const RobotModel& model, const MjcfWriteOptions& options = {},
                               std::vector<std::string>* left_out = nullptr);

}  // namespace exid
