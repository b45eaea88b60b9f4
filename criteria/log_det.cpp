// Criterion `log_det`: D-optimality, J = -log det M. dJ/dM = -M^-1.
#include <cmath>

#include "exid/criteria/spectrum.hpp"
#include "exid/fmath.hpp"
#include "exid/interfaces.hpp"

namespace {

class LogDet final : public exid::criteria::SpectralCriterion {
 public:
  static constexpr const char* kName = "log_det";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc = "D-optimality: -log det(W^T W)";
  explicit LogDet(const exid::ParamSet& p) : SpectralCriterion(p) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    auto s = exid::criteria::spectrum(M, kName);
    if (dM) *dM = -(s.V * s.lambda.cwiseInverse().asDiagonal() * s.V.transpose());
    double J = 0;  // exid's log: the same bits on every CPU
    for (Eigen::Index i = 0; i < s.lambda.size(); ++i) J -= exid::fmath::log(s.lambda(i));
    return J;
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(LogDet)
