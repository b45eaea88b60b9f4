// Test plugin library: a criterion that works and a robot whose factory throws.
#include <Eigen/Core>

#include "exid/error.hpp"
#include "exid/interfaces.hpp"

namespace {

class TraceCriterion final : public exid::Criterion {
 public:
  static constexpr const char* kName = "test_trace";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: J = scale * trace(M)";
  static std::vector<exid::ParamDecl> params() {
    return {exid::param_double("scale", 1.0, "", "multiplier", 0.0, std::nullopt, true)};
  }
  explicit TraceCriterion(const exid::ParamSet& p) : scale_(p.getDouble("scale")) {}
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    if (dM) *dM = scale_ * Eigen::MatrixXd::Identity(M.rows(), M.cols());
    return scale_ * M.trace();
  }

 private:
  double scale_;
};

class ThrowingRobot final : public exid::Robot {
 public:
  static constexpr const char* kName = "test_throws";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: a factory that throws";
  static std::vector<exid::ParamDecl> params() { return {}; }
  explicit ThrowingRobot(const exid::ParamSet&) {
    throw exid::Error("deliberate failure in the factory");
  }
  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    return nullptr;
  }
};

// Fixtures for configuration tests: their declarations matter, running them is refused.
class ConfigEstimator final : public exid::Estimator {
 public:
  static constexpr const char* kName = "test_estimator";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: parameters of every type";
  static std::vector<exid::ParamDecl> params() {
    return {exid::param_double("forgetting_factor", 1.0, "", "forgetting factor", 0.0, 1.0, true,
                               false),
            exid::param_int("iterations", 10, "iterations", 1, 1000),
            exid::param_bool("verbose", false, "talk"),
            exid::param_string("method", std::string("qr"), "solver", {"qr", "svd"}),
            exid::param_ints("joints", std::vector<std::int64_t>{}, "joints", 1, 7),
            exid::param_doubles("weights_Nm", std::vector<double>{}, "N m", "weights")};
  }
  explicit ConfigEstimator(const exid::ParamSet&) {}
  exid::Estimate estimate(const exid::ObservationModel&, const exid::Dataset&, const exid::Prior*,
                          const exid::RunContext&) override {
    throw exid::Error("test_estimator is a configuration fixture and does not estimate");
  }
};

class ConfigExperiment final : public exid::Experiment {
 public:
  static constexpr const char* kName = "test_experiment";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: a required path parameter";
  static std::vector<exid::ParamDecl> params() {
    return {exid::param_path("file", std::nullopt, "recording"),
            exid::param_double("period_s", 0.01, "s", "sample period", 0.0, std::nullopt, true)};
  }
  explicit ConfigExperiment(const exid::ParamSet&) {}
  exid::Dataset run(std::shared_ptr<const exid::RobotModel>, const exid::Samples*,
                    const exid::RunContext&) override {
    throw exid::Error("test_experiment is a configuration fixture and produces no data");
  }
};

class ConfigModel final : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "test_model";
  static constexpr const char* kVersion = "0.1";
  static constexpr const char* kDoc = "test: no parameters";
  static std::vector<exid::ParamDecl> params() { return {}; }
  explicit ConfigModel(const exid::ParamSet&) {}
  std::vector<std::string> fullNames() const override { return {"a"}; }
  Eigen::VectorXd fullNominal() const override { return Eigen::VectorXd::Ones(1); }
  exid::Rows fullRows(const exid::Dataset&, const exid::RunContext&) const override { return {}; }
  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    return Eigen::MatrixXd::Ones(s.size(), 1);
  }
  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd&,
                     exid::Samples* g) const override {
    *g = s;
    g->q.setZero();
    g->qd.setZero();
    g->qdd.setZero();
  }
};

}  // namespace

EXID_REGISTER_PLUGIN(TraceCriterion, ThrowingRobot, ConfigEstimator, ConfigExperiment, ConfigModel)
