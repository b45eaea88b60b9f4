// exid — experiment `csv`: the segment's optional preprocessing (preprocess.hpp).
#include "preprocess.hpp"

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "exid/error.hpp"
#include "exid/signal.hpp"

namespace exid::csv_experiment {

Preprocessed preprocess(const exid::ParamSet& P, exid::Dataset* d, const std::string& file) {
  Preprocessed pp;
  pp.cutoff_hz = P.getDouble("differentiate_cutoff_hz");
  pp.order = static_cast<int>(P.getInt("filter_order"));
  pp.filter_torque = P.getBool("filter_torque");
  pp.decimation = static_cast<int>(P.getInt("decimation"));
  if (pp.cutoff_hz <= 0) {
    exid::check(pp.decimation == 1 && !pp.filter_torque,
                "experiment 'csv': decimation and filter_torque need differentiate_cutoff_hz > 0");
    return pp;
  }
  exid::check(pp.decimation == 1 || pp.filter_torque,
              "experiment 'csv': decimation > 1 needs filter_torque: true (the torque must be "
              "low-passed before samples are dropped)");
  const Eigen::Index K = d->size();
  exid::check(K >= 8, fmt::format("experiment 'csv': {}: {} samples in the segment are too few to "
                                  "filter and differentiate",
                                  file, K));
  double jitter = 0;
  pp.fs = exid::samplingRate(d->t, &jitter);
  exid::check(pp.cutoff_hz < 0.5 * pp.fs,
              fmt::format("experiment 'csv': differentiate_cutoff_hz = {} Hz must be below the "
                          "Nyquist frequency {} Hz of the data",
                          pp.cutoff_hz, 0.5 * pp.fs));
  exid::check(pp.decimation == 1 || pp.cutoff_hz < 0.5 * pp.fs / pp.decimation,
              fmt::format("experiment 'csv': decimation {} leaves a Nyquist frequency of {} Hz, "
                          "below differentiate_cutoff_hz = {} Hz (aliasing)",
                          pp.decimation, 0.5 * pp.fs / pp.decimation, pp.cutoff_hz));
  const exid::Sos sos = exid::butterworthLowpass(pp.order, pp.cutoff_hz, pp.fs);
  d->q = exid::filtfiltColumns(sos, d->q);
  d->qd = exid::centralFirstDerivative(d->t, d->q);
  d->qdd = exid::centralSecondDerivative(d->t, d->q);
  if (pp.filter_torque) {
    if (d->hasTorque()) d->tau = exid::filtfiltColumns(sos, d->tau);
    if (d->hasWrench()) d->wrench = exid::filtfiltColumns(sos, d->wrench);
  }
  // Default trim: the filter's edge transient, 2 fs / fc samples (two periods of the cut-off)
  // at each end, but at most 5 % of the segment at each end, so that a default never discards
  // more than 10 % of a short recording (the zero-phase filter pads its ends by reflection:
  // what is left of the transient there is small). fs is the median step's rate, rounded to
  // the file's resolution (a 100 Hz log is 100 Hz, not 100.0000001: 2 fs / fc = 100, not 101).
  // Every count in double first: ceil(2 fs / cutoff) of a tiny cut-off, or a huge trim_edges,
  // does not fit an int (it was narrowed, wrapped and indexed before the data); a transient
  // longer than the whole segment leaves nothing the filter has not smeared.
  const std::int64_t trim_p = P.getInt("trim_edges");
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
  exid::check(static_cast<double>(K) - 2.0 * trim >= 2.0,
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

}  // namespace exid::csv_experiment
