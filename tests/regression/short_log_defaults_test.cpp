// Defaults that keep a short recording (docs/real_data.md, "Defaults on short recordings"): a
// study of the data's documented facts (file, columns, rate) with the estimator's defaults
// predicts new motion within 1.5 times the best of several tuned studies exid can express, on
// simulated 100 Hz logs of a few seconds of motion after a long standstill, and on long logs.
// The held-out error is the same for every study: the identified base parameters' prediction of
// the noise-free torque of a fresh motion, from its exact q, qd, qdd.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "../models/model_test_util.hpp"
#include "exid/config.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"

namespace {

namespace fs = std::filesystem;

fs::path tmpDir() {
  fs::path p = fs::temp_directory_path() / ("exid_short_log_" + std::to_string(::getpid()));
  fs::create_directories(p);
  return p;
}

/// A recording: `rest_s` at the first pose, then `motion_s` of the simulate experiment's own
/// motion; only t, q and tau (noise on tau, q quantised to 1e-5 rad) in the file.
fs::path writeLog(const std::string& robot, double rate, double rest_s, double motion_s,
                  double noise, std::uint64_t seed, const std::string& name) {
  auto r = mtest::robot(robot);
  const double dt = 1.0 / rate;
  const exid::Dataset d = mtest::simulate(
      r,
      fmt::format("{{duration_s: {:.6f}, sample_period_s: {:.10g}, noise_tau_Nm: {:.6g}, "
                  "period_s: {:.6f}, harmonics: 3}}",
                  motion_s, dt, noise, motion_s),
      seed);
  const int n = r->dof(), R = static_cast<int>(std::lround(rest_s * rate)), K = d.size();
  exid::CsvTable T;
  T.columns = {"t"};
  for (const char* g : {"q", "tau"})
    for (int j = 1; j <= n; ++j) T.columns.push_back(g + std::to_string(j));
  T.data.resize(R + K, 1 + 2 * n);
  auto dd = exid::makeDynamicsData(*r);
  exid::DriveColumns cols;
  cols.rotor_inertia = cols.coulomb = cols.viscous = cols.offset = true;
  const Eigen::VectorXd q0 = d.q.row(0).transpose(), zero = Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd g0 = exid::actuatorTorque(*r, *dd, cols, q0, zero, zero);
  std::mt19937_64 rng(seed + 5);
  std::normal_distribution<double> nz(0.0, noise);
  for (int k = 0; k < R + K; ++k) {
    T.data(k, 0) = std::round(k * dt * rate) / rate;
    for (int j = 0; j < n; ++j) {
      const double q = k < R ? q0(j) : d.q(k - R, j);
      T.data(k, 1 + j) = std::round(q * 1e5) / 1e5;
      T.data(k, 1 + n + j) = k < R ? g0(j) + nz(rng) : d.tau(k - R, j);
    }
  }
  const fs::path f = tmpDir() / (name + ".csv");
  exid::writeCsvAtomic(f, T);
  return f;
}

/// Relative error of the base parameters' prediction of a fresh, noise-free motion's torque.
double heldOut(const std::string& robot, const std::string& model_yaml,
               const Eigen::VectorXd& theta) {
  auto r = mtest::robot(robot);
  const exid::Dataset v = mtest::simulate(
      r, "{duration_s: 6, sample_period_s: 0.01, noise_tau_Nm: 0, period_s: 6, harmonics: 4}",
      4242);
  auto m = mtest::model("differential", model_yaml, r);
  const exid::Rows rows = m->rows(v, mtest::context());
  return (rows.W * theta - rows.y).norm() / rows.y.norm();
}

struct Outcome {
  bool ok = false;
  std::string message;
  double held_out = NAN;
};

Outcome runOn(const std::string& robot, const fs::path& log, const std::string& experiment_extra,
              const std::string& estimator, const std::string& tag) {
  const std::string model = "{}";
  const std::string study = fmt::format(
      "name: short_{}\nrobot: {{type: {}}}\nmodel: {{type: differential, params: {}}}\n"
      "experiment: {{type: csv, params: {{file: '{}'{}}}}}\nestimator: {}\n",
      tag, robot, model, log.string(), experiment_extra.empty() ? "" : ", " + experiment_extra,
      estimator);
  Outcome o;
  try {
    exid::StudyConfig cfg =
        exid::parseStudy(study, "short.yaml", exid_test::sourceDir(), exid_test::registry());
    exid::RunOptions opt;
    const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), opt);
    o.ok = r.ok;
    o.message = r.message;
    if (!r.ok) return o;
    const exid::Json& P = *r.summary.find("identification")->find("parameters");
    Eigen::VectorXd theta(static_cast<Eigen::Index>(P.size()));
    for (std::size_t i = 0; i < P.size(); ++i)
      theta(static_cast<Eigen::Index>(i)) = P.at(i).find("value")->asDouble();
    o.held_out = heldOut(robot, model, theta);
  } catch (const std::exception& e) {
    o.message = e.what();
  }
  return o;
}

