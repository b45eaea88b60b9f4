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
// second part carries a known payload phi (facts.payload_part_from_t_s, csv payload_file):
//   tau_m,j - [T^T Yp phi]_j (payload part only) = Y_j pi - dK_j tau_m,j.
// Without the payload part the scale of pi and the gains is not identifiable: refused, unless
// drive_gains_scale: prior says that a prior on the gains (gains_ls's gain_prior_std) sets it.
#include "differential.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/payload.hpp"

namespace exid::differential {

std::vector<exid::ParamDecl> DifferentialModel::params() {
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
      exid::param_bool("coulomb", true,
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
                         "the exponent delta of the Stribeck curve (fixed, not fitted)", 0.5, 4.0),
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

DifferentialModel::DifferentialModel(const exid::ParamSet& p)
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

std::vector<std::string> DifferentialModel::fullNames() const {
  std::vector<std::string> names = exid::parameterNames(robot(), cols_);
  for (int j = 0; j < robot().dof(); ++j) {
    const std::vector<std::string> f = frictionColumns().names(j);
    names.insert(names.end(), f.begin(), f.end());
  }
  for (int j = 0; j < loadCount(); ++j) names.push_back("FcL" + std::to_string(j + 1));
  for (int j = 0; j < gainCount(); ++j) names.push_back("dK" + std::to_string(j + 1));
  return names;
}

Eigen::VectorXd DifferentialModel::fullNominal() const {
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

// The parameters of the `simulate` experiment's plant (Dataset::facts.simulated): its payload
// (merged into the sensor body), its drive terms (none with drive_terms: false), its
// friction beyond Coulomb + viscous (coulomb_negative_Nm, stribeck_Nm,
// coulomb_load_Nm_per_Nm) and its gain errors (recorded_torque_gain: dK = 1/g - 1;
// drive_torque_gain: dK = g - 1). What the model has no column for is left out.
Eigen::VectorXd DifferentialModel::fullTruth(const exid::PlantTruth& plant) const {
  Eigen::VectorXd out = fullNominal();
  const exid::RobotModel& R = robot();
  const int n = R.dof(), P0 = exid::numParameters(R, cols_), E = extraPerJoint();
  if (!plant.payload.empty()) {
    const exid::LoadMass& m = plant.payload;
    const exid::Payload load{m.mass_kg, m.com_m, m.inertia_com_kg_m2};
    out.segment<10>(10 * R.sensorBody()) += exid::transformInertial(load.pi(), R.sensor_pose);
  }
  // one value (every drive) or one per drive
  auto perDrive = [&](const std::vector<double>& j, std::vector<double>* v) {
    if (j.empty()) return false;
    v->assign(static_cast<std::size_t>(n), 0.0);
    for (int d = 0; d < n; ++d)
      (*v)[static_cast<std::size_t>(d)] = j.at(j.size() == 1 ? 0 : static_cast<std::size_t>(d));
    return j.size() == 1 || static_cast<int>(j.size()) == n;
  };
  if (!plant.drive_terms) {
    out.segment(R.numInertialParameters(), P0 - R.numInertialParameters()).setZero();
    out.segment(P0, E * n).setZero();
  }
  std::vector<double> v;
  const int nc = coulomb_extra_ ? (asym_ ? 2 : 1) : 0;
  if (asym_ && coulomb_extra_ && perDrive(plant.coulomb_negative_Nm, &v))
    for (int j = 0; j < n; ++j) out[P0 + E * j + 1] = v[static_cast<std::size_t>(j)];
  if (stribeck_ && perDrive(plant.stribeck_Nm, &v))
    for (int j = 0; j < n; ++j) out[P0 + E * j + nc] = v[static_cast<std::size_t>(j)];
  const int Pl = P0 + E * n, Pg = Pl + loadCount();
  if (load_ && perDrive(plant.coulomb_load_Nm_per_Nm, &v))
    for (int j = 0; j < n; ++j) out[Pl + j] = v[static_cast<std::size_t>(j)];
  if (gains_ && perDrive(plant.recorded_torque_gain, &v))
    for (int j = 0; j < n; ++j) out[Pg + j] = 1.0 / v[static_cast<std::size_t>(j)] - 1.0;
  if (gains_ && perDrive(plant.drive_torque_gain, &v))
    for (int j = 0; j < n; ++j) out[Pg + j] = v[static_cast<std::size_t>(j)] - 1.0;
  return out;
}

std::vector<exid::NonlinearParameter> DifferentialModel::nonlinearParameters() const {
  std::vector<exid::NonlinearParameter> out;
  const int P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
  const int nc = coulomb_extra_ ? (asym_ ? 2 : 1) : 0;
  for (const Slot& sl : slots()) {
    const int j = sl.joint, c0 = P0 + E * j;
    // a velocity of the measured coordinate: m/s for a prismatic joint measured directly
    const auto u = static_cast<std::size_t>(j < robot().dof() ? robot().actuatedJoint(j) : j);
    const char* unit = !robot().hasTransmission() && u < robot().bodies.size() &&
                               robot().bodies[u].type == exid::JointType::Prismatic
                           ? "m/s"
                           : "rad/s";
    if (sl.eps) {
      exid::NonlinearParameter e{"eps" + std::to_string(j + 1), unit, perJoint(eps_param_, j), {}};
      for (int c = 0; c < nc + (stribeck_ ? 1 : 0); ++c) e.columns.push_back(c0 + c);
      out.push_back(e);
    } else {
      out.push_back({"vs" + std::to_string(j + 1), unit, perJoint(vs_param_, j), {c0 + nc}});
    }
  }
  return out;
}

exid::Json DifferentialModel::describe() const {
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
    f["nonlinear_parameters"] = exid::models::nonlinearParametersJson(nonlinearParameters());
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

}  // namespace exid::differential

EXID_REGISTER_PLUGIN(exid::differential::DifferentialModel)
