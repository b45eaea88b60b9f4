// exid — physical consistency and priors for the estimators (part of exid_estimators_common).
//
// Pseudo-inertia of one body (Wensing, Kim & Slotine 2017): with the standard parameters
// XX XY XZ YY YZ ZZ MX MY MZ M about the body origin,
//   J = [[Sigma, h], [h^T, m]],  Sigma = tr(I)/2 E - I = integral of x x^T dm,  h = m c.
// The body is physically consistent (m > 0, inertia about the COM positive definite, triangle
// inequalities) exactly when J is positive definite. Log-Cholesky (Rucker & Wensing 2022):
// J = U U^T with U upper triangular, U_kk = exp(t_kk); the 10 coordinates
//   t = [log U00, log U11, log U22, log U33, U01, U02, U03, U12, U13, U23]
// range over R^10 and every value gives a consistent body. See docs/consistent.md.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace exid::estimators {

using Vec10 = Eigen::Matrix<double, 10, 1>;

/// Pseudo-inertia J (4x4, symmetric) of standard parameters, and back.
Eigen::Matrix4d pseudoInertia(const Vec10& pi);
Vec10 inertialFromPseudo(const Eigen::Matrix4d& J);

/// Standard parameters from log-Cholesky coordinates (always consistent).
Vec10 logCholeskyToInertial(const Vec10& t);
/// Chain rule: given g = df/dpi, returns df/dt (exact).
Vec10 logCholeskyVjp(const Vec10& t, const Vec10& g);
/// dpi/dt (10 x 10), exact.
Eigen::Matrix<double, 10, 10> logCholeskyJacobian(const Vec10& t);
/// Log-Cholesky coordinates of the nearest consistent body: the eigenvalues of J are raised to
/// at least `eig_floor` (> 0). *projected tells whether anything changed.
Vec10 logCholeskyFromInertial(const Vec10& pi, double eig_floor, bool* projected = nullptr);
/// Smallest eigenvalue of J (> 0: consistent; the margin of the strict inequalities).
double pseudoInertiaMinEigenvalue(const Vec10& pi);

// ============================================================== priors

/// Checks sizes, finiteness and positive definiteness of a prior for p base parameters and
/// returns S (upper triangular) with S^T S = covariance^-1 (the prior's square-root
/// information). Throws exid::Error prefixed with `who`.
Eigen::MatrixXd priorSqrtInformation(const Prior& prior, int p, const std::string& who);
/// Adds the prior as p pseudo-observation rows S theta = S theta0 (regularised least squares).
void addPriorRows(RowAccumulator* acc, const Prior& prior, const std::string& who);

/// Rank-tolerant least squares (never throws on rank deficiency): minimum-norm solution of the
/// column-scaled problem truncated at opt.rank_tolerance; *rank receives the numerical rank.
Eigen::VectorXd solveMinimumNorm(const RowAccumulator& acc, double rank_tolerance, int* rank);

/// Standard deviation of the data rows for combining them with a prior: rss / (m - rank) of the
/// rank-tolerant fit (floored at 1e-9 of the rms of y so noise-free data stay finite).
double noiseStdForPrior(const RowAccumulator& acc, double rank_tolerance);

/// Regularised least squares of the rows in `acc` with a prior: the rows divided by their noise
/// std (noiseStdForPrior, times sqrt(variance_factor) when the residuals are correlated, e.g.
/// decimated rows), stacked with the prior's pseudo-observations, solved with unit variance and
/// no rank decision (the prior makes the problem positive definite). *noise_std receives the
/// std used. Covariance: the posterior (W^T W / s^2 + Sigma^-1)^-1, s^2 = noise_std^2.
LsSolution solveWithPrior(const RowAccumulator& acc, const Prior& prior,
                          const std::vector<std::string>& names, SolveOptions opt,
                          const std::string& who, double variance_factor, double* noise_std);

/// Summary of a prior for Estimate::details.
Json priorDetails(const Prior& prior, const Eigen::VectorXd& estimate,
                  const Eigen::VectorXd& posterior_std);

}  // namespace exid::estimators
