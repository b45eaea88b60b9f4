#pragma once
// Signal processing for sampled recordings: Butterworth low-pass design, causal and zero-phase
// (forward-backward) filtering, central differences, the sampling rate of time stamps, and the
// parallel decimation of observation rows. Used by the experiments (differentiating recorded
// positions) and the estimators (filtered_ls).
#include <Eigen/Core>
#include <array>
#include <complex>
#include <cstddef>
#include <vector>

#include "exid/data.hpp"

namespace exid {

/// Second-order sections b0 b1 b2 1 a1 a2 (transposed direct form II).
struct Sos {
  std::vector<std::array<double, 6>> sections;
  int order = 0;
};

/// Digital Butterworth low-pass of `order` with -3 dB at cutoff_hz (single pass), designed by
/// the bilinear transform with pre-warping; unit DC gain. Throws unless 0 < cutoff < fs/2.
Sos butterworthLowpass(int order, double cutoff_hz, double fs_hz);
/// Frequency response at f (Hz).
std::complex<double> sosResponse(const Sos& sos, double f_hz, double fs_hz);
/// Causal filtering in place with initial state zi (2 per section); zi updated.
void sosFilter(const Sos& sos, Eigen::Ref<Eigen::VectorXd> x, std::vector<double>* zi);
/// Steady-state state for a unit step input (scipy's sosfilt_zi).
std::vector<double> sosStepState(const Sos& sos);
/// Zero-phase forward-backward filtering (as scipy's sosfiltfilt): odd extension at each end
/// (point reflection, keeps value and slope continuous) of 10 time constants of the slowest
/// pole (at least 3 (2 sections + 1) samples), steady-state initial conditions. Magnitude |H|^2.
Eigen::VectorXd filtfilt(const Sos& sos, const Eigen::Ref<const Eigen::VectorXd>& x);
/// filtfilt of every column.
Eigen::MatrixXd filtfiltColumns(const Sos& sos, const Eigen::MatrixXd& X);
/// Row-major samples x signals.
using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
/// filtfilt of every column of a row-major block, in place: the same padding, initial
/// conditions and arithmetic per column as filtfilt (bit for bit), with the recursion run over
/// all columns of a sample at once (vectorised across signals instead of latency-bound per
/// signal).
void filtfiltRowsInPlace(const Sos& sos, RowMajorMatrix* X);
void filtfiltRowsInPlace(const Sos& sos, Eigen::Map<RowMajorMatrix> X);
/// A row-major block of tens of MB written once and dropped (filtered_ls's rows of one chunk),
/// in its own anonymous mapping advised for transparent huge pages (madvise; the kernel's
/// default on Debian): one page fault per 2 MB instead of one per 4 kB page.
class LargeRows {
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
long settlingSamples(const Sos& sos, double tol);

/// Sampling rate 1 / median(dt); *jitter = max |dt - median| / median. Throws on < 3 samples
/// or non-increasing t.
double samplingRate(const Eigen::VectorXd& t, double* jitter);
/// The same for a dataset in memory or streamed: the stream's own figures when it has them
/// (DatasetStream::samplingRate), else one pass that reads the time stamps (8 bytes a sample).
double samplingRate(const Dataset& d, double* jitter);
/// First derivative by three-point central differences (non-uniform t allowed), second-order
/// one-sided three-point formulas at the ends.
Eigen::MatrixXd centralFirstDerivative(const Eigen::VectorXd& t, const Eigen::MatrixXd& X);
/// Second derivative by the three-point central formula; ends linearly extrapolated.
Eigen::MatrixXd centralSecondDerivative(const Eigen::VectorXd& t, const Eigen::MatrixXd& X);

/// Parallel decimation (Gautier): for each equation, its rows form a time series; every
/// column of W and y is low-pass filtered with `sos` (zero phase) and one row in `factor` is
/// kept. Equations keep their identity; output rows are sample-major.
Rows decimateRows(const Rows& rows, int factor, const Sos& sos);

/// White noise of variance s^2 passed through filtfilt(sos) and kept one sample in `factor` is
/// correlated; its long-run variance (sum of its autocovariances, what the precision of a
/// least-squares fit with slowly varying regressors depends on) is kappa times its marginal
/// variance (what the residuals show). Returns kappa = sum_j g(j factor) / g(0), g the
/// autocorrelation of the filtfilt impulse response.
double decimationVarianceFactor(const Sos& sos, int factor);

}  // namespace exid
