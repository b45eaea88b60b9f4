// A closed chain through the whole study pipeline: the shipped palletiser example, and the
// four-bar identified by batch_ls with its base-parameter count (the palletiser's estimators:
// tests/models/closed_chain_study_test.cpp).
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../models/closed_chain_study_util.hpp"
#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

using closed_study::relErr;
using closed_study::run;

TEST(ClosedChainStudy, FourbarIdentifies) {
  const exid::StudyResult r = run("fourbar", "{type: batch_ls}");
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(relErr(r), 1e-9);
  // 8 inertial base parameters (tests/robots/closed_chain_robots_test.cpp) + Fc1, Fv1, OFF1
  // (Ia1's column is ZZ1's: the crank turns about a fixed axis)
  EXPECT_EQ(r.summary.find("robot")->find("n_base_parameters")->asDouble(), 8 + 3);
}

TEST(ClosedChainStudy, ExampleStudyRuns) {
  exid::StudyConfig cfg =
      exid::loadStudy(exid_test::sourceDir() / "examples/palletizer.yaml", exid_test::registry());
  const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(relErr(r), 0.05);
}
