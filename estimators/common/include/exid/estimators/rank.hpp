// exid — a rank test at a relative tolerance that needs no SVD where bounds settle it (the
// estimators' common library).
#pragma once

#include <Eigen/Core>

namespace exid::estimators {

/// Whether A's singular values satisfy sigma_min > tol * sigma_max (sigma_min the
/// min(rows, cols)-th), with the decision an SVD of A gives. For rows >= cols it is first read
/// from A's triangular factor R (A = QR, the same singular values): with
/// kappa = ||R||_F ||R^-1||_F, 1 / kappa <= sigma_min / sigma_max <= cols / kappa, so
/// 1 / kappa > 2 tol settles "above" and cols / kappa < tol / 2 "below" (the factor 2 far
/// beyond the rounding of R and R^-1). Otherwise (between the bounds, R singular, a wide or
/// empty A, values not finite) the singular values decide (Eigen's BDCSVD of A). *by_svd (when
/// given): whether they were needed. A Householder QR and a triangular inverse cost about a
/// fifth of the SVD's values at 88 x 76.
bool aboveRankTolerance(const Eigen::Ref<const Eigen::MatrixXd>& A, double tol,
                        bool* by_svd = nullptr);

}  // namespace exid::estimators
