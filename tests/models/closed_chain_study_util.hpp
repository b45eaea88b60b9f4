// A closed-chain robot through a whole study, from noise-free simulated data (the helpers of
// tests/models/closed_chain_study_test.cpp and tests/integration/closed_chain_example_test.cpp).
#pragma once

#include <string>

#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace closed_study {

inline exid::StudyResult run(const std::string& robot, const std::string& estimator,
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

inline double relErr(const exid::StudyResult& r) {
  const exid::Json* id = r.summary.find("identification");
  if (!id || !id->find("param_rel_err")) return 1e300;
  return id->find("param_rel_err")->asDouble();
}

}  // namespace closed_study
