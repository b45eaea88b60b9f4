// A small observation model with known full columns for the estimator tests and benchmark:
// n measurements ("joints") of pendulums that share one set of parameters, each with its own
// torque offset:
//   tau_j = (ZZ1 + Ia1) qdd_j + g (MX1 cos q_j - MY1 sin q_j) + Fv1 qd_j + Fc1 sign(qd_j) + OFFj
// ZZ1 and Ia1 share the column qdd_j, so the base parameters regroup them (ZZ1R = ZZ1 + Ia1):
// the names and expressions must come from model.base(). Rows are sample-major (k * n + j),
// equation j. Optional extra pseudo-random columns (`extra`) make p larger for the benchmark.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/interfaces.hpp"

namespace est_test {

inline std::shared_ptr<const exid::RobotModel> makeRobot(int n) {
  auto r = std::make_shared<exid::RobotModel>();
  r->name = "test_pendulums";
  r->source = "estimator tests";
  for (int j = 0; j < n; ++j) {
    exid::Body b;
    b.name = "link" + std::to_string(j + 1);
    b.joint_name = "joint" + std::to_string(j + 1);
    b.parent = j - 1;
    b.inertia << 0.1, 0, 0, 0.1, 0, 0.5, 0.8, -0.3, 0, 2.0;
    r->bodies.push_back(b);
    r->limits.push_back(exid::JointLimits{});
    r->drives.push_back(exid::Drive{});
  }
  return r;
}

class PendulumModel : public exid::ObservationModel {
 public:
  static constexpr double kG = 9.81;
  /// n joints; `extra` additional pseudo-random columns (hashUnit) with parameters X1..Xextra.
  explicit PendulumModel(int n = 1, int extra = 0) : n_(n), extra_(extra) {
    setPluginName("test_pendulum");
  }

  std::vector<std::string> fullNames() const override {
    std::vector<std::string> v = {"ZZ1", "MX1", "MY1", "Fv1", "Fc1", "Ia1"};
    for (int j = 0; j < n_; ++j) v.push_back("OFF" + std::to_string(j + 1));
    for (int c = 0; c < extra_; ++c) v.push_back("X" + std::to_string(c + 1));
    return v;
  }
  Eigen::VectorXd fullNominal() const override {
    Eigen::VectorXd v(6 + n_ + extra_);
    v.head(6) << 0.5, 0.8, -0.3, 0.2, 0.4, 0.1;
    for (int j = 0; j < n_; ++j) v(6 + j) = 0.05 * (j + 1);
    for (int c = 0; c < extra_; ++c) v(6 + n_ + c) = 0.1 * (c + 1);
    return v;
  }
  int numFullCols() const { return 6 + n_ + extra_; }

  /// The full row of joint j at one sample.
  void fullRow(int j, double q, double qd, double qdd, Eigen::Ref<Eigen::RowVectorXd> w) const {
    w.setZero();
    w(0) = qdd;
    w(1) = kG * std::cos(q);
    w(2) = -kG * std::sin(q);
    w(3) = qd;
    w(4) = qd > 0 ? 1.0 : (qd < 0 ? -1.0 : 0.0);
    w(5) = qdd;
    w(6 + j) = 1.0;
    for (int c = 0; c < extra_; ++c) w(6 + n_ + c) = hashUnit(c, q, qd, qdd);
  }

