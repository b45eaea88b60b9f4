// A study's stages as units (framework/study/src/stages.hpp): each called on its own with its
// typed inputs, its output checked, and its one record rendered into the same summary.json keys
// and values as a whole run gives (wall-clock times aside).
#include "stages.hpp"  // framework/study/src

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "exid/config.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace {

const char* kStudy =
    "name: stages_as_units\n"
    "seed: 3\n"
    "robot: {type: planar2r}\n"
    "model: {type: differential, params: {viscous: true}}\n"
    "excitation:\n"
    "  trajectory: {type: fourier, params: {harmonics: 2, period_s: 4}}\n"
    "  criterion: {type: cond}\n"
    "  optimizer: {type: nlopt, params: {max_evaluations: 150}}\n";

exid::StudyConfig study(const std::string& text) {
  return exid::parseStudy(text, "stages.yaml", exid_test::sourceDir(), exid_test::registry());
}

// The keys of a summary.json object, in order.
std::vector<std::string> keys(const exid::Json& j) {
  std::vector<std::string> k;
  for (const auto& [name, value] : j.items()) k.push_back(name);
  return k;
}

// Equal but for wall-clock and CPU times (wall_s, cpu_s, the histories' time stamps).
void expectSameButTimes(const exid::Json& a, const exid::Json& b, const std::string& where) {
  ASSERT_EQ(keys(a), keys(b)) << where;
  if (a.isObject()) {
    for (const auto& [name, value] : a.items()) {
      if (name == "wall_s" || name == "cpu_s" || name == "t_s" || name == "history_cpu_s") continue;
      expectSameButTimes(value, *b.find(name), where + "." + name);
    }
    return;
  }
  if (a.isArray()) {
    for (std::size_t i = 0; i < a.size(); ++i)
      expectSameButTimes(a.at(i), b.at(i), where + "[" + std::to_string(i) + "]");
    return;
  }
  EXPECT_EQ(a.dump(0), b.dump(0)) << where;
}

}  // namespace

TEST(Stages, RobotAndModelStagesAreUnitsWithTypedOutputs) {
  const exid::StudyConfig cfg = study(kStudy);
  exid::RunOptions opt;
  const exid::StageEnv env(cfg, exid_test::registry(), opt, {});
  const char* entered = nullptr;
  exid::StageEnv named(cfg, exid_test::registry(), opt, {},
                       [&](const char* stage) { entered = stage; });

  const exid::RobotStageOut robot = exid::robotStage(named);
  EXPECT_STREQ(entered, "robot");
  ASSERT_TRUE(robot.robot);
  EXPECT_EQ(robot.robot->dof(), 2);
  EXPECT_EQ(robot.summary.type, "planar2r");
  EXPECT_EQ(robot.summary.dof, 2);
  EXPECT_EQ(robot.summary.n_parameters, robot.robot->numInertialParameters());
  EXPECT_FALSE(robot.summary.n_base_parameters);  // no model yet

  const exid::ModelStageOut model = exid::modelStage(env, robot);
  ASSERT_TRUE(model.model);
  EXPECT_EQ(model.type, "differential");
  EXPECT_EQ(model.n_base, model.model->numBase());
  EXPECT_EQ(model.base_parameters, model.model->base().names);
  EXPECT_GT(model.n_full, model.n_base);
  EXPECT_TRUE(model.traj);  // the excitation's trajectory, bound to the robot
  EXPECT_TRUE(model.moving_joints.empty());

  // The records render into summary.json's keys and the typed results, nothing else.
  exid::Json S = exid::Json::object();
  exid::StudySummary T;
  exid::StudyRecord rec{&S, &T, nullptr};
  exid::record(env, robot, rec);
  ASSERT_TRUE(T.robot);
  EXPECT_FALSE(T.robot->n_base_parameters);
  exid::record(env, model, rec);
  EXPECT_EQ(T.robot->n_base_parameters, model.n_base);
  EXPECT_EQ(T.robot->n_parameters, model.n_full);
  EXPECT_EQ(keys(S), (std::vector<std::string>{"robot", "model"}));

  // ... the same as a whole run's.
  const exid::StudyResult whole = exid::runStudy(cfg, exid_test::registry(), opt);
  ASSERT_TRUE(whole.ok) << whole.message;
  for (const char* part : {"robot", "model"}) {
    ASSERT_TRUE(whole.summary.find(part)) << part;
    expectSameButTimes(*S.find(part), *whole.summary.find(part), part);
  }
  EXPECT_EQ(whole.headline.robot->n_base_parameters, T.robot->n_base_parameters);
}

TEST(Stages, TheExcitationStageRecordsWhatAWholeRunRecords) {
  const exid::StudyConfig cfg = study(kStudy);
  exid::RunOptions opt;
  const exid::StageEnv env(cfg, exid_test::registry(), opt, {});
  const exid::RobotStageOut robot = exid::robotStage(env);
  const exid::ModelStageOut model = exid::modelStage(env, robot);
  const exid::ExcitationStageOut x = exid::excitationStage(env, robot, model);
  ASSERT_TRUE(x.ran);
  EXPECT_EQ(x.traj, model.traj);  // the model stage's trajectory, optimised
  EXPECT_EQ(x.best.size(), x.initial.size());
  EXPECT_LE(x.summary.criterion_final, x.summary.criterion_initial);
  EXPECT_EQ(x.summary.criterion_final, x.result.criterion_final);
  EXPECT_EQ(x.summary.optimizer, "nlopt");

  exid::Json S = exid::Json::object();
  exid::StudySummary T;
  exid::StudyRecord rec{&S, &T, nullptr};
  exid::record(env, robot, rec);
  exid::record(env, model, rec);
  exid::record(env, x, rec);
  ASSERT_TRUE(T.excitation);
  EXPECT_EQ(T.excitation->criterion_final, x.summary.criterion_final);

  const exid::StudyResult whole = exid::runStudy(cfg, exid_test::registry(), opt);
  ASSERT_TRUE(whole.ok) << whole.message;
  ASSERT_TRUE(whole.summary.find("excitation"));
  expectSameButTimes(*S.find("excitation"), *whole.summary.find("excitation"), "excitation");
  EXPECT_EQ(T.warnings, whole.headline.warnings);
}

TEST(Stages, AStageWithoutItsSectionRecordsNothing) {
  const exid::StudyConfig cfg = study(
      "name: robot_only\n"
      "robot: {type: planar2r}\n");
  exid::RunOptions opt;
  const exid::StageEnv env(cfg, exid_test::registry(), opt, {});
  const exid::RobotStageOut robot = exid::robotStage(env);
  const exid::ModelStageOut model = exid::modelStage(env, robot);
  EXPECT_FALSE(model.model);
  const exid::ExcitationStageOut x = exid::excitationStage(env, robot, model);
  EXPECT_FALSE(x.ran);
  exid::StudyEstimator estimator(cfg, exid_test::registry());
  const exid::ExperimentStageOut e = exid::experimentStage(env, robot, model, x, estimator);
  EXPECT_FALSE(e.data);

  exid::Json S = exid::Json::object();
  exid::StudySummary T;
  exid::StudyRecord rec{&S, &T, nullptr};
  exid::record(env, robot, rec);
  exid::record(env, model, rec);
  exid::record(env, x, rec);
  exid::record(env, e, rec);
  EXPECT_EQ(keys(S), (std::vector<std::string>{"robot"}));
  EXPECT_FALSE(T.excitation);
  EXPECT_FALSE(T.experiment);
}
