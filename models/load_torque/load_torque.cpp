// exid — observation model `load_torque`: payload parameters from the joint torques, with the
// robot's own parameters KNOWN (its description, drive terms included). One row per sample and
// selected joint:
//   tau_m,i - tau_robot,i(qm, qdm, qddm) = [T^T Yp(q, qd, qdd)]_i phi
// tau_robot = exid::actuatorTorque with every drive term of the robot file (Ia, Fc, Fv, OFF);
// Yp = exid::payloadTorqueRegressor (payload about the sensor origin, sensor axes,
// phi = M MX MY MZ XX XY XZ YY YZ ZZ), mapped to measured coordinates by T^T.
#include <fmt/format.h>

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"

namespace {

using exid::models::requireTorqueSignals;

class LoadTorqueModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "load_torque";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "payload parameters from joint torques with the robot known: tau_m - tau_robot = T^T Yp phi, "
      "one row per sample and selected joint; needs q, qd, qdd, tau";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::models::payloadParams("payload (nominal values of the parameters)");
    p.push_back(exid::param_ints("joints", std::vector<std::int64_t>{},
                                 "1-based joints whose torque equations are used; empty: all",
                                 1.0));
    return p;
  }

  explicit LoadTorqueModel(const exid::ParamSet& p)
      : payload_(exid::models::Payload::fromParams(p)), joints_param_(p.getInts("joints")) {}

  std::vector<std::string> fullNames() const override { return exid::models::payloadNames(); }
  Eigen::VectorXd fullNominal() const override { return payload_.phi(); }
  Eigen::VectorXd fullTruth(const exid::PlantTruth& plant) const override {
    const exid::LoadMass& m = plant.payload;  // (none: zero)
    return exid::models::Payload{m.mass_kg, m.com_m, m.inertia_com_kg_m2}.phi();
  }
  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;  // one row per sample and selected joint
    sp.required_signals = {"q", "qd", "qdd", "tau"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof();
    const std::string who = "model 'load_torque'";
    requireTorqueSignals(d, n, who);
    exid::Rows r;
    r.W = fullDesign(d.samples());
    const int K = d.size(), m = static_cast<int>(sel_.size());
    exid::models::sizeRows(&r, K, m);
    exid::DriveColumns all{true, true, true, true};
    auto data = exid::makeDynamicsData(R);
    for (int k = 0; k < K; ++k) {
      const Eigen::VectorXd tr = exid::actuatorTorque(
          R, *data, all, d.q.row(k).transpose(), d.qd.row(k).transpose(), d.qdd.row(k).transpose());
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        r.y[k * m + i] = d.tau(k, j) - tr[j];
        r.equation[static_cast<std::size_t>(k * m + i)] = i;
      }
    }
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) r.t[static_cast<std::size_t>(k * m + i)] = d.t[k];
    r.equation_names = exid::models::torqueEquationNames(R, sel_);
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    exid::check(!R.hasLoops(), fmt::format("model 'load_torque': robot '{}' is a closed chain; "
                                           "this model is not implemented for loop-closure "
                                           "joints (use 'differential')",
                                           R.name));
    exid::models::requireSamples(s, n, true, "model 'load_torque'");
    Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m, 10);
    Eigen::MatrixXd Yp(n, 10), Ym(n, 10);
    auto data = exid::makeDynamicsData(R);
    Eigen::VectorXd q, qd, qdd;
    for (int k = 0; k < K; ++k) {
      exid::measuredToJoint(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                            s.qdd.row(k).transpose(), &q, &qd, &qdd);
      exid::payloadTorqueRegressor(R, *data, q, qd, qdd, Yp);
      if (R.hasTransmission())
        Ym.noalias() = R.transmission.transpose() * Yp;
      else
        Ym = Yp;
      for (int i = 0; i < m; ++i) W.row(k * m + i) = Ym.row(sel_[static_cast<std::size_t>(i)]);
    }
    return W;
  }

  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    exid::check(dW.rows() == static_cast<Eigen::Index>(K) * m && dW.cols() == 10,
                fmt::format("model 'load_torque': fullDesignVjp: dW is {} x {} (expected {} x 10)",
                            dW.rows(), dW.cols(), K * m));
    exid::models::zeroGrad(s, grad);
    auto data = exid::makeDynamicsData(R);
    Eigen::MatrixXd Gm(n, 10), G(n, 10);
    Eigen::VectorXd q, qd, qdd, gq, gqd, gqdd;
    for (int k = 0; k < K; ++k) {
      exid::measuredToJoint(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                            s.qdd.row(k).transpose(), &q, &qd, &qdd);
      Gm.setZero();
      for (int i = 0; i < m; ++i) Gm.row(sel_[static_cast<std::size_t>(i)]) = dW.row(k * m + i);
      // <Gm, T^T Yp> = <T Gm, Yp>
      if (R.hasTransmission())
        G.noalias() = R.transmission * Gm;
      else
        G = Gm;
      exid::payloadTorqueRegressorVjp(R, *data, q, qd, qdd, G, &gq, &gqd, &gqdd);
      exid::models::storeSampleGrad(R, k, &gq, &gqd, &gqdd, grad);
    }
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] = "tau_m,i - tau_robot,i = [T^T Yp(q, qd, qdd)]_i phi";
    j["known_robot"] =
        "the robot description's inertial parameters and all its drive terms "
        "(Ia, Fc, Fv, OFF)";
    j["parameters"] =
        "phi = M MX MY MZ XX XY XZ YY YZ ZZ of the payload about the sensor origin, "
        "sensor axes";
    j["joints"] = exid::models::intsJson(sel_, 1);
    j["equation_index"] = "position of the joint in 'joints' (0-based)";
    j["nominal_payload"] = payload_.json();
    return j;
  }

 protected:
  void onBind(const exid::RunContext&) override {
    sel_ = exid::models::selectJoints(joints_param_, robot().dof(),
                                      "model 'load_torque' on robot '" + robot().name + "'");
  }

 private:
  exid::models::Payload payload_;
  std::vector<std::int64_t> joints_param_;
  std::vector<int> sel_;
};

}  // namespace

EXID_REGISTER_PLUGIN(LoadTorqueModel)
