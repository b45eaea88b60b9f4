// exid — numerical code shared by the estimator plugins (static library
// exid_estimators_common). One implementation of each piece, reused by batch_ls, rls,
// filtered_ls and wls. See docs/estimators.md for the equations and the choices.
#pragma once

#include <Eigen/Core>
#include <array>
#include <complex>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "exid/context.hpp"
#include "exid/data.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"
#include "exid/signal.hpp"

namespace exid::estimators {

// ============================================================== least squares

/// Streaming compression of the augmented rows [W y] (p + 1 columns) into a square factor F
/// with F^T F = [W y]^T [W y]. Memory is O(p^2 + buffer), independent of the number of rows.
///
/// Method::Qr (default): F is the upper-triangular R of a Householder QR of [R_prev; new rows]
///   (rows are buffered and compressed in blocks). cond(F) = cond([W y]): nothing is squared.
/// Method::Normal: accumulates the Gram matrix [W y]^T [W y] (a symmetric rank-k update,
///   about half the flops of the QR), and F comes from its eigendecomposition. Squares
///   cond(W): the solution's relative error grows like eps cond(W)^2 (eps = 2.2e-16), so it is
///   safe when the column-scaled cond(W) is moderate (scaledCondition(); batch_ls's
///   `accumulate: auto` uses it below 1e3 and falls back to a QR pass above).
class RowAccumulator {
 public:
  enum class Method { Qr, Normal };
  RowAccumulator() = default;
  explicit RowAccumulator(int p, Method method = Method::Qr, int block_rows = 1024);

  /// Adds rows (W: r x p, y: r), each multiplied by `scale` (a weight sqrt(w)).
  void add(const Eigen::Ref<const Eigen::MatrixXd>& W, const Eigen::Ref<const Eigen::VectorXd>& y,
           double scale = 1.0);
  /// add(W, y) for rows of several equations (equation[i]: the label of row i, e.g. the joint
  /// of a torque row). Normal: the Gram matrix of each equation's rows over only the columns
  /// that are not zero in them (a joint's torque does not depend on the links before it nor on
  /// the other joints' drives: about a third of the flops for a 6-joint arm), added into the
  /// whole. Exact: the columns left out contribute exact zeros. Qr: each equation's rows over
  /// its own non-zero columns reduced to their triangular factor first, whose rows are added
  /// (the same R^T R, about a ninth of the flops for a 6-joint arm's torque rows). Fewer than
  /// 64 rows, more than 64 labels, or rows without labels: add(W, y).
  void addEquations(const Eigen::Ref<const Eigen::MatrixXd>& W,
                    const Eigen::Ref<const Eigen::VectorXd>& y, const std::vector<int>& equation);
  /// Adds one row.
  void addRow(const Eigen::Ref<const Eigen::RowVectorXd>& w, double y, double scale = 1.0);
  /// Adds everything another accumulator holds, multiplied by scale.
  void merge(const RowAccumulator& other, double scale = 1.0);

  int cols() const { return p_; }
  long rows() const { return m_; }
  /// The number of data rows the accumulated factor stands for, when it was built from another
  /// factor's rows (varpro): what rows() reports and the solves count as m.
  void setRowCount(long m) { m_ = m; }
  Method method() const { return method_; }
  /// (p+1) x (p+1) factor with F^T F = [W y]^T [W y] (compresses pending rows first).
  const Eigen::MatrixXd& factor() const;
  /// Normal: [W y]^T [W y] as accumulated, its lower triangle (compresses pending rows first;
  /// the upper triangle is not kept). Qr: refused (exid::Error).
  const Eigen::MatrixXd& normalLower() const;
  /// ||y - W theta||^2, exact from the factor: ||F [theta; -1]||^2.
  double residualSquared(const Eigen::VectorXd& theta) const;
  /// Euclidean norm of each column of W (p).
  Eigen::VectorXd columnNorms() const;
  /// sigma_max / sigma_min of W with every column scaled to unit norm (inf when W is rank
  /// deficient to working precision). Normal: from the eigenvalues of the scaled Gram matrix
  /// (accurate while cond^2 << 1/eps); Qr: from the singular values of the scaled R.
  double scaledCondition() const;
  /// ||y||^2 of everything added (scaled).
  double ySquaredNorm() const;
  /// min_theta ||y - W theta||^2, cheaply: Qr: the last diagonal entry of R squared; Normal:
  /// yTy - bT G^-1 b by a Cholesky (LDLT) solve of the column-scaled Gram matrix (absolute
  /// error ~ eps yTy). HUGE_VAL when W is singular to working precision.
  double minimumResidualSquared() const;

