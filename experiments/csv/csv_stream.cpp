// exid — experiment `csv`: the recording as a stream: opened (columns, then the scan), then
// passes over the samples, in chunks read in order or in pieces (fetched in order, decoded on
// any thread, settled in order), the first whole pass completing the recording statistics;
// and the dataset's meta.
#include "csv_stream.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "exid/error.hpp"

namespace exid::csv_experiment {

std::shared_ptr<CsvStream> CsvStream::open(const exid::ParamSet& P,
                                           std::shared_ptr<const exid::RobotModel> robot,
                                           const exid::RunContext& ctx) {
  exid::check(robot != nullptr, "experiment 'csv': no robot");
  auto s = std::shared_ptr<CsvStream>(new CsvStream(P, std::move(robot)));
  s->resolveColumns(ctx);
  s->scan();
  return s;
}

void CsvStream::rewind() {
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
  std::vector<double> qd_per_q(conv_.q_scale.size());
  for (std::size_t j = 0; j < conv_.q_scale.size() && j < conv_.qd_scale.size(); ++j)
    qd_per_q[j] = conv_.qd_scale[j] / conv_.q_scale[j];
  stats_ = std::make_unique<RecordingStats>(pq_, ptau_, used_.size(), ct_, pqd_, qd_per_q, tfactor_,
                                            dt_);
  collecting_ = !stats_done_;
  if (collecting_) collected_ = exid::Dataset();
  taken_ = 0;
}

int CsvStream::read(int count, exid::Dataset* chunk) {
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
std::unique_ptr<CsvStream::Piece> CsvStream::fetch(int count) {
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

void CsvStream::decode(Piece& piece, exid::Dataset* chunk) const {
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

void CsvStream::settle(const Piece& piece, const exid::Dataset& chunk) {
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

exid::Json CsvStream::metaAfter(const exid::RecordingPipeline& steps) const {
  const int K = size();
  exid::Json m = exid::Json::object();
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
    exid::Json w = exid::Json::array();
    if (dropped_ > 0)
      w.push_back(exid::Json(fmt::format(
          "experiment 'csv': {}: {} of {} rows ({:.1f} %) dropped for missing or non-finite "
          "values (drop_bad_rows)",
          files_[0], dropped_, rows_, 100.0 * dropped_ / std::max(1, rows_))));
    steps.account(&a, &w);
    if (w.size() > 0) m["warnings"] = w;
  }
  m["torque_from"] = tfrom_;
  std::vector<std::string> sig = {"q"};
  if (!pqd_.empty()) sig.push_back("qd");
  if (!pqdd_.empty()) sig.push_back("qdd");
  if (!ptau_.empty()) sig.push_back("tau");
  if (!pw_.empty()) sig.push_back("wrench");
  if (!pb_.empty()) sig.push_back("base");
  if (!pc_.empty()) sig.push_back(fmt::format("contact ({})", pc_.size() / 6));
  m["signals"] = exid::Json(sig);
  if (files_.size() > 1) m["torque_file"] = files_[1];
  steps.describe(&m);
  m["samples"] = steps.done().samples_used;
  return m;
}

// ---- a pass
void CsvStream::sizeChunk(int want, exid::Dataset* chunk) const {
  chunk->t.resize(want);
  chunk->q.resize(want, n_);
  chunk->qd.resize(pqd_.empty() ? 0 : want, pqd_.empty() ? 0 : n_);
  chunk->qdd.resize(pqdd_.empty() ? 0 : want, pqdd_.empty() ? 0 : n_);
  chunk->tau.resize(ptau_.empty() ? 0 : want, ptau_.empty() ? 0 : n_);
  chunk->wrench.resize(pw_.empty() ? 0 : want, pw_.empty() ? 0 : 6);
  const auto nb = static_cast<Eigen::Index>(pb_.size()), nc = static_cast<Eigen::Index>(pc_.size());
  chunk->base.resize(nb == 0 ? 0 : want, nb);
  chunk->contact.resize(nc == 0 ? 0 : want, nc);
  chunk->source = files_[0];
}

// The file rows from data row `from` on that hold the next m kept rows (the dropped rows
// among them counted, from the scan's list); advances dptr_ past those dropped rows.
int CsvStream::fileRowsFor(long from, long m) {
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
bool CsvStream::nextKeptRow() {
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

// Used values uv of file data row `row` into sample k of *d (tau: a work vector).
void CsvStream::convert(int k, const double* uv, int row, exid::Dataset* d,
                        Eigen::VectorXd* tau) const {
  const int n = n_;
  d->t[k] = ct_ ? tfactor_ * uv[static_cast<std::size_t>(pt_)] : row * dt_;
  for (int j = 0; j < n; ++j) {
    const auto u = static_cast<std::size_t>(j);
    d->q(k, j) = conv_.q(j, uv[static_cast<std::size_t>(pq_[u])]);
    if (!pqd_.empty()) d->qd(k, j) = conv_.qd(j, uv[static_cast<std::size_t>(pqd_[u])]);
    if (!pqdd_.empty()) d->qdd(k, j) = conv_.qd(j, uv[static_cast<std::size_t>(pqdd_[u])]);
  }
  if (!ptau_.empty()) {
    conv_.torque(uv, ptau_.data(), tau);
    d->tau.row(k) = tau->transpose();
  }
  for (std::size_t e = 0; e < pw_.size(); ++e)
    d->wrench(k, static_cast<Eigen::Index>(e)) =
        conv_.wrench(static_cast<int>(e), uv[static_cast<std::size_t>(pw_[e])]);
  for (std::size_t e = 0; e < pb_.size(); ++e)
    d->base(k, static_cast<Eigen::Index>(e)) = uv[static_cast<std::size_t>(pb_[e])];
  for (std::size_t e = 0; e < pc_.size(); ++e)
    d->contact(k, static_cast<Eigen::Index>(e)) = uv[static_cast<std::size_t>(pc_[e])];
}

void CsvStream::collect(const exid::Dataset& chunk, int k) {
  const Eigen::Index i = taken_ / stride_;
  if (i == 0) {  // sized once: samples 0, stride, 2 stride, ... of the pass
    const Eigen::Index M = (size() + stride_ - 1) / stride_;
    collected_.t.resize(M);
    collected_.q.resize(M, n_);
    collected_.qd.resize(pqd_.empty() ? 0 : M, pqd_.empty() ? 0 : n_);
    collected_.qdd.resize(pqdd_.empty() ? 0 : M, pqdd_.empty() ? 0 : n_);
    collected_.tau.resize(ptau_.empty() ? 0 : M, ptau_.empty() ? 0 : n_);
    collected_.wrench.resize(pw_.empty() ? 0 : M, pw_.empty() ? 0 : 6);
    collected_.base.resize(pb_.empty() ? 0 : M, static_cast<Eigen::Index>(pb_.size()));
    collected_.contact.resize(pc_.empty() ? 0 : M, static_cast<Eigen::Index>(pc_.size()));
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
  row(&collected_.base, chunk.base);
  row(&collected_.contact, chunk.contact);
}

void CsvStream::finishPass() {
  if (!collecting_ || stats_done_) return;
  stats_->finish(&recording_, tau_names_);
  stats_done_ = true;
  collecting_ = false;
  collected_.source = files_[0];
  collected_.meta = meta();
}

}  // namespace exid::csv_experiment
