// exid — observation model `differential`: the equations of motion, one row per sample and
// selected joint (paper eqns 1 and 3):
//   tau_m,i - tau_f,i = Y_i(qm, qdm, qddm) * pi
// Y is exid::actuatorRegressor (rigid-body columns through the transmission, then per measured
// coordinate the enabled drive columns Ia, Fc, Fv, OFF). With `friction: subtract` the robot's
// own friction torque tau_f = Fc sign(qdm) + Fv qdm (+ OFF unless `offset` identifies it) is
// subtracted from the measurement instead of identified (the paper's approach).
//
// Friction beyond Coulomb + viscous (docs/models.md, "Nonlinear friction"), columns after the
// drive columns, per selected joint j:
//   s_j = sign(qdm_j), or tanh(qdm_j / eps_j) with coulomb_smoothing_rad_s (eps_j nonlinear);
//   Coulomb: Fc_j s_j, or asymmetric FcP_j (1 + s_j)/2 - FcN_j (1 - s_j)/2;
//   Stribeck: Fs_j s_j exp(-(|qdm_j| / vs_j)^delta) (vs_j nonlinear, delta fixed).
// The nonlinear parameters (eps_j, vs_j) take the study's values in rows(); the `varpro`
// estimator fits them (ObservationModel::fullRowsAt gives the exact column derivatives).
#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
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
        exid::param_bool("coulomb_asymmetric", false,
                         "with friction: model, two Coulomb levels per drive: FcP_j for qdm_j > 0 "
                         "and FcN_j for qdm_j < 0 (columns (1 + s)/2 and -(1 - s)/2)"),
        exid::param_doubles("coulomb_smoothing_rad_s", std::vector<double>{}, "rad/s",
                            "smooth sign s = tanh(qdm / eps) instead of sign(qdm) in the Coulomb "
                            "(and Stribeck) columns: eps per drive (one value: every drive); "
                            "nonlinear parameters eps_j, fitted by `varpro`; empty: sign",
                            0),
        exid::param_bool("stribeck", false,
                         "with friction: model, a Stribeck column Fs_j s exp(-(|qdm_j| / vs_j)^"
                         "stribeck_exponent) per drive (needs stribeck_velocity_rad_s)"),
        exid::param_doubles("stribeck_velocity_rad_s", std::vector<double>{}, "rad/s",
                            "Stribeck velocity vs_j per drive (one value: every drive): the value "
                            "rows use and `varpro` starts from (nonlinear parameters vs_j)",
                            0),
        exid::param_double("stribeck_exponent", 2.0, "",
                           "the exponent delta of the Stribeck curve (fixed, not fitted)", 0.5,
                           4.0),
    };
  }

  explicit DifferentialModel(const exid::ParamSet& p)
      : joints_param_(p.getInts("joints")), friction_(p.getString("friction")) {
    cols_.rotor_inertia = p.getBool("rotor_inertia");
    cols_.coulomb = friction_ == "model" && p.getBool("coulomb");
    cols_.viscous = friction_ == "model" && p.getBool("viscous");
    cols_.offset = p.getBool("offset");
    asym_ = p.getBool("coulomb_asymmetric");
    eps_param_ = p.getDoubles("coulomb_smoothing_rad_s");
    stribeck_ = p.getBool("stribeck");
    vs_param_ = p.getDoubles("stribeck_velocity_rad_s");
    delta_ = p.getDouble("stribeck_exponent");
    const bool extra = asym_ || !eps_param_.empty() || stribeck_;
    exid::check(!extra || friction_ == "model",
                "model 'differential': coulomb_asymmetric, coulomb_smoothing_rad_s and stribeck "
                "need friction: model (they are identified columns)");
    exid::check(!(asym_ || !eps_param_.empty()) || p.getBool("coulomb"),
                "model 'differential': coulomb_asymmetric and coulomb_smoothing_rad_s shape the "
                "Coulomb columns: they need coulomb: true");
    exid::check(!stribeck_ || !vs_param_.empty(),
                "model 'differential': stribeck: true needs stribeck_velocity_rad_s (the "
                "Stribeck velocity of each drive, or one for all: the value rows use and varpro "
                "starts from; exid does not guess it)");
    exid::check(stribeck_ || vs_param_.empty(),
                "model 'differential': stribeck_velocity_rad_s is given but stribeck is false");
    for (double v : eps_param_)
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("model 'differential': coulomb_smoothing_rad_s: {} is not a "
                              "positive width (leave the list empty for sign(qdm))",
                              v));
    for (double v : vs_param_)
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("model 'differential': stribeck_velocity_rad_s: {} is not a "
                              "positive velocity",
                              v));
    coulomb_extra_ = cols_.coulomb && (asym_ || !eps_param_.empty());
    if (coulomb_extra_) cols_.coulomb = false;  // the Coulomb columns are the extra ones
  }

  std::vector<std::string> fullNames() const override {
    std::vector<std::string> names = exid::parameterNames(robot(), cols_);
    for (int j = 0; j < robot().dof(); ++j) {
      const std::string k = std::to_string(j + 1);
      if (coulomb_extra_ && !asym_) names.push_back("Fc" + k);
      if (coulomb_extra_ && asym_) {
        names.push_back("FcP" + k);
        names.push_back("FcN" + k);
      }
      if (stribeck_) names.push_back("Fs" + k);
    }
    return names;
  }
  Eigen::VectorXd fullNominal() const override {
    const Eigen::VectorXd v = exid::parameterValues(robot(), cols_);
    const int n = robot().dof(), E = extraPerJoint();
    Eigen::VectorXd out(v.size() + E * n);
    out.head(v.size()) = v;
    for (int j = 0; j < n; ++j) {
      const double fc = drive(j).coulomb;
      int c = static_cast<int>(v.size()) + E * j;
      if (coulomb_extra_) out[c++] = fc;  // (symmetric nominal: FcP = FcN = Fc)
      if (coulomb_extra_ && asym_) out[c++] = fc;
      if (stribeck_) out[c++] = 0.0;  // no Stribeck term in the robot description
    }
    return out;
  }

  std::vector<exid::NonlinearParameter> nonlinearParameters() const override {
    std::vector<exid::NonlinearParameter> out;
    const int P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
    const int nc = coulomb_extra_ ? (asym_ ? 2 : 1) : 0;
    for (const Slot& sl : slots()) {
      const int j = sl.joint, c0 = P0 + E * j;
      if (sl.eps) {
        exid::NonlinearParameter e{
            "eps" + std::to_string(j + 1), "rad/s", perJoint(eps_param_, j), {}};
        for (int c = 0; c < nc + (stribeck_ ? 1 : 0); ++c) e.columns.push_back(c0 + c);
        out.push_back(e);
      } else {
        out.push_back({"vs" + std::to_string(j + 1), "rad/s", perJoint(vs_param_, j), {c0 + nc}});
      }
    }
    return out;
  }

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;  // the rows of sample k are the equations of motion at sample k
    sp.required_signals = {"q", "qd", "qdd", "tau"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext& ctx) const override {
    return fullRowsAt(d, studyEta(), nullptr, ctx);
  }

  exid::Rows fullRowsAt(const exid::Dataset& d, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW,
                        const exid::RunContext&) const override {
    const int n = robot().dof();
    const std::string who = "model 'differential'";
    requireTorqueSignals(d, n, who);
    exid::Rows r;
    r.W = designAt(d.samples(), frictionAt(eta), dW);
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
    return designAt(s, frictionAt(studyEta()), nullptr);
  }

  // The per-drive widths and Stribeck velocities at eta (nonlinearParameters() order).
  struct Friction {
    std::vector<double> eps, vs;  // per drive (eps 0: sign)
  };
  Friction frictionAt(const Eigen::VectorXd& eta) const {
    const int n = robot().dof();
    Friction f;
    f.eps.assign(static_cast<std::size_t>(n), 0.0);
    f.vs.assign(static_cast<std::size_t>(n), 1.0);
    for (int j = 0; j < n; ++j) {
      if (!eps_param_.empty()) f.eps[static_cast<std::size_t>(j)] = perJoint(eps_param_, j);
      if (stribeck_) f.vs[static_cast<std::size_t>(j)] = perJoint(vs_param_, j);
    }
    const std::vector<Slot> sl = slots();
    exid::check(eta.size() == static_cast<Eigen::Index>(sl.size()),
                "model 'differential': wrong number of nonlinear parameter values");
    for (std::size_t k = 0; k < sl.size(); ++k) {
      const double v = eta[static_cast<Eigen::Index>(k)];
      if (!(v > 0 && std::isfinite(v)))
        throw exid::Error(fmt::format("model 'differential': {}{} = {} (must be positive)",
                                      sl[k].eps ? "eps" : "vs", sl[k].joint + 1, v));
      (sl[k].eps ? f.eps : f.vs)[static_cast<std::size_t>(sl[k].joint)] = v;
    }
    return f;
  }

  // Full design rows at the friction f; dW (optional): the derivatives of the columns the
  // nonlinear parameters move, in nonlinearParameters() order.
  Eigen::MatrixXd designAt(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* dW) const {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    exid::models::requireSamples(s, n, true, "model 'differential'");
    const int P0 = exid::numParameters(R, cols_), E = extraPerJoint();
    const int P = P0 + E * n;
    // One sample's rows are a block of m consecutive rows of W: each column receives m
    // contiguous numbers (cache friendly), and nothing is allocated per sample.
    Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m, P);
    Eigen::MatrixXd Y(n, P0);
    Eigen::VectorXd q(n), qd(n), qdd(n);
    bool all = m == n;
    for (int i = 0; all && i < m; ++i) all = sel_[static_cast<std::size_t>(i)] == i;
    auto data = exid::makeDynamicsData(R);
    for (int k = 0; k < K; ++k) {
      q = s.q.row(k).transpose();
      qd = s.qd.row(k).transpose();
      qdd = s.qdd.row(k).transpose();
      if (all && E == 0) {
        // Written in place (a strided block of W): no per-sample copy.
        exid::actuatorRegressor(R, *data, cols_, q, qd, qdd,
                                W.middleRows(static_cast<Eigen::Index>(k) * m, m));
      } else {
        exid::actuatorRegressor(R, *data, cols_, q, qd, qdd, Y);
        for (int i = 0; i < m; ++i)
          W.row(k * m + i).head(P0) = Y.row(sel_[static_cast<std::size_t>(i)]);
      }
    }
    if (E > 0) extraColumns(s, f, &W, dW);
    return W;
  }

  // The nonlinear friction columns (after the P0 drive columns) of W, and their derivatives
  // with respect to the nonlinear parameters into dW (see designAt).
  void extraColumns(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* W,
                    Eigen::MatrixXd* dW) const {
    const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
    W->rightCols(E * n).setZero();
    // where each drive's derivative columns start in dW (nonlinearParameters() order)
    std::vector<int> deps(static_cast<std::size_t>(n), -1), dvs(static_cast<std::size_t>(n), -1);
    int L = 0;
    const int nc = coulomb_extra_ ? (asym_ ? 2 : 1) : 0;
    for (const Slot& sl : slots()) {
      (sl.eps ? deps : dvs)[static_cast<std::size_t>(sl.joint)] = L;
      L += sl.eps ? nc + (stribeck_ ? 1 : 0) : 1;
    }
    if (dW) dW->setZero(W->rows(), L);
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        const auto u = static_cast<std::size_t>(j);
        const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
        const double v = s.qd(k, j), eps = f.eps[u];
        const double sg = eps > 0 ? std::tanh(v / eps) : (v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0));
        const double ds_deps = eps > 0 ? -(v / (eps * eps)) * (1.0 - sg * sg) : 0.0;
        int c = P0 + E * j, l = deps[u];
        if (coulomb_extra_ && !asym_) {
          (*W)(row, c++) = sg;
          if (dW && l >= 0) (*dW)(row, l++) = ds_deps;
        } else if (coulomb_extra_) {
          (*W)(row, c++) = 0.5 * (1.0 + sg);
          (*W)(row, c++) = -0.5 * (1.0 - sg);
          if (dW && l >= 0) {
            (*dW)(row, l++) = 0.5 * ds_deps;
            (*dW)(row, l++) = 0.5 * ds_deps;
          }
        }
        if (stribeck_) {
          const double r = std::abs(v) / f.vs[u];
          const double rd = std::pow(r, delta_), g = std::exp(-rd);
          (*W)(row, c) = sg * g;
          if (dW && l >= 0) (*dW)(row, l) = ds_deps * g;
          if (dW && dvs[u] >= 0) (*dW)(row, dvs[u]) = sg * g * delta_ * rd / f.vs[u];
        }
      }
  }

  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P0 = exid::numParameters(R, cols_), P = P0 + extraPerJoint() * n;
    exid::check(dW.rows() == static_cast<Eigen::Index>(K) * m && dW.cols() == P,
                fmt::format("model 'differential': fullDesignVjp: dW is {} x {} (expected {} x {})",
                            dW.rows(), dW.cols(), K * m, P));
    exid::models::zeroGrad(s, grad);
    Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, P0);
    Eigen::VectorXd gq, gqd, gqdd;
    auto data = exid::makeDynamicsData(R);
    const Friction f = frictionAt(studyEta());
    for (int k = 0; k < K; ++k) {
      G.setZero();
      for (int i = 0; i < m; ++i)
        G.row(sel_[static_cast<std::size_t>(i)]) = dW.row(k * m + i).head(P0);
      exid::actuatorRegressorVjp(R, *data, cols_, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                                 s.qdd.row(k).transpose(), G, &gq, &gqd, &gqdd);
      for (int i = 0; i < m && P > P0; ++i) {  // the extra columns' derivatives in qdm_j
        const int j = sel_[static_cast<std::size_t>(i)];
        gqd[j] += extraColumnsVjp(
            s.qd(k, j), f, j, dW.row(k * m + i).segment(P0 + extraPerJoint() * j, extraPerJoint()));
      }
      grad->q.row(k) = gq.transpose();
      grad->qd.row(k) = gqd.transpose();
      grad->qdd.row(k) = gqdd.transpose();
    }
  }

  // sum_e g_e d(column e of drive j)/d qdm_j (sign has derivative 0; tanh and Stribeck not).
  double extraColumnsVjp(double v, const Friction& f, int j,
                         const Eigen::Ref<const Eigen::RowVectorXd>& g) const {
    const auto u = static_cast<std::size_t>(j);
    const double eps = f.eps[u];
    const double sg = eps > 0 ? std::tanh(v / eps) : (v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0));
    const double ds = eps > 0 ? (1.0 - sg * sg) / eps : 0.0;
    double out = 0.0;
    int e = 0;
    if (coulomb_extra_ && !asym_) out += g[e++] * ds;
    if (coulomb_extra_ && asym_) {
      out += g[e++] * 0.5 * ds;
      out += g[e++] * 0.5 * ds;
    }
    if (stribeck_) {
      const double vs = f.vs[u], r = std::abs(v) / vs, rd = std::pow(r, delta_), gg = std::exp(-rd);
      // d/dv [s g] = ds g + s g (-delta r^(delta-1) sign(v) / vs)
      const double dr = v == 0.0 ? 0.0 : delta_ * std::pow(r, delta_ - 1.0) * (v > 0 ? 1 : -1) / vs;
      out += g[e] * (ds * gg - sg * gg * dr);
    }
    return out;
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
    if (coulomb_extra_ || stribeck_) {
      exid::Json f = exid::Json::object();
      f["coulomb_asymmetric"] = asym_;
      f["sign"] = eps_param_.empty() ? "sign(qdm)" : "tanh(qdm / eps_j)";
      if (stribeck_) {
        f["stribeck"] = "Fs_j s exp(-(|qdm_j| / vs_j)^delta)";
        f["stribeck_exponent"] = delta_;
      }
      exid::Json nl = exid::Json::array();
      for (const auto& p : nonlinearParameters()) {
        exid::Json e = exid::Json::object();
        e["name"] = p.name;
        e["value"] = p.value;
        e["unit"] = p.unit;
        nl.push_back(e);
      }
      f["nonlinear_parameters"] = nl;
      j["nonlinear_friction"] = f;
    }
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
    const exid::Drive D = drive(j);
    const double sg = qdm > 0.0 ? 1.0 : (qdm < 0.0 ? -1.0 : 0.0);
    return D.coulomb * sg + D.viscous * qdm + (cols_.offset ? 0.0 : D.offset);
  }

  exid::Drive drive(int j) const {
    const auto& dr = robot().drives;
    return j < static_cast<int>(dr.size()) ? dr[static_cast<std::size_t>(j)] : exid::Drive{};
  }
  // The nonlinear parameters in order: per selected joint (ascending), its width then its
  // Stribeck velocity.
  struct Slot {
    bool eps = false;
    int joint = 0;
  };
  std::vector<Slot> slots() const {
    std::vector<int> joints = sel_;
    std::sort(joints.begin(), joints.end());
    std::vector<Slot> out;
    for (int j : joints) {
      if (!eps_param_.empty()) out.push_back({true, j});
      if (stribeck_) out.push_back({false, j});
    }
    return out;
  }
  int extraPerJoint() const { return (coulomb_extra_ ? (asym_ ? 2 : 1) : 0) + (stribeck_ ? 1 : 0); }
  double perJoint(const std::vector<double>& v, int j) const {
    exid::check(v.size() == 1 || static_cast<int>(v.size()) == robot().dof(),
                fmt::format("model 'differential': {} values given for robot '{}' of {} drives "
                            "(expected one, or one per drive)",
                            v.size(), robot().name, robot().dof()));
    return v.size() == 1 ? v[0] : v[static_cast<std::size_t>(j)];
  }
  Eigen::VectorXd studyEta() const {
    const std::vector<exid::NonlinearParameter> nl = nonlinearParameters();
    Eigen::VectorXd eta(static_cast<Eigen::Index>(nl.size()));
    for (std::size_t k = 0; k < nl.size(); ++k) eta[static_cast<Eigen::Index>(k)] = nl[k].value;
    return eta;
  }

  std::vector<std::int64_t> joints_param_;
  std::string friction_;
  exid::DriveColumns cols_;
  std::vector<int> sel_;
  bool asym_ = false, stribeck_ = false, coulomb_extra_ = false;
  std::vector<double> eps_param_, vs_param_;
  double delta_ = 2.0;
};

}  // namespace

EXID_REGISTER_PLUGIN(DifferentialModel)
