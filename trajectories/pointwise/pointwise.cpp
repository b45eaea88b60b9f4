// Trajectory `pointwise`: the paper's form (section 3, eqns 13-16). Decision variables are the
// accelerations u_k = qdd_k of the moving joints at every sample k = 0..K-1; the state
// X = [q; qd] follows the exact double-integrator discretisation (zero-order hold)
//   X_{k+1} = A X_k + B u_k,  A = [[I, dt I], [0, I]],  B = [[dt^2/2 I], [dt I]],
// from a given X_0 = [q0; qd0]. The sample k carries (q_k, qd_k, qdd_k = u_k).
// VJP = the paper's backward costate recursion (eqn 15): lambda_K = 0,
//   g_k      = dJ/du_k + B^T lambda_{k+1},
//   lambda_k = dJ/dX_k + A^T lambda_{k+1},
// i.e. one sweep backwards over the trajectory, O(K n). The Jacobian (constant) is cached.
#include <fmt/format.h>

#include <cmath>

#include "exid/error.hpp"
#include "exid/fmath.hpp"
#include "exid/io.hpp"
#include "exid/trajectories/traj_common.hpp"

namespace {

class Pointwise final : public exid::Trajectory {
 public:
  static constexpr const char* kName = "pointwise";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "the paper's pointwise trajectory: variables are the accelerations qdd_k at every sample; "
      "q, qd by the exact double-integrator recursion X_{k+1} = A X_k + B qdd_k from X_0; VJP is "
      "the backward costate recursion";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::trajectories::commonParams();
    p.push_back(exid::param_double("duration_s", 10.0, "s",
                                   "duration: K = duration_s / sample_period_s samples", 0.0,
                                   std::nullopt, true));
    p.push_back(
        exid::param_doubles("q0_rad", std::vector<double>{}, "rad",
                            "initial positions X_0 (one per joint; empty: the centre of "
                            "the range, or rest_position_rad for joints that do not move)"));
    p.push_back(exid::param_string("init", std::string("cosine"),
                                   "start: cosine (q = q0 + A (cos(2 pi f_i t) - 1), f_i = "
                                   "(i+1) init_frequency_hz for the i-th moving joint, A capped to "
                                   "the limits); csv: init_csv; zero: no motion",
                                   {"cosine", "csv", "zero"}));
    p.push_back(exid::param_double("init_amplitude_rad", 0.5, "rad",
                                   "amplitude A of the cosine start", 0.0));
    p.push_back(exid::param_double("init_frequency_hz", 0.1, "Hz",
                                   "base frequency of the cosine start", 0.0, std::nullopt, true));
    p.push_back(exid::param_path("init_csv", std::string(""),
                                 "start from a trajectory: CSV with t and qdd1..qddn (taken as the "
                                 "accelerations), or t and q1..qn (one period of a periodic "
                                 "signal, differentiated exactly by trigonometric interpolation; "
                                 "X_0 then comes from the file)"));
    return p;
  }

  explicit Pointwise(const exid::ParamSet& p)
      : D_(p.getDouble("duration_s")),
        q0_param_(p.getDoubles("q0_rad")),
        init_(p.getString("init")),
        amp_(p.getDouble("init_amplitude_rad")),
        freq_(p.getDouble("init_frequency_hz")),
        csv_(p.getString("init_csv")) {
    opt_ = exid::trajectories::readCommon(p);
  }

  void bind(std::shared_ptr<const exid::RobotModel> robot, const exid::RunContext& ctx) override {
    const std::string who = "trajectory 'pointwise'";
    js_ = exid::trajectories::resolveJoints(*robot, opt_, who);
    K_ = exid::trajectories::sampleCount(opt_, D_, false, who);
    dt_ = opt_.samples > 0 ? D_ / K_ : opt_.sample_period;
    const int n = js_.n;
    nm_ = static_cast<int>(js_.moving.size());
    X0q_ = js_.rest;
    for (int j : js_.moving) X0q_(j) = js_.centre(j);
    if (!q0_param_.empty()) {
      exid::check(static_cast<int>(q0_param_.size()) == n,
                  fmt::format("{}: q0_rad has {} values (expected {})", who, q0_param_.size(), n));
      X0q_ = Eigen::Map<const Eigen::VectorXd>(q0_param_.data(), n);
    }
    X0qd_ = Eigen::VectorXd::Zero(n);
    z0_ = Eigen::VectorXd::Zero(numVariables());
    if (init_ == "cosine") {
      for (int i = 0; i < nm_; ++i) {
        const int j = js_.moving[static_cast<std::size_t>(i)];
        const double w = 2.0 * M_PI * freq_ * (i + 1);
        double A = amp_;
        const double room = X0q_(j) - js_.q_lo(j);
        if (std::isfinite(room)) A = std::min(A, 0.45 * room);
        if (std::isfinite(js_.qd_max(j))) A = std::min(A, 0.9 * js_.qd_max(j) / w);
        if (std::isfinite(js_.qdd_max(j))) A = std::min(A, 0.9 * js_.qdd_max(j) / (w * w));
        A = std::max(A, 0.0);
        // u_k = (qd(t_{k+1}) - qd(t_k)) / dt reproduces qd exactly at the samples (no drift)
        for (int k = 0; k < K_; ++k) {
          const double qd1 = -A * w * exid::fmath::sin(w * (k + 1) * dt_),
                       qd0 = -A * w * exid::fmath::sin(w * k * dt_);
          z0_(i * K_ + k) = (qd1 - qd0) / dt_;
        }
      }
    } else if (init_ == "csv") {
      exid::check(!csv_.empty(), fmt::format("{}: init: csv needs init_csv", who));
      std::filesystem::path path(csv_);
      if (path.is_relative() && !ctx.study_dir.empty()) path = ctx.study_dir / path;
      loadCsv(path, who);
    }
    J_.resize(0, 0);
  }

