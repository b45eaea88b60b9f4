// Stacked observation models: differential + load_wrench in one study, each block with its
// weight; the columns are the union (matched by name) and the base parameters those of the stack.
#include <gtest/gtest.h>

#include <filesystem>

#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

TEST(StackedModels, DifferentialPlusLoadWrenchRecoverRobotAndPayloadTogether) {
  const std::string payload =
      "payload_mass_kg: 1.5, payload_com_m: [0.02, -0.01, 0.06], payload_inertia_kg_m2: [0.003, 0, "
      "0, 0.004, 0, 0.002]";
  const std::string study =
      "robot: {type: puma560}\n"
      "model:\n"
      "  - {type: differential, weight: 1.0, params: {rotor_inertia: false, coulomb: false, "
      "viscous: false}}\n"
      "  - {type: load_wrench, weight: 2.0, params: {" +
      payload +
      "}}\n"
      "experiment: {type: simulate, params: {duration_s: 6, drive_terms: false, wrench: true, " +
      payload +
      "}}\n"
      "estimator: {type: batch_ls}\n";
  exid::StudyConfig cfg =
      exid::parseStudy(study, "stacked.yaml", exid_test::sourceDir(), exid_test::registry());
  ASSERT_EQ(cfg.models.size(), 2u);
  exid::RunOptions opt;
  exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), opt);
  ASSERT_TRUE(r.ok) << r.message;
  const exid::Json& s = r.summary;
  // Union of columns: 60 robot inertial + 10 payload parameters.
  EXPECT_EQ(s.find("model")->find("n_full")->asInt(), 70);
  // The payload's parameters are separately identifiable through the wrench; the robot's 36.
  EXPECT_EQ(s.find("model")->find("n_base")->asInt(), 46);
  // The simulated robot carries the payload, so the differential block's truth is robot + payload:
  // the stack explains the torques and the wrench exactly (noise-free): residual ~ 0.
  EXPECT_LT(s.find("identification")->find("residual_rms")->asDouble(), 1e-8);
  // Payload parameters: estimated = nominal (the payload given in the model's params).
  int checked = 0;
  const exid::Json& params = *s.find("identification")->find("parameters");
  for (std::size_t i = 0; i < params.size(); ++i) {
    const std::string name = params.at(i).find("name")->asString();
    if (name.rfind("L_", 0) != 0) continue;
    EXPECT_NEAR(params.at(i).find("value")->asDouble(), params.at(i).find("nominal")->asDouble(),
                1e-8)
        << name;
    ++checked;
  }
  EXPECT_EQ(checked, 10);
}
