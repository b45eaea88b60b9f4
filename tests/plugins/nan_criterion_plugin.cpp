// Test plugin library (tests/hostile): criteria that fail at every point: one evaluates to NaN, as
// a criterion whose arithmetic breaks down does; one throws exid::Error, as a criterion does on a
// singular information matrix.
#include <Eigen/Core>
#include <cmath>

#include "exid/error.hpp"
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

class SingularCriterion final : public exid::Criterion {
 public:
  static constexpr const char* kName = "test_singular";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: throws 'singular' whatever the information matrix";
  static std::vector<exid::ParamDecl> params() { return {}; }
  explicit SingularCriterion(const exid::ParamSet&) {}
  double evaluate(const Eigen::MatrixXd&, Eigen::MatrixXd*) const override {
    throw exid::Error("test_singular: the information matrix is singular");
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(NanCriterion, SingularCriterion)
