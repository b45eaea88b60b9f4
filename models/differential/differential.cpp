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
//   Stribeck: Fs_j s_j exp(-(|qdm_j| / vs_j)^delta) (vs_j nonlinear, delta fixed);
//   load-dependent Coulomb (coulomb_load): FcL_j |tau_m,j| sign(qdm_j), the friction of a
//   gear growing with the torque it carries (the recorded torque in rows; the nominal robot's
//   in a design).
// The nonlinear parameters (eps_j, vs_j) take the study's values in rows(); the `varpro`
// estimator fits them (ObservationModel::fullRowsAt gives the exact column derivatives).
//
// Drive gains (drive_gains, docs/models.md "Drive gains"): the true torque of drive j is
// (1 + dK_j) times the recorded one, dK_j identified with the rest from a recording whose
// second part carries a known payload phi (meta.payload_part_from_t_s, csv payload_file):
//   tau_m,j - [T^T Yp phi]_j (payload part only) = Y_j pi - dK_j tau_m,j.
// Without the payload part the scale of pi and the gains is not identifiable: refused, unless
// drive_gains_scale: prior says that a prior on the gains (gains_ls's gain_prior_std) sets it.
#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"
#include "exid/payload.hpp"

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
    std::vector<exid::ParamDecl> p = {
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
        exid::param_bool("coulomb_load", false,
                         "a load-dependent Coulomb term FcL_j |tau_m,j| sign(qdm_j) per drive "
                         "(FcL dimensionless: Coulomb torque per N m carried)"),
        exid::param_bool("drive_gains", false,
                         "identify a gain correction dK_j per drive: the true torque is (1 + "
                         "dK_j) times the recorded one; needs the data's payload part (csv "
                         "payload_file) and that payload (payload_mass_kg, ...), or "
                         "drive_gains_scale: prior"),
        exid::param_string("drive_gains_scale", "payload",
                           "what sets the gains' common scale: payload (a known payload in the "
                           "recording's payload part) or prior (the gains_ls estimator's "
                           "gain_prior_std on dK; no payload part, the data fix the gains' "
                           "ratios only)",
                           {"payload", "prior"}),
    };
    for (const auto& d :
         exid::payloadParams("known payload carried in the recording's payload part (drive_gains)"))
      p.push_back(d);
    return p;
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
    load_ = p.getBool("coulomb_load");
    exid::check(!load_ || friction_ == "model",
                "model 'differential': coulomb_load needs friction: model (an identified column)");
    exid::check(!load_ || eps_param_.empty(),
                "model 'differential': coulomb_load multiplies sign(qdm): it is not combined with "
                "coulomb_smoothing_rad_s");
    gains_ = p.getBool("drive_gains");
    exid::check(!(load_ && gains_),
                "model 'differential': coulomb_load and drive_gains both put the recorded torque "
                "in a column; they are not combined");
    gains_prior_ = p.getString("drive_gains_scale") == "prior";
    const exid::Payload load = exid::Payload::fromParams(p);
    exid::check(!gains_ || gains_prior_ || load.mass > 0,
                "model 'differential': drive_gains: true needs the known payload of the "
                "recording's payload part (payload_mass_kg > 0, payload_com_m, "
                "payload_inertia_kg_m2): it sets the scale of the gains (or "
                "drive_gains_scale: prior, with gains_ls's gain_prior_std)");
    exid::check(gains_ || load.mass == 0,
                "model 'differential': payload_mass_kg is given but drive_gains is false");
    exid::check(!gains_prior_ || load.mass == 0,
                "model 'differential': payload_mass_kg is given with drive_gains_scale: prior "
                "(a known payload sets the scale: drive_gains_scale: payload)");
    exid::check(gains_ || !gains_prior_,
                "model 'differential': drive_gains_scale: prior is given but drive_gains is "
                "false");
    phi_ = load.phi();
    // The design's structural payload under drive_gains_scale: prior (the base parameters only;
    // never in rows): 1 kg, 5 cm off the flange's axis, with some inertia. With it the dK
    // columns are base columns; the data alone then lack one direction (the gains' common
    // scale), which the estimator's prior fixes.
    if (gains_prior_) {
      exid::Payload structural;
      structural.mass = 1.0;
      structural.com = Eigen::Vector3d(0.05, 0.03, 0.08);
      structural.I_com = Eigen::Vector3d(0.002, 0.003, 0.0025).asDiagonal();
      design_phi_ = structural.phi();
    } else {
      design_phi_ = phi_;
    }
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
    for (int j = 0; j < loadCount(); ++j) names.push_back("FcL" + std::to_string(j + 1));
    for (int j = 0; j < gainCount(); ++j) names.push_back("dK" + std::to_string(j + 1));
    return names;
  }
  Eigen::VectorXd fullNominal() const override {
    const Eigen::VectorXd v = exid::parameterValues(robot(), cols_);
    const int n = robot().dof(), E = extraPerJoint();
    // FcL, dK: 0
    Eigen::VectorXd out = Eigen::VectorXd::Zero(v.size() + E * n + loadCount() + gainCount());
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

  // The parameters of the `simulate` experiment's plant, from the dataset's meta: its payload
  // (merged into the sensor body), its drive terms (none with drive_terms: false), its
  // friction beyond Coulomb + viscous (coulomb_negative_Nm, stribeck_Nm,
  // coulomb_load_Nm_per_Nm) and its gain errors (recorded_torque_gain: dK = 1/g - 1;
  // drive_torque_gain: dK = g - 1). What the model has no column for is left out.
  Eigen::VectorXd fullTruth(const exid::Json& meta) const override {
    Eigen::VectorXd out = fullNominal();
    const exid::RobotModel& R = robot();
    const int n = R.dof(), P0 = exid::numParameters(R, cols_), E = extraPerJoint();
    if (const exid::Json* p = meta.find("payload"); p && p->isObject()) {
      const exid::Payload load = exid::Payload::fromJson(*p);
      if (!load.empty())
        out.segment<10>(10 * R.sensorBody()) += exid::transformInertial(load.pi(), R.sensor_pose);
    }
    auto perDrive = [&](const char* key, std::vector<double>* v) {
      const exid::Json* j = meta.find(key);
      if (!j || !j->isArray() || j->size() == 0) return false;
      v->assign(static_cast<std::size_t>(n), 0.0);
      for (int d = 0; d < n; ++d)
        (*v)[static_cast<std::size_t>(d)] =
            j->at(j->size() == 1 ? 0 : static_cast<std::size_t>(d)).asDouble();
      return j->size() == 1 || static_cast<int>(j->size()) == n;
    };
    if (const exid::Json* dt = meta.find("drive_terms");
        dt && dt->type() == exid::Json::Type::Bool && !dt->asBool()) {
      out.segment(10 * n, P0 - 10 * n).setZero();
      out.segment(P0, E * n).setZero();
    }
    std::vector<double> v;
    const int nc = coulomb_extra_ ? (asym_ ? 2 : 1) : 0;
    if (asym_ && coulomb_extra_ && perDrive("coulomb_negative_Nm", &v))
      for (int j = 0; j < n; ++j) out[P0 + E * j + 1] = v[static_cast<std::size_t>(j)];
    if (stribeck_ && perDrive("stribeck_Nm", &v))
      for (int j = 0; j < n; ++j) out[P0 + E * j + nc] = v[static_cast<std::size_t>(j)];
    const int Pl = P0 + E * n, Pg = Pl + loadCount();
    if (load_ && perDrive("coulomb_load_Nm_per_Nm", &v))
      for (int j = 0; j < n; ++j) out[Pl + j] = v[static_cast<std::size_t>(j)];
    if (gains_ && perDrive("recorded_torque_gain", &v))
      for (int j = 0; j < n; ++j) out[Pg + j] = 1.0 / v[static_cast<std::size_t>(j)] - 1.0;
    if (gains_ && perDrive("drive_torque_gain", &v))
      for (int j = 0; j < n; ++j) out[Pg + j] = v[static_cast<std::size_t>(j)] - 1.0;
    return out;
  }

  std::vector<exid::NonlinearParameter> nonlinearParameters() const override {
    std::vector<exid::NonlinearParameter> out;
    const int P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
    const int nc = coulomb_extra_ ? (asym_ ? 2 : 1) : 0;
    for (const Slot& sl : slots()) {
      const int j = sl.joint, c0 = P0 + E * j;
      // a velocity of the measured coordinate: m/s for a prismatic joint measured directly
      const auto u = static_cast<std::size_t>(j);
      const char* unit = !robot().hasTransmission() && u < robot().bodies.size() &&
                                 robot().bodies[u].type == exid::JointType::Prismatic
                             ? "m/s"
                             : "rad/s";
      if (sl.eps) {
        exid::NonlinearParameter e{
            "eps" + std::to_string(j + 1), unit, perJoint(eps_param_, j), {}};
        for (int c = 0; c < nc + (stribeck_ ? 1 : 0); ++c) e.columns.push_back(c0 + c);
        out.push_back(e);
      } else {
        out.push_back({"vs" + std::to_string(j + 1), unit, perJoint(vs_param_, j), {c0 + nc}});
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
    r.W = designAt(d.samples(), frictionAt(eta), dW, false);
    const int K = d.size(), m = static_cast<int>(sel_.size());
    exid::models::sizeRows(&r, K, m);
    // drive gains: the payload part's samples (t >= its first) carry the known payload
    double loaded_from = HUGE_VAL;
    if (gains_ && gains_prior_) {
      exid::check(d.meta.find("payload_part_from_t_s") == nullptr,
                  fmt::format("{}: the data have a payload part (meta.payload_part_from_t_s) "
                              "but drive_gains_scale is prior: give the payload "
                              "(payload_mass_kg, ...) and drive_gains_scale: payload ({})",
                              who, d.source));
    } else if (gains_) {
      const exid::Json* from = d.meta.find("payload_part_from_t_s");
      if (!from || !from->isNumber())
        throw exid::Error(
            fmt::format("{}: drive_gains needs a part of the recording with the known payload (csv "
                        "payload_file; meta.payload_part_from_t_s): without it the gains and the "
                        "parameters' scale are not identifiable ({})",
                        who, d.source));
      loaded_from = from->asDouble();
    }
    const int Pg = static_cast<int>(r.W.cols()) - gainCount(), Pl = Pg - loadCount();
    auto data = gains_ ? exid::makeDynamicsData(robot()) : nullptr;  // (once per call)
    Eigen::VectorXd tp;
    for (int k = 0; k < K; ++k) {
      const bool loaded = gains_ && d.t[k] >= loaded_from;
      if (loaded) tp = payloadTorque(*data, phi_, d.q.row(k), d.qd.row(k), d.qdd.row(k));
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        double y = d.tau(k, j);
        if (friction_ == "subtract") y -= frictionTorque(j, d.qd(k, j));
        if (gains_) r.W(k * m + i, Pg + j) = -d.tau(k, j);
        if (load_) r.W(k * m + i, Pl + j) = std::abs(d.tau(k, j)) * signum(d.qd(k, j));
        if (loaded) y -= tp[j];
        r.y[k * m + i] = y;
        r.equation[static_cast<std::size_t>(k * m + i)] = i;
        r.t[static_cast<std::size_t>(k * m + i)] = d.t[k];
      }
    }
    r.equation_names = exid::models::torqueEquationNames(robot(), sel_);
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    return designAt(s, frictionAt(studyEta()), nullptr);
  }
  Eigen::MatrixXd fullDesignAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                               Eigen::MatrixXd* dW) const override {
    return designAt(s, frictionAt(eta), dW);
  }

  bool fullTorqueAt(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                    const Eigen::VectorXd& eta, const Eigen::VectorXd& phi, Eigen::VectorXd* tau,
                    Eigen::MatrixXd* d_q, Eigen::MatrixXd* d_qd,
                    Eigen::MatrixXd* d_qdd) const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), P0 = exid::numParameters(R, cols_), E = extraPerJoint();
    const int T = loadCount() + gainCount();
    if (phi.size() != P0 + E * n + T || tau == nullptr)  // (a simulation's every step)
      throw exid::Error(
          fmt::format("model 'differential': fullTorqueAt: {} parameters, expected {}{}",
                      phi.size(), P0 + E * n + T, tau ? "" : "; tau must be given"));
    if (static_cast<int>(sel_.size()) != n) return false;
    for (int i = 0; i < n; ++i)
      if (sel_[static_cast<std::size_t>(i)] != i) return false;
    if (T > 0 && !phi.tail(T).isZero(0.0)) return false;      // (the torque columns: the design's)
    const Friction f = E > 0 ? frictionAt(eta) : Friction{};  // (only the extra columns read it)
    {
      const Workspace data(*this);
      exid::actuatorTorqueWith(R, *data, cols_, phi.head(P0), q, qd, qdd, tau, d_q, d_qd, d_qdd);
    }
    for (int j = 0; j < n && E > 0; ++j) {  // the nonlinear friction columns (extraColumns)
      const auto u = static_cast<std::size_t>(j);
      const auto g = phi.segment(P0 + E * j, E);
      const double v = qd[j], eps = f.eps[u];
      const double sg = eps > 0 ? std::tanh(v / eps) : signum(v);
      double t = 0.0;
      int e = 0;
      if (coulomb_extra_ && !asym_) t += g[e++] * sg;
      if (coulomb_extra_ && asym_) {
        t += g[e++] * 0.5 * (1.0 + sg);
        t -= g[e++] * 0.5 * (1.0 - sg);
      }
      if (stribeck_) t += g[e] * sg * std::exp(-std::pow(std::abs(v) / f.vs[u], delta_));
      (*tau)[j] += t;
      if (d_qd) (*d_qd)(j, j) += extraColumnsVjp(v, f, j, g.transpose());
    }
    return true;
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
  // With drive gains and gain_design, the dK columns are those of a design (no measurement):
  // minus the nominal robot's torque, with the known payload on every other sample (the
  // identifiable space of a recording with and without it); else zero (fullRowsAt fills them).
  Eigen::MatrixXd designAt(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* dW,
                           bool gain_design = true) const {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    exid::models::requireSamples(s, n, true, "model 'differential'");
    const int P0 = exid::numParameters(R, cols_), E = extraPerJoint();
    const int P = P0 + E * n + loadCount() + gainCount();
    // One sample's rows are a block of m consecutive rows of W: each column receives m
    // contiguous numbers (cache friendly), and nothing is allocated per sample.
    Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m, P);
    Eigen::MatrixXd Y(n, P0);
    Eigen::VectorXd q(n), qd(n), qdd(n);
    bool all = m == n;
    for (int i = 0; all && i < m; ++i) all = sel_[static_cast<std::size_t>(i)] == i;
    const Workspace data(*this);
    for (int k = 0; k < K; ++k) {
      q = s.q.row(k).transpose();
      qd = s.qd.row(k).transpose();
      qdd = s.qdd.row(k).transpose();
      if (all && E == 0) {
        // Written in place (a strided block of W): no per-sample copy.
        exid::actuatorRegressor(R, *data, cols_, q, qd, qdd,
                                W.middleRows(static_cast<Eigen::Index>(k) * m, m).leftCols(P0));
      } else {
        exid::actuatorRegressor(R, *data, cols_, q, qd, qdd, Y);
        for (int i = 0; i < m; ++i)
          W.row(k * m + i).head(P0) = Y.row(sel_[static_cast<std::size_t>(i)]);
      }
    }
    if (E > 0) extraColumns(s, f, &W, dW);
    if (load_) loadColumns(s, &W);
    if (gains_) gainColumns(s, gain_design, &W);
    return W;
  }

  static double signum(double v) { return exid::coulombSign(v); }

  // The FcL columns of a design: |nominal torque| sign(qdm) (rows() puts the recorded torque).
  void loadColumns(const exid::Samples& s, Eigen::MatrixXd* W) const {
    const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int Pl = static_cast<int>(W->cols()) - n;
    const Eigen::VectorXd nominal = fullNominal().head(Pl);
    W->rightCols(n).setZero();  // (a row has its own joint's column only)
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
        (*W)(row, Pl + j) = std::abs(W->row(row).head(Pl).dot(nominal)) * signum(s.qd(k, j));
      }
  }

  // The dK columns of a design (see designAt), or zeros.
  void gainColumns(const exid::Samples& s, bool gain_design, Eigen::MatrixXd* W) const {
    const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int Pg = static_cast<int>(W->cols()) - n;
    W->rightCols(n).setZero();
    if (!gain_design) return;
    const Eigen::VectorXd nominal = fullNominal().head(Pg);
    auto data = exid::makeDynamicsData(robot());
    Eigen::VectorXd tp = Eigen::VectorXd::Zero(n);
    for (int k = 0; k < K; ++k) {
      if (k % 2 == 1)
        tp = payloadTorque(*data, design_phi_, s.q.row(k), s.qd.row(k), s.qdd.row(k));
      else
        tp.setZero();
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
        (*W)(row, Pg + j) = -(W->row(row).head(Pg).dot(nominal) + tp[j]);
      }
    }
  }

  // The known payload's torque at a sample, in the measured coordinates: T^T Yp phi.
  Eigen::VectorXd payloadTorque(exid::DynamicsData& data, const Eigen::Matrix<double, 10, 1>& phi,
                                const Eigen::Ref<const Eigen::RowVectorXd>& qm,
                                const Eigen::Ref<const Eigen::RowVectorXd>& qdm,
                                const Eigen::Ref<const Eigen::RowVectorXd>& qddm) const {
    const exid::RobotModel& R = robot();
    Eigen::VectorXd q, qd, qdd;
    exid::measuredToJoint(R, qm.transpose(), qdm.transpose(), qddm.transpose(), &q, &qd, &qdd);
    Eigen::MatrixXd Yp(R.dof(), 10);
    exid::payloadTorqueRegressor(R, data, q, qd, qdd, Yp);
    const Eigen::VectorXd t = Yp * phi;
    if (R.hasTransmission()) return R.transmission.transpose() * t;
    return t;
  }

  // The nonlinear friction columns (after the P0 drive columns) of W, and their derivatives
  // with respect to the nonlinear parameters into dW (see designAt).
  void extraColumns(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* W,
                    Eigen::MatrixXd* dW) const {
    const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
    W->middleCols(P0, E * n).setZero();
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
        const double sg = eps > 0 ? std::tanh(v / eps) : signum(v);
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
    fullDesignVjpAt(s, studyEta(), dW, grad);
  }

  void fullDesignVjpAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                       const Eigen::MatrixXd& dW, exid::Samples* grad) const override {
    const Friction f = frictionAt(eta);
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P0 = exid::numParameters(R, cols_), P = P0 + extraPerJoint() * n;
    const int T = loadCount() + gainCount();  // the torque columns
    exid::check(dW.rows() == static_cast<Eigen::Index>(K) * m && dW.cols() == P + T,
                fmt::format("model 'differential': fullDesignVjp: dW is {} x {} (expected {} x {})",
                            dW.rows(), dW.cols(), K * m, P + T));
    if (load_) {
      // the FcL columns |W_row nominal| sign(qdm_j): their part of the gradient goes through the
      // other columns, times sign(nominal torque) sign(qdm_j) the nominal values (sign(qdm)'s
      // derivative is 0)
      const Eigen::MatrixXd Wd = designAt(s, f, nullptr);
      Eigen::MatrixXd dWe = dW.leftCols(P);
      const Eigen::VectorXd nominal = fullNominal().head(P);
      for (int k = 0; k < K; ++k)
        for (int i = 0; i < m; ++i) {
          const int j = sel_[static_cast<std::size_t>(i)];
          const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
          const double c =
              dW(row, P + j) * signum(Wd.row(row).head(P).dot(nominal)) * signum(s.qd(k, j));
          if (c != 0.0) dWe.row(row) += c * nominal.transpose();
        }
      designVjpNoGains(s, f, dWe, grad);
      return;
    }
    if (gains_) {
      // the dK columns -(W_row nominal + [odd k] T^T Yp phi): their part of the gradient goes
      // through the other columns (times the nominal values) and the payload's torque
      Eigen::MatrixXd dWe = dW.leftCols(P);
      const Eigen::VectorXd nominal = fullNominal().head(P);
      for (int k = 0; k < K; ++k)
        for (int i = 0; i < m; ++i) {
          const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
          dWe.row(row) -= dW(row, P + sel_[static_cast<std::size_t>(i)]) * nominal.transpose();
        }
      designVjpNoGains(s, f, dWe, grad);
      payloadTorqueVjp(s, dW, P, grad);
      return;
    }
    designVjpNoGains(s, f, dW, grad);
  }

  // The gradient of sum_k,j c_kj [T^T Yp phi]_j over the odd samples, c = -dW's dK columns,
  // added to grad.
  void payloadTorqueVjp(const exid::Samples& s, const Eigen::MatrixXd& dW, int P,
                        exid::Samples* grad) const {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    auto data = exid::makeDynamicsData(R);
    Eigen::MatrixXd Gm(n, 10), G(n, 10);
    Eigen::VectorXd q, qd, qdd, gq, gqd, gqdd;
    for (int k = 1; k < K; k += 2) {
      exid::measuredToJoint(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                            s.qdd.row(k).transpose(), &q, &qd, &qdd);
      Gm.setZero();
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        Gm.row(j) -= dW(static_cast<Eigen::Index>(k) * m + i, P + j) * design_phi_.transpose();
      }
      if (R.hasTransmission())
        G.noalias() = R.transmission * Gm;
      else
        G = Gm;
      exid::payloadTorqueRegressorVjp(R, *data, q, qd, qdd, G, &gq, &gqd, &gqdd);
      exid::models::jointGradToMeasured(R, &gq);
      exid::models::jointGradToMeasured(R, &gqd);
      exid::models::jointGradToMeasured(R, &gqdd);
      grad->q.row(k) += gq.transpose();
      grad->qd.row(k) += gqd.transpose();
      grad->qdd.row(k) += gqdd.transpose();
    }
  }

  // fullDesignVjp of every column but the dK ones (dW: K m x P).
  void designVjpNoGains(const exid::Samples& s, const Friction& f, const Eigen::MatrixXd& dW,
                        exid::Samples* grad) const {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
    const int P0 = exid::numParameters(R, cols_), P = P0 + extraPerJoint() * n;
    exid::models::zeroGrad(s, grad);
    Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, P0);
    Eigen::VectorXd gq, gqd, gqdd;
    const Workspace data(*this);
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
    const double sg = eps > 0 ? std::tanh(v / eps) : signum(v);
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
    if (load_)
      j["coulomb_load"] =
          "FcL_j |tau_m,j| sign(qdm_j): the recorded torque in rows, the nominal robot's in a "
          "design";
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
    if (gains_) {
      exid::Json g = exid::Json::object();
      g["equation"] =
          "(1 + dK_j) tau_m,j = Y_j pi + [T^T Yp phi]_j (the payload part only): rows tau_m,j - "
          "[T^T Yp phi]_j = Y_j pi - dK_j tau_m,j";
      g["payload_phi"] = exid::Json(std::vector<double>(phi_.data(), phi_.data() + 10));
      g["scale"] = gains_prior_ ? "prior: no payload part; the gains' common scale comes from "
                                  "the estimator's gain prior (gains_ls gain_prior_std)"
                                : "payload: the known payload in the recording's payload part";
      g["design"] = gains_prior_
                        ? "dK columns: minus the nominal torque, a structural 1 kg payload on "
                          "every other sample (the base parameters only)"
                        : "dK columns: minus the nominal torque, the payload on every other sample";
      j["drive_gains"] = g;
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
  // The dynamics algorithms' workspaces, reused from call to call (a simulation asks for the
  // design of one state thousands of times; a workspace costs more to make than to use). A call
  // on any thread takes one for its duration.
  class Workspace {
   public:
    explicit Workspace(const DifferentialModel& m) : m_(m), r_(&m.robot()), d_(m.takeData()) {}
    ~Workspace() { m_.giveData(std::move(d_), r_); }
    Workspace(const Workspace&) = delete;
    Workspace& operator=(const Workspace&) = delete;
    exid::DynamicsData& operator*() const { return *d_; }

   private:
    const DifferentialModel& m_;
    const exid::RobotModel* r_;  // the robot it was made for
    exid::DynamicsDataPtr d_;
  };
  exid::DynamicsDataPtr takeData() const {
    {
      std::lock_guard<std::mutex> lock(pool_mutex_);
      if (pool_robot_.get() == &robot() && !pool_.empty()) {
        exid::DynamicsDataPtr d = std::move(pool_.back());
        pool_.pop_back();
        return d;
      }
    }
    return exid::makeDynamicsData(robot());
  }
  void giveData(exid::DynamicsDataPtr d, const exid::RobotModel* made_for) const {
    if (made_for != &robot()) return;  // (bound to another robot during the call: dropped)
    std::lock_guard<std::mutex> lock(pool_mutex_);
    if (pool_robot_.get() != &robot()) {  // (bound to another robot since: of no use)
      pool_.clear();
      pool_robot_ = robotPtr();  // (held: no other robot can take its address while pooled)
    }
    if (pool_.size() < 64) pool_.push_back(std::move(d));
  }
  mutable std::mutex pool_mutex_;
  mutable std::vector<exid::DynamicsDataPtr> pool_;
  mutable std::shared_ptr<const exid::RobotModel> pool_robot_;

  double frictionTorque(int j, double qdm) const {
    const exid::Drive D = drive(j);
    const double sg = exid::coulombSign(qdm);
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
    if (v.size() != 1 && static_cast<int>(v.size()) != robot().dof())  // (a hot path)
      throw exid::Error(
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
  bool asym_ = false, stribeck_ = false, coulomb_extra_ = false, gains_ = false;
  bool gains_prior_ = false;  // drive_gains_scale: prior
  Eigen::Matrix<double, 10, 1> phi_ = Eigen::Matrix<double, 10, 1>::Zero();  // drive_gains' payload
  Eigen::Matrix<double, 10, 1> design_phi_ = Eigen::Matrix<double, 10, 1>::Zero();  // the design's
  int gainCount() const { return gains_ ? robot().dof() : 0; }
  bool load_ = false;  // coulomb_load
  int loadCount() const { return load_ ? robot().dof() : 0; }
  std::vector<double> eps_param_, vs_param_;
  double delta_ = 2.0;
};

}  // namespace

EXID_REGISTER_PLUGIN(DifferentialModel)
