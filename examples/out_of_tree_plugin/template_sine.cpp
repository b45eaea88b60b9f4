// TEMPLATE (trajectory): one sinusoid per moving joint, the i-th moving joint at harmonic i:
//   q_j(t) = c_j + a_j sin(i w t) + b_j cos(i w t),   w = 2 pi / period_s,
// variables z = [c_j, a_j, b_j] joint after joint; the other joints rest at the centre of their
// range. Linear in z, periodic, sampled over one period and defined at any time. Shows: bind,
// initial, bounds (necessary conditions only: the limits are the excitation problem's
// constraints), evaluate / vjp / jacobian / evaluateAt / vjpAt, all exact, from one basis
// function, and honest TrajectorySpecs. Core API alone (exid::core). Not overridden: describe()
// and parametersAt() (free-form JSON for the summary and the exported parameter file).
// To make it yours: change basis() and kVars (variables per joint), then bind()'s start point
// and bounds. Limitation: measured = joint coordinates (a transmission is refused).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/interfaces.hpp"

namespace {

// exid::JointLimits says "no limit" with +-1e300: made +-inf here
double known(double x) { return std::abs(x) < 1e100 ? x : std::copysign(HUGE_VAL, x); }

class TemplateSine final : public exid::Trajectory {
 public:
  static constexpr const char* kName = "template_sine";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "one sinusoid per moving joint, the i-th at harmonic i: q_j = c_j + a_j sin(i w t) + b_j "
      "cos(i w t), variables [c_j, a_j, b_j]; periodic (out-of-tree template)";
  static constexpr int kVars = 3;  // variables per moving joint
  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_double("period_s", 10.0, "s", "period T (w = 2 pi / T)", 0.0, {}, true),
        exid::param_double("sample_period_s", 0.1, "s", "design sample spacing", 0.0, {}, true),
        exid::param_ints("joints", std::vector<std::int64_t>{}, "1-based moving joints; empty: all",
                         1.0),
    };
  }
  explicit TemplateSine(const exid::ParamSet& p)
      : T_(p.getDouble("period_s")),
        dt_(p.getDouble("sample_period_s")),
        joints_(p.getInts("joints")) {}

  void bind(std::shared_ptr<const exid::RobotModel> robot, const exid::RunContext&) override {
    const std::string who = fmt::format("trajectory '{}'", kName);
    exid::check(!robot->hasTransmission(), who + ": robots with a transmission are not supported");
    n_ = robot->dof();
    moving_.clear();
    for (auto j : joints_) {
      exid::check(j >= 1 && j <= n_, fmt::format("{}: joint {} is not in 1..{}", who, j, n_));
      moving_.push_back(static_cast<int>(j - 1));
    }
    for (int j = 0; joints_.empty() && j < n_; ++j) moving_.push_back(j);
    const int m = static_cast<int>(moving_.size());
    const long K = std::lround(T_ / dt_);
    exid::check(K >= 2 && K <= 1000000, fmt::format("{}: {} samples per period", who, K));
    t_ = Eigen::VectorXd::LinSpaced(K, 0.0, T_ * (K - 1) / K);  // one period, end excluded
    rest_ = Eigen::VectorXd::Zero(n_);  // the centre of each joint's range (0 without one)
    for (int j = 0; j < n_; ++j) {
      const exid::JointLimits& L = robot->limits[static_cast<std::size_t>(j)];
      if (std::isfinite(known(L.q_min) + known(L.q_max))) rest_(j) = 0.5 * (L.q_min + L.q_max);
    }
    w_.resize(m);
    z0_ = lo_ = hi_ = Eigen::VectorXd::Zero(kVars * m);
    for (int i = 0; i < m; ++i) {
      const int j = moving_[static_cast<std::size_t>(i)];
      const exid::JointLimits& L = robot->limits[static_cast<std::size_t>(j)];
      const double w = (i + 1) * 2 * M_PI / T_;  // harmonic i + 1
      // |a|, |b| <= sqrt(a^2 + b^2) = the amplitude, which every limit of q, qd, qdd bounds
      const double amax = std::min({0.5 * (known(L.q_max) - known(L.q_min)), known(L.qd_max) / w,
                                    known(L.qdd_max) / (w * w)});
      w_(i) = w;
      z0_.segment<kVars>(kVars * i) << rest_(j), kInit * (std::isfinite(amax) ? amax : 1.0), 0.0;
      lo_.segment<kVars>(kVars * i) << known(L.q_min), -amax, -amax;
      hi_.segment<kVars>(kVars * i) << known(L.q_max), amax, amax;
    }
  }

  int numVariables() const override { return kVars * static_cast<int>(moving_.size()); }
  Eigen::VectorXd initial() const override { return z0_; }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override {
    if (lo) *lo = lo_;
    if (hi) *hi = hi_;
  }
  // on the sample grid: the same as at any time
  exid::Samples evaluate(const Eigen::VectorXd& z) const override { return evaluateAt(z, t_); }
  Eigen::VectorXd vjp(const Eigen::VectorXd& z, const exid::Samples& adj) const override {
    return vjpAt(z, t_, adj);
  }
  exid::Samples evaluateAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t) const override {
    exid::check(z.size() == numVariables(), "trajectory 'template_sine': wrong size of z");
    exid::Samples s{t, rest_.transpose().replicate(t.size(), 1),
                    Eigen::MatrixXd::Zero(t.size(), n_), Eigen::MatrixXd::Zero(t.size(), n_)};
    for (std::size_t i = 0; i < moving_.size(); ++i)
      for (Eigen::Index k = 0; k < t.size(); ++k) {
        const Eigen::Vector3d x = basis(i, t(k)) * z.segment<kVars>(kVars * i);  // q, qd, qdd
        s.q(k, moving_[i]) = x(0);
        s.qd(k, moving_[i]) = x(1);
        s.qdd(k, moving_[i]) = x(2);
      }
    return s;
  }
  // Gradient of <adj.q, q> + <adj.qd, qd> + <adj.qdd, qdd>: the basis transposed (linear in z).
  Eigen::VectorXd vjpAt(const Eigen::VectorXd&, const Eigen::VectorXd& t,
                        const exid::Samples& adj) const override {
    Eigen::VectorXd g = Eigen::VectorXd::Zero(numVariables());
    for (std::size_t i = 0; i < moving_.size(); ++i)
      for (Eigen::Index k = 0; k < t.size(); ++k) {
        const int j = moving_[i];
        g.segment<kVars>(kVars * i) +=
            basis(i, t(k)).transpose() * Eigen::Vector3d(adj.q(k, j), adj.qd(k, j), adj.qdd(k, j));
      }
    return g;
  }
  // d[vec(q); vec(qd); vec(qdd)]/dz, vec column-major: q(k, j) is row j K + k.
  Eigen::MatrixXd jacobian(const Eigen::VectorXd&) const override {
    const Eigen::Index K = t_.size(), Kn = K * n_;
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(3 * Kn, numVariables());
    for (std::size_t i = 0; i < moving_.size(); ++i)
      for (Eigen::Index k = 0; k < K; ++k) {
        const Eigen::Matrix<double, 3, kVars> B = basis(i, t_(k));
        for (int d = 0; d < 3; ++d)
          J.block<1, kVars>(d * Kn + moving_[i] * K + k, kVars * i) = B.row(d);
      }
    return J;
  }

  exid::TrajectorySpecs specs() const override {
    exid::TrajectorySpecs sp;
    sp.moving_joints = moving_;
    sp.linear = true;      // samples affine in z
    sp.continuous = true;  // evaluateAt / vjpAt at any time in [0, T]
    sp.periodic = true;    // the grid covers one period
    sp.duration_s = T_;
    sp.repeatable = true;     // periodic: it ends in its start state
    sp.rest_to_rest = false;  // qd(0) = i w a_j is not zero
    return sp;
  }

 private:
  // Rows q, qd, qdd of moving joint i at time t, as linear maps of its variables [c, a, b].
  Eigen::Matrix<double, 3, kVars> basis(std::size_t i, double t) const {
    const double w = w_(static_cast<Eigen::Index>(i)), s = std::sin(w * t), c = std::cos(w * t);
    Eigen::Matrix<double, 3, kVars> B;
    B << 1.0, s, c,          //
        0.0, w * c, -w * s,  //
        0.0, -w * w * s, -w * w * c;
    return B;
  }

  double T_, dt_;
  static constexpr double kInit = 0.3;  // start amplitude: this fraction of the largest allowed
  std::vector<std::int64_t> joints_;
  int n_ = 0;
  std::vector<int> moving_;  // 0-based
  Eigen::VectorXd t_, rest_, w_, z0_, lo_, hi_;
};

}  // namespace

EXID_REGISTER_PLUGIN(TemplateSine)
