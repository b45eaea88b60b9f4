// The embedding facade (exid/exid.hpp): the study and the matrix as `exid run` and `exid matrix`
// run them, with the core's types kept inside.
#include "exid/exid.hpp"

#include <fmt/format.h>

#include <exception>
#include <utility>

#include "exid/config.hpp"
#include "exid/matrix.hpp"
#include "exid/registry.hpp"
#include "exid/runner.hpp"
#include "exid/study_check.hpp"

namespace exid {

namespace {

StudyOutcome failedBeforeRunning(const std::string& message) {
  StudyOutcome o;
  o.status = "failed";
  o.message = message;
  return o;
}

/// Checks the study as `exid run` does (the robot loaded, every plugin made from its
/// parameters, a prior's file read) and runs it.
StudyOutcome runChecked(const StudyConfig& cfg, const std::string& source, const Registry& plugins,
                        const StudySettings& settings) {
  RunOptions opt;
  opt.out_dir = settings.out_dir;
  opt.progress = settings.progress;
  opt.cancelled = settings.cancelled;
  opt.robot = checkStudy(cfg, plugins, source);
  const StudyResult r = runStudy(cfg, plugins, opt);
  StudyOutcome o;
  o.ok = r.ok;
  o.cancelled = r.cancelled;
  o.status = r.headline.status;
  o.message = r.message;
  o.verdict = r.headline.verdict;
  o.verdict_reasons = r.headline.verdict_reasons;
  o.warnings = r.headline.warnings;
  o.summary = r.summary;
  o.written_to = r.written_to;
  return o;
}

}  // namespace

StudyOutcome runStudyFile(const std::filesystem::path& study_yaml, const Registry& plugins,
                          const StudySettings& settings) {
  try {
    const StudyConfig cfg = loadStudy(study_yaml, plugins);
    return runChecked(cfg, study_yaml.string(), plugins, settings);
  } catch (const std::exception& e) {
    return failedBeforeRunning(e.what());
  }
}

StudyOutcome runStudyText(const std::string& study_yaml, const std::string& source_name,
                          const std::filesystem::path& base_dir, const Registry& plugins,
                          const StudySettings& settings) {
  try {
    const StudyConfig cfg = parseStudy(study_yaml, source_name, base_dir, plugins);
    return runChecked(cfg, source_name, plugins, settings);
  } catch (const std::exception& e) {
    return failedBeforeRunning(e.what());
  }
}

MatrixOutcome runMatrixFile(const std::filesystem::path& matrix_yaml, const Registry& plugins,
                            const MatrixSettings& settings) {
  MatrixOutcome o;
  try {
    check(!settings.out_dir.empty(),
          fmt::format("{}: MatrixSettings::out_dir is empty: a matrix writes its results "
                      "database and its cells' folders there",
                      matrix_yaml.string()));
    const MatrixSpec spec = loadMatrix(matrix_yaml, plugins);
    MatrixOptions opt;
    opt.out_dir = settings.out_dir;
    opt.jobs = settings.jobs;
    opt.retry_failed = settings.retry_failed;
    opt.force = settings.force;
    opt.cancelled = settings.cancelled;
    const MatrixRunSummary s = runMatrix(spec, plugins, opt);
    o.ok = true;
    o.cells = s.total;
    o.skipped = s.skipped;
    o.succeeded = s.ok;
    o.failed = s.failed;
    o.timed_out = s.timeout;
    o.not_run = s.not_run;
    o.wall_s = s.wall_s;
    o.database = settings.out_dir / opt.database;
  } catch (const std::exception& e) {
    o.ok = false;
    o.message = e.what();
  }
  return o;
}

ParamSet pluginParams(const PluginInfo& info, const std::string& yaml_params,
                      const std::string& context, const std::filesystem::path& base_dir) {
  return resolveParams(info, yaml_params, context, base_dir);
}

}  // namespace exid
