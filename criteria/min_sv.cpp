// Criterion `min_sv`: 1 / sigma_min(W) = lambda_min(M)^(-1/2). dJ/dM = -J^3/2 v_min v_min^T.
#include <cmath>

#include "exid/criteria/spectrum.hpp"
#include "exid/interfaces.hpp"

namespace {

class MinSv final : public exid::criteria::SpectralCriterion {
 public:
  static constexpr const char* kName = "min_sv";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc = "reciprocal of the smallest singular value of W";
  explicit MinSv(const exid::ParamSet& p) : SpectralCriterion(p) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    auto s = exid::criteria::spectrum(M, kName);
    const double J = 1.0 / std::sqrt(s.lambda(0));
    if (dM) *dM = -0.5 * J * J * J * s.V.col(0) * s.V.col(0).transpose();
    return J;
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(MinSv)
