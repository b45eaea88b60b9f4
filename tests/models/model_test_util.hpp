// Helpers for the observation-model and experiment tests (tests/models, tests/experiments).
#pragma once

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>

#include "dyn_robots.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid_test.hpp"

namespace mtest {

/// A robot from its plugin; when the plugin is missing or fails, the test suite's own table
/// (PUMA 560, Panda) or nullptr.
inline std::shared_ptr<const exid::RobotModel> robot(const std::string& name) {
  try {
    return exid_test::robot(name);
  } catch (const std::exception& e) {
    std::printf("[note] robot plugin '%s' unavailable (%s)\n", name.c_str(), e.what());
  }
  if (name == "puma560")
    return std::make_shared<const exid::RobotModel>(exid::testing::puma560Standard());
  if (name == "panda") return std::make_shared<const exid::RobotModel>(exid::testing::panda());
  return nullptr;
}

/// Samples [begin, end) of a dataset as a csv experiment reads them: t, q, qd, qdd, tau columns,
/// full precision; `t_offset` is added to the time stamps.
inline void writeCsv(const exid::Dataset& d, const std::filesystem::path& f, int begin = 0,
                     int end = -1, double t_offset = 0.0) {
  std::ofstream o(f);
  const int n = d.dof();
  o << "t";
  for (const char* g : {"q", "qd", "qdd", "tau"})
    for (int j = 1; j <= n; ++j) o << "," << g << j;
  o << "\n";
  for (int k = begin; k < (end < 0 ? d.size() : end); ++k) {
    o << fmt::format("{:.17g}", d.t[k] + t_offset);
    for (const Eigen::MatrixXd* M : {&d.q, &d.qd, &d.qdd, &d.tau})
      for (int j = 0; j < n; ++j) o << fmt::format(",{:.17g}", (*M)(k, j));
    o << "\n";
  }
}

inline exid::RunContext context(std::uint64_t seed = 7) {
  exid::RunContext ctx;
  ctx.seed = seed;
  return ctx;
}

inline exid::Dataset simulate(const std::shared_ptr<const exid::RobotModel>& r,
                              const std::string& yaml, std::uint64_t seed = 7,
                              const exid::Samples* reference = nullptr) {
  auto e = exid_test::create<exid::Experiment>("simulate", yaml);
  return e->run(r, reference, context(seed));
}

inline std::shared_ptr<exid::ObservationModel> model(
    const std::string& name, const std::string& yaml,
    const std::shared_ptr<const exid::RobotModel>& r) {
  auto m = exid_test::create<exid::ObservationModel>(name, yaml);
  m->bind(r, context(11));
  return m;
}

struct Recovery {
  double rows_rel = 0;   // max |W_full pi_full - y| / max |y|
  double est_rel = 0;    // ||theta - theta*|| / ||theta*||
  double worst_rel = 0;  // max_i |theta_i - theta*_i| / max(|theta*_i|, 1e-6 ||theta*||_inf)
  double condW = 0;
  int rows = 0, base = 0;
};

/// Rows of the model on the data, residual of the full rows with the nominal parameters, and
/// batch least squares on the base columns (column-pivoting QR).
inline Recovery recover(const exid::ObservationModel& m, const exid::Dataset& d) {
  Recovery out;
  const exid::RunContext ctx = context();
  const exid::Rows full = m.fullRows(d, ctx);
  const Eigen::VectorXd r = full.W * m.fullNominal() - full.y;
  out.rows_rel = r.cwiseAbs().maxCoeff() / full.y.cwiseAbs().maxCoeff();
  const exid::Rows rows = m.rows(d, ctx);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(rows.W);
  const Eigen::VectorXd th = qr.solve(rows.y);
  const Eigen::VectorXd tr = m.baseNominal();
  out.est_rel = (th - tr).norm() / tr.norm();
  const double floor = 1e-6 * tr.cwiseAbs().maxCoeff();
  for (Eigen::Index i = 0; i < th.size(); ++i)
    out.worst_rel =
        std::max(out.worst_rel, std::abs(th[i] - tr[i]) / std::max(std::abs(tr[i]), floor));
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(rows.W);
  const auto& s = svd.singularValues();
  out.condW = s[0] / s[s.size() - 1];
  out.rows = static_cast<int>(rows.W.rows());
  out.base = m.numBase();
  return out;
}

inline void print(const char* what, const Recovery& r) {
  std::printf(
      "[%s] rows %d, base %d, cond(W) %.3g, row residual %.2e, estimate error %.2e (norm), "
      "%.2e (worst parameter)\n",
      what, r.rows, r.base, r.condW, r.rows_rel, r.est_rel, r.worst_rel);
}

/// fullDesignVjp against central finite differences of <G, fullDesign(s)> for random G.
inline double vjpError(const exid::ObservationModel& m, const exid::Samples& s, bool with_qdd,
                       std::uint64_t seed = 3) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  const Eigen::MatrixXd W0 = m.fullDesign(s);
  Eigen::MatrixXd G(W0.rows(), W0.cols());
  for (Eigen::Index i = 0; i < G.size(); ++i) G.data()[i] = nd(rng);
  exid::Samples g;
  m.fullDesignVjp(s, G, &g);
  double worst = 0.0, scale = 0.0;
  const double h = 1e-6;
  for (int which = 0; which < (with_qdd ? 3 : 2); ++which) {
    for (Eigen::Index k = 0; k < s.q.rows(); ++k)
      for (Eigen::Index j = 0; j < s.q.cols(); ++j) {
        exid::Samples sp = s, sm = s;
        Eigen::MatrixXd& xp = which == 0 ? sp.q : (which == 1 ? sp.qd : sp.qdd);
        Eigen::MatrixXd& xm = which == 0 ? sm.q : (which == 1 ? sm.qd : sm.qdd);
        xp(k, j) += h;
        xm(k, j) -= h;
        const double fd = (G.cwiseProduct(m.fullDesign(sp) - m.fullDesign(sm))).sum() / (2 * h);
        const Eigen::MatrixXd& an = which == 0 ? g.q : (which == 1 ? g.qd : g.qdd);
        worst = std::max(worst, std::abs(fd - an(k, j)));
        scale = std::max(scale, std::abs(fd));
      }
  }
  return worst / std::max(scale, 1e-12);
}

