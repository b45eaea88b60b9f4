// A closed chain through the whole study pipeline: the shipped palletiser example, and the
// four-bar identified by batch_ls with its base-parameter count (the palletiser's estimators:
// tests/models/closed_chain_study_test.cpp).
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace {

exid::StudyResult run(const std::string& robot, const std::string& estimator,
                      const std::string& extra = "",
                      const std::string& experiment =
                          "{period_s: 10, harmonics: 5, "
                          "duration_s: 10, sample_period_s: 0.005}") {
  // noise-free: the simulated torques are the model's
  const std::string study =
      "robot: {type: " + robot +
      "}\n"
      "model: {type: differential, params: {rotor_inertia: true, viscous: true, coulomb: true, "
      "offset: true}}\n"
      "experiment: {type: simulate, params: " +
      experiment +
      "}\n"
      "estimator: " +
      estimator + "\n" + extra;
  exid::StudyConfig cfg =
      exid::parseStudy(study, "closed_chain.yaml", exid_test::sourceDir(), exid_test::registry());
  return exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
}

double relErr(const exid::StudyResult& r) {
  const exid::Json* id = r.summary.find("identification");
  if (!id || !id->find("param_rel_err")) return 1e300;
  return id->find("param_rel_err")->asDouble();
}

}  // namespace

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
