// Log-Cholesky parameterisation of the pseudo-inertia, projection to consistency, priors as
// pseudo-observations, rank-tolerant least squares. See consistent.hpp and docs/consistent.md.
#include "exid/estimators/consistent.hpp"

#include <fmt/format.h>

#include <cmath>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid::estimators {

namespace {

// Off-diagonal entries of U in the order of t(4..9).
constexpr int kOffRow[6] = {0, 0, 0, 1, 1, 2};
constexpr int kOffCol[6] = {1, 2, 3, 2, 3, 3};

Eigen::Matrix4d upperFactor(const Vec10& t) {
  Eigen::Matrix4d U = Eigen::Matrix4d::Zero();
  for (int k = 0; k < 4; ++k) U(k, k) = std::exp(t(k));
  for (int k = 0; k < 6; ++k) U(kOffRow[k], kOffCol[k]) = t(4 + k);
  return U;
}

}  // namespace

Eigen::Matrix4d pseudoInertia(const Vec10& pi) {
  Eigen::Matrix3d I;
  I << pi(0), pi(1), pi(2), pi(1), pi(3), pi(4), pi(2), pi(4), pi(5);
  Eigen::Matrix4d J;
  J.topLeftCorner<3, 3>() = 0.5 * I.trace() * Eigen::Matrix3d::Identity() - I;
  J.block<3, 1>(0, 3) = pi.segment<3>(6);
  J.block<1, 3>(3, 0) = pi.segment<3>(6).transpose();
  J(3, 3) = pi(9);
  return J;
}

Vec10 inertialFromPseudo(const Eigen::Matrix4d& J) {
  Vec10 pi;
  pi << J(1, 1) + J(2, 2), -J(0, 1), -J(0, 2), J(0, 0) + J(2, 2), -J(1, 2), J(0, 0) + J(1, 1),
      J(0, 3), J(1, 3), J(2, 3), J(3, 3);
  return pi;
}

Vec10 logCholeskyToInertial(const Vec10& t) {
  const Eigen::Matrix4d U = upperFactor(t);
  return inertialFromPseudo(U * U.transpose());
}

Vec10 logCholeskyVjp(const Vec10& t, const Vec10& g) {
  // df = <G, dJ> with G holding g at the entries of J that inertialFromPseudo reads;
  // dJ = dU U^T + U dU^T  =>  df/dU = (G + G^T) U (upper triangle), dU_kk = U_kk dt_kk.
  Eigen::Matrix4d G = Eigen::Matrix4d::Zero();
  G(1, 1) += g(0);
  G(2, 2) += g(0);
  G(0, 1) -= g(1);
  G(0, 2) -= g(2);
  G(0, 0) += g(3);
  G(2, 2) += g(3);
  G(1, 2) -= g(4);
  G(0, 0) += g(5);
  G(1, 1) += g(5);
  G(0, 3) += g(6);
  G(1, 3) += g(7);
  G(2, 3) += g(8);
  G(3, 3) += g(9);
  const Eigen::Matrix4d U = upperFactor(t);
  const Eigen::Matrix4d dU = (G + G.transpose()) * U;
  Vec10 out;
  for (int k = 0; k < 4; ++k) out(k) = dU(k, k) * U(k, k);
  for (int k = 0; k < 6; ++k) out(4 + k) = dU(kOffRow[k], kOffCol[k]);
  return out;
}

Eigen::Matrix<double, 10, 10> logCholeskyJacobian(const Vec10& t) {
  Eigen::Matrix<double, 10, 10> Jac;
  for (int i = 0; i < 10; ++i) Jac.row(i) = logCholeskyVjp(t, Vec10::Unit(i)).transpose();
  return Jac;
}

double pseudoInertiaMinEigenvalue(const Vec10& pi) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(pseudoInertia(pi), Eigen::EigenvaluesOnly);
  return es.eigenvalues()(0);
}

Vec10 logCholeskyFromInertial(const Vec10& pi, double eig_floor, bool* projected) {
  check(eig_floor > 0 && std::isfinite(eig_floor),
        "logCholeskyFromInertial: eig_floor must be positive");
  check(pi.allFinite(), "logCholeskyFromInertial: non-finite parameters");
  Eigen::Matrix4d J = pseudoInertia(pi);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(J);
  Eigen::Vector4d l = es.eigenvalues();
  const bool low = l.minCoeff() < eig_floor;
  if (projected) *projected = low;
  if (low) {
    l = l.cwiseMax(eig_floor);
    J = es.eigenvectors() * l.asDiagonal() * es.eigenvectors().transpose();
  }
  // J = U U^T with U upper triangular: U = P L P, P the reversal, P J P = L L^T.
  Eigen::Matrix4d P = Eigen::Matrix4d::Zero();
  for (int k = 0; k < 4; ++k) P(k, 3 - k) = 1.0;
  Eigen::LLT<Eigen::Matrix4d> llt(P * J * P);
  check(llt.info() == Eigen::Success,
        "logCholeskyFromInertial: pseudo-inertia not positive definite");
  const Eigen::Matrix4d L = llt.matrixL();
  const Eigen::Matrix4d U = P * L * P;
  Vec10 t;
  for (int k = 0; k < 4; ++k) t(k) = std::log(U(k, k));
  for (int k = 0; k < 6; ++k) t(4 + k) = U(kOffRow[k], kOffCol[k]);
  return t;
}

