// exid — the closed loop of a model at estimated parameters (exid/estimators/closed_loop.hpp).
#include "exid/estimators/closed_loop.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/io.hpp"
#include "exid/sampled_reference.hpp"

namespace exid::estimators {

using Eigen::MatrixXd;
using Eigen::VectorXd;

void Reference::eval(double at, VectorXd* qo, VectorXd* qdo, VectorXd* qddo) const {
  quinticHermite(s, std::min(std::max(at, t0()), t1()), qo, qdo, qddo);
}

Reference readReference(const std::filesystem::path& f, const RobotModel& robot,
                        const std::string& who) {
  const int n = robot.dof();
  const CsvTable T = readCsv(f);
  check(T.has("t"), fmt::format("{}: {}: no column 't'", who, f.string()));
  Reference r;
  r.s.t = T.column("t");
  const Eigen::Index K = r.s.t.size();
  check(K >= 2, fmt::format("{}: {}: {} samples (at least 2)", who, f.string(), K));
  MatrixXd q(K, n), qd(K, n), qdd(K, n);
  for (int j = 0; j < n; ++j)
    for (auto [pre, M] : {std::pair<const char*, MatrixXd*>{"q", &q}, {"qd", &qd}, {"qdd", &qdd}}) {
      const std::string c = fmt::format("{}{}", pre, j + 1);
      check(T.has(c), fmt::format("{}: {}: no column '{}' (expected t, q1..q{}, qd1..qd{}, "
                                  "qdd1..qdd{})",
                                  who, f.string(), c, n, n, n));
      M->col(j) = T.column(c);
    }
  for (Eigen::Index k = 1; k < K; ++k)
    check(
        r.s.t[k] > r.s.t[k - 1],
        fmt::format("{}: {}: time not strictly increasing at data row {}", who, f.string(), k + 1));
  r.s.q.resize(K, n);
  r.s.qd.resize(K, n);
  r.s.qdd.resize(K, n);
  for (Eigen::Index k = 0; k < K; ++k) {
    VectorXd a, b, c;
    jointToMeasured(robot, q.row(k).transpose(), qd.row(k).transpose(), qdd.row(k).transpose(), &a,
                    &b, &c);
    r.s.q.row(k) = a.transpose();
    r.s.qd.row(k) = b.transpose();
    r.s.qdd.row(k) = c.transpose();
  }
  return r;
}

std::vector<ParamDecl> ClosedLoop::params() {
  return {
      param_path("reference_file", std::string(),
                 "the commanded trajectory of the recording: a CSV with t, q1..qn, qd1..qdn, "
                 "qdd1..qddn in joint coordinates (as `exid excite --export` writes "
                 "trajectory.csv); required"),
      param_doubles("kp_Nm_per_rad", std::vector<double>{}, "N m/rad",
                    "the controller's position gain per joint (one value: every joint; "
                    "required)"),
      param_doubles("kd_Nm_s_per_rad", std::vector<double>{}, "N m s/rad",
                    "the controller's velocity gain per joint (one value: every joint; "
                    "required)"),
      param_string("feedforward", std::string("nominal"),
                   "nominal: the controller adds the robot description's torque of the "
                   "reference (all drive terms); none: PD alone",
                   {"nominal", "none"}),
      param_double("rtol", 1e-8, "", "the simulation's relative tolerance", 0.0, 1.0, true),
      param_double("atol", 1e-10, "", "the simulation's absolute tolerance", 0.0, 1.0, true),
      param_int("max_steps", 20000, "CVODES steps between two samples at most", 1, 1e9),

  };
}

void ClosedLoop::checkParams(const ParamSet& p, const std::string& who) {
  check(!p.getString("reference_file").empty(),
        who +
            ": reference_file is required (the trajectory the robot was commanded to follow: "
            "the closed loop is simulated from it)");
  check(!p.getDoubles("kp_Nm_per_rad").empty() && !p.getDoubles("kd_Nm_s_per_rad").empty(),
        who +
            ": kp_Nm_per_rad and kd_Nm_s_per_rad are required (the robot's PD gains: the "
            "simulated closed loop must be the robot's; exid does not guess them)");
  // A negative gain pushes the joint away from the reference: the simulated loop diverges and
  // its integration never ends (it ran until killed). Refused before anything is simulated.
  for (const char* key : {"kp_Nm_per_rad", "kd_Nm_s_per_rad"}) {
    const std::vector<double> g = p.getDoubles(key);
    for (std::size_t i = 0; i < g.size(); ++i)
      check(std::isfinite(g[i]) && g[i] >= 0,
            fmt::format("{}: {}[{}] = {}: a PD gain must be a finite number >= 0 (a negative gain "
                        "makes the simulated closed loop unstable)",
                        who, key, i, g[i]));
  }
}

ClosedLoop::ClosedLoop(const ObservationModel& model, const ParamSet& p, const Dataset& data,
                       const RunContext& ctx, const std::string& who)
    : model_(&model), robot_(model.robotPtr()), n_(robot_->dof()), who_(who) {
  // a floating base: the joints' loop on the recorded base motion (a model of its own)
  floating_ = robot_->floating_base && model.specs().floating_base;
  if (!floating_)
    robot_->requireFixedBase(who +
                             " (its closed-loop simulation integrates the fixed-base forward "
                             "dynamics)");
  checkParams(p, who);
  if (floating_) setUpFloating(data);
  const std::string file = p.getString("reference_file");
  const std::vector<double> kp = p.getDoubles("kp_Nm_per_rad"),
                            kd = p.getDoubles("kd_Nm_s_per_rad");
  ff_ = p.getString("feedforward") == "nominal";
  setUpRows(model);
  auto perJoint = [&](const std::vector<double>& v, const char* name) {
    check(v.size() == 1 || static_cast<int>(v.size()) == n_,
          fmt::format("{}: {}: expected 1 or {} values, found {}", who, name, n_, v.size()));
    VectorXd out(n_);
    for (int j = 0; j < n_; ++j) out[j] = v[v.size() == 1 ? 0 : static_cast<std::size_t>(j)];
    return out;
  };
  Kp_ = perJoint(kp, "kp_Nm_per_rad");
  Kd_ = perJoint(kd, "kd_Nm_s_per_rad");
  std::filesystem::path f = file;
  if (f.is_relative() && !ctx.study_dir.empty()) f = ctx.study_dir / f;
  ref_ = readReference(f, *robot_, who);
  file_ = f.string();
  check(data.tFirst() >= ref_.t0() && data.tLast() <= ref_.t1(),
        fmt::format("{}: the recording's times [{}, {}] s are not within the reference's [{}, "
                    "{}] s ({}): the simulation is driven by the reference",
                    who, data.tFirst(), data.tLast(), ref_.t0(), ref_.t1(), file_));
  // the simulation starts at the reference's start: the base motion is read there (at most one
  // sample period before the recording's first sample)
  if (floating_)
    check(data.t[0] <= ref_.t0() + (data.t[1] - data.t[0]),
          fmt::format("{}: the recording starts at t = {} s, more than a sample after the "
                      "reference's start {} s ({}): the simulated loop starts there and needs "
                      "the recorded base motion from then",
                      who, data.t[0], ref_.t0(), file_));
  if (!floating_) dyn_ = makeDynamicsData(*robot_);
  setUpColumns(model, data);
}

void ClosedLoop::setUpFloating(const Dataset& data) {
  const int K = data.size();
  check(data.base.rows() == K && data.base.cols() == 9,
        fmt::format("{}: on a floating base the simulated loop runs on the recorded base motion: "
                    "the recording ({}) has none (expected {} x 9: omega, alpha, f; found {} x {})",
                    who_, data.source, K, data.base.rows(), data.base.cols()));
  check(data.contact.size() == 0 || data.contact.rows() == K,
        fmt::format("{}: the recording's contact wrenches have {} rows for {} samples ({})", who_,
                    data.contact.rows(), K, data.source));
  check(K >= 6, fmt::format("{}: on a floating base the recorded base motion is interpolated "
                            "between six samples: the recording ({}) has {}",
                            who_, data.source, K));
  for (int k = 1; k < K; ++k)
    check(data.t[k] > data.t[k - 1],
          fmt::format("{}: the recording's time is not strictly increasing at sample {} ({})", who_,
                      k, data.source));
  fb_t_ = data.t;
  fb_base_ = data.base;
  fb_contact_ = data.contact;
}

Eigen::RowVectorXd ClosedLoop::recordedAt(const MatrixXd& X, double t) const {
  const Eigen::Index K = fb_t_.size();
  const double* b = fb_t_.data();
  Eigen::Index i = static_cast<Eigen::Index>(std::upper_bound(b, b + K, t) - b) - 1;
  i = std::max<Eigen::Index>(0, std::min<Eigen::Index>(i, K - 2));  // interval [t_i, t_i+1]
  const Eigen::Index s0 = std::max<Eigen::Index>(0, std::min<Eigen::Index>(i - 2, K - 6));
  Eigen::RowVectorXd out = Eigen::RowVectorXd::Zero(X.cols());
  for (Eigen::Index m = 0; m < 6; ++m) {
    double w = 1.0;
    for (Eigen::Index l = 0; l < 6; ++l)
      if (l != m) w *= (t - fb_t_[s0 + l]) / (fb_t_[s0 + m] - fb_t_[s0 + l]);
    out += w * X.row(s0 + m);
  }
  return out;
}

MatrixXd ClosedLoop::jointRows(const MatrixXd& W) const {
  const Eigen::Index m = rows_per_sample_, K = W.rows() / m;
  MatrixXd out(K * n_, W.cols());
  for (Eigen::Index k = 0; k < K; ++k)
    out.middleRows(k * n_, n_) = W.middleRows(k * m + m - n_, n_);
  return out;
}

namespace {

// One sample of a floating base's recording at zero torque: the model's rows there have the
// contacts' part alone on their measured side.
Dataset floatingSample(double t, const VectorXd& q, const VectorXd& qd, const VectorXd& qdd,
                       const Eigen::RowVectorXd& base, const Eigen::RowVectorXd& contact,
                       const std::string& who) {
  Dataset d;
  d.t = VectorXd::Constant(1, t);
  d.q = q.transpose();
  d.qd = qd.transpose();
  d.qdd = qdd.transpose();
  d.tau = MatrixXd::Zero(1, q.size());
  d.base = base;
  d.contact = contact;
  d.source = who + " (the closed loop's contact wrenches)";
  return d;
}

}  // namespace

VectorXd ClosedLoop::contactTorque(const VectorXd& q, double t) const {
  if (fb_contact_.cols() == 0) return VectorXd::Zero(n_);
  const VectorXd z = VectorXd::Zero(n_);
  const Rows r = model_->fullRowsAt(
      floatingSample(t, q, z, z, recordedAt(fb_base_, t), recordedAt(fb_contact_, t), who_), eta_,
      nullptr, RunContext{});
  return r.y.tail(n_);
}

VectorXd ClosedLoop::floatingTorque(const VectorXd& rest, double t, const VectorXd& q,
                                    const VectorXd& qd, const VectorXd& qdd,
                                    bool with_contact) const {
  if (with_contact && fb_contact_.cols() > 0) {  // one pass of the model's rows: W phi - y
    const Rows r = model_->fullRowsAt(
        floatingSample(t, q, qd, qdd, recordedAt(fb_base_, t), recordedAt(fb_contact_, t), who_),
        eta_, nullptr, RunContext{});
    return (r.W * fullOf(rest) - r.y).tail(n_);
  }
  Samples s;
  s.t = VectorXd::Constant(1, t);
  s.q = q.transpose();
  s.qd = qd.transpose();
  s.qdd = qdd.transpose();
  s.base = recordedAt(fb_base_, t);
  const VectorXd w = jointRows(model_->designAt(s, eta_, nullptr)) * rest;
  return with_contact ? VectorXd(w - contactTorque(q, t)) : w;
}

VectorXd ClosedLoop::floatingFeedforward(double t, const VectorXd& qr, const VectorXd& qdr,
                                         const VectorXd& qddr) const {
  const BaseMotion b = recordedAt(fb_base_, t).transpose();
  VectorXd tau = floatingInverseDynamics(*robot_, qr, qdr, qddr, b).tail(n_);
  for (int j = 0; j < n_; ++j)  // the description's drive terms (actuatorTorque's)
    tau[j] += driveTorque(driveAt(*robot_, j), qdr[j], qddr[j]);
  return tau;
}

ClosedLoop::ClosedLoop(const ObservationModel& model, const Dataset& data, const std::string& who)
    : model_(&model), robot_(model.robotPtr()), n_(robot_->dof()), who_(who), open_(true) {
  // a floating base: the joints driven by the recorded torque on the recorded base motion and
  // contact wrenches (a model of its own)
  floating_ = robot_->floating_base && model.specs().floating_base;
  if (!floating_)
    robot_->requireFixedBase(who +
                             " (its torque-driven simulation integrates the fixed-base forward "
                             "dynamics)");
  if (floating_) setUpFloating(data);
  setUpRows(model);
  check(data.size() >= 10 && data.tau.rows() == data.size() && data.tau.cols() == n_,
        fmt::format("{}: the torque-driven loop needs the recorded torque of all {} joints and "
                    "at least 10 samples ({})",
                    who, n_, data.source));
  Kp_ = VectorXd::Zero(n_);
  Kd_ = VectorXd::Zero(n_);
  ff_ = false;
  rec_t_ = data.t;
  rec_tau_ = data.tau;
  file_ = "the recorded torque";
  if (!floating_) dyn_ = makeDynamicsData(*robot_);
  setUpColumns(model, data);
}

double ClosedLoop::firstTime() const { return open_ ? rec_t_[3] : ref_.t0(); }
double ClosedLoop::lastTime() const { return open_ ? rec_t_[rec_t_.size() - 5] : ref_.t1(); }

VectorXd ClosedLoop::recordedTorque(double t) const {
  const Eigen::Index K = rec_t_.size();
  const double* b = rec_t_.data();
  Eigen::Index k = static_cast<Eigen::Index>(std::upper_bound(b, b + K, t) - b) - 1;
  k = std::max<Eigen::Index>(3, std::min<Eigen::Index>(k, K - 5));
  if (!(t >= rec_t_[3] - 1e-12 && t <= rec_t_[K - 5] + 1e-12))  // (every step: no format)
    throw Error(fmt::format("{}: t = {} s is outside the recorded torque's span [{}, {}] s", who_,
                            t, rec_t_[3], rec_t_[K - 5]));
  // eight samples about t: the spline's interval [t_k, t_k+1] and its slopes' neighbours
  // (read at every step: the scratch keeps its room)
  rec_tl_ = rec_t_.segment(k - 3, 8);
  rec_Xl_ = rec_tau_.middleRows(k - 3, 8);
  shiftedRows(rec_tl_, rec_Xl_, 1, t - rec_t_[k], 3, 4, &rec_out_, nullptr);
  return rec_out_.row(0).transpose();
}

void ClosedLoop::setUpRows(const ObservationModel& model) {
  const std::string& who = who_;
  check(model.specs().per_sample,
        fmt::format("{}: model '{}' must give rows per sample", who, model.pluginName()));
  s_.t = VectorXd::Zero(n_ + 1);
  s_.q = MatrixXd::Zero(n_ + 1, n_);
  s_.qd = MatrixXd::Zero(n_ + 1, n_);
  s_.qdd = MatrixXd::Zero(n_ + 1, n_);
  if (floating_) {  // the model's rows per sample: the joint rows last (rows: all or joints)
    s_.base = MatrixXd::Zero(n_ + 1, 9);
    const Eigen::Index rows = model.design(s_).rows();
    rows_per_sample_ = static_cast<int>(rows / (n_ + 1));
    check(rows == static_cast<Eigen::Index>(n_ + 1) * rows_per_sample_ &&
              (rows_per_sample_ == n_ || rows_per_sample_ == n_ + 6),
          fmt::format("{}: model '{}' gives {} rows per sample on a floating base of {} joints: "
                      "the closed loop simulates the joints from the joint rows, so the model "
                      "needs them (rows: all or joints, not base)",
                      who, model.pluginName(), rows_per_sample_, n_));
    return;
  }
  check(model.design(s_).rows() == static_cast<Eigen::Index>(n_ + 1) * n_,
        fmt::format("{}: model '{}' must give one row per joint of all {} joints (the "
                    "simulation needs every joint's torque; e.g. differential with every joint)",
                    who, model.pluginName(), n_));
}

void ClosedLoop::setUpColumns(const ObservationModel& model, const Dataset& data) {
  const std::string& who = who_;
  const std::vector<NonlinearParameter> nl = model.nonlinearParameters();
  eta_.resize(static_cast<Eigen::Index>(nl.size()));
  for (std::size_t k = 0; k < nl.size(); ++k) {
    eta_[static_cast<Eigen::Index>(k)] = nl[k].value;
    for (std::size_t c = 0; c < nl[k].columns.size(); ++c) nl_param_.push_back(static_cast<int>(k));
  }
  nl_base_ = model.nonlinearColumnsInBase();
  const std::vector<std::string>& names = model.base().names;
  for (std::size_t b = 0; b < names.size(); ++b)
    if (const int kind = torqueColumnKind(names[b])) {
      const int j = std::stoi(names[b].substr(kind == 1 ? 2 : 3)) - 1;
      check(j >= 0 && j < n_,
            fmt::format("{}: base parameter {} names no drive of the {}", who, names[b], n_));
      tcol_.push_back({static_cast<int>(b), j, kind});
    }
  check(
      !data.facts.payload_part_from_t_s,
      fmt::format("{}: the recording has a part with a known payload (facts.payload_part_from_t_s, "
                  "{}): the closed loop does not simulate that payload; give the part without "
                  "it, and for drive gains a prior (didim's gain_prior_std) or gains_ls",
                  who, data.source));
}

VectorXd ClosedLoop::restOf(const VectorXd& theta) const {
  if (tcol_.empty()) return theta;
  VectorXd r = theta;
  for (const TorqueColumn& c : tcol_) r[c.base] = 0.0;
  return r;
}

VectorXd ClosedLoop::delivered(const VectorXd& theta, const VectorXd& tau_c, const VectorXd& qd,
                               VectorXd* slope) const {
  VectorXd u = tau_c;
  if (slope) *slope = VectorXd::Ones(n_);
  for (const TorqueColumn& c : tcol_) {
    const double v = theta[c.base], tj = tau_c[c.joint];
    if (c.kind == 1) {  // dK: the true torque constant over the nominal one, minus 1
      u[c.joint] += v * tj;
      if (slope) (*slope)[c.joint] += v;
    } else {  // FcL: -FcL |tau| sign(qd)
      const double sq = exid::coulombSign(qd[c.joint]);
      const double st = tj > 0 ? 1.0 : (tj < 0 ? -1.0 : 0.0);
      u[c.joint] -= v * std::abs(tj) * sq;
      if (slope) (*slope)[c.joint] -= v * st * sq;
    }
  }
  return u;
}

bool ClosedLoop::hasDriveGains() const { return !driveGainColumns().empty(); }

std::vector<int> ClosedLoop::driveGainColumns() const {
  std::vector<int> out;
  for (const TorqueColumn& c : tcol_)
    if (c.kind == 1) out.push_back(c.base);
  return out;
}

void ClosedLoop::setNonlinear(const VectorXd& eta, bool sensitivities) {
  check(eta.size() == eta_.size(), fmt::format("{}: {} nonlinear parameter values, expected {}",
                                               who_, eta.size(), eta_.size()));
  eta_ = eta;
  eta_sens_ = sensitivities && eta.size() > 0;
}

std::string ClosedLoop::describe() const {
  // (the joints' loop on the recorded base motion)
  const char* floating = floating_ ? "; floating base: the joints simulated on the recorded base "
                                     "motion and contact wrenches (degree-5 Lagrange between "
                                     "samples)"
                                   : "";
  if (open_)
    return std::string(
               "torque-driven: the drives' command is the recorded torque (cubic "
               "Hermite between samples)") +
           floating;
  if (floating_)
    return fmt::format(
        "tau = {}Kp (qr - q) + Kd (qdr - qd), reference {}{}",
        ff_ ? "tau_ff(robot description, all drive terms, on the recorded base motion; qr, "
              "qdr, qddr) + "
            : "",
        file_, floating);
  return fmt::format("tau = {}Kp (qr - q) + Kd (qdr - qd), reference {}",
                     ff_ ? "tau_ff(robot description; qr, qdr, qddr) + " : "", file_);
}

VectorXd ClosedLoop::control(double t, const VectorXd& q, const VectorXd& qd) const {
  if (open_) return recordedTorque(t);
  VectorXd qr, qdr, qddr;
  ref_.eval(t, &qr, &qdr, &qddr);
  VectorXd tau = Kp_.cwiseProduct(qr - q) + Kd_.cwiseProduct(qdr - qd);
  if (ff_ && floating_) {
    tau += floatingFeedforward(t, qr, qdr, qddr);
  } else if (ff_) {
    DriveColumns all{true, true, true, true};
    tau += actuatorTorque(*robot_, *dyn_, all, qr, qdr, qddr);
  }
  return tau;
}

VectorXd ClosedLoop::controlRate(double t, const VectorXd& q, const VectorXd& qd,
                                 const VectorXd& a) const {
  (void)q;
  check(!open_, who_ + ": the torque-driven loop's command rate is not defined");
  check(!floating_, who_ + ": the command's rate is not available on a floating base");
  VectorXd qr, qdr, qddr;
  const double tc = std::min(std::max(t, ref_.t0()), ref_.t1());
  ref_.eval(tc, &qr, &qdr, &qddr);
  // outside the reference's span it is held: its rates are zero there
  const bool inside = t >= ref_.t0() && t <= ref_.t1();
  const VectorXd jr = inside ? quinticHermiteJerk(ref_.s, tc) : VectorXd::Zero(n_);
  if (!inside) {
    qdr.setZero();
    qddr.setZero();
  }
  VectorXd rate = Kp_.cwiseProduct(qdr - qd) + Kd_.cwiseProduct(qddr - a);
  if (ff_ && inside) {
    DriveColumns all{true, true, true, true};
    VectorXd tff;
    MatrixXd Dq, Dqd, Dqdd;
    actuatorTorqueDerivatives(*robot_, *dyn_, all, qr, qdr, qddr, &tff, &Dq, &Dqd, &Dqdd);
    rate += Dq * qdr + Dqd * qddr + Dqdd * jr;
  }
  return rate;
}

const VectorXd& ClosedLoop::fullOf(const VectorXd& theta) const {
  // (asked at every step of a simulation for the same theta: kept)
  if (full_key_.size() == theta.size() && full_key_ == theta) return full_phi_;
  const BaseParameters& B = model_->base();
  VectorXd phi = VectorXd::Zero(B.numFull());
  const VectorXd rest = restOf(theta);
  for (int i = 0; i < B.rank(); ++i) phi[B.independent[static_cast<std::size_t>(i)]] = rest[i];
  full_phi_ = std::move(phi);
  full_key_ = theta;
  return full_phi_;
}

VectorXd ClosedLoop::acceleration(const VectorXd& theta, double t, const VectorXd& q,
                                  const VectorXd& qd, MatrixXd* Mo, VectorXd* command) const {
  const int n = n_;
  // h = w(q, qd, 0) theta and M: the model's torque at theta when it gives it (O(n^2)), else
  // (n + 1) n torques of its rows (theta's torque columns, if any, act through delivered())
  VectorXd h;
  MatrixXd M;
  if (floating_) {
    // the joint rows with the recorded base motion: h = w(q, qd, 0) theta - c(q, t), M e_i =
    // w(q, qd, e_i) theta - w(q, qd, 0) theta
    for (int k = 0; k <= n; ++k) {
      s_.q.row(k) = q.transpose();
      s_.qd.row(k) = qd.transpose();
    }
    s_.qdd.setZero();
    for (int i = 0; i < n; ++i) s_.qdd(i + 1, i) = 1.0;
    s_.base.rowwise() = recordedAt(fb_base_, t);
    const VectorXd f = jointRows(model_->designAt(s_, eta_, nullptr)) * restOf(theta);
    h = f.head(n) - contactTorque(q, t);
    M.resize(n, n);
    for (int i = 0; i < n; ++i) M.col(i) = f.segment((i + 1) * n, n) - f.head(n);
  } else if (!model_->fullTorqueAt(q, qd, VectorXd::Zero(n), eta_, fullOf(theta), &h, nullptr,
                                   nullptr, &M)) {
    for (int k = 0; k <= n; ++k) {
      s_.q.row(k) = q.transpose();
      s_.qd.row(k) = qd.transpose();
    }
    s_.qdd.setZero();
    for (int i = 0; i < n; ++i) s_.qdd(i + 1, i) = 1.0;
    const MatrixXd W = model_->designAt(s_, eta_, nullptr);
    const VectorXd f = tcol_.empty() ? VectorXd(W * theta) : VectorXd(W * restOf(theta));
    h = f.head(n);
    M.resize(n, n);
    for (int i = 0; i < n; ++i) M.col(i) = f.segment((i + 1) * n, n) - h;
  }
  M = 0.5 * (M + M.transpose());
  Eigen::LDLT<MatrixXd> ldlt(M);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().array() > 0).all())
    throw Error(fmt::format(
        "{}: the estimate's mass matrix is not positive definite at t = {} s (the estimate is "
        "too far from a physical robot to simulate: try consistent_ls first)",
        who_, t));
  if (Mo) *Mo = M;
  const VectorXd tau_c = control(t, q, qd);
  if (command) *command = tau_c;
  return ldlt.solve(delivered(theta, tau_c, qd, nullptr) - h);
}

}  // namespace exid::estimators
