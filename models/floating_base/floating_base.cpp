// exid — observation model `floating_base`: the rows of a floating-base robot
// (exid/floating_base.hpp; docs/models.md, "floating_base"). Per sample, with the base motion
// b = (omega, alpha, f) of Dataset::base and the contact wrenches w_c of Dataset::contact:
//   base rows (6)   Y_base(q, qd, qdd, b) pi_f = sum_c X*_c w_c          (rows: all | base)
//   joint rows (n)  Y_joint(q, qd, qdd, b) pi_f = tau + sum_c J_c^T w_c  (rows: all | joints)
// pi_f = [XX0 .. M0 (the base link); XX1 .. M1; ...]. The base rows need no joint torque
// (torque-free identification, Ayusawa, Venture and Nakamura 2014).
// Joint friction and drive columns (the `differential` model's options, names and columns, all
// off by default), on the joint rows only, after pi_f: per joint Ia, Fc, Fv, OFF
// (exid::driveColumnValues), then with coulomb_smoothing_rad_s the Coulomb column tanh(qd / eps)
// (eps: a nonlinear parameter, fitted by `varpro`), then with coulomb_load FcL |tau| sign(qd)
// (the recorded torque in rows, Rows::torque; the torque column of `gains_ls`). A joint's
// friction torque acts between its two bodies, equal and opposite: it cancels in the whole
// robot's momentum balance, so the base rows have zeros there.
#include "exid/floating_base.hpp"

#include <fmt/format.h>

#include <Eigen/Core>
#include <random>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"

