// exid inspect on the command line, and the inspection exid run puts into summary.json: a
// recording with torque signs flipped on joints 2 and 4 is named as such; clean simulated data
// gives no warning.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "../models/model_test_util.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"
#include "exid/runner.hpp"
#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace {

using exid_cli::CmdResult;
using exid_cli::runExid;
using exid_cli::slurp;

fs::path tempDir(const std::string& name) { return exid_cli::freshTempDir("exid_inspect_", name); }

/// Simulated PUMA 560 data (10 s at 100 Hz, 0.05 N m torque noise), optionally with the torques
/// of joints 2 and 4 negated, written with (or without) its time column.
fs::path writeData(const fs::path& dir, const std::string& name, bool flip, bool time_column) {
  auto r = mtest::robot("puma560");
  exid::Dataset d = mtest::simulate(r, "{duration_s: 10, noise_tau_Nm: 0.05}");
  if (flip) {
    d.tau.col(1) *= -1.0;
    d.tau.col(3) *= -1.0;
  }
  exid::CsvTable T = exid::datasetTable(d);
  if (!time_column) {
    T.columns.erase(T.columns.begin());
    const Eigen::MatrixXd X = T.data.rightCols(T.data.cols() - 1);
    T.data = X;
  }
  const fs::path f = dir / name;
  exid::writeCsvAtomic(f, T);
  return f;
}

std::string study(const fs::path& data) {
  return "robot: {type: puma560}\n"
         "model: {type: differential}\n"
         "experiment: {type: csv, params: {file: " +
         data.string() +
         "}}\n"
         "estimator: {type: batch_ls}\n";
}

std::string verdict(const exid::Json& J, int joint) {
  return J.find("joints")
      ->at(static_cast<std::size_t>(joint))
      .find("sign_check")
      ->find("verdict")
      ->asString();
}

}  // namespace

TEST(InspectCli, WritesTheJsonAndNamesTheFlippedJoints) {
  const fs::path dir = tempDir("cli");
  const fs::path data = writeData(dir, "flipped.csv", true, true);
  const fs::path json = dir / "inspect.json";
  CmdResult r = runExid("inspect puma560 " + data.string() + " --json " + json.string());
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("torque sign flipped"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("100 Hz"), std::string::npos) << r.out;
  ASSERT_TRUE(fs::exists(json));
  const exid::Json J = exid::Json::parse(slurp(json));
  for (int j = 0; j < 6; ++j) EXPECT_EQ(verdict(J, j), j == 1 || j == 3 ? "flipped" : "ok") << j;
  EXPECT_EQ(J.find("recording")->find("timing")->find("rate_hz")->asDouble(), 100.0);
  EXPECT_TRUE(J.find("delay")->find("delay_s")->isNumber());
  EXPECT_TRUE(J.find("regressor")->find("cond")->isNumber());
  // the csv experiment's own parameters: its remedy, tau_scale, given with --set
  r = runExid("inspect puma560 " + data.string() + " --set 'tau_scale=[1, -1, 1, -1, 1, 1]'");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.out.find("sign flipped"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("warnings: none"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

TEST(InspectCli, AMissingSamplePeriodIsRefusedAsByTheCsvExperiment) {
  const fs::path dir = tempDir("period");
  const fs::path data = writeData(dir, "no_t.csv", false, false);
  CmdResult r = runExid("inspect puma560 " + data.string());
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("no time column 't' and no sample_period_s: exid does not guess the sample "
                       "rate"),
            std::string::npos)
      << r.out;
  r = runExid("inspect puma560 " + data.string() + " --set sample_period_s=0.01");
  EXPECT_EQ(r.code, 0) << r.out;
  r = runExid("inspect puma560 " + data.string() + " --params '{sample_period_s: 0.01}'");
  EXPECT_EQ(r.code, 0) << r.out;
  r = runExid("inspect puma560 " + data.string() + " --set sample_period_s");
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("expected key=value"), std::string::npos) << r.out;
  r = runExid("inspect puma560 " + (dir / "absent.csv").string());
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("absent.csv: no such data file"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

TEST(InspectCli, RunPutsTheFlipWarningAndTheInspectionIntoTheSummary) {
  const fs::path dir = tempDir("run_flipped");
  const fs::path data = writeData(dir, "flipped.csv", true, true);
  std::ofstream(dir / "s.yaml") << study(data);
  CmdResult r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json S = exid::Json::parse(slurp(dir / "o" / "summary.json"));
  const exid::Json& w = *S.find("warnings");
  bool found = false;
  for (std::size_t i = 0; i < w.size(); ++i)
    found = found || (w.at(i).asString().find("inspection (experiment): tau2, tau4 are the "
                                              "negative") != std::string::npos &&
                      w.at(i).asString().find("torque sign flipped") != std::string::npos);
  EXPECT_TRUE(found) << w.dump(2);
  const exid::Json& I = *S.find("inspection")->find("experiment");
  EXPECT_EQ(verdict(I, 1), "flipped");
  EXPECT_EQ(verdict(I, 0), "ok");
  EXPECT_NE(slurp(dir / "o" / "report.md").find("torque sign flipped"), std::string::npos);
  // exid inspect STUDY.yaml: the same checks on the study's data
  r = runExid("inspect " + (dir / "s.yaml").string() + " --json " + (dir / "i.json").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json J = exid::Json::parse(slurp(dir / "i.json"));
  EXPECT_EQ(verdict(*J.find("experiment"), 3), "flipped");
  fs::remove_all(dir);
}

TEST(InspectCli, RunOnCleanSimulatedDataWarnsOfNothing) {
  const fs::path dir = tempDir("run_clean");
  const fs::path data = writeData(dir, "clean.csv", false, true);
  std::ofstream(dir / "s.yaml") << study(data);
  CmdResult r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json S = exid::Json::parse(slurp(dir / "o" / "summary.json"));
  EXPECT_EQ(S.find("warnings")->size(), 0u) << S.find("warnings")->dump(2);
  const exid::Json& I = *S.find("inspection")->find("experiment");
  for (int j = 0; j < 6; ++j) EXPECT_EQ(verdict(I, j), "ok") << j;
  fs::remove_all(dir);
}
