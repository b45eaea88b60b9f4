// exid — experiment `csv`: the recording-level statistics of the rows it uses (meta.recording):
// held runs (duplicate and frozen rows, or held at rest) and the torque columns' saturation.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "exid/json.hpp"

namespace exid::csv_experiment {

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
  RecordingStats(std::vector<int> q_pos, std::vector<int> tau_pos, std::size_t used, bool has_time,
                 std::vector<int> qd_pos = {}, std::vector<double> qd_per_q = {},
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
  void add(const double* v, int row);

  /// The statistics (after every row): duplicate_rows, frozen_rows, saturation.
  void finish(exid::Json* R, const std::vector<std::string>& tau_names) const;

 private:
  struct Run {
    int first_row = 0;
    long long length = 0;
    std::vector<double> before, after;  // per joint: the step into and out of the run
    std::vector<double> resolution;     // per joint: the held or next value's resolution
    long long before_rows = 0;          // rows the step into the run took
    std::vector<int> dup_rows;          // the run's rows that repeat every compared column
    std::vector<double> travel;         // per joint: the recorded velocities' travel over the run
  };
  struct Saturation {
    double lo = HUGE_VAL, hi = -HUGE_VAL;
    double value = 0;  // the run in progress
    long long run = 0;
    long long at_lo = 0, at_hi = 0;  // samples in runs >= kSaturationRun at lo / hi
  };
  static void closeRun(Saturation* s);
  void saturationAdd(std::size_t k, double v);
  /// The finest power of ten (down to 1e-9) a printed value is a multiple of: its column's
  /// resolution where it was written (5 significant digits: 1e-3 at 50, 1e-4 at 5); 0 for a
  /// value with more digits.
  static double localResolution(double x);
  void endRun(const std::vector<double>& after, const double* v);

  std::vector<int> pq_, ptau_, pqd_;
  std::vector<double> qd_per_q_;
  std::vector<double> prev_;
  std::size_t compared_;  // the columns a duplicate repeats: every used one but the time
  bool has_time_;         // the time column is the last used one
  double time_unit_s_, period_s_;
  std::vector<double> quantum_, step_, before_, run_travel_;
  std::vector<double> next_step_;  // (the step of the row being added: no allocation per row)
  long long N_ = 0, last_change_ = 0, step_rows_ = 0, before_rows_ = 0;
  long long run_len_ = 0;
  int run_first_row_ = 0;
  bool run_has_before_ = false;
  std::vector<int> run_dup_rows_;
  std::vector<Run> runs_;
  std::vector<Saturation> sat_;
};

}  // namespace exid::csv_experiment