namespace {

using exid::models::requireSignal;

class FloatingBaseModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "floating_base";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "floating-base robot: the base link's six Newton-Euler rows balanced by the measured "
      "contact wrenches and/or the joint rows (torques plus J^T w); needs q, qd, qdd, the base "
      "motion (omega, alpha, f) and the contact wrenches, and tau for the joint rows";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_string("rows", std::string("all"),
                           "which rows: all (base and joints), base (the base link's six rows "
                           "alone: no joint torque needed) or joints",
                           {"all", "base", "joints"}),
        exid::param_strings("contact_links", std::vector<std::string>{},
                            "the links carrying the contact (F/T) sensors, one per contact, in "
                            "the order of the dataset's contact columns (the base link or a "
                            "body's link)"),
        exid::param_doubles("contact_poses", std::vector<double>{}, "m, rad",
                            "sensor frame of each contact in its link's frame: x y z roll pitch "
                            "yaw, six numbers per contact (empty: identity poses)"),
        // the `differential` model's drive columns (its names and meanings; here off by
        // default: a floating robot's joint rows are rigid-body rows unless asked)
        exid::param_bool("rotor_inertia", false,
                         "identify the rotor inertia Ia_j (column qdd_j) of every joint (joint "
                         "rows)"),
        exid::param_bool("coulomb", false,
                         "identify Coulomb friction Fc_j (column sign(qd_j)) of every joint"),
        exid::param_bool("viscous", false,
                         "identify viscous friction Fv_j (column qd_j) of every joint"),
        exid::param_bool("offset", false, "identify a torque offset OFF_j (column 1) per joint"),
        exid::param_doubles("coulomb_smoothing_rad_s", std::vector<double>{}, "rad/s",
                            "smooth sign s = tanh(qd / eps) instead of sign(qd) in the Coulomb "
                            "columns: eps per joint (one value: every joint); nonlinear "
                            "parameters eps_j, fitted by `varpro`; empty: sign (needs coulomb)",
                            0),
        exid::param_bool("coulomb_load", false,
                         "a load-dependent Coulomb term FcL_j |tau_j| sign(qd_j) per joint (FcL "
                         "dimensionless: Coulomb torque per N m carried; the recorded torque in "
                         "the column: fitted by `gains_ls`)"),
    };
  }

  explicit FloatingBaseModel(const exid::ParamSet& p)
      : rows_(p.getString("rows")),
        contact_links_(p.getStrings("contact_links")),
        contact_pose_values_(p.getDoubles("contact_poses")),
        context_(p.context) {
    cols_.rotor_inertia = p.getBool("rotor_inertia");
    cols_.coulomb = p.getBool("coulomb");
    cols_.viscous = p.getBool("viscous");
    cols_.offset = p.getBool("offset");
    eps_ = p.getDoubles("coulomb_smoothing_rad_s");
    load_ = p.getBool("coulomb_load");
    const std::string who = context_.empty() ? "model 'floating_base'" : context_;
    exid::check(eps_.empty() || cols_.coulomb,
                who +
                    ": coulomb_smoothing_rad_s shapes the Coulomb columns: it needs coulomb: "
                    "true");
    for (double v : eps_)
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("{}: coulomb_smoothing_rad_s: {} is not a positive width (leave "
                              "the list empty for sign(qd))",
                              who, v));
    exid::check(!load_ || eps_.empty(),
                who +
                    ": coulomb_load multiplies sign(qd): it is not combined with "
                    "coulomb_smoothing_rad_s");
    exid::check((!hasFriction()) || rows_ != "base",
                who +
                    ": rows: base has no joint rows: the joint friction and drive columns "
                    "(rotor_inertia, coulomb, viscous, offset, coulomb_load) need rows all or "
                    "joints");
    smooth_ = !eps_.empty();
    if (smooth_) cols_.coulomb = false;  // the Coulomb columns are the smoothed ones
    exid::check(
        contact_pose_values_.empty() || contact_pose_values_.size() == 6 * contact_links_.size(),
        fmt::format("{}: contact_poses: {} numbers for {} contact link(s) (expected six "
                    "per contact: x y z roll pitch yaw, or none)",
                    context_.empty() ? "model 'floating_base'" : context_,
                    contact_pose_values_.size(), contact_links_.size()));
  }

  std::vector<std::string> fullNames() const override {
    const exid::RobotModel& R = robot();
    std::vector<std::string> names = exid::floatingParameterNames(R);
    // the drive columns' names as the differential model writes them (Ia1, Fc1, Fv1, OFF1, ...)
    const std::vector<std::string> drive = exid::parameterNames(R, cols_);
    names.insert(names.end(), drive.begin() + R.numInertialParameters(), drive.end());
    for (int j = 0; j < (smooth_ ? R.dof() : 0); ++j) names.push_back("Fc" + std::to_string(j + 1));
    for (int j = 0; j < (load_ ? R.dof() : 0); ++j) names.push_back("FcL" + std::to_string(j + 1));
    return names;
  }
  Eigen::VectorXd fullNominal() const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), P0 = 10 * (n + 1), Pd = cols_.count() * n;
    Eigen::VectorXd out = Eigen::VectorXd::Zero(P0 + Pd + extraCount() + loadCount());  // FcL: 0
    out.head(P0) = exid::floatingParameters(R);
    out.segment(P0, Pd) = exid::parameterValues(R, cols_).tail(Pd);
    for (int j = 0; j < extraCount(); ++j) out[P0 + Pd + j] = drive(j).coulomb;
    return out;
  }

  // The `simulate` experiment's plant (Dataset::facts.simulated): its drive terms (none with
  // drive_terms: false) and its load-dependent Coulomb friction (coulomb_load_Nm_per_Nm).
  Eigen::VectorXd fullTruth(const exid::PlantTruth& plant) const override {
    Eigen::VectorXd out = fullNominal();
    const int n = robot().dof(), P0 = 10 * (n + 1), Pd = cols_.count() * n;
    if (!plant.drive_terms) out.segment(P0, Pd + extraCount()).setZero();
    const std::vector<double>& fcl = plant.coulomb_load_Nm_per_Nm;
    if (load_ && (fcl.size() == 1 || static_cast<int>(fcl.size()) == n))
      for (int j = 0; j < n; ++j)
        out[P0 + Pd + extraCount() + j] = fcl[fcl.size() == 1 ? 0 : static_cast<std::size_t>(j)];
    return out;
  }

  std::vector<exid::NonlinearParameter> nonlinearParameters() const override {
    std::vector<exid::NonlinearParameter> out;
    const exid::RobotModel& R = robot();
    const int n = R.dof(), c0 = 10 * (n + 1) + cols_.count() * n;
    for (int j = 0; j < extraCount(); ++j) {
      const char* unit = R.bodies[static_cast<std::size_t>(j)].type == exid::JointType::Prismatic
                             ? "m/s"
                             : "rad/s";
      out.push_back({"eps" + std::to_string(j + 1), unit, epsOf(j), {c0 + j}});
    }
    return out;
  }

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;
    sp.required_signals = {"q", "qd", "qdd"};
    if (rows_ != "base") sp.required_signals.push_back("tau");
    sp.floating_base = true;
    return sp;
  }

  exid::Samples randomSamples(int count, std::uint64_t seed) const override {
    exid::Samples s = ObservationModel::randomSamples(count, seed);
    std::mt19937_64 rng(seed ^ 0xb5ad4eceda1ce2a9ull);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    s.base.resize(count, 9);
    for (int k = 0; k < count; ++k)
      for (int c = 0; c < 9; ++c) s.base(k, c) = (c < 3 ? 2.0 : c < 6 ? 6.0 : 15.0) * u(rng);
    return s;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext& ctx) const override {
    return fullRowsAt(d, studyEta(), nullptr, ctx);
  }

  exid::Rows fullRowsAt(const exid::Dataset& d, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW,
                        const exid::RunContext&) const override {
    const int n = robot().dof();
    const std::string who = "model 'floating_base'";
    requireSignal(d, d.q, "q", n, who);
    requireSignal(d, d.qd, "qd", n, who);
    requireSignal(d, d.qdd, "qdd", n, who);
    const int K = d.size();
    if (rows_ != "base") requireSignal(d, d.tau, "tau", n, who);
    exid::check(d.base.rows() == K && d.base.cols() == 9,
                fmt::format("{}: the dataset ({}) has no base motion (9 columns: omega, alpha, f "
                            "in the base frame; found {} x {})",
                            who, d.source, d.base.rows(), d.base.cols()));
    const int C = static_cast<int>(contact_links_.size());
    exid::check(
        (C == 0 && d.contact.size() == 0) || (d.contact.rows() == K && d.contact.cols() == 6 * C),
        fmt::format("{}: the dataset ({}) has {} contact column(s); the model declares {} "
                    "contact(s) (contact_links), six columns each",
                    who, d.source, d.contact.cols(), C));
    exid::check(C > 0 || rows_ == "joints",
                fmt::format("{}: no contact declared (contact_links): the base rows equal the "
                            "contact wrenches, so rows '{}' needs at least one (rows: joints "
                            "for a robot with no contact)",
                            who, rows_));
    exid::Rows r;
    r.W = designAt(d.samples(), eta, dW);
    const int m = rowsPerSample();
    r.y.resize(m * K);
    if (load_) r.torque.assign(static_cast<std::size_t>(m * K), 0.0);
    r.equation.resize(static_cast<std::size_t>(m * K));
    r.t.resize(static_cast<std::size_t>(m * K));
    const std::vector<int> bodies = contactBodies();
    Eigen::VectorXd rhs(6 + n);
    for (int k = 0; k < K; ++k) {
      rhs.setZero();
      if (rows_ != "base") rhs.tail(n) = d.tau.row(k).transpose();
      const Eigen::VectorXd q = d.q.row(k).transpose();
      for (int c = 0; c < C; ++c) {
        const Eigen::MatrixXd Cm =
            exid::contactMap(robot(), q, bodies[static_cast<size_t>(c)], contactPose(c));
        rhs += Cm * d.contact.block(k, 6 * c, 1, 6).transpose();
      }
      const int first = rows_ == "joints" ? 6 : 0;
      for (int e = 0; e < m; ++e) {
        r.y[m * k + e] = rhs[first + e];
        r.equation[static_cast<std::size_t>(m * k + e)] = e;
        r.t[static_cast<std::size_t>(m * k + e)] = d.t[k];
      }
      if (load_) {  // the recorded torque in the FcL columns (rows_ != base)
        const int j0 = rows_ == "joints" ? 0 : 6, Pl = static_cast<int>(r.W.cols()) - n;
        for (int j = 0; j < n; ++j) {
          const Eigen::Index row = static_cast<Eigen::Index>(m) * k + j0 + j;
          r.W(row, Pl + j) = exid::loadCoulombColumn(d.tau(k, j), d.qd(k, j));
          r.torque[static_cast<std::size_t>(row)] = d.tau(k, j);
        }
      }
    }
    r.numEquations = m;
    r.equation_names = equationNames();
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    return designAt(s, studyEta(), nullptr);
  }
  Eigen::MatrixXd fullDesignAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                               Eigen::MatrixXd* dW) const override {
    return designAt(s, eta, dW);
  }

  // The full design at the widths eta (nonlinearParameters() order); dW (optional): the
  // derivatives of the smoothed Coulomb columns, one column per width. The FcL columns of a
  // design: |the nominal robot's joint torque (no contact)| sign(qd); rows put the recorded one.
  Eigen::MatrixXd designAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                           Eigen::MatrixXd* dW) const {
    const exid::RobotModel& R = robot();
    const int K = s.size(), n = R.dof();
    exid::models::requireSamples(s, n, true, "model 'floating_base'");
    exid::check(s.base.rows() == K && s.base.cols() == 9,
                fmt::format("model 'floating_base': the samples have no base motion (9 columns: "
                            "omega, alpha, f in the base frame; found {} x {})",
                            s.base.rows(), s.base.cols()));
    const int L = extraCount();
    exid::check(eta.size() == L,
                fmt::format("model 'floating_base': {} nonlinear parameter values given, "
                            "expected {}",
                            eta.size(), L));
    for (int j = 0; j < L; ++j)
      exid::check(
          eta[j] > 0 && std::isfinite(eta[j]),
          fmt::format("model 'floating_base': eps{} = {} (must be positive)", j + 1, eta[j]));
    const int m = rowsPerSample(), first = rows_ == "joints" ? 6 : 0;
    const int P0 = 10 * (n + 1), nd = cols_.count(), Pd = nd * n, Pl = P0 + Pd + L;
    const int P = Pl + loadCount();
    Eigen::MatrixXd W(m * K, P), Y;
    if (P > P0) W.rightCols(P - P0).setZero();
    if (dW) dW->setZero(m * K, L);
    const Eigen::VectorXd nominal = load_ ? fullNominal().head(Pl) : Eigen::VectorXd();
    for (int k = 0; k < K; ++k) {
      const exid::BaseMotion b = s.base.row(k).transpose();
      exid::floatingRegressor(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                              s.qdd.row(k).transpose(), b, Y);
      W.middleRows(m * k, m).leftCols(P0) = Y.middleRows(first, m);
      if (P == P0) continue;
      // the joint rows' drive and friction columns (the base rows: zero)
      for (int j = 0; j < n; ++j) {
        const Eigen::Index row = static_cast<Eigen::Index>(m) * k + (6 - first) + j;
        const double v = s.qd(k, j);
        const exid::DriveColumnValues dv = exid::driveColumnValues(cols_, v, s.qdd(k, j));
        for (int e = 0; e < dv.count; ++e) W(row, P0 + nd * j + e) = dv.v[e];
        if (L > 0) {
          double ds = 0.0;
          W(row, P0 + Pd + j) = exid::smoothCoulombSign(v, eta[j], &ds);
          if (dW) (*dW)(row, j) = ds;
        }
        if (load_) W(row, Pl + j) = exid::loadCoulombColumn(W.row(row).head(Pl).dot(nominal), v);
      }
    }
    return W;
  }

  void fullDesignVjp(const exid::Samples&, const Eigen::MatrixXd&, exid::Samples*) const override {
    throw exid::Error(
        "model 'floating_base': excitation design is not available for a floating-base robot "
        "(the regressor's vector-Jacobian product is not written; use a given trajectory)");
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] =
        "base rows: Y_base pi_f = sum_c X*_c w_c; joint rows: Y_joint pi_f = tau + sum_c "
        "J_c^T w_c";
    j["rows"] = rows_;
    j["base_motion"] =
        "omega [rad/s], alpha [rad/s^2], f = a - g [m/s^2] of the base origin, base frame";
    j["contact_wrench"] =
        "fx fy fz mx my mz exerted by the environment on the robot, sensor frame, moment about "
        "the sensor origin";
    j["contact_links"] = exid::Json(contact_links_);
    j["parameters"] = "XX0 .. M0 the base link's, then each body's (exid/floating_base.hpp)";
    if (hasFriction()) {
      exid::Json f = exid::Json::object();
      f["rows"] = "the joint rows only (a joint's friction cancels in the base rows)";
      f["rotor_inertia"] = cols_.rotor_inertia;
      f["coulomb"] = cols_.coulomb || smooth_;
      f["viscous"] = cols_.viscous;
      f["offset"] = cols_.offset;
      f["sign"] = smooth_ ? "tanh(qd / eps_j)" : "sign(qd)";
      if (load_)
        f["coulomb_load"] =
            "FcL_j |tau_j| sign(qd_j): the recorded torque in rows, the nominal robot's (no "
            "contact) in a design";
      if (smooth_) {
        f["nonlinear_parameters"] = exid::models::nonlinearParametersJson(nonlinearParameters());
      }
      j["joint_friction"] = f;
    }
    return j;
  }

 protected:
  void onBind(const exid::RunContext&) override {
    const exid::RobotModel& R = robot();
    exid::requireFloatingBase(R, "the observation model 'floating_base'");
    exid::check(!R.hasTransmission(),
                fmt::format("model 'floating_base': robot '{}' has a transmission matrix (not "
                            "modelled for a floating base: give joint coordinates)",
                            R.name));
    contactBodies();  // the links exist
    studyEta();       // one width, or one per joint
  }

 private:
  int rowsPerSample() const {
    const int n = robot().dof();
    return rows_ == "all" ? 6 + n : rows_ == "base" ? 6 : n;
  }
  std::vector<int> contactBodies() const {
    std::vector<int> out;
    for (const auto& l : contact_links_)
      out.push_back(exid::floatingBodyIndex(robot(), l, "model 'floating_base': contact_links"));
    return out;
  }
  exid::Pose contactPose(int c) const {
    if (contact_pose_values_.empty()) return exid::Pose{};
    return exid::poseFromXyzRpy(&contact_pose_values_[static_cast<size_t>(6 * c)]);
  }
  std::vector<std::string> equationNames() const {
    std::vector<std::string> names;
    if (rows_ != "joints")
      for (const char* e : {"base fx [N]", "base fy [N]", "base fz [N]", "base mx [N m]",
                            "base my [N m]", "base mz [N m]"})
        names.push_back(e);
    if (rows_ != "base")
      for (int j = 0; j < robot().dof(); ++j)
        names.push_back(fmt::format("tau joint {} ({})", j + 1,
                                    robot().bodies[static_cast<size_t>(j)].joint_name));
    return names;
  }

  bool hasFriction() const { return cols_.count() > 0 || !eps_.empty() || load_; }
  int extraCount() const { return smooth_ ? robot().dof() : 0; }
  int loadCount() const { return load_ ? robot().dof() : 0; }
  exid::Drive drive(int j) const {
    const auto& dr = robot().drives;
    return j < static_cast<int>(dr.size()) ? dr[static_cast<std::size_t>(j)] : exid::Drive{};
  }
  double epsOf(int j) const {
    exid::check(eps_.size() == 1 || static_cast<int>(eps_.size()) == robot().dof(),
                fmt::format("model 'floating_base': coulomb_smoothing_rad_s: {} values given for "
                            "robot '{}' of {} joints (expected one, or one per joint)",
                            eps_.size(), robot().name, robot().dof()));
    return eps_.size() == 1 ? eps_[0] : eps_[static_cast<std::size_t>(j)];
  }
  Eigen::VectorXd studyEta() const {
    Eigen::VectorXd eta(extraCount());
    for (int j = 0; j < extraCount(); ++j) eta[j] = epsOf(j);
    return eta;
  }

  std::string rows_;
  exid::DriveColumns cols_;
  std::vector<double> eps_;
  bool smooth_ = false, load_ = false;
  std::vector<std::string> contact_links_;
  std::vector<double> contact_pose_values_;
  std::string context_;
};

}  // namespace

EXID_REGISTER_PLUGIN(FloatingBaseModel)
