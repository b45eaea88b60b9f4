#include "exid/trajectories/traj_common.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "exid/error.hpp"

namespace exid::trajectories {

namespace {
constexpr double kInf = HUGE_VAL;
bool finite(double x) { return std::isfinite(x) && std::abs(x) < 1e299; }
}  // namespace

std::vector<ParamDecl> commonParams() {
  return {
      param_double("sample_period_s", 0.1, "s", "sample period of the design grid", 0.0,
                   std::nullopt, true),
      param_int("samples", 0, "number of samples (0: from the period/duration and sample_period_s)",
                0.0, kMaxDesignSamples),
      param_double("position_margin_rad", 0.0, "rad",
                   "margin kept inside the joint position limits", 0.0),
      param_bool("velocity_limits", true, "impose the joint velocity limits at every sample"),
      param_bool("acceleration_limits", true,
                 "impose the joint acceleration limits at every sample"),
      param_double("velocity_limit_rad_s", 0.0, "rad/s",
                   "own velocity cap |qd| <= value at every sample (0: none); part of the "
                   "excitation problem's limits (Trajectory::adjustLimits), also on robots without "
                   "velocity limits and with velocity_limits: false",
                   0.0),
      param_double("acceleration_limit_rad_s2", 0.0, "rad/s^2",
                   "own acceleration cap |qdd| <= value (0: none), as velocity_limit_rad_s", 0.0),
      param_ints("joints", std::vector<std::int64_t>{},
                 "1-based joints that move (empty: all); the others stay at rest_position_rad", 1.0,
                 10000.0),
      param_doubles("rest_position_rad", std::vector<double>{}, "rad",
                    "positions of the joints that do not move (one value per joint or one for all; "
                    "empty: the centre of their range)"),
  };
}

CommonOptions readCommon(const ParamSet& p) {
  CommonOptions o;
  o.sample_period = p.getDouble("sample_period_s");
  o.samples = static_cast<int>(p.getInt("samples"));
  o.margin = p.getDouble("position_margin_rad");
  o.velocity_limits = p.getBool("velocity_limits");
  o.acceleration_limits = p.getBool("acceleration_limits");
  o.velocity_cap = p.getDouble("velocity_limit_rad_s");
  o.acceleration_cap = p.getDouble("acceleration_limit_rad_s2");
  o.joints = p.getInts("joints");
  o.rest = p.getDoubles("rest_position_rad");
  return o;
}

bool JointSpace::hasCaps() const { return hasVelocityCap() || hasAccelerationCap(); }
bool JointSpace::hasVelocityCap() const { return qd_cap.size() && qd_cap.array().isFinite().any(); }
bool JointSpace::hasAccelerationCap() const {
  return qdd_cap.size() && qdd_cap.array().isFinite().any();
}

void adjustLimitsCommon(const JointSpace& js, const CommonOptions& o,
                        std::vector<JointLimits>* limits) {
  if (!limits) return;
  const int n = std::min(js.n, static_cast<int>(limits->size()));
  for (int j = 0; j < n; ++j) {
    JointLimits& L = (*limits)[static_cast<std::size_t>(j)];
    if (!o.velocity_limits) L.qd_max = kInf;
    if (!o.acceleration_limits) L.qdd_max = kInf;
    if (std::isfinite(js.qd_cap_joint(j)))
      L.qd_max = finite(L.qd_max) ? std::min(L.qd_max, js.qd_cap_joint(j)) : js.qd_cap_joint(j);
    if (std::isfinite(js.qdd_cap_joint(j)))
      L.qdd_max =
          finite(L.qdd_max) ? std::min(L.qdd_max, js.qdd_cap_joint(j)) : js.qdd_cap_joint(j);
  }
}

JointSpace resolveJoints(const RobotModel& r, const CommonOptions& o, const std::string& who) {
  JointSpace js;
  js.n = r.dof();
  const int n = js.n;
  if (o.joints.empty()) {
    for (int j = 0; j < n; ++j) js.moving.push_back(j);
  } else {
    std::vector<bool> seen(static_cast<std::size_t>(n), false);
    for (auto j1 : o.joints) {
      check(j1 >= 1 && j1 <= n,
            fmt::format("{}: joints: {} is not a joint of the {}-dof robot", who, j1, n));
      check(!seen[static_cast<std::size_t>(j1 - 1)],
            fmt::format("{}: joints: {} given twice", who, j1));
      seen[static_cast<std::size_t>(j1 - 1)] = true;
      js.moving.push_back(static_cast<int>(j1 - 1));
    }
  }
  js.q_lo = Eigen::VectorXd::Constant(n, -kInf);
  js.q_hi = Eigen::VectorXd::Constant(n, kInf);
  js.qd_max = Eigen::VectorXd::Constant(n, kInf);
  js.qdd_max = Eigen::VectorXd::Constant(n, kInf);
  js.qd_cap = Eigen::VectorXd::Constant(n, kInf);
  js.qdd_cap = Eigen::VectorXd::Constant(n, kInf);
  js.qd_cap_joint = js.qd_cap;
  js.qdd_cap_joint = js.qdd_cap;
  js.centre = Eigen::VectorXd::Zero(n);
  // Limits are given in joint coordinates; with a diagonal (or identity) transmission they map
  // one to one onto measured coordinates. Otherwise only the caps and the centre are used.
  const bool diag = !r.hasTransmission() ||
                    (r.transmission.rows() == n && r.transmission.cols() == n &&
                     r.transmission.isDiagonal() && (r.transmission.diagonal().array() != 0).all());
  for (int j = 0; j < n; ++j) {
    const JointLimits L = j < static_cast<int>(r.limits.size())
                              ? r.limits[static_cast<std::size_t>(j)]
                              : JointLimits{};
    double lo = finite(L.q_min) ? L.q_min + o.margin : -kInf;
    double hi = finite(L.q_max) ? L.q_max - o.margin : kInf;
    double vd = (o.velocity_limits && finite(L.qd_max)) ? L.qd_max : kInf;
    double ad = (o.acceleration_limits && finite(L.qdd_max)) ? L.qdd_max : kInf;
    if (r.hasTransmission()) {
      if (!diag) {
        lo = -kInf;
        hi = kInf;
        vd = kInf;
        ad = kInf;
      } else {
        const double d = r.transmission(j, j);
        const double off = r.transmission_offset.size() ? r.transmission_offset(j) : 0.0;
        double a = (lo - off) / d, b = (hi - off) / d;
        lo = std::min(a, b);
        hi = std::max(a, b);
        vd /= std::abs(d);
        ad /= std::abs(d);
      }
    }
    check(!(lo > hi),
          fmt::format("{}: joint {}: position margin {} leaves no range", who, j + 1, o.margin));
    js.q_lo(j) = lo;
    js.q_hi(j) = hi;
    if (o.velocity_cap > 0) js.qd_cap(j) = o.velocity_cap;
    if (o.acceleration_cap > 0) js.qdd_cap(j) = o.acceleration_cap;
    const double tj = diag && r.hasTransmission() ? std::abs(r.transmission(j, j)) : 1.0;
    js.qd_cap_joint(j) = js.qd_cap(j) * tj;
    js.qdd_cap_joint(j) = js.qdd_cap(j) * tj;
    js.qd_max(j) = std::min(vd, js.qd_cap(j));
    js.qdd_max(j) = std::min(ad, js.qdd_cap(j));
    if (std::isfinite(lo) && std::isfinite(hi))
      js.centre(j) = 0.5 * (lo + hi);
    else if (std::isfinite(lo))
      js.centre(j) = lo + 1.0;
    else if (std::isfinite(hi))
      js.centre(j) = hi - 1.0;
  }
  js.rest = js.centre;
  if (!o.rest.empty()) {
    check(o.rest.size() == 1 || static_cast<int>(o.rest.size()) == n,
          fmt::format("{}: rest_position_rad has {} values (expected 1 or {})", who, o.rest.size(),
                      n));
    for (int j = 0; j < n; ++j)
      js.rest(j) = o.rest.size() == 1 ? o.rest[0] : o.rest[static_cast<std::size_t>(j)];
  }
  return js;
}

Json describeCommon(const JointSpace& js, const CommonOptions& o, bool linear) {
  Json d = Json::object();
  d["linear"] = linear;
  std::vector<double> moving;
  for (int j : js.moving) moving.push_back(j + 1);
  d["joints"] = Json(moving);
  d["position_margin_rad"] = o.margin;
  if (js.hasCaps()) {
    Json caps = Json::object();
    std::vector<double> v(js.qd_cap.data(), js.qd_cap.data() + js.n),
        a(js.qdd_cap.data(), js.qdd_cap.data() + js.n);
    for (auto& x : v)
      if (!std::isfinite(x)) x = 0.0;  // 0: none
    for (auto& x : a)
      if (!std::isfinite(x)) x = 0.0;
    caps["qd_max"] = Json(v);
    caps["qdd_max"] = Json(a);
    caps["imposed_by"] = "Trajectory::adjustLimits (the excitation problem's g)";
    d["caps"] = caps;
  }
  return d;
}

TrajectorySpecs specsCommon(const JointSpace& js, bool linear) {
  TrajectorySpecs sp;
  sp.moving_joints = js.moving;
  sp.linear = linear;
  return sp;
}

std::vector<ParamDecl> restToRestParams() {
  return {
      param_bool("rest_to_rest", false,
                 "start and stop at rest: qd = qdd = 0 at both ends, exactly (by construction)"),
      param_doubles("start_position_rad", std::vector<double>{}, "rad",
                    "with rest_to_rest: the position the motion starts (and ends) at, one value "
                    "per joint or one for all (empty: free)"),
  };
}

Eigen::VectorXd resolveStart(const JointSpace& js, const std::vector<double>& start,
                             const std::string& who) {
  if (start.empty()) return {};
  check(start.size() == 1 || static_cast<int>(start.size()) == js.n,
        fmt::format("{}: start_position_rad has {} values (expected 1 or {})", who, start.size(),
                    js.n));
  Eigen::VectorXd q = js.rest;
  for (int j : js.moving) {
    q(j) = start.size() == 1 ? start[0] : start[static_cast<std::size_t>(j)];
    check(std::isfinite(q(j)) && q(j) >= js.q_lo(j) && q(j) <= js.q_hi(j),
          fmt::format("{}: start_position_rad of joint {} = {} is outside its range [{}, {}] "
                      "(limits less the position margin)",
                      who, j + 1, q(j), js.q_lo(j), js.q_hi(j)));
  }
  return q;
}

int sampleCount(const CommonOptions& o, double T, bool include_end, const std::string& who,
                const std::string& t_key) {
  if (o.samples > 0) return o.samples;
  // The quotient is checked in double before it becomes a count (it overflowed an int).
  const double r = T / o.sample_period;
  check(std::isfinite(r) && r <= kMaxDesignSamples,
        fmt::format("{}: {} = {} s / sample_period_s = {} s gives {:g} samples, more than the "
                    "{:g} allowed; lengthen sample_period_s or shorten {}",
                    who, t_key, T, o.sample_period, r, kMaxDesignSamples, t_key));
  int K = static_cast<int>(std::lround(r));
  check(K >= 2, fmt::format("{}: {} s at {} s per sample gives fewer than 2 samples", who, T,
                            o.sample_period));
  return include_end ? K + 1 : K;
}

// ---------------------------------------------------------------- BasisTrajectory
void BasisTrajectory::setGrid(Eigen::VectorXd t, int m) {
  t_ = std::move(t);
  m_ = m;
  const Eigen::Index K = t_.size();
  Bq_.resize(K, m);
  Bqd_.resize(K, m);
  Bqdd_.resize(K, m);
  Eigen::RowVectorXd bq, bqd, bqdd;
  for (Eigen::Index k = 0; k < K; ++k) {
    basisAt(t_(k), &bq, &bqd, &bqdd);
    Bq_.row(k) = bq;
    Bqd_.row(k) = bqd;
    Bqdd_.row(k) = bqdd;
  }
  J_.resize(0, 0);
}

TrajectorySpecs BasisTrajectory::basisSpecs() const {
  TrajectorySpecs sp = specsCommon(js_, true);
  sp.continuous = true;
  return sp;
}

Samples BasisTrajectory::evaluateAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t) const {
  check(z.size() == numVariables(), fmt::format("trajectory '{}': {} variables given, {} expected",
                                                pluginName(), z.size(), numVariables()));
  const Eigen::Index K = t.size();
  Samples s;
  s.t = t;
  s.q = Eigen::MatrixXd::Zero(K, js_.n);
  s.qd = s.q;
  s.qdd = s.q;
  for (int j = 0; j < js_.n; ++j) s.q.col(j).setConstant(js_.rest(j));
  Eigen::RowVectorXd bq, bqd, bqdd;
  for (Eigen::Index k = 0; k < K; ++k) {
    basisAt(t(k), &bq, &bqd, &bqdd);
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      const auto zj = z.segment(static_cast<Eigen::Index>(i) * m_, m_);
      s.q(k, j) = bq.dot(zj) + offset(j);
      s.qd(k, j) = bqd.dot(zj);
      s.qdd(k, j) = bqdd.dot(zj);
    }
  }
  return s;
}

