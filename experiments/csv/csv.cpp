// exid — experiment `csv`: a recorded (or previously written) dataset read from a CSV file with
// the columns of docs/conventions.md §1: t, q1..qn, qd1..qdn, qdd1..qddn, tau1..taun, fx..mz.
// q is required; every other group is optional but complete when present (all n joints, or all
// six wrench components). Absent qd/qdd stay absent: estimators decide how to differentiate.
// The file written by the runner (experiment.csv, exid::datasetTable) reads back exactly.
// Extensions for recordings as published (docs/experiments.md): other column names
// (q_columns, tau_columns), torques from a second row-aligned file (torque_file), and optional
// zero-phase low-pass + central differences (+ decimation) of the segment.
// Here: the plugin (parameters, the payload part). The recording's pipeline: columns -> signals
// -> segment/split is CsvStream (csv_stream.hpp; csv_columns.cpp, csv_scan.cpp, csv_stream.cpp)
// with the recording statistics RecordingStats (recording_stats.hpp); the filter steps
// (resampling, a known delay, the differentiating filter, trim, decimation) are the data layer's
// RecordingPipeline (exid/recording.hpp), shared with the rosbag2 experiment.
#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "csv_stream.hpp"
#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/recording.hpp"
#include "exid/segment.hpp"
#include "exid/signal.hpp"

namespace {

using exid::csv_experiment::CsvStream;

class CsvExperiment : public exid::Experiment {
 public:
  static constexpr const char* kName = "csv";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "recorded data from a CSV file with columns t, q1..qn, qd.., qdd.., tau.. (or motor "
      "currents), fx..mz; optional segment, joint signs and offsets, bad-row dropping";

  static std::vector<exid::ParamDecl> params() {
    using namespace exid;
    std::vector<ParamDecl> p = {
        param_path("file", std::nullopt, "the CSV file (relative paths: to the study file)"),
        param_bool("drop_bad_rows", false,
                   "drop rows with missing or non-finite values in the columns used (counted in "
                   "meta); false: such a row is an error naming its line and column"),
        param_double("sample_period_s", 0.0, "s",
                     "sampling period of a file without a time column (t = row * period); 0: "
                     "not given (a file without a time column is then an error: exid does not "
                     "guess a rate)",
                     0.0),
        param_string("time_column", std::string("t"),
                     "name of the time column; absent from the file: sample_period_s is needed"),
        param_string("time_unit", std::string("s"), "unit of the time column",
                     {"s", "ms", "us", "ns"}),
        param_double("max_gap_ratio", 1.5, "",
                     "a time step longer than this times the median step (a gap), or shorter "
                     "than its inverse (uneven stamps), is an error naming the rows",
                     1.0, std::nullopt, true),
        param_string("current_prefix", std::string("i"), "prefix of the motor current columns"),
        param_strings("q_columns", std::vector<std::string>{},
                      "names of the n position columns (in file), instead of q1..qn"),
        param_path("torque_file", std::string(),
                   "a second CSV holding the torque (or current) columns, row-aligned with file "
                   "(same number of data rows); empty: file"),
        param_path("payload_file", std::string(),
                   "a second recording of the same robot carrying a known payload (the drive "
                   "gains' reference, model differential's drive_gains), read with the same "
                   "parameters and appended after the first (its times moved to follow them; "
                   "meta.payload_part); empty: none"),
        param_path("payload_torque_file", std::string(),
                   "the payload part's torque_file (needed when torque_file is given)"),
        param_strings("tau_columns", std::vector<std::string>{},
                      "names of the n torque columns (or currents with torque_from: current), "
                      "instead of tau1..taun / <current_prefix>1..n"),
        param_int("threads", 0,
                  "threads for the scan of the time stamps before the first pass (the file in "
                  "pieces read at once; the result does not depend on the count); 0: the cores "
                  "this process may run on, at most 8",
                  0, 256),
    };
    const auto conv = signalConversionParams("the torque columns");  // exid/recording.hpp
    p.insert(p.end(), conv.begin(), conv.end());
    const auto segment = segmentParams("sample");
    p.insert(p.end(), segment.begin(), segment.end());
    const auto steps = recordingStepParams();  // the filter steps (exid/recording.hpp)
    p.insert(p.end(), steps.begin(), steps.end());
    return p;
  }

  explicit CsvExperiment(const exid::ParamSet& p) : P_(p) {}

