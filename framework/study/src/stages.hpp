// exid — one study, stage by stage (private to the study layer). Each stage is a function of
// what every stage reads (StageEnv) and of the earlier stages' outputs, returning its own output:
// what the next stages use and ONE record of its result (the typed summary part, summary.json's
// untyped extras, what the report shows). record() renders that one record into summary.json,
// the typed StudySummary and the report section, and writes the stage's files. runStudy()
// (runner.cpp) runs the stages in order and records each. The stages are in stages_design.cpp
// (robot, model, excitation), stages_data.cpp (experiment, identification) and
// stages_validation.cpp (validation); the helpers they share in run_helpers.cpp.
#pragma once

#include <fcntl.h>
#include <fmt/format.h>
#include <stdio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <system_error>
#include <thread>
#include <utility>

#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/export.hpp"
#include "exid/input_file.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"
#include "exid/runner.hpp"
#include "exid/trajectory_export.hpp"
#include "exid/version.hpp"
#include "report.hpp"
#include "run_folder.hpp"
#include "stacked_model.hpp"

namespace exid {

namespace fs = std::filesystem;

// What a study says when the optimiser found no trajectory within every constraint.
std::string infeasibleText(const OptimizerResult& r, const StudySummary::Excitation& x);

// The smallest distance over the design samples and checked pairs, initial and final.
void collisionSummary(const CollisionOptions& o, const RobotModel& robot, const Samples& initial,
                      const Samples& best, StudySummary::Excitation* x, Eigen::VectorXd* dmin_best);

// Seconds since a time point.
double seconds(std::chrono::steady_clock::time_point since);

// raw: the estimator filters and differentiates the signals itself (EstimatorSpecs::
// needs_raw_dataset), so qd and qdd may be absent.
void checkDataset(const Dataset& d, const RobotModel& robot, const ObservationModel* model,
                  const std::string& what, bool raw = false);

// Every value finite, else an error naming the stage's quantity, the element and the value.
void checkFinite(const Eigen::MatrixXd& M, const std::string& what,
                 const std::vector<std::string>& names = {});

// (a streamed dataset: every value is checked by the stream as it is read)
void checkDatasetFinite(const Dataset& d, const std::string& what);

// A long recording is inspected on every s-th sample (at most kRunInspectSamples, run_helpers.cpp):
// the checks cost a fraction of the identification, never several times it.
long streamInspectStride(long K);

// exid inspect's checks on a dataset of the study (inspect.hpp): the whole result goes under
// summary.json `inspection.<what>`, its warnings among the study's (applyInspection). An
// inspection that cannot be done is noted there; it never fails the study.
// The inspection's result for a dataset: the checks, or a note when it could not be done.
Json inspectionOf(const RobotModel& robot, const ObservationModel* model, const Dataset& d,
                  const RunContext& ctx);

// The held-out prediction of rows whose columns hold the recorded torque (stages_data.cpp).
std::string predictTorqueColumns(const Rows& rows, const Estimate& est, Eigen::VectorXd* pred);

// What every stage reads: the study, the plugins, the run's options and context, the folder it
// writes into, the run's input manifest and who is told which stage runs.
struct EXID_API StageEnv {
  StageEnv(const StudyConfig& study, const Registry& registry, const RunOptions& options,
           fs::path staging, std::function<void(const char*)> set_stage = {});
  const StudyConfig& cfg;
  const Registry& reg;
  const RunOptions& opt;
  const fs::path dir;  // where this run writes ("" = nowhere)
  RunContext ctx;
  /// Every file the run read through the opener (exid/input_file.hpp): summary.json `inputs`. A
  /// stage's own thread records into it (InputManifestScope); null: the caller's scope only.
  InputManifest* manifest = nullptr;
  std::function<void(const char*)> set_stage;  // names the stage now running (failures, watchdog)

