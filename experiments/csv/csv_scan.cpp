// exid — experiment `csv`: the one scan of the recording's rows before the first pass: bad
// rows dropped or refused, the time stamps checked to increase (read on several threads when
// nothing may be dropped), row alignment of the torque file, gaps and uneven stamps, the
// segment and its split, the sampling rate and the recording's timing statistics.
#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <new>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <vector>

#include "csv_stream.hpp"
#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/recording_stats.hpp"
#include "exid/signal.hpp"

namespace exid::csv_experiment {

int CsvStream::rowOf(const ScanRows& s, std::size_t i) const {
  return s.keep.empty() ? static_cast<int>(i) : s.keep[i];
}

double CsvStream::timeOf(const ScanRows& s, long i) const {
  return ct_ ? tfactor_ * s.raw[static_cast<std::size_t>(i)]
             : rowOf(s, static_cast<std::size_t>(i)) * dt_;
}

void CsvStream::scan() {
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
void CsvStream::checkRowAligned() const {
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
std::vector<double> CsvStream::scanRows() {
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
  exid::check(rows > 0, fmt::format("experiment 'csv': {}: no data rows after the header", file));
  exid::check(kept_rows_ > 0,
              fmt::format("experiment 'csv': {}: every row was dropped ({} with bad values)", file,
                          dropped_));
  return raw;
}

namespace {

// The starts of the pieces of the data [begin, size) of file descriptor fd, each after the
// first newline at or after its nominal start - 1, and size at the end; empty when a read
// failed.
std::vector<std::uint64_t> pieceStarts(int fd, std::uint64_t begin, std::uint64_t size,
                                       std::uint64_t piece_bytes) {
  const std::uint64_t data = size - begin;
  const auto count = static_cast<std::size_t>(std::min<std::uint64_t>(4096, data / piece_bytes));
  std::vector<std::uint64_t> start{begin};
  std::vector<char> probe(std::size_t{1} << 16);
  for (std::size_t i = 1; i < count; ++i) {
    std::uint64_t at = begin + data * i / count - 1;
    if (at < start.back()) continue;
    bool found = false;
    while (!found && at < size) {
      const ssize_t got = ::pread(fd, probe.data(), probe.size(), static_cast<off_t>(at));
      if (got <= 0) return {};
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
  return start;
}

// Each piece of the scan in pieces: its rows and, with a time column, their stamps; ok false
// when a reader failed or a stamp is not finite (the serial scan names the line).
struct ScanPart {
  std::vector<double> t;
  long rows = 0;
  bool ok = true, done = false;
};

// The bytes [from_byte, to_byte) of file descriptor fd (whole lines) parsed into *pc by a reader
// of the columns of `like`; time_column: the one column read is the time stamps. The piece's
// lines are mapped (no copy of the text; unmapped when parsed, so the file's pages stay out of
// the process's memory). v: one row's values.
void parsePiece(int fd, std::uint64_t from_byte, std::uint64_t to_byte, std::uint64_t page,
                const exid::CsvReader& like, bool time_column, std::vector<double>* v,
                ScanPart* pc) {
  const std::uint64_t from = from_byte / page * page;
  const auto len = static_cast<std::size_t>(to_byte - from);
  void* map =
      ::mmap(nullptr, len, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, static_cast<off_t>(from));
  if (map == MAP_FAILED) {
    pc->ok = false;
    return;
  }
  try {
    exid::CsvReader r(std::string_view(static_cast<const char*>(map) + (from_byte - from),
                                       static_cast<std::size_t>(to_byte - from_byte)),
                      like, 0);
    while (r.next(v->data())) {
      ++pc->rows;
      if (time_column) {
        if (!std::isfinite((*v)[0])) throw exid::Error("not finite");
        pc->t.push_back((*v)[0]);
      }
    }
  } catch (const std::exception&) {
    pc->ok = false;
  }
  ::munmap(map, len);
}

}  // namespace

// scanRows() without dropped rows (only the time column read, or only rows counted) on
// several threads: the data in byte ranges that start at a line, each parsed by a reader
// of whole lines (CsvReader's body constructor), the pieces' stamps appended in file
// order as they are done (memory: the stamps and a few pieces in flight). False (nothing
// set) on one thread, a small file, or anything the serial scan must report with its line
// (a bad or non-increasing time, no rows): the serial scan then runs.
bool CsvStream::scanInPieces(const exid::CsvReader& like, std::vector<double>* raw) {
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
  const std::vector<std::uint64_t> start = pieceStarts(fd, begin, size, kPiece);
  if (start.empty()) return false;
  const std::size_t pieces = start.size() - 1;
  if (pieces < 2) return false;
  std::vector<ScanPart> piece(pieces);
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
      ScanPart& m = piece[merged];
      failed = failed || !m.ok;
      if (!failed) {
        if (merged == 0 && !m.t.empty()) {
          // room for the whole file's stamps at the first piece's density (+ 1 %): growing by
          // doubling instead held the old and the new array at once (a 10 M-sample run's peak
          // memory rose by half); a low estimate only means growing as before
          const std::uint64_t bytes0 = std::max<std::uint64_t>(1, start[1] - start[0]);
          const double per_byte = static_cast<double>(m.t.size()) / static_cast<double>(bytes0);
          raw->reserve(
              static_cast<std::size_t>(1.01 * per_byte * static_cast<double>(size - begin) + 16.0));
        }
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
      parsePiece(fd, start[k], start[k + 1], page, like, ct_, &v, &piece[k]);
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
std::vector<int> CsvStream::keptFileRows() const {
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
void CsvStream::checkUniformSteps(const ScanRows& s) const {
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
      throw exid::Error(
          fmt::format("experiment 'csv': {}: {} (data row {}): time step {} s "
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
void CsvStream::selectSegment(const ScanRows& s) {
  const std::string& file = files_[0];
  const double tfirst = t_first_abs_;
  span_ = timeOf(s, kept_rows_ - 1) - tfirst;
  const double step_tol = kept_rows_ > 1 ? 0.5 * span_ / static_cast<double>(kept_rows_ - 1) : 0.0;
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
void CsvStream::scanSamplingRate(const ScanRows& s) {
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
void CsvStream::recordTiming(ScanRows* s) {
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

}  // namespace exid::csv_experiment