Eigen::VectorXd BasisTrajectory::vjpAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t,
                                       const Samples& adj) const {
  check(z.size() == numVariables(), fmt::format("trajectory '{}': {} variables given, {} expected",
                                                pluginName(), z.size(), numVariables()));
  Eigen::VectorXd g = Eigen::VectorXd::Zero(numVariables());
  Eigen::RowVectorXd bq, bqd, bqdd;
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    basisAt(t(k), &bq, &bqd, &bqdd);
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      g.segment(static_cast<Eigen::Index>(i) * m_, m_) += adj.q(k, j) * bq.transpose() +
                                                          adj.qd(k, j) * bqd.transpose() +
                                                          adj.qdd(k, j) * bqdd.transpose();
    }
  }
  return g;
}

Samples BasisTrajectory::evaluate(const Eigen::VectorXd& z) const {
  check(z.size() == numVariables(), fmt::format("trajectory '{}': {} variables given, {} expected",
                                                pluginName(), z.size(), numVariables()));
  const Eigen::Index K = t_.size();
  Samples s;
  s.t = t_;
  s.q = Eigen::MatrixXd::Zero(K, js_.n);
  s.qd = s.q;
  s.qdd = s.q;
  for (int j = 0; j < js_.n; ++j) s.q.col(j).setConstant(js_.rest(j));
  for (std::size_t i = 0; i < js_.moving.size(); ++i) {
    const int j = js_.moving[i];
    auto zj = z.segment(static_cast<Eigen::Index>(i) * m_, m_);
    s.q.col(j).noalias() = Bq_ * zj;
    if (q_offset_.size()) s.q.col(j).array() += q_offset_(j);
    s.qd.col(j).noalias() = Bqd_ * zj;
    s.qdd.col(j).noalias() = Bqdd_ * zj;
  }
  return s;
}

