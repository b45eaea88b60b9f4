// Trajectory `fourier`: a finite Fourier series per moving joint (Swevers et al. 1997)
//   q_j(t) = q0_j + sum_{l=1..L} a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t),  w = 2 pi / T,
//   qd_j(t) = sum a_jl cos(w l t) + b_jl sin(w l t),
//   qdd_j(t) = sum -a_jl w l sin(w l t) + b_jl w l cos(w l t).
// Decision variables per moving joint: [q0_j, a_j1..a_jL, b_j1..b_jL]. Periodic and
// band-limited; sampled over one period (t = 0, dt, ..., T - dt), and defined at any time
// (evaluateAt). Linear in z: the Jacobian is constant and cached.
#include <fmt/format.h>

#include <cmath>
#include <random>

#include "exid/error.hpp"
#include "traj_common.hpp"

namespace {

class Fourier final : public exid::traj::BasisTrajectory {
 public:
  static constexpr const char* kName = "fourier";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "finite Fourier series per joint (Swevers): q = q0 + sum a_l/(w l) sin(w l t) - b_l/(w l) "
      "cos(w l t); variables [q0, a_1..a_L, b_1..b_L] per moving joint; periodic, one period "
      "sampled";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::traj::commonParams();
    p.push_back(
        exid::param_double("period_s", 10.0, "s", "fundamental period T", 0.0, std::nullopt, true));
    p.push_back(exid::param_int("harmonics", 5, "number of harmonics L", 1.0, 1000.0));
    p.push_back(exid::param_string("init", std::string("random"),
                                   "start: random coefficients (seed) scaled to init_scale of the "
                                   "limits, offsets at the centre; zero: offsets at the centre, no "
                                   "motion; coefficients: init_coefficients",
                                   {"random", "zero", "coefficients"}));
    p.push_back(exid::param_double("init_scale", 0.5, "",
                                   "fraction of the tightest of position range, velocity and "
                                   "acceleration limits the random start uses",
                                   0.0, 1.0, true));
    p.push_back(exid::param_int("seed", 0, "seed of the random start (0: the study seed)", 0.0));
    p.push_back(exid::param_doubles("init_coefficients", std::vector<double>{}, "",
                                    "with init: coefficients, z itself (moving joint after joint: "
                                    "q0, a_1..a_L, b_1..b_L)"));
    return p;
  }

  explicit Fourier(const exid::ParamSet& p)
      : period_(p.getDouble("period_s")),
        L_(static_cast<int>(p.getInt("harmonics"))),
        init_(p.getString("init")),
        init_scale_(p.getDouble("init_scale")),
        seed_(static_cast<std::uint64_t>(p.getInt("seed"))),
        coeffs_(p.getDoubles("init_coefficients")) {
    opt_ = exid::traj::readCommon(p);
  }

  void bind(std::shared_ptr<const exid::RobotModel> robot, const exid::RunContext& ctx) override {
    const std::string who = "trajectory 'fourier'";
    js_ = exid::traj::resolveJoints(*robot, opt_, who);
    const int K = exid::traj::sampleCount(opt_, period_, false, who, "period_s");
    const double dt = opt_.samples > 0 ? period_ / K : opt_.sample_period;
    w_ = 2.0 * M_PI / period_;
    const double w = w_;
    Eigen::VectorXd t(K);
    const int m = 1 + 2 * L_;
    for (int k = 0; k < K; ++k) t(k) = k * dt;
    setGrid(t, m);
    // start
    const int nv = numVariables();
    zref_ = Eigen::VectorXd::Zero(nv);
    for (std::size_t i = 0; i < js_.moving.size(); ++i)
      zref_(static_cast<Eigen::Index>(i) * m) = js_.centre(js_.moving[i]);
    z0_ = zref_;
    if (init_ == "random") {
      std::mt19937_64 rng(seed_ ? seed_ : ctx.seed);
      std::uniform_real_distribution<double> U(-1.0, 1.0);
      for (std::size_t i = 0; i < js_.moving.size(); ++i)
        for (int c = 1; c < m; ++c) z0_(static_cast<Eigen::Index>(i) * m + c) = U(rng);
      scaleIntoLimits(&z0_, zref_, init_scale_);
    } else if (init_ == "coefficients") {
      exid::check(
          static_cast<int>(coeffs_.size()) == nv,
          fmt::format(
              "{}: init_coefficients has {} values (expected {} = {} joints x (1 + 2 x {}))", who,
              coeffs_.size(), nv, js_.moving.size(), L_));
      z0_ = Eigen::Map<const Eigen::VectorXd>(coeffs_.data(), nv);
    }
    // Bounds (necessary conditions, valid for every feasible z): q0 within the range; the l-th
    // coefficient pair is at most twice the amplitude of qd, of q (times w l), of qdd / (w l).
    lo_ = Eigen::VectorXd::Constant(nv, -HUGE_VAL);
    hi_ = Eigen::VectorXd::Constant(nv, HUGE_VAL);
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      const Eigen::Index c0 = static_cast<Eigen::Index>(i) * m;
      lo_(c0) = js_.q_lo(j);
      hi_(c0) = js_.q_hi(j);
      for (int l = 1; l <= L_; ++l) {
        double b = HUGE_VAL;
        const double wl = w * l;
        if (std::isfinite(js_.qd_max(j))) b = std::min(b, 2.0 * js_.qd_max(j));
        if (std::isfinite(js_.q_hi(j) - js_.q_lo(j)))
          b = std::min(b, 2.0 * (js_.q_hi(j) - js_.q_lo(j)) * wl);
        if (std::isfinite(js_.qdd_max(j))) b = std::min(b, 2.0 * js_.qdd_max(j) / wl);
        for (Eigen::Index c : {c0 + l, c0 + L_ + l}) {
          lo_(c) = -b;
          hi_(c) = b;
        }
      }
    }
  }

  Eigen::VectorXd initial() const override { return z0_; }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override {
    if (lo) *lo = lo_;
    if (hi) *hi = hi_;
  }
  exid::TrajectorySpecs specs() const override {
    exid::TrajectorySpecs sp = basisSpecs();
    sp.periodic = true;
    sp.duration_s = period_;
    return sp;
  }
  exid::Json describe() const override {
    exid::Json d = BasisTrajectory::describe();
    d["period_s"] = period_;
    d["harmonics"] = L_;
    d["init"] = init_;
    return d;
  }

 protected:
  void basisAt(double t, Eigen::RowVectorXd* bq, Eigen::RowVectorXd* bqd,
               Eigen::RowVectorXd* bqdd) const override {
    const int m = 1 + 2 * L_;
    bq->setZero(m);
    bqd->setZero(m);
    bqdd->setZero(m);
    (*bq)(0) = 1.0;
    for (int l = 1; l <= L_; ++l) {
      const double wl = w_ * l, s = std::sin(wl * t), c = std::cos(wl * t);
      (*bq)(l) = s / wl;
      (*bq)(L_ + l) = -c / wl;
      (*bqd)(l) = c;
      (*bqd)(L_ + l) = s;
      (*bqdd)(l) = -wl * s;
      (*bqdd)(L_ + l) = wl * c;
    }
  }

 private:
  double period_;
  double w_ = 0.0;  // 2 pi / period_
  int L_;
  std::string init_;
  double init_scale_;
  std::uint64_t seed_;
  std::vector<double> coeffs_;
  Eigen::VectorXd z0_, zref_, lo_, hi_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Fourier)
