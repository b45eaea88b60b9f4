// Criterion `cond`: the condition number of the base regressor, cond(W) = sigma_max / sigma_min
// = sqrt(lambda_max(M) / lambda_min(M)). Gradient: dJ/dM = J/2 (v_max v_max^T / lambda_max -
// v_min v_min^T / lambda_min) (simple extreme eigenvalues assumed).
#include <cmath>

#include "exid/criteria/spectrum.hpp"
#include "exid/interfaces.hpp"

namespace {

class Cond final : public exid::criteria::SpectralCriterion {
 public:
  static constexpr const char* kName = "cond";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "condition number of W: sigma_max/sigma_min (cond(M) is its square)";
  explicit Cond(const exid::ParamSet& p) : SpectralCriterion(p, true) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    auto s = exid::criteria::spectrum(M, kName);
    const Eigen::Index n = s.lambda.size();
    const double lmin = s.lambda(0), lmax = s.lambda(n - 1);
    const double J = std::sqrt(lmax / lmin);
    if (dM) {
      const Eigen::VectorXd vmin = s.V.col(0), vmax = s.V.col(n - 1);
      *dM = 0.5 * J * (vmax * vmax.transpose() / lmax - vmin * vmin.transpose() / lmin);
    }
    return J;
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(Cond)