  bool write() const { return !dir.empty(); }
  void enter(const char* stage) const {
    if (set_stage) set_stage(stage);
  }
  /// The progress callback of a stage (RunOptions::progress with the stage's name).
  std::function<void(double, const std::string&)> progressFor(const std::string& stage) const;
};

// Where a stage's record goes: summary.json's tree, the typed results, the report (null: none).
struct StudyRecord {
  Json* summary;
  StudySummary* typed;
  Report* report = nullptr;
  /// What a user should know about this run's results (logged unless `log` is false): the
  /// summary's and the report's warnings.
  void warn(const std::string& text, bool log = true);
};

// An inspection's result under summary.json `inspection.<what>`, its warnings among the study's.
void applyInspection(StudyRecord& rec, const char* what, const Json& I);

// What the experiment's record gets once the estimator has read the data: the inspection that ran
// beside it, or (a streamed recording) the meta of the whole pass and the inspection after it.
struct ExperimentFollowUp {
  std::optional<Json> meta;        // summary.json experiment.meta, replaced
  std::optional<Json> inspection;  // summary.json inspection.experiment
};
void record(const ExperimentFollowUp& f, StudyRecord& rec);

// The study's estimator, made once from its parameters (its specs steer the experiment, it
// identifies, and it processes the validation rows as it processed its own), and the experiment's
// inspection while it runs beside it. That inspection reads robot, model and data (it holds
// them): it is waited for before the estimator goes, also when a stage throws; its result stays
// here until the identification's record takes it, or the failure's.
class StudyEstimator {
 public:
  StudyEstimator(const StudyConfig& cfg, const Registry& reg) : cfg_(cfg), reg_(reg) {}
  ~StudyEstimator() {
    if (inspection_.valid()) inspection_.wait();
  }
  StudyEstimator(const StudyEstimator&) = delete;
  StudyEstimator& operator=(const StudyEstimator&) = delete;

  Estimator& get() {
    if (!estimator_)
      estimator_ = reg_.create<Estimator>(cfg_.estimator->type, cfg_.estimator->params);
    return *estimator_;
  }
  /// Runs the experiment's inspection beside the estimator.
  void inspectBeside(std::function<Json()> inspect) {
    inspection_ = std::async(std::launch::async, std::move(inspect));
  }
  /// What the experiment's record gets after the estimator (the inspection beside it waited for).
  ExperimentFollowUp& followUp() {
    if (inspection_.valid()) follow_up_.inspection = inspection_.get();
    return follow_up_;
  }
  ExperimentFollowUp takeFollowUp() { return std::exchange(followUp(), ExperimentFollowUp()); }

