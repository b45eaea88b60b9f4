// exid — one study, stage by stage (private to the study layer): the StudyRun that runStudy()
// (runner.cpp) drives and the helpers its stages share (run_helpers.cpp). The stages are in
// stages_design.cpp (robot, model, excitation) and stages_data.cpp (experiment, identification,
// validation).
#pragma once

#include <fcntl.h>
#include <fmt/format.h>
#include <stdio.h>
#include <unistd.h>

#include <Eigen/Eigenvalues>
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

#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
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

// exid inspect's checks on a dataset of the study (inspect.hpp): the whole result under
// summary.json `inspection.<what>`, its warnings among the study's. An inspection that cannot be
// done is noted there; it never fails the study.
// The inspection's result for a dataset: the checks, or a note when it could not be done.
Json inspectionOf(const RobotModel& robot, const ObservationModel* model, const Dataset& d,
                  const RunContext& ctx);

// An inspection's result under summary.json `inspection.<what>`, its warnings among the study's.
void applyInspection(Json& S, const std::function<void(const std::string&)>& warn, const char* what,
                     const Json& I);

// exid inspect's checks on a dataset of the study, applied (inspectionOf, applyInspection).
void inspectInto(Json& S, const std::function<void(const std::string&)>& warn, const char* what,
                 const RobotModel& robot, const ObservationModel* model, const Dataset& d,
                 const RunContext& ctx);

// The held-out prediction of rows whose columns hold the recorded torque (stages_data.cpp).
std::string predictTorqueColumns(const Rows& rows, const Estimate& est, Eigen::VectorXd* pred);

// One study, stage by stage: what the stages share (the study, the summary being built, the
// run's context and folder) and what each leaves to the next (robot, model, trajectory, the
// excitation's optimum, the dataset, the estimate). runStudy() sets up the run folder and the
// watchdog, runs the stages in order and publishes the results; a stage that throws ends the
// study with that stage named.
class StudyRun {
 public:
  StudyRun(const StudyConfig& study, const Registry& registry, const RunOptions& options,
           Json& summary, StudySummary& typed, const fs::path& staging, Report& rep,
           std::function<void(const char*)> set_stage)
      : cfg(study),
        reg(registry),
        opt(options),
        S(summary),
        T(typed),
        write(!options.out_dir.empty()),
        dir(staging),
        report(rep),
        setStage(std::move(set_stage)) {
    ctx.study_dir = cfg.dir;
    ctx.out_dir = dir;
    ctx.seed = cfg.seed;
    ctx.deadline = Deadline(cfg.budget_s);
    ctx.cancelled = opt.cancelled;
  }
  // The inspection beside the estimator reads robot, model and data: it is waited for before
  // they go (also when a stage throws); its result stays.
  ~StudyRun() {
    if (experiment_inspection.valid()) experiment_inspection.wait();
  }
  StudyRun(const StudyRun&) = delete;
  StudyRun& operator=(const StudyRun&) = delete;

  void robotStage();
  void modelStage();
  void excitationStage();
  void experimentStage();
  void identificationStage();
  void validationStage();

  /// What a user should know about this run's results (also logged): the report lists them.
  void warn(const std::string& text) {
    logWarn(text);
    T.warnings.push_back(text);
    S["warnings"].push_back(Json(text));
  }
  /// The experiment's inspection, when it ran beside the estimator, into the summary.
  void collectExperimentInspection() {
    if (experiment_inspection.valid())
      applyInspection(S, warnFn(), "experiment", experiment_inspection.get());
  }

  const StudyConfig& cfg;
  const Registry& reg;
  const RunOptions& opt;
  Json& S;          // summary.json: the typed results (T) rendered, and what has no fixed type
  StudySummary& T;  // the typed results
  const bool write;
  const fs::path dir;  // where this run writes ("" = nowhere)
  Report& report;
  std::function<void(const char*)> setStage;
  RunContext ctx;
  /// Every file the run read through the opener (exid/input_file.hpp): summary.json `inputs`.
  InputManifest manifest;

 private:
  std::function<void(const std::string&)> warnFn() {
    return [this](const std::string& text) { warn(text); };
  }
  void completeStreamedPass(const RunContext& ictx);
  void checkEstimateFinite() const;
  Json parametersJson(const Eigen::VectorXd& nominal, const Eigen::VectorXd& truth, bool simulated,
                      double* err2_out, double* tru2_out) const;
  Json nonlinearJson() const;
  void warnIdentificationColumns();
  Rows heldOutRows(const Dataset& vd, const RunContext& vctx, bool by_estimator);
  Json splitJson(const Dataset& vd) const;
  static void errorsPerEquation(const Rows& rows, const Eigen::VectorXd& err,
                                StudySummary::Validation* va);
  void writeValidationCsv(const Rows& rows, const Eigen::VectorXd& pred) const;
  void excitationOutputs(const Samples& initial, const Samples& best, const OptimizerResult& r,
                         const ExcitationOptions& xo, Json& X);
  std::function<void(double, const std::string&)> progressFor(const std::string& st) const {
    const RunOptions* o = &opt;
    return [o, st](double f, const std::string& text) {
      if (o->progress) o->progress(st, f, text);
    };
  }

  std::shared_ptr<const RobotModel> robot;
  std::shared_ptr<ObservationModel> model;
  std::shared_ptr<Trajectory> traj;
  std::optional<Samples> reference;  // the excitation's optimum
  Eigen::VectorXd dmin_;             // its smallest distance per design sample (collision)
  std::optional<Dataset> data;
  std::optional<Estimate> est;
  /// The study's estimator, made once from its parameters (its specs steer the experiment, it
  /// identifies, and it processes the validation rows as it processed its own).
  Estimator& estimator() {
    if (!estimator_) estimator_ = reg.create<Estimator>(cfg.estimator->type, cfg.estimator->params);
    return *estimator_;
  }
  std::shared_ptr<Estimator> estimator_;
  // The experiment's inspection when it runs beside the estimator (a recording in memory).
  std::future<Json> experiment_inspection;
};

}  // namespace exid
