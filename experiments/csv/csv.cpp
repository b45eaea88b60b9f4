// exid — experiment `csv`: a recorded (or previously written) dataset read from a CSV file with
// the columns of docs/conventions.md §1: t, q1..qn, qd1..qdn, qdd1..qddn, tau1..taun, fx..mz.
// q is required; every other group is optional but complete when present (all n joints, or all
// six wrench components). Absent qd/qdd stay absent: estimators decide how to differentiate.
// The file written by the runner (experiment.csv, exid::datasetTable) reads back exactly.
// Extensions for recordings as published (docs/experiments.md): other column names
// (q_columns, tau_columns), torques from a second row-aligned file (torque_file), and optional
// zero-phase low-pass + central differences (+ decimation) of the segment.
#include <fcntl.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <sys/mman.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <new>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <vector>

#include "exid/context.hpp"
#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/segment.hpp"
#include "exid/signal.hpp"

namespace {

namespace fs = std::filesystem;
using Eigen::MatrixXd;
using Eigen::VectorXd;

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
        param_doubles("q_scale", std::vector<double>{}, "",
                      "per joint, multiplies the q column (after which sign and offset_rad "
                      "apply), e.g. 0.0174533 for degrees; empty: 1"),
        param_doubles("qd_scale", std::vector<double>{}, "",
                      "per joint, multiplies the qd and qdd columns; empty: as q_scale"),
        param_doubles("tau_scale", std::vector<double>{}, "",
                      "per joint, multiplies the torque column alone (after torque constants), "
                      "e.g. -1 for a torque recorded with the opposite sign to the joint; "
                      "empty: 1"),
        param_double("resample_hz", 0.0, "Hz",
                     "> 0: the segment is linearly interpolated onto a uniform grid at this rate "
                     "(uneven time stamps, e.g. a logger's jitter, are then accepted; a gap "
                     "longer than max_gap_ratio times the median step is still an error: nothing "
                     "is invented across it); 0: the stamps must be uniform",
                     0.0),
        param_double("measurement_delay_s", 0.0, "s",
                     "a known delay of the torque (and wrench) behind the positions: q, qd, qdd "
                     "of sample k are read at t_k - measurement_delay_s (cubic Hermite "
                     "interpolation, before any filter), the torque stays as recorded; the "
                     "samples at the ends without positions then are dropped and counted "
                     "(meta.measurement_delay); the dataset is then held in memory; 0: none "
                     "(varpro can fit an unknown delay)"),
        param_doubles("wrench_scale", std::vector<double>{}, "",
                      "6 values multiplying fx fy fz mx my mz (a unit, a sign); empty: 1"),
        param_double("max_gap_ratio", 1.5, "",
                     "a time step longer than this times the median step (a gap), or shorter "
                     "than its inverse (uneven stamps), is an error naming the rows",
                     1.0, std::nullopt, true),
        param_string("torque_from", std::string("tau"),
                     "tau: columns tau1..taun; current: columns <current_prefix>1..n times "
                     "torque_constants_Nm_per_A",
                     {"tau", "current"}),
        param_string("current_prefix", std::string("i"), "prefix of the motor current columns"),
        param_doubles("torque_constants_Nm_per_A", std::vector<double>{}, "N m/A",
                      "per joint: torque per ampere of current j, referred to the coordinate "
                      "named by current_frame (gear ratio included)"),
        param_string("current_frame", std::string("measured"),
                     "measured: tau_m = Kt .* i directly; joint: the products act on the joint "
                     "coordinates and tau_m = T^T (Kt .* i) with the robot's transmission T",
                     {"measured", "joint"}),
        param_doubles("sign", std::vector<double>{}, "",
                      "per joint +1 or -1, applied to q, qd, qdd and tau of that joint; empty: "
                      "all +1"),
        param_doubles("offset_rad", std::vector<double>{}, "rad",
                      "per joint, added to q after the sign; empty: zeros"),
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
        param_double("differentiate_cutoff_hz", 0.0, "Hz",
                     "> 0: q of the segment is low-passed (zero-phase Butterworth, filter_order) "
                     "and qd, qdd are its central differences (replacing qd/qdd columns); 0: off",
                     0.0),
        param_int("filter_order", 4, "order of that Butterworth filter (per pass)", 1, 12),
        param_bool("filter_torque", false,
                   "with differentiate_cutoff_hz: tau (and the wrench) pass through the same "
                   "zero-phase filter"),
        param_int("decimation", 1,
                  "keep one sample in this many after filtering (> 1 needs "
                  "differentiate_cutoff_hz and filter_torque, and the cut-off below the new "
                  "Nyquist frequency)",
                  1, 1e6),
        param_int("threads", 0,
                  "threads for the scan of the time stamps before the first pass (the file in "
                  "pieces read at once; the result does not depend on the count); 0: the cores "
                  "this process may run on, at most 8",
                  0, 256),
        param_int("trim_edges", -1,
                  "samples dropped at each end of the segment after filtering; -1: "
                  "ceil(2 fs / cutoff) when filtering, else 0",
                  -1, 1e9),
    };
    const auto segment = segmentParams("sample");
    const auto at = std::find_if(p.begin(), p.end(),
                                 [](const ParamDecl& d) { return d.name == "torque_from"; });
    p.insert(at, segment.begin(), segment.end());
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
  /// filtered alone), meta.payload_part describes it and meta.payload_part_from_t_s marks its
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
    exid::Json part = exid::Json::object();
    part["source"] = b.source;
    part["samples"] = Kb;
    part["from_t_s"] = a.t[Ka];
    part["time_offset_s"] = offset;
    part["meta"] = b.meta;
    a.meta["payload_part"] = part;
    a.meta["payload_part_from_t_s"] = a.t[Ka];
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
    // Resampling on request: linear interpolation of every signal onto a uniform grid.
    const int K = d.size();
    const double rs_hz = P_.getDouble("resample_hz");
    int resampled_from = 0;
    if (rs_hz > 0.0) {
      resampled_from = K;
      d = exid::resampleUniform(d, rs_hz, "experiment 'csv': " + src->file());
    }
    // A known measurement delay: the positions read at t - delay, the ends without them
    // dropped (counted).
    const double delay = P_.getDouble("measurement_delay_s");
    int delay_front = 0, delay_back = 0;
    if (delay != 0.0)
      d = exid::compensateDelay(d, delay, "experiment 'csv': measurement_delay_s", &delay_front,
                                &delay_back);
    const int K_grid = d.size();  // samples entering the filter (after resampling, delay)
    const Preprocessed pp = preprocess(&d, src->file());
    d.meta = src->metaAfter(K_grid, resampled_from, rs_hz, pp, d.size());
    if (delay != 0.0) {
      exid::Json& td = d.meta["measurement_delay"];
      td["delay_s"] = delay;
      td["dropped_samples_front"] = delay_front;
      td["dropped_samples_back"] = delay_back;
    }
    ctx.report(1.0, fmt::format("{} samples from {}", d.size(), src->file()));
    return d;
  }

  /// The recording streamed from its file (one scan of its time stamps now; the samples are
  /// read in chunks by whoever consumes them, in one or more passes). Resampling and the
  /// differentiating filter need the whole segment at once: then the dataset is in memory.
  exid::Dataset stream(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples* ref,
                       const exid::RunContext& ctx) override {
    if (P_.getDouble("resample_hz") > 0.0 || P_.getDouble("differentiate_cutoff_hz") > 0.0 ||
        P_.getDouble("measurement_delay_s") != 0.0 || !P_.getString("payload_file").empty())
      return run(robot, ref, ctx);
    exid::check(P_.getInt("decimation") == 1 && !P_.getBool("filter_torque"),
                "experiment 'csv': decimation and filter_torque need differentiate_cutoff_hz > 0");
    auto src = CsvStream::open(P_, robot, ctx);
    exid::Dataset d;
    d.stream = src;
    d.source = src->file();
    d.meta = src->meta();
    ctx.report(1.0, fmt::format("{} samples in {} (streamed)", d.size(), src->file()));
    return d;
  }

 private:
  struct Preprocessed {
    double cutoff_hz = 0, fs = 0;
    int order = 0, trim = 0, decimation = 1;
    int trim_transient = 0, trim_cap = 0, samples_before_trim = 0;
    bool trim_default = false;
    bool filter_torque = false;
  };

  /// Recording-level statistics of the rows the experiment uses (the segment's rows of the file,
  /// before any filtering), accumulated row by row in one pass. Held runs: consecutive rows whose
  /// every q repeats the previous row. A run is in motion when, for some joint, the position moved
  /// by at least kFrozenQuanta times its column's resolution (the smallest step of the column, or
  /// the printed value's own where it is coarser: 5 significant digits print 50 rad to 1e-3)
  /// into the run and out of it, and the
  /// speed out of it (the step over the run's length + 1 rows) is at least kFrozenSpeedRatio
  /// times the speed into it (the step into the run over the rows it took): the robot went on
  /// moving while the positions were held. Otherwise it is a standstill (a stop and a start, or a
  /// slow joint below its encoder's resolution). In a run in motion, a row that repeats every
  /// used column but the time stamp is a duplicate (a logger writing one sample twice); one
  /// whose other columns change is frozen (sample-and-hold positions). Runs at rest are counted
  /// apart and never warned about. Saturation of each torque column: samples at the column's
  /// minimum or maximum in runs of >= 3. Timing statistics come from the scan of the time
  /// stamps. meta.recording; exid::inspectDataset warns from it. Memory: the previous row, and
  /// per held run, one step into and out of it per joint (the column's resolution, which decides
  /// whether it counts, is known only at the end).
  class RecordingStats {
   public:
    static constexpr double kFrozenSpeedRatio = 0.5, kFrozenQuanta = 3.0;
    static constexpr int kSaturationRun = 3;

    /// used: the used columns, the time column (when the file has one) the last of them.
    /// qd_pos: the velocity columns (empty: none), qd_per_q: per joint the velocity column's
    /// unit in position units per second (qd_scale / q_scale); seconds_per_time_unit: the time
    /// column's unit, or period_s: the sample period without a time column.
    RecordingStats(std::vector<int> q_pos, std::vector<int> tau_pos, std::size_t used,
                   bool has_time, std::vector<int> qd_pos = {}, std::vector<double> qd_per_q = {},
                   double seconds_per_time_unit = 1.0, double period_s = 0.0)
        : pq_(std::move(q_pos)),
          ptau_(std::move(tau_pos)),
          pqd_(std::move(qd_pos)),
          qd_per_q_(std::move(qd_per_q)),
          prev_(used),
          compared_(has_time && used > 0 ? used - 1 : used),
          has_time_(has_time),
          time_unit_s_(seconds_per_time_unit),
          period_s_(period_s),
          quantum_(pq_.size(), HUGE_VAL),
          step_(pq_.size(), 0.0),
          run_travel_(pq_.size(), 0.0),
          sat_(ptau_.size()) {}

    /// The next row (values of the used columns) and its data row in the file (0-based).
    void add(const double* v, int row) {
      if (N_ > 0) {
        bool same_q = true;
        for (int c : pq_) same_q = same_q && v[c] == prev_[static_cast<std::size_t>(c)];
        if (same_q) {
          bool dup = true;
          for (std::size_t c = 0; c < compared_ && dup; ++c) dup = v[c] == prev_[c];
          if (run_len_ == 0) {  // a run starts: the step into the held value and its rows
            run_first_row_ = row;
            run_has_before_ = step_rows_ > 0;
            before_ = step_;
            before_rows_ = step_rows_;
            run_dup_rows_.clear();
            std::fill(run_travel_.begin(), run_travel_.end(), 0.0);
          }
          ++run_len_;
          if (dup) run_dup_rows_.push_back(row);
          // the travel the recorded velocities give over the held rows (position units)
          const double dt = has_time_ ? (v[compared_] - prev_[compared_]) * time_unit_s_
                                      : period_s_;
          if (pqd_.size() == pq_.size() && std::isfinite(dt) && dt > 0)
            for (std::size_t j = 0; j < pq_.size(); ++j)
              run_travel_[j] += v[pqd_[j]] * qd_per_q_[j] * dt;
        } else {
          std::vector<double> d(pq_.size());
          for (std::size_t j = 0; j < pq_.size(); ++j) {
            d[j] = std::abs(v[pq_[j]] - prev_[static_cast<std::size_t>(pq_[j])]);
            if (d[j] > 0) quantum_[j] = std::min(quantum_[j], d[j]);
          }
          if (run_len_ > 0) endRun(d, v);  // the run ends here
          step_ = std::move(d);
          step_rows_ = N_ - last_change_;
          last_change_ = N_;
        }
      }
      for (std::size_t k = 0; k < ptau_.size(); ++k) saturationAdd(k, v[ptau_[k]]);
      std::copy(v, v + prev_.size(), prev_.begin());
      ++N_;
    }

    /// The statistics (after every row): duplicate_rows, frozen_rows, saturation.
    void finish(exid::Json* R, const std::vector<std::string>& tau_names) const {
      (*R)["rows"] = N_;
      long long runs = 0, frozen = 0, dups = 0, rest_runs = 0, rest_rows = 0, rest_dups = 0;
      exid::Json frozen_at = exid::Json::array(), dup_at = exid::Json::array();
      auto runs_of = runs_;
      if (run_len_ > 0) {  // a run at the end of the rows: nothing after it, so never in motion
        Run r;
        r.length = run_len_;
        r.dup_rows = run_dup_rows_;
        runs_of.push_back(std::move(r));
      }
      for (const Run& r : runs_of) {
        bool moves = false;
        for (std::size_t j = 0; j < pq_.size() && !moves && r.before_rows > 0; ++j) {
          const double q3 = kFrozenQuanta * std::max(quantum_[j], r.resolution[j]);
          moves = r.before[j] >= q3 && r.after[j] >= q3 &&
                  r.after[j] / static_cast<double>(r.length + 1) >=
                      kFrozenSpeedRatio * r.before[j] / static_cast<double>(r.before_rows);
          // (at a turning point the step into the run is small: there the recorded velocity
          // says whether the joint moves: a travel of kFrozenQuanta resolutions per held row,
          // and a step of as much into or out of the run)
          moves = moves || (!r.travel.empty() && std::max(r.before[j], r.after[j]) >= q3 &&
                            std::abs(r.travel[j]) >= q3 * static_cast<double>(r.length));
        }
        const auto nd = static_cast<long long>(r.dup_rows.size());
        if (!moves) {
          ++rest_runs;
          rest_rows += r.length;
          rest_dups += nd;
          continue;
        }
        dups += nd;
        for (int dr : r.dup_rows)
          if (dup_at.size() < 20) dup_at.push_back(exid::Json(dr + 1));
        if (r.length > nd) {
          ++runs;
          frozen += r.length - nd;
          if (frozen_at.size() < 20) frozen_at.push_back(exid::Json(r.first_row + 1));
        }
      }
      (*R)["duplicate_rows"]["count"] = dups;
      (*R)["duplicate_rows"]["data_rows"] = dup_at;
      (*R)["duplicate_rows"]["definition"] =
          "rows that repeat the previous row in every used column but the time stamp while the "
          "robot moves";
      (*R)["frozen_rows"]["rows"] = frozen;
      (*R)["frozen_rows"]["runs"] = runs;
      (*R)["frozen_rows"]["first_data_rows"] = frozen_at;
      (*R)["frozen_rows"]["definition"] =
          "rows that repeat every joint position (but not every other column) while the robot "
          "moves: the speed out of the held run is at least half the speed into it, or (at a "
          "turning point) the recorded velocities travel 3 resolutions per held row";
      (*R)["held_at_rest"]["rows"] = rest_rows;
      (*R)["held_at_rest"]["runs"] = rest_runs;
      (*R)["held_at_rest"]["exact_repeats"] = rest_dups;
      (*R)["held_at_rest"]["note"] =
          "rows holding every position at a standstill (or below the encoders' resolution): "
          "normal, not warned about";
      exid::Json sat = exid::Json::array();
      for (std::size_t k = 0; k < ptau_.size(); ++k) {
        Saturation s = sat_[k];
        if (s.run > 0) closeRun(&s);
        const long long at_limit = s.lo == s.hi ? s.at_lo : s.at_lo + s.at_hi;
        exid::Json o = exid::Json::object();
        o["column"] = tau_names[k];
        o["min"] = N_ > 0 ? exid::Json(s.lo) : exid::Json();
        o["max"] = N_ > 0 ? exid::Json(s.hi) : exid::Json();
        o["saturated_samples"] = at_limit;
        o["fraction"] = N_ > 0 ? static_cast<double>(at_limit) / static_cast<double>(N_) : 0.0;
        if (N_ > 1 && s.lo == s.hi) o["constant"] = true;
        sat.push_back(o);
      }
      (*R)["saturation"] = sat;
    }

   private:
    struct Run {
      int first_row = 0;
      long long length = 0;
      std::vector<double> before, after;  // per joint: the step into and out of the run
      std::vector<double> resolution;     // per joint: the held or next value's resolution
      long long before_rows = 0;          // rows the step into the run took
      std::vector<int> dup_rows;          // the run's rows that repeat every compared column
      std::vector<double> travel;  // per joint: the recorded velocities' travel over the run
    };
    struct Saturation {
      double lo = HUGE_VAL, hi = -HUGE_VAL;
      double value = 0;  // the run in progress
      long long run = 0;
      long long at_lo = 0, at_hi = 0;  // samples in runs >= kSaturationRun at lo / hi
    };
    static void closeRun(Saturation* s) {
      if (s->run >= kSaturationRun) {
        if (s->value == s->lo) s->at_lo += s->run;
        if (s->value == s->hi) s->at_hi += s->run;
      }
      s->run = 0;
    }
    void saturationAdd(std::size_t k, double v) {
      Saturation& s = sat_[k];
      if (s.run > 0 && v != s.value) closeRun(&s);
      // a new extreme: no earlier run had its value
      if (v < s.lo) {
        s.lo = v;
        s.at_lo = 0;
      }
      if (v > s.hi) {
        s.hi = v;
        s.at_hi = 0;
      }
      s.value = v;
      ++s.run;
    }
    /// The finest power of ten (down to 1e-9) a printed value is a multiple of: its column's
    /// resolution where it was written (5 significant digits: 1e-3 at 50, 1e-4 at 5); 0 for a
    /// value with more digits.
    static double localResolution(double x) {
      for (int d = 0; d <= 9; ++d) {
        const double y = x * std::pow(10.0, d);
        if (std::abs(y - std::round(y)) <= 1e-6 + 16 * 2.220446049250313e-16 * std::abs(y))
          return std::pow(10.0, -d);
      }
      return 0.0;
    }
    void endRun(const std::vector<double>& after, const double* v) {
      if (run_has_before_) {
        Run r;
        r.first_row = run_first_row_;
        r.length = run_len_;
        r.before = before_;
        r.after = after;
        r.resolution.resize(pq_.size());
        for (std::size_t j = 0; j < pq_.size(); ++j)
          // (the finer of the two: one of them may be a round number)
          r.resolution[j] = std::min(localResolution(prev_[static_cast<std::size_t>(pq_[j])]),
                                     localResolution(v[pq_[j]]));
        r.before_rows = before_rows_;
        r.dup_rows = std::move(run_dup_rows_);
        if (pqd_.size() == pq_.size()) r.travel = run_travel_;
        runs_.push_back(std::move(r));
      } else {
        Run r;  // no step into it (the first rows): at rest
        r.length = run_len_;
        r.dup_rows = std::move(run_dup_rows_);
        runs_.push_back(std::move(r));
      }
      run_dup_rows_.clear();
      run_len_ = 0;
    }

    std::vector<int> pq_, ptau_, pqd_;
    std::vector<double> qd_per_q_;
    std::vector<double> prev_;
    std::size_t compared_;  // the columns a duplicate repeats: every used one but the time
    bool has_time_;         // the time column is the last used one
    double time_unit_s_, period_s_;
    std::vector<double> quantum_, step_, before_, run_travel_;
    long long N_ = 0, last_change_ = 0, step_rows_ = 0, before_rows_ = 0;
    long long run_len_ = 0;
    int run_first_row_ = 0;
    bool run_has_before_ = false;
    std::vector<int> run_dup_rows_;
    std::vector<Run> runs_;
    std::vector<Saturation> sat_;
  };

  /// The csv experiment's reading of a recording: its columns found from the headers, one scan
  /// of the rows (time stamps; every used column with drop_bad_rows) that checks time, gaps,
  /// the segment and the split, and then passes over the samples in chunks, each reading the
  /// file(s) again. Memory: 8 bytes per row for the time stamps during the scan (released
  /// after it), the dropped rows' numbers, and one chunk.
  class CsvStream : public exid::DatasetStream {
    struct Ref {
      int source = 0, column = 0;
    };

   public:
    static std::shared_ptr<CsvStream> open(const exid::ParamSet& P,
                                           std::shared_ptr<const exid::RobotModel> robot,
                                           const exid::RunContext& ctx) {
      exid::check(robot != nullptr, "experiment 'csv': no robot");
      auto s = std::shared_ptr<CsvStream>(new CsvStream(P, std::move(robot)));
      s->resolveColumns(ctx);
      s->scan();
      return s;
    }

    const std::string& file() const { return files_[0]; }
    int size() const override { return static_cast<int>(i1_ - i0_); }
    int dof() const override { return n_; }
    bool hasVelocity() const override { return !pqd_.empty(); }
    bool hasAcceleration() const override { return !pqdd_.empty(); }
    bool hasTorque() const override { return !ptau_.empty(); }
    bool hasWrench() const override { return !pw_.empty(); }
    double tFirst() const override { return t_first_; }
    double tLast() const override { return t_last_; }
    bool passed() const override { return stats_done_; }
    void collectEvery(int stride) override { stride_ = std::max(1, stride); }
    const exid::Dataset& collected() const override { return collected_; }
    bool samplingRate(double* fs_hz, double* jitter) const override {
      if (!has_rate_) return false;
      *fs_hz = fs_hz_;
      *jitter = jitter_;
      return true;
    }
    exid::Json meta() const override { return metaAfter(size(), 0, 0.0, Preprocessed(), size()); }

    void rewind() override {
      readers_.clear();
      for (std::size_t f = 0; f < files_.size(); ++f) {
        exid::CsvReadOptions opt;
        opt.allow_non_finite = true;  // checked below, only in the columns used
        opt.text_columns = true;
        readers_.push_back(std::make_unique<exid::CsvReader>(files_[f], opt, "CSV data"));
        readers_.back()->select(select_[f]);
      }
      row_ = -1;
      kept_ = -1;
      dptr_ = 0;
      settled_ = 0;
      if (protos_.empty())  // the files' columns and selection, for decode()
        for (std::size_t f = 0; f < files_.size(); ++f) {
          exid::CsvReadOptions opt;
          opt.allow_non_finite = true;
          opt.text_columns = true;
          protos_.push_back(std::make_unique<exid::CsvReader>(files_[f], opt, "CSV data"));
          protos_.back()->select(select_[f]);
        }
      std::vector<double> qd_per_q(qscale_.size());
      for (std::size_t j = 0; j < qscale_.size() && j < qdscale_.size(); ++j)
        qd_per_q[j] = qdscale_[j] / qscale_[j];
      stats_ = std::make_unique<RecordingStats>(pq_, ptau_, used_.size(), ct_, pqd_, qd_per_q,
                                                tfactor_, dt_);
      collecting_ = !stats_done_;
      if (collecting_) collected_ = exid::Dataset();
      taken_ = 0;
    }

    int read(int count, exid::Dataset* chunk) override {
      exid::check(!readers_.empty(), "experiment 'csv': a pass read before rewind()");
      const int want = static_cast<int>(std::min<long>(count, i1_ - std::max(i0_, kept_ + 1)));
      if (want <= 0) {
        finishPass();
        return 0;
      }
      sizeChunk(want, chunk);
      int k = 0;
      while (k < want) {
        if (!nextKeptRow()) break;
        if (kept_ < i0_) continue;
        convert(k, chunk);
        if (collecting_) {
          stats_->add(uv_.data(), row_);
          if (stride_ > 0 && taken_ % stride_ == 0) collect(*chunk, k);
          ++taken_;
        }
        ++k;
      }
      exid::check(k == want, fmt::format("experiment 'csv': {}: the file changed while it was "
                                         "read (a pass found {} of the {} samples of the scan)",
                                         files_[0], kept_ - i0_ + 1, size()));
      if (kept_ + 1 >= i1_) finishPass();
      return k;
    }

    // ---- a pass in pieces (fetch, decode on any thread, settle in order)
    struct CsvPiece : Piece {
      std::vector<std::string> text;  // per file: the rows' lines
      std::vector<int> line_before;   // per file: the file line before them
      int first_row = 0;              // file data row of the first line's row (0-based)
      int rows = 0;                   // data rows in text (samples and dropped rows)
      std::vector<double> values;     // decoded: per sample, its used values (for settle)
      std::vector<int> row_of;        // decoded: per sample, its file data row
    };

    std::unique_ptr<Piece> fetch(int count) override {
      exid::check(!readers_.empty(), "experiment 'csv': a pass read before rewind()");
      auto piece = std::make_unique<CsvPiece>();
      const long first = std::max(i0_, kept_ + 1);
      const int want = static_cast<int>(std::max<long>(0, std::min<long>(count, i1_ - first)));
      piece->count = want;
      if (want == 0) return piece;
      // file rows: those before the first sample passed over, then the piece's (with the
      // dropped rows among them: decode finds them bad again, by the same rule)
      const int skip = fileRowsFor(row_ + 1, first - (kept_ + 1));
      const int take = fileRowsFor(row_ + 1 + skip, want);
      piece->first_row = row_ + 1 + skip;
      piece->rows = take;
      piece->text.resize(readers_.size());
      piece->line_before.resize(readers_.size());
      for (std::size_t f = 0; f < readers_.size(); ++f) {
        const int skipped = readers_[f]->skipRows(skip);
        const int got = readers_[f]->takeRows(take, &piece->text[f], &piece->line_before[f]);
        exid::check(skipped == skip && got == take,
                    fmt::format("experiment 'csv': {}: the file changed while it was read (a "
                                "pass found fewer rows than the scan)",
                                files_[f]));
      }
      row_ += skip + take;
      kept_ = first + want - 1;
      return piece;
    }

    void decode(Piece& piece, exid::Dataset* chunk) const override {
      auto& pc = dynamic_cast<CsvPiece&>(piece);
      sizeChunk(pc.count, chunk);
      std::vector<std::unique_ptr<exid::CsvReader>> rd;
      for (std::size_t f = 0; f < pc.text.size(); ++f)
        rd.push_back(std::make_unique<exid::CsvReader>(pc.text[f], *protos_[f], pc.line_before[f]));
      std::vector<std::vector<double>> vals = vals_;
      const std::size_t U = used_.size();
      pc.values.resize(static_cast<std::size_t>(pc.count) * U);
      pc.row_of.resize(static_cast<std::size_t>(pc.count));
      Eigen::VectorXd tau;
      int k = 0;
      for (int r = 0; r < pc.rows; ++r) {
        double* uv = pc.values.data() + static_cast<std::size_t>(std::min(k, pc.count - 1)) * U;
        if (!readRow(rd, &vals, uv))  // (messages built only when a check fails: per row)
          throw exid::Error(
              fmt::format("experiment 'csv': {}: the file changed while it was read", files_[0]));
        const int row = pc.first_row + r;
        if (const int bad = badColumn(uv); bad >= 0) {
          if (!drop_) badValue(rd, bad, row);
          continue;
        }
        if (k >= pc.count)
          throw exid::Error(
              fmt::format("experiment 'csv': {}: the file changed while it was read "
                          "(more good rows than the scan found, at data row {})",
                          files_[0], row + 1));
        convert(k, uv, row, chunk, &tau);
        pc.row_of[static_cast<std::size_t>(k)] = row;
        ++k;
      }
      exid::check(k == pc.count, fmt::format("experiment 'csv': {}: the file changed while it was "
                                             "read (a piece found {} of its {} samples)",
                                             files_[0], k, pc.count));
    }

    void settle(const Piece& piece, const exid::Dataset& chunk) override {
      const auto& pc = dynamic_cast<const CsvPiece&>(piece);
      if (collecting_) {
        const std::size_t U = used_.size();
        for (int k = 0; k < pc.count; ++k) {
          stats_->add(pc.values.data() + static_cast<std::size_t>(k) * U,
                      pc.row_of[static_cast<std::size_t>(k)]);
          if (stride_ > 0 && taken_ % stride_ == 0) collect(chunk, k);
          ++taken_;
        }
      }
      settled_ += pc.count;
      if (settled_ >= size()) finishPass();
    }

    /// The meta of the dataset after resampling (resampled_from > 0), filtering (pp) and
    /// decimation: `samples_used` samples from the `K_grid` that entered the filter.
    exid::Json metaAfter(int K_grid, int resampled_from, double rs_hz, const Preprocessed& pp,
                         int samples_used) const {
      const int K = size();
      exid::Json m = exid::Json::object();
      m["simulated"] = false;
      m["file"] = files_[0];
      m["rows_in_file"] = rows_;
      m["dropped_rows"] = dropped_;
      m["samples"] = K;
      m["time_column"] = ct_ ? exid::Json(tname_) : exid::Json(false);
      if (ct_) m["time_unit"] = tunit_;
      if (!ct_) m["sample_period_s"] = dt_;
      m["segment_s"] = exid::Json(std::vector<double>{ts_, te_});
      if (part_ != "none") m["split"] = seg_.splitMeta(in_segment_, K);
      m["recording_span_s"] = span_;
      m["recording"] = recording_;
      m["scan"]["pieces"] = scan_pieces_;  // the first reading of the file (threads)
      m["scan"]["threads"] = scan_threads_;
      {  // Where the rows went: every sample dropped, cut, trimmed or decimated is counted.
        exid::Json& a = m["accounting"];
        a["rows_in_file"] = rows_;
        a["dropped_bad_rows"] = dropped_;
        a["outside_segment"] = kept_rows_ - in_segment_;
        if (part_ != "none") a["other_part_of_split"] = in_segment_ - K;
        a["segment_samples"] = K;
        if (resampled_from > 0) {
          a["resampled_from"] = resampled_from;
          a["resampled_to"] = K_grid;
          a["resample_hz"] = rs_hz;
        }
        const int trimmed = pp.cutoff_hz > 0 ? 2 * pp.trim : 0;
        a["trimmed_edges"] = trimmed;
        a["trimmed_percent_of_segment"] = 100.0 * trimmed / std::max(1, K_grid);
        a["decimated_away"] = K_grid - trimmed - samples_used;
        a["samples_used"] = samples_used;
        exid::Json w = exid::Json::array();
        if (dropped_ > 0)
          w.push_back(exid::Json(fmt::format(
              "experiment 'csv': {}: {} of {} rows ({:.1f} %) dropped for missing or non-finite "
              "values (drop_bad_rows)",
              files_[0], dropped_, rows_, 100.0 * dropped_ / std::max(1, rows_))));
        if (trimmed > 0.1 * K_grid)
          w.push_back(exid::Json(fmt::format(
              "experiment 'csv': {}: trim_edges = {} discards {} of the segment's {} samples "
              "({:.1f} %, more than 10 %)",
              files_[0], pp.trim, trimmed, K_grid, 100.0 * trimmed / K_grid)));
        if (pp.trim_default && pp.trim < pp.trim_transient)
          a["trim_rule"] = fmt::format(
              "ceil(2 fs / fc) = {} samples capped at 5 % of the segment: {} at each end",
              pp.trim_transient, pp.trim);
        else if (pp.trim_default)
          a["trim_rule"] = fmt::format("ceil(2 fs / fc) = {} samples at each end", pp.trim);
        if (w.size() > 0) m["warnings"] = w;
      }
      m["torque_from"] = tfrom_;
      std::vector<std::string> sig = {"q"};
      if (!pqd_.empty()) sig.push_back("qd");
      if (!pqdd_.empty()) sig.push_back("qdd");
      if (!ptau_.empty()) sig.push_back("tau");
      if (!pw_.empty()) sig.push_back("wrench");
      m["signals"] = exid::Json(sig);
      if (files_.size() > 1) m["torque_file"] = files_[1];
      if (pp.cutoff_hz > 0) {
        m["differentiated"] = exid::Json::object();
        m["differentiated"]["cutoff_hz"] = pp.cutoff_hz;
        m["differentiated"]["filter_order"] = pp.order;
        m["differentiated"]["filter_torque"] = pp.filter_torque;
        m["differentiated"]["trimmed_samples_each_end"] = pp.trim;
        m["differentiated"]["decimation"] = pp.decimation;
        m["differentiated"]["sample_rate_hz"] = pp.fs;
      }
      m["samples"] = samples_used;
      return m;
    }

   private:
    CsvStream(const exid::ParamSet& P, std::shared_ptr<const exid::RobotModel> robot)
        : P_(P), robot_(std::move(robot)), n_(robot_->dof()) {}

    // ---- columns, from the headers
    void resolveColumns(const exid::RunContext& ctx) {
      openFiles(ctx);
      const int fq = 0, ftau = static_cast<int>(files_.size()) - 1;
      std::vector<Ref> cq = namedColumns(fq, "q_columns");
      if (cq.empty()) cq = columnGroup("q", true, "joint positions are required", fq);
      const std::vector<Ref> cqd = columnGroup("qd", false, "");
      const std::vector<Ref> cqdd = columnGroup("qdd", false, "");
      const std::vector<Ref> ctau = torqueColumns(ftau);
      const std::vector<Ref> cw = wrenchColumns();
      const int ct = timeColumn();
      readScales();
      layoutColumns(cq, cqd, cqdd, ctau, cw, ct);
    }

    // The file (and torque_file), relative to the study, and their columns.
    void openFiles(const exid::RunContext& ctx) {
      auto path = [&](fs::path p) {
        if (p.is_relative() && !ctx.study_dir.empty()) p = ctx.study_dir / p;
        return p.string();
      };
      files_.push_back(path(P_.getString("file")));
      if (!P_.getString("torque_file").empty()) files_.push_back(path(P_.getString("torque_file")));
      for (const std::string& f : files_) {
        exid::CsvReadOptions opt;
        opt.text_columns = true;
        exid::CsvReader r(f, opt, "CSV data");
        columns_.push_back(r.columns());
      }
    }

    // Column c of source f, or -1.
    int col(int f, const std::string& c) const {
      const auto& C = columns_[static_cast<std::size_t>(f)];
      const auto it = std::find(C.begin(), C.end(), c);
      return it == C.end() ? -1 : static_cast<int>(it - C.begin());
    }

    // The n columns named by parameter `key` in source f (none when the list is empty).
    std::vector<Ref> namedColumns(int f, const char* key) const {
      const int n = n_;
      std::vector<Ref> idx;
      const std::vector<std::string> names = P_.getStrings(key);
      if (names.empty()) return idx;
      exid::check(static_cast<int>(names.size()) == n,
                  fmt::format("experiment 'csv': {}: expected {} names (one per joint of robot "
                              "'{}'), found {}",
                              key, n, robot_->name, names.size()));
      for (std::size_t a = 0; a < names.size(); ++a)
        for (std::size_t b = 0; b < a; ++b)
          exid::check(names[a] != names[b],
                      fmt::format("experiment 'csv': {}: column '{}' is named twice (elements "
                                  "{} and {}); each joint needs its own column",
                                  key, names[a], b + 1, a + 1));
      for (const auto& c : names) {
        const int i = col(f, c);
        exid::check(i >= 0, fmt::format("experiment 'csv': {}: {}: no column '{}' (found "
                                        "columns: {})",
                                        files_[static_cast<std::size_t>(f)], key, c,
                                        fmt::join(columns_[static_cast<std::size_t>(f)], ", ")));
        idx.push_back({f, i});
      }
      return idx;
    }

    // Columns prefix1..prefixn of source f: all n, or none (an error when required; `what`
    // says why they are).
    std::vector<Ref> columnGroup(const std::string& prefix, bool required, const char* what,
                                 int f = 0) const {
      const int n = n_;
      const std::string& fileg = files_[static_cast<std::size_t>(f)];
      const auto& C = columns_[static_cast<std::size_t>(f)];
      std::vector<Ref> idx;
      int found = 0;
      while (col(f, prefix + std::to_string(found + 1)) >= 0) ++found;
      if (found == 0) {
        exid::check(!required,
                    fmt::format("experiment 'csv': {}: missing column '{}1' ({}; expected "
                                "columns {}1..{}{} for the {} joints of robot '{}'; found "
                                "columns: {})",
                                fileg, prefix, what, prefix, prefix, n, n, robot_->name,
                                fmt::join(C, ", ")));
        return idx;
      }
      exid::check(
          found == n,
          fmt::format("experiment 'csv': {}: wrong joint count: found columns {}1..{}{} "
                      "({} joints), expected {}1..{}{} for robot '{}' ({} joints)",
                      fileg, prefix, prefix, found, found, prefix, prefix, n, robot_->name, n));
      for (int j = 1; j <= n; ++j) idx.push_back({f, col(f, prefix + std::to_string(j))});
      return idx;
    }

    // The torque columns of source ftau (tau, or motor currents with their torque constants).
    std::vector<Ref> torqueColumns(int ftau) {
      tfrom_ = P_.getString("torque_from");
      std::vector<Ref> ctau = namedColumns(ftau, "tau_columns");
      if (tfrom_ == "tau") {
        if (ctau.empty()) ctau = columnGroup("tau", ftau > 0, "torque_file is given", ftau);
      } else {
        const std::string pre = P_.getString("current_prefix");
        if (ctau.empty())
          ctau = columnGroup(pre, true, "torque_from: current needs the motor currents", ftau);
        Kt_ = P_.getDoubles("torque_constants_Nm_per_A");
        exid::check(static_cast<int>(Kt_.size()) == n_,
                    fmt::format("experiment 'csv': torque_constants_Nm_per_A: expected {} values "
                                "(one per joint of robot '{}'), found {}",
                                n_, robot_->name, Kt_.size()));
      }
      return ctau;
    }

    // fx fy fz mx my mz: all six, or none.
    std::vector<Ref> wrenchColumns() const {
      std::vector<Ref> cw;
      const char* wn[6] = {"fx", "fy", "fz", "mx", "my", "mz"};
      int present = 0;
      for (const char* c : wn) present += col(0, c) >= 0;
      if (present > 0) {
        std::vector<std::string> missing;
        for (const char* c : wn)
          if (col(0, c) < 0) missing.push_back(c);
        exid::check(missing.empty(),
                    fmt::format("experiment 'csv': {}: incomplete wrench: missing column(s) {} "
                                "(expected all of fx fy fz mx my mz, or none)",
                                files_[0], fmt::join(missing, ", ")));
        for (const char* c : wn) cw.push_back({0, col(0, c)});
      }
      return cw;
    }

    // The time column of file (-1: none; sample_period_s is then needed) and its unit.
    int timeColumn() {
      tname_ = P_.getString("time_column");
      const int ct = col(0, tname_);
      dt_ = P_.getDouble("sample_period_s");
      exid::check(ct >= 0 || dt_ > 0,
                  fmt::format("experiment 'csv': {}: no time column '{}' and no sample_period_s: "
                              "exid does not guess the sample rate; give time_column (the name "
                              "of the time column, with time_unit) or sample_period_s (found "
                              "columns: {})",
                              files_[0], tname_, fmt::join(columns_[0], ", ")));
      tunit_ = P_.getString("time_unit");
      tfactor_ = tunit_ == "ms" ? 1e-3 : tunit_ == "us" ? 1e-6 : tunit_ == "ns" ? 1e-9 : 1.0;
      return ct;
    }

    // A per-joint scale: n finite non-zero values (empty: dflt for every joint).
    std::vector<double> perJoint(const char* key, std::vector<double> v, double dflt) const {
      const int n = n_;
      if (v.empty()) v.assign(static_cast<std::size_t>(n), dflt);
      exid::check(static_cast<int>(v.size()) == n,
                  fmt::format("experiment 'csv': {}: expected {} values (one per joint of "
                              "robot '{}'), found {}",
                              key, n, robot_->name, v.size()));
      for (double x : v)
        exid::check(std::isfinite(x) && x != 0.0,
                    fmt::format("experiment 'csv': {}: {} is not a usable scale", key, x));
      return v;
    }

    // Scales, signs, offsets and the remaining options.
    void readScales() {
      const int n = n_;
      qscale_ = perJoint("q_scale", P_.getDoubles("q_scale"), 1.0);
      qdscale_ = P_.getDoubles("qd_scale").empty()
                     ? qscale_
                     : perJoint("qd_scale", P_.getDoubles("qd_scale"), 1.0);
      tauscale_ = perJoint("tau_scale", P_.getDoubles("tau_scale"), 1.0);
      wscale_ = P_.getDoubles("wrench_scale");
      if (wscale_.empty()) wscale_.assign(6, 1.0);
      exid::check(wscale_.size() == 6,
                  fmt::format("experiment 'csv': wrench_scale: expected 6 values (fx fy fz mx my "
                              "mz), found {}",
                              wscale_.size()));
      for (double x : wscale_)
        exid::check(std::isfinite(x) && x != 0.0,
                    fmt::format("experiment 'csv': wrench_scale: {} is not a usable scale", x));
      sign_ = P_.getDoubles("sign");
      off_ = P_.getDoubles("offset_rad");
      if (sign_.empty()) sign_.assign(static_cast<std::size_t>(n), 1.0);
      if (off_.empty()) off_.assign(static_cast<std::size_t>(n), 0.0);
      exid::check(static_cast<int>(sign_.size()) == n,
                  fmt::format("experiment 'csv': sign: expected {} values (one per joint), found "
                              "{}",
                              n, sign_.size()));
      exid::check(static_cast<int>(off_.size()) == n,
                  fmt::format("experiment 'csv': offset_rad: expected {} values (one per joint), "
                              "found {}",
                              n, off_.size()));
      for (int j = 0; j < n; ++j)
        exid::check(
            sign_[static_cast<std::size_t>(j)] == 1.0 || sign_[static_cast<std::size_t>(j)] == -1.0,
            fmt::format("experiment 'csv': sign: joint {}: expected +1 or -1, found {}", j + 1,
                        sign_[static_cast<std::size_t>(j)]));
      joint_frame_ = P_.getString("current_frame") == "joint";
      drop_ = P_.getBool("drop_bad_rows");
    }

    // The used columns, in the order q, qd, qdd, tau, wrench, t; per source the columns it
    // reads and where each value goes.
    void layoutColumns(const std::vector<Ref>& cq, const std::vector<Ref>& cqd,
                       const std::vector<Ref>& cqdd, const std::vector<Ref>& ctau,
                       const std::vector<Ref>& cw, int ct) {
      auto add = [&](const std::vector<Ref>& g, std::vector<int>* pos) {
        for (const Ref& r : g) {
          pos->push_back(static_cast<int>(used_.size()));
          used_.push_back(r);
        }
      };
      add(cq, &pq_);
      add(cqd, &pqd_);
      add(cqdd, &pqdd_);
      add(ctau, &ptau_);
      add(cw, &pw_);
      ct_ = ct >= 0;
      if (ct_) {
        pt_ = static_cast<int>(used_.size());
        used_.push_back({0, ct});
      }
      select_.assign(files_.size(), {});
      for (const Ref& r : used_) {
        auto& sel = select_[static_cast<std::size_t>(r.source)];
        if (std::find(sel.begin(), sel.end(), r.column) == sel.end()) sel.push_back(r.column);
      }
      slot_.clear();
      for (const Ref& r : used_) {
        const auto& sel = select_[static_cast<std::size_t>(r.source)];
        slot_.push_back({r.source, static_cast<int>(std::find(sel.begin(), sel.end(), r.column) -
                                                    sel.begin())});
      }
      for (std::size_t f = 0; f < files_.size(); ++f) vals_.emplace_back(select_[f].size());
      uv_.resize(used_.size());
      for (int p : ptau_) tau_names_.push_back(colName(used_[static_cast<std::size_t>(p)], false));
    }

    std::string colName(const Ref& r, bool with_file = true) const {
      const std::string& c =
          columns_[static_cast<std::size_t>(r.source)][static_cast<std::size_t>(r.column)];
      if (!with_file) return c;
      return files_.size() > 1
                 ? fmt::format("{}' of {}", c, files_[static_cast<std::size_t>(r.source)])
                 : c + "'";
    }

    // One row of every source into uv_ (false at the end of the first file); the sources must
    // have the same number of rows (the scan checks).
    bool readRow(std::vector<std::unique_ptr<exid::CsvReader>>& rd) {
      return readRow(rd, &vals_, uv_.data());
    }
    // The same into the given buffers (vals: per source, one row's values; uv: used values).
    bool readRow(std::vector<std::unique_ptr<exid::CsvReader>>& rd,
                 std::vector<std::vector<double>>* vals, double* uv) const {
      bool more = true;
      for (std::size_t f = 0; f < rd.size(); ++f) {
        const bool got = rd[f]->next((*vals)[f].data());
        if (f == 0) more = got;
        if (!more) return false;
        exid::check(got, "experiment 'csv': internal error: the torque file ended early");
      }
      for (std::size_t u = 0; u < used_.size(); ++u)
        uv[u] = (*vals)[static_cast<std::size_t>(slot_[u].source)]
                       [static_cast<std::size_t>(slot_[u].column)];
      return true;
    }

    // The first used column whose value in uv_ (or uv) is not finite, or -1.
    int badColumn() const { return badColumn(uv_.data()); }
    int badColumn(const double* uv) const {
      for (std::size_t u = 0; u < used_.size(); ++u)
        if (!std::isfinite(uv[u])) return static_cast<int>(u);
      return -1;
    }

    // A bad value at used column u in the current row of reader set rd: text in that column is
    // named first (it is never a dropped row), then the missing or non-finite value.
    [[noreturn]] void badValue(const std::vector<std::unique_ptr<exid::CsvReader>>& rd, int u,
                               int row) const {
      const Ref& r = used_[static_cast<std::size_t>(u)];
      const std::string& why =
          rd[static_cast<std::size_t>(r.source)]->notNumeric()[static_cast<std::size_t>(r.column)];
      if (!why.empty()) throw exid::Error("experiment 'csv': " + why);
      throw exid::Error(fmt::format(
          "experiment 'csv': {}: line {} (data row {}): column '{}: missing or non-finite value "
          "(set drop_bad_rows: true to drop such rows)",
          files_[static_cast<std::size_t>(r.source)],
          rd[static_cast<std::size_t>(r.source)]->line(), row + 1, colName(r)));
    }

    // The file line of data row `row` of source f (read again: only an error needs it).
    int lineOfRow(int f, int row) const {
      exid::CsvReadOptions opt;
      opt.allow_non_finite = true;
      opt.text_columns = true;
      exid::CsvReader r(files_[static_cast<std::size_t>(f)], opt, "CSV data");
      r.select({});
      for (int k = 0; k <= row; ++k)
        if (!r.next(nullptr)) return 0;
      return r.line();
    }
    std::string lineText(int row) const {
      const int l = lineOfRow(0, row);
      return l > 0 ? fmt::format("line {}", l) : fmt::format("data row {}", row + 1);
    }
    // ---- the scan: rows, bad values (drop_bad_rows), time, gaps, segment, split
    // What the scan keeps of the kept rows: the time stamps as written (with a time column)
    // and, only when rows were dropped, each one's file row.
    struct ScanRows {
      std::vector<double> raw;
      std::vector<int> keep;
    };
    int rowOf(const ScanRows& s, std::size_t i) const {
      return s.keep.empty() ? static_cast<int>(i) : s.keep[i];
    }
    double timeOf(const ScanRows& s, long i) const {
      return ct_ ? tfactor_ * s.raw[static_cast<std::size_t>(i)]
                 : rowOf(s, static_cast<std::size_t>(i)) * dt_;
    }

    void scan() {
      checkRowAligned();
      ScanRows s;
      s.raw = scanRows();
      s.keep = keptFileRows();
      checkUniformSteps(s);
      selectSegment(s);
      scanSamplingRate(s);
      recordTiming(&s);
    }

    // torque_file: row-aligned with file
    void checkRowAligned() const {
      if (files_.size() <= 1) return;
      int tau_rows = 0, file_rows = 0;
      for (int f = 0; f < 2; ++f) {
        int& count = f == 0 ? file_rows : tau_rows;
        exid::CsvReadOptions opt;
        opt.allow_non_finite = true;
        opt.text_columns = true;
        exid::CsvReader r(files_[static_cast<std::size_t>(f)], opt, "CSV data");
        r.select({});
        while (r.next(nullptr)) ++count;
      }
      if (tau_rows != file_rows) {
        const int f = tau_rows > file_rows ? 1 : 0;
        const int k = std::min(file_rows, tau_rows);
        const int line = lineOfRow(f, k);
        throw exid::Error(fmt::format(
            "experiment 'csv': torque_file {} has {} data rows, file {} has {}: the two files "
            "must be row-aligned ({}: data row {} at line {} has no counterpart)",
            files_[1], tau_rows, files_[0], file_rows, files_[static_cast<std::size_t>(f)], k + 1,
            line));
      }
    }

    // Every row once: bad rows dropped (drop_bad_rows) or refused, time checked to increase.
    // Returns the kept rows' time stamps as written (with a time column).
    std::vector<double> scanRows() {
      const std::string& file = files_[0];
      // Readers for the scan: the time column alone, unless rows may be dropped (then every
      // used column decides).
      std::vector<std::unique_ptr<exid::CsvReader>> rd;
      for (std::size_t f = 0; f < files_.size(); ++f) {
        exid::CsvReadOptions opt;
        opt.allow_non_finite = true;
        opt.text_columns = true;
        rd.push_back(std::make_unique<exid::CsvReader>(files_[f], opt, "CSV data"));
        rd.back()->select(
            drop_ ? select_[f]
                  : (f == 0 && ct_ ? std::vector<int>{used_.back().column} : std::vector<int>{}));
      }
      std::vector<double> raw;  // per kept row: the time stamp as written
      if (!drop_ && scanInPieces(*rd[0], &raw)) return raw;
      raw.clear();
      std::error_code size_err;
      const auto file_size = std::filesystem::file_size(file, size_err);
      const double file_bytes = size_err ? 0.0 : static_cast<double>(file_size);
      bool reserved = false;
      const std::uint64_t header_bytes = rd[0]->bytesRead();  // (the header's lines)
      int rows = 0, prev_line = 0;
      double prev_t = 0;
      std::vector<double> v0(std::max<std::size_t>(1, vals_[0].size()));
      while (true) {
        bool got;
        if (drop_) {
          got = readRow(rd);
        } else {
          got = rd[0]->next(v0.data());
        }
        if (!got) break;
        const int r = rows++;
        if (drop_) {
          const int bad = badColumn();
          if (bad >= 0) {
            const Ref& br = used_[static_cast<std::size_t>(bad)];
            if (!rd[static_cast<std::size_t>(br.source)]
                     ->notNumeric()[static_cast<std::size_t>(br.column)]
                     .empty())
              badValue(rd, bad, r);  // text is never dropped
            ++dropped_;
            dropped_rows_.push_back(r);
            continue;
          }
        }
        const double rv = ct_ ? (drop_ ? uv_[static_cast<std::size_t>(pt_)] : v0[0]) : 0.0;
        if (ct_ && !std::isfinite(rv)) {
          if (!drop_) {
            uv_[static_cast<std::size_t>(pt_)] = rv;
            badValue(rd, pt_, r);
          }
        }
        const double t = ct_ ? tfactor_ * rv : r * dt_;
        if (kept_rows_ > 0 && !(t > prev_t))
          throw exid::Error(
              fmt::format("experiment 'csv': {}: line {} (data row {}): column '{}': time "
                          "must strictly increase; t = {} s after t = {} s at line {}",
                          file, rd[0]->line(), r + 1, tname_, t, prev_t, prev_line));
        if (kept_rows_ == 0) t_first_abs_ = t;
        prev_t = t;
        prev_line = rd[0]->line();
        if (ct_) {
          // After 4096 rows, room for the whole file's time stamps at those rows' density
          // (+10 %): growing by doubling would copy them, holding both copies at once (the
          // peak memory of a long recording's run). Pages never written are never resident,
          // so an estimate too high costs little; one too low grows as before.
          if (!reserved && raw.size() == 4096) {
            reserved = true;
            const double used = static_cast<double>(rd[0]->bytesRead() - header_bytes);
            if (used > 0 && file_bytes > used) {
              try {
                raw.reserve(static_cast<std::size_t>(
                    1.1 * 4096.0 * (file_bytes - static_cast<double>(header_bytes)) / used));
              } catch (const std::bad_alloc&) {  // (then it grows as it goes)
              }
            }
          }
          raw.push_back(rv);
        }
        ++kept_rows_;
      }
      rows_ = rows;
      exid::check(rows > 0,
                  fmt::format("experiment 'csv': {}: no data rows after the header", file));
      exid::check(kept_rows_ > 0,
                  fmt::format("experiment 'csv': {}: every row was dropped ({} with bad values)",
                              file, dropped_));
      return raw;
    }

    // scanRows() without dropped rows (only the time column read, or only rows counted) on
    // several threads: the data in byte ranges that start at a line, each parsed by a reader
    // of whole lines (CsvReader's body constructor), the pieces' stamps appended in file
    // order as they are done (memory: the stamps and a few pieces in flight). False (nothing
    // set) on one thread, a small file, or anything the serial scan must report with its line
    // (a bad or non-increasing time, no rows): the serial scan then runs.
    bool scanInPieces(const exid::CsvReader& like, std::vector<double>* raw) {
      const int threads = exid::resolveThreads(P_.getInt("threads"));
      const std::string& file = files_[0];
      std::error_code err;
      const auto size = std::filesystem::file_size(file, err);
      const std::uint64_t begin = like.bytesRead();  // the data after the header's lines
      constexpr std::uint64_t kPiece = std::uint64_t{4} << 20;
      if (threads < 2 || err || size < begin + 2 * kPiece) return false;
      int fd = -1;
      try {  // the input-file checks again (the file may have been replaced since the header)
        fd = exid::openInputFile(file, "CSV", exid::kStreamedFileBytes);
      } catch (const exid::Error&) {
        return false;  // the serial scan reports it
      }
      struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
      } closer{fd};
      // piece starts: after the first newline at or after each nominal start - 1
      const std::uint64_t data = size - begin;
      const auto count = static_cast<std::size_t>(std::min<std::uint64_t>(4096, data / kPiece));
      std::vector<std::uint64_t> start{begin};
      std::vector<char> probe(std::size_t{1} << 16);
      for (std::size_t i = 1; i < count; ++i) {
        std::uint64_t at = begin + data * i / count - 1;
        if (at < start.back()) continue;
        bool found = false;
        while (!found && at < size) {
          const ssize_t got = ::pread(fd, probe.data(), probe.size(), static_cast<off_t>(at));
          if (got <= 0) return false;
          const void* nl = std::memchr(probe.data(), '\n', static_cast<std::size_t>(got));
          if (nl) {
            at += static_cast<std::uint64_t>(static_cast<const char*>(nl) - probe.data()) + 1;
            found = true;
          } else {
            at += static_cast<std::uint64_t>(got);
          }
        }
        if (!found || at >= size) break;
        if (at > start.back()) start.push_back(at);
      }
      start.push_back(size);
      const std::size_t pieces = start.size() - 1;
      if (pieces < 2) return false;
      // each piece: its rows and, with a time column, their stamps; ok false when a reader
      // failed or a stamp is not finite (the serial scan names the line)
      struct Part {
        std::vector<double> t;
        long rows = 0;
        bool ok = true, done = false;
      };
      std::vector<Part> piece(pieces);
      std::mutex mu;
      std::size_t merged = 0;
      bool failed = false;
      std::atomic<std::size_t> next{0};
      std::atomic<bool> stop{false};
      long rows = 0;
      double prev = 0.0;
      bool increasing = true;
      auto merge = [&](std::size_t k) {  // (under mu) piece k is done: append what is ready
        piece[k].done = true;
        while (merged < pieces && piece[merged].done) {
          Part& m = piece[merged];
          failed = failed || !m.ok;
          if (!failed) {
            for (std::size_t i = 0; i < m.t.size() && increasing; ++i) {
              increasing = (rows == 0 && i == 0) || m.t[i] > prev;
              prev = m.t[i];
            }
            raw->insert(raw->end(), m.t.begin(), m.t.end());
            rows += m.rows;
          }
          std::vector<double>().swap(m.t);
          ++merged;
        }
        if (failed || !increasing) stop = true;
      };
      const auto page = static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE));
      auto work = [&] {
        std::vector<double> v(std::max<std::size_t>(1, like.selected().size()));
        for (std::size_t k; !stop && (k = next++) < pieces;) {
          Part& pc = piece[k];
          // the piece's whole lines mapped (no copy of the text; unmapped when parsed, so the
          // file's pages stay out of the process's memory)
          const std::uint64_t from = start[k] / page * page;
          const auto len = static_cast<std::size_t>(start[k + 1] - from);
          void* map = ::mmap(nullptr, len, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd,
                             static_cast<off_t>(from));
          if (map == MAP_FAILED) {
            pc.ok = false;
          } else {
            try {
              exid::CsvReader r(std::string_view(static_cast<const char*>(map) + (start[k] - from),
                                                 static_cast<std::size_t>(start[k + 1] - start[k])),
                                like, 0);
              while (r.next(v.data())) {
                ++pc.rows;
                if (ct_) {
                  if (!std::isfinite(v[0])) throw exid::Error("not finite");
                  pc.t.push_back(v[0]);
                }
              }
            } catch (const std::exception&) {
              pc.ok = false;
            }
            ::munmap(map, len);
          }
          std::lock_guard<std::mutex> lock(mu);
          try {
            merge(k);
          } catch (...) {   // (no room for the stamps: the serial scan says so; a thread never
            failed = true;  // lets an exception out)
            stop = true;
          }
        }
      };
      std::size_t used = 1;
      {
        std::vector<std::thread> pool;
        for (int i = 1; i < threads && static_cast<std::size_t>(i) < pieces; ++i) {
          try {
            pool.emplace_back(work);
          } catch (const std::system_error&) {  // (no more threads: fewer do the pieces)
            break;
          }
        }
        used += pool.size();
        work();
        for (std::thread& t : pool) t.join();
      }
      if (failed || !increasing || merged < pieces || rows == 0) {
        std::vector<double>().swap(*raw);
        return false;
      }
      rows_ = static_cast<int>(rows);
      kept_rows_ = rows;
      t_first_abs_ = ct_ ? tfactor_ * (*raw)[0] : 0.0;
      scan_pieces_ = static_cast<int>(pieces);
      scan_threads_ = static_cast<int>(used);
      return true;
    }

    // The file row of each kept row, only when rows were dropped (else empty).
    std::vector<int> keptFileRows() const {
      std::vector<int> keep;
      if (!dropped_rows_.empty()) {
        keep.reserve(static_cast<std::size_t>(kept_rows_));
        for (long i = 0, r = 0, d = 0; i < kept_rows_; ++r) {
          if (d < static_cast<long>(dropped_rows_.size()) &&
              dropped_rows_[static_cast<std::size_t>(d)] == r) {
            ++d;
            continue;
          }
          keep.push_back(static_cast<int>(r));
          ++i;
        }
      }
      return keep;
    }

    // Gaps and uneven stamps: one behaviour, refused with the place (a filter, a derivative
    // and an energy integral all assume a uniform rate). Steps across dropped rows count per
    // row.
    void checkUniformSteps(const ScanRows& s) const {
      if (!ct_ || s.raw.size() < 3) return;
      // step i: from kept row i to i + 1, per file row (computed where needed, never held:
      // the stamps are the scan's one array)
      auto stepAt = [&](std::size_t i) {
        return (timeOf(s, static_cast<long>(i + 1)) - timeOf(s, static_cast<long>(i))) /
               static_cast<double>(rowOf(s, i + 1) - rowOf(s, i));
      };
      const std::size_t nsteps = s.raw.size() - 1;
      const double med = exid::medianOfValues(nsteps, stepAt);
      const double ratio = P_.getDouble("max_gap_ratio");
      const bool resample = P_.getDouble("resample_hz") > 0.0;
      for (std::size_t i = 0; i < nsteps; ++i) {
        const double step = stepAt(i);
        if (!(step <= ratio * med && (resample || step >= med / ratio)))
          throw exid::Error(fmt::format(
              "experiment 'csv': {}: {} (data row {}): time step {} s "
              "against a median step of {} s: {} (a filter, derivatives and "
              "energy integrals need a uniform rate); {} (max_gap_ratio = {})",
              files_[0], lineText(rowOf(s, i + 1)), rowOf(s, i + 1) + 1, step, med,
              step > med ? "a gap" : "uneven time stamps",
              step > med ? "resample the recording onto a uniform grid (resample_hz; a gap "
                           "is then bridged by interpolation), or cut the recording there "
                           "with t_start_s/t_end_s"
                         : "resample the recording onto a uniform grid (resample_hz), or "
                           "cut the recording there with t_start_s/t_end_s",
              ratio));
      }
    }

    // Segment (inside the recording, never clamped) and its split into an identification and
    // a validation part (half-open at the split point: no sample belongs to both).
    void selectSegment(const ScanRows& s) {
      const std::string& file = files_[0];
      const double tfirst = t_first_abs_;
      span_ = timeOf(s, kept_rows_ - 1) - tfirst;
      const double step_tol =
          kept_rows_ > 1 ? 0.5 * span_ / static_cast<double>(kept_rows_ - 1) : 0.0;
      seg_ = exid::resolveSegment(P_, span_, step_tol, "experiment 'csv': ", file);
      ts_ = seg_.t_start_s;
      te_ = seg_.t_end_s;
      part_ = seg_.part;
      seg_end_ = seg_.end_s;
      tsplit_ = seg_.split_s;
      const double lo = seg_.lo_s;
      const double hi = seg_.hi_s;
      // the samples: kept rows [i0_, i1_) (time increases, so the selection is one range)
      i0_ = -1;
      i1_ = -1;
      in_segment_ = 0;
      for (long i = 0; i < kept_rows_; ++i) {
        const double rel = timeOf(s, i) - tfirst;
        if (rel < ts_) continue;
        if (te_ > 0.0 && rel > te_) break;
        ++in_segment_;
        if (rel < lo || (part_ == "identification" && rel >= hi)) continue;
        if (i0_ < 0) i0_ = i;
        i1_ = i + 1;
      }
      exid::check(i0_ >= 0, fmt::format("experiment 'csv': {}: no sample in the segment [{}, {}] s "
                                        "after the first sample (t = {} s; the file spans {} s)",
                                        file, lo, part_ == "none" ? te_ : hi, tfirst, span_));
      if (i0_ < 0) i0_ = i1_ = 0;
      t_first_ = timeOf(s, i0_);
      t_last_ = timeOf(s, i1_ - 1);
    }

    // The samples' sampling rate as exid::samplingRate computes it on a pass's t (the same
    // differences of the same doubles, the same median): samplingRate() without a pass.
    void scanSamplingRate(const ScanRows& s) {
      has_rate_ = false;
      if (i1_ - i0_ >= 3) {
        auto dtAt = [&](std::size_t k) {
          const long i = i0_ + static_cast<long>(k);
          return timeOf(s, i + 1) - timeOf(s, i);
        };
        const auto nd = static_cast<std::size_t>(i1_ - i0_ - 1);
        bool increasing = true;
        for (std::size_t k = 0; k < nd && increasing; ++k) increasing = dtAt(k) > 0;
        if (increasing) {
          const double med = exid::medianOfValues(nd, dtAt);
          double jit = 0.0;
          for (std::size_t k = 0; k < nd; ++k) jit = std::max(jit, std::abs(dtAt(k) - med) / med);
          fs_hz_ = 1.0 / med;
          jitter_ = jit;
          has_rate_ = true;
        }
      }
    }

    // Recording statistics: the timing now; the rest after the first whole pass. The samples'
    // stamps are cut out of s->raw in place.
    void recordTiming(ScanRows* s) {
      recording_ = exid::Json::object();
      recording_["file"] = files_[0];
      recording_["rows"] = static_cast<long long>(i1_ - i0_);
      if (ct_) {
        std::vector<double>& raw = s->raw;
        raw.erase(raw.begin() + i1_, raw.end());  // the samples' stamps, in place
        raw.erase(raw.begin(), raw.begin() + i0_);
        std::vector<int> sel_rows;
        if (!s->keep.empty()) sel_rows.assign(s->keep.begin() + i0_, s->keep.begin() + i1_);
        exid::Json t = exid::samplingStats(raw, tfactor_, sel_rows, P_.getDouble("max_gap_ratio"));
        t["source"] = fmt::format("time column '{}'", tname_);
        recording_["timing"] = t;
      } else {
        exid::Json t = exid::Json::object();
        t["source"] = "sample_period_s";
        t["rate_hz"] = exid::rateFromPeriod(dt_);
        t["period_s"] = dt_;
        t["jitter"]["std_rel"] = 0.0;
        t["jitter"]["max_rel"] = 0.0;
        t["gaps"]["count"] = 0;
        recording_["timing"] = t;
      }
    }

    // ---- a pass
    void sizeChunk(int want, exid::Dataset* chunk) const {
      chunk->t.resize(want);
      chunk->q.resize(want, n_);
      chunk->qd.resize(pqd_.empty() ? 0 : want, pqd_.empty() ? 0 : n_);
      chunk->qdd.resize(pqdd_.empty() ? 0 : want, pqdd_.empty() ? 0 : n_);
      chunk->tau.resize(ptau_.empty() ? 0 : want, ptau_.empty() ? 0 : n_);
      chunk->wrench.resize(pw_.empty() ? 0 : want, pw_.empty() ? 0 : 6);
      chunk->source = files_[0];
    }

    // The file rows from data row `from` on that hold the next m kept rows (the dropped rows
    // among them counted, from the scan's list); advances dptr_ past those dropped rows.
    int fileRowsFor(long from, long m) {
      long r = from;
      const long start = r;
      long kept = 0;
      while (kept < m) {
        if (dptr_ < dropped_rows_.size()) {
          const long d = dropped_rows_[dptr_];
          if (d < r) {
            ++dptr_;
            continue;
          }
          // kept rows up to the next dropped one
          const long run = std::min(m - kept, d - r);
          kept += run;
          r += run;
          if (kept < m && r == d) {
            ++dptr_;
            ++r;
          }
        } else {
          r += m - kept;
          kept = m;
        }
      }
      return static_cast<int>(r - start);
    }

    // The next kept row into uv_ (its file row in row_, its kept index in kept_); false at the
    // end of the file. A bad value is an error, or the row is skipped as the scan dropped it.
    bool nextKeptRow() {
      while (true) {
        if (!readRow(readers_)) return false;
        ++row_;
        const int bad = badColumn();
        if (bad >= 0) {
          if (!drop_) badValue(readers_, bad, row_);
          continue;  // the scan dropped it (the same rule on the same values)
        }
        ++kept_;
        return true;
      }
    }

    void convert(int k, exid::Dataset* d) { convert(k, uv_.data(), row_, d, &tau_); }
    // Used values uv of file data row `row` into sample k of *d (tau: a work vector).
    void convert(int k, const double* uv, int row, exid::Dataset* d, Eigen::VectorXd* tau) const {
      const int n = n_;
      d->t[k] = ct_ ? tfactor_ * uv[static_cast<std::size_t>(pt_)] : row * dt_;
      for (int j = 0; j < n; ++j) {
        const auto u = static_cast<std::size_t>(j);
        const double s = sign_[u];
        d->q(k, j) = s * qscale_[u] * uv[static_cast<std::size_t>(pq_[u])] + off_[u];
        if (!pqd_.empty()) d->qd(k, j) = s * qdscale_[u] * uv[static_cast<std::size_t>(pqd_[u])];
        if (!pqdd_.empty()) d->qdd(k, j) = s * qdscale_[u] * uv[static_cast<std::size_t>(pqdd_[u])];
      }
      if (!ptau_.empty()) {
        tau->resize(n);
        for (int j = 0; j < n; ++j) {
          const auto u = static_cast<std::size_t>(j);
          double v = uv[static_cast<std::size_t>(ptau_[u])];
          if (!Kt_.empty()) v *= Kt_[u];
          (*tau)[j] = v;
        }
        if (!Kt_.empty() && joint_frame_ && robot_->hasTransmission())
          *tau = robot_->transmission.transpose() * *tau;
        for (int j = 0; j < n; ++j)
          d->tau(k, j) = sign_[static_cast<std::size_t>(j)] *
                         tauscale_[static_cast<std::size_t>(j)] * (*tau)[j];
      }
      for (std::size_t e = 0; e < pw_.size(); ++e)
        d->wrench(k, static_cast<Eigen::Index>(e)) =
            wscale_[e] * uv[static_cast<std::size_t>(pw_[e])];
    }

    void collect(const exid::Dataset& chunk, int k) {
      const Eigen::Index i = taken_ / stride_;
      if (i == 0) {  // sized once: samples 0, stride, 2 stride, ... of the pass
        const Eigen::Index M = (size() + stride_ - 1) / stride_;
        collected_.t.resize(M);
        collected_.q.resize(M, n_);
        collected_.qd.resize(pqd_.empty() ? 0 : M, pqd_.empty() ? 0 : n_);
        collected_.qdd.resize(pqdd_.empty() ? 0 : M, pqdd_.empty() ? 0 : n_);
        collected_.tau.resize(ptau_.empty() ? 0 : M, ptau_.empty() ? 0 : n_);
        collected_.wrench.resize(pw_.empty() ? 0 : M, pw_.empty() ? 0 : 6);
      }
      auto row = [&](Eigen::MatrixXd* dst, const Eigen::MatrixXd& src) {
        if (src.cols() > 0) dst->row(i) = src.row(k);
      };
      collected_.t[i] = chunk.t[k];
      row(&collected_.q, chunk.q);
      row(&collected_.qd, chunk.qd);
      row(&collected_.qdd, chunk.qdd);
      row(&collected_.tau, chunk.tau);
      row(&collected_.wrench, chunk.wrench);
    }

    void finishPass() {
      if (!collecting_ || stats_done_) return;
      stats_->finish(&recording_, tau_names_);
      stats_done_ = true;
      collecting_ = false;
      collected_.source = files_[0];
      collected_.meta = meta();
    }

    exid::ParamSet P_;
    std::shared_ptr<const exid::RobotModel> robot_;
    int n_ = 0;
    std::vector<std::string> files_;
    std::vector<std::vector<std::string>> columns_;
    std::vector<Ref> used_;                         // q, qd, qdd, tau, wrench, t
    std::vector<int> pq_, pqd_, pqdd_, ptau_, pw_;  // positions in used_
    int pt_ = -1;
    bool ct_ = false;                        // a time column
    std::vector<std::vector<int>> select_;   // per source: the columns it reads
    std::vector<Ref> slot_;                  // per used column: (source, place in its values)
    std::vector<std::vector<double>> vals_;  // per source: one row's values
    std::vector<double> uv_;                 // one row's used values
    std::vector<std::string> tau_names_;
    std::vector<double> qscale_, qdscale_, tauscale_, wscale_, sign_, off_, Kt_;
    Eigen::VectorXd tau_;
    bool joint_frame_ = false, drop_ = false;
    double tfactor_ = 1.0, dt_ = 0.0;
    std::string tname_, tunit_, tfrom_, part_;
    // the scan
    int rows_ = 0, dropped_ = 0;
    long kept_rows_ = 0;
    int scan_pieces_ = 1, scan_threads_ = 1;  // how the scan read the file (scanInPieces)
    std::vector<int> dropped_rows_;
    long i0_ = 0, i1_ = 0;
    int in_segment_ = 0;
    double ts_ = 0, te_ = 0, tsplit_ = 0, seg_end_ = 0, span_ = 0;
    exid::RecordingSegment seg_;
    double t_first_abs_ = 0, t_first_ = 0, t_last_ = 0;
    bool has_rate_ = false;  // samplingRate(): known from the scan
    double fs_hz_ = 0, jitter_ = 0;
    exid::Json recording_;
    // a pass
    std::vector<std::unique_ptr<exid::CsvReader>> readers_;
    std::vector<std::unique_ptr<exid::CsvReader>> protos_;  // never read: decode()'s template
    int row_ = -1;
    long kept_ = -1;
    std::size_t dptr_ = 0;  // fetch(): dropped_rows_ before row_ + 1
    long settled_ = 0;      // samples of the pass settled
    std::unique_ptr<RecordingStats> stats_;
    bool stats_done_ = false, collecting_ = false;
    int stride_ = 0;  // collectEvery(); 0: nothing kept
    long taken_ = 0;
    exid::Dataset collected_;
  };

  /// Optional: zero-phase low-pass of q (and tau, wrench), central differences, trim, decimate.
  Preprocessed preprocess(exid::Dataset* d, const std::string& file) const {
    Preprocessed pp;
    pp.cutoff_hz = P_.getDouble("differentiate_cutoff_hz");
    pp.order = static_cast<int>(P_.getInt("filter_order"));
    pp.filter_torque = P_.getBool("filter_torque");
    pp.decimation = static_cast<int>(P_.getInt("decimation"));
    if (pp.cutoff_hz <= 0) {
      exid::check(
          pp.decimation == 1 && !pp.filter_torque,
          "experiment 'csv': decimation and filter_torque need differentiate_cutoff_hz > 0");
      return pp;
    }
    exid::check(pp.decimation == 1 || pp.filter_torque,
                "experiment 'csv': decimation > 1 needs filter_torque: true (the torque must be "
                "low-passed before samples are dropped)");
    const Eigen::Index K = d->size();
    exid::check(K >= 8,
                fmt::format("experiment 'csv': {}: {} samples in the segment are too few to "
                            "filter and differentiate",
                            file, K));
    double jitter = 0;
    pp.fs = exid::samplingRate(d->t, &jitter);
    exid::check(pp.cutoff_hz < 0.5 * pp.fs,
                fmt::format("experiment 'csv': differentiate_cutoff_hz = {} Hz must be below the "
                            "Nyquist frequency {} Hz of the data",
                            pp.cutoff_hz, 0.5 * pp.fs));
    exid::check(pp.decimation == 1 || pp.cutoff_hz < 0.5 * pp.fs / pp.decimation,
                fmt::format("experiment 'csv': decimation {} leaves a Nyquist frequency of {} Hz, "
                            "below differentiate_cutoff_hz = {} Hz (aliasing)",
                            pp.decimation, 0.5 * pp.fs / pp.decimation, pp.cutoff_hz));
    const exid::Sos sos = exid::butterworthLowpass(pp.order, pp.cutoff_hz, pp.fs);
    d->q = exid::filtfiltColumns(sos, d->q);
    d->qd = exid::centralFirstDerivative(d->t, d->q);
    d->qdd = exid::centralSecondDerivative(d->t, d->q);
    if (pp.filter_torque) {
      if (d->hasTorque()) d->tau = exid::filtfiltColumns(sos, d->tau);
      if (d->hasWrench()) d->wrench = exid::filtfiltColumns(sos, d->wrench);
    }
    // Default trim: the filter's edge transient, 2 fs / fc samples (two periods of the cut-off)
    // at each end, but at most 5 % of the segment at each end, so that a default never discards
    // more than 10 % of a short recording (the zero-phase filter pads its ends by reflection:
    // what is left of the transient there is small). fs is the median step's rate, rounded to
    // the file's resolution (a 100 Hz log is 100 Hz, not 100.0000001: 2 fs / fc = 100, not 101).
    // Every count in double first: ceil(2 fs / cutoff) of a tiny cut-off, or a huge trim_edges,
    // does not fit an int (it was narrowed, wrapped and indexed before the data); a transient
    // longer than the whole segment leaves nothing the filter has not smeared.
    const std::int64_t trim_p = P_.getInt("trim_edges");
    const double transient = 2.0 * pp.fs / pp.cutoff_hz;
    exid::check(std::isfinite(transient) && transient <= static_cast<double>(K),
                fmt::format("experiment 'csv': {}: differentiate_cutoff_hz = {} Hz is too low for "
                            "the {} samples of the segment at {} Hz: its edge transient 2 fs / fc "
                            "= {:g} samples is longer than the segment; raise the cut-off",
                            file, pp.cutoff_hz, K, pp.fs, transient));
    pp.trim_transient = static_cast<int>(std::ceil(transient - 1e-6 * std::max(1.0, transient)));
    pp.trim_cap = static_cast<int>(std::floor(0.05 * static_cast<double>(K)));
    pp.trim_default = trim_p < 0;
    const double trim = trim_p >= 0 ? static_cast<double>(trim_p)
                                    : static_cast<double>(std::min(pp.trim_transient, pp.trim_cap));
    exid::check(
        static_cast<double>(K) - 2.0 * trim >= 2.0,
        fmt::format("experiment 'csv': {}: trimming {} samples at each end of the {} of the "
                    "segment leaves too few ({}); lower trim_edges or raise "
                    "differentiate_cutoff_hz = {} Hz",
                    file, trim, K,
                    trim_p >= 0 ? "trim_edges" : "trim_edges: -1 trims ceil(2 fs / cutoff)",
                    pp.cutoff_hz));
    pp.trim = static_cast<int>(trim);
    pp.samples_before_trim = static_cast<int>(K);
    for (const Eigen::MatrixXd* M : {&d->q, &d->qd, &d->qdd})
      exid::check(M->allFinite(),
                  fmt::format("experiment 'csv': {}: the low-pass filter (differentiate_cutoff_hz "
                              "= {} Hz, filter_order {}, sample rate {} Hz) gave non-finite "
                              "values; raise the cut-off",
                              file, pp.cutoff_hz, pp.order, pp.fs));
    std::vector<Eigen::Index> keep;
    for (Eigen::Index k = pp.trim; k < K - pp.trim; k += pp.decimation) keep.push_back(k);
    auto pick = [&](const Eigen::MatrixXd& M) {
      Eigen::MatrixXd out(static_cast<Eigen::Index>(keep.size()), M.cols());
      for (std::size_t i = 0; i < keep.size(); ++i)
        out.row(static_cast<Eigen::Index>(i)) = M.row(keep[i]);
      return out;
    };
    Eigen::VectorXd t(static_cast<Eigen::Index>(keep.size()));
    for (std::size_t i = 0; i < keep.size(); ++i) t[static_cast<Eigen::Index>(i)] = d->t[keep[i]];
    d->t = t;
    d->q = pick(d->q);
    d->qd = pick(d->qd);
    d->qdd = pick(d->qdd);
    if (d->tau.rows() > 0) d->tau = pick(d->tau);
    if (d->wrench.rows() > 0) d->wrench = pick(d->wrench);
    return pp;
  }

  exid::ParamSet P_;
};

}  // namespace

EXID_REGISTER_PLUGIN(CsvExperiment)
