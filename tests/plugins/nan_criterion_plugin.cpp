// Test plugin library (tests/hostile): a criterion that evaluates to NaN at every point, as a
// criterion whose arithmetic breaks down does.
#include <Eigen/Core>
#include <cmath>

#include "exid/interfaces.hpp"

namespace {

class NanCriterion final : public exid::Criterion {
 public:
  static constexpr const char* kName = "test_nan";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: J = NaN whatever the information matrix";
  static std::vector<exid::ParamDecl> params() { return {}; }
  explicit NanCriterion(const exid::ParamSet&) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    if (dM) *dM = Eigen::MatrixXd::Constant(M.rows(), M.cols(), std::nan(""));
    return std::nan("");
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(NanCriterion)