// ---------------------------------------------------------------- priors
Eigen::MatrixXd priorSqrtInformation(const Prior& prior, int p, const std::string& who) {
  check(prior.value.size() == p && prior.covariance.rows() == p && prior.covariance.cols() == p,
        fmt::format(
            "{}: the prior has {} values and a {}x{} covariance; the model has {} base parameters",
            who, prior.value.size(), prior.covariance.rows(), prior.covariance.cols(), p));
  check(prior.value.allFinite() && prior.covariance.allFinite(),
        fmt::format("{}: the prior is not finite", who));
  const Eigen::MatrixXd C = 0.5 * (prior.covariance + prior.covariance.transpose());
  check((C - prior.covariance).cwiseAbs().maxCoeff() <=
            1e-9 * std::max(1e-300, C.cwiseAbs().maxCoeff()),
        fmt::format("{}: the prior covariance is not symmetric", who));
  Eigen::LLT<Eigen::MatrixXd> llt(C);
  check(llt.info() == Eigen::Success,
        fmt::format("{}: the prior covariance is not positive definite", who));
  const Eigen::MatrixXd L = llt.matrixL();
  Eigen::MatrixXd S = Eigen::MatrixXd::Identity(p, p);
  L.triangularView<Eigen::Lower>().solveInPlace(S);  // S = L^-1, S^T S = C^-1
  check(S.allFinite(), fmt::format("{}: the prior covariance is numerically singular", who));
  return S;
}

void addPriorRows(RowAccumulator* acc, const Prior& prior, const std::string& who) {
  const Eigen::MatrixXd S = priorSqrtInformation(prior, acc->cols(), who);
  acc->add(S, S * prior.value);
}

Eigen::VectorXd solveMinimumNorm(const RowAccumulator& acc, double rank_tolerance, int* rank) {
  const int p = acc.cols();
  const Eigen::MatrixXd& F = acc.factor();
  const Eigen::MatrixXd Fw = F.leftCols(p);
  const Eigen::VectorXd fy = F.col(p);
  Eigen::VectorXd d = Fw.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < p; ++j)
    if (!(d(j) > 0.0)) d(j) = 1.0;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Fw * d.cwiseInverse().asDiagonal(),
                                        Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd s = svd.singularValues();
  int r = 0;
  Eigen::VectorXd c = svd.matrixU().transpose() * fy;
  for (int i = 0; i < s.size(); ++i) {
    if (s(0) > 0 && s(i) > rank_tolerance * s(0)) {
      c(i) /= s(i);
      ++r;
    } else {
      c(i) = 0.0;
    }
  }
  if (rank) *rank = r;
  return (svd.matrixV() * c).cwiseQuotient(d);
}

double noiseStdForPrior(const RowAccumulator& acc, double rank_tolerance) {
  int rank = 0;
  const Eigen::VectorXd theta = solveMinimumNorm(acc, rank_tolerance, &rank);
  const double rss = acc.residualSquared(theta);
  const long m = acc.rows();
  const double dof = static_cast<double>(std::max<long>(1, m - rank));
  const double yrms =
      acc.factor().col(acc.cols()).norm() / std::sqrt(static_cast<double>(std::max<long>(1, m)));
  return std::max(std::sqrt(std::max(rss, 0.0) / dof), 1e-9 * std::max(yrms, 1e-300));
}

LsSolution solveWithPrior(const RowAccumulator& acc, const Prior& prior,
                          const std::vector<std::string>& names, SolveOptions opt,
                          const std::string& who, double variance_factor, double* noise_std) {
  const double noise =
      noiseStdForPrior(acc, opt.rank_tolerance) * std::sqrt(std::max(variance_factor, 0.0));
  RowAccumulator tot(acc.cols());
  tot.merge(acc, 1.0 / noise);
  addPriorRows(&tot, prior, who);
  opt.unit_variance = true;
  // Noise-free data with a prior are legitimately ill-conditioned (tiny noise std, large
  // weights): no rank decision.
  opt.rank_tolerance = 0.0;
  if (noise_std) *noise_std = noise;
  return solveLeastSquares(tot, names, opt, who);
}

Json priorDetails(const Prior& prior, const Eigen::VectorXd& estimate,
                  const Eigen::VectorXd& posterior_std) {
  Json j = Json::object();
  const Eigen::VectorXd sd = prior.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  j["value"] =
      Json(std::vector<double>(prior.value.data(), prior.value.data() + prior.value.size()));
  j["std"] = Json(std::vector<double>(sd.data(), sd.data() + sd.size()));
  // Share of each parameter's information that comes from the prior: posterior variance over
  // prior variance (1 = the data say nothing about it, 0 = the data decide).
  std::vector<double> share;
  double maha = 0.0;
  for (Eigen::Index i = 0; i < sd.size(); ++i) {
    share.push_back(posterior_std.size() > i && sd(i) > 0 ? std::pow(posterior_std(i) / sd(i), 2)
                                                          : NAN);
  }
  const Eigen::VectorXd dv = estimate - prior.value;
  Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (prior.covariance + prior.covariance.transpose()));
  if (llt.info() == Eigen::Success) maha = std::sqrt(std::max(0.0, dv.dot(llt.solve(dv))));
  j["prior_share"] = Json(share);
  j["prior_share_definition"] =
      "posterior variance / prior variance per base parameter (1: prior only)";
  j["mahalanobis_from_prior"] = maha;
  return j;
}

}  // namespace exid::estimators
