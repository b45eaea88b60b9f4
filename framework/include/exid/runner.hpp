// exid — running a study: robot -> model -> excitation -> experiment -> estimator ->
// validation -> report. Every stage is optional except the robot. Files are written atomically;
// a failure stops the study, is recorded in summary.json (status "failed", message) and keeps
// what finished stages wrote.
#pragma once

#include <filesystem>
#include <functional>
#include <string>

#include "exid/config.hpp"
#include "exid/data.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"

namespace exid {

class Registry;
class ObservationModel;
struct Prior;

struct RunOptions {
  std::filesystem::path out_dir;  // "" = write nothing
  std::function<void(const std::string& stage, double fraction, const std::string& text)> progress;
  std::function<bool()> cancelled;
};

struct StudyResult {
  bool ok = false;
  std::string message;
  Json summary;
};

/// Never throws for failures inside the study: they come back as ok = false.
StudyResult runStudy(const StudyConfig& cfg, const Registry& registry, const RunOptions& options);

/// The prior a study asks for (StudyConfig::prior) on the model's (bound) base parameters.
/// Throws exid::Error when it cannot be built (missing file or names, zero variances).
Prior buildPrior(const PriorSpec& spec, const ObservationModel& model);

/// Dataset <-> CSV table (DESIGN.md §3 column names).
CsvTable datasetTable(const Dataset& d);
CsvTable samplesTable(const Samples& s);

/// The Markdown table printed at the end of `exid run`.
std::string briefTable(const Json& summary);

}  // namespace exid
