// exid — robot description loaders: DH / modified-DH YAML tables, URDF (urdfdom), MJCF (MuJoCo)
// and SDFormat.
//
// Library exid_robots (robots/loaders). The file formats are documented in docs/robots.md.
//
// Errors (bad XML/YAML, missing or duplicate links/joints, kinematic loops, wrong types,
// non-finite numbers, unknown keys, unsupported joints) throw exid::Error with a message that
// names the source, the place (YAML line, link, joint) and the rule broken, e.g.
//   "puma.yaml:14: links[2].mass: expected a number, found 'heavy'"
//   "arm.urdf: joint 'j3': floating joints are not supported (only revolute, continuous,
//    prismatic and fixed)"
//
// Physically impossible inertial data (exid::checkPhysical: negative mass, inertia not positive
// semi-definite, triangle inequality; and a zero mass with a non-zero inertia tensor) is a
// WARNING by default (classic published models, e.g. the PUMA 560, contain such data) and an
// ERROR with LoadOptions::strict.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

struct EXID_API LoadOptions {
  /// Physically impossible inertial data (and other suspicious data, see above) is an error.
  bool strict = false;
  /// Where warnings go (one line each, "source: link 'x': rule"). Null: printed to stderr.
  std::vector<std::string>* warnings = nullptr;
  /// URDF only: a companion file whose root element is <exid> (same content as the <exid>
  /// extension element, docs/robots.md), for a URDF that must stay as published. Empty: none.
  /// A URDF that has its own <exid> element and a companion is an error.
  std::filesystem::path urdf_extension;
  /// URDF, SDF and MJCF: use the joints' damping and friction (URDF and SDF <dynamics>; MJCF
  /// damping, frictionloss and armature) as the nominal viscous and Coulomb friction (and rotor
  /// inertia). Off by default: those are usually a simulator's values, not identified ones; the
  /// model's notes then say that they were ignored.
  bool urdf_dynamics_as_friction = false;
};

/// A DH (standard or modified) YAML table. See docs/robots.md for the keys.
EXID_API RobotModel loadDhYaml(const std::filesystem::path& file, const LoadOptions& options = {});
/// The same from text; `source` names it in messages (e.g. "puma560.yaml (embedded)").
EXID_API RobotModel loadDhYamlString(const std::string& text, const std::string& source,
                                     const LoadOptions& options = {});

/// A URDF file (urdfdom) with the optional <exid> extension element. See docs/robots.md.
EXID_API RobotModel loadUrdf(const std::filesystem::path& file, const LoadOptions& options = {});
/// The same from text; `source` names it in messages.
EXID_API RobotModel loadUrdfString(const std::string& xml, const std::string& source,
                                   const LoadOptions& options = {});

/// An MJCF file (MuJoCo's XML): one body tree in <worldbody> with <inertial> elements, hinge and
/// slide joints (one per body), <default> classes for joints and motors, gravity from <option>,
/// a motor's ctrlrange times its gear as the torque limit, the site "exid_sensor" as the sensor
/// frame, joint `ref`s, `connect` constraints as the loop-closure joints of a closed chain (the
/// motors' joints actuated). Refused with a message: free and ball joints, several joints in one
/// body, <include>, other equality constraints and tendons, joint springs, inertia computed from
/// geoms. See docs/robots.md.
EXID_API RobotModel loadMjcf(const std::filesystem::path& file, const LoadOptions& options = {});
EXID_API RobotModel loadMjcfString(const std::string& xml, const std::string& source,
                                   const LoadOptions& options = {});

/// An SDFormat 1.5-1.9 file: one <model> fixed to the world by one fixed joint, revolute,
/// continuous, prismatic and fixed joints, poses through the frame graph (relative_to, <frame>,
/// expressed_in), the frame "exid_sensor" as the sensor frame. SDF carries no gravity (the
/// default is used; the model's notes say so); loops closed by the joints <exid:closed_chain>
/// names as cut. See docs/robots.md.
EXID_API RobotModel loadSdf(const std::filesystem::path& file, const LoadOptions& options = {});
EXID_API RobotModel loadSdfString(const std::string& xml, const std::string& source,
                                  const LoadOptions& options = {});

/// Dispatches on the extension: .urdf -> loadUrdf, .sdf -> loadSdf, .mjcf -> loadMjcf, .xml ->
/// by its root element (<mujoco>: MJCF, <sdf>: SDF, else URDF), .yaml / .yml -> loadDhYaml.
EXID_API RobotModel loadRobotFile(const std::filesystem::path& file,
                                  const LoadOptions& options = {});

/// Checks every body with exid::checkPhysical (plus "zero mass with non-zero inertia"), and
/// reports each problem as "source: link 'name' (body i): rule": a warning, or exid::Error when
/// options.strict. Called by the loaders; exposed for code-built models.
EXID_API void checkModelPhysical(const RobotModel& model, const LoadOptions& options);

/// Reports one warning according to options (appended to options.warnings, else stderr).
EXID_API void reportWarning(const LoadOptions& options, const std::string& message);

}  // namespace exid
