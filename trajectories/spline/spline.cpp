// Trajectory `spline`: per moving joint a cubic (C2) or quintic (C4) spline through `knots`
// uniformly spaced knots over `duration_s`. Decision variables: the knot values. boundary:
// rest — the motion starts and ends at rest (qd = 0, and for the quintic also qdd = 0, at both
// ends; the cubic is the clamped spline); periodic — q, and derivatives 1..degree-1 continuous
// across the period end (the last knot equals the first, knots - 1 variables per joint).
// rest_to_rest (quintic, boundary rest): qd = qdd = 0 at both ends; with start_position_rad the
// first and last knots are that position, and the variables are the interior knots relative to
// it (q = start + sum of the interior knots' basis times their offsets: the interpolating spline
// of constant knots is that constant).
// The map knot values -> spline coefficients is linear (one banded system, solved once for
// every unit vector at bind()), so the signals at the samples, or at any time (evaluateAt), are
// a basis times z.
#include <fmt/format.h>

#include <cmath>
#include <random>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/trajectories/traj_common.hpp"

namespace {

class Spline final : public exid::trajectories::BasisTrajectory {
 public:
  static constexpr const char* kName = "spline";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "cubic (C2) or quintic (C4) interpolating splines through uniformly spaced knots per joint; "
      "variables: knot values; boundary rest (starts and ends at rest) or periodic";

  static std::vector<exid::ParamDecl> params() {
    auto p = exid::trajectories::commonParams();
    p.push_back(exid::param_double("duration_s", 10.0, "s", "duration (the period when periodic)",
                                   0.0, std::nullopt, true));
    p.push_back(exid::param_int("knots", 10, "number of knots, both ends included", 3.0, 10000.0));
    p.push_back(exid::param_int("degree", 3, "3: cubic (C2); 5: quintic (C4)", 3.0, 5.0));
    p.push_back(exid::param_string("boundary", std::string("rest"),
                                   "rest: qd = 0 (quintic: and qdd = 0) at both ends; periodic",
                                   {"rest", "periodic"}));
    p.push_back(exid::param_string("init", std::string("random"),
                                   "start: random knots (seed) scaled to init_scale of the limits "
                                   "about the centre; knots: init_knots",
                                   {"random", "knots"}));
    p.push_back(exid::param_double("init_scale", 0.5, "",
                                   "fraction of the tightest limit the random start uses", 0.0, 1.0,
                                   true));
    p.push_back(exid::param_int("seed", 0, "seed of the random start (0: the study seed)", 0.0));
    p.push_back(exid::param_doubles("init_knots", std::vector<double>{}, "rad",
                                    "with init: knots, z itself (moving joint after joint; "
                                    "with start_position_rad: the interior knots less it)"));
    for (auto& d : exid::trajectories::restToRestParams()) p.push_back(d);
    return p;
  }

  explicit Spline(const exid::ParamSet& p)
      : D_(p.getDouble("duration_s")),
        knots_(static_cast<int>(p.getInt("knots"))),
        degree_(static_cast<int>(p.getInt("degree"))),
        periodic_(p.getString("boundary") == "periodic"),
        init_(p.getString("init")),
        init_scale_(p.getDouble("init_scale")),
        seed_(static_cast<std::uint64_t>(p.getInt("seed"))),
        init_knots_(p.getDoubles("init_knots")),
        rest_(p.getBool("rest_to_rest")),
        start_(p.getDoubles("start_position_rad")) {
    opt_ = exid::trajectories::readCommon(p);
    exid::check(degree_ == 3 || degree_ == 5,
                fmt::format("trajectory 'spline': degree {} (use 3 or 5)", degree_));
    exid::check(rest_ || start_.empty(),
                "trajectory 'spline': start_position_rad is given without rest_to_rest: true");
    exid::check(!rest_ || (degree_ == 5 && !periodic_),
                "trajectory 'spline': rest_to_rest needs degree: 5 and boundary: rest (the cubic "
                "spline ends with zero velocity but not zero acceleration)");
  }

