// exid — running a study: robot -> model -> excitation -> experiment -> estimator ->
// validation -> report. Every stage is optional except the robot. Files are written atomically;
// a failure stops the study, is recorded in summary.json (status "failed", message) and keeps
// what finished stages wrote.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "exid/config.hpp"
#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"
#include "exid/summary.hpp"
#include "exid/tables.hpp"  // samplesTable, datasetTable (formerly here)

namespace exid {

class Registry;
class ObservationModel;
struct Prior;
struct RobotModel;

struct EXID_API RunOptions {
  std::filesystem::path out_dir;  // "" = write nothing
  std::function<void(const std::string& stage, double fraction, const std::string& text)> progress;
  std::function<bool()> cancelled;
  /// > 0 (command-line programs only): once cancelled() turns true, a run that has not ended
  /// within this many seconds (a long computation without a stop check, e.g. one call into an
  /// optimiser library) is ended by a watchdog: it records status "cancelled" in summary.json,
  /// publishes the run folder as for any failed run (partial files of the stage removed) and
  /// ends the PROCESS with _exit(hard_stop_exit_code()).
  double hard_stop_s = 0.0;
  std::function<int()> hard_stop_exit_code;
  /// `exid excite --export DIR`: the optimal excitation trajectory written for execution into
  /// this folder (trajectory_export.hpp: at export_rate_Hz, export_periods repetitions, checked
  /// against the robot's limits); "" = none. summary.json: excitation.export.
  std::filesystem::path export_dir;
  double export_rate_Hz = 1000.0;
  int export_periods = 1;
  /// Remove the `*.tmp.PID` files and staging folders of dead processes beside out_dir first
  /// (a matrix does it once for all its cells instead).
  bool clean_stale = true;
  /// The study's robot when already loaded (checkStudy, exid/study_check.hpp, returns it). The
  /// robot stage loads it again all the same, inside the run: the files it reads are the run's
  /// inputs (summary.json `inputs`, a matrix cell's key). Kept for callers that hold it.
  std::shared_ptr<const RobotModel> robot;
};

struct EXID_API StudyResult {
  bool ok = false;
  std::string message;
  Json summary;
  /// The typed results summary.json's status, robot, excitation, experiment, identification and
  /// validation keys are rendered from (summary.hpp).
  StudySummary headline;
  /// Where the run's files are: out_dir, or (a failed run beside an earlier run's results,
  /// which it leaves untouched) out_dir + ".failed". Empty when nothing was written.
  std::filesystem::path written_to;
  /// The stop was a request (SIGINT/SIGTERM through RunOptions::cancelled): status "cancelled".
  bool cancelled = false;
};

/// Never throws for failures inside the study: they come back as ok = false.
EXID_API StudyResult runStudy(const StudyConfig& cfg, const Registry& registry,
                              const RunOptions& options);

/// The study trimmed to one of its stages, as `exid excite|simulate|identify` run it:
///   excite   -- robot, model and excitation (no experiment, estimator or validation);
///   simulate -- the excitation (if any) and the experiment (no estimator or validation);
///   identify -- the experiment and the estimator (no excitation or validation); a non-empty
///               `data` (a CSV file, or a ROS 2 bag folder: a folder holding metadata.yaml)
///               replaces the experiment by the `csv` (or `rosbag2`) experiment reading it.
/// Throws exid::Error when the study lacks the stage's section or `stage` is none of these.
EXID_API StudyConfig stageStudy(StudyConfig cfg, const std::string& stage, const Registry& registry,
                                const std::filesystem::path& data = {});

/// The prior a study asks for (StudyConfig::prior) on the model's (bound) base parameters.
/// Throws exid::Error when it cannot be built (missing file or names, zero variances).
EXID_API Prior buildPrior(const PriorSpec& spec, const ObservationModel& model);

/// What an excitation design adds as already known (excitation.information): the information of
/// an earlier study's estimate and/or of a prior on the robot description's values, weighed
/// against the new experiment's rows by its noise std and recording rate: `matrix` (base x base,
/// the model's base columns) = noise_std^2 / (recording_rate_hz * dt) * (sum of the inverse
/// covariances), dt the design's sample period, so that W^T W + matrix is the total information
/// up to a factor. Empty when the study adds none. Throws exid::Error naming the file, the key
/// or the parameter when it cannot be built.
struct EXID_API KnownInformation {
  Eigen::MatrixXd matrix;
  double rows_per_design_sample = 0.0;
  std::vector<std::string> sources;
};
EXID_API KnownInformation knownInformation(const StudyConfig& cfg, const ObservationModel& model,
                                           const Samples& design);

}  // namespace exid