Eigen::VectorXd BasisTrajectory::vjp(const Eigen::VectorXd&, const Samples& adj) const {
  Eigen::VectorXd g(numVariables());
  for (std::size_t i = 0; i < js_.moving.size(); ++i) {
    const int j = js_.moving[i];
    auto gj = g.segment(static_cast<Eigen::Index>(i) * m_, m_);
    gj.noalias() = Bq_.transpose() * adj.q.col(j);
    gj.noalias() += Bqd_.transpose() * adj.qd.col(j);
    gj.noalias() += Bqdd_.transpose() * adj.qdd.col(j);
  }
  return g;
}

Eigen::MatrixXd BasisTrajectory::jacobian(const Eigen::VectorXd&) const {
  if (J_.size() == 0) {
    const Eigen::Index K = t_.size(), n = js_.n, Kn = K * n;
    J_ = Eigen::MatrixXd::Zero(3 * Kn, numVariables());
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const Eigen::Index j = js_.moving[i], c = static_cast<Eigen::Index>(i) * m_;
      J_.block(j * K, c, K, m_) = Bq_;
      J_.block(Kn + j * K, c, K, m_) = Bqd_;
      J_.block(2 * Kn + j * K, c, K, m_) = Bqdd_;
    }
  }
  return J_;
}

