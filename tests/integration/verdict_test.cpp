// A finished study judges its own results (summary.json `verdict`): "suspect" with its reasons
// where the held-out prediction is no better than zero, far above the identification residual,
// or an estimator doubts its own choice; "ok" otherwise. Each reason is tested where it must be
// said and where it must not.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid/summary.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

// A planar 2R study: identification on a clean simulation, validation on a simulation whose
// recorded torque is `gain` times the plant's (-1: every sign flipped).
exid::StudyResult runWithValidationGain(const std::string& gain, const std::string& tag,
                                        bool write = false) {
  const std::string study =
      "name: verdict_" + tag +
      "\n"
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n"
      "experiment: {type: simulate, params: {duration_s: 6, noise_tau_Nm: 0.01}}\n"
      "estimator: {type: batch_ls}\n"
      "validation: {type: simulate, params: {duration_s: 4, period_s: 4, noise_tau_Nm: 0.01, "
      "recorded_torque_gain: [" +
      gain + "]}}\n";
  exid::StudyConfig cfg =
      exid::parseStudy(study, "verdict.yaml", exid_test::sourceDir(), exid_test::registry());
  exid::RunOptions opt;
  if (write) {
    const fs::path out =
        fs::temp_directory_path() / ("exid_verdict_" + tag + "_" + std::to_string(getpid()));
    fs::remove_all(out);
    opt.out_dir = out;
  }
  return exid::runStudy(cfg, exid_test::registry(), opt);
}

std::string readFile(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

const exid::Json* verdictOf(const exid::Json& S) { return S.find("verdict"); }

}  // namespace

TEST(Verdict, CleanStudyIsOk) {
  const exid::StudyResult r = runWithValidationGain("1", "clean");
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.headline.verdict, "ok");
  EXPECT_TRUE(r.headline.verdict_reasons.empty());
  const exid::Json* v = verdictOf(r.summary);
  ASSERT_TRUE(v);
  EXPECT_EQ(v->find("value")->asString(), "ok");
  EXPECT_EQ(v->find("reasons")->size(), 0u);
  EXPECT_LT(r.headline.validation->relative_error, 0.2);
}

TEST(Verdict, HeldOutWorseThanZeroIsSuspectAndShownFirst) {
  const exid::StudyResult r = runWithValidationGain("-1", "flipped", true);
  ASSERT_TRUE(r.ok) << r.message;  // the study ran: status ok, but its verdict says what is wrong
  EXPECT_GE(r.headline.validation->relative_error, 1.0);
  EXPECT_EQ(r.headline.verdict, "suspect");
  ASSERT_EQ(r.headline.verdict_reasons.size(), 1u);
  EXPECT_NE(r.headline.verdict_reasons[0].find("no better than predicting zero"), std::string::npos)
      << r.headline.verdict_reasons[0];
  // summary.json, the brief table and the report (before anything else of the results)
  const std::string json = readFile(r.written_to / "summary.json");
  EXPECT_NE(json.find("\"suspect\""), std::string::npos);
  const std::string md = readFile(r.written_to / "report.md");
  const auto at_verdict = md.find("## Verdict: suspect");
  ASSERT_NE(at_verdict, std::string::npos) << md.substr(0, 600);
  EXPECT_LT(at_verdict, md.find("| quantity | value |"));
  EXPECT_NE(exid::briefTable(r.headline).find("| verdict | suspect: "), std::string::npos);
  fs::remove_all(r.written_to);
}

TEST(Verdict, HeldOutFarAboveTheResidualIsSuspect) {
  // Half the torque recorded: a relative error near 0.5 (better than zero), but far above the
  // identification residual (the noise, 0.01 N m).
  const exid::StudyResult r = runWithValidationGain("0.5", "half");
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(r.headline.validation->relative_error, 1.0);
  EXPECT_EQ(r.headline.verdict, "suspect");
  ASSERT_EQ(r.headline.verdict_reasons.size(), 1u);
  EXPECT_NE(r.headline.verdict_reasons[0].find("times the identification residual"),
            std::string::npos)
      << r.headline.verdict_reasons[0];
}

TEST(Verdict, ReasonsFromTheSummaryTree) {
  auto tree = [](double rel, double val_rms, double id_rms) {
    exid::Json S = exid::Json::object();
    S["validation"]["relative_error"] = rel;
    S["validation"]["residual_rms"] = val_rms;
    S["identification"]["residual_rms"] = id_rms;
    return S;
  };
  EXPECT_TRUE(exid::verdictReasons(tree(0.1, 0.2, 0.1)).empty());    // 2x: not far above
  EXPECT_TRUE(exid::verdictReasons(tree(0.03, 1.0, 0.01)).empty());  // immaterial error
  EXPECT_EQ(exid::verdictReasons(tree(0.1, 0.5, 0.1)).size(), 1u);   // 5x and material
  EXPECT_EQ(exid::verdictReasons(tree(1.0, 1.0, 1.0)).size(), 1u);   // no better than zero
  EXPECT_TRUE(exid::verdictReasons(exid::Json::object()).empty());   // nothing to judge
  // an estimator's own doubt
  exid::Json S = tree(0.1, 0.1, 0.1);
  S["identification"]["details"]["suspect"].push_back(exid::Json("scale at the grid's edge"));
  ASSERT_EQ(exid::verdictReasons(S).size(), 1u);
  EXPECT_EQ(exid::verdictReasons(S)[0], "scale at the grid's edge");
  // a fit far outside its prior: 4 parameters, chi-square(4) has mean 4, std 2.83; 6 std: 21
  exid::Json P = tree(0.1, 0.1, 0.1);
  auto& prior = P["identification"]["details"]["prior"];
  for (int i = 0; i < 4; ++i) prior["value"].push_back(exid::Json(1.0));
  prior["mahalanobis_from_prior"] = 3.0;  // d^2 = 9: inside
  EXPECT_TRUE(exid::verdictReasons(P).empty());
  prior["mahalanobis_from_prior"] = 5.0;  // d^2 = 25: far outside
  ASSERT_EQ(exid::verdictReasons(P).size(), 1u);
  EXPECT_NE(exid::verdictReasons(P)[0].find("far outside its prior"), std::string::npos);
}