  void bind(std::shared_ptr<const exid::RobotModel> robot, const exid::RunContext& ctx) override {
    const std::string who = "trajectory 'spline'";
    js_ = exid::trajectories::resolveJoints(*robot, opt_, who);
    S_ = knots_ - 1;
    const int S = S_, d = degree_, nc = d + 1;
    const int nk = periodic_ ? knots_ - 1 : knots_;  // independent knots per joint
    q_offset_ = exid::trajectories::resolveStart(js_, start_, who);
    const bool fixed_start = q_offset_.size() > 0;
    const int nv = fixed_start ? knots_ - 2 : nk;  // variables per joint
    h_ = D_ / S;
    const double h = h_;
    const int N = nc * S;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(N, N), R = Eigen::MatrixXd::Zero(N, nk);
    int row = 0;
    auto knotVar = [&](int i) { return periodic_ ? i % nk : i; };
    for (int i = 0; i < S; ++i) {
      for (int p = 0; p <= d; ++p) A(row, i * nc + p) = dpow(p, 0, 0.0);
      R(row++, knotVar(i)) = 1.0;
      for (int p = 0; p <= d; ++p) A(row, i * nc + p) = dpow(p, 0, h);
      R(row++, knotVar(i + 1)) = 1.0;
    }
    for (int i = 1; i < S; ++i)
      for (int r = 1; r < d; ++r, ++row)
        for (int p = 0; p <= d; ++p) {
          A(row, (i - 1) * nc + p) += dpow(p, r, h);
          A(row, i * nc + p) -= dpow(p, r, 0.0);
        }
    if (periodic_) {
      for (int r = 1; r < d; ++r, ++row)
        for (int p = 0; p <= d; ++p) {
          A(row, (S - 1) * nc + p) += dpow(p, r, h);
          A(row, p) -= dpow(p, r, 0.0);
        }
    } else {
      for (int r = 1; r <= (d - 1) / 2; ++r) {
        for (int p = 0; p <= d; ++p) A(row, p) = dpow(p, r, 0.0);
        ++row;
        for (int p = 0; p <= d; ++p) A(row, (S - 1) * nc + p) = dpow(p, r, h);
        ++row;
      }
    }
    exid::check(row == N, "trajectory 'spline': internal: system size");
    C_ = A.fullPivLu().solve(R);  // coefficients per unit knot vector
    if (fixed_start) {
      const Eigen::MatrixXd interior = C_.middleCols(1, nv);
      C_ = interior;  // the end knots are the start position (the constant offset)
    }
    const int K = exid::trajectories::sampleCount(opt_, D_, !periodic_, who);
    const double dt = opt_.samples > 0 ? D_ / (periodic_ ? K : K - 1) : opt_.sample_period;
    Eigen::VectorXd t(K);
    for (int k = 0; k < K; ++k) t(k) = k * dt;
    setGrid(t, nv);
    const int n_all = numVariables();
    Eigen::VectorXd zref = Eigen::VectorXd::Zero(n_all);
    if (!fixed_start)
      for (std::size_t i = 0; i < js_.moving.size(); ++i)
        zref.segment(static_cast<Eigen::Index>(i) * nv, nv).setConstant(js_.centre(js_.moving[i]));
    if (init_ == "knots") {
      exid::check(static_cast<int>(init_knots_.size()) == n_all,
                  fmt::format("{}: init_knots has {} values (expected {})", who, init_knots_.size(),
                              n_all));
      z0_ = Eigen::Map<const Eigen::VectorXd>(init_knots_.data(), n_all);
    } else {
      std::mt19937_64 rng(seed_ ? seed_ : ctx.seed);
      std::uniform_real_distribution<double> U(-1.0, 1.0);
      z0_ = zref;
      for (Eigen::Index i = 0; i < n_all; ++i) z0_(i) += U(rng);
      scaleIntoLimits(&z0_, zref, init_scale_);
    }
    lo_.resize(n_all);
    hi_.resize(n_all);
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      lo_.segment(static_cast<Eigen::Index>(i) * nv, nv).setConstant(js_.q_lo(j) - offset(j));
      hi_.segment(static_cast<Eigen::Index>(i) * nv, nv).setConstant(js_.q_hi(j) - offset(j));
    }
  }

