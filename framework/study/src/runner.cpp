// exid — running a study (runner.hpp): the run folder prepared, the stages run in order, each
// stage's output recorded (stages.hpp: summary.json, the typed summary, the report), the results
// published.
#include "exid/runner.hpp"

#include "exid/recording.hpp"
#include "stages.hpp"

namespace exid {

namespace fs = std::filesystem;

namespace {

// The run folder is replaced as a whole when the run is written: an export inside it would be
// lost without a word.
void refuseExportInsideRun(const RunOptions& opt) {
  if (!opt.export_dir.empty()) {
    const fs::path out = fs::weakly_canonical(fs::absolute(opt.out_dir));
    const fs::path exp = fs::weakly_canonical(fs::absolute(opt.export_dir));
    if (std::mismatch(out.begin(), out.end(), exp.begin(), exp.end()).first == out.end())
      throw Error(
          fmt::format("--export {}: inside the output folder {}, which is replaced "
                      "as a whole when the run is written; export to a folder "
                      "outside it",
                      opt.export_dir.string(), opt.out_dir.string()));
  }
  if (!opt.export_dir.empty()) exportFolder(opt.export_dir);  // before any stage runs
}

// summary.json `inputs`: every file the run read through the opener, in path order.
Json inputManifestJson(const InputManifest& m) {
  Json out = Json::array();
  for (const InputRecord& r : m.entries()) {
    Json e = Json::object();
    e["path"] = r.path;
    e["kind"] = r.kind;
    e["size_bytes"] = static_cast<long long>(r.size_bytes);
    e["xxh3_64"] = hashHex(r.xxh3_64);
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace

namespace {
// A study's result before its stages: status "running", the build, the configuration's hash.
StudyResult startedResult(const StudyConfig& cfg) {
  StudyResult res;
  Json& S = res.summary;
  res.headline.study = cfg.name;
  S = Json::object();
  renderInto(res.headline, &S);  // status "running", message, study, warnings
  S["exid_version"] = EXID_VERSION_STRING;
  S["exid_commit"] = gitCommit();
  S["build"] = Registry::fingerprintText();
  S["config_hash"] = cfg.hash();
  S["seed"] = Json(static_cast<long long>(cfg.seed));
  return res;
}
// A stage that threw: the failure in the result and the summary, with what the machine (not the
// study) caused marked: out of space, out of memory, over the study's budget.
void recordFailure(const std::exception& e, const std::string& stage, const RunOptions& opt,
                   const RunContext& ctx, StudyResult* result) {
  StudyResult& res = *result;
  Json& S = res.summary;
  StudySummary& T = res.headline;
  res.ok = false;
  const auto* io = dynamic_cast<const IoError*>(&e);
  const bool nomem = dynamic_cast<const std::bad_alloc*>(&e) != nullptr;
  res.message = fmt::format("stage '{}': {}", stage,
                            nomem ? std::string("out of memory (std::bad_alloc)") : e.what());
  res.cancelled = opt.cancelled && opt.cancelled();
  T.status = res.cancelled ? "cancelled" : "failed";
  T.failed_stage = stage;
  T.message = res.message;
  if (io && io->outOfSpace()) S["out_of_space"] = true;  // the machine's, not the study's
  // (a thread or mapping refused under a memory cap: std::system_error EAGAIN / ENOMEM)
  const auto* se = dynamic_cast<const std::system_error*>(&e);
  if (nomem || (se && (se->code() == std::errc::resource_unavailable_try_again ||
                       se->code() == std::errc::not_enough_memory)))
    S["out_of_memory"] = true;
  if (ctx.deadline.expired()) S["timed_out"] = true;  // over budget_s: a timeout, not a bug
}

// The run folder published: the report (a run that succeeded) and summary.json written into the
// staging folder, which replaces the output folder in one rename, or goes to NAME.failed beside
// an earlier successful run. A failure to write leaves the failure visible where it can and
// nothing half written.
void publishRun(const RunFolder& folder, Report& report, StudyResult* result) {
  StudyResult& res = *result;
  Json& S = res.summary;
  StudySummary& T = res.headline;
  const fs::path& dir = folder.staging;
  // Published where: a failure beside an earlier successful run goes to NAME.failed.
  const bool beside = !res.ok && holdsOkRun(folder.final_dir);
  const fs::path target = beside ? folder.failed_dir : folder.final_dir;
  try {
    if (res.ok) {
      const std::string missing = report.write(T);
      S["report"] = (folder.final_dir / "report.md").string();
      if (!missing.empty()) S["report_missing_plots"] = missing;
    }
    if (beside)
      S["note"] = fmt::format(
          "this run failed; the results of the earlier successful run in {} are untouched",
          folder.final_dir.string());
    writeFileAtomic(dir / "summary.json", S.dump(2) + "\n");
    std::error_code ec;
    if (res.ok || !beside) fs::remove_all(folder.failed_dir, ec);  // superseded
    publish(dir, target);
    res.written_to = target == folder.final_dir ? folder.named : target;
  } catch (const std::exception& e) {
    res.ok = false;
    const auto* io = dynamic_cast<const IoError*>(&e);
    if (io && io->outOfSpace()) S["out_of_space"] = true;
    res.message += (res.message.empty() ? "" : "; ") + std::string("writing results: ") + e.what();
    T.status = "failed";
    T.message = res.message;
    renderInto(T, &S);
    // Whatever was written stays in the staging folder's place only if publishing it
    // worked; the earlier results are never touched. Try to leave the failure visible.
    std::error_code ec;
    try {
      writeFileAtomic(dir / "summary.json", S.dump(2) + "\n");
      const bool besides2 = holdsOkRun(folder.final_dir);
      const fs::path t2 = besides2 ? folder.failed_dir : folder.final_dir;
      if (fs::exists(dir, ec)) {
        if (besides2) fs::remove_all(folder.failed_dir, ec);
        publish(dir, t2);
        res.written_to = t2 == folder.final_dir ? folder.named : t2;
      }
    } catch (const std::exception&) {
      fs::remove_all(dir, ec);  // nothing half written is left behind
    }
  }
}

}  // namespace

StudyResult runStudy(const StudyConfig& cfg, const Registry& reg, const RunOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  StudyResult res = startedResult(cfg);
  Json& S = res.summary;
  StudySummary& T = res.headline;
  const bool write = !opt.out_dir.empty();
  RunFolder folder;
  if (write) {
    try {
      refuseExportInsideRun(opt);
      folder = prepareRunFolder(opt.out_dir, opt.clean_stale);
    } catch (const std::exception& e) {  // nothing written, nothing replaced
      res.ok = false;
      res.message = fmt::format("stage 'setup': {}", e.what());
      T.status = "failed";
      T.failed_stage = "setup";
      T.message = res.message;
      renderInto(T, &S);
      return res;
    }
  }
  const fs::path dir = folder.staging;  // where this run writes ("" = nowhere)
  Report report(cfg, dir);
  std::string stage = "setup";
  std::atomic<const char*> stage_now{"setup"};  // for the watchdog's thread
  auto setStage = [&](const char* name) {
    stage = name;
    stage_now = name;
  };
  Watchdog watchdog(opt, write ? folder : RunFolder{}, cfg, stage_now, t_start);
  StageEnv env(cfg, reg, opt, dir, setStage);
  const RunContext& ctx = env.ctx;
  InputManifest manifest;  // every file the stages read: summary.json `inputs`
  env.manifest = &manifest;
  std::optional<InputManifestScope> inputs;
  inputs.emplace(&manifest);
  StudyRecord rec{&S, &T, &report};
  {
    // (the estimator waits for the inspection beside it before the stages' outputs go)
    std::optional<RobotStageOut> robot;
    std::optional<ModelStageOut> model;
    std::optional<ExcitationStageOut> excitation;
    std::optional<ExperimentStageOut> experiment;
    std::optional<IdentificationStageOut> identification;
    std::optional<ValidationStageOut> validation;
    StudyEstimator estimator(cfg, reg);
    try {
      if (write) {
        writeFileAtomic(dir / "study.resolved.yaml", cfg.resolvedYaml());
      }
      record(env, robot.emplace(robotStage(env)), rec);
      record(env, model.emplace(modelStage(env, *robot)), rec);
      record(env, excitation.emplace(excitationStage(env, *robot, *model)), rec);
      record(env, experiment.emplace(experimentStage(env, *robot, *model, *excitation, estimator)),
             rec);
      record(
          env,
          identification.emplace(identificationStage(env, *robot, *model, *experiment, estimator)),
          rec);
      record(env,
             validation.emplace(
                 validationStage(env, *robot, *model, *experiment, *identification, estimator)),
             rec);
      if (ctx.shouldStop())
        throw Error(fmt::format(
            "stopped: {}", ctx.deadline.expired() ? "study budget_s exhausted" : "interrupted"));
      T.status = "ok";
      renderInto(T, &S);
      judgeResults(S, &T);  // the results' own verdict, from what the stages recorded
      res.ok = true;
    } catch (const std::exception& e) {
      // (a failed identification keeps the data's inspection)
      record(estimator.takeFollowUp(), rec);
      recordFailure(e, stage, opt, ctx, &res);
    }
  }
  inputs.reset();
  S["inputs"] = inputManifestJson(manifest);
  T.wall_s = seconds(t_start);
  renderInto(T, &S);
  const std::lock_guard<std::mutex> finishing(watchdog.finishing());
  watchdog.finished();
  if (write) publishRun(folder, report, &res);
  return res;
}

StudyConfig stageStudy(StudyConfig cfg, const std::string& stage, const Registry& reg,
                       const fs::path& data) {
  const std::string study = cfg.file.empty() ? cfg.name : cfg.file.string();
  if (!data.empty() && stage != "identify")
    throw Error(
        fmt::format("a data file replaces the experiment of stage 'identify' alone (stage "
                    "'{}')",
                    stage));
  if (stage == "excite") {
    if (!cfg.hasExcitation()) throw Error(fmt::format("{}: no excitation section", study));
    cfg.experiment.reset();
    cfg.estimator.reset();
    cfg.validation.reset();
  } else if (stage == "simulate") {
    if (!cfg.experiment) throw Error(fmt::format("{}: no experiment section", study));
    cfg.estimator.reset();
    cfg.validation.reset();
  } else if (stage == "identify") {
    if (!cfg.estimator) throw Error(fmt::format("{}: no estimator section", study));
    cfg.trajectory.reset();
    cfg.criterion.reset();
    cfg.optimizer.reset();
    cfg.validation.reset();
    if (!data.empty()) {
      // A ROS 2 bag (a folder, an MCAP or SQLite storage file: experiment rosbag2, parameter
      // `path`); anything else is a CSV file (experiment csv, parameter `file`).
      const bool bag = isBagPath(data);
      const char* type = bag ? "rosbag2" : "csv";
      std::string esc;
      for (char ch : fs::absolute(data).string())
        esc += ch == '\'' ? std::string("''") : std::string(1, ch);
      PluginSpec spec;
      spec.kind = PluginKind::Experiment;
      spec.type = type;
      spec.key_path = "experiment";
      spec.params = resolveParams(reg.get(PluginKind::Experiment, type),
                                  fmt::format("{{{}: '{}'}}", bag ? "path" : "file", esc),
                                  "experiment.params", fs::current_path());
      cfg.experiment = spec;
    }
    if (!cfg.experiment)
      throw Error(fmt::format("{}: no experiment section and no data file", study));
  } else {
    throw Error(fmt::format("unknown stage '{}'; stages: excite, simulate, identify", stage));
  }
  return cfg;
}

}  // namespace exid