  exid::Dataset run(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples*,
                    const exid::RunContext& ctx) override {
    const std::string pfile = P_.getString("payload_file"),
                      ptfile = P_.getString("payload_torque_file");
    exid::check(!pfile.empty() || ptfile.empty(),
                "experiment 'csv': payload_torque_file is given without payload_file");
    exid::check(pfile.empty() || P_.getString("torque_file").empty() || !ptfile.empty(),
                "experiment 'csv': the torques come from torque_file: the payload part needs "
                "its own, payload_torque_file");
    exid::Dataset d = runPart(P_, robot, ctx);
    if (pfile.empty()) return d;
    exid::ParamSet P2 = P_;
    P2.set("file", pfile);
    P2.set("torque_file", ptfile);
    return appendPayloadPart(std::move(d), runPart(P2, robot, ctx));
  }

  /// The recording with a known payload (payload_file) after the first: its time stamps moved
  /// to follow the first part's by one median step (the signals are not joined: each part was
  /// filtered alone), meta.payload_part describes it and facts.payload_part_from_t_s marks its
  /// first sample for the models (differential's drive_gains).
  static exid::Dataset appendPayloadPart(exid::Dataset a, const exid::Dataset& b) {
    const int Ka = a.size(), Kb = b.size();
    exid::check(Ka >= 3 && Kb >= 2,
                fmt::format("experiment 'csv': {} samples without and {} with the payload (at "
                            "least 3 and 2)",
                            Ka, Kb));
    double jitter = 0.0;
    const double dt = 1.0 / exid::samplingRate(a.t, &jitter);  // the median step
    const double offset = a.t[Ka - 1] + dt - b.t[0];
    Eigen::VectorXd t(Ka + Kb);
    t << a.t, b.t.array() + offset;
    a.t.swap(t);
    auto stack = [&](Eigen::MatrixXd* x, const Eigen::MatrixXd& y, const char* what) {
      exid::check(x->cols() == y.cols(),
                  fmt::format("experiment 'csv': the payload part has {} {} columns, the first "
                              "part {}",
                              y.cols(), what, x->cols()));
      if (x->cols() == 0) return;
      Eigen::MatrixXd s(Ka + Kb, x->cols());
      s << *x, y;
      x->swap(s);
    };
    stack(&a.q, b.q, "q");
    stack(&a.qd, b.qd, "qd");
    stack(&a.qdd, b.qdd, "qdd");
    stack(&a.tau, b.tau, "torque");
    stack(&a.wrench, b.wrench, "wrench");
    stack(&a.base, b.base, "base motion");
    stack(&a.contact, b.contact, "contact wrench");
    exid::Json part = exid::Json::object();
    part["source"] = b.source;
    part["samples"] = Kb;
    part["from_t_s"] = a.t[Ka];
    part["time_offset_s"] = offset;
    part["meta"] = b.meta;
    a.meta["payload_part"] = part;
    a.facts.payload_part_from_t_s = a.t[Ka];
    a.source += " + " + b.source;
    return a;
  }

  exid::Dataset runPart(const exid::ParamSet& P, std::shared_ptr<const exid::RobotModel> robot,
                        const exid::RunContext& ctx) const {
    auto src = CsvStream::open(P, robot, ctx);
    exid::Dataset d;
    d.stream = src;
    d.source = src->file();
    d = exid::materialize(d);  // one pass: the recording's statistics are complete
    // The filter steps: resampling, a known delay, the differentiating filter (recording.hpp).
    exid::RecordingPipeline steps(exid::RecordingSteps::fromParams(P_),
                                  "experiment 'csv': " + src->file());
    d = steps.run(std::move(d));
    d.meta = src->metaAfter(steps);
    ctx.report(1.0, fmt::format("{} samples from {}", d.size(), src->file()));
    return d;
  }

  /// The recording streamed from its file (one scan of its time stamps now; the samples are
  /// read in chunks by whoever consumes them, in one or more passes). The filter steps and a
  /// payload part need the whole segment at once: then the dataset is in memory.
  exid::Dataset stream(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples* ref,
                       const exid::RunContext& ctx) override {
    const exid::RecordingSteps steps = exid::RecordingSteps::fromParams(P_);
    if (steps.needWholeSegment() || !P_.getString("payload_file").empty())
      return run(robot, ref, ctx);
    steps.check("experiment 'csv'");
    auto src = CsvStream::open(P_, robot, ctx);
    if (src->hasFloating()) return run(robot, ref, ctx);  // (base, contact: in memory)
    exid::Dataset d;
    d.stream = src;
    d.source = src->file();
    d.meta = src->meta();
    ctx.report(1.0, fmt::format("{} samples in {} (streamed)", d.size(), src->file()));
    return d;
  }

 private:
  exid::ParamSet P_;
};

}  // namespace

EXID_REGISTER_PLUGIN(CsvExperiment)
