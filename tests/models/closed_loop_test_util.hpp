// Helpers of the tests of the estimators that simulate the closed loop (iv, didim): a
// commanded trajectory, written as `exid excite --export` writes it, and the PD gains the
// `simulate` experiment applied.
#pragma once

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "exid/data.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace cltest {

// A closed-loop case: the robot, the model, the recording, the estimators' loop parameters
// (reference_file and gains) and the true base parameters.
struct Loop {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::ObservationModel> model;
  exid::Dataset data;
  std::string params;
  Eigen::VectorXd truth;
};

// A smooth commanded trajectory of every joint (sums of sines), sampled at 1 kHz.
inline exid::Samples reference(int n, double duration) {
  const double dt = 0.001;
  const int K = static_cast<int>(std::round(duration / dt)) + 1;
  exid::Samples s;
  s.t = Eigen::VectorXd::LinSpaced(K, 0.0, (K - 1) * dt);
  s.q.resize(K, n);
  s.qd.resize(K, n);
  s.qdd.resize(K, n);
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j) {
      s.q(k, j) = s.qd(k, j) = s.qdd(k, j) = 0.0;
      for (int l = 1; l <= 4; ++l) {  // four sines per joint, frequencies apart
        const double t = s.t[k], a = 0.5 / l, w = 0.9 * l + 0.23 * j, ph = 0.7 * j + l;
        s.q(k, j) += a * std::sin(w * t + ph);
        s.qd(k, j) += a * w * std::cos(w * t + ph);
        s.qdd(k, j) += -a * w * w * std::sin(w * t + ph);
      }
    }
  return s;
}

// The reference as the export writes it: t, q1..qn, qd1..qdn, qdd1..qddn.
inline void writeReference(const exid::Samples& s, const std::filesystem::path& f) {
  std::ofstream o(f);
  const int n = s.dof();
  o << "t";
  for (const char* g : {"q", "qd", "qdd"})
    for (int j = 1; j <= n; ++j) o << "," << g << j;
  o << "\n";
  for (int k = 0; k < s.size(); ++k) {
    o << fmt::format("{:.17g}", s.t[k]);
    for (const Eigen::MatrixXd* M : {&s.q, &s.qd, &s.qdd})
      for (int j = 0; j < n; ++j) o << fmt::format(",{:.17g}", (*M)(k, j));
    o << "\n";
  }
}

inline std::string gains(const exid::Json& meta) {
  const exid::Json& g = *meta.find("pd_gains");
  auto list = [](const exid::Json& a) {
    std::string s;
    for (std::size_t i = 0; i < a.size(); ++i)
      s += (i ? ", " : "") + fmt::format("{:.17g}", a.at(i).asDouble());
    return "[" + s + "]";
  };
  return fmt::format("kp_Nm_per_rad: {}, kd_Nm_s_per_rad: {}", list(*g.find("kp_Nm_per_rad")),
                     list(*g.find("kd_Nm_s_per_rad")));
}

/// The PUMA 560 tracking the reference of `duration` s under PD and feed-forward (kp 400, kd 40,
/// 200 Hz, tanh Coulomb of 0.05 rad/s, seed 7), the reference written into a fresh folder named
/// from `tmp_prefix`: robot, data and the estimator's loop parameters (params); the model and
/// the truth are the test's.
inline Loop pumaTracking(double duration, const std::string& tmp_prefix) {
  Loop s;
  s.robot = mtest::robot("puma560");
  const exid::Samples ref = reference(s.robot->dof(), duration);
  s.data = mtest::simulate(
      s.robot,
      "{controller: pd_feedforward, kp: 400, kd: 40, sample_period_s: 0.005, coulomb: tanh, "
      "coulomb_velocity_scale: 0.05}",
      7, &ref);
  const std::filesystem::path dir = exid_cli::freshTempDir(tmp_prefix, "ref");
  writeReference(ref, dir / "reference.csv");
  s.params =
      fmt::format("reference_file: {}, {}", (dir / "reference.csv").string(), gains(s.data.meta));
  return s;
}

/// A study's estimate and the robot's own (nominal) base parameters, from its parameters.csv
/// (name, index, value, std, rel_std_percent, nominal): one (value, nominal) per base
/// parameter. A recording carries no truth: the plant simulated the nominal parameters. An
/// unreadable file or a malformed line is a test failure (and an empty result).
inline std::vector<std::pair<double, double>> estimateAndNominal(
    const std::filesystem::path& out_dir) {
  std::vector<std::pair<double, double>> out;
  std::ifstream f(out_dir / "parameters.csv");
  EXPECT_TRUE(f.good()) << (out_dir / "parameters.csv").string();
  std::string line;
  std::getline(f, line);
  while (std::getline(f, line)) {
    std::vector<std::string> c;
    std::stringstream ls(line);
    for (std::string x; std::getline(ls, x, ',');) c.push_back(x);
    EXPECT_EQ(c.size(), 6u) << line;
    if (c.size() != 6u) return {};
    out.emplace_back(std::stod(c[2]), std::stod(c[5]));
  }
  return out;
}

}  // namespace cltest
