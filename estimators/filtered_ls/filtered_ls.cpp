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
#include "filtered_ls.hpp"

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

namespace exid::filtered_ls {

std::vector<exid::ParamDecl> FilteredLs::params() {
  return {
      exid::param_double(
          "cutoff_hz", 10.0, "Hz",
          "cutoff (-3 dB per pass) of the position low-pass; 0: positions not filtered", 0.0),
      exid::param_int("filter_order", 4, "order of the position Butterworth filter", 1.0, 20.0),
      exid::param_bool("differentiate", false,
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
      exid::param_double("chunk_memory_mb", 16.0, "MB",
                         "the largest rows buffer of one chunk (per thread): a chunk's rows "
                         "(every equation's base columns and measurement, its samples and the "
                         "decimation margins) are filtered a block of columns at a time within "
                         "it, the model's rows computed once per block (the same numbers for "
                         "any value)",
                         0.001, 1e6),
      exid::param_int(
          "threads", 0,
          "threads building the chunks (0: from the work, a thread per 4 chunks, at most the "
          "cores this process may run on and 8); the chunks are merged in order, so the result "
          "is the same for any count",
          0, 256),
      exid::estimators::rankToleranceParam(),
  };
}

FilteredLs::FilteredLs(const exid::ParamSet& p)
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
      chunk_memory_mb_(p.getDouble("chunk_memory_mb")),
      threads_(static_cast<int>(p.getInt("threads"))) {
  opt_.rank_tolerance = p.getDouble("rank_tolerance");
}

exid::Estimate FilteredLs::estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                                    const exid::Prior* prior, const exid::RunContext& ctx) {
  const auto t0 = std::chrono::steady_clock::now();
  const int K = data.size();
  Processed P = process(model, data, ctx, false);
  const double kappa = P.kappa, dec_cut = P.dec_cut;
  const long rows_before = P.rows_before;
  const int R = P.R;
  const std::string& dec_note = P.dec_note;

  // ---- 5. least squares
  ctx.report(0.9, "filtered_ls: solving");
  exid::Estimate e = solve(model, P, prior);
  exid::Json& d = e.details;
  describeFilters(P, data, &d);
  describeStandstill(P, K, &d);
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
  d["threads_from"] = threads_ == 0 ? "the work (threads: 0): a thread per 4 chunks, at most "
                                      "the cores"
                                    : "the study (threads)";
  d["column_blocks"] = Json(static_cast<long long>(P.column_blocks));
  d["chunk_buffer_mb"] = P.buffer_bytes / 1e6;
  d["memory"] =
      P.streamed ? "per chunk of chunk_samples: its samples (with both filters' margins at each "
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

/// Step 5: least squares on the accumulated rows (the covariance scaled by kappa), or with a
/// prior the regularised least squares.
exid::Estimate FilteredLs::solve(const exid::ObservationModel& model, const Processed& P,
                                 const exid::Prior* prior) const {
  const double kappa = P.kappa;
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
  return e;
}

/// The filters' details: the sampling, the cutoffs and sources of qd and qdd, the trimmed
/// edges, min_speed, and the warnings on the sampling and the trimmed share.
void FilteredLs::describeFilters(const Processed& P, const exid::Dataset& data,
                                 exid::Json* dp) const {
  exid::Json& d = *dp;
  const int K = data.size();
  const double fs = P.fs, jitter = P.jitter;
  const bool filter_q = P.filter_q, diff_qd = P.diff_qd, diff_qdd = P.diff_qdd;
  const long trim = P.trim;
  d["estimator"] = kName;
  d["fs_hz"] = fs;
  d["sampling_jitter"] = jitter;
  d["cutoff_hz"] = filter_q ? exid::Json(cutoff_) : exid::Json(nullptr);
  d["filter_order"] = order_;
  d["filter"] = filter_q ? "Butterworth (bilinear), forward-backward (zero phase, |H|^2)" : "none";
  d["qd_source"] = diff_qd ? "central differences of filtered q"
                           : (filter_q ? "measured, filtered" : "measured");
  d["qdd_source"] = diff_qdd ? (diff_qd ? "central second differences of filtered q"
                                        : "central differences of filtered qd")
                             : (filter_q ? "measured, filtered" : "measured");
  d["trimmed_samples_each_end"] = Json(static_cast<long long>(trim));
  d["trimmed_percent"] = 100.0 * static_cast<double>(P.trimmed_total) / std::max(1, K);
  if (P.parts > 1) {
    d["recordings"] = Json(static_cast<long long>(P.parts));
    d["recordings_rule"] =
        "each recording filtered, differentiated, trimmed (trimmed_samples_each_end at both of "
        "its ends, the first's) and decimated on its own; the rows merged in order";
    d["trimmed_samples"] = Json(static_cast<long long>(P.trimmed_total));
  }
  if (P.trim_default)
    d["trim_rule"] =
        trim < P.trim_transient
            ? fmt::format("ceil(2 fs / fc) = {} samples capped at 5 % of the data: {} at each end",
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
  if (P.trimmed_total > K / 10) {
    if (!d.find("warnings")) d["warnings"] = Json::array();
    d["warnings"].push_back(Json(fmt::format(
        "filtered_ls: trim_edges = {} discards {} of the {} samples ({:.1f} %, more than 10 %)",
        trim, P.trimmed_total, K, 100.0 * static_cast<double>(P.trimmed_total) / K)));
  }
  if (!min_speed_.empty()) {
    d["min_speed"] = Json(min_speed_);
    d["slow_samples_removed"] = Json(static_cast<long long>(P.slow_removed));
    d["slow_samples_removed_percent"] =
        100.0 * static_cast<double>(P.slow_removed) /
        static_cast<double>(std::max<long>(1, P.samples_after_decimation));
  }
}

/// details.standstill: the mode, and where samples stand still, how many and their rule.
void FilteredLs::describeStandstill(const Processed& P, int K, exid::Json* dp) const {
  exid::Json& d = *dp;
  {
    Json st = Json::object();
    st["mode"] = P.standstill;
    if (standstill_ == "auto")
      st["mode_rule"] = P.per_sample ? "auto: drop (the model gives one row per sample)"
                                     : "auto: zero_velocity (the model's rows span samples)";
    if (P.rest_min > 0) {
      const long Kt = K - P.trimmed_total;
      st["min_samples"] = Json(static_cast<long long>(P.rest_min));
      st["tolerance"] = standstill_tol_.empty() ? Json("exact repetition") : Json(standstill_tol_);
      st["samples"] = Json(static_cast<long long>(P.rest_samples));
      st["percent"] =
          100.0 * static_cast<double>(P.rest_samples) / static_cast<double>(std::max<long>(1, Kt));
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
}

}  // namespace exid::filtered_ls

EXID_REGISTER_PLUGIN(exid::filtered_ls::FilteredLs)
