// exid — estimator `filtered_ls`: steps 1-4 (see filtered_ls.cpp): the plan (trim, decimation,
// filters), the standstills, the samples filtered and differentiated, the model's rows
// decimated and accumulated, chunk by chunk on several threads.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <exception>
#include <limits>
#include <map>
#include <thread>

#include "exid/error.hpp"
#include "exid/estimators/consistent.hpp"
#include "filtered_ls.hpp"

namespace exid::filtered_ls {

/// Steps 1-3 decided before any sample is read: rates, filters, trim, decimation, chunks.
void FilteredLs::plan(const exid::ObservationModel& model, const exid::Dataset& data, Processed* P,
                      estimators::Sos* sos, estimators::Sos* dsos) const {
  const int K = data.size();
  exid::check(K >= 8,
              fmt::format("filtered_ls: dataset '{}' has {} samples; filtering needs at least 8",
                          data.source, K));
  exid::check((data.streamed() || data.q.rows() == K) && data.dof() > 0,
              fmt::format("filtered_ls: dataset '{}' has no positions q", data.source));
  P->fs = exid::samplingRate(data, &P->jitter);
  const double fs = P->fs;
  P->filter_q = cutoff_ > 0.0;
  if (P->filter_q)
    exid::check(cutoff_ < 0.5 * fs,
                fmt::format("filtered_ls: cutoff_hz = {:g} Hz must be below the Nyquist "
                            "frequency fs/2 = {:g} Hz of '{}'",
                            cutoff_, 0.5 * fs, data.source));
  const int n = data.dof();
  exid::check(min_speed_.empty() || static_cast<int>(min_speed_.size()) == n,
              fmt::format("filtered_ls: min_speed: expected {} values (one per joint), found {}", n,
                          min_speed_.size()));
  exid::check(standstill_tol_.empty() || static_cast<int>(standstill_tol_.size()) == n,
              fmt::format("filtered_ls: standstill_tolerance: expected {} values (one per "
                          "joint), found {}",
                          n, standstill_tol_.size()));
  for (double v : standstill_tol_)
    exid::check(std::isfinite(v) && v >= 0.0,
                fmt::format("filtered_ls: standstill_tolerance: every value must be finite and "
                            ">= 0, found {:g}",
                            v));
  if (standstill_ != "filter") {  // (decided before per_sample is known: the same for any mode)
    const double min_s = standstill_min_s_ > 0.0 ? standstill_min_s_
                         : cutoff_ > 0.0         ? 2.0 / cutoff_
                                                 : 0.0;
    P->rest_min = std::max<long>(3, static_cast<long>(std::ceil(min_s * fs - 1e-9)));
  }
  if (P->filter_q) *sos = estimators::butterworthLowpass(order_, cutoff_, fs);
  P->diff_qd = differentiate_ || !data.hasVelocity();
  P->diff_qdd = differentiate_ || !data.hasAcceleration();
  // Trim: by default the filter's edge transient, ceil(2 fs / fc - eps) samples, but at most
  // 5 % of the data at each end (the csv experiment's rule: a default never discards more
  // than 10 %; the edges of a zero-phase filter with steady-state initial conditions are
  // already close, and a short recording cannot spare its edges).
  const bool diff = P->diff_qd || P->diff_qdd;
  long trim = trim_;
  if (trim < 0) {
    P->trim_default = true;
    P->trim_transient =
        P->filter_q ? static_cast<long>(std::ceil(2.0 * fs / cutoff_ - 1e-9)) : (diff ? 1 : 0);
    trim = std::min(P->trim_transient, std::max<long>(diff ? 1 : 0, K / 20));
  }
  exid::check(K - 2 * trim >= 8,
              fmt::format("filtered_ls: trimming {} samples at each end of {} leaves too few; "
                          "lower trim_edges or raise cutoff_hz",
                          trim, K));
  P->trim = trim;
  P->trimmed_total = 2 * trim;
  int R = decimation_;
  if (R == 0)
    R = P->filter_q ? std::max(1, static_cast<int>(std::floor(0.2 * fs / cutoff_ + 1e-6))) : 1;
  P->per_sample = estimators::modelIsPerSample(model);
  if (R > 1 && !P->per_sample) {
    P->dec_note = fmt::format(
        "decimation {} skipped: the model '{}' does not give one row per sample and equation", R,
        model.pluginName());
    R = 1;
  }
  exid::check(min_speed_.empty() || P->per_sample,
              fmt::format("filtered_ls: min_speed needs a model with one row per sample and "
                          "equation (model '{}' is not)",
                          model.pluginName()));
  P->standstill = standstill_ == "auto" ? (P->per_sample ? "drop" : "zero_velocity") : standstill_;
  exid::check(standstill_ != "drop" || P->per_sample,
              fmt::format("filtered_ls: standstill: drop needs a model with one row per sample "
                          "and equation (model '{}' is not); zero_velocity works with any",
                          model.pluginName()));
  if (R > 1) {
    P->dec_cut = dec_ratio_ * 0.5 * fs / R;
    *dsos = estimators::butterworthLowpass(dec_order_, P->dec_cut, fs);
    if (correct_) P->kappa = estimators::decimationVarianceFactor(*dsos, R);
  }
  P->R = R;
  // Chunks [a, b) of the trimmed samples (multiples of R, so the kept samples are those of the
  // whole recording), each computed with `margin` samples of context on both sides: the
  // decimation filter's transient from the chunk's artificial ends decays below 1e-13 before
  // the chunk starts. The signals of a chunk and its margins are filtered and differentiated
  // from `signal_margin` more samples on each side: the position filter's transient from those
  // artificial ends decays below 1e-16 (the rounding of the doubles) before them, and the
  // differences need two neighbours.
  const long Kt = K - 2 * trim;
  P->margin_samples = R > 1 ? estimators::settlingSamples(*dsos, 1e-13) : 0;
  P->signal_margin = (P->filter_q ? estimators::settlingSamples(*sos, 1e-16) : 0) + (diff ? 4 : 0);
  // (a sample's standstill is decided on the raw positions within rest_min of it)
  P->signal_margin = std::max(P->signal_margin, 2 * P->rest_min + 1);
  // (at least 8 margins: the context computed twice costs at most a quarter more)
  long C = std::max<long>(chunk_samples_, 8 * P->margin_samples);
  // The same number of chunks, of equal sizes: the same work (each chunk's context is the
  // same), shared evenly between threads (a short last chunk would leave one thread idle).
  // It does not depend on the thread count, so neither do the results.
  if (Kt > 0) C = (Kt + (Kt + C - 1) / C - 1) / ((Kt + C - 1) / C);
  C = ((C + R - 1) / R) * R;
  if (!P->per_sample) C = Kt;  // such a model's rows need the whole dataset at once
  P->chunk_samples = C;
  P->streamed = P->per_sample;
}

/// Per sample of raw: 1 where the whole robot stands still, i.e. the sample lies in a window
/// of P.rest_min samples of raw over which every joint's position range is within its
/// tolerance (0: the positions repeat exactly); with standstill: drop, 2 within rest_min
/// samples of a standstill (its edge); 0 elsewhere. A sample's answer depends only on the raw
/// positions within 2 rest_min of it, so a chunk with that much context decides as the whole
/// recording would.
std::vector<char> FilteredLs::standstill(const exid::Dataset& raw, const Processed& P) const {
  const long K = raw.size(), L = P.rest_min;
  std::vector<char> rest(static_cast<std::size_t>(K), 0);
  if (L <= 0 || K < L) return rest;
  const long S = K - L + 1;  // window starts
  std::vector<char> ok(static_cast<std::size_t>(S), 1);
  for (Eigen::Index j = 0; j < raw.q.cols(); ++j) {
    const double tol = standstill_tol_.empty() ? 0.0 : standstill_tol_[static_cast<std::size_t>(j)];
    // sliding-window max and min (monotone deques of sample indices)
    std::deque<long> hi, lo;
    for (long k = 0; k < K; ++k) {
      const double v = raw.q(k, j);
      while (!hi.empty() && raw.q(hi.back(), j) <= v) hi.pop_back();
      while (!lo.empty() && raw.q(lo.back(), j) >= v) lo.pop_back();
      hi.push_back(k);
      lo.push_back(k);
      const long s = k - L + 1;
      if (s < 0) continue;
      while (hi.front() < s) hi.pop_front();
      while (lo.front() < s) lo.pop_front();
      if (!(raw.q(hi.front(), j) - raw.q(lo.front(), j) <= tol))
        ok[static_cast<std::size_t>(s)] = 0;
    }
  }
  // rest[k]: some window start in [k - L + 1, k] is ok
  long open = 0;  // ok windows covering k
  for (long k = 0; k < K; ++k) {
    if (k < S && ok[static_cast<std::size_t>(k)]) ++open;
    if (k - L >= 0 && k - L < S && ok[static_cast<std::size_t>(k - L)]) --open;
    rest[static_cast<std::size_t>(k)] = open > 0;
  }
  // drop: the position filter's transient (L samples) beside a standstill is its edge (2):
  // there the filtered velocity still carries the kink where the motion leaves or reaches rest
  if (P.standstill == "drop") {
    long last = -(L + 1);  // the last standstill sample seen going forward
    for (long k = 0; k < K; ++k) {
      if (rest[static_cast<std::size_t>(k)] == 1)
        last = k;
      else if (k - last <= L)
        rest[static_cast<std::size_t>(k)] = 2;
    }
    last = K + L + 1;
    for (long k = K - 1; k >= 0; --k) {
      if (rest[static_cast<std::size_t>(k)] == 1)
        last = k;
      else if (last - k <= L)
        rest[static_cast<std::size_t>(k)] = 2;
    }
  }
  return rest;
}

/// Steps 1-2 on raw samples: the filtered (and differentiated) signals; 2b: zero qd, qdd where
/// rest (per sample of raw) is set.
exid::Dataset FilteredLs::filtered(exid::Dataset raw, const Processed& P,
                                   const estimators::Sos& sos,
                                   const std::vector<char>& rest) const {
  exid::Dataset f = raw;
  if (P.filter_q) f.q = estimators::filtfiltColumns(sos, raw.q);
  if (P.diff_qd) {
    f.qd = estimators::centralFirstDerivative(raw.t, f.q);
  } else if (P.filter_q) {
    f.qd = estimators::filtfiltColumns(sos, raw.qd);
  }
  if (P.diff_qdd) {
    f.qdd = P.diff_qd ? estimators::centralSecondDerivative(raw.t, f.q)
                      : estimators::centralFirstDerivative(raw.t, f.qd);
  } else if (P.filter_q) {
    f.qdd = estimators::filtfiltColumns(sos, raw.qdd);
  }
  for (std::size_t k = 0; k < rest.size(); ++k)
    if (rest[k] == 1) {
      const auto i = static_cast<Eigen::Index>(k);
      if (f.qd.rows() > i) f.qd.row(i).setZero();
      if (f.qdd.rows() > i) f.qdd.row(i).setZero();
    }
  return f;
}

/// Step 4 for chunk [ca, cb) of the trimmed samples: f holds the filtered samples [lo, hi)
/// (the chunk and its decimation margins). The rows, one row of M per sample (equation g's p
/// base columns and its y at columns [g (p + 1), (g + 1)(p + 1))), built a block of samples at
/// a time (the model's rows of the whole chunk are never held), every column filtered at once,
/// one sample in R kept (4b: less the slow ones) and accumulated.
void FilteredLs::chunkRows(const exid::ObservationModel& model, const Processed& P,
                           const estimators::Sos& dsos, const exid::Dataset& f,
                           const std::vector<char>& rest, long lo, long ca, long cb, bool keep_rows,
                           const exid::RunContext& ctx, ChunkOut* o) const {
  for (long sidx = ca; sidx < cb; ++sidx) {
    o->rest += rest[static_cast<std::size_t>(sidx - lo)] == 1;
    o->rest_edge += rest[static_cast<std::size_t>(sidx - lo)] == 2;
  }
  const int p = model.numBase();
  const long trim = P.trim, hi = lo + f.size();
  const int R = P.R;
  if (!P.per_sample) {  // (standstill: drop needs one row per sample: checked in plan())
    exid::Rows rows = model.rows(f, ctx);
    estimators::checkRows(rows, p, kName, static_cast<int>(trim));
    o->rows_before = rows.y.size();
    o->kept = rows.y.size();
    o->acc = estimators::RowAccumulator(p);
    o->acc.add(rows.W, rows.y);
    if (keep_rows) o->rows = std::move(rows);
    return;
  }
  // The rows buffer (one row of every equation's columns per sample of the chunk and its
  // margins) is filled and filtered a block of columns at a time, so that it stays within
  // chunk_memory_mb: the model's rows are computed once per block; each column is filtered on
  // its own, so the blocks give the same numbers as one pass. The kept samples' rows of every
  // block are gathered in K (one in R samples) and accumulated at the end.
  const long L = hi - lo;
  const bool drop_rest = P.standstill == "drop";
  const std::vector<long> kept_samples = keptSamples(model, P, f, rest, lo, ca, cb, o);
  const auto nk = static_cast<Eigen::Index>(kept_samples.size());
  // (without decimation no column is filtered: one block, whose kept rows are read in place)
  const bool filter = R > 1 && L >= 2;
  const auto width = filter
                         ? static_cast<Eigen::Index>(std::max<double>(
                               1.0, std::floor(chunk_memory_mb_ * 1e6 /
                                               (8.0 * static_cast<double>(std::max<long>(L, 1))))))
                         : std::numeric_limits<Eigen::Index>::max() / 2;
  SampleRows s;
  exid::RowMajorMatrix K;
  Eigen::Index cols = 0;
  o->column_blocks = 0;
  for (Eigen::Index c0 = 0; c0 == 0 || c0 < cols; c0 += width) {
    sampleRows(model, P, f, lo, ca, cb, keep_rows, ctx, c0, width, &s, o);
    if (c0 == 0) {
      cols = static_cast<Eigen::Index>(s.labels.size()) * (p + 1);
      if (filter) K.resize(nk, cols);
    }
    ++o->column_blocks;
    auto M = s.M.map();
    o->buffer_bytes = std::max(o->buffer_bytes, 8.0 * static_cast<double>(M.size()));
    // Rows to be dropped are zero before the decimation filter (0 = 0 theta holds exactly):
    // the filter would otherwise spread them into the kept rows beside a standstill (at its
    // edges the positions are held while the robot may already move).
    if (drop_rest)
      for (long k = 0; k < L; ++k)
        if (rest[static_cast<std::size_t>(k)]) M.row(k).setZero();
    if (!filter) break;
    estimators::filtfiltRowsInPlace(dsos, M);
    for (Eigen::Index k = 0; k < nk; ++k)
      K.row(k).segment(c0, M.cols()) = M.row(kept_samples[static_cast<std::size_t>(k)] - lo);
    s.M = estimators::LargeRows();
  }
  const auto M = s.M.map();  // (without filtering: the one block; else empty)
  auto keptRow = [&](Eigen::Index k) {
    const double* row =
        filter ? K.row(k).data() : M.row(kept_samples[static_cast<std::size_t>(k)] - lo).data();
    return Eigen::Map<const Eigen::RowVectorXd>(row, cols);
  };
  const std::vector<int>& labels = s.labels;
  const std::vector<double>& times = s.times;
  const exid::Rows& head = s.head;
  const auto G = static_cast<Eigen::Index>(labels.size());
  Eigen::MatrixXd W(nk * G, p);
  Eigen::VectorXd y(W.rows());
  exid::Rows out;
  out.numEquations = head.numEquations;
  out.equation_names = head.equation_names;
  for (Eigen::Index k = 0; k < nk; ++k) {
    const long local = kept_samples[static_cast<std::size_t>(k)] - lo;
    for (Eigen::Index g = 0; g < G; ++g) {
      const Eigen::Index r = k * G + g;
      W.row(r) = keptRow(k).segment(g * (p + 1), p);
      y(r) = keptRow(k)(g * (p + 1) + p);
      if (keep_rows) {
        out.equation.push_back(labels[static_cast<std::size_t>(g)]);
        if (!times.empty()) out.t.push_back(times[static_cast<std::size_t>(local * G + g)]);
      }
    }
  }
  o->kept = static_cast<long>(nk);
  o->acc = estimators::RowAccumulator(p);
  o->acc.add(W, y);
  if (keep_rows) {
    out.W = std::move(W);
    out.y = std::move(y);
    o->rows = std::move(out);
  }
}

void FilteredLs::sampleRows(const exid::ObservationModel& model, const Processed& P,
                            const exid::Dataset& f, long lo, long ca, long cb, bool keep_rows,
                            const exid::RunContext& ctx, Eigen::Index c0, Eigen::Index width,
                            SampleRows* s, ChunkOut* o) const {
  const int p = model.numBase();
  const long trim = P.trim, hi = lo + f.size();
  const long L = hi - lo;
  estimators::LargeRows& Mbuf = s->M;
  std::vector<int>& labels = s->labels;
  std::vector<double>& times = s->times;
  exid::Rows& head = s->head;
  constexpr long kBlock = 1024;
  for (long a = lo; a < hi; a += kBlock) {
    const long b = std::min(hi, a + kBlock);
    exid::Rows rows =
        model.rows(exid::sliceDataset(f, static_cast<int>(a - lo), static_cast<int>(b - lo)), ctx);
    estimators::checkRows(rows, p, kName, static_cast<int>(trim + a));
    if (a == lo && c0 == 0) {
      if (rows.equation.empty()) {
        labels = {0};
      } else {
        labels = rows.equation;
        std::sort(labels.begin(), labels.end());
        labels.erase(std::unique(labels.begin(), labels.end()), labels.end());
      }
      const bool has_t = rows.t.size() == static_cast<std::size_t>(rows.y.size());
      if (keep_rows && has_t) times.resize(static_cast<std::size_t>(L) * labels.size());
      head.numEquations = rows.numEquations;
      head.equation_names = rows.equation_names;
      o->rows_before =
          static_cast<long>(std::min<long>(cb - ca, L) * std::max(1, rows.numEquations));
    }
    const auto G = labels.size();
    const Eigen::Index c1 = std::min(static_cast<Eigen::Index>(G) * (p + 1), c0 + width);
    if (a == lo) Mbuf = estimators::LargeRows(L, c1 - c0);
    auto M = Mbuf.map();
    std::vector<long> next(G, a - lo);  // per group: the next sample's row of M
    for (Eigen::Index i = 0; i < rows.y.size(); ++i) {
      const int label = rows.equation.empty() ? 0 : rows.equation[static_cast<std::size_t>(i)];
      const auto g = static_cast<std::size_t>(
          std::lower_bound(labels.begin(), labels.end(), label) - labels.begin());
      if (g == G || labels[g] != label || next[g] >= b - lo)
        throw exid::Error(fmt::format(
            "filtered_ls: model '{}' gave rows of equation {} beyond one per sample and "
            "equation of its first samples (samples {}-{})",
            model.pluginName(), label, trim + a, trim + b - 1));
      const long sm = next[g]++;
      // equation g's columns [e0, e0 + p] within the block [c0, c1)
      const Eigen::Index e0 = static_cast<Eigen::Index>(g) * (p + 1);
      const Eigen::Index from = std::max(e0, c0), to = std::min(e0 + p, c1);
      if (to > from)
        M.row(sm).segment(from - c0, to - from) = rows.W.row(i).segment(from - e0, to - from);
      if (e0 + p >= c0 && e0 + p < c1) M(sm, e0 + p - c0) = rows.y(i);
      if (c0 == 0 && !times.empty())
        times[static_cast<std::size_t>(sm) * G + g] = rows.t[static_cast<std::size_t>(i)];
    }
    for (std::size_t g = 0; g < G; ++g)
      exid::check(next[g] == b - lo,
                  fmt::format("filtered_ls: model '{}' gave {} rows of equation {} for {} "
                              "samples",
                              model.pluginName(), next[g] - (a - lo), labels[g], b - a));
  }
}

/// The samples of chunk [ca, cb) kept, one in R (4b): less those at rest (standstill: drop)
/// and the slow ones (min_speed); counted in o.
std::vector<long> FilteredLs::keptSamples(const exid::ObservationModel& model, const Processed& P,
                                          const exid::Dataset& f, const std::vector<char>& rest,
                                          long lo, long ca, long cb, ChunkOut* o) const {
  const int R = P.R;
  const bool drop_rest = P.standstill == "drop";
  const exid::RobotModel& robot = model.robot();
  const bool via_T = min_speed_joint_ && robot.hasTransmission();
  std::vector<long> kept_samples;
  for (long sidx = ((ca + R - 1) / R) * R; sidx < cb; sidx += R) {
    if (drop_rest && rest[static_cast<std::size_t>(sidx - lo)]) {
      ++o->rest_removed;
      continue;
    }
    if (!min_speed_.empty()) {
      const auto v_row = f.qd.row(sidx - lo).transpose();
      const Eigen::VectorXd v =
          via_T ? Eigen::VectorXd(robot.transmission * v_row) : Eigen::VectorXd(v_row);
      bool slow = false;
      for (Eigen::Index j = 0; j < v.size(); ++j)
        slow = slow || std::abs(v(j)) < min_speed_[static_cast<std::size_t>(j)];
      if (slow) {
        ++o->slow;
        continue;
      }
    }
    kept_samples.push_back(sidx);
  }
  return kept_samples;
}

/// Steps 1-4 (also used for the validation rows of raw validation data, so that the held-out
/// error is measured on rows processed exactly like the identification rows). In chunks of
/// samples, in memory or streamed alike: each chunk's raw samples (with the margins of the
/// filters) read in order, filtered, differentiated, turned into rows, decimated and
/// accumulated on several threads, merged in chunk order (the same result for any thread
/// count, and for a recording read whole or streamed).
FilteredLs::Processed FilteredLs::process(const exid::ObservationModel& model,
                                          const exid::Dataset& data, const exid::RunContext& ctx,
                                          bool keep_rows) const {
  if (data.facts.parts.size() < 2) return processPart(model, data, ctx, keep_rows);
  exid::check(!data.streamed(), "filtered_ls: a dataset of several recordings must be in memory");
  Processed all;
  bool first = true;
  const int p = model.numBase();
  for (const exid::PartRange& pr : exid::partRanges(data.t, data.facts)) {
    exid::Dataset part = exid::sliceDataset(data, pr.begin, pr.end);
    part.facts.parts.clear();
    part.source = data.facts.parts[static_cast<std::size_t>(pr.part)].source;
    Processed P = processPart(model, part, ctx, keep_rows);
    if (first) {  // the first part: its plan
      all = std::move(P);
      first = false;
      continue;
    }
    exid::check(std::abs(P.fs - all.fs) <= 1e-6 * all.fs && P.R == all.R,
                fmt::format("filtered_ls: the recordings are sampled at different rates ({} at "
                            "{:g} Hz, the first at {:g} Hz): one filter and decimation needs one "
                            "rate (resample_hz puts each recording on the same grid)",
                            part.source, P.fs, all.fs));
    all.acc.merge(P.acc);
    if (keep_rows) appendRows(&all.rows, P.rows, p);
    all.chunks += P.chunks;
    all.threads = std::max(all.threads, P.threads);
    all.column_blocks = std::max(all.column_blocks, P.column_blocks);
    all.buffer_bytes = std::max(all.buffer_bytes, P.buffer_bytes);
    all.jitter = std::max(all.jitter, P.jitter);
    all.rows_before += P.rows_before;
    all.slow_removed += P.slow_removed;
    all.samples_after_decimation += P.samples_after_decimation;
    all.rest_samples += P.rest_samples;
    all.rest_removed += P.rest_removed;
    all.rest_edge_samples += P.rest_edge_samples;
    all.trimmed_total += P.trimmed_total;
    ++all.parts;
  }
  return all;
}

FilteredLs::Processed FilteredLs::processPart(const exid::ObservationModel& model,
                                              const exid::Dataset& data,
                                              const exid::RunContext& ctx, bool keep_rows) const {
  Processed P;
  estimators::Sos sos, dsos;
  ctx.report(0.0, "filtered_ls: planning");
  plan(model, data, &P, &sos, &dsos);
  const long K = data.size(), trim = P.trim, Kt = K - 2 * trim, C = P.chunk_samples;
  const long margin = P.margin_samples, sm = P.signal_margin;
  const long nchunks = (Kt + C - 1) / C;
  P.chunks = nchunks;
  const int p = model.numBase();
  // threads: 0 chooses from the work: a thread per 4 chunks at least (each thread holds its
  // own chunk's buffers, and a chunk's margins are computed by both of its neighbours' threads:
  // with fewer chunks the threads cost more memory than they save time), at most the cores.
  const long per_thread = threads_ == 0 ? 4 : 1;
  const int T = static_cast<int>(
      std::max<long>(1, std::min<long>(exid::resolveThreads(threads_), nchunks / per_thread)));
  P.threads = T;
  // chunk c: trimmed samples [ca, cb), rows of [lo, hi), raw samples [rlo, rhi)
  struct Span {
    long ca, cb, lo, hi, rlo, rhi;
  };
  auto spanOf = [&](long c) {
    Span s;
    s.ca = c * C;
    s.cb = std::min(Kt, s.ca + C);
    s.lo = P.per_sample ? std::max<long>(0, s.ca - margin) : 0;
    s.hi = P.per_sample ? std::min(Kt, s.cb + margin) : Kt;
    s.rlo = std::max<long>(0, trim + s.lo - sm);
    s.rhi = std::min(K, trim + s.hi + sm);
    return s;
  };
  std::vector<ChunkOut> outs(2 * static_cast<std::size_t>(T));  // the chunks in flight
  auto out = [&](long c) -> ChunkOut& { return outs[static_cast<std::size_t>(c % (2 * T))]; };
  exid::SampleWindow window(data);
  P.acc = estimators::RowAccumulator(p);
  exid::Rows all;
  ctx.report(0.1, "filtered_ls: filtering, rows and decimation");
  estimators::pipelineChunks(
      nchunks, T,
      [&](long c, exid::Dataset* raw) {
        const Span s = spanOf(c);
        *raw = window.span(static_cast<int>(s.rlo), static_cast<int>(s.rhi));
      },
      [&](long c, const exid::Dataset& raw) {
        if (ctx.shouldStop()) throw exid::Error("filtered_ls: stopped");
        const Span s = spanOf(c);
        const std::vector<char> rest_raw = standstill(raw, P);
        const auto from = static_cast<std::ptrdiff_t>(trim + s.lo - s.rlo),
                   to = static_cast<std::ptrdiff_t>(trim + s.hi - s.rlo);
        const exid::Dataset f = exid::sliceDataset(filtered(raw, P, sos, rest_raw),
                                                   static_cast<int>(from), static_cast<int>(to));
        const std::vector<char> rest(rest_raw.begin() + from, rest_raw.begin() + to);
        ChunkOut& o = out(c);
        o = ChunkOut();
        chunkRows(model, P, dsos, f, rest, s.lo, s.ca, s.cb, keep_rows, ctx, &o);
      },
      [&](long c) {  // in chunk order: deterministic
        ChunkOut& o = out(c);
        P.acc.merge(o.acc);
        P.rows_before += o.rows_before;
        P.column_blocks = std::max(P.column_blocks, o.column_blocks);
        P.buffer_bytes = std::max(P.buffer_bytes, o.buffer_bytes);
        P.slow_removed += o.slow;
        P.rest_samples += o.rest;
        P.rest_edge_samples += o.rest_edge;
        P.rest_removed += o.rest_removed;
        P.samples_after_decimation += o.kept + o.slow + o.rest_removed;
        if (keep_rows) appendRows(&all, o.rows, p);
        o = ChunkOut();
        ctx.report(0.1 + 0.8 * static_cast<double>(c + 1) / static_cast<double>(nchunks),
                   fmt::format("filtered_ls: {} / {} chunks", c + 1, nchunks));
      });
  exid::check(P.acc.rows() > 0,
              fmt::format("filtered_ls: no rows left of '{}'{}{}", data.source,
                          min_speed_.empty() ? "" : " (min_speed removed every sample)",
                          P.standstill == "drop" && P.rest_removed > 0
                              ? fmt::format(" ({} rows at a standstill removed: standstill: "
                                            "drop; zero_velocity keeps them)",
                                            P.rest_removed)
                              : std::string()));
  if (keep_rows) P.rows = std::move(all);
  return P;
}

void FilteredLs::appendRows(exid::Rows* all, const exid::Rows& r, int p) {
  const Eigen::Index r0 = all->W.rows();
  all->W.conservativeResize(r0 + r.W.rows(), p);
  all->y.conservativeResize(r0 + r.y.size());
  all->W.bottomRows(r.W.rows()) = r.W;
  all->y.tail(r.y.size()) = r.y;
  all->equation.insert(all->equation.end(), r.equation.begin(), r.equation.end());
  all->t.insert(all->t.end(), r.t.begin(), r.t.end());
  all->numEquations = r.numEquations;
  all->equation_names = r.equation_names;
}

}  // namespace exid::filtered_ls
