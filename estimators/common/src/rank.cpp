// exid — the rank test of exid/estimators/rank.hpp.
#include "exid/estimators/rank.hpp"

#include <cmath>

#include "exid/eigen_instances.hpp"

namespace exid::estimators {

bool aboveRankTolerance(const Eigen::Ref<const Eigen::MatrixXd>& A, double tol, bool* by_svd) {
  const Eigen::Index m = A.rows(), n = A.cols();
  if (by_svd) *by_svd = false;
  if (n > 0 && m >= n) {
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(A);
    const Eigen::MatrixXd R = qr.matrixQR().topRows(n).triangularView<Eigen::Upper>();
    Eigen::MatrixXd Ri = Eigen::MatrixXd::Identity(n, n);
    R.triangularView<Eigen::Upper>().solveInPlace(Ri);
    const double kappa = R.norm() * Ri.norm();
    if (std::isfinite(kappa) && kappa > 0) {
      if (1.0 / kappa > 2.0 * tol) return true;
      if (static_cast<double>(n) / kappa < 0.5 * tol) return false;
    }
  }
  if (by_svd) *by_svd = true;
  const Eigen::BDCSVD<Eigen::MatrixXd> svd(A);
  const Eigen::VectorXd sv = svd.singularValues();
  return sv.size() > 0 && sv[sv.size() - 1] > tol * sv[0];
}

}  // namespace exid::estimators
