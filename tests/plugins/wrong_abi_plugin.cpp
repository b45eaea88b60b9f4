// Test plugin library built with a different plugin ABI version (999): must be refused.
#define EXID_PLUGIN_ABI_OVERRIDE 999
#include "exid/interfaces.hpp"

namespace {
class StaleCriterion final : public exid::Criterion {
 public:
  static constexpr const char* kName = "test_stale";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: wrong ABI";
  static std::vector<exid::ParamDecl> params() { return {}; }
  explicit StaleCriterion(const exid::ParamSet&) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd*) const override { return M.trace(); }
};
}  // namespace

EXID_REGISTER_PLUGIN(StaleCriterion)
