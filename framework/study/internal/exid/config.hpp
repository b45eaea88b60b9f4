// exid — study files. A study is a YAML file whose sections each name a plugin:
//
//   name: puma_demo            # optional
//   seed: 1                    # optional, default 1
//   robot:      {type: puma560, params: {...}}
//   model:      {type: differential, params: {...}}      # or a list, each with `weight`
//   excitation:                                          # optional
//     trajectory: {type: fourier, params: {...}}
//     criterion:  {type: cond}
//     optimizer:  {type: nlopt, params: {...}}
//     constraints: {torque_margin: 0.8}                  # optional: torque limits
//   experiment: {type: simulate, params: {...}}
//   estimator:  {type: batch_ls, params: {...}}
//   validation: {type: simulate, params: {...}}          # optional: a second experiment
//   report:     {type: standard, params: {...}}          # optional
//   prior:      {from: robot, relative_std: 0.3, absolute_std: 1e-3}   # optional, or
//               {from: study, study: path/to/out_dir, scale: 1.0}
//
// The whole file is validated before any work starts; every problem is reported at once, each
// naming the file, the line and the key path, e.g.
//   study.yaml:14: estimator.params.forgetting_factor = 1.2: must be in (0, 1]
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "exid/collision.hpp"
#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/plugin.hpp"

namespace exid {

class Registry;

struct EXID_API PluginSpec {
  PluginKind kind = PluginKind::Robot;
  std::string type;      // plugin name
  ParamSet params;       // resolved: defaults filled in, paths absolute
  std::string key_path;  // "estimator", "model[1]", "excitation.optimizer"
  int line = 0;          // 1-based line of the section in the file (0 = unknown)
  double weight = 1.0;   // for stacked models
};

/// A prior on the base parameters for the estimator (docs/consistent.md):
///   from: robot  -- the robot description's standard values pi0 with independent standard
///                   deviations sqrt((relative_std |pi0_i|)^2 + absolute_std^2), mapped to the
///                   base parameters: theta0 = K pi0, Sigma = K diag(std^2) K^T;
///   from: study  -- another study's identified base parameters (DIR/parameters.csv: value and
///                   std, matched by name), standard deviations multiplied by `scale`.
struct EXID_API PriorSpec {
  std::string from;  // "robot" | "study"
  double relative_std = 0.3;
  double absolute_std = 0.0;
  // from: robot, the drive columns (Ia, Fc, Fv, OFF): a robot file's friction values are rarely
  // known as well as its masses; unset = relative_std / absolute_std.
  std::optional<double> drive_relative_std, drive_absolute_std;
  std::filesystem::path study;  // from: study (absolute)
  double scale = 1.0;
  int line = 0;
};

/// `split:` one recording, two parts: the experiment identifies on the part before the split
/// point and a copy of it (with `validation` parameters laid over) validates on the rest.
struct EXID_API SplitSpec {
  double identification_fraction = 0.0;           // of the experiment's segment; 0: at_s
  double at_s = 0.0;                              // seconds after the segment's start; 0: fraction
  std::vector<std::string> validation_overrides;  // parameter names laid over the copy
  int line = 0;
};

struct EXID_API ReportOptions {
  bool plots = true;
  std::string title;
  /// experiment.csv: "auto" (simulated data always; recorded data, a copy of the input, only up
  /// to kExperimentCsvAutoSamples samples), "always", "never".
  std::string experiment_csv = "auto";
};
inline constexpr long kExperimentCsvAutoSamples = 100000;

struct EXID_API StudyConfig {
  std::filesystem::path file;  // the study file ("" when parsed from text)
  std::filesystem::path dir;   // relative paths resolve here
  std::string name;
  std::uint64_t seed = 1;
  double budget_s = 0.0;  // whole-study wall-clock budget (0 = none)
  std::optional<PluginSpec> robot;
  std::vector<PluginSpec> models;
  /// base_columns: full parameters the model keeps as base columns, in this order before the
  /// others (BaseParameterOptions::preferred; docs/base_parameters.md); empty: the natural order.
  std::vector<std::string> base_columns;
  /// base_columns: pivoted (BaseParameterOptions::Rule::Pivoted): QR with column pivoting on the
  /// unit-norm columns instead of the natural order; base_columns is then empty.
  bool base_columns_pivoted = false;
  std::optional<PluginSpec> trajectory, criterion, optimizer;  // excitation (all or none)
  /// excitation.constraints (excitationConstraintParams(); every key has its default when the
  /// section is absent).
  ParamSet excitation_constraints;
  /// excitation.information (excitationInformationParams()): what is already known, added to the
  /// new trajectory's information (docs/excitation.md §11); every key has its default when the
  /// section is absent.
  ParamSet excitation_information;
  /// The section says something (an earlier study or a prior).
  bool hasExcitationInformation() const;
  /// excitation.collision (docs/excitation.md §12): collision avoidance, null when absent;
  /// obstacles' relative mesh files resolve in `dir`.
  std::shared_ptr<const CollisionOptions> excitation_collision;
  /// The same section as JSON (normalised: every key), for the resolved study and its hash.
  Json excitation_collision_json;
  std::optional<PluginSpec> experiment, estimator, validation;
  ReportOptions report;
  std::optional<PriorSpec> prior;
  std::optional<SplitSpec> split;  // (already expanded into experiment + validation)

  bool hasExcitation() const { return optimizer.has_value(); }
  /// The resolved study as YAML text (every default filled in), and as JSON.
  std::string resolvedYaml() const;
  Json resolvedJson() const;
  /// Hash (16 hex digits, FNV-1a 64) of the resolved study: identifies a configuration.
  std::string hash() const;
};

/// The keys of `excitation.constraints`: torque_margin (fraction of the torque limits the
/// predicted torques may reach; 0: no torque limits) and torque_max_Nm (the limits, when the
/// robot description has none).
EXID_API std::vector<ParamDecl> excitationConstraintParams();

/// The keys of `excitation.information`: earlier_study (a run folder whose identification's
/// covariance.csv is added), prior_relative_std / prior_absolute_std (the robot description's
/// values with that uncertainty), noise_std and recording_rate_hz (the new experiment's noise
/// and rate, which weigh its information against what is known).
EXID_API std::vector<ParamDecl> excitationInformationParams();

/// Why a study (or matrix) name cannot be used, "" when it can. The name becomes a folder
/// (out/<name>, a matrix's cells): a plain file name, so that no output can leave the output
/// root (no '/', '\\', control bytes, leading '.').
EXID_API std::string studyNameProblem(const std::string& name);

/// The files a study reads (path parameters of every section, a prior's parameters.csv), in a
/// fixed order; the matrix keys its cells by their contents.
EXID_API std::vector<std::filesystem::path> studyInputFiles(const StudyConfig& cfg,
                                                            const Registry& reg);

/// Parses and validates. Throws exid::Error with every problem found, one per line.
EXID_API StudyConfig loadStudy(const std::filesystem::path& file, const Registry& registry);
EXID_API StudyConfig parseStudy(const std::string& yaml_text, const std::string& source_name,
                                const std::filesystem::path& base_dir, const Registry& registry);

/// Resolves a params mapping given as YAML text for one plugin (used by single-stage commands
/// and matrices): "{max_iterations: 10}" -> ParamSet with defaults. Throws like parseStudy.
EXID_API ParamSet resolveParams(const PluginInfo& info, const std::string& yaml_params,
                                const std::string& context, const std::filesystem::path& base_dir);

}  // namespace exid
