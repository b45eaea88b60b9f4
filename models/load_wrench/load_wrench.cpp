// exid — observation model `load_wrench`: payload parameters from a wrist force/torque sensor,
// six rows per sample (docs/conventions.md §2):
//   w = A(omega, alpha, a - g) phi (+ w0)
// w = [fx fy fz mx my mz] is the wrench the sensor (i.e. the robot) exerts on the payload,
// expressed in the sensor frame, moment about the sensor origin; A = exid::wrenchRegressor at
// the joint coordinates q = T qm + q0; phi = [M MX MY MZ XX XY XZ YY YZ ZZ] of the payload
// about the sensor origin, sensor axes (first moments M c, inertia about the origin). The
// optional sensor offset w0 adds six constant columns.
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

using exid::models::requireSignal;

class LoadWrenchModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "load_wrench";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "payload parameters from a wrist F/T sensor: w = A(omega, alpha, a - g) phi (+ offset), six "
      "rows per sample, sensor frame; needs q, qd, qdd, wrench";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::models::payloadParams("payload (nominal values of the parameters)");
    p.push_back(exid::param_bool(
        "sensor_offset", false, "identify a constant sensor offset: six columns OFF_FX .. OFF_MZ"));
    return p;
  }

  explicit LoadWrenchModel(const exid::ParamSet& p)
      : payload_(exid::models::Payload::fromParams(p)), offset_(p.getBool("sensor_offset")) {}

  std::vector<std::string> fullNames() const override {
    auto names = exid::models::payloadNames();
    if (offset_)
      for (const char* c : {"OFF_FX", "OFF_FY", "OFF_FZ", "OFF_MX", "OFF_MY", "OFF_MZ"})
        names.push_back(c);
    return names;
  }
  Eigen::VectorXd fullNominal() const override {
    Eigen::VectorXd v = Eigen::VectorXd::Zero(numFull());
    v.head(10) = payload_.phi();
    return v;
  }
  Eigen::VectorXd fullTruth(const exid::PlantTruth& plant) const override {
    Eigen::VectorXd v = fullNominal();        // the simulation adds no sensor offset
    const exid::LoadMass& m = plant.payload;  // (none: zero)
    v.head(10) = exid::models::Payload{m.mass_kg, m.com_m, m.inertia_com_kg_m2}.phi();
    return v;
  }
  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;  // six rows per sample
    sp.required_signals = {"q", "qd", "qdd", "wrench"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    const int n = robot().dof();
    const std::string who = "model 'load_wrench'";
    requireSignal(d, d.q, "q", n, who);
    requireSignal(d, d.qd, "qd", n, who);
    requireSignal(d, d.qdd, "qdd", n, who);
    check(d.wrench.cols() == 6 && d.wrench.rows() == d.size(),
          fmt::format("{}: the dataset ({}) has no wrist wrench (columns fx fy fz mx my mz)", who,
                      d.source.empty() ? "unnamed" : d.source));
    exid::Rows r;
    r.W = fullDesign(d.samples());
    const int K = d.size();
    r.y.resize(6 * K);
    r.equation.resize(static_cast<std::size_t>(6 * K));
    for (int k = 0; k < K; ++k)
      for (int e = 0; e < 6; ++e) {
        r.y[6 * k + e] = d.wrench(k, e);
        r.equation[static_cast<std::size_t>(6 * k + e)] = e;
      }
    r.numEquations = 6;
    r.t.resize(static_cast<std::size_t>(6 * K));
    for (int k = 0; k < K; ++k)
      for (int e = 0; e < 6; ++e) r.t[static_cast<std::size_t>(6 * k + e)] = d.t[k];
    r.equation_names = {"fx [N]", "fy [N]", "fz [N]", "mx [N m]", "my [N m]", "mz [N m]"};
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    const exid::RobotModel& R = robot();
    const int K = s.size();
    exid::models::requireSamples(s, R.dof(), true, "model 'load_wrench'");
    Eigen::MatrixXd W = Eigen::MatrixXd::Zero(6 * K, numFull());
    auto data = exid::makeDynamicsData(R);
    Eigen::VectorXd q, qd, qdd;
    Eigen::Matrix<double, 6, 10> A;
    for (int k = 0; k < K; ++k) {
      exid::measuredToJoint(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                            s.qdd.row(k).transpose(), &q, &qd, &qdd);
      exid::wrenchRegressor(R, *data, q, qd, qdd, A);
      W.block(6 * k, 0, 6, 10) = A;
      if (offset_) W.block(6 * k, 10, 6, 6).setIdentity();
    }
    return W;
  }

  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    const exid::RobotModel& R = robot();
    const int K = s.size();
    exid::check(dW.rows() == 6 * K && dW.cols() == numFull(),
                fmt::format("model 'load_wrench': fullDesignVjp: dW is {} x {} (expected {} x {})",
                            dW.rows(), dW.cols(), 6 * K, numFull()));
    exid::models::zeroGrad(s, grad);
    auto data = exid::makeDynamicsData(R);
    Eigen::VectorXd q, qd, qdd, gq, gqd, gqdd;
    for (int k = 0; k < K; ++k) {
      exid::measuredToJoint(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                            s.qdd.row(k).transpose(), &q, &qd, &qdd);
      const Eigen::Matrix<double, 6, 10> G = dW.block(6 * k, 0, 6, 10);
      exid::wrenchRegressorVjp(R, *data, q, qd, qdd, G, &gq, &gqd, &gqdd);
      exid::models::storeSampleGrad(R, k, &gq, &gqd, &gqdd, grad);
    }
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] = "w = A(omega, alpha, a - g) phi (+ w0)";
    j["wrench"] =
        "fx fy fz mx my mz: wrench exerted by the sensor on the payload, sensor frame, "
        "moment about the sensor origin";
    j["parameters"] =
        "phi = M MX MY MZ XX XY XZ YY YZ ZZ of the payload about the sensor origin, "
        "sensor axes";
    j["sensor_offset"] = offset_;
    j["nominal_payload"] = payload_.json();
    j["equation_index"] = "wrench component 0..5 (fx fy fz mx my mz)";
    return j;
  }

 private:
  int numFull() const { return offset_ ? 16 : 10; }
  static void check(bool c, const std::string& m) { exid::check(c, m); }

  exid::models::Payload payload_;
  bool offset_;
};

}  // namespace

EXID_REGISTER_PLUGIN(LoadWrenchModel)
