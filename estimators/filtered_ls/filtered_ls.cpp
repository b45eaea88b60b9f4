// exid — estimator `filtered_ls`: the standard practice on measured data (Gautier):
//   1. zero-phase low-pass of the positions q: Butterworth (bilinear transform, order
//      filter_order, -3 dB at cutoff_hz per pass), run forward and backward (filtfilt) with
//      odd extension and steady-state initial conditions (no edge step transient);
//   2. qd and qdd by central differences of the filtered q when the data lack them or
//      `differentiate: true`; measured qd / qdd otherwise pass through the same filter;
//   3. a few samples at both ends are dropped (trim_edges), where filtering and differences
//      are least accurate;
//   4. rows W, y from the model, then parallel decimation: every column of W and y, per
//      equation, low-pass filtered (its own zero-phase Butterworth, cutoff
//      decimation_cutoff_ratio x the new Nyquist frequency) and one sample in `decimation` kept;
//   5. least squares with batch_ls's solver (QR of [W y], rank-revealing SVD, covariance).
// Holds the filtered signals and the rows of the whole dataset in memory (filtfilt is
// non-causal): memory O(samples x rows per sample x p), unlike batch_ls.
#include <fmt/format.h>

#include <chrono>
#include <cmath>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/interfaces.hpp"

namespace {

namespace est = exid::est;

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
        exid::param_double("rank_tolerance", 1e-8, "",
                           "a direction is unidentifiable when its singular value of the "
                           "column-scaled W is below this times the largest",
                           0.0, 1.0, true, true),
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
        correct_(p.getBool("correct_correlation")) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
  }

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.needs_raw_dataset = true;
    s.accepts_prior = true;
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int K = data.size();
    exid::check(K >= 8,
                fmt::format("filtered_ls: dataset '{}' has {} samples; filtering needs at least 8",
                            data.source, K));
    exid::check(data.q.rows() == K && data.q.cols() > 0,
                fmt::format("filtered_ls: dataset '{}' has no positions q", data.source));
    double jitter = 0.0;
    const double fs = est::samplingRate(data.t, &jitter);
    if (jitter > 0.05)
      exid::logWarn(
          fmt::format("filtered_ls: sampling of '{}' is not uniform (max |dt - median| = {:.0f} % "
                      "of the median); filters assume fs = {:g} Hz",
                      data.source, 100 * jitter, fs));
    const bool filter_q = cutoff_ > 0.0;
    if (filter_q)
      exid::check(cutoff_ < 0.5 * fs,
                  fmt::format("filtered_ls: cutoff_hz = {:g} Hz must be below the Nyquist "
                              "frequency fs/2 = {:g} Hz of '{}'",
                              cutoff_, 0.5 * fs, data.source));

    // ---- 1-2. filtering and differentiation
    ctx.report(0.0, "filtered_ls: filtering");
    exid::Dataset f = data;
    est::Sos sos;
    if (filter_q) {
      sos = est::butterworthLowpass(order_, cutoff_, fs);
      f.q = est::filtfiltColumns(sos, data.q);
    }
    const bool diff_qd = differentiate_ || !data.hasVelocity();
    const bool diff_qdd = differentiate_ || !data.hasAcceleration();
    if (diff_qd) {
      f.qd = est::centralFirstDerivative(data.t, f.q);
    } else if (filter_q) {
      f.qd = est::filtfiltColumns(sos, data.qd);
    }
    if (diff_qdd) {
      f.qdd = diff_qd ? est::centralSecondDerivative(data.t, f.q)
                      : est::centralFirstDerivative(data.t, f.qd);
    } else if (filter_q) {
      f.qdd = est::filtfiltColumns(sos, data.qdd);
    }
    if (ctx.shouldStop()) throw exid::Error("filtered_ls: stopped after filtering");

    // ---- 3. trim
    long trim = trim_;
    if (trim < 0)
      trim = filter_q ? static_cast<long>(std::ceil(2.0 * fs / cutoff_))
                      : ((diff_qd || diff_qdd) ? 1 : 0);
    exid::check(K - 2 * trim >= 8,
                fmt::format("filtered_ls: trimming {} samples at each end of {} leaves too few; "
                            "lower trim_edges or raise cutoff_hz",
                            trim, K));
    if (trim > 0) f = est::sliceDataset(f, static_cast<int>(trim), static_cast<int>(K - trim));

    // ---- 4. rows and parallel decimation
    ctx.report(0.3, "filtered_ls: observation rows");
    exid::Rows rows = model.rows(f, ctx);
    est::checkRows(rows, model.numBase(), kName, static_cast<int>(trim));
    const long rows_before = rows.y.size();
    int R = decimation_;
    std::string dec_note;
    if (R == 0)
      R = filter_q ? std::max(1, static_cast<int>(std::floor(0.2 * fs / cutoff_ + 1e-6))) : 1;
    if (R > 1 && !est::modelIsPerSample(model)) {
      dec_note = fmt::format(
          "decimation {} skipped: the model '{}' does not give one row per sample and equation", R,
          model.pluginName());
      exid::logWarn("filtered_ls: " + dec_note);
      R = 1;
    }
    double dec_cut = 0.0, kappa = 1.0;
    if (R > 1) {
      if (ctx.shouldStop()) throw exid::Error("filtered_ls: stopped before decimation");
      ctx.report(0.6, "filtered_ls: parallel decimation");
      dec_cut = dec_ratio_ * 0.5 * fs / R;
      const est::Sos dsos = est::butterworthLowpass(dec_order_, dec_cut, fs);
      rows = est::decimateRows(rows, R, dsos);
      if (correct_) kappa = est::decimationVarianceFactor(dsos, R);
    }

    // ---- 5. least squares
    ctx.report(0.9, "filtered_ls: solving");
    est::RowAccumulator acc(model.numBase());
    acc.add(rows.W, rows.y);
    exid::Estimate e;
    if (!prior) {
      const est::LsSolution s = est::solveLeastSquares(acc, model.base().names, opt_, kName);
      est::fillEstimate(&e, model, s, s.rss, s.m);
      if (kappa != 1.0) {  // decimated residuals are correlated: scale the covariance
        e.covariance *= kappa;
        e.std *= std::sqrt(kappa);
        e.details["parameters"] = est::parameterTable(e);
      }
    } else {
      // Regularised least squares (docs/consistent.md "Priors"): the rows divided by their noise
      // std, inflated by the decimation's variance factor (the data carry kappa times less
      // information than independent rows would), stacked with the prior's pseudo-observations.
      double noise = 0.0;
      const est::LsSolution s =
          est::solveWithPrior(acc, *prior, model.base().names, opt_, kName, kappa, &noise);
      est::fillEstimate(&e, model, s, acc.residualSquared(s.theta), acc.rows());
      e.rows = acc.rows();
      e.details["noise_std"] = noise;
      e.details["prior"] = est::priorDetails(*prior, s.theta, s.std);
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
    d["decimation"] = R;
    d["decimation_cutoff_hz"] = R > 1 ? exid::Json(dec_cut) : exid::Json(nullptr);
    d["decimation_order"] = dec_order_;
    if (!dec_note.empty()) d["decimation_note"] = dec_note;
    d["rows_before_decimation"] = Json(static_cast<long long>(rows_before));
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
  est::SolveOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(FilteredLs)
