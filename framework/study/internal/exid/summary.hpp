// exid — a study's results, typed: the status, the robot, the excitation, the experiment, the
// identification and the validation as the runner records them. summary.json's keys for these
// values, the brief table `exid run` prints and the report's summary are all rendered from this
// one record (summary.json adds what has no fixed type: meta, details, inspection, history).
#pragma once

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"

namespace exid {

// The stages' parts of a study's results (StudySummary::Robot, ...).
struct EXID_API RobotSummary {
  std::string type, name;
  int dof = 0;
  int n_parameters = 0;
  std::optional<int> n_base_parameters;  // once a model is bound
  std::vector<std::string> notes;        // known defects of shipped data, said once
  double wall_s = NAN;
};
struct EXID_API ExcitationSummary {
  std::string trajectory, criterion, optimizer;
  double criterion_initial = NAN, criterion_final = NAN;
  double cond_W_initial = NAN, cond_W_final = NAN;
  double max_constraint_violation = NAN;
  bool feasible = true;  // the result holds every constraint (else a warning says which)
  std::optional<double> torque_margin, torque_ratio_max;  // with torque limits
  /// With collision avoidance: the margin, the checked pairs, and the smallest distance over
  /// the design samples and pairs at the initial and the final trajectory, and where.
  std::optional<double> distance_margin_m, min_distance_initial_m, min_distance_final_m;
  int collision_pairs = 0;
  std::string min_distance_pair;
  std::vector<std::string> collision_excluded;
  /// The five pairs that come closest at the final trajectory's design samples, closest first.
  std::vector<std::pair<std::string, double>> closest_pairs_m;
  int iterations = 0;
  long long evaluations = 0;
  double wall_s = NAN;
  StopReason stop_reason = StopReason::None;
  std::string stop_reason_text;  // the reason with the optimiser's own words
  bool reproducible = true;      // false: stopped by a time budget
};
struct EXID_API ExperimentSummary {
  std::string type;
  long long samples = 0;
  double duration_s = NAN;
  double wall_s = NAN;
};
struct EXID_API IdentificationSummary {
  std::string estimator;
  double wall_s = NAN;
  long long rows = 0;
  double cond_W = NAN, residual_rms = NAN, sigma = NAN;
  std::optional<double> param_abs_err, param_rel_err;  // simulated data: against the truth
};
struct EXID_API ValidationSummary {
  std::string type;
  long long samples = 0, rows = 0;
  double relative_error = NAN;
  double residual_rms = NAN;  // RMS of the held-out prediction error over every row
  std::vector<double> rms_per_joint, relative_error_per_joint;
  double wall_s = NAN;
};

struct EXID_API StudySummary {
  std::string study;
  std::string status = "running";  // running, ok, failed, cancelled
  std::string failed_stage;        // the stage that failed ("" unless failed or cancelled)
  std::string message;
  std::vector<std::string> warnings;  // what a user should know about the results
  /// What the results say of themselves (status ok only): "ok", or "suspect" with the reasons
  /// (judgeResults). Empty until judged.
  std::string verdict;
  std::vector<std::string> verdict_reasons;
  double wall_s = NAN;

  using Robot = RobotSummary;
  using Excitation = ExcitationSummary;
  using Experiment = ExperimentSummary;
  using Identification = IdentificationSummary;
  using Validation = ValidationSummary;
  std::optional<Robot> robot;
  std::optional<Excitation> excitation;
  std::optional<Experiment> experiment;
  std::optional<Identification> identification;
  std::optional<Validation> validation;
};

/// Writes the typed values into summary.json's objects (keys already there keep their place).
EXID_API void renderInto(const StudySummary& s,
                         Json* summary);  // status, message, ..., warnings, wall_s
EXID_API void renderInto(const StudySummary::Robot& r, Json* robot);
EXID_API void renderInto(const StudySummary::Excitation& x, Json* excitation);
EXID_API void renderInto(const StudySummary::Experiment& e, Json* experiment);
EXID_API void renderInto(const StudySummary::Identification& i, Json* identification);
EXID_API void renderInto(const StudySummary::Validation& v, Json* validation);

/// The Markdown table printed at the end of `exid run` and at the top of report.md.
EXID_API std::string briefTable(const StudySummary& s);

/// Thresholds of the verdict (docs/study.md, "The verdict").
inline constexpr double kVerdictHeldOutNoBetterThanZero = 1.0;  // held-out relative error
inline constexpr double kVerdictHeldOutOverResidual = 3.0;      // held-out RMS / identification's
inline constexpr double kVerdictHeldOutMaterial = 0.05;  // the ratio counts above this rel. error
inline constexpr double kVerdictPriorTailSigma = 6.0;    // chi-square tail, in its std

/// The reasons a finished study's results are suspect, read from its summary.json tree (empty:
/// nothing found): a held-out error no better than zero torque, a held-out error far above the
/// identification residual, an estimator's own doubts (identification.details.suspect, e.g. a
/// scale chosen at the edge of its grid), a fit far outside its prior.
EXID_API std::vector<std::string> verdictReasons(const Json& summary);

/// Sets s->verdict and s->verdict_reasons from the summary tree (verdictReasons).
EXID_API void judgeResults(const Json& summary, StudySummary* s);

}  // namespace exid