struct Scenario {
  std::string robot;
  double rest_s, motion_s, noise;
};

}  // namespace

TEST(ShortLogDefaults, DocumentedFactsWithDefaultsAreWithinOneAndAHalfOfTheBestTunedStudy) {
  const Scenario scenarios[] = {
      {"puma560", 20, 4, 0.05},  // short motion after a long standstill
      {"panda", 15, 4, 0.05},    //
      {"puma560", 0, 30, 0.05},  // a long log, no standstill
      {"panda", 2, 30, 0.05},    //
  };
  int s_index = 0;
  for (const Scenario& sc : scenarios) {
    SCOPED_TRACE(fmt::format("{} rest {} s motion {} s", sc.robot, sc.rest_s, sc.motion_s));
    const fs::path log = writeLog(sc.robot, 100, sc.rest_s, sc.motion_s, sc.noise,
                                  77 + static_cast<std::uint64_t>(s_index), "log");
    const Outcome def = runOn(sc.robot, log, "", "{type: filtered_ls}", "defaults");
    ASSERT_TRUE(def.ok) << def.message;
    // Tuned studies: the segment of motion only, other cut-offs, no decimation, batch_ls on the
    // csv experiment's own differentiation.
    const std::string seg = fmt::format("t_start_s: {}", sc.rest_s > 0 ? sc.rest_s - 0.2 : 0.0);
    const std::vector<std::pair<std::string, std::string>> tuned = {
        {seg, "{type: filtered_ls}"},
        {seg, "{type: filtered_ls, params: {cutoff_hz: 5, decimation: 1}}"},
        {seg, "{type: filtered_ls, params: {cutoff_hz: 8, decimation: 1, trim_edges: 0}}"},
        {seg, "{type: filtered_ls, params: {cutoff_hz: 15, decimation: 1, trim_edges: 0}}"},
        {seg + ", differentiate_cutoff_hz: 8, filter_torque: true", "{type: batch_ls}"},
        {seg + ", differentiate_cutoff_hz: 12, filter_torque: true", "{type: batch_ls}"},
        {"", "{type: filtered_ls, params: {cutoff_hz: 8, decimation: 1, trim_edges: 0}}"},
    };
    double best = HUGE_VAL;
    std::string best_what;
    int t = 0;
    for (const auto& [exp, est] : tuned) {
      const Outcome o = runOn(sc.robot, log, exp, est, "tuned" + std::to_string(t++));
      std::printf("  %s %s: %s %.4f\n", exp.c_str(), est.c_str(), o.ok ? "" : o.message.c_str(),
                  o.held_out);
      if (o.ok && o.held_out < best) {
        best = o.held_out;
        best_what = exp + " " + est;
      }
    }
    std::printf(
        "%s, %g s at rest then %g s of motion at 100 Hz: defaults %.4f, best tuned %.4f "
        "(%s): ratio %.2f\n",
        sc.robot.c_str(), sc.rest_s, sc.motion_s, def.held_out, best, best_what.c_str(),
        def.held_out / best);
    EXPECT_LE(def.held_out, 1.5 * best) << best_what;
    ++s_index;
  }
  fs::remove_all(tmpDir());
}
