// exid — observation model `differential`: the equations of motion, one row per sample and
// selected joint (paper eqns 1 and 3):
//   tau_m,i - tau_f,i = Y_i(qm, qdm, qddm) * pi
// Y is exid::actuatorRegressor (rigid-body columns through the transmission, then per measured
// coordinate the enabled drive columns Ia, Fc, Fv, OFF). With `friction: subtract` the robot's
// own friction torque tau_f = Fc sign(qdm) + Fv qdm (+ OFF unless `offset` identifies it) is
// subtracted from the measurement instead of identified (the paper's approach).
#include <fmt/format.h>

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "model_common.hpp"

namespace {

using exid::models::requireTorqueSignals;

class DifferentialModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "differential";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "equations of motion tau_m - tau_f = Y(qm, qdm, qddm) pi, one row per sample and selected "
      "joint (paper eqns 1, 3); drive columns Ia, Fc, Fv, OFF optional";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_ints("joints", std::vector<std::int64_t>{},
                         "1-based joints whose torque equations are used; empty: all (the paper's "
                         "eqn 3 uses joint 1 alone)",
                         1.0),
        exid::param_string("friction", std::string("model"),
                           "model: identify Coulomb/viscous columns (see coulomb, viscous); "
                           "subtract: subtract the robot's own friction torque Fc sign(qd) + Fv qd "
                           "(+ OFF unless offset is identified) from the measurement; none: ignore",
                           {"model", "subtract", "none"}),
        exid::param_bool("rotor_inertia", true,
                         "identify the rotor inertia Ia_j (column qddm_j) of every drive"),
        exid::param_bool(
            "coulomb", true,
            "with friction: model, identify Coulomb friction Fc_j (column sign(qdm_j))"),
        exid::param_bool("viscous", true,
                         "with friction: model, identify viscous friction Fv_j (column qdm_j)"),
        exid::param_bool("offset", false, "identify a torque offset OFF_j (column 1) per drive"),
    };
  }

  explicit DifferentialModel(const exid::ParamSet& p)
      : joints_param_(p.getInts("joints")), friction_(p.getString("friction")) {
    cols_.rotor_inertia = p.getBool("rotor_inertia");
    cols_.coulomb = friction_ == "model" && p.getBool("coulomb");
    cols_.viscous = friction_ == "model" && p.getBool("viscous");
    cols_.offset = p.getBool("offset");
  }

  std::vector<std::string> fullNames() const override {
    return exid::parameterNames(robot(), cols_);
  }
  Eigen::VectorXd fullNominal() const override { return exid::parameterValues(robot(), cols_); }

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;  // the rows of sample k are the equations of motion at sample k
    sp.required_signals = {"q", "qd", "qdd", "tau"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    const int n = robot().dof();
    const std::string who = "model 'differential'";
    requireTorqueSignals(d, n, who);
    exid::Rows r;
    r.W = fullDesign(d.samples());
    const int K = d.size(), m = static_cast<int>(sel_.size());
    exid::models::sizeRows(&r, K, m);
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        double y = d.tau(k, j);
        if (friction_ == "subtract") y -= frictionTorque(j, d.qd(k, j));
        r.y[k * m + i] = y;
        r.equation[static_cast<std::size_t>(k * m + i)] = i;
        r.t[static_cast<std::size_t>(k * m + i)] = d.t[k];
      }
    r.equation_names = exid::models::torqueEquationNames(robot(), sel_);
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    exid::models::requireSamples(s, n, true, "model 'differential'");
    const int P = exid::numParameters(R, cols_);
    // One sample's rows are a block of m consecutive rows of W: each column receives m
    // contiguous numbers (cache friendly), and nothing is allocated per sample.
    Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m, P);
    Eigen::MatrixXd Y(n, P);
    Eigen::VectorXd q(n), qd(n), qdd(n);
    bool all = m == n;
    for (int i = 0; all && i < m; ++i) all = sel_[static_cast<std::size_t>(i)] == i;
    auto data = exid::makeDynamicsData(R);
    for (int k = 0; k < K; ++k) {
      q = s.q.row(k).transpose();
      qd = s.qd.row(k).transpose();
      qdd = s.qdd.row(k).transpose();
      if (all) {
        // Written in place (a strided block of W): no per-sample copy.
        exid::actuatorRegressor(R, *data, cols_, q, qd, qdd,
                                W.middleRows(static_cast<Eigen::Index>(k) * m, m));
      } else {
        exid::actuatorRegressor(R, *data, cols_, q, qd, qdd, Y);
        for (int i = 0; i < m; ++i) W.row(k * m + i) = Y.row(sel_[static_cast<std::size_t>(i)]);
      }
    }
    return W;
  }

  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P = exid::numParameters(R, cols_);
    exid::check(dW.rows() == static_cast<Eigen::Index>(K) * m && dW.cols() == P,
                fmt::format("model 'differential': fullDesignVjp: dW is {} x {} (expected {} x {})",
                            dW.rows(), dW.cols(), K * m, P));
    exid::models::zeroGrad(s, grad);
    Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, P);
    Eigen::VectorXd gq, gqd, gqdd;
    auto data = exid::makeDynamicsData(R);
    for (int k = 0; k < K; ++k) {
      G.setZero();
      for (int i = 0; i < m; ++i) G.row(sel_[static_cast<std::size_t>(i)]) = dW.row(k * m + i);
      exid::actuatorRegressorVjp(R, *data, cols_, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                                 s.qdd.row(k).transpose(), G, &gq, &gqd, &gqdd);
      grad->q.row(k) = gq.transpose();
      grad->qd.row(k) = gqd.transpose();
      grad->qdd.row(k) = gqdd.transpose();
    }
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] = "tau_m,i - tau_f,i = Y_i(qm, qdm, qddm) pi (paper eqns 1, 3)";
    j["joints"] = exid::models::intsJson(sel_, 1);
    j["equation_index"] = "position of the joint in 'joints' (0-based)";
    j["friction"] = friction_;
    if (friction_ == "subtract")
      j["friction_subtracted"] = cols_.offset ? "Fc sign(qdm) + Fv qdm (robot drive data)"
                                              : "Fc sign(qdm) + Fv qdm + OFF (robot drive data)";
    j["rotor_inertia"] = cols_.rotor_inertia;
    j["coulomb"] = cols_.coulomb;
    j["viscous"] = cols_.viscous;
    j["offset"] = cols_.offset;
    j["rows_per_sample"] = static_cast<int>(sel_.size());
    return j;
  }

 protected:
  void onBind(const exid::RunContext&) override {
    sel_ = exid::models::selectJoints(joints_param_, robot().dof(),
                                      "model 'differential' on robot '" + robot().name + "'");
  }

 private:
  double frictionTorque(int j, double qdm) const {
    const auto& dr = robot().drives;
    const exid::Drive D =
        j < static_cast<int>(dr.size()) ? dr[static_cast<std::size_t>(j)] : exid::Drive{};
    const double sg = qdm > 0.0 ? 1.0 : (qdm < 0.0 ? -1.0 : 0.0);
    return D.coulomb * sg + D.viscous * qdm + (cols_.offset ? 0.0 : D.offset);
  }

  std::vector<std::int64_t> joints_param_;
  std::string friction_;
  exid::DriveColumns cols_;
  std::vector<int> sel_;
};

}  // namespace

EXID_REGISTER_PLUGIN(DifferentialModel)
