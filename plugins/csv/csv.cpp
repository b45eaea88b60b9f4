// exid — experiment `csv`: a recorded (or previously written) dataset read from a CSV file with
// the columns of docs/conventions.md §1: t, q1..qn, qd1..qdn, qdd1..qddn, tau1..taun, fx..mz.
// q is required; every other group is optional but complete when present (all n joints, or all
// six wrench components). Absent qd/qdd stay absent: estimators decide how to differentiate.
// The file written by the runner (experiment.csv, exid::datasetTable) reads back exactly.
// Extensions for recordings as published (docs/experiments.md): other column names
// (q_columns, tau_columns), torques from a second row-aligned file (torque_file), and optional
// zero-phase low-pass + central differences (+ decimation) of the segment.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"

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
    return {
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
        param_doubles("wrench_scale", std::vector<double>{}, "",
                      "6 values multiplying fx fy fz mx my mz (a unit, a sign); empty: 1"),
        param_double("max_gap_ratio", 1.5, "",
                     "a time step longer than this times the median step (a gap), or shorter "
                     "than its inverse (uneven stamps), is an error naming the rows",
                     1.0, std::nullopt, true),
        param_double("t_start_s", 0.0, "s",
                     "segment start, in seconds after the first sample's time", 0.0),
        param_double("t_end_s", 0.0, "s",
                     "segment end, in seconds after the first sample's time; 0: to the end", 0.0),
        param_string("split_part", std::string("none"),
                     "none: the whole segment; identification / validation: the part of the "
                     "segment before / after the split point (split_fraction or split_at_s; the "
                     "study key `split` sets these); each part is filtered on its own, so no "
                     "sample of one touches the other",
                     {"none", "identification", "validation"}),
        param_double("split_fraction", 0.0, "",
                     "with split_part: the split point as a fraction of the segment's duration "
                     "(e.g. 0.65: identification = first 65 %); 0: use split_at_s",
                     0.0, 1.0, false, true),
        param_double("split_at_s", 0.0, "s",
                     "with split_part: the split point in seconds after the segment's start; "
                     "0: use split_fraction",
                     0.0),
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
        param_int("trim_edges", -1,
                  "samples dropped at each end of the segment after filtering; -1: "
                  "ceil(2 fs / cutoff) when filtering, else 0",
                  -1, 1e9),
    };
  }

  explicit CsvExperiment(const exid::ParamSet& p) : P_(p) {}

  exid::Dataset run(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples*,
                    const exid::RunContext& ctx) override {
    exid::check(robot != nullptr, "experiment 'csv': no robot");
    const int n = robot->dof();

    // Per file: its table (only the columns the experiment can use are read: see usable) and
    // the file line of every data row.
    struct Source {
      std::string file;
      std::vector<int> line_of;
      exid::CsvTable T;
    };
    // A column the experiment may use: the time column, q_columns / tau_columns, a wrench
    // component, or a group's prefix followed by digits (q1.., qd.., qdd.., tau.., currents).
    // The others are never converted (a column of labels nobody uses is not an error).
    const std::string time_name = P_.getString("time_column");
    const std::vector<std::string> named_q = P_.getStrings("q_columns");
    const std::vector<std::string> named_tau = P_.getStrings("tau_columns");
    const std::vector<std::string> prefixes = {"q", "qd", "qdd", "tau",
                                               P_.getString("current_prefix")};
    auto usable = [&](const std::string& c) {
      if (c == time_name) return true;
      for (const auto* v : {&named_q, &named_tau})
        if (std::find(v->begin(), v->end(), c) != v->end()) return true;
      for (const char* w : {"fx", "fy", "fz", "mx", "my", "mz"})
        if (c == w) return true;
      for (const std::string& pre : prefixes)
        if (c.size() > pre.size() && c.compare(0, pre.size(), pre) == 0 &&
            c.find_first_not_of("0123456789", pre.size()) == std::string::npos)
          return true;
      return false;
    };
    auto readSource = [&](fs::path p) {
      if (p.is_relative() && !ctx.study_dir.empty()) p = ctx.study_dir / p;
      Source src;
      src.file = p.string();
      exid::CsvReadOptions opt;
      opt.allow_non_finite = true;  // checked below, only in the columns used
      opt.text_columns = true;      // a column of labels nobody uses is not an error
      exid::CsvReader reader(p, opt, "CSV data");
      src.T = exid::readCsvColumns(reader, usable);
      src.line_of = std::move(src.T.line_of);
      exid::check(src.T.data.rows() > 0,
                  fmt::format("experiment 'csv': {}: no data rows after the header", src.file));
      return src;
    };
    std::vector<Source> srcs;
    srcs.reserve(2);  // references into srcs[0] are taken below
    srcs.push_back(readSource(P_.getString("file")));
    const std::string file = srcs[0].file;
    const exid::CsvTable& T = srcs[0].T;
    const int rows = static_cast<int>(T.data.rows());
    int fq = 0, ftau = 0;  // which source holds q / the torques
    if (!P_.getString("torque_file").empty()) {
      srcs.push_back(readSource(P_.getString("torque_file")));
      ftau = 1;
      const int tau_rows = static_cast<int>(srcs[1].T.data.rows());
      if (tau_rows != rows) {
        // The place: the first data row of the longer file that has no counterpart.
        const Source& longer = srcs[tau_rows > rows ? 1 : 0];
        const int k = std::min(rows, tau_rows);
        const int line = k < static_cast<int>(longer.line_of.size())
                             ? longer.line_of[static_cast<std::size_t>(k)]
                             : 0;
        throw exid::Error(fmt::format(
            "experiment 'csv': torque_file {} has {} data rows, file {} has {}: the two files "
            "must be row-aligned ({}: data row {} at line {} has no counterpart)",
            srcs[1].file, tau_rows, file, rows, longer.file, k + 1, line));
      }
    }
    // Columns as (source, column) references, flattened: ref = source * kStride + column.
    constexpr int kStride = 1 << 20;
    auto value = [&](int r, int ref) {
      const exid::CsvTable& Ts = srcs[static_cast<std::size_t>(ref / kStride)].T;
      return Ts.data(r, Ts.dataCol(ref % kStride));
    };
    auto colName = [&](int ref) {
      const Source& sr = srcs[static_cast<std::size_t>(ref / kStride)];
      return srcs.size() > 1
                 ? fmt::format("{}' of {}", sr.T.columns[static_cast<std::size_t>(ref % kStride)],
                               sr.file)
                 : sr.T.columns[static_cast<std::size_t>(ref % kStride)] + "'";
    };
    auto named = [&](int f, const char* key) -> std::vector<int> {
      std::vector<int> idx;
      const std::vector<std::string> names = P_.getStrings(key);
      if (names.empty()) return idx;
      const Source& sr = srcs[static_cast<std::size_t>(f)];
      exid::check(static_cast<int>(names.size()) == n,
                  fmt::format("experiment 'csv': {}: expected {} names (one per joint of robot "
                              "'{}'), found {}",
                              key, n, robot->name, names.size()));
      for (std::size_t a = 0; a < names.size(); ++a)
        for (std::size_t b = 0; b < a; ++b)
          exid::check(names[a] != names[b],
                      fmt::format("experiment 'csv': {}: column '{}' is named twice (elements {} "
                                  "and {}); each joint needs its own column",
                                  key, names[a], b + 1, a + 1));
      for (const auto& c : names) {
        const int i = sr.T.col(c);
        exid::check(i >= 0,
                    fmt::format("experiment 'csv': {}: {}: no column '{}' (found columns: {})",
                                sr.file, key, c, fmt::join(sr.T.columns, ", ")));
        idx.push_back(f * kStride + i);
      }
      return idx;
    };

    // Column groups.
    auto group = [&](const std::string& prefix, bool required, const char* what,
                     int f = 0) -> std::vector<int> {
      const exid::CsvTable& Tg = srcs[static_cast<std::size_t>(f)].T;
      const std::string& fileg = srcs[static_cast<std::size_t>(f)].file;
      std::vector<int> idx;
      int found = 0;
      while (Tg.has(prefix + std::to_string(found + 1))) ++found;
      if (found == 0) {
        exid::check(!required, fmt::format("experiment 'csv': {}: missing column '{}1' ({}; "
                                           "expected columns {}1..{}{} for the {} joints of robot "
                                           "'{}'; found columns: {})",
                                           fileg, prefix, what, prefix, prefix, n, n, robot->name,
                                           fmt::join(Tg.columns, ", ")));
        return idx;
      }
      exid::check(
          found == n,
          fmt::format("experiment 'csv': {}: wrong joint count: found columns {}1..{}{} "
                      "({} joints), expected {}1..{}{} for robot '{}' ({} joints)",
                      fileg, prefix, prefix, found, found, prefix, prefix, n, robot->name, n));
      for (int j = 1; j <= n; ++j) idx.push_back(f * kStride + Tg.col(prefix + std::to_string(j)));
      return idx;
    };
    std::vector<int> cq = named(fq, "q_columns");
    if (cq.empty()) cq = group("q", true, "joint positions are required", fq);
    const std::vector<int> cqd = group("qd", false, "");
    const std::vector<int> cqdd = group("qdd", false, "");
    const std::string tfrom = P_.getString("torque_from");
    std::vector<int> ctau;
    std::vector<double> Kt;
    ctau = named(ftau, "tau_columns");
    if (tfrom == "tau") {
      if (ctau.empty()) ctau = group("tau", ftau > 0, "torque_file is given", ftau);
    } else {
      const std::string pre = P_.getString("current_prefix");
      if (ctau.empty())
        ctau = group(pre, true, "torque_from: current needs the motor currents", ftau);
      Kt = P_.getDoubles("torque_constants_Nm_per_A");
      exid::check(
          static_cast<int>(Kt.size()) == n,
          fmt::format("experiment 'csv': torque_constants_Nm_per_A: expected {} values (one "
                      "per joint of robot '{}'), found {}",
                      n, robot->name, Kt.size()));
    }
    std::vector<int> cw;
    {
      const char* wn[6] = {"fx", "fy", "fz", "mx", "my", "mz"};
      int present = 0;
      for (const char* c : wn) present += T.has(c);
      if (present > 0) {
        std::vector<std::string> missing;
        for (const char* c : wn)
          if (!T.has(c)) missing.push_back(c);
        exid::check(missing.empty(),
                    fmt::format("experiment 'csv': {}: incomplete wrench: missing column(s) {} "
                                "(expected all of fx fy fz mx my mz, or none)",
                                file, fmt::join(missing, ", ")));
        for (const char* c : wn) cw.push_back(T.col(c));  // source 0
      }
    }
    const std::string tname = P_.getString("time_column");
    const int ct = T.col(tname);
    const double dt = P_.getDouble("sample_period_s");
    exid::check(ct >= 0 || dt > 0,
                fmt::format("experiment 'csv': {}: no time column '{}' and no sample_period_s: "
                            "exid does not guess the sample rate; give time_column (the name of "
                            "the time column, with time_unit) or sample_period_s (found columns: "
                            "{})",
                            file, tname, fmt::join(T.columns, ", ")));
    const std::string tunit = P_.getString("time_unit");
    const double tfactor = tunit == "ms" ? 1e-3 : tunit == "us" ? 1e-6 : tunit == "ns" ? 1e-9 : 1.0;
    // Per-signal scales (a unit, a sign of one signal alone).
    auto perJoint = [&](const char* key, std::vector<double> v, double dflt) {
      if (v.empty()) v.assign(static_cast<std::size_t>(n), dflt);
      exid::check(static_cast<int>(v.size()) == n,
                  fmt::format("experiment 'csv': {}: expected {} values (one per joint of robot "
                              "'{}'), found {}",
                              key, n, robot->name, v.size()));
      for (double x : v)
        exid::check(std::isfinite(x) && x != 0.0,
                    fmt::format("experiment 'csv': {}: {} is not a usable scale", key, x));
      return v;
    };
    const std::vector<double> qscale = perJoint("q_scale", P_.getDoubles("q_scale"), 1.0);
    const std::vector<double> qdscale = P_.getDoubles("qd_scale").empty()
                                            ? qscale
                                            : perJoint("qd_scale", P_.getDoubles("qd_scale"), 1.0);
    const std::vector<double> tauscale = perJoint("tau_scale", P_.getDoubles("tau_scale"), 1.0);
    std::vector<double> wscale = P_.getDoubles("wrench_scale");
    if (wscale.empty()) wscale.assign(6, 1.0);
    exid::check(wscale.size() == 6,
                fmt::format("experiment 'csv': wrench_scale: expected 6 values (fx fy fz mx my "
                            "mz), found {}",
                            wscale.size()));
    for (double x : wscale)
      exid::check(std::isfinite(x) && x != 0.0,
                  fmt::format("experiment 'csv': wrench_scale: {} is not a usable scale", x));

    // Per-joint sign and offset.
    std::vector<double> sign = P_.getDoubles("sign"), off = P_.getDoubles("offset_rad");
    if (sign.empty()) sign.assign(static_cast<std::size_t>(n), 1.0);
    if (off.empty()) off.assign(static_cast<std::size_t>(n), 0.0);
    exid::check(static_cast<int>(sign.size()) == n,
                fmt::format("experiment 'csv': sign: expected {} values (one per joint), found {}",
                            n, sign.size()));
    exid::check(
        static_cast<int>(off.size()) == n,
        fmt::format("experiment 'csv': offset_rad: expected {} values (one per joint), found {}", n,
                    off.size()));
    for (int j = 0; j < n; ++j)
      exid::check(
          sign[static_cast<std::size_t>(j)] == 1.0 || sign[static_cast<std::size_t>(j)] == -1.0,
          fmt::format("experiment 'csv': sign: joint {}: expected +1 or -1, found {}", j + 1,
                      sign[static_cast<std::size_t>(j)]));

    // Rows: bad values in the used columns, time.
    std::vector<int> used = cq;
    for (const std::vector<int>* g : {&cqd, &cqdd, static_cast<const std::vector<int>*>(&ctau),
                                      static_cast<const std::vector<int>*>(&cw)})
      used.insert(used.end(), g->begin(), g->end());
    if (ct >= 0) used.push_back(ct);
    // Text in a column that is used is an error at its first such cell (never a dropped row).
    for (int c : used) {
      const std::string& why =
          srcs[static_cast<std::size_t>(c / kStride)].T.notNumeric(c % kStride);
      if (!why.empty()) throw exid::Error("experiment 'csv': " + why);
      exid::check(srcs[static_cast<std::size_t>(c / kStride)].T.dataCol(c % kStride) >= 0,
                  "experiment 'csv': internal error: a column used was not read");
    }
    const bool drop = P_.getBool("drop_bad_rows");
    std::vector<int> keep;
    std::vector<double> tk;
    int dropped = 0;
    auto lineText = [&](int r, int f = 0) {
      const std::vector<int>& line_of = srcs[static_cast<std::size_t>(f)].line_of;
      return r < static_cast<int>(line_of.size())
                 ? fmt::format("line {}", line_of[static_cast<std::size_t>(r)])
                 : fmt::format("data row {}", r + 1);
    };
    for (int r = 0; r < rows; ++r) {
      int bad = -1;
      for (int c : used)
        if (!std::isfinite(value(r, c))) {
          bad = c;
          break;
        }
      if (bad >= 0) {
        if (drop) {
          ++dropped;
          continue;
        }
        const int bf = bad / kStride;
        throw exid::Error(fmt::format(
            "experiment 'csv': {}: {} (data row {}): column '{}: missing or non-finite value (set "
            "drop_bad_rows: true to drop such rows)",
            srcs[static_cast<std::size_t>(bf)].file, lineText(r, bf), r + 1, colName(bad)));
      }
      const double t = ct >= 0 ? tfactor * value(r, ct) : r * dt;
      if (!keep.empty())
        exid::check(
            t > tk.back(),
            fmt::format("experiment 'csv': {}: {} (data row {}): column '{}': time must "
                        "strictly increase; t = {} s after t = {} s at {}",
                        file, lineText(r), r + 1, tname, t, tk.back(), lineText(keep.back())));
      keep.push_back(r);
      tk.push_back(t);
    }
    exid::check(!keep.empty(),
                fmt::format("experiment 'csv': {}: every row was dropped ({} with bad "
                            "values)",
                            file, dropped));

    // Gaps and uneven stamps: one behaviour, refused with the place (a filter, a derivative and
    // an energy integral all assume a uniform rate).
    if (ct >= 0 && tk.size() >= 3) {
      // per row of the file: a step across rows dropped for bad values spans that many rows
      std::vector<double> steps(tk.size() - 1);
      for (std::size_t i = 1; i < tk.size(); ++i)
        steps[i - 1] = (tk[i] - tk[i - 1]) / static_cast<double>(keep[i] - keep[i - 1]);
      std::vector<double> sorted = steps;
      std::nth_element(sorted.begin(),
                       sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                       sorted.end());
      const double med = sorted[sorted.size() / 2];
      const double ratio = P_.getDouble("max_gap_ratio");
      const bool resample = P_.getDouble("resample_hz") > 0.0;
      for (std::size_t i = 0; i < steps.size(); ++i)
        exid::check(steps[i] <= ratio * med && (resample || steps[i] >= med / ratio),
                    fmt::format("experiment 'csv': {}: {} (data row {}): time step {} s against "
                                "a median step of {} s: {} (a filter, derivatives and energy "
                                "integrals need a uniform rate); cut the recording there with "
                                "t_start_s/t_end_s{} (max_gap_ratio = {})",
                                file, lineText(keep[i + 1]), keep[i + 1] + 1, steps[i], med,
                                steps[i] > med ? "a gap" : "uneven time stamps",
                                steps[i] > med ? "" : ", or resample it (resample_hz)", ratio));
    }
    // Segment: inside the recording, never clamped.
    const double ts = P_.getDouble("t_start_s"), te = P_.getDouble("t_end_s");
    exid::check(te == 0.0 || te > ts,
                fmt::format("experiment 'csv': t_end_s = {} must be after t_start_s = {} (or 0 for "
                            "the end)",
                            te, ts));
    const double tfirst = tk.front();
    const double span = tk.back() - tfirst;
    const double step_tol = tk.size() > 1 ? 0.5 * span / static_cast<double>(tk.size() - 1) : 0.0;
    exid::check(ts <= span,
                fmt::format("experiment 'csv': {}: t_start_s = {} s is after the end of the "
                            "recording ({} s after its first sample)",
                            file, ts, span));
    exid::check(te <= span + step_tol,
                fmt::format("experiment 'csv': {}: t_end_s = {} s is past the end of the "
                            "recording ({} s after its first sample); the segment is never "
                            "clamped (0: to the end)",
                            file, te, span));
    // Split of the segment into an identification and a validation part (half-open at the
    // split point: no sample belongs to both).
    const std::string part = P_.getString("split_part");
    const double sf = P_.getDouble("split_fraction"), sat = P_.getDouble("split_at_s");
    const double seg_end = te > 0.0 ? std::min(te, span) : span;
    double tsplit = 0.0;
    if (part != "none") {
      exid::check((sf > 0.0) != (sat > 0.0),
                  fmt::format("experiment 'csv': split_part = {} needs exactly one of "
                              "split_fraction (found {}) and split_at_s (found {})",
                              part, sf, sat));
      tsplit = sf > 0.0 ? ts + sf * (seg_end - ts) : ts + sat;
      exid::check(tsplit > ts && tsplit < seg_end,
                  fmt::format("experiment 'csv': {}: the split point {} s (split_at_s = {}) is "
                              "not inside the segment [{}, {}] s",
                              file, tsplit, sat, ts, seg_end));
    } else {
      exid::check(sf == 0.0 && sat == 0.0,
                  fmt::format("experiment 'csv': split_fraction / split_at_s need split_part "
                              "(identification or validation; the study key `split` sets all "
                              "three)"));
    }
    const double lo = part == "validation" ? tsplit : ts;
    const double hi = part == "identification" ? tsplit : seg_end;
    std::vector<int> sel;
    int in_segment = 0;
    for (std::size_t i = 0; i < keep.size(); ++i) {
      const double rel = tk[i] - tfirst;
      if (rel < ts) continue;
      if (te > 0.0 && rel > te) break;
      ++in_segment;
      if (rel < lo || (part == "identification" && rel >= hi)) continue;
      sel.push_back(static_cast<int>(i));
    }
    exid::check(!sel.empty(),
                fmt::format("experiment 'csv': {}: no sample in the segment [{}, {}] s "
                            "after the first sample (t = {} s; the file spans {} s)",
                            file, lo, part == "none" ? te : hi, tfirst, tk.back() - tfirst));

    // Fill the dataset.
    const int K = static_cast<int>(sel.size());
    exid::Dataset d;
    d.t.resize(K);
    d.q.resize(K, n);
    if (!cqd.empty()) d.qd.resize(K, n);
    if (!cqdd.empty()) d.qdd.resize(K, n);
    if (!ctau.empty()) d.tau.resize(K, n);
    if (!cw.empty()) d.wrench.resize(K, 6);
    const bool joint_frame = P_.getString("current_frame") == "joint";
    VectorXd tau(n);  // one buffer for every row (no allocation per sample)
    for (int k = 0; k < K; ++k) {
      const std::size_t i = static_cast<std::size_t>(sel[static_cast<std::size_t>(k)]);
      const int r = keep[i];
      d.t[k] = tk[i];
      for (int j = 0; j < n; ++j) {
        const double s = sign[static_cast<std::size_t>(j)];
        const double qs = qscale[static_cast<std::size_t>(j)];
        const double vs = qdscale[static_cast<std::size_t>(j)];
        d.q(k, j) =
            s * qs * value(r, cq[static_cast<std::size_t>(j)]) + off[static_cast<std::size_t>(j)];
        if (!cqd.empty()) d.qd(k, j) = s * vs * value(r, cqd[static_cast<std::size_t>(j)]);
        if (!cqdd.empty()) d.qdd(k, j) = s * vs * value(r, cqdd[static_cast<std::size_t>(j)]);
      }
      if (!ctau.empty()) {
        for (int j = 0; j < n; ++j) {
          double v = value(r, ctau[static_cast<std::size_t>(j)]);
          if (!Kt.empty()) v *= Kt[static_cast<std::size_t>(j)];
          tau[j] = v;
        }
        if (!Kt.empty() && joint_frame && robot->hasTransmission())
          tau = robot->transmission.transpose() * tau;
        for (int j = 0; j < n; ++j)
          d.tau(k, j) =
              sign[static_cast<std::size_t>(j)] * tauscale[static_cast<std::size_t>(j)] * tau[j];
      }
      for (std::size_t e = 0; e < cw.size(); ++e)
        d.wrench(k, static_cast<Eigen::Index>(e)) = wscale[e] * value(r, cw[e]);
    }
    // Resampling on request: linear interpolation of every signal onto a uniform grid.
    const double rs_hz = P_.getDouble("resample_hz");
    int resampled_from = 0;
    if (rs_hz > 0.0) {
      exid::check(K >= 2, fmt::format("experiment 'csv': {}: resample_hz needs two samples", file));
      resampled_from = K;
      const double t0 = d.t[0], span_s = d.t[K - 1] - t0;
      // (counted in double first: a huge rate must not overflow the integer count)
      const double Md = std::floor(span_s * rs_hz + 1e-9) + 1.0;
      exid::check(Md >= 2.0 && Md <= 1e8,
                  fmt::format("experiment 'csv': {}: resample_hz = {} gives {:g} samples over "
                              "{} s (2 to 1e8)",
                              file, rs_hz, Md, span_s));
      const auto M = static_cast<Eigen::Index>(Md);
      exid::Dataset u;
      u.t.resize(M);
      for (Eigen::Index m = 0; m < M; ++m) u.t[m] = t0 + static_cast<double>(m) / rs_hz;
      auto interp = [&](const Eigen::MatrixXd& A) {
        if (A.size() == 0) return Eigen::MatrixXd();
        Eigen::MatrixXd B(M, A.cols());
        Eigen::Index k = 0;
        for (Eigen::Index m = 0; m < M; ++m) {
          while (k + 2 < K && d.t[k + 1] <= u.t[m]) ++k;
          const double a = (u.t[m] - d.t[k]) / (d.t[k + 1] - d.t[k]);
          B.row(m) = (1.0 - a) * A.row(k) + a * A.row(k + 1);
        }
        return B;
      };
      u.q = interp(d.q);
      u.qd = interp(d.qd);
      u.qdd = interp(d.qdd);
      u.tau = interp(d.tau);
      u.wrench = interp(d.wrench);
      d = std::move(u);
    }
    const int K_grid = d.size();  // samples entering the filter (after any resampling)
    const Preprocessed pp = preprocess(&d, file);

    d.source = file;
    exid::Json& m = d.meta;
    m["simulated"] = false;
    m["file"] = file;
    m["rows_in_file"] = rows;
    m["dropped_rows"] = dropped;
    m["samples"] = K;
    m["time_column"] = ct >= 0 ? exid::Json(tname) : exid::Json(false);
    if (ct >= 0) m["time_unit"] = tunit;
    if (ct < 0) m["sample_period_s"] = dt;
    m["segment_s"] = exid::Json(std::vector<double>{ts, te});
    if (part != "none") {
      exid::Json& sp = m["split"];
      sp["part"] = part;
      sp["split_at_s"] = tsplit;
      if (sf > 0.0) sp["fraction"] = sf;
      sp["identification_s"] = exid::Json(std::vector<double>{ts, tsplit});
      sp["validation_s"] = exid::Json(std::vector<double>{tsplit, seg_end});
      sp["segment_samples"] = in_segment;
      sp["part_samples"] = static_cast<int>(sel.size());
    }
    m["recording_span_s"] = span;
    m["recording"] = recordingStats(file, keep, sel, value, srcs, used, cq, ctau, ct, tfactor, dt);
    // Where the rows went: every sample dropped, cut, trimmed or decimated is counted.
    {
      exid::Json& a = m["accounting"];
      a["rows_in_file"] = rows;
      a["dropped_bad_rows"] = dropped;
      a["outside_segment"] = static_cast<int>(keep.size()) - in_segment;
      if (part != "none") a["other_part_of_split"] = in_segment - K;
      a["segment_samples"] = K;
      if (resampled_from > 0) {
        a["resampled_from"] = resampled_from;
        a["resampled_to"] = K_grid;
        a["resample_hz"] = rs_hz;
      }
      const int trimmed = pp.cutoff_hz > 0 ? 2 * pp.trim : 0;
      a["trimmed_edges"] = trimmed;
      a["trimmed_percent_of_segment"] = 100.0 * trimmed / std::max(1, K_grid);
      a["decimated_away"] = K_grid - trimmed - static_cast<int>(d.size());
      a["samples_used"] = static_cast<int>(d.size());
      exid::Json w = exid::Json::array();
      if (dropped > 0)
        w.push_back(exid::Json(fmt::format(
            "experiment 'csv': {}: {} of {} rows ({:.1f} %) dropped for missing or non-finite "
            "values (drop_bad_rows)",
            file, dropped, rows, 100.0 * dropped / std::max(1, rows))));
      if (trimmed > 0.1 * K_grid)
        w.push_back(exid::Json(fmt::format(
            "experiment 'csv': {}: trim_edges = {} discards {} of the segment's {} samples "
            "({:.1f} %, more than 10 %)",
            file, pp.trim, trimmed, K_grid, 100.0 * trimmed / K_grid)));
      if (pp.trim_default && pp.trim < pp.trim_transient)
        a["trim_rule"] =
            fmt::format("ceil(2 fs / fc) = {} samples capped at 5 % of the segment: {} at each end",
                        pp.trim_transient, pp.trim);
      else if (pp.trim_default)
        a["trim_rule"] = fmt::format("ceil(2 fs / fc) = {} samples at each end", pp.trim);
      if (w.size() > 0) m["warnings"] = w;
    }
    m["torque_from"] = tfrom;
    std::vector<std::string> sig = {"q"};
    if (!cqd.empty()) sig.push_back("qd");
    if (!cqdd.empty()) sig.push_back("qdd");
    if (!ctau.empty()) sig.push_back("tau");
    if (!cw.empty()) sig.push_back("wrench");
    m["signals"] = exid::Json(sig);
    if (srcs.size() > 1) m["torque_file"] = srcs[1].file;
    if (pp.cutoff_hz > 0) {
      m["differentiated"] = exid::Json::object();
      m["differentiated"]["cutoff_hz"] = pp.cutoff_hz;
      m["differentiated"]["filter_order"] = pp.order;
      m["differentiated"]["filter_torque"] = pp.filter_torque;
      m["differentiated"]["trimmed_samples_each_end"] = pp.trim;
      m["differentiated"]["decimation"] = pp.decimation;
      m["differentiated"]["sample_rate_hz"] = pp.fs;
    }
    m["samples"] = d.size();
    ctx.report(1.0, fmt::format("{} samples from {}", d.size(), file));
    return d;
  }

 private:
  /// Recording-level statistics of the rows the experiment uses (the segment's rows of the file,
  /// before any filtering): sample rate exact to the stamps' resolution, jitter and gaps of the
  /// time stamps; duplicate rows (identical to the previous row in every used column, the time
  /// stamp included: with a time column such a row is refused before, time must increase);
  /// frozen rows (every q repeats the previous row while the robot moves: some joint stepped by
  /// at least kFrozenQuanta times its column's resolution before the run and by more than
  /// kFrozenJump times that step after it, which sets sample-and-hold apart from a standstill, a
  /// slow encoder or a file printed with few digits); saturation of each torque column (samples at
  /// the column's minimum or maximum in runs of >= 3). meta.recording; exid::inspectDataset warns
  /// from it.
  template <class Value, class Sources>
  exid::Json recordingStats(const std::string& file, const std::vector<int>& keep,
                            const std::vector<int>& sel, const Value& value, const Sources& srcs,
                            const std::vector<int>& used, const std::vector<int>& cq,
                            const std::vector<int>& ctau, int ct, double tfactor,
                            double period) const {
    constexpr double kFrozenJump = 1.5, kFrozenQuanta = 3.0;
    constexpr int kSaturationRun = 3;
    constexpr int kStride = 1 << 20;  // as in run(): ref = source * kStride + column
    std::vector<int> rows;
    for (int i : sel) rows.push_back(keep[static_cast<std::size_t>(i)]);
    const std::size_t N = rows.size();
    exid::Json R = exid::Json::object();
    R["file"] = file;
    R["rows"] = static_cast<long long>(N);
    if (ct >= 0) {
      std::vector<double> raw(N);
      for (std::size_t i = 0; i < N; ++i) raw[i] = value(rows[i], ct);
      exid::Json t = exid::samplingStats(raw, tfactor, rows, P_.getDouble("max_gap_ratio"));
      t["source"] = fmt::format("time column '{}'", P_.getString("time_column"));
      R["timing"] = t;
    } else {
      exid::Json t = exid::Json::object();
      t["source"] = "sample_period_s";
      t["rate_hz"] = exid::rateFromPeriod(period);
      t["period_s"] = period;
      t["jitter"]["std_rel"] = 0.0;
      t["jitter"]["max_rel"] = 0.0;
      t["gaps"]["count"] = 0;
      R["timing"] = t;
    }
    auto same = [&](std::size_t i, const std::vector<int>& cols) {
      for (int c : cols)
        if (value(rows[i], c) != value(rows[i - 1], c)) return false;
      return true;
    };
    std::vector<char> dup(N, 0), held(N, 0);
    long long ndup = 0;
    exid::Json dup_at = exid::Json::array();
    for (std::size_t i = 1; i < N; ++i) {
      dup[i] = same(i, used);
      held[i] = !dup[i] && same(i, cq);
      if (dup[i] && ++ndup <= 20) dup_at.push_back(exid::Json(rows[i] + 1));
    }
    R["duplicate_rows"]["count"] = ndup;
    R["duplicate_rows"]["data_rows"] = dup_at;
    // The resolution of each q column: its smallest non-zero step (a file printed with few
    // digits repeats q while the robot creeps; that is no sample-and-hold).
    std::vector<double> quantum(cq.size(), HUGE_VAL);
    for (std::size_t i = 1; i < N; ++i)
      for (std::size_t j = 0; j < cq.size(); ++j) {
        const double d = std::abs(value(rows[i], cq[j]) - value(rows[i - 1], cq[j]));
        if (d > 0) quantum[j] = std::min(quantum[j], d);
      }
    auto dq = [&](std::size_t i, std::size_t j) {  // |q_j(i) - q_j(i-1)|
      return std::abs(value(rows[i], cq[j]) - value(rows[i - 1], cq[j]));
    };
    long long runs = 0, frozen = 0;
    exid::Json frozen_at = exid::Json::array();
    for (std::size_t a = 1; a < N;) {
      if (!held[a]) {
        ++a;
        continue;
      }
      std::size_t b = a;
      while (b + 1 < N && held[b + 1]) ++b;
      // rows a..b repeat row a-1; the steps before (a-2 -> a-1) and after (b -> b+1)
      bool jumps = false;  // a joint that moved by kFrozenQuanta or more jumps after the run
      for (std::size_t j = 0; a >= 2 && b + 1 < N && j < cq.size(); ++j)
        jumps = jumps || (dq(a - 1, j) >= kFrozenQuanta * quantum[j] &&
                          dq(b + 1, j) > kFrozenJump * dq(a - 1, j));
      if (jumps) {
        ++runs;
        frozen += static_cast<long long>(b - a + 1);
        if (frozen_at.size() < 20) frozen_at.push_back(exid::Json(rows[a] + 1));
      }
      a = b + 1;
    }
    R["frozen_rows"]["rows"] = frozen;
    R["frozen_rows"]["runs"] = runs;
    R["frozen_rows"]["first_data_rows"] = frozen_at;
    exid::Json sat = exid::Json::array();
    for (int c : ctau) {
      const auto& T = srcs[static_cast<std::size_t>(c / kStride)].T;
      double lo = HUGE_VAL, hi = -HUGE_VAL;
      for (std::size_t i = 0; i < N; ++i) {
        lo = std::min(lo, value(rows[i], c));
        hi = std::max(hi, value(rows[i], c));
      }
      long long at_limit = 0;
      for (std::size_t i = 0; i < N;) {
        const double v = value(rows[i], c);
        std::size_t e = i + 1;
        while (e < N && value(rows[e], c) == v) ++e;
        if ((v == lo || v == hi) && e - i >= static_cast<std::size_t>(kSaturationRun))
          at_limit += static_cast<long long>(e - i);
        i = e;
      }
      exid::Json s = exid::Json::object();
      s["column"] = T.columns[static_cast<std::size_t>(c % kStride)];
      s["min"] = N > 0 ? exid::Json(lo) : exid::Json();
      s["max"] = N > 0 ? exid::Json(hi) : exid::Json();
      s["saturated_samples"] = at_limit;
      s["fraction"] = N > 0 ? static_cast<double>(at_limit) / static_cast<double>(N) : 0.0;
      if (N > 1 && lo == hi) s["constant"] = true;
      sat.push_back(s);
    }
    R["saturation"] = sat;
    return R;
  }

  struct Preprocessed {
    double cutoff_hz = 0, fs = 0;
    int order = 0, trim = 0, decimation = 1;
    int trim_transient = 0, trim_cap = 0, samples_before_trim = 0;
    bool trim_default = false;
    bool filter_torque = false;
  };

  /// Optional: zero-phase low-pass of q (and tau, wrench), central differences, trim, decimate.
  Preprocessed preprocess(exid::Dataset* d, const std::string& file) const {
    namespace est = exid::est;
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
    pp.fs = est::samplingRate(d->t, &jitter);
    exid::check(pp.cutoff_hz < 0.5 * pp.fs,
                fmt::format("experiment 'csv': differentiate_cutoff_hz = {} Hz must be below the "
                            "Nyquist frequency {} Hz of the data",
                            pp.cutoff_hz, 0.5 * pp.fs));
    exid::check(pp.decimation == 1 || pp.cutoff_hz < 0.5 * pp.fs / pp.decimation,
                fmt::format("experiment 'csv': decimation {} leaves a Nyquist frequency of {} Hz, "
                            "below differentiate_cutoff_hz = {} Hz (aliasing)",
                            pp.decimation, 0.5 * pp.fs / pp.decimation, pp.cutoff_hz));
    const est::Sos sos = est::butterworthLowpass(pp.order, pp.cutoff_hz, pp.fs);
    d->q = est::filtfiltColumns(sos, d->q);
    d->qd = est::centralFirstDerivative(d->t, d->q);
    d->qdd = est::centralSecondDerivative(d->t, d->q);
    if (pp.filter_torque) {
      if (d->hasTorque()) d->tau = est::filtfiltColumns(sos, d->tau);
      if (d->hasWrench()) d->wrench = est::filtfiltColumns(sos, d->wrench);
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
