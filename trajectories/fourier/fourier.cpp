// Trajectory `fourier`: a finite Fourier series per moving joint (Swevers et al. 1997)
//   q_j(t) = q0_j + sum_{l=1..L} a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t),  w = 2 pi / T,
//   qd_j(t) = sum a_jl cos(w l t) + b_jl sin(w l t),
//   qdd_j(t) = sum -a_jl w l sin(w l t) + b_jl w l cos(w l t).
// Decision variables per moving joint: [q0_j, a_j1..a_jL, b_j1..b_jL]. Periodic and
// band-limited; sampled over one period (t = 0, dt, ..., T - dt), and defined at any time
// (evaluateAt). Linear in z: the Jacobian is constant and cached.
// rest_to_rest: qd(0) = sum_l a_l = 0 and qdd(0) = w sum_l l b_l = 0 (hence also at T), by
// eliminating a_1 = -sum_{l>=2} a_l and b_1 = -sum_{l>=2} l b_l; the variables per joint are
// then [s_j, a_j2..a_jL, b_j2..b_jL] with s_j = q(0) the start position, or, when
// start_position_rad fixes it, [a_j2..a_jL, b_j2..b_jL] with q = start_j + the series.
#include <fmt/format.h>

#include <cmath>
#include <random>

#include "exid/error.hpp"
#include "exid/fmath.hpp"
#include "exid/trajectories/traj_common.hpp"

