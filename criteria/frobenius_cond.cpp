// Criterion `frobenius_cond`: ||W||_F ||W^+||_F = sqrt(tr M * tr M^-1) (Vandanjon et al. 1995).
// dJ/dM = (J / 2) (I / tr M - M^-2 / tr M^-1).
#include <cmath>

#include "exid/criteria/spectrum.hpp"
#include "exid/interfaces.hpp"

namespace {

class FrobeniusCond final : public exid::criteria::SpectralCriterion {
 public:
  static constexpr const char* kName = "frobenius_cond";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc = "Frobenius condition number ||W||_F ||W^+||_F";
  explicit FrobeniusCond(const exid::ParamSet& p) : SpectralCriterion(p) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    auto s = exid::criteria::spectrum(M, kName);
    const double tr = s.lambda.sum();
    const double tri = s.lambda.cwiseInverse().sum();
    const double J = std::sqrt(tr * tri);
    if (dM) {
      Eigen::MatrixXd Minv2 =
          s.V * s.lambda.cwiseInverse().cwiseAbs2().asDiagonal() * s.V.transpose();
      *dM = 0.5 * J * (Eigen::MatrixXd::Identity(M.rows(), M.cols()) / tr - Minv2 / tri);
    }
    return J;
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(FrobeniusCond)
