// An out-of-tree criterion: A-optimality, J = trace(M^-1) (the mean variance of the estimates
// for unit noise). dJ/dM = -M^-2. Built with find_package(exid) + exid_add_plugin.
// exid/eigen_instances.hpp in place of <Eigen/Cholesky>: the LLT of a MatrixXd is the one
// libexid_dynamics compiled (docs/architecture.md, "Eigen's decompositions, compiled once").
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"

namespace {

class AOptimal final : public exid::Criterion {
 public:
  static constexpr const char* kName = "a_optimal";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "A-optimality: trace((W^T W)^-1) (example out-of-tree plugin)";
  static std::vector<exid::ParamDecl> params() {
    return {exid::param_double("weight", 1.0, "", "multiplier of the criterion", 0.0, std::nullopt,
                               true)};
  }
  explicit AOptimal(const exid::ParamSet& p) : weight_(p.getDouble("weight")) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    Eigen::LLT<Eigen::MatrixXd> llt(M);
    if (llt.info() != Eigen::Success)
      throw exid::Error("a_optimal: information matrix is not positive definite");
    Eigen::MatrixXd Minv = llt.solve(Eigen::MatrixXd::Identity(M.rows(), M.cols()));
    if (dM) *dM = -weight_ * Minv * Minv;
    return weight_ * Minv.trace();
  }

 private:
  double weight_;
};

}  // namespace

EXID_REGISTER_PLUGIN(AOptimal)
