// The study key `base_columns`: the model keeps the named full parameters as base columns. The
// identified model is the same (same fit, same residuals: the identifiable space does not
// depend on the choice); the base parameters, their regrouping and the unscaled cond(W) do.
#include <gtest/gtest.h>

#include <algorithm>

#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace {

exid::StudyResult run(const std::string& extra) {
  const std::string study =
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n" +
      extra +
      "experiment: {type: simulate, params: {duration_s: 4, noise_tau_Nm: 0.01}}\n"
      "estimator: {type: batch_ls}\n";
  exid::StudyConfig cfg =
      exid::parseStudy(study, "base_columns.yaml", exid_test::sourceDir(), exid_test::registry());
  return exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
}

std::vector<std::string> baseNames(const exid::StudyResult& r) {
  std::vector<std::string> out;
  const exid::Json* b = r.summary.find("model")->find("base_parameters");
  for (std::size_t i = 0; i < b->size(); ++i) out.push_back(b->at(i).asString());
  return out;
}

}  // namespace

TEST(BaseColumns, NamedColumnsAreKeptAndTheFitIsTheSame) {
  const exid::StudyResult nat = run("");
  const exid::StudyResult named = run("base_columns: [M2, M1]\n");
  ASSERT_TRUE(nat.ok) << nat.message;
  ASSERT_TRUE(named.ok) << named.message;
  const auto n0 = baseNames(nat), n1 = baseNames(named);
  EXPECT_EQ(n0.size(), n1.size());
  EXPECT_NE(std::find(n1.begin(), n1.end(), "M2R"), n1.end());
  EXPECT_EQ(std::find(n1.begin(), n1.end(), "MX2R"), n1.end());
  EXPECT_NE(std::find(n0.begin(), n0.end(), "MX2R"), n0.end());
  // Same data (same seed), same space: the same residual; another basis: another cond(W).
  const double r0 = nat.headline.identification->residual_rms;
  const double r1 = named.headline.identification->residual_rms;
  EXPECT_NEAR(r1, r0, 1e-9 * r0);
  EXPECT_GT(
      std::abs(named.headline.identification->cond_W / nat.headline.identification->cond_W - 1.0),
      1e-3);
  // The key is part of the study: it is in the resolved study and changes its hash.
  const std::string yaml = "robot: {type: planar2r}\nmodel: {type: differential}\n";
  const auto c0 = exid::parseStudy(yaml, "a.yaml", exid_test::sourceDir(), exid_test::registry());
  const auto c1 = exid::parseStudy(yaml + "base_columns: [M2]\n", "a.yaml", exid_test::sourceDir(),
                                   exid_test::registry());
  EXPECT_NE(c0.hash(), c1.hash());
  EXPECT_NE(c1.resolvedYaml().find("base_columns: [M2]"), std::string::npos) << c1.resolvedYaml();
}

TEST(BaseColumns, ADependentOrUnknownColumnFailsTheModelStageNamingIt) {
  // The rotor inertia of joint 1 and ZZ1 have the same column (ZZ1R = ZZ1 + Ia1 - ...).
  const exid::StudyResult dep = run("base_columns: [ZZ1, Ia1]\n");
  ASSERT_FALSE(dep.ok);
  EXPECT_EQ(dep.headline.failed_stage, "model");
  EXPECT_NE(dep.message.find("'Ia1' is a combination of the columns named before it (ZZ1)"),
            std::string::npos)
      << dep.message;
  const exid::StudyResult unknown = run("base_columns: [ZZ7]\n");
  ASSERT_FALSE(unknown.ok);
  EXPECT_NE(unknown.message.find("'ZZ7' is not a parameter of the model"), std::string::npos)
      << unknown.message;
  // Not a list: a configuration error naming the key and its line.
  try {
    exid::parseStudy("robot: {type: planar2r}\nmodel: {type: differential}\nbase_columns: M2\n",
                     "bad.yaml", exid_test::sourceDir(), exid_test::registry());
    ADD_FAILURE() << "no error";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("bad.yaml:3"), std::string::npos) << m;
    EXPECT_NE(m.find("base_columns: expected a non-empty list"), std::string::npos) << m;
  }
}

// `base_columns: pivoted`: the columns of a QR with column pivoting on unit-norm columns (the
// rule of scipy.linalg.qr(pivoting=True) baselines). The same space and fit as the natural
// order, other base columns, and the rule is part of the study.
TEST(BaseColumns, PivotedRuleKeepsOtherColumnsAndTheFitIsTheSame) {
  const exid::StudyResult nat = run("");
  const exid::StudyResult piv = run("base_columns: pivoted\n");
  ASSERT_TRUE(nat.ok) << nat.message;
  ASSERT_TRUE(piv.ok) << piv.message;
  const auto n0 = baseNames(nat), n1 = baseNames(piv);
  EXPECT_EQ(n0.size(), n1.size());
  EXPECT_NE(n0, n1) << ::testing::PrintToString(n1);
  const double r0 = nat.headline.identification->residual_rms;
  const double r1 = piv.headline.identification->residual_rms;
  EXPECT_NEAR(r1, r0, 1e-9 * r0);
  const std::string yaml = "robot: {type: planar2r}\nmodel: {type: differential}\n";
  const auto c0 = exid::parseStudy(yaml, "a.yaml", exid_test::sourceDir(), exid_test::registry());
  const auto c1 = exid::parseStudy(yaml + "base_columns: pivoted\n", "a.yaml",
                                   exid_test::sourceDir(), exid_test::registry());
  EXPECT_NE(c0.hash(), c1.hash());
  EXPECT_NE(c1.resolvedYaml().find("base_columns: pivoted"), std::string::npos)
      << c1.resolvedYaml();
  // Another word is an error naming the key, its line and both forms.
  try {
    exid::parseStudy(yaml + "base_columns: pivot\n", "bad.yaml", exid_test::sourceDir(),
                     exid_test::registry());
    ADD_FAILURE() << "no error";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("bad.yaml:3"), std::string::npos) << m;
    EXPECT_NE(m.find("or `pivoted`"), std::string::npos) << m;
  }
}