 private:
  void compress() const;
  void addEquationsQr(const Eigen::Ref<const Eigen::MatrixXd>& W,
                      const Eigen::Ref<const Eigen::VectorXd>& y,
                      const std::vector<std::vector<Eigen::Index>>& rows);
  int p_ = 0;
  Method method_ = Method::Qr;
  long m_ = 0;
  int block_rows_ = 1024;
  mutable Eigen::MatrixXd buf_;   // Qr: rows [R; pending]; Normal: pending rows
  mutable int fill_ = 0;          // rows used in buf_
  mutable Eigen::MatrixXd gram_;  // Normal: (p+1)^2 lower triangle
  mutable Eigen::MatrixXd F_;     // cached factor
  mutable bool dirty_ = true;
};

/// The columns of W not zero in the rows idx, ascending.
void nonzeroColumns(const Eigen::Ref<const Eigen::MatrixXd>& W,
                    const std::vector<Eigen::Index>& idx, std::vector<Eigen::Index>* cols);
/// The rows of each equation label (ascending labels, each label's rows in order); false
/// (nothing meant) when there are more than 64 labels.
bool rowsByEquation(const std::vector<int>& equation, std::vector<int>* labels,
                    std::vector<std::vector<Eigen::Index>>* rows);

struct SolveOptions {
  /// A direction is unidentifiable when its singular value of the column-scaled W is below
  /// rank_tolerance * the largest (same convention as the base parameters, 1e-8).
  double rank_tolerance = 1e-8;
  /// How many standard parameters to name per unidentifiable direction.
  int explain_terms = 4;
  /// The rows are already in units of the noise standard deviation (weighted rows, or data
  /// stacked with a prior): covariance (W^T W)^-1 without the factor sigma^2.
  bool unit_variance = false;
  /// false: theta, rss, sigma2 and the scaled singular values alone (no covariance, std or
  /// unscaled singular values: their SVD and products are skipped), for a solve whose
  /// statistics are not read (varpro's trial points); the scaled SVD is then Eigen's divide
  /// and conquer (BDCSVD, about twice as fast as Jacobi's at 64 columns) instead of Jacobi's.
  bool statistics = true;
};

struct LsSolution {
  Eigen::VectorXd theta, std, rel_std_percent;
  Eigen::MatrixXd covariance;
  Eigen::VectorXd singular_values;         // of W (unscaled), descending
  Eigen::VectorXd singular_values_scaled;  // of W with unit-norm columns, descending
  double rss = 0.0;                        // ||y - W theta||^2
  double sigma2 = 0.0;                     // rss / (m - p)
  double cond_W = 0.0;                     // sigma_max / sigma_min of W
  double cond_W_scaled = 0.0;
  long m = 0;
  int p = 0;
};

/// Rank-revealing least squares on an accumulated factor: SVD of the column-scaled factor
/// (Jacobi, p x p), refuses a rank-deficient problem with exid::Error naming the directions
/// (explainNullSpace). Covariance sigma^2 (W^T W)^-1 with sigma^2 = rss / (m - p).
/// `who` prefixes messages ("batch_ls").
LsSolution solveLeastSquares(const RowAccumulator& acc, const std::vector<std::string>& names,
                             const SolveOptions& opt, const std::string& who);

/// Text naming the unidentifiable directions: for each null-space vector v (of the
/// column-scaled problem), its largest components as "0.71 Fc1 - 0.71 OFF1".
std::string explainNullSpace(const Eigen::MatrixXd& null_vectors, const Eigen::VectorXd& ratios,
                             const std::vector<std::string>& names, int terms);

/// 100 * std / |value| (Gautier's relative standard deviation); +inf when value == 0.
Eigen::VectorXd relativeStdPercent(const Eigen::VectorXd& value, const Eigen::VectorXd& std);

/// Fills names, expressions, value, std, covariance, sigma, cond_W, rows and the common details
/// (per-parameter table with rel_std_percent, singular values, dof). residual_rms is set from
/// the unweighted residual sum of squares `rss_unweighted` over `m_unweighted` rows.
void fillEstimate(Estimate* e, const ObservationModel& model, const LsSolution& s,
                  double rss_unweighted, long m_unweighted);
/// The per-parameter table of details: [{name, expression, value, std, rel_std_percent}].
Json parameterTable(const Estimate& e);
/// Where a fit stopped, for its messages: "name = value" for the first `max_terms` of names
/// (values in the same order), then "(N more: details.parameters)".
std::string describePoint(const std::vector<std::string>& names, const Eigen::VectorXd& values,
                          int max_terms = 12);

// ============================================================== streaming rows

// Datasets in memory or streamed (Dataset::stream): the functions below read a streamed
// dataset in one pass, in order, holding only the chunks at work (exid::SampleWindow).

/// Whether model.rows() may be computed on consecutive slices of a dataset and stacked, i.e.
/// the rows of sample k depend on sample k only: the model's specs().per_sample.
bool modelIsPerSample(const ObservationModel& model);

/// Streams a dataset through the model: calls fn(rows, begin, end) on consecutive slices of at
/// most chunk_samples samples (the whole dataset at once when the model is not per sample: a
/// streamed dataset is then read whole into memory).
/// Reports progress in [lo, hi] of the stage and throws exid::Error when ctx.shouldStop().
/// The `rank_tolerance` parameter of the least-squares estimators (BaseSolveOptions).
ParamDecl rankToleranceParam();

/// A fitted measurement delay's settings (the estimator parameters measurement_delay,
/// measurement_delay_initial_s, measurement_delay_max_s), checked: a bound is required and
/// holds the start; without the delay neither is given. `who` starts the messages; `ends`
/// says what the bound leaves out.
struct DelaySettings {
  bool on = false;
  double initial_s = 0.0, max_s = 0.0;
  static DelaySettings from(const ParamSet& p, const std::string& who, const std::string& ends);
  /// The three parameters' declarations: `what` documents measurement_delay, `bound`
  /// measurement_delay_max_s.
  static std::vector<ParamDecl> params(const std::string& what, const std::string& bound);
};

/// A prior on the drive gains (gain_prior_std, gain_prior_dK), checked: positive stds, means
/// above -1, no mean without a std.
void checkGainPrior(const std::vector<double>& std_dev, const std::vector<double>& mean,
                    const std::string& who);
/// One value per drive gain from `key`'s values (none: `fallback`; one: every gain).
Eigen::VectorXd perGain(const std::vector<double>& values, std::size_t gains, const char* key,
                        double fallback, const std::string& who);

/// The secant update of the second-order term S of a nonlinear least-squares Hessian
/// (J^T J + S, S ~ sum r_i d2 r_i / dtheta2), Dennis, Gay and Welsch's as in NL2SOL: for the
/// step s, y = grad f(new) - grad f(old) and y# = (J_new - J_old)^T r_new (f = ||r||^2 / 2),
/// S is first scaled by min(1, |s^T y#| / |s^T S s|), then
/// S += (v y^T + y v^T) / (y^T s) - (v^T s) y y^T / (y^T s)^2, v = y# - S s, so that the
/// updated S is symmetric and S s = y#. Skipped (false, S unchanged) when y^T s is not
/// positive (a step along which the gradient did not grow).
bool secantSecondOrderUpdate(Eigen::MatrixXd* S, const Eigen::VectorXd& s, const Eigen::VectorXd& y,
                             const Eigen::VectorXd& ysharp);

/// The capabilities of an estimator that reads its rows in chunks (forEachChunk,
/// accumulateRows) and takes a prior.
EstimatorSpecs streamingSpecs();
/// Runs work(c) for the chunks c in [0, n) on `threads` threads (the caller's among them), and
/// consume(c) in chunk order, one at a time, on whichever thread finished the chunk that was
/// waited for. So a reduction done in consume is the same for any thread count. No thread waits
/// for a wave: a thread takes the next chunk as soon as it is free, while fewer than
/// 2 * threads chunks are taken and not yet consumed (so a chunk's result may live in slot
/// c % (2 * threads)). A failure (work or consume) stops the taking of chunks; the chunks
/// before the first failing one are consumed, none after it, and that failure is rethrown.
void parallelChunks(long n, int threads, const std::function<void(long)>& work,
                    const std::function<void(long)>& consume);
/// parallelChunks for chunks that each need an input read in order (the spans of a streamed
/// dataset): read(c, &input) runs in chunk order, one at a time (beside work and consume of
/// other chunks), when chunk c is taken; then work(c, input) and consume(c) as above. The
/// inputs of at most 2 * threads chunks exist at once. A failing read counts as its chunk's
/// failure.
void pipelineChunks(long n, int threads, const std::function<void(long, Dataset*)>& read,
                    const std::function<void(long, const Dataset&)>& work,
                    const std::function<void(long)>& consume);
/// The model's rows of the dataset in chunks of chunk_samples, accumulated per chunk on
/// `threads` threads and merged in chunk order (the same bits for any thread count).
RowAccumulator accumulateRows(const ObservationModel& model, const Dataset& data, int chunk_samples,
                              const RunContext& ctx, const std::string& who, double lo, double hi,
                              RowAccumulator::Method method, int threads);

void forEachChunk(const ObservationModel& model, const Dataset& data, int chunk_samples,
                  const RunContext& ctx, const std::string& who, double lo, double hi,
                  const std::function<void(const Rows&, int begin, int end)>& fn);

/// For rows computed from `samples` consecutive samples: the sample (0-based, within them) of
/// each row, and an order of the rows in time (stable within a sample). Recognises sample-major
/// (equation = i % r) and equation-major (equation = i / samples) layouts; otherwise spreads the
/// rows evenly in the given order.
void rowTimeOrder(const Rows& rows, int samples, std::vector<int>* sample_of_row,
                  std::vector<int>* order);

/// Throws exid::Error when the rows are not finite or shapes disagree with the model.
void checkRows(const Rows& rows, int p, const std::string& who, int begin);

/// Folds the rows `index` of `rows` (one equation's rows of a chunk) into the accumulator
/// `(*acc)[eq]`, created (QR, blocks of 512 rows) on first use. wls and consistent_ls weight
/// each equation separately from these per-equation factors.
void addEquationRows(const Rows& rows, const std::vector<int>& index, int eq,
                     std::map<int, RowAccumulator>* acc);

// ============================================================== signals
// Signal processing lives in the core (exid/signal.hpp, shared with the experiments); its names
// are used here as estimators:: names too.
using exid::butterworthLowpass;
using exid::centralFirstDerivative;
using exid::centralSecondDerivative;
using exid::decimateRows;
using exid::decimationVarianceFactor;
using exid::filtfilt;
using exid::filtfiltColumns;
using exid::filtfiltRowsInPlace;
using exid::LargeRows;
using exid::RowMajorMatrix;
using exid::samplingRate;
using exid::settlingSamples;
using exid::Sos;
using exid::sosFilter;
using exid::sosResponse;
using exid::sosStepState;

}  // namespace exid::estimators
