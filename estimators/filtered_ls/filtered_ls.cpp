// exid — estimator `filtered_ls`: the standard practice on measured data (Gautier):
//   1. zero-phase low-pass of the positions q: Butterworth (bilinear transform, order
//      filter_order, -3 dB at cutoff_hz per pass), run forward and backward (filtfilt) with
//      odd extension and steady-state initial conditions (no edge step transient);
//   2. qd and qdd by central differences of the filtered q when the data lack them or
//      `differentiate: true`; measured qd / qdd otherwise pass through the same filter;
//   2b. where the whole robot stands still (every joint's raw position held, within
//      standstill_tolerance, for at least standstill_min_s), qd and qdd are zero (and, with
//      standstill: drop, the rows are removed): the zero-phase filter would start the motion a
//      few samples early there, and the Coulomb column would take the sign of a velocity the
//      torque at rest does not have;
//   3. a few samples at both ends are dropped (trim_edges), where filtering and differences
//      are least accurate;
//   4. rows W, y from the model, then parallel decimation: every column of W and y, per
//      equation, low-pass filtered (its own zero-phase Butterworth, cutoff
//      decimation_cutoff_ratio x the new Nyquist frequency) and one sample in `decimation` kept;
//   4b. optionally (min_speed) the samples where a joint is nearly at rest are removed;
//   5. least squares with batch_ls's solver (QR of [W y], rank-revealing SVD, covariance).
// Every step runs chunk by chunk, with margins: a chunk's rows are decimated with the decimation
// filter's settling time of context at each side, and its signals filtered from the position
// filter's settling time (to 1e-16) more, so that a chunk gives what the whole recording would
// and memory is bounded by the chunk, not the recording. A recording is read whole or streamed
// from its file alike (specs().streams), with the same result.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <exception>
#include <map>
#include <thread>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/interfaces.hpp"

