// Defaults on short recordings (docs/real_data.md, "Defaults on short recordings"): a study of
// the data's documented facts (file, columns, rate) with the estimator's defaults against the
// best of several tuned studies exid can express, on simulated 100 Hz logs, short and long, with
// and without a standstill before the motion. Asserted: within 1.5 times on every log.
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

/// A recording: `rest_s` at rest, then `motion_s` of motion that starts from rest smoothly (q,
/// qd, qdd continuous): q_j = c_j + sum_h a_jh (1 - cos(w_jh u))^2 / 4, u = t - rest_s, three
/// frequencies per joint; the torque of the robot's own model (rigid bodies and drives) plus
/// noise. Only t, q (quantised to 1e-5 rad) and tau in the file: a raw log.
fs::path writeLog(const std::string& robot, double rate, double rest_s, double motion_s,
                  double noise, std::uint64_t seed, const std::string& name) {
  auto r = mtest::robot(robot);
  const double dt = 1.0 / rate;
  const int n = r->dof();
  const int K = static_cast<int>(std::lround((rest_s + motion_s) * rate)) + 1;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uf(0.15, 0.9);
  std::normal_distribution<double> nz(0.0, noise);
  Eigen::MatrixXd amp(n, 3), w(n, 3);
  Eigen::VectorXd c(n);
  for (int j = 0; j < n; ++j) {
    const auto& lim = r->limits[static_cast<std::size_t>(j)];
    const bool known = lim.q_max < 1e299 && lim.q_min > -1e299;
    const double span = known ? std::min(1.2, 0.5 * (lim.q_max - lim.q_min)) : 1.2;
    c(j) = known ? 0.5 * (lim.q_min + lim.q_max) - 0.5 * span : 0.0;
    for (int h = 0; h < 3; ++h) {
      amp(j, h) = span / 3.0;
      w(j, h) = 2 * M_PI * uf(rng);
    }
  }
  exid::CsvTable T;
  T.columns = {"t"};
  for (const char* g : {"q", "tau"})
    for (int j = 1; j <= n; ++j) T.columns.push_back(g + std::to_string(j));
  T.data.resize(K, 1 + 2 * n);
  auto dd = exid::makeDynamicsData(*r);
  exid::DriveColumns cols;
  cols.rotor_inertia = cols.coulomb = cols.viscous = cols.offset = true;
  for (int k = 0; k < K; ++k) {
    const double t = k * dt, u = std::max(0.0, t - rest_s);
    Eigen::VectorXd q(n), qd(n), qdd(n);
    for (int j = 0; j < n; ++j) {
      q(j) = c(j);
      qd(j) = qdd(j) = 0;
      for (int h = 0; h < 3; ++h) {
        const double a = amp(j, h), om = w(j, h), ph = om * u, cp = std::cos(ph), sp = std::sin(ph);
        q(j) += a * (1 - cp) * (1 - cp) / 4;
        qd(j) += a * om * (1 - cp) * sp / 2;
        qdd(j) += a * om * om * (sp * sp + (1 - cp) * cp) / 2;
      }
    }
    const Eigen::VectorXd tau = exid::actuatorTorque(*r, *dd, cols, q, qd, qdd);
    T.data(k, 0) = std::round(t * rate) / rate;
    for (int j = 0; j < n; ++j) {
      T.data(k, 1 + j) = std::round(q(j) * 1e5) / 1e5;
      T.data(k, 1 + n + j) = tau(j) + nz(rng);
    }
  }
  const fs::path f = tmpDir() / (name + ".csv");
  exid::writeCsvAtomic(f, T);
  return f;
}

/// Relative error of the base parameters' prediction of a fresh, noise-free motion's torque.
double heldOut(const std::string& robot, const std::string& model_yaml,
               const Eigen::VectorXd& theta, const std::vector<std::string>& names) {
  auto r = mtest::robot(robot);
  const exid::Dataset v = mtest::simulate(
      r, "{duration_s: 6, sample_period_s: 0.01, noise_tau_Nm: 0, period_s: 6, harmonics: 4}",
      4242);
  auto m = mtest::model("differential", model_yaml, r);
  EXPECT_EQ(m->base().names, names);  // the same base parameters as the study's
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
  const std::string model = "{rotor_inertia: true, viscous: true, coulomb: true, offset: true}";
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
    std::vector<std::string> names;
    for (std::size_t i = 0; i < P.size(); ++i) {
      theta(static_cast<Eigen::Index>(i)) = P.at(i).find("value")->asDouble();
      names.push_back(P.at(i).find("name")->asString());
    }
    o.held_out = heldOut(robot, model, theta, names);
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
      {"panda", 2, 30, 0.05},    // a long log after a short standstill
      {"panda", 0, 30, 0.05},    // a long log, no standstill
      {"puma560", 0, 6, 0.05},   // a short log, no standstill
      {"panda", 0, 5, 0.05},     //
  };
  int s_index = 0;
  for (const Scenario& sc : scenarios) {
    SCOPED_TRACE(fmt::format("{} rest {} s motion {} s", sc.robot, sc.rest_s, sc.motion_s));
    const fs::path log =
        writeLog(sc.robot, 100, sc.rest_s, sc.motion_s, sc.noise,
                 77 + static_cast<std::uint64_t>(s_index), "log" + std::to_string(s_index));
    const Outcome def = runOn(sc.robot, log, "", "{type: filtered_ls}", "defaults");
    ASSERT_TRUE(def.ok) << def.message;
    // Tuned studies: the segment of motion only (from its first sample, or with 0.2 s of the
    // standstill), other cut-offs, no decimation, batch_ls on the csv experiment's own
    // differentiation, the standstill's rows kept.
    const std::string seg = fmt::format("t_start_s: {}", sc.rest_s > 0 ? sc.rest_s - 0.2 : 0.0);
    const std::vector<std::pair<std::string, std::string>> tuned = {
        {fmt::format("t_start_s: {}", sc.rest_s), "{type: filtered_ls}"},
        {"", "{type: filtered_ls, params: {standstill: zero_velocity}}"},
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
  if (!std::getenv("EXID_KEEP")) fs::remove_all(tmpDir());
}
