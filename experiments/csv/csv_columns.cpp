// exid — experiment `csv`: the columns of the recording found from the files' headers (names,
// groups, the torque from currents, the wrench, the time column), the reading options (scales,
// signs, offsets) and one row read into the used values; a bad value named with its place.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "csv_stream.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/recording.hpp"

namespace exid::csv_experiment {

namespace fs = std::filesystem;

void CsvStream::resolveColumns(const exid::RunContext& ctx) {
  openFiles(ctx);
  const int fq = 0, ftau = static_cast<int>(files_.size()) - 1;
  std::vector<Ref> cq = namedColumns(fq, "q_columns");
  if (cq.empty()) cq = columnGroup("q", true, "joint positions are required", fq);
  const std::vector<Ref> cqd = columnGroup("qd", false, "");
  const std::vector<Ref> cqdd = columnGroup("qdd", false, "");
  const std::vector<Ref> ctau = torqueColumns(ftau);
  const std::vector<Ref> cw = wrenchColumns();
  std::vector<Ref> cb, cc;
  floatingColumns(&cb, &cc);
  const int ct = timeColumn();
  readScales();
  layoutColumns(cq, cqd, cqdd, ctau, cw, cb, cc, ct);
}

// The file (and torque_file), relative to the study, and their columns.
void CsvStream::openFiles(const exid::RunContext& ctx) {
  auto path = [&](fs::path p) {
    if (p.is_relative() && !ctx.study_dir.empty()) p = ctx.study_dir / p;
    return p.string();
  };
  files_.push_back(path(P_.getString("file")));
  if (!P_.getString("torque_file").empty()) files_.push_back(path(P_.getString("torque_file")));
  for (const std::string& f : files_) {
    if (exid::isBagPath(f))  // (a bag read as a CSV file says "found columns: \x89MCAP0")
      throw exid::Error(fmt::format(
          "experiment 'csv': {}: a ROS 2 bag ({}), not a CSV file: read it with experiment "
          "rosbag2 (path: {})",
          f, fs::is_directory(f) ? "a folder" : exid::bagStorageOf(f) + " storage file", f));
    exid::CsvReadOptions opt;
    opt.text_columns = true;
    exid::CsvReader r(f, opt, "CSV data");
    columns_.push_back(r.columns());
  }
}

// Column c of source f, or -1.
int CsvStream::col(int f, const std::string& c) const {
  const auto& C = columns_[static_cast<std::size_t>(f)];
  const auto it = std::find(C.begin(), C.end(), c);
  return it == C.end() ? -1 : static_cast<int>(it - C.begin());
}

// The n columns named by parameter `key` in source f (none when the list is empty).
std::vector<CsvStream::Ref> CsvStream::namedColumns(int f, const char* key) const {
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
std::vector<CsvStream::Ref> CsvStream::columnGroup(const std::string& prefix, bool required,
                                                   const char* what, int f) const {
  const int n = n_;
  const std::string& fileg = files_[static_cast<std::size_t>(f)];
  const auto& C = columns_[static_cast<std::size_t>(f)];
  std::vector<Ref> idx;
  int found = 0;
  while (col(f, prefix + std::to_string(found + 1)) >= 0) ++found;
  if (found == 0) {
    exid::check(!required, fmt::format("experiment 'csv': {}: missing column '{}1' ({}; expected "
                                       "columns {}1..{}{} for the {} joints of robot '{}'; found "
                                       "columns: {})",
                                       fileg, prefix, what, prefix, prefix, n, n, robot_->name,
                                       fmt::join(C, ", ")));
    return idx;
  }
  exid::check(found == n,
              fmt::format("experiment 'csv': {}: wrong joint count: found columns {}1..{}{} "
                          "({} joints), expected {}1..{}{} for robot '{}' ({} joints)",
                          fileg, prefix, prefix, found, found, prefix, prefix, n, robot_->name, n));
  for (int j = 1; j <= n; ++j) idx.push_back({f, col(f, prefix + std::to_string(j))});
  return idx;
}

// The torque columns of source ftau (tau, or motor currents with their torque constants).
std::vector<CsvStream::Ref> CsvStream::torqueColumns(int ftau) {
  tfrom_ = P_.getString("torque_from");
  std::vector<Ref> ctau = namedColumns(ftau, "tau_columns");
  if (tfrom_ == "tau") {
    if (ctau.empty()) ctau = columnGroup("tau", ftau > 0, "torque_file is given", ftau);
  } else {
    const std::string pre = P_.getString("current_prefix");
    if (ctau.empty())
      ctau = columnGroup(pre, true, "torque_from: current needs the motor currents", ftau);
  }
  return ctau;
}

// fx fy fz mx my mz: all six, or none.
std::vector<CsvStream::Ref> CsvStream::wrenchColumns() const {
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

// A floating base's signals (docs/conventions.md, "Floating base"): base_omega_x .. base_f_z
// (all nine, or none) and contact<c>_fx .. contact<c>_mz for c = 1, 2, ... (each complete),
// read as they are (SI, base or sensor frame; no scale, sign or offset).
void CsvStream::floatingColumns(std::vector<Ref>* cb, std::vector<Ref>* cc) const {
  const char* bn[9] = {"base_omega_x", "base_omega_y", "base_omega_z",
                       "base_alpha_x", "base_alpha_y", "base_alpha_z",
                       "base_f_x",     "base_f_y",     "base_f_z"};
  auto group = [&](const std::vector<std::string>& names, const std::string& what,
                   std::vector<Ref>* out) {
    int present = 0;
    for (const auto& c : names) present += col(0, c) >= 0;
    if (present == 0) return false;
    std::vector<std::string> missing;
    for (const auto& c : names)
      if (col(0, c) < 0) missing.push_back(c);
    exid::check(missing.empty(),
                fmt::format("experiment 'csv': {}: incomplete {}: missing column(s) {} (expected "
                            "all of {}, or none)",
                            files_[0], what, fmt::join(missing, ", "), fmt::join(names, " ")));
    for (const auto& c : names) out->push_back({0, col(0, c)});
    return true;
  };
  group(std::vector<std::string>(bn, bn + 9), "base motion", cb);
  for (int c = 1;; ++c) {
    std::vector<std::string> names;
    for (const char* k : {"fx", "fy", "fz", "mx", "my", "mz"})
      names.push_back(fmt::format("contact{}_{}", c, k));
    if (!group(names, fmt::format("contact {} wrench", c), cc)) break;
  }
  for (const auto& name : columns_[0])
    if (name.rfind("contact", 0) == 0 && name.find('_') != std::string::npos) {
      const std::string num = name.substr(7, name.find('_') - 7);
      exid::check(!num.empty() && num.find_first_not_of("0123456789") == std::string::npos &&
                      std::stoul(num) >= 1 && std::stoul(num) <= cc->size() / 6,
                  fmt::format("experiment 'csv': {}: column '{}': contact wrenches are numbered "
                              "1, 2, ... without a gap (found contact{} after {} contact(s))",
                              files_[0], name, num, cc->size() / 6));
    }
}

// The time column of file (-1: none; sample_period_s is then needed) and its unit.
int CsvStream::timeColumn() {
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

// Scales, signs, offsets, torque constants (exid/recording.hpp) and the remaining options.
void CsvStream::readScales() {
  conv_ = exid::SignalConversion::fromParams(
      P_, n_, robot_->hasTransmission() ? robot_->transmission : Eigen::MatrixXd(),
      "experiment 'csv'");
  drop_ = P_.getBool("drop_bad_rows");
}

// The used columns, in the order q, qd, qdd, tau, wrench, t; per source the columns it
// reads and where each value goes.
void CsvStream::layoutColumns(const std::vector<Ref>& cq, const std::vector<Ref>& cqd,
                              const std::vector<Ref>& cqdd, const std::vector<Ref>& ctau,
                              const std::vector<Ref>& cw, const std::vector<Ref>& cb,
                              const std::vector<Ref>& cc, int ct) {
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
  add(cb, &pb_);
  add(cc, &pc_);
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
    slot_.push_back(
        {r.source, static_cast<int>(std::find(sel.begin(), sel.end(), r.column) - sel.begin())});
  }
  for (std::size_t f = 0; f < files_.size(); ++f) vals_.emplace_back(select_[f].size());
  uv_.resize(used_.size());
  for (int p : ptau_) tau_names_.push_back(colName(used_[static_cast<std::size_t>(p)], false));
}

std::string CsvStream::colName(const Ref& r, bool with_file) const {
  const std::string& c =
      columns_[static_cast<std::size_t>(r.source)][static_cast<std::size_t>(r.column)];
  if (!with_file) return c;
  return files_.size() > 1 ? fmt::format("{}' of {}", c, files_[static_cast<std::size_t>(r.source)])
                           : c + "'";
}

// One row of every source into uv_ (false at the end of the first file); the sources must
// have the same number of rows (the scan checks).
bool CsvStream::readRow(std::vector<std::unique_ptr<exid::CsvReader>>& rd) {
  return readRow(rd, &vals_, uv_.data());
}

// The same into the given buffers (vals: per source, one row's values; uv: used values).
bool CsvStream::readRow(std::vector<std::unique_ptr<exid::CsvReader>>& rd,
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

int CsvStream::badColumn(const double* uv) const {
  for (std::size_t u = 0; u < used_.size(); ++u)
    if (!std::isfinite(uv[u])) return static_cast<int>(u);
  return -1;
}

// A bad value at used column u in the current row of reader set rd: text in that column is
// named first (it is never a dropped row), then the missing or non-finite value.
void CsvStream::badValue(const std::vector<std::unique_ptr<exid::CsvReader>>& rd, int u,
                         int row) const {
  const Ref& r = used_[static_cast<std::size_t>(u)];
  const std::string& why =
      rd[static_cast<std::size_t>(r.source)]->notNumeric()[static_cast<std::size_t>(r.column)];
  if (!why.empty()) throw exid::Error("experiment 'csv': " + why);
  throw exid::Error(fmt::format(
      "experiment 'csv': {}: line {} (data row {}): column '{}: missing or non-finite value "
      "(set drop_bad_rows: true to drop such rows)",
      files_[static_cast<std::size_t>(r.source)], rd[static_cast<std::size_t>(r.source)]->line(),
      row + 1, colName(r)));
}

// The file line of data row `row` of source f (read again: only an error needs it).
int CsvStream::lineOfRow(int f, int row) const {
  exid::CsvReadOptions opt;
  opt.allow_non_finite = true;
  opt.text_columns = true;
  exid::CsvReader r(files_[static_cast<std::size_t>(f)], opt, "CSV data");
  r.select({});
  for (int k = 0; k <= row; ++k)
    if (!r.next(nullptr)) return 0;
  return r.line();
}

std::string CsvStream::lineText(int row) const {
  const int l = lineOfRow(0, row);
  return l > 0 ? fmt::format("line {}", l) : fmt::format("data row {}", row + 1);
}

}  // namespace exid::csv_experiment