namespace {

namespace estimators = exid::estimators;

class FilteredLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "filtered_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "least squares on real data: zero-phase Butterworth filtering of q, central differences for "
      "qd/qdd, parallel decimation of W and y, then batch_ls's solver";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_double(
            "cutoff_hz", 10.0, "Hz",
            "cutoff (-3 dB per pass) of the position low-pass; 0: positions not filtered", 0.0),
        exid::param_int("filter_order", 4, "order of the position Butterworth filter", 1.0, 20.0),
        exid::param_bool(
            "differentiate", false,
            "always compute qd, qdd by central differences of the filtered q (otherwise "
            "only when the data lack them)"),
        exid::param_int("decimation", 0,
                        "parallel decimation factor; 0: automatic (floor(0.2 fs / cutoff_hz), 1 "
                        "without a position filter); 1: none",
                        0.0, 1e6),
        exid::param_int("decimation_order", 8, "order of the decimation Butterworth filter", 1.0,
                        20.0),
        exid::param_double(
            "decimation_cutoff_ratio", 0.8, "",
            "decimation filter cutoff as a fraction of the decimated Nyquist frequency", 0.0, 1.0,
            true, true),
        exid::param_bool("correct_correlation", true,
                         "scale the covariance by kappa, the long-run / marginal variance ratio of "
                         "white noise after the decimation filter (the decimated residuals are "
                         "correlated; without it std is under-stated by ~15 %)"),
        exid::param_int("trim_edges", -1,
                        "samples dropped at each end after filtering; -1: automatic "
                        "(ceil(2 fs / cutoff_hz), or 1 after differentiating without a filter)",
                        -1.0, 1e9),
        exid::param_doubles("min_speed", std::vector<double>{}, "rad/s or m/s",
                            "per joint: samples (after decimation) where any joint moves slower "
                            "than its value are removed whole (where Coulomb friction changes "
                            "sign; FIGAROH's dq_lim_def rule); empty: none removed"),
        exid::param_string("min_speed_frame", std::string("measured"),
                           "coordinates of min_speed: measured (the data's, e.g. motors) or "
                           "joint (through the robot's transmission)",
                           {"measured", "joint"}),
        exid::param_string(
            "standstill", std::string("auto"),
            "samples where the whole robot stands still (every joint's raw position stays within "
            "standstill_tolerance for at least standstill_min_s): zero_velocity: their qd and qdd "
            "are zero (the zero-phase filter starts the motion early there, and the Coulomb "
            "column would take the sign of a velocity the torque at rest does not have); drop: "
            "their rows are removed too (at rest, static friction holds an unknown torque, and "
            "at a standstill's edges the robot may move below the encoders' resolution); filter: "
            "as filtered, like every other sample; auto: drop where the model gives one row per "
            "sample and equation, zero_velocity otherwise",
            {"auto", "zero_velocity", "drop", "filter"}),
        exid::param_double("standstill_min_s", 0.0, "s",
                           "shortest standstill; 0: automatic (2 / cutoff_hz, the position "
                           "filter's transient, and at least 3 samples)",
                           0.0, 1e6),
        exid::param_doubles("standstill_tolerance", std::vector<double>{}, "rad or m",
                            "per joint, measured coordinates: the largest range of raw "
                            "positions that still counts as standing (noisy encoders); empty: "
                            "positions repeat exactly (the encoder did not tick)"),
        exid::param_int("chunk_samples", 8192,
                        "samples per chunk of the row pipeline (rows, decimation filter, "
                        "accumulation): memory is bounded by the chunk (plus the decimation "
                        "filter's settling margin at each side), not by the recording",
                        64, 1e8),
        exid::param_int(
            "threads", 0,
            "threads building the chunks (0: the cores this process may run on, at most 8); the "
            "chunks are merged in order, so the result is the same for any count",
            0, 256),
        exid::estimators::rankToleranceParam(),
    };
  }

  explicit FilteredLs(const exid::ParamSet& p)
      : cutoff_(p.getDouble("cutoff_hz")),
        order_(static_cast<int>(p.getInt("filter_order"))),
        differentiate_(p.getBool("differentiate")),
        decimation_(static_cast<int>(p.getInt("decimation"))),
        dec_order_(static_cast<int>(p.getInt("decimation_order"))),
        dec_ratio_(p.getDouble("decimation_cutoff_ratio")),
        trim_(p.getInt("trim_edges")),
        correct_(p.getBool("correct_correlation")),
        min_speed_(p.getDoubles("min_speed")),
        min_speed_joint_(p.getString("min_speed_frame") == "joint"),
        standstill_(p.getString("standstill")),
        standstill_min_s_(p.getDouble("standstill_min_s")),
        standstill_tol_(p.getDoubles("standstill_tolerance")),
        chunk_samples_(p.getInt("chunk_samples")),
        threads_(static_cast<int>(p.getInt("threads"))) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
  }

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.needs_raw_dataset = true;
    s.accepts_prior = true;
    s.streams = true;  // chunks of samples with the filters' margins (process())
    return s;
  }

  /// Steps 1-4 (also used for the validation rows of raw validation data, so that the held-out
  /// error is measured on rows processed exactly like the identification rows).
  struct Processed {
    exid::Rows rows;                 // with keep_rows
    estimators::RowAccumulator acc;  // every kept row
    bool streamed = false, per_sample = true;
    long chunk_samples = 0, margin_samples = 0, signal_margin = 0;
    long chunks = 0;
    int threads = 1;
    double fs = 0.0, jitter = 0.0, dec_cut = 0.0, kappa = 1.0;
    bool filter_q = false, diff_qd = false, diff_qdd = false;
    long trim = 0, trim_transient = 0;
    bool trim_default = false;
    int R = 1;
    long rows_before = 0, slow_removed = 0, samples_after_decimation = 0;
    std::string standstill;                   // the mode in force (auto resolved)
    long rest_min = 0;                        // standstill: shortest run [samples]; 0: off
    long rest_samples = 0, rest_removed = 0;  // trimmed samples at rest; rows removed (drop)
    long rest_edge_samples = 0;               // trimmed samples at a standstill's edges (drop)
    std::string dec_note;
  };

  /// Steps 1-3 decided before any sample is read: rates, filters, trim, decimation, chunks.
  void plan(const exid::ObservationModel& model, const exid::Dataset& data, Processed* P,
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
                fmt::format("filtered_ls: min_speed: expected {} values (one per joint), found {}",
                            n, min_speed_.size()));
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
    P->standstill =
        standstill_ == "auto" ? (P->per_sample ? "drop" : "zero_velocity") : standstill_;
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
    P->signal_margin =
        (P->filter_q ? estimators::settlingSamples(*sos, 1e-16) : 0) + (diff ? 4 : 0);
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
  std::vector<char> standstill(const exid::Dataset& raw, const Processed& P) const {
    const long K = raw.size(), L = P.rest_min;
    std::vector<char> rest(static_cast<std::size_t>(K), 0);
    if (L <= 0 || K < L) return rest;
    const long S = K - L + 1;  // window starts
    std::vector<char> ok(static_cast<std::size_t>(S), 1);
    for (Eigen::Index j = 0; j < raw.q.cols(); ++j) {
      const double tol =
          standstill_tol_.empty() ? 0.0 : standstill_tol_[static_cast<std::size_t>(j)];
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
  exid::Dataset filtered(exid::Dataset raw, const Processed& P, const estimators::Sos& sos,
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

  struct ChunkOut {
    exid::Rows rows;
    estimators::RowAccumulator acc;
    long slow = 0, kept = 0, rows_before = 0, rest = 0, rest_edge = 0, rest_removed = 0;
  };

  /// Step 4 for chunk [ca, cb) of the trimmed samples: f holds the filtered samples [lo, hi)
  /// (the chunk and its decimation margins). The rows, one row of M per sample (equation g's p
  /// base columns and its y at columns [g (p + 1), (g + 1)(p + 1))), built a block of samples at
  /// a time (the model's rows of the whole chunk are never held), every column filtered at once,
  /// one sample in R kept (4b: less the slow ones) and accumulated.
  void chunkRows(const exid::ObservationModel& model, const Processed& P,
                 const estimators::Sos& dsos, const exid::Dataset& f, const std::vector<char>& rest,
                 long lo, long ca, long cb, bool keep_rows, const exid::RunContext& ctx,
                 ChunkOut* o) const {
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
    const long L = hi - lo;
    constexpr long kBlock = 1024;
    estimators::LargeRows Mbuf;  // huge pages: written once, tens of MB
    std::vector<int> labels;     // equation label of each group, ascending
    std::vector<double> times;   // (keep_rows) per sample and group: the row's time
    exid::Rows head;             // numEquations, equation_names
    for (long a = lo; a < hi; a += kBlock) {
      const long b = std::min(hi, a + kBlock);
      exid::Rows rows = model.rows(
          exid::sliceDataset(f, static_cast<int>(a - lo), static_cast<int>(b - lo)), ctx);
      estimators::checkRows(rows, p, kName, static_cast<int>(trim + a));
      if (a == lo) {
        if (rows.equation.empty()) {
          labels = {0};
        } else {
          labels = rows.equation;
          std::sort(labels.begin(), labels.end());
          labels.erase(std::unique(labels.begin(), labels.end()), labels.end());
        }
        Mbuf = estimators::LargeRows(L, static_cast<Eigen::Index>(labels.size()) * (p + 1));
        const bool has_t = rows.t.size() == static_cast<std::size_t>(rows.y.size());
        if (keep_rows && has_t) times.resize(static_cast<std::size_t>(L) * labels.size());
        head.numEquations = rows.numEquations;
        head.equation_names = rows.equation_names;
        o->rows_before =
            static_cast<long>(std::min<long>(cb - ca, L) * std::max(1, rows.numEquations));
      }
      const auto G = labels.size();
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
        const Eigen::Index c0 = static_cast<Eigen::Index>(g) * (p + 1);
        M.row(sm).segment(c0, p) = rows.W.row(i);
        M(sm, c0 + p) = rows.y(i);
        if (!times.empty())
          times[static_cast<std::size_t>(sm) * G + g] = rows.t[static_cast<std::size_t>(i)];
      }
      for (std::size_t g = 0; g < G; ++g)
        exid::check(next[g] == b - lo,
                    fmt::format("filtered_ls: model '{}' gave {} rows of equation {} for {} "
                                "samples",
                                model.pluginName(), next[g] - (a - lo), labels[g], b - a));
    }
    auto M = Mbuf.map();
    const bool drop_rest = P.standstill == "drop";
    // Rows to be dropped are zero before the decimation filter (0 = 0 theta holds exactly): the
    // filter would otherwise spread them into the kept rows beside a standstill (at its edges
    // the positions are held while the robot may already move).
    if (drop_rest)
      for (long k = 0; k < L; ++k)
        if (rest[static_cast<std::size_t>(k)]) M.row(k).setZero();
    if (R > 1 && L >= 2) estimators::filtfiltRowsInPlace(dsos, M);
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
    const auto G = static_cast<Eigen::Index>(labels.size());
    Eigen::MatrixXd W(static_cast<Eigen::Index>(kept_samples.size()) * G, p);
    Eigen::VectorXd y(W.rows());
    exid::Rows out;
    out.numEquations = head.numEquations;
    out.equation_names = head.equation_names;
    for (std::size_t k = 0; k < kept_samples.size(); ++k) {
      const long local = kept_samples[k] - lo;
      for (Eigen::Index g = 0; g < G; ++g) {
        const Eigen::Index r = static_cast<Eigen::Index>(k) * G + g;
        W.row(r) = M.row(local).segment(g * (p + 1), p);
        y(r) = M(local, g * (p + 1) + p);
        if (keep_rows) {
          out.equation.push_back(labels[static_cast<std::size_t>(g)]);
          if (!times.empty()) out.t.push_back(times[static_cast<std::size_t>(local * G + g)]);
        }
      }
    }
    o->kept = static_cast<long>(kept_samples.size());
    o->acc = estimators::RowAccumulator(p);
    o->acc.add(W, y);
    if (keep_rows) {
      out.W = std::move(W);
      out.y = std::move(y);
      o->rows = std::move(out);
    }
  }

  /// Steps 1-4 (also used for the validation rows of raw validation data, so that the held-out
  /// error is measured on rows processed exactly like the identification rows). In chunks of
  /// samples, in memory or streamed alike: each chunk's raw samples (with the margins of the
  /// filters) read in order, filtered, differentiated, turned into rows, decimated and
  /// accumulated on several threads, merged in chunk order (the same result for any thread
  /// count, and for a recording read whole or streamed).
  Processed process(const exid::ObservationModel& model, const exid::Dataset& data,
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
    const int T = static_cast<int>(std::min<long>(exid::resolveThreads(threads_), nchunks));
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

  static void appendRows(exid::Rows* all, const exid::Rows& r, int p) {
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

  exid::Rows validationRows(const exid::ObservationModel& model, const exid::Dataset& data,
                            const exid::RunContext& ctx) const override {
    return process(model, data, ctx, true).rows;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int K = data.size();
    Processed P = process(model, data, ctx, false);
    const double fs = P.fs, jitter = P.jitter, kappa = P.kappa, dec_cut = P.dec_cut;
    const bool filter_q = P.filter_q, diff_qd = P.diff_qd, diff_qdd = P.diff_qdd;
    const long trim = P.trim, rows_before = P.rows_before;
    const int R = P.R;
    const std::string& dec_note = P.dec_note;

    // ---- 5. least squares
    ctx.report(0.9, "filtered_ls: solving");
    const estimators::RowAccumulator& acc = P.acc;
    exid::Estimate e;
    if (!prior) {
      const estimators::LsSolution s =
          estimators::solveLeastSquares(acc, model.base().names, opt_, kName);
      estimators::fillEstimate(&e, model, s, s.rss, s.m);
      if (kappa != 1.0) {  // decimated residuals are correlated: scale the covariance
        e.covariance *= kappa;
        e.std *= std::sqrt(kappa);
        e.details["parameters"] = estimators::parameterTable(e);
      }
    } else {
      // Regularised least squares (docs/consistent.md "Priors"): the rows divided by their noise
      // std, inflated by the decimation's variance factor (the data carry kappa times less
      // information than independent rows would), stacked with the prior's pseudo-observations.
      double noise = 0.0;
      const estimators::LsSolution s =
          estimators::solveWithPrior(acc, *prior, model.base().names, opt_, kName, kappa, &noise);
      estimators::fillEstimate(&e, model, s, acc.residualSquared(s.theta), acc.rows());
      e.rows = acc.rows();
      e.details["noise_std"] = noise;
      e.details["prior"] = estimators::priorDetails(*prior, s.theta, s.std);
      e.details["covariance_definition"] =
          "posterior (W^T W / s^2 + Sigma_prior^-1)^-1, s^2 = kappa rss / (m - rank) of the "
          "rank-tolerant fit of the rows alone (kappa: the decimation's variance factor)";
    }
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["fs_hz"] = fs;
    d["sampling_jitter"] = jitter;
    d["cutoff_hz"] = filter_q ? exid::Json(cutoff_) : exid::Json(nullptr);
    d["filter_order"] = order_;
    d["filter"] =
        filter_q ? "Butterworth (bilinear), forward-backward (zero phase, |H|^2)" : "none";
    d["qd_source"] = diff_qd ? "central differences of filtered q"
                             : (filter_q ? "measured, filtered" : "measured");
    d["qdd_source"] = diff_qdd ? (diff_qd ? "central second differences of filtered q"
                                          : "central differences of filtered qd")
                               : (filter_q ? "measured, filtered" : "measured");
    d["trimmed_samples_each_end"] = Json(static_cast<long long>(trim));
    d["trimmed_percent"] = 100.0 * 2.0 * static_cast<double>(trim) / std::max(1, K);
    if (P.trim_default)
      d["trim_rule"] =
          trim < P.trim_transient
              ? fmt::format(
                    "ceil(2 fs / fc) = {} samples capped at 5 % of the data: {} at each end",
                    P.trim_transient, trim)
              : fmt::format("ceil(2 fs / fc) = {} samples at each end", trim);
    if (jitter > 0.05) {
      if (!d.find("warnings")) d["warnings"] = Json::array();
      d["warnings"].push_back(Json(fmt::format(
          "filtered_ls: the sampling of '{}' is not uniform (max |dt - median| = {:.0f} % of the "
          "median step); the filters assume fs = {:g} Hz (the csv experiment's resample_hz puts "
          "the data on a uniform grid)",
          data.source, 100 * jitter, fs)));
    }
    if (2 * trim > K / 10) {
      if (!d.find("warnings")) d["warnings"] = Json::array();
      d["warnings"].push_back(Json(fmt::format(
          "filtered_ls: trim_edges = {} discards {} of the {} samples ({:.1f} %, more than 10 %)",
          trim, 2 * trim, K, 200.0 * static_cast<double>(trim) / K)));
    }
    if (!min_speed_.empty()) {
      d["min_speed"] = Json(min_speed_);
      d["slow_samples_removed"] = Json(static_cast<long long>(P.slow_removed));
      d["slow_samples_removed_percent"] =
          100.0 * static_cast<double>(P.slow_removed) /
          static_cast<double>(std::max<long>(1, P.samples_after_decimation));
    }
    {
      Json st = Json::object();
      st["mode"] = P.standstill;
      if (standstill_ == "auto")
        st["mode_rule"] = P.per_sample ? "auto: drop (the model gives one row per sample)"
                                       : "auto: zero_velocity (the model's rows span samples)";
      if (P.rest_min > 0) {
        const long Kt = K - 2 * trim;
        st["min_samples"] = Json(static_cast<long long>(P.rest_min));
        st["tolerance"] =
            standstill_tol_.empty() ? Json("exact repetition") : Json(standstill_tol_);
        st["samples"] = Json(static_cast<long long>(P.rest_samples));
        st["percent"] = 100.0 * static_cast<double>(P.rest_samples) /
                        static_cast<double>(std::max<long>(1, Kt));
        if (P.standstill == "drop") {
          st["edge_samples"] = Json(static_cast<long long>(P.rest_edge_samples));
          st["rows_removed"] = Json(static_cast<long long>(P.rest_removed));
        }
        st["rule"] = fmt::format(
            "a sample stands still when it lies in {} samples over which every joint's raw "
            "position {}; {}",
            P.rest_min,
            standstill_tol_.empty() ? "repeats exactly" : "stays within standstill_tolerance",
            P.standstill == "drop"
                ? fmt::format("its rows are removed, and those of the {} samples at each side "
                              "of a standstill (the position filter's transient)",
                              P.rest_min)
                : std::string("there qd = qdd = 0"));
      }
      d["standstill"] = st;
    }
    d["decimation"] = R;
    d["decimation_cutoff_hz"] = R > 1 ? exid::Json(dec_cut) : exid::Json(nullptr);
    d["decimation_order"] = dec_order_;
    if (!dec_note.empty()) d["decimation_note"] = dec_note;
    d["rows_before_decimation"] = Json(static_cast<long long>(rows_before));
    d["streamed"] = P.streamed;
    d["chunk_samples"] = Json(static_cast<long long>(P.chunk_samples));
    d["chunks"] = Json(static_cast<long long>(P.chunks));
    d["chunk_margin_samples"] = Json(static_cast<long long>(P.margin_samples));
    d["signal_margin_samples"] = Json(static_cast<long long>(P.signal_margin));
    d["threads"] = P.threads;
    d["memory"] =
        P.streamed
            ? "per chunk of chunk_samples: its samples (with both filters' margins at each "
              "side) read, filtered, differentiated, turned into rows, decimated and "
              "accumulated; memory bounded by the chunk (times the threads), not the recording"
            : fmt::format(
                  "the model '{}' does not give one row per sample: its rows of the whole "
                  "recording are held at once",
                  model.pluginName());
    d["samples"] = K;
    d["noise_correlation_factor"] = kappa;
    d["std_definition"] =
        std::string(prior ? "posterior (W^T W / (kappa sigma^2) + Sigma_prior^-1)^-1"
                          : "covariance = kappa sigma^2 (W^T W)^-1") +
        " on the decimated rows; kappa = sum of the autocorrelation of white noise after the "
        "decimation filter, at multiples of the decimation factor (the decimated residuals are "
        "correlated; kappa = 1 without correction)";
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ctx.report(1.0, "filtered_ls: done");
    return e;
  }

 private:
  using Json = exid::Json;
  double cutoff_;
  int order_;
  bool differentiate_;
  int decimation_, dec_order_;
  double dec_ratio_;
  long trim_;
  bool correct_;
  std::vector<double> min_speed_;
  bool min_speed_joint_ = false;
  std::string standstill_;
  double standstill_min_s_ = 0.0;
  std::vector<double> standstill_tol_;
  long chunk_samples_ = 8192;
  int threads_ = 0;
  estimators::SolveOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(FilteredLs)