/// A few random samples within the robot's limits (velocities away from zero).
inline exid::Samples randomSamples(const exid::RobotModel& r, int K, double dt,
                                   std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int n = r.dof();
  exid::Samples s;
  s.t = Eigen::VectorXd::LinSpaced(K, 0.0, (K - 1) * dt);
  s.q.resize(K, n);
  s.qd.resize(K, n);
  s.qdd.resize(K, n);
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j) {
      s.q(k, j) = 1.2 * u(rng);
      const double v = u(rng);
      s.qd(k, j) = (v >= 0 ? 0.2 : -0.2) + v;
      s.qdd(k, j) = 3.0 * u(rng);
    }
  return s;
}

/// Part one without the payload, part two with it, both simulated with the recorded torque
/// through `gains` (recorded_torque_gain, a YAML list), 4 s each at 200 Hz (seeds 3 and 4); the
/// second part's time follows the first's and facts.payload_part_from_t_s says where it starts
/// (as the csv experiment's payload_file does).
inline exid::Dataset gainedTwoParts(const std::shared_ptr<const exid::RobotModel>& r,
                                    const std::string& gains, const std::string& payload) {
  exid::Dataset a = simulate(
      r, fmt::format("{{duration_s: 4, sample_period_s: 0.005, recorded_torque_gain: {}}}", gains),
      3);
  const exid::Dataset b = simulate(
      r,
      fmt::format("{{duration_s: 4, sample_period_s: 0.005, recorded_torque_gain: {}, {}}}", gains,
                  payload),
      4);
  const int Ka = a.size(), Kb = b.size();
  const double from = a.t[Ka - 1] + 0.005;
  Eigen::VectorXd t(Ka + Kb);
  t << a.t, b.t.array() - b.t[0] + from;
  a.t = t;
  for (auto [x, y] : {std::pair{&a.q, &b.q}, {&a.qd, &b.qd}, {&a.qdd, &b.qdd}, {&a.tau, &b.tau}}) {
    Eigen::MatrixXd m(Ka + Kb, x->cols());
    m << *x, *y;
    *x = m;
  }
  a.facts.payload_part_from_t_s = from;
  return a;
}

}  // namespace mtest
