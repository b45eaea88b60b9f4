// exid — the embedding facade: a program runs a study or a matrix described in YAML, as
// `exid run` and `exid matrix` do, through this header alone (with exid/registry.hpp for the
// plugins and exid/json.hpp for the summary). The study's and the matrix's own types (the parsed
// configuration, the runner, the cells) are the core's and are not installed.
//
//   exid::Registry plugins;
//   plugins.scan();                                  // the installed plugins
//   exid::StudySettings s;
//   s.out_dir = "out";
//   const exid::StudyOutcome r = exid::runStudyFile("study.yaml", plugins, s);
//   if (!r.ok) std::cerr << r.message << "\n";       // the failing stage and why
//   else if (r.verdict != "ok") ...                  // the results judge themselves
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/plugin.hpp"

namespace exid {

class Registry;

/// How a study runs; every field has `exid run`'s default.
struct EXID_API StudySettings {
  std::filesystem::path out_dir;  ///< the run folder; "" writes nothing
  /// stage ("excitation", "identification", ...), fraction done in [0, 1], a line of text
  std::function<void(const std::string& stage, double fraction, const std::string& text)> progress;
  std::function<bool()> cancelled;  ///< polled between steps: true stops the study
};

/// What a study gave. A study that fails does not throw: ok is false and message says which
/// stage failed and why (a file that cannot be read, an unknown plugin, a singular problem).
struct EXID_API StudyOutcome {
  bool ok = false;         ///< status "ok": every configured stage finished
  bool cancelled = false;  ///< stopped by StudySettings::cancelled
  std::string status;      ///< summary.json's status: ok, failed or cancelled
  std::string message;     ///< why it failed ("" when ok)
  /// the results' own verdict (status ok only): "ok", or "suspect" with verdict_reasons
  std::string verdict;
  std::vector<std::string> verdict_reasons;
  std::vector<std::string> warnings;  ///< what a user should know about the results
  Json summary;                       ///< summary.json's tree
  std::filesystem::path written_to;   ///< the run folder ("" when nothing was written)
};

/// Loads the study file (errors name the file and the key), checks it and runs it.
EXID_API StudyOutcome runStudyFile(const std::filesystem::path& study_yaml, const Registry& plugins,
                                   const StudySettings& settings = {});
/// The same for a study given as YAML text; relative paths in it are taken from base_dir.
EXID_API StudyOutcome runStudyText(const std::string& study_yaml, const std::string& source_name,
                                   const std::filesystem::path& base_dir, const Registry& plugins,
                                   const StudySettings& settings = {});

/// How a matrix runs; every field has `exid matrix`'s default.
struct EXID_API MatrixSettings {
  std::filesystem::path out_dir;  ///< required: the results database and the cells' folders
  int jobs = 1;                   ///< cells run at once (each in a process of its own)
  bool retry_failed = false;      ///< run again the cells that failed or timed out before
  bool force = false;             ///< run every cell again, finished ones included
  std::function<bool()> cancelled;
};

/// What a matrix gave: the count of its cells by outcome. A cell that fails never loses the
/// others; ok is false when the matrix file itself cannot be used (message says why).
struct EXID_API MatrixOutcome {
  bool ok = false;
  std::string message;
  int cells = 0;    ///< in the matrix
  int skipped = 0;  ///< finished before (their results were in the database)
  int succeeded = 0, failed = 0, timed_out = 0, not_run = 0;
  double wall_s = 0.0;
  std::filesystem::path database;  ///< the results database
};

/// Loads the matrix file, checks every cell's study before anything runs, and runs the cells.
EXID_API MatrixOutcome runMatrixFile(const std::filesystem::path& matrix_yaml,
                                     const Registry& plugins, const MatrixSettings& settings);

/// A plugin's parameters from a YAML mapping given as text ("{max_iterations: 10}"), resolved
/// as a study resolves them: defaults filled in, types, ranges and choices checked, paths taken
/// from base_dir. Throws exid::Error naming context, the key and what was expected.
EXID_API ParamSet pluginParams(const PluginInfo& info, const std::string& yaml_params,
                               const std::string& context, const std::filesystem::path& base_dir);

}  // namespace exid