  int numVariables() const override { return K_ * nm_; }
  Eigen::VectorXd initial() const override { return z0_; }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override {
    Eigen::VectorXd l(numVariables()), h(numVariables());
    for (int i = 0; i < nm_; ++i) {
      const double a = js_.qdd_max(js_.moving[static_cast<std::size_t>(i)]);
      l.segment(i * K_, K_).setConstant(std::isfinite(a) ? -a : -HUGE_VAL);
      h.segment(i * K_, K_).setConstant(std::isfinite(a) ? a : HUGE_VAL);
    }
    if (lo) *lo = l;
    if (hi) *hi = h;
  }

  exid::Samples evaluate(const Eigen::VectorXd& z) const override {
    exid::check(z.size() == numVariables(),
                fmt::format("trajectory 'pointwise': {} variables given, {} expected", z.size(),
                            numVariables()));
    exid::Samples s;
    s.t = Eigen::VectorXd::LinSpaced(K_, 0.0, (K_ - 1) * dt_);
    s.q.resize(K_, js_.n);
    s.qd = Eigen::MatrixXd::Zero(K_, js_.n);
    s.qdd = Eigen::MatrixXd::Zero(K_, js_.n);
    for (int j = 0; j < js_.n; ++j) s.q.col(j).setConstant(js_.rest(j));
    const double h2 = 0.5 * dt_ * dt_;
    for (int i = 0; i < nm_; ++i) {
      const int j = js_.moving[static_cast<std::size_t>(i)];
      double q = X0q_(j), qd = X0qd_(j);
      for (int k = 0; k < K_; ++k) {
        const double u = z(i * K_ + k);
        s.q(k, j) = q;
        s.qd(k, j) = qd;
        s.qdd(k, j) = u;
        q += dt_ * qd + h2 * u;  // X_{k+1} = A X_k + B u_k
        qd += dt_ * u;
      }
    }
    return s;
  }

  Eigen::VectorXd vjp(const Eigen::VectorXd&, const exid::Samples& adj) const override {
    Eigen::VectorXd g(numVariables());
    const double h2 = 0.5 * dt_ * dt_;
    for (int i = 0; i < nm_; ++i) {
      const int j = js_.moving[static_cast<std::size_t>(i)];
      double lq = 0.0, lqd = 0.0;  // lambda_{k+1} = [lambda_q; lambda_qd]; lambda_K = 0
      for (int k = K_ - 1; k >= 0; --k) {
        g(i * K_ + k) = adj.qdd(k, j) + h2 * lq + dt_ * lqd;  // dJ/du_k + B^T lambda_{k+1}
        const double nlq = adj.q(k, j) + lq;                  // dJ/dX_k + A^T lambda_{k+1}
        const double nlqd = adj.qd(k, j) + dt_ * lq + lqd;
        lq = nlq;
        lqd = nlqd;
      }
    }
    return g;
  }

  Eigen::MatrixXd jacobian(const Eigen::VectorXd&) const override {
    if (J_.size() == 0) {
      const Eigen::Index K = K_, n = js_.n, Kn = K * n;
      J_ = Eigen::MatrixXd::Zero(3 * Kn, numVariables());
      for (int i = 0; i < nm_; ++i) {
        const Eigen::Index j = js_.moving[static_cast<std::size_t>(i)],
                           c = static_cast<Eigen::Index>(i) * K;
        for (Eigen::Index k = 0; k < K; ++k) {
          for (Eigen::Index l = 0; l < k; ++l) {
            J_(j * K + k, c + l) = dt_ * dt_ * (static_cast<double>(k - l) - 0.5);
            J_(Kn + j * K + k, c + l) = dt_;
          }
          J_(2 * Kn + j * K + k, c + k) = 1.0;
        }
      }
    }
    return J_;
  }

