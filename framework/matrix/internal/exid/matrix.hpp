// exid — comparison matrices: a base study plus axes; the cells are their product (or an
// explicit list). Every cell runs isolated in its own process (an exception, a crash or a
// numerical failure becomes status `failed`, a cell over its budget `timeout`; the others go
// on), N at a time. Results go to a SQLite database (schema in docs/matrix.md), one
// transaction per cell; re-running skips finished cells (keyed by the hash of the resolved
// configuration); a run killed part-way loses only the cells in flight.
//
//   name: ci
//   base: ../default.yaml          # a study file (relative to this file), or `study: {...}` inline
//   cell_budget_s: 60              # wall-clock budget of one cell (0 = none)
//   axes:                          # product of the axes, in this order
//     robot: [{type: puma560}, {type: planar2r}]          # a section replaced whole
//     estimator: [{type: batch_ls}, {type: rls}]
//     experiment.params.noise_tau_Nm: [0.0, 0.05]         # any parameter by key path
//     seed: [1, 2, 3]
//     "@model":                    # a composite axis (named "model"): each value sets several
//       - {label: wrench, model: {type: load_wrench}, experiment.params.wrench: true}
//   cells:                         # or: an explicit list of overrides (instead of axes)
//     - {estimator: {type: rls}, seed: 2}
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "exid/config.hpp"
#include "exid/export.hpp"
#include "exid/json.hpp"

namespace exid {

class Registry;

struct EXID_API MatrixCell {
  int index = 0;
  std::vector<std::pair<std::string, std::string>> coords;  // axis -> short value label
  std::string label;                                        // "robot=puma560 estimator=rls"
  std::string yaml;                                         // the cell's study text
  // Key of the cell's result: the resolved configuration, the contents of every file the study
  // reads (path parameters, a prior's parameters.csv) and the exid version. A cell whose key
  // is in the database is finished (skipped on resume).
  std::string hash;
  std::string config_hash;  // of the resolved configuration alone (StudyConfig::hash)
  StudyConfig config;
};

struct EXID_API MatrixSpec {
  std::string name;
  std::filesystem::path file;
  double cell_budget_s = 0.0;
  // Address space a cell may add to what it inherits from the matrix process (RLIMIT_AS on the
  // cell's process); 0 = no cap. A cell over it fails ("out of memory").
  double cell_memory_mb = 0.0;
  std::vector<std::string> axes;  // axis names in order
  std::vector<MatrixCell> cells;
};

/// Parses a matrix file and validates EVERY cell's study before anything runs (errors name
/// the matrix file, the cell and the study problem).
EXID_API MatrixSpec loadMatrix(const std::filesystem::path& file, const Registry& registry);

struct EXID_API MatrixOptions {
  std::filesystem::path out_dir;
  int jobs = 1;
  int shard_index = 0, shard_count = 1;  // run cells with index % count == index
  bool retry_failed = false;             // re-run cells whose status is failed/timeout
  bool force = false;                    // re-run every cell, finished ones included
  bool write_cell_files = true;          // each cell's study outputs under out/cells/<hash>
  std::function<bool()> cancelled;
  std::string database = "results.sqlite";
};

struct EXID_API MatrixRunSummary {
  int total = 0, skipped = 0, ok = 0, failed = 0, timeout = 0, not_run = 0;
  int incomplete = 0;  // of the failed: stopped by the machine (disk full); run again on resume
  double wall_s = 0.0;
};

EXID_API MatrixRunSummary runMatrix(const MatrixSpec& spec, const Registry& registry,
                                    const MatrixOptions& opt);

/// Markdown table of a metric (mean over the cells that share the row/column keys); also
/// returns the CSV text. Rows/cols are axis names; metric is a metric name (exact, or the
/// last component: "param_rel_err" matches "identification.param_rel_err").
struct EXID_API MatrixTable {
  std::string markdown, csv;
};
EXID_API MatrixTable matrixTable(const std::filesystem::path& db,
                                 const std::vector<std::string>& rows,
                                 const std::vector<std::string>& cols, const std::string& metric);
/// Every metric name in the database.
EXID_API std::vector<std::string> matrixMetrics(const std::filesystem::path& db);
/// Copies the runs of the source databases into dest (created if needed), skipping hashes
/// already present. Returns the number of runs copied.
EXID_API int mergeMatrixDatabases(const std::filesystem::path& dest,
                                  const std::vector<std::filesystem::path>& sources);

}  // namespace exid