 private:
  const StudyConfig& cfg_;
  const Registry& reg_;
  std::shared_ptr<Estimator> estimator_;
  std::future<Json> inspection_;
  ExperimentFollowUp follow_up_;
};

// The stages, each with its output: what the next stages use, then its one record. A stage that
// throws has recorded nothing; a record that throws (writing a file) leaves what it rendered.

// The robot: its plugin builds the model of the arm.
struct RobotStageOut {
  std::shared_ptr<const RobotModel> robot;
  RobotSummary summary;
  std::vector<std::string> warnings;  // the robot's own (logged on load)
};
EXID_API RobotStageOut robotStage(const StageEnv& env);
EXID_API void record(const StageEnv& env, const RobotStageOut& r, StudyRecord& rec);

// The observation model, bound to the robot (and to the joints the excitation moves).
struct ModelStageOut {
  std::shared_ptr<ObservationModel> model;  // null: the study has no model (nothing recorded)
  /// The excitation's trajectory, bound, when the study designs one (it says which joints move).
  std::shared_ptr<Trajectory> traj;
  std::string type;  // the model's plugin name
  int n_full = 0, n_base = 0;
  std::vector<std::string> base_parameters;
  Json details;
  std::vector<double> moving_joints;  // 1-based; empty: every joint moves
  double wall_s = NAN;
};
EXID_API ModelStageOut modelStage(const StageEnv& env, const RobotStageOut& robot);
EXID_API void record(const StageEnv& env, const ModelStageOut& m, StudyRecord& rec);

// Excitation design: the trajectory that optimises the criterion under the limits.
struct ExcitationStageOut {
  bool ran = false;                  // false: the study designs no trajectory
  std::shared_ptr<Trajectory> traj;  // its parameters at the optimum: result.z
  std::shared_ptr<ObservationModel> model;
  ExcitationOptions options;
  OptimizerResult result;
  Samples initial, best;  // best: the reference of the experiment
  ExcitationSummary summary;
  std::optional<Json> known_information;  // summary.json excitation.known_information
  Eigen::VectorXd tau_max;                // with torque limits: the limits and the optimal
  Eigen::MatrixXd tau;                    // trajectory's predicted torques
  Eigen::VectorXd min_distance;           // with collision avoidance: per design sample
  std::vector<std::string> warnings;
};
EXID_API ExcitationStageOut excitationStage(const StageEnv& env, const RobotStageOut& robot,
                                            const ModelStageOut& model);
// (writes the trajectories, the criterion's history and the --export)
EXID_API void record(const StageEnv& env, const ExcitationStageOut& x, StudyRecord& rec);

// The experiment: simulated, or a recording read whole or streamed.
struct ExperimentStageOut {
  std::shared_ptr<const Dataset> data;      // null: the study has no experiment
  std::shared_ptr<const RobotModel> robot;  // the robot the data are of
  ExperimentSummary summary;
  std::string streamed;  // a streamed recording: what that means for its statistics
  std::vector<std::string> warnings;
  std::optional<Json> inspection;  // inspected here (no estimator to run beside)
  bool write_csv = false;          // experiment.csv, else why not (when the run writes)
  std::string csv_not_written;
};
EXID_API ExperimentStageOut experimentStage(const StageEnv& env, const RobotStageOut& robot,
                                            const ModelStageOut& model,
                                            const ExcitationStageOut& excitation,
                                            StudyEstimator& estimator);
// (writes experiment.csv)
EXID_API void record(const StageEnv& env, const ExperimentStageOut& e, StudyRecord& rec);

// Identification: the estimator on the dataset; the parameters against the truth or the nominal
// values.
struct IdentificationStageOut {
  std::optional<Estimate> est;  // none: the study has no estimator
  ExperimentFollowUp experiment;
  IdentificationSummary summary;
  std::optional<Json> prior;  // the study's prior section, resolved
  Json parameters, nonlinear_parameters;
  Eigen::VectorXd truth;  // what the report compares with: the simulation's, or the nominal
  bool simulated = false;
  std::vector<std::string> warnings;
};
EXID_API IdentificationStageOut identificationStage(const StageEnv& env, const RobotStageOut& robot,
                                                    const ModelStageOut& model,
                                                    const ExperimentStageOut& experiment,
                                                    StudyEstimator& estimator);
EXID_API void record(const StageEnv& env, const IdentificationStageOut& i, StudyRecord& rec);

// Validation on held-out data.
struct ValidationStageOut {
  bool ran = false;  // false: the study has no validation
  ValidationSummary summary;
  Json meta;                      // the validation data's
  std::optional<Json> delay;      // a fitted measurement delay's compensation
  std::string torque_prediction;  // how the torque columns' rows were predicted
  std::string rows_processing;
  std::optional<Json> split;          // summary.json split
  std::vector<std::string> warnings;  // the data's
  Json inspection;
  Rows rows;
  Eigen::VectorXd predicted;
};
EXID_API ValidationStageOut validationStage(const StageEnv& env, const RobotStageOut& robot,
                                            const ModelStageOut& model,
                                            const ExperimentStageOut& experiment,
                                            const IdentificationStageOut& identification,
                                            StudyEstimator& estimator);
// (writes validation.csv)
EXID_API void record(const StageEnv& env, const ValidationStageOut& v, StudyRecord& rec);

}  // namespace exid
