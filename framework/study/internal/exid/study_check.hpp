// exid — the checks of a study that need its plugins: what `exid validate` refuses, `exid run`
// (and the single-stage commands, and the Python package's run_study) refuses before any stage
// runs, with the same message.
#pragma once

#include <memory>

#include "exid/config.hpp"
#include "exid/export.hpp"

namespace exid {

class Registry;
struct RobotModel;

/// Checks a parsed study (loadStudy/parseStudy) beyond its syntax, without running anything:
///   - the robot is loaded (its file read and checked: a xacro file, a bad URDF or DH table is
///     refused here, not in the run's first stage);
///   - every plugin the study names is made from its parameters (models, excitation trajectory,
///     criterion and optimiser, experiment, estimator, validation): the checks their
///     constructors make across parameters (an estimator's measurement_delay without its
///     bound, say) are made;
///   - a prior from an earlier study: its parameters.csv is read and every row checked.
/// Throws exid::Error "FILE:LINE: SECTION: what is wrong", FILE `source` (as the user named the
/// study; empty: cfg.file). Returns the robot it loaded (a run reuses it: RunOptions::robot).
EXID_API std::shared_ptr<const RobotModel> checkStudy(const StudyConfig& cfg,
                                                      const Registry& registry,
                                                      const std::string& source = "");

/// The rows of a prior's parameters.csv (PriorSpec::from == "study") checked without a model:
/// every value a finite number, every std a positive number whose variance (times the prior's
/// scale) is usable (std <= kMaxPriorStd). Throws exid::Error naming the file and the line.
EXID_API void checkPriorFile(const PriorSpec& spec);

/// The largest standard deviation a prior may have (a prior std of 1e300 squares to infinity;
/// a std this large is no prior at all: leave the prior out).
inline constexpr double kMaxPriorStd = 1e100;

}  // namespace exid