  double positionMargin() const override { return opt_.margin; }
  bool velocityLimits() const override { return opt_.velocity_limits || js_.hasVelocityCap(); }
  bool accelerationLimits() const override {
    return opt_.acceleration_limits || js_.hasAccelerationCap();
  }
  void adjustLimits(std::vector<exid::JointLimits>* limits) const override {
    exid::trajectories::adjustLimitsCommon(js_, opt_, limits);
  }
  // Defined at the samples only (the accelerations are the variables): not continuous.
  exid::TrajectorySpecs specs() const override {
    exid::TrajectorySpecs sp = exid::trajectories::specsCommon(js_, true);
    sp.duration_s = D_;
    return sp;
  }
  exid::Json describe() const override {
    exid::Json d = exid::trajectories::describeCommon(js_, opt_, true);
    d["samples"] = K_;
    d["sample_period_s"] = dt_;
    d["init"] = init_;
    return d;
  }

 private:
  void loadCsv(const std::filesystem::path& path, const std::string& who) {
    exid::CsvTable T = exid::readCsv(path);
    exid::check(T.has("t"), fmt::format("{}: init_csv {}: no column t", who, path.string()));
    const int N = static_cast<int>(T.data.rows());
    exid::check(N >= 2, fmt::format("{}: init_csv {}: fewer than 2 rows", who, path.string()));
    bool has_qdd = true, has_q = true;
    for (int j : js_.moving) {
      has_qdd = has_qdd && T.has(fmt::format("qdd{}", j + 1));
      has_q = has_q && T.has(fmt::format("q{}", j + 1));
    }
    exid::check(has_qdd || has_q,
                fmt::format("{}: init_csv {}: needs columns qdd<j> or q<j> for every moving joint",
                            who, path.string()));
    if (has_qdd) {
      exid::check(N >= K_, fmt::format("{}: init_csv {}: {} rows, {} samples needed", who,
                                       path.string(), N, K_));
      for (int i = 0; i < nm_; ++i) {
        const int j = js_.moving[static_cast<std::size_t>(i)];
        z0_.segment(i * K_, K_) = T.column(fmt::format("qdd{}", j + 1)).head(K_);
        if (T.has(fmt::format("q{}", j + 1))) X0q_(j) = T.column(fmt::format("q{}", j + 1))(0);
        if (T.has(fmt::format("qd{}", j + 1))) X0qd_(j) = T.column(fmt::format("qd{}", j + 1))(0);
      }
      return;
    }
    // One period of a periodic q: trigonometric interpolation, exact derivative.
    const Eigen::VectorXd t = T.column("t");
    const double dtc = (t(N - 1) - t(0)) / (N - 1);
    const double Tp = N * dtc, w = 2.0 * M_PI / Tp;
    for (int i = 0; i < nm_; ++i) {
      const int j = js_.moving[static_cast<std::size_t>(i)];
      const Eigen::VectorXd x = T.column(fmt::format("q{}", j + 1));
      const int M = N / 2;
      Eigen::VectorXd a(M + 1), b(M + 1);
      for (int m = 0; m <= M; ++m) {
        double sa = 0, sb = 0;
        for (int r = 0; r < N; ++r) {
          sa += x(r) * exid::fmath::cos(2.0 * M_PI * m * r / N);
          sb += x(r) * exid::fmath::sin(2.0 * M_PI * m * r / N);
        }
        const bool edge = m == 0 || (N % 2 == 0 && m == M);
        a(m) = (edge ? 1.0 : 2.0) * sa / N;
        b(m) = edge ? 0.0 : 2.0 * sb / N;
      }
      auto qd_at = [&](double tt) {
        double v = 0;
        for (int m = 1; m <= M; ++m)
          v += w * m * (-a(m) * exid::fmath::sin(w * m * tt) + b(m) * exid::fmath::cos(w * m * tt));
        return v;
      };
      double q0 = 0;
      for (int m = 0; m <= M; ++m) q0 += a(m);  // x(0)
      X0q_(j) = q0;
      X0qd_(j) = qd_at(0.0);
      for (int k = 0; k < K_; ++k) z0_(i * K_ + k) = (qd_at((k + 1) * dt_) - qd_at(k * dt_)) / dt_;
    }
  }

  exid::trajectories::CommonOptions opt_;
  exid::trajectories::JointSpace js_;
  double D_;
  std::vector<double> q0_param_;
  std::string init_;
  double amp_, freq_;
  std::string csv_;
  int K_ = 0, nm_ = 0;
  double dt_ = 0.1;
  Eigen::VectorXd X0q_, X0qd_, z0_;
  mutable Eigen::MatrixXd J_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Pointwise)