namespace {

class Fourier final : public exid::trajectories::BasisTrajectory {
 public:
  static constexpr const char* kName = "fourier";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "finite Fourier series per joint (Swevers): q = q0 + sum a_l/(w l) sin(w l t) - b_l/(w l) "
      "cos(w l t); variables [q0, a_1..a_L, b_1..b_L] per moving joint; periodic, one period "
      "sampled";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::trajectories::commonParams();
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
                                    "q0, a_1..a_L, b_1..b_L; with rest_to_rest: [q(0),] "
                                    "a_2..a_L, b_2..b_L)"));
    for (auto& d : exid::trajectories::restToRestParams()) p.push_back(d);
    return p;
  }

  explicit Fourier(const exid::ParamSet& p)
      : period_(p.getDouble("period_s")),
        L_(static_cast<int>(p.getInt("harmonics"))),
        init_(p.getString("init")),
        init_scale_(p.getDouble("init_scale")),
        seed_(static_cast<std::uint64_t>(p.getInt("seed"))),
        coeffs_(p.getDoubles("init_coefficients")),
        rest_(p.getBool("rest_to_rest")),
        start_(p.getDoubles("start_position_rad")) {
    opt_ = exid::trajectories::readCommon(p);
    exid::check(rest_ || start_.empty(),
                "trajectory 'fourier': start_position_rad is given without rest_to_rest: true");
    exid::check(!rest_ || L_ >= 2,
                "trajectory 'fourier': rest_to_rest needs harmonics >= 2 (one harmonic at rest at "
                "both ends does not move)");
  }

  void bind(std::shared_ptr<const exid::RobotModel> robot, const exid::RunContext& ctx) override {
    const std::string who = "trajectory 'fourier'";
    js_ = exid::trajectories::resolveJoints(*robot, opt_, who);
    const int K = exid::trajectories::sampleCount(opt_, period_, false, who, "period_s");
    const double dt = opt_.samples > 0 ? period_ / K : opt_.sample_period;
    w_ = 2.0 * M_PI / period_;
    const double w = w_;
    Eigen::VectorXd t(K);
    const int mf = 1 + 2 * L_;  // full coefficients per joint
    // Reduced variables -> full coefficients (identity unless rest_to_rest).
    q_offset_ = exid::trajectories::resolveStart(js_, start_, who);
    const bool fixed_start = q_offset_.size() > 0;
    const int m = rest_ ? 2 * (L_ - 1) + (fixed_start ? 0 : 1) : mf;
    P_ = Eigen::MatrixXd::Zero(mf, m);
    if (!rest_) {
      P_.setIdentity();
    } else {
      const int o = fixed_start ? 0 : 1;  // column of the first coefficient variable
      if (!fixed_start) P_(0, 0) = 1.0;   // q(0) = q0 - sum b_l / (w l)
      for (int l = 2; l <= L_; ++l) {
        const int ca = o + (l - 2), cb = o + (L_ - 1) + (l - 2);
        P_(l, ca) = 1.0;       // a_l
        P_(1, ca) = -1.0;      // a_1 = -sum a_l
        P_(L_ + l, cb) = 1.0;  // b_l
        P_(L_ + 1, cb) = -l;   // b_1 = -sum l b_l
        // q0 = q(0) + sum_l b_l / (w l) with b_1 substituted
        P_(0, cb) = 1.0 / (w * l) - l / w;
      }
    }
    for (int k = 0; k < K; ++k) t(k) = k * dt;
    setGrid(t, m);
    // start
    const int nv = numVariables();
    zref_ = Eigen::VectorXd::Zero(nv);
    const int c_first = rest_ ? (fixed_start ? 0 : 1) : 1;  // first coefficient variable
    if (c_first == 1)
      for (std::size_t i = 0; i < js_.moving.size(); ++i)
        zref_(static_cast<Eigen::Index>(i) * m) = js_.centre(js_.moving[i]);
    z0_ = zref_;
    if (init_ == "random") {
      std::mt19937_64 rng(seed_ ? seed_ : ctx.seed);
      std::uniform_real_distribution<double> U(-1.0, 1.0);
      for (std::size_t i = 0; i < js_.moving.size(); ++i)
        for (int c = c_first; c < m; ++c) z0_(static_cast<Eigen::Index>(i) * m + c) = U(rng);
      scaleIntoLimits(&z0_, zref_, init_scale_);
    } else if (init_ == "coefficients") {
      exid::check(
          static_cast<int>(coeffs_.size()) == nv,
          fmt::format(
              "{}: init_coefficients has {} values (expected {} = {} joints x {} per joint)", who,
              coeffs_.size(), nv, js_.moving.size(), m));
      z0_ = Eigen::Map<const Eigen::VectorXd>(coeffs_.data(), nv);
    }
    // Bounds (necessary conditions, valid for every feasible z): q0 within the range; the l-th
    // coefficient pair is at most twice the amplitude of qd, of q (times w l), of qdd / (w l).
    // With rest_to_rest the same bounds hold for the remaining variables (q(0) within the
    // range; a_l, b_l for l >= 2).
    lo_ = Eigen::VectorXd::Constant(nv, -HUGE_VAL);
    hi_ = Eigen::VectorXd::Constant(nv, HUGE_VAL);
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      const Eigen::Index c0 = static_cast<Eigen::Index>(i) * m;
      if (c_first == 1) {
        lo_(c0) = js_.q_lo(j);
        hi_(c0) = js_.q_hi(j);
      }
      for (int l = 1; l <= L_; ++l) {
        double b = HUGE_VAL;
        const double wl = w * l;
        if (std::isfinite(js_.qd_max(j))) b = std::min(b, 2.0 * js_.qd_max(j));
        if (std::isfinite(js_.q_hi(j) - js_.q_lo(j)))
          b = std::min(b, 2.0 * (js_.q_hi(j) - js_.q_lo(j)) * wl);
        if (std::isfinite(js_.qdd_max(j))) b = std::min(b, 2.0 * js_.qdd_max(j) / wl);
        if (rest_ && l == 1) continue;  // a_1, b_1 eliminated
        const Eigen::Index ca = rest_ ? c0 + c_first + (l - 2) : c0 + l,
                           cb = rest_ ? c0 + c_first + (L_ - 1) + (l - 2) : c0 + L_ + l;
        for (Eigen::Index c : {ca, cb}) {
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
    sp.repeatable = true;
    sp.rest_to_rest = rest_;
    sp.duration_s = period_;
    return sp;
  }
  exid::Json describe() const override {
    exid::Json d = BasisTrajectory::describe();
    d["period_s"] = period_;
    d["harmonics"] = L_;
    d["init"] = init_;
    if (rest_) {
      d["rest_to_rest"] = true;
      if (q_offset_.size())
        d["start_position_rad"] =
            exid::Json(std::vector<double>(q_offset_.data(), q_offset_.data() + q_offset_.size()));
    }
    return d;
  }
  exid::Json parametersAt(const Eigen::VectorXd& z) const override {
    exid::Json d = exid::Json::object();
    d["form"] = "q_j(t) = q0_j + sum_l a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t)";
    d["period_s"] = period_;
    d["omega_rad_s"] = w_;
    d["harmonics"] = L_;
    d["rest_to_rest"] = rest_;
    const int m = static_cast<int>(P_.cols());
    exid::Json joints = exid::Json::array();
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      const Eigen::VectorXd c = P_ * z.segment(static_cast<Eigen::Index>(i) * m, m);
      exid::Json x = exid::Json::object();
      x["joint"] = j + 1;
      x["q0_rad"] = c(0) + offset(j);
      x["a_rad_s"] = exid::Json(std::vector<double>(c.data() + 1, c.data() + 1 + L_));
      x["b_rad_s"] = exid::Json(std::vector<double>(c.data() + 1 + L_, c.data() + 1 + 2 * L_));
      joints.push_back(x);
    }
    d["joints"] = joints;
    return d;
  }

 protected:
  void basisAt(double t, Eigen::RowVectorXd* bq, Eigen::RowVectorXd* bqd,
               Eigen::RowVectorXd* bqdd) const override {
    if (!rest_) {
      fullBasisAt(t, bq, bqd, bqdd);
      return;
    }
    Eigen::RowVectorXd fq, fqd, fqdd;
    fullBasisAt(t, &fq, &fqd, &fqdd);
    *bq = fq * P_;
    *bqd = fqd * P_;
    *bqdd = fqdd * P_;
  }

 private:
  void fullBasisAt(double t, Eigen::RowVectorXd* bq, Eigen::RowVectorXd* bqd,
                   Eigen::RowVectorXd* bqdd) const {
    const int m = 1 + 2 * L_;
    bq->setZero(m);
    bqd->setZero(m);
    bqdd->setZero(m);
    (*bq)(0) = 1.0;
    for (int l = 1; l <= L_; ++l) {
      const double wl = w_ * l;
      double s, c;
      exid::fmath::sincos(wl * t, &s, &c);  // exid's: the same bits on every CPU
      (*bq)(l) = s / wl;
      (*bq)(L_ + l) = -c / wl;
      (*bqd)(l) = c;
      (*bqd)(L_ + l) = s;
      (*bqdd)(l) = -wl * s;
      (*bqdd)(L_ + l) = wl * c;
    }
  }

  double period_;
  double w_ = 0.0;  // 2 pi / period_
  int L_;
  std::string init_;
  double init_scale_;
  std::uint64_t seed_;
  std::vector<double> coeffs_;
  bool rest_;
  std::vector<double> start_;
  Eigen::MatrixXd P_;  // reduced variables -> full coefficients, per joint
  Eigen::VectorXd z0_, zref_, lo_, hi_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Fourier)