  /// A deterministic pseudo-random number in [-1, 1) from (c, q, qd, qdd): columns of a random
  /// linear system (independent, unlike smooth functions of q on a periodic path).
  static double hashUnit(int c, double q, double qd, double qdd) {
    std::uint64_t h = 0x9e3779b97f4a7c15ull * static_cast<std::uint64_t>(c + 1);
    for (double v : {q, qd, qdd}) {
      std::uint64_t b;
      std::memcpy(&b, &v, sizeof b);
      h ^= b + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
      h = (h ^ (h >> 30)) * 0xbf58476d1ce4e5b9ull;
      h = (h ^ (h >> 27)) * 0x94d049bb133111ebull;
      h ^= h >> 31;
    }
    return static_cast<double>(h >> 11) * 0x1.0p-52 - 1.0;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    exid::check(d.hasVelocity() && d.hasAcceleration() && d.hasTorque(),
                "test model: needs q, qd, qdd, tau");
    const int K = d.size();
    for (int seen = max_samples_per_call.load();
         K > seen && !max_samples_per_call.compare_exchange_weak(seen, K);) {
    }  // (rows may be asked for on several threads at once)
    exid::Rows r;
    r.W.resize(static_cast<Eigen::Index>(K) * n_, numFullCols());
    r.y.resize(static_cast<Eigen::Index>(K) * n_);
    r.equation.resize(static_cast<std::size_t>(K) * n_);
    r.numEquations = n_;
    Eigen::RowVectorXd w(numFullCols());
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < n_; ++j) {
        const Eigen::Index i = static_cast<Eigen::Index>(k) * n_ + j;
        fullRow(j, d.q(k, j), d.qd(k, j), d.qdd(k, j), w);
        r.W.row(i) = w;
        r.y(i) = d.tau(k, j);
        r.equation[static_cast<std::size_t>(i)] = j;
      }
    return r;
  }
  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    const int K = s.size();
    Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * n_, numFullCols());
    Eigen::RowVectorXd w(numFullCols());
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < n_; ++j) {
        fullRow(j, s.q(k, j), s.qd(k, j), s.qdd(k, j), w);
        W.row(static_cast<Eigen::Index>(k) * n_ + j) = w;
      }
    return W;
  }
  void fullDesignVjp(const exid::Samples&, const Eigen::MatrixXd&, exid::Samples*) const override {
    throw exid::Error("test model: no VJP");
  }
  /// The largest number of samples one fullRows() call has seen (streaming check).
  mutable std::atomic<int> max_samples_per_call{0};

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;
    return sp;
  }

 private:
  int n_, extra_;
};

inline std::shared_ptr<PendulumModel> makeModel(int n, int extra = 0) {
  auto m = std::make_shared<PendulumModel>(n, extra);
  exid::RunContext ctx;
  m->bind(makeRobot(n), ctx);
  return m;
}

struct DataOptions {
  int samples = 2000;
  double dt = 0.005;
  std::vector<double> tau_noise;  // per joint (empty: none)
  double q_noise = 0.0;
  bool derivatives = true;  // store qd, qdd
  double qd_offset = 0.0;   // added to every velocity (a joint that never reverses)
  std::uint64_t seed = 1;
  double t0 = 0.0;
  /// If set, the full parameter vector used to make tau (default: the model's nominal).
  Eigen::VectorXd pi;
};

/// Sum-of-sines motions, torques from the model's full columns, Gaussian noise.
inline exid::Dataset makeData(const PendulumModel& model, int n, const DataOptions& o) {
  exid::Dataset d;
  const int K = o.samples;
  d.t = Eigen::VectorXd::LinSpaced(K, o.t0, o.t0 + (K - 1) * o.dt);
  d.q.resize(K, n);
  d.qd.resize(K, n);
  d.qdd.resize(K, n);
  d.tau.resize(K, n);
  const double f[3] = {0.3, 0.7, 1.3}, a[3] = {1.0, 0.5, 0.3};
  for (int j = 0; j < n; ++j)
    for (int k = 0; k < K; ++k) {
      const double t = d.t(k);
      double q = 0, qd = o.qd_offset, qdd = 0;
      for (int h = 0; h < 3; ++h) {
        const double w = 2 * M_PI * f[h] * (1.0 + 0.13 * j), ph = 0.7 * h + 1.1 * j;
        q += a[h] * std::sin(w * t + ph);
        qd += a[h] * w * std::cos(w * t + ph);
        qdd += -a[h] * w * w * std::sin(w * t + ph);
      }
      q += o.qd_offset * t;
      d.q(k, j) = q;
      d.qd(k, j) = qd;
      d.qdd(k, j) = qdd;
    }
  const Eigen::VectorXd pi = o.pi.size() ? o.pi : model.fullNominal();
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::RowVectorXd w(model.numFullCols());
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j) {
      model.fullRow(j, d.q(k, j), d.qd(k, j), d.qdd(k, j), w);
      const double s = o.tau_noise.empty() ? 0.0 : o.tau_noise[static_cast<std::size_t>(j)];
      d.tau(k, j) = w.dot(pi) + s * N(rng);
    }
  if (o.q_noise > 0)
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < n; ++j) d.q(k, j) += o.q_noise * N(rng);
  if (!o.derivatives) {
    d.qd.resize(0, 0);
    d.qdd.resize(0, 0);
  }
  d.source = "est_test::makeData";
  d.facts.simulated = exid::PlantTruth();
  return d;
}

}  // namespace est_test
