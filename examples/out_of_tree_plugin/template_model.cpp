// TEMPLATE (observation model): the rigid-body equations of motion of selected joints,
//   tau_j(t_k) = Y_j(q_k, qd_k, qdd_k) pi,   one row per sample k and selected joint j,
// with the core's torque regressor (exid::torqueRegressor, exid/dynamics.hpp) and its exact
// reverse-mode derivative (exid::torqueRegressorVjp) for excitation design. The model works on
// FULL columns (the 10 standard parameters of every body); the framework finds the base
// parameters (ObservationModel::bind) and derives the base-column forms. Shows: fullNames /
// fullNominal, fullRows, fullDesign, fullDesignVjp, ModelSpecs (per-sample rows, required
// signals) and the installed model helpers (exid::models_common, "exid/models/model_common.hpp").
// To make it yours: change the rows and their columns (drive or friction columns:
// exid::actuatorRegressor in exid/drive.hpp, as the model `differential` does), keep
// fullDesignVjp exact (the excitation design's gradient is built from it) and declare in specs()
// what the rows need. Limitation: measured = joint coordinates (a transmission is refused).
#include <fmt/format.h>

#include <string>
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"

namespace {

class TemplateModel final : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "template_model";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "rigid-body equations of motion tau_j = Y_j(q, qd, qdd) pi of the selected joints, one row "
      "per sample and joint (out-of-tree template)";
  static std::vector<exid::ParamDecl> params() {
    return {exid::param_ints("joints", std::vector<std::int64_t>{},
                             "1-based joints whose torque equations are rows; empty: all", 1.0)};
  }
  explicit TemplateModel(const exid::ParamSet& p) : joints_param_(p.getInts("joints")) {}

  std::vector<std::string> fullNames() const override { return robot().inertialParameterNames(); }
  Eigen::VectorXd fullNominal() const override { return robot().inertialParameters(); }

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;  // the rows of sample k use sample k alone: the data may be streamed
    sp.required_signals = {"q", "qd", "qdd", "tau"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    const int n = robot().dof(), K = d.size(), m = static_cast<int>(sel_.size());
    exid::models::requireSignal(d, d.q, "q", n, who());
    exid::models::requireSignal(d, d.qd, "qd", n, who());
    exid::models::requireSignal(d, d.qdd, "qdd", n, who());
    exid::models::requireSignal(d, d.tau, "tau", n, who());
    exid::Rows r;
    r.W = fullDesign(d.samples());
    r.y.resize(static_cast<Eigen::Index>(K) * m);
    r.equation.resize(static_cast<std::size_t>(K) * m);
    r.t.resize(static_cast<std::size_t>(K) * m);
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) {
        const std::size_t row = static_cast<std::size_t>(k) * m + i;
        r.y(static_cast<Eigen::Index>(row)) = d.tau(k, sel_[static_cast<std::size_t>(i)]);
        r.equation[row] = i;  // equation i: the torque of the i-th selected joint
        r.t[row] = d.t(k);
      }
    r.numEquations = m;
    r.equation_names = exid::models::torqueEquationNames(robot(), sel_);
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    exid::models::requireSamples(s, n, true, who());
    Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m, R.numInertialParameters());
    Eigen::MatrixXd Y(n, R.numInertialParameters());
    auto data = exid::makeDynamicsData(R);  // a workspace per call: thread-safe
    for (int k = 0; k < K; ++k) {
      exid::torqueRegressor(R, *data, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                            s.qdd.row(k).transpose(), Y);
      for (int i = 0; i < m; ++i) W.row(k * m + i) = Y.row(sel_[static_cast<std::size_t>(i)]);
    }
    return W;
  }

  // d<dW, W>/d(q, qd, qdd), sample by sample: the rows of sample k scattered back into an n x P
  // matrix G, then the regressor's own VJP.
  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P = R.numInertialParameters();
    exid::check(dW.rows() == static_cast<Eigen::Index>(K) * m && dW.cols() == P,
                fmt::format("{}: fullDesignVjp: dW is {} x {} (expected {} x {})", who(), dW.rows(),
                            dW.cols(), K * m, P));
    exid::models::zeroGrad(s, grad);
    Eigen::MatrixXd G(n, P);
    Eigen::VectorXd gq, gqd, gqdd;
    auto data = exid::makeDynamicsData(R);
    for (int k = 0; k < K; ++k) {
      G.setZero();
      for (int i = 0; i < m; ++i) G.row(sel_[static_cast<std::size_t>(i)]) = dW.row(k * m + i);
      exid::torqueRegressorVjp(R, *data, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                               s.qdd.row(k).transpose(), G, &gq, &gqd, &gqdd);
      grad->q.row(k) = gq.transpose();
      grad->qd.row(k) = gqd.transpose();
      grad->qdd.row(k) = gqdd.transpose();
    }
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] = "tau_j = Y_j(q, qd, qdd) pi (rigid bodies)";
    j["joints"] = exid::models::intsJson(sel_, 1);
    j["rows_per_sample"] = static_cast<int>(sel_.size());
    return j;
  }

 protected:
  void onBind(const exid::RunContext&) override {  // the robot is known from here on
    exid::check(!robot().hasTransmission(),
                fmt::format("{}: robot '{}' has a transmission (measured coordinates differ from "
                            "the joint coordinates this model uses); use the model 'differential'",
                            who(), robot().name));
    sel_ = exid::models::selectJoints(joints_param_, robot().dof(), who());
  }

 private:
  static std::string who() { return fmt::format("model '{}'", kName); }
  std::vector<std::int64_t> joints_param_;
  std::vector<int> sel_;  // 0-based selected joints
};

}  // namespace

EXID_REGISTER_PLUGIN(TemplateModel)
