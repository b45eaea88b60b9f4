#pragma once

#include "exid/export.hpp"
// Signal processing for sampled recordings: Butterworth low-pass design, causal and zero-phase
// (forward-backward) filtering, central differences, the sampling rate of time stamps, and the
// parallel decimation of observation rows. Used by the experiments (differentiating recorded
// positions) and the estimators (filtered_ls).
#include <Eigen/Core>
#include <array>
#include <complex>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "exid/data.hpp"

namespace exid {

/// Second-order sections b0 b1 b2 1 a1 a2 (transposed direct form II).
struct EXID_API Sos {
  std::vector<std::array<double, 6>> sections;
  int order = 0;
};

/// Digital Butterworth low-pass of `order` with -3 dB at cutoff_hz (single pass), designed by
/// the bilinear transform with pre-warping; unit DC gain. Throws unless 0 < cutoff < fs/2.
EXID_API Sos butterworthLowpass(int order, double cutoff_hz, double fs_hz);
/// Frequency response at f (Hz).
EXID_API std::complex<double> sosResponse(const Sos& sos, double f_hz, double fs_hz);
/// Causal filtering in place with initial state zi (2 per section); zi updated.
EXID_API void sosFilter(const Sos& sos, Eigen::Ref<Eigen::VectorXd> x, std::vector<double>* zi);
/// Steady-state state for a unit step input (scipy's sosfilt_zi).
EXID_API std::vector<double> sosStepState(const Sos& sos);
/// Zero-phase forward-backward filtering (as scipy's sosfiltfilt): odd extension at each end
/// (point reflection, keeps value and slope continuous) of 10 time constants of the slowest
/// pole (at least 3 (2 sections + 1) samples), steady-state initial conditions. Magnitude |H|^2.
EXID_API Eigen::VectorXd filtfilt(const Sos& sos, const Eigen::Ref<const Eigen::VectorXd>& x);
/// filtfilt of every column.
EXID_API Eigen::MatrixXd filtfiltColumns(const Sos& sos, const Eigen::MatrixXd& X);
/// Row-major samples x signals.
using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
/// filtfilt of every column of a row-major block, in place: the same padding, initial
/// conditions and arithmetic per column as filtfilt (bit for bit), with the recursion run over
/// all columns of a sample at once (vectorised across signals instead of latency-bound per
/// signal).
EXID_API void filtfiltRowsInPlace(const Sos& sos, RowMajorMatrix* X);
EXID_API void filtfiltRowsInPlace(const Sos& sos, Eigen::Map<RowMajorMatrix> X);
/// A row-major block of tens of MB written once and dropped (filtered_ls's rows of one chunk),
/// in its own anonymous mapping advised for transparent huge pages (madvise; the kernel's
/// default on Debian): one page fault per 2 MB instead of one per 4 kB page.
class EXID_API LargeRows {
 public:
  LargeRows() = default;
  LargeRows(Eigen::Index rows, Eigen::Index cols);
  ~LargeRows();
  LargeRows(const LargeRows&) = delete;
  LargeRows& operator=(const LargeRows&) = delete;
  LargeRows(LargeRows&& o) noexcept;
  LargeRows& operator=(LargeRows&& o) noexcept;
  Eigen::Map<RowMajorMatrix> map() const { return {data_, rows_, cols_}; }

 private:
  double* data_ = nullptr;
  std::size_t bytes_ = 0;
  Eigen::Index rows_ = 0, cols_ = 0;
};
/// Samples after which the slowest pole's transient has decayed below `tol` (relative):
/// ceil(log(tol) / log(r_max)); 0 for a filter without poles.
EXID_API long settlingSamples(const Sos& sos, double tol);

/// Sampling rate 1 / median(dt); *jitter = max |dt - median| / median. Throws on < 3 samples
/// or non-increasing t.
EXID_API double samplingRate(const Eigen::VectorXd& t, double* jitter);
/// The same for a dataset in memory or streamed: the stream's own figures when it has them
/// (DatasetStream::samplingRate), else one pass that reads the time stamps (8 bytes a sample).
EXID_API double samplingRate(const Dataset& d, double* jitter);
/// First derivative by three-point central differences (non-uniform t allowed), second-order
/// one-sided three-point formulas at the ends.
EXID_API Eigen::MatrixXd centralFirstDerivative(const Eigen::VectorXd& t, const Eigen::MatrixXd& X);
/// Second derivative by the three-point central formula; ends linearly extrapolated.
EXID_API Eigen::MatrixXd centralSecondDerivative(const Eigen::VectorXd& t,
                                                 const Eigen::MatrixXd& X);

/// Parallel decimation (Gautier): for each equation, its rows form a time series; every
/// column of W and y is low-pass filtered with `sos` (zero phase) and one row in `factor` is
/// kept. Equations keep their identity; output rows are sample-major.
EXID_API Rows decimateRows(const Rows& rows, int factor, const Sos& sos);

/// White noise of variance s^2 passed through filtfilt(sos) and kept one sample in `factor` is
/// correlated; its long-run variance (sum of its autocovariances, what the precision of a
/// least-squares fit with slowly varying regressors depends on) is kappa times its marginal
/// variance (what the residuals show). Returns kappa = sum_j g(j factor) / g(0), g the
/// autocorrelation of the filtfilt impulse response.
EXID_API double decimationVarianceFactor(const Sos& sos, int factor);

/// Element n / 2 of the n values value(0 .. n-1) in ascending order (what std::nth_element
/// puts there: the median of an odd count, the upper median of an even one), without holding
/// the values: an exact radix selection on the bits of the doubles, four passes over the values
/// of 16 bits each, 0.5 MB of counts. For the median step of a recording of any length. NaN
/// values are not allowed; n = 0 gives NaN.
template <class F>
double medianOfValues(std::size_t n, F value) {
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  // doubles to unsigned integers of the same order: negative ones flipped, positive ones with
  // the sign bit set
  auto key = [](double x) {
    std::uint64_t u;
    std::memcpy(&u, &x, sizeof u);
    return (u >> 63) ? ~u : (u | (std::uint64_t{1} << 63));
  };
  std::vector<std::size_t> count(std::size_t{1} << 16);
  std::size_t rank = n / 2;  // among the values whose key starts with `prefix`
  std::uint64_t prefix = 0;
  for (int pass = 0; pass < 4; ++pass) {
    const int shift = 48 - 16 * pass;
    std::fill(count.begin(), count.end(), std::size_t{0});
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint64_t u = key(value(i));
      if (pass > 0 && (u >> (shift + 16)) != prefix) continue;
      ++count[static_cast<std::size_t>((u >> shift) & 0xffffu)];
    }
    std::size_t b = 0;
    while (rank >= count[b]) rank -= count[b++];
    prefix = (prefix << 16) | b;
  }
  const std::uint64_t u = (prefix >> 63) ? (prefix & ~(std::uint64_t{1} << 63)) : ~prefix;
  double x;
  std::memcpy(&x, &u, sizeof x);
  return x;
}

/// Quadratic Savitzky-Golay fit over +-m samples at every sample (near the ends, the fit to the
/// first or last 2m + 1 samples evaluated off its centre, so the window never shrinks): the
/// smoothed value, first and second derivative of each column of X, uniform step dt. Outputs
/// given as nullptr are not computed.
EXID_API void savitzkyGolay(const Eigen::MatrixXd& X, double dt, int m, Eigen::MatrixXd* value,
                            Eigen::MatrixXd* d1, Eigen::MatrixXd* d2);

}  // namespace exid
