// exid — a study's experiment and identification stages and their records (stages.hpp).
#include "stages.hpp"

namespace exid {

namespace {

// experiment.csv: simulated data always; recorded data are a copy of the input, written (by
// default) only while small. Why not, when not ("" when it is).
std::string experimentCsvNotWritten(const StudyConfig& cfg, const Dataset& data, bool* write_csv) {
  const bool simulated_data = data.facts.simulated.has_value();
  const std::string& policy = cfg.report.experiment_csv;
  *write_csv = policy == "always" ||
               (policy == "auto" && (simulated_data || data.size() <= kExperimentCsvAutoSamples));
  if (*write_csv) return "";
  return policy == "never" ? std::string("report.params.experiment_csv: never")
                           : fmt::format(
                                 "recorded data of {} samples (more than {}): a copy of the input; "
                                 "report.params.experiment_csv: always writes it",
                                 data.size(), kExperimentCsvAutoSamples);
}

// experiment.csv, the joints named in a first comment line (readers skip it; exid's csv
// experiment too), written a row at a time: the text is never held whole.
void writeExperimentCsv(const StageEnv& env, const RobotModel& robot, const Dataset& data) {
  std::string joints;
  for (int j = 0; j < robot.dof(); ++j) {
    const std::string& jn =
        robot.hasTransmission()
            ? std::string()
            : robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name;
    joints += fmt::format("{}{} = {}", j ? ", " : "", j + 1,
                          jn.empty() ? fmt::format("measured coordinate {}", j + 1) : jn);
  }
  AtomicFileWriter out(env.dir / "experiment.csv");
  out.write(
      fmt::format("# exid experiment of study '{}', robot '{}': joints {}; SI units, t in s\n",
                  env.cfg.name, robot.name, joints));
  const Dataset whole = data.streamed() ? materialize(data) : Dataset();
  writeCsv(out, datasetTable(data.streamed() ? whole : data));
  out.commit();
}

}  // namespace

ExperimentStageOut experimentStage(const StageEnv& env, const RobotStageOut& robot_out,
                                   const ModelStageOut& model_out,
                                   const ExcitationStageOut& excitation,
                                   StudyEstimator& estimator) {
  const StudyConfig& cfg = env.cfg;
  ExperimentStageOut out;
  if (!cfg.experiment) return out;
  env.enter("experiment");
  const auto t0 = std::chrono::steady_clock::now();
  const std::shared_ptr<const RobotModel>& robot = robot_out.robot;
  const std::shared_ptr<ObservationModel>& model = model_out.model;
  auto exp = env.reg.create<Experiment>(cfg.experiment->type, cfg.experiment->params);
  RunContext ectx = env.ctx;
  ectx.progress = env.progressFor("experiment");
  const EstimatorSpecs especs = cfg.estimator ? estimator.get().specs() : EstimatorSpecs();
  // Streamed (read in chunks, never held whole) when the estimator streams and nothing else
  // needs the whole dataset (experiment.csv: always).
  const bool may_stream = cfg.estimator && especs.streams && cfg.report.experiment_csv != "always";
  const Samples* reference = excitation.ran ? &excitation.best : nullptr;
  auto data = std::make_shared<Dataset>(may_stream ? exp->stream(robot, reference, ectx)
                                                   : exp->run(robot, reference, ectx));
  // A streamed recording that experiment.csv will copy (the `auto` policy: up to
  // kExperimentCsvAutoSamples samples) is read whole once, here: the copy and the estimator
  // then share one pass, and the inspection runs beside the estimator. Streaming pays only
  // when nothing needs the whole recording.
  if (data->streamed() && env.write() && cfg.report.experiment_csv == "auto" &&
      data->size() <= kExperimentCsvAutoSamples)
    *data = materialize(*data);
  checkDataset(*data, *robot, model.get(), "experiment", especs.needs_raw_dataset);
  checkDatasetFinite(*data, "experiment");
  ExperimentSummary& ex = out.summary;
  ex.type = cfg.experiment->type;
  ex.samples = data->size();
  ex.duration_s = data->tLast() - data->tFirst();
  ex.wall_s = seconds(t0);
  if (data->streamed()) {
    out.streamed = fmt::format(
        "read from the file in chunks by the estimator '{}' (never held whole); the "
        "recording's statistics and the inspection are from its first pass",
        cfg.estimator->type);
    data->stream->collectEvery(static_cast<int>(streamInspectStride(data->size())));
  }
  out.warnings = experimentWarnings(*data, "experiment");
  out.data = data;
  out.robot = robot;
  if (!data->streamed()) {
    if (cfg.estimator) {
      // The inspection runs beside the estimator (both only read the dataset and the model) and
      // is recorded when the estimator is done, at the same place in the summary and among the
      // warnings as if it had run here.
      InputManifest* manifest = env.manifest;
      estimator.inspectBeside([robot, model, data, ectx, manifest] {
        std::optional<InputManifestScope> inputs;  // a file it reads is the run's input
        if (manifest) inputs.emplace(manifest);
        return inspectionOf(*robot, model.get(), *data, ectx);
      });
    } else {
      out.inspection = inspectionOf(*robot, model.get(), *data, ectx);
    }
  }
  out.csv_not_written = experimentCsvNotWritten(cfg, *data, &out.write_csv);
  return out;
}

void record(const StageEnv& env, const ExperimentStageOut& e, StudyRecord& rec) {
  if (!e.data) return;
  rec.typed->experiment = e.summary;
  Json& E = (*rec.summary)["experiment"];
  renderInto(e.summary, &E);
  E["meta"] = e.data->meta;
  describeFacts(e.data->facts, &E["meta"]);
  if (!e.streamed.empty()) E["streamed"] = e.streamed;
  for (const std::string& w : e.warnings) rec.warn(w);
  if (e.inspection) applyInspection(rec, "experiment", *e.inspection);
  // experiment.csv: what was written, or why not, is in the summary.
  if (env.write() && !e.write_csv) E["csv_not_written"] = e.csv_not_written;
  if (env.write() && e.write_csv) {
    writeExperimentCsv(env, *e.robot, *e.data);
    E["csv"] = "experiment.csv";
  }
}

namespace {

// A streamed recording: its statistics (and the samples kept for the inspection) are complete
// after a whole pass (the estimator's, or one more here), then inspected.
void completeStreamedPass(const RobotModel& robot, const ObservationModel* model,
                          const Dataset& data, const RunContext& ictx, ExperimentFollowUp* f) {
  if (!data.stream->passed()) {
    Dataset chunk;
    data.stream->rewind();
    while (data.stream->read(8192, &chunk) > 0) {
    }
  }
  Dataset passed = data;  // (streamed: the samples stay in the file)
  passed.meta = data.stream->meta();
  f->meta = passed.meta;
  describeFacts(data.facts, &*f->meta);
  f->inspection = inspectionOf(robot, model, passed, ictx);
}

// Every value of the estimate finite, else an error naming the estimator and the parameter.
void checkEstimateFinite(const StudyConfig& cfg, const Estimate& est) {
  checkFinite(est.value, fmt::format("estimator '{}': the estimate of", cfg.estimator->type),
              est.names);
  if (est.std.size() > 0)
    checkFinite(est.std,
                fmt::format("estimator '{}': the standard deviation of", cfg.estimator->type),
                est.names);
  check(std::isfinite(est.residual_rms),
        fmt::format("estimator '{}': the residual RMS is {} (a non-finite result is an "
                    "error, never a result)",
                    cfg.estimator->type, est.residual_rms));
}

// The base parameters' table of summary.json (value, std, nominal, the truth of a simulation);
// *err2 and *tru2 receive the squared error against the truth and the truth's squared norm.
Json parametersJson(const Estimate& est, const Eigen::VectorXd& nominal,
                    const Eigen::VectorXd& truth, bool simulated, double* err2_out,
                    double* tru2_out) {
  Json params = Json::array();
  double err2 = 0, tru2 = 0;
  for (Eigen::Index i = 0; i < est.value.size(); ++i) {
    Json p = Json::object();
    p["name"] = est.names[static_cast<std::size_t>(i)];
    p["expression"] = est.expressions[static_cast<std::size_t>(i)];
    p["value"] = est.value(i);
    p["std"] = est.std.size() > i ? est.std(i) : NAN;
    p["rel_std_percent"] =
        est.std.size() > i && est.value(i) != 0 ? 100.0 * est.std(i) / std::abs(est.value(i)) : NAN;
    p["nominal"] = nominal(i);
    if (simulated) p["true"] = truth(i);
    err2 += (est.value(i) - truth(i)) * (est.value(i) - truth(i));
    tru2 += truth(i) * truth(i);
    params.push_back(p);
  }
  *err2_out = err2;
  *tru2_out = tru2;
  return params;
}

// The fitted nonlinear parameters (varpro, didim): value, std, unit and initial value.
Json nonlinearJson(const Estimate& est, const ObservationModel& model) {
  Json nl = Json::array();
  const std::vector<NonlinearParameter> decl = model.nonlinearParameters();
  for (Eigen::Index k = 0; k < est.nonlinear.size(); ++k) {
    Json p = Json::object();
    const auto u = static_cast<std::size_t>(k);
    p["name"] = u < est.nonlinear_names.size() ? est.nonlinear_names[u] : std::string();
    p["value"] = est.nonlinear(k);
    p["std"] = est.nonlinear_std.size() > k ? est.nonlinear_std(k) : NAN;
    // the model's by name; else the estimator's own (a delay)
    const std::string name = p["name"].asString();
    const auto it = std::find_if(decl.begin(), decl.end(),
                                 [&](const NonlinearParameter& d) { return d.name == name; });
    if (it != decl.end()) {
      p["unit"] = it->unit;
      p["initial"] = it->value;
    } else if (const Json* en = est.details.find("nonlinear_parameters");
               en && en->isArray() && u < en->size()) {
      if (const Json* v = en->at(u).find("unit")) p["unit"] = *v;
      if (const Json* v = en->at(u).find("initial")) p["initial"] = *v;
    } else if (name == "measurement_delay_s") {
      p["unit"] = "s";
    }
    nl.push_back(p);
  }
  return nl;
}

// What the estimate's columns say of it: the model's nonlinear parameters the estimator kept at
// the study's values, and drive-gain or load columns that hold the recorded torque.
std::vector<std::string> identificationColumnWarnings(const StudyConfig& cfg, const Estimate& est,
                                                      const ObservationModel& model) {
  std::vector<std::string> out;
  // the model's nonlinear parameters the estimator did not fit (matched by name)
  {
    std::string names;
    for (const auto& p : model.nonlinearParameters())
      if (std::find(est.nonlinear_names.begin(), est.nonlinear_names.end(), p.name) ==
          est.nonlinear_names.end())
        names += (names.empty() ? "" : ", ") + fmt::format("{} = {:g} {}", p.name, p.value, p.unit);
    if (!names.empty())
      out.push_back(fmt::format(
          "identification: estimator '{}' kept the model's nonlinear parameters at the study's "
          "values ({}); the `varpro` and `didim` estimators fit them",
          cfg.estimator->type, names));
  }
  // Drive gains' columns hold the recorded torque: an estimator other than gains_ls (the
  // torque in the measurement only), iv (a simulated instrument) or didim (the simulated
  // command) has errors in variables there (docs/estimators.md, "gains_ls").
  if (const std::string& et = cfg.estimator->type;
      et != "gains_ls" && et != "iv" && et != "didim") {
    std::string gains, loads;
    for (const std::string& n : est.names) {
      if (torqueColumnKind(n) == 1) gains += (gains.empty() ? "" : ", ") + n;
      if (torqueColumnKind(n) == 2) loads += (loads.empty() ? "" : ", ") + n;
    }
    if (!loads.empty())
      out.push_back(fmt::format(
          "identification: the load-dependent Coulomb columns ({}) hold the recorded torque: "
          "estimator '{}' has errors in variables there, a bias of many standard deviations on "
          "long recordings; gains_ls fits them with the torque in the measurement only",
          loads, cfg.estimator->type));
    if (!gains.empty())
      out.push_back(fmt::format(
          "identification: the drive gains' columns ({}) hold the recorded torque: estimator "
          "'{}' has errors in variables there, which biases the gains towards the recorded "
          "scale (many standard deviations at 1 % torque noise); gains_ls fits them with the "
          "torque in the measurement only",
          gains, cfg.estimator->type));
  }
  return out;
}

}  // namespace

IdentificationStageOut identificationStage(const StageEnv& env, const RobotStageOut& robot,
                                           const ModelStageOut& model_out,
                                           const ExperimentStageOut& experiment,
                                           StudyEstimator& estimator) {
  const StudyConfig& cfg = env.cfg;
  IdentificationStageOut out;
  if (!cfg.estimator) return out;
  env.enter("identification");
  const auto t0 = std::chrono::steady_clock::now();
  const ObservationModel& model = *model_out.model;
  const Dataset& data = *experiment.data;
  Estimator& identifier = estimator.get();
  RunContext ictx = env.ctx;
  ictx.progress = env.progressFor("identification");
  std::optional<Prior> prior;
  if (cfg.prior) {
    check(identifier.specs().accepts_prior,
          fmt::format("prior: the estimator '{}' does not take a prior (batch_ls, wls, "
                      "consistent_ls and rls do)",
                      cfg.estimator->type));
    prior = buildPrior(*cfg.prior, model);
  }
  const Estimate& est =
      out.est.emplace(identifier.estimate(model, data, prior ? &*prior : nullptr, ictx));
  // (the experiment's record completed: kept by the estimator until this stage's record takes
  // it, or the failure's)
  ExperimentFollowUp& follow_up = estimator.followUp();
  if (data.streamed())
    completeStreamedPass(*robot.robot, model_out.model.get(), data, ictx, &follow_up);
  checkEstimateFinite(cfg, est);
  IdentificationSummary& id = out.summary;
  id.estimator = cfg.estimator->type;
  id.wall_s = seconds(t0);
  id.rows = static_cast<long long>(est.rows);
  id.cond_W = est.cond_W;
  id.residual_rms = est.residual_rms;
  id.sigma = est.sigma;
  if (cfg.prior) out.prior = cfg.resolvedJson()["prior"];
  out.simulated = data.facts.simulated.has_value();
  const Eigen::VectorXd nominal = model.baseNominal();
  // A simulated study is judged against what the simulation used (its payload), never
  // against a nominal value it did not use.
  out.truth = out.simulated
                  ? Eigen::VectorXd(model.base().reduce(model.fullTruth(*data.facts.simulated)))
                  : nominal;
  double err2 = 0, tru2 = 0;
  out.parameters = parametersJson(est, nominal, out.truth, out.simulated, &err2, &tru2);
  if (out.simulated) {
    id.param_abs_err = std::sqrt(err2);
    if (tru2 > 0)
      id.param_rel_err = std::sqrt(err2 / tru2);
    else
      out.warnings.push_back(
          "identification: every true parameter is zero (the simulation used none of the "
          "model's parameters, e.g. no payload): param_rel_err is undefined; "
          "param_abs_err is given");
  }
  if (est.nonlinear.size() > 0)  // fitted with the linear ones (varpro)
    out.nonlinear_parameters = nonlinearJson(est, model);
  for (std::string& w : identificationColumnWarnings(cfg, est, model))
    out.warnings.push_back(std::move(w));
  if (const Json* w = est.details.find("warnings"); w && w->isArray())
    for (std::size_t i = 0; i < w->size(); ++i)
      out.warnings.push_back("identification: " + w->at(i).asString());
  out.experiment = estimator.takeFollowUp();
  return out;
}

void record(const StageEnv&, const IdentificationStageOut& i, StudyRecord& rec) {
  if (!i.est) return;
  record(i.experiment, rec);
  rec.typed->identification = i.summary;
  Json& I = (*rec.summary)["identification"];
  I["estimator"] = i.summary.estimator;
  if (i.prior) I["prior"] = *i.prior;
  for (const std::string& w : i.warnings) rec.warn(w);
  renderInto(i.summary, &I);
  I["parameters"] = i.parameters;
  if (i.est->nonlinear.size() > 0) I["nonlinear_parameters"] = i.nonlinear_parameters;
  I["details"] = i.est->details;
  if (rec.report) rec.report->identification(*i.est, i.truth, i.simulated);
}

}  // namespace exid