  Eigen::VectorXd initial() const override { return z0_; }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override {
    if (lo) *lo = lo_;
    if (hi) *hi = hi_;
  }
  exid::TrajectorySpecs specs() const override {
    exid::TrajectorySpecs sp = basisSpecs();
    sp.periodic = periodic_;
    sp.rest_to_rest = rest_;
    sp.repeatable = periodic_ || (rest_ && q_offset_.size() > 0);
    sp.duration_s = D_;
    return sp;
  }
  exid::Json parametersAt(const Eigen::VectorXd& z) const override {
    exid::Json d = exid::Json::object();
    d["form"] = fmt::format("{} interpolating spline through uniformly spaced knots",
                            degree_ == 3 ? "cubic (C2)" : "quintic (C4)");
    d["duration_s"] = D_;
    d["degree"] = degree_;
    d["boundary"] = periodic_ ? "periodic" : "rest";
    d["rest_to_rest"] = rest_;
    std::vector<double> tk;
    for (int i = 0; i < knots_; ++i) tk.push_back(i * h_);
    d["knot_times_s"] = exid::Json(tk);
    exid::Json joints = exid::Json::array();
    const int nv = m_;
    for (std::size_t i = 0; i < js_.moving.size(); ++i) {
      const int j = js_.moving[i];
      const Eigen::VectorXd zj = z.segment(static_cast<Eigen::Index>(i) * nv, nv);
      std::vector<double> kv;
      if (q_offset_.size()) {
        kv.push_back(offset(j));
        for (int c = 0; c < nv; ++c) kv.push_back(zj(c) + offset(j));
        kv.push_back(offset(j));
      } else {
        for (int c = 0; c < nv; ++c) kv.push_back(zj(c));
        if (periodic_) kv.push_back(zj(0));
      }
      exid::Json x = exid::Json::object();
      x["joint"] = j + 1;
      x["knots_rad"] = exid::Json(kv);
      joints.push_back(x);
    }
    d["joints"] = joints;
    return d;
  }
  exid::Json describe() const override {
    exid::Json d = BasisTrajectory::describe();
    d["duration_s"] = D_;
    d["knots"] = knots_;
    d["degree"] = degree_;
    d["boundary"] = periodic_ ? "periodic" : "rest";
    return d;
  }

 protected:
  // Segment i = floor(t / h) (the last one up to the end), tau = t - i h; each row is the
  // derivative of the segment's polynomial times its coefficients per unit knot vector.
  void basisAt(double t, Eigen::RowVectorXd* bq, Eigen::RowVectorXd* bqd,
               Eigen::RowVectorXd* bqdd) const override {
    const int d = degree_, nc = d + 1;
    int i = std::min(S_ - 1, static_cast<int>(std::floor(t / h_ + 1e-12)));
    i = std::max(i, 0);
    const double tau = t - i * h_;
    Eigen::RowVectorXd e(nc);
    for (int r = 0; r < 3; ++r) {
      for (int p = 0; p <= d; ++p) e(p) = dpow(p, r, tau);
      (r == 0 ? *bq : (r == 1 ? *bqd : *bqdd)) = e * C_.middleRows(i * nc, nc);
    }
  }

 private:
  // derivative factor: d^r/dtau^r tau^p = p!/(p-r)! tau^(p-r)
  static double dpow(int p, int r, double tau) {
    if (r > p) return 0.0;
    double f = 1.0;
    for (int i = 0; i < r; ++i) f *= p - i;
    return f * std::pow(tau, p - r);
  }

  double D_;
  int knots_, degree_;
  int S_ = 0;          // segments (knots - 1)
  double h_ = 0.0;     // segment length [s]
  Eigen::MatrixXd C_;  // polynomial coefficients (segment after segment) per unit knot vector
  bool periodic_;
  std::string init_;
  double init_scale_;
  std::uint64_t seed_;
  std::vector<double> init_knots_;
  bool rest_;
  std::vector<double> start_;
  Eigen::VectorXd z0_, lo_, hi_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Spline)