Json BasisTrajectory::describe() const {
  Json d = describeCommon(js_, opt_, true);
  d["samples"] = static_cast<long>(t_.size());
  d["variables_per_joint"] = m_;
  return d;
}

void BasisTrajectory::scaleIntoLimits(Eigen::VectorXd* z, const Eigen::VectorXd& zref,
                                      double fraction) const {
  for (std::size_t i = 0; i < js_.moving.size(); ++i) {
    const int j = js_.moving[i];
    const Eigen::Index c = static_cast<Eigen::Index>(i) * m_;
    Eigen::VectorXd dz = z->segment(c, m_) - zref.segment(c, m_);
    const double dq = (Bq_ * dz).cwiseAbs().maxCoeff(), dv = (Bqd_ * dz).cwiseAbs().maxCoeff(),
                 da = (Bqdd_ * dz).cwiseAbs().maxCoeff();
    // the reference's (constant) position: the centre, or the start position it is tied to
    const double c0 = q_offset_.size() ? q_offset_(j) : js_.centre(j);
    const double half = std::min(js_.q_hi(j) - c0, c0 - js_.q_lo(j));
    double s = kInf;
    if (dq > 0 && std::isfinite(half)) s = std::min(s, half / dq);
    if (dv > 0 && std::isfinite(js_.qd_max(j))) s = std::min(s, js_.qd_max(j) / dv);
    if (da > 0 && std::isfinite(js_.qdd_max(j))) s = std::min(s, js_.qdd_max(j) / da);
    if (!std::isfinite(s)) s = dq > 0 ? 1.0 / dq : 1.0;  // unlimited joint: 1 rad amplitude
    z->segment(c, m_) = zref.segment(c, m_) + fraction * s * dz;
  }
}

}  // namespace exid::trajectories
