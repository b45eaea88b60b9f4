// The typed study summary is the one source: summary.json's headline keys, the brief table and
// the report carry exactly its values, for a successful study with every stage and for a
// failed one.
#include "exid/summary.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

double num(const exid::Json& j, const std::string& section, const std::string& key) {
  const exid::Json* s = j.find(section);
  EXPECT_TRUE(s) << section;
  const exid::Json* v = s ? s->find(key) : nullptr;
  EXPECT_TRUE(v) << section << "." << key;
  return v ? v->asDouble() : NAN;
}

std::string readFile(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

}  // namespace

TEST(StudySummary, JsonBriefTableAndReportAreRenderedFromTheTypedResults) {
  const std::string study =
      "name: typed_summary\n"
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n"
      "excitation:\n"
      "  trajectory: {type: fourier, params: {harmonics: 2, period_s: 4}}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt, params: {max_evaluations: 200}}\n"
      "experiment: {type: simulate, params: {duration_s: 3, noise_tau_Nm: 0.01}}\n"
      "estimator: {type: batch_ls}\n"
      "validation: {type: simulate, params: {duration_s: 2, noise_tau_Nm: 0.01}}\n";
  exid::StudyConfig cfg =
      exid::parseStudy(study, "typed.yaml", exid_test::sourceDir(), exid_test::registry());
  const fs::path out =
      fs::temp_directory_path() / ("exid_typed_summary_" + std::to_string(getpid()));
  fs::remove_all(out);
  exid::RunOptions opt;
  opt.out_dir = out;
  exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), opt);
  ASSERT_TRUE(r.ok) << r.message;
  const exid::StudySummary& T = r.headline;
  const exid::Json& S = r.summary;
  EXPECT_EQ(T.status, "ok");
  EXPECT_EQ(S.find("status")->asString(), T.status);
  EXPECT_EQ(S.find("study")->asString(), "typed_summary");
  EXPECT_DOUBLE_EQ(S.find("wall_s")->asDouble(), T.wall_s);
  ASSERT_TRUE(T.robot && T.excitation && T.experiment && T.identification && T.validation);
  EXPECT_EQ(T.robot->dof, 2);
  EXPECT_EQ(num(S, "robot", "dof"), T.robot->dof);
  EXPECT_EQ(num(S, "robot", "n_base_parameters"), *T.robot->n_base_parameters);
  EXPECT_EQ(num(S, "excitation", "cond_W_final"), T.excitation->cond_W_final);
  EXPECT_EQ(num(S, "excitation", "evaluations"), T.excitation->evaluations);
  EXPECT_LE(T.excitation->evaluations, 200);
  EXPECT_EQ(S.find("excitation")->find("stop_reason")->asString(), T.excitation->stop_reason_text);
  EXPECT_NE(T.excitation->stop_reason, exid::StopReason::None);
  EXPECT_EQ(num(S, "experiment", "samples"), T.experiment->samples);
  EXPECT_EQ(num(S, "identification", "cond_W"), T.identification->cond_W);
  EXPECT_EQ(num(S, "identification", "residual_rms"), T.identification->residual_rms);
  ASSERT_TRUE(T.identification->param_rel_err);  // simulated: judged against the truth
  EXPECT_EQ(num(S, "identification", "param_rel_err"), *T.identification->param_rel_err);
  EXPECT_EQ(num(S, "validation", "relative_error"), T.validation->relative_error);
  EXPECT_EQ(T.validation->rms_per_joint.size(), 2u);
  // The brief table shows the typed values, and report.md starts with the same table.
  const std::string brief = exid::briefTable(T);
  for (const std::string& v :
       {fmt::format("{:.6g}", T.identification->cond_W),
        fmt::format("{:.6g}", T.validation->relative_error),
        fmt::format("{:.6g}", T.excitation->cond_W_final), std::string("planar2r (2 dof)")})
    EXPECT_NE(brief.find(v), std::string::npos) << v << " not in\n" << brief;
  EXPECT_NE(readFile(out / "report.md").find(brief), std::string::npos);
  // summary.json on disk is the rendered record.
  const exid::Json disk = exid::Json::parse(readFile(out / "summary.json"));
  EXPECT_EQ(num(disk, "identification", "cond_W"), T.identification->cond_W);
  fs::remove_all(out);
}

TEST(StudySummary, AFailedStudyNamesItsStageInBothForms) {
  // A recording without the second joint's columns: the experiment stage fails.
  const fs::path csv =
      fs::temp_directory_path() / ("exid_typed_summary_" + std::to_string(getpid()) + ".csv");
  {
    std::ofstream f(csv);
    f << "t,q1,qd1,qdd1,tau1\n";
    for (int k = 0; k < 50; ++k) f << 0.01 * k << ",0.1,0,0,1\n";
  }
  const std::string study =
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n"
      "experiment: {type: csv, params: {file: " +
      csv.string() +
      "}}\n"
      "estimator: {type: batch_ls}\n";
  exid::StudyConfig cfg =
      exid::parseStudy(study, "failing.yaml", exid_test::sourceDir(), exid_test::registry());
  exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
  ASSERT_FALSE(r.ok);
  EXPECT_EQ(r.headline.status, "failed");
  EXPECT_EQ(r.headline.failed_stage, "experiment");
  EXPECT_EQ(r.summary.find("failed_stage")->asString(), "experiment");
  EXPECT_EQ(r.summary.find("message")->asString(), r.headline.message);
  EXPECT_TRUE(r.headline.robot.has_value());
  EXPECT_FALSE(r.headline.identification.has_value());
  EXPECT_NE(exid::briefTable(r.headline).find("| status | failed |"), std::string::npos);
  fs::remove(csv);
}
