// exid — robot description loaders: DH / modified-DH YAML tables and URDF (urdfdom).
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
  /// URDF only: use <dynamics damping friction> as the nominal viscous and Coulomb friction.
  /// Off by default: those are usually a simulator's (Gazebo's) values, not identified ones;
  /// the model's notes then say that they were ignored.
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

/// Dispatches on the extension: .urdf / .xml -> loadUrdf, .yaml / .yml -> loadDhYaml.
EXID_API RobotModel loadRobotFile(const std::filesystem::path& file,
                                  const LoadOptions& options = {});

/// Checks every body with exid::checkPhysical (plus "zero mass with non-zero inertia"), and
/// reports each problem as "source: link 'name' (body i): rule": a warning, or exid::Error when
/// options.strict. Called by the loaders; exposed for code-built models.
EXID_API void checkModelPhysical(const RobotModel& model, const LoadOptions& options);

/// Reports one warning according to options (appended to options.warnings, else stderr).
EXID_API void reportWarning(const LoadOptions& options, const std::string& message);

}  // namespace exid
