// exid — observation model `floating_base`: the rows of a floating-base robot
// (exid/floating_base.hpp; docs/models.md, "floating_base"). Per sample, with the base motion
// b = (omega, alpha, f) of Dataset::base and the contact wrenches w_c of Dataset::contact:
//   base rows (6)   Y_base(q, qd, qdd, b) pi_f = sum_c X*_c w_c          (rows: all | base)
//   joint rows (n)  Y_joint(q, qd, qdd, b) pi_f = tau + sum_c J_c^T w_c  (rows: all | joints)
// pi_f = [XX0 .. M0 (the base link); XX1 .. M1; ...]. The base rows need no joint torque
// (torque-free identification, Ayusawa, Venture and Nakamura 2014).
// Joint friction and drive columns (the `differential` model's options, names and columns, all
// off by default), on the joint rows only, after pi_f: per joint Ia, Fc, Fv, OFF
// (exid::driveColumnValues), then with coulomb_smoothing_rad_s, coulomb_asymmetric or stribeck the
// nonlinear friction columns of exid::FrictionColumns (Fc shaped by tanh(qd / eps), or FcP and
// FcN; Fs s exp(-(|qd| / vs)^delta); eps and vs nonlinear parameters, fitted by `varpro`), per
// joint in that order, then with coulomb_load FcL |tau| sign(qd)
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
        exid::param_bool("coulomb_asymmetric", false,
                         "separate Coulomb levels for qd > 0 and qd < 0 (columns (1 + s)/2 and "
                         "-(1 - s)/2: FcP_j, FcN_j; needs coulomb)"),
        exid::param_bool("stribeck", false,
                         "a Stribeck term Fs_j s exp(-(|qd_j| / vs_j)^stribeck_exponent) per joint "
                         "(needs stribeck_velocity_rad_s)"),
        exid::param_doubles("stribeck_velocity_rad_s", std::vector<double>{}, "rad/s",
                            "the Stribeck velocity vs per joint (one value: every joint): the "
                            "value rows use and varpro starts from; nonlinear parameters vs_j"),
        exid::param_double("stribeck_exponent", 2.0, "", "the Stribeck exponent delta", 0.5, 4.0),
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
    vs_ = p.getDoubles("stribeck_velocity_rad_s");
    const bool asym = p.getBool("coulomb_asymmetric");
    fc_.asymmetric = asym;
    fc_.stribeck = p.getBool("stribeck");
    fc_.delta = p.getDouble("stribeck_exponent");
    const std::string who = context_.empty() ? "model 'floating_base'" : context_;
    exid::check((eps_.empty() && !asym) || cols_.coulomb,
                who +
                    ": coulomb_smoothing_rad_s and coulomb_asymmetric shape the Coulomb columns: "
                    "they need coulomb: true");
    exid::check(!fc_.stribeck || !vs_.empty(),
                who +
                    ": stribeck: true needs stribeck_velocity_rad_s (the Stribeck velocity of "
                    "each joint, or one for all: the value rows use and varpro starts from; exid "
                    "does not guess it)");
    exid::check(fc_.stribeck || vs_.empty(),
                who + ": stribeck_velocity_rad_s is given but stribeck is false");
    exid::check(fc_.stribeck || fc_.delta == 2.0,
                who + ": stribeck_exponent is given but stribeck is false");
    for (double v : eps_)
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("{}: coulomb_smoothing_rad_s: {} is not a positive width (leave "
                              "the list empty for sign(qd))",
                              who, v));
    for (double v : vs_)
      exid::check(
          v > 0 && std::isfinite(v),
          fmt::format("{}: stribeck_velocity_rad_s: {} is not a positive velocity", who, v));
    exid::check(!load_ || eps_.empty(),
                who +
                    ": coulomb_load multiplies sign(qd): it is not combined with "
                    "coulomb_smoothing_rad_s");
    exid::check((!hasFriction()) || rows_ != "base",
                who +
                    ": rows: base has no joint rows: the joint friction and drive columns "
                    "(rotor_inertia, coulomb, viscous, offset, coulomb_asymmetric, stribeck, "
                    "coulomb_load) need rows all or joints");
    fc_.coulomb = cols_.coulomb && (asym || !eps_.empty());
    if (fc_.coulomb) cols_.coulomb = false;  // the Coulomb columns are the shaped ones
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
    for (int j = 0; j < (fc_.perJoint() > 0 ? R.dof() : 0); ++j) {
      const std::vector<std::string> f = fc_.names(j);
      names.insert(names.end(), f.begin(), f.end());
    }
    for (int j = 0; j < (load_ ? R.dof() : 0); ++j) names.push_back("FcL" + std::to_string(j + 1));
    return names;
  }
  Eigen::VectorXd fullNominal() const override {
    const exid::RobotModel& R = robot();
    const int n = R.dof(), P0 = 10 * (n + 1), Pd = cols_.count() * n;
    Eigen::VectorXd out = Eigen::VectorXd::Zero(P0 + Pd + extraCount() + loadCount());  // FcL: 0
    out.head(P0) = exid::floatingParameters(R);
    out.segment(P0, Pd) = exid::parameterValues(R, cols_).tail(Pd);
    const int E = fc_.perJoint();
    for (int j = 0; j < n && E > 0; ++j) {
      int c = P0 + Pd + E * j;
      if (fc_.coulomb) out[c++] = drive(j).coulomb;  // (symmetric nominal: FcP = FcN = Fc)
      if (fc_.coulomb && fc_.asymmetric) out[c++] = drive(j).coulomb;
      if (fc_.stribeck) out[c] = 0.0;  // no Stribeck term in the robot description
    }
    return out;
  }

  // The `simulate` experiment's plant (Dataset::facts.simulated): its drive terms (none with
  // drive_terms: false), its friction beyond Coulomb + viscous (coulomb_negative_Nm,
  // stribeck_Nm) and its load-dependent Coulomb friction (coulomb_load_Nm_per_Nm). What the model
  // has no column for is left out.
  Eigen::VectorXd fullTruth(const exid::PlantTruth& plant) const override {
    Eigen::VectorXd out = fullNominal();
    const int n = robot().dof(), P0 = 10 * (n + 1), Pd = cols_.count() * n, E = fc_.perJoint();
    if (!plant.drive_terms) out.segment(P0, Pd + extraCount()).setZero();
    // one value (every joint) or one per joint; else none
    auto perJoint = [&](const std::vector<double>& v, int j, double* x) {
      if (!(v.size() == 1 || static_cast<int>(v.size()) == n)) return false;
      *x = v[v.size() == 1 ? 0 : static_cast<std::size_t>(j)];
      return true;
    };
    double x = 0.0;
    for (int j = 0; j < n; ++j) {
      const int c = P0 + Pd + E * j;
      if (fc_.coulomb && fc_.asymmetric && perJoint(plant.coulomb_negative_Nm, j, &x))
        out[c + 1] = x;
      if (fc_.stribeck && perJoint(plant.stribeck_Nm, j, &x)) out[c + fc_.coulombCount()] = x;
      if (load_ && perJoint(plant.coulomb_load_Nm_per_Nm, j, &x))
        out[P0 + Pd + extraCount() + j] = x;
    }
    return out;
  }

  // Per joint (ascending) its width eps_j (moving every nonlinear friction column of the joint)
  // then its Stribeck velocity vs_j (the Fs column).
  std::vector<exid::NonlinearParameter> nonlinearParameters() const override {
    std::vector<exid::NonlinearParameter> out;
    const exid::RobotModel& R = robot();
    const int n = R.dof(), c0 = 10 * (n + 1) + cols_.count() * n, E = fc_.perJoint();
    for (const Slot& sl : slots()) {
      const int j = sl.joint;
      const char* unit = R.bodies[static_cast<std::size_t>(j)].type == exid::JointType::Prismatic
                             ? "m/s"
                             : "rad/s";
      if (sl.eps) {
        exid::NonlinearParameter e{
            "eps" + std::to_string(j + 1), unit, listValue(eps_, "coulomb_smoothing_rad_s", j), {}};
        for (int c = 0; c < E; ++c) e.columns.push_back(c0 + E * j + c);
        out.push_back(e);
      } else {
        out.push_back({"vs" + std::to_string(j + 1),
                       unit,
                       listValue(vs_, "stribeck_velocity_rad_s", j),
                       {c0 + E * j + fc_.coulombCount()}});
      }
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

  // The full design at the nonlinear parameters eta (nonlinearParameters() order); dW
  // (optional): the derivatives of the columns each moves, in that order (a width: every
  // nonlinear friction column of its joint; a Stribeck velocity: the Fs column). The FcL columns
  // of a design: |the nominal robot's joint torque (no contact)| sign(qd); rows put the
  // recorded one.
  Eigen::MatrixXd designAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                           Eigen::MatrixXd* dW) const {
    const exid::RobotModel& R = robot();
    const int K = s.size(), n = R.dof();
    exid::models::requireSamples(s, n, true, "model 'floating_base'");
    exid::check(s.base.rows() == K && s.base.cols() == 9,
                fmt::format("model 'floating_base': the samples have no base motion (9 columns: "
                            "omega, alpha, f in the base frame; found {} x {})",
                            s.base.rows(), s.base.cols()));
    const std::vector<Slot> sl = slots();
    exid::check(eta.size() == static_cast<Eigen::Index>(sl.size()),
                fmt::format("model 'floating_base': {} nonlinear parameter values given, "
                            "expected {}",
                            eta.size(), sl.size()));
    // each joint's width and Stribeck velocity, and where their derivative columns start
    const int E = fc_.perJoint();
    std::vector<double> eps(static_cast<std::size_t>(n), 0.0), vs(static_cast<std::size_t>(n), 1.0);
    std::vector<int> deps(static_cast<std::size_t>(n), -1), dvs(static_cast<std::size_t>(n), -1);
    int Ld = 0;
    for (std::size_t k = 0; k < sl.size(); ++k) {
      const double v = eta[static_cast<Eigen::Index>(k)];
      const auto j = static_cast<std::size_t>(sl[k].joint);
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("model 'floating_base': {}{} = {} (must be positive)",
                              sl[k].eps ? "eps" : "vs", j + 1, v));
      (sl[k].eps ? eps : vs)[j] = v;
      (sl[k].eps ? deps : dvs)[j] = Ld;
      Ld += sl[k].eps ? E : 1;  // (a width moves every column of its joint; vs the Fs column)
    }
    const int L = extraCount();
    const int m = rowsPerSample(), first = rows_ == "joints" ? 6 : 0;
    const int P0 = 10 * (n + 1), nd = cols_.count(), Pd = nd * n, Pl = P0 + Pd + L;
    const int P = Pl + loadCount();
    Eigen::MatrixXd W(m * K, P), Y;
    if (P > P0) W.rightCols(P - P0).setZero();
    if (dW) dW->setZero(m * K, Ld);
    double w[3], dw_eps[3], dw_vs = 0.0;
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
        if (E > 0) {
          const auto u = static_cast<std::size_t>(j);
          fc_.values(v, eps[u], vs[u], w, dw_eps, &dw_vs);
          for (int e = 0; e < E; ++e) W(row, P0 + Pd + E * j + e) = w[e];
          if (dW && deps[u] >= 0)
            for (int e = 0; e < E; ++e) (*dW)(row, deps[u] + e) = dw_eps[e];
          if (dW && dvs[u] >= 0) (*dW)(row, dvs[u]) = dw_vs;
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
      f["coulomb"] = cols_.coulomb || fc_.coulomb;
      f["coulomb_asymmetric"] = fc_.asymmetric;
      f["viscous"] = cols_.viscous;
      f["offset"] = cols_.offset;
      f["sign"] = eps_.empty() ? "sign(qd)" : "tanh(qd / eps_j)";
      if (fc_.stribeck) {
        f["stribeck"] = "Fs_j s exp(-(|qd_j| / vs_j)^delta)";
        f["stribeck_exponent"] = fc_.delta;
      }
      if (load_)
        f["coulomb_load"] =
            "FcL_j |tau_j| sign(qd_j): the recorded torque in rows, the nominal robot's (no "
            "contact) in a design";
      if (!nonlinearParameters().empty()) {
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
    studyEta();       // one width (Stribeck velocity), or one per joint
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

  // The nonlinear parameters in order: per joint (ascending), its width then its Stribeck
  // velocity.
  struct Slot {
    bool eps = false;
    int joint = 0;
  };
  std::vector<Slot> slots() const {
    std::vector<Slot> out;
    for (int j = 0; j < robot().dof() && fc_.perJoint() > 0; ++j) {
      if (!eps_.empty()) out.push_back({true, j});
      if (fc_.stribeck) out.push_back({false, j});
    }
    return out;
  }
  bool hasFriction() const { return cols_.count() > 0 || fc_.perJoint() > 0 || load_; }
  int extraCount() const { return fc_.perJoint() * robot().dof(); }
  int loadCount() const { return load_ ? robot().dof() : 0; }
  exid::Drive drive(int j) const {
    const auto& dr = robot().drives;
    return j < static_cast<int>(dr.size()) ? dr[static_cast<std::size_t>(j)] : exid::Drive{};
  }
  // a per-joint list's value (coulomb_smoothing_rad_s, stribeck_velocity_rad_s)
  double listValue(const std::vector<double>& v, const char* key, int j) const {
    exid::check(v.size() == 1 || static_cast<int>(v.size()) == robot().dof(),
                fmt::format("model 'floating_base': {}: {} values given for robot '{}' of {} "
                            "joints (expected one, or one per joint)",
                            key, v.size(), robot().name, robot().dof()));
    return v.size() == 1 ? v[0] : v[static_cast<std::size_t>(j)];
  }
  Eigen::VectorXd studyEta() const {
    const std::vector<exid::NonlinearParameter> nl = nonlinearParameters();
    Eigen::VectorXd eta(static_cast<Eigen::Index>(nl.size()));
    for (std::size_t k = 0; k < nl.size(); ++k) eta[static_cast<Eigen::Index>(k)] = nl[k].value;
    return eta;
  }

  std::string rows_;
  exid::DriveColumns cols_;
  std::vector<double> eps_, vs_;
  exid::FrictionColumns fc_;  // the nonlinear friction columns (coulomb: shaped Coulomb columns)
  bool load_ = false;
  std::vector<std::string> contact_links_;
  std::vector<double> contact_pose_values_;
  std::string context_;
};

}  // namespace

EXID_REGISTER_PLUGIN(FloatingBaseModel)
