// exid — experiment `csv`: the recording statistics (recording_stats.hpp).
#include "recording_stats.hpp"

#include <algorithm>
#include <cmath>

namespace exid::csv_experiment {

void RecordingStats::add(const double* v, int row) {
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
      const double dt = has_time_ ? (v[compared_] - prev_[compared_]) * time_unit_s_ : period_s_;
      if (pqd_.size() == pq_.size() && std::isfinite(dt) && dt > 0)
        for (std::size_t j = 0; j < pq_.size(); ++j)
          run_travel_[j] += v[pqd_[j]] * qd_per_q_[j] * dt;
    } else {
      std::vector<double>& d = next_step_;
      d.resize(pq_.size());
      for (std::size_t j = 0; j < pq_.size(); ++j) {
        d[j] = std::abs(v[pq_[j]] - prev_[static_cast<std::size_t>(pq_[j])]);
        if (d[j] > 0) quantum_[j] = std::min(quantum_[j], d[j]);
      }
      if (run_len_ > 0) endRun(d, v);  // the run ends here
      step_.swap(d);
      step_rows_ = N_ - last_change_;
      last_change_ = N_;
    }
  }
  for (std::size_t k = 0; k < ptau_.size(); ++k) saturationAdd(k, v[ptau_[k]]);
  std::copy(v, v + prev_.size(), prev_.begin());
  ++N_;
}

void RecordingStats::finish(exid::Json* R, const std::vector<std::string>& tau_names) const {
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

void RecordingStats::closeRun(Saturation* s) {
  if (s->run >= kSaturationRun) {
    if (s->value == s->lo) s->at_lo += s->run;
    if (s->value == s->hi) s->at_hi += s->run;
  }
  s->run = 0;
}

void RecordingStats::saturationAdd(std::size_t k, double v) {
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

double RecordingStats::localResolution(double x) {
  for (int d = 0; d <= 9; ++d) {
    const double y = x * std::pow(10.0, d);
    if (std::abs(y - std::round(y)) <= 1e-6 + 16 * 2.220446049250313e-16 * std::abs(y))
      return std::pow(10.0, -d);
  }
  return 0.0;
}

void RecordingStats::endRun(const std::vector<double>& after, const double* v) {
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

}  // namespace exid::csv_experiment
