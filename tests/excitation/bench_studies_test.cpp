// The benchmark studies (examples/bench): run through exid::runStudy, then cond(W) is recomputed
// from trajectory_optimal.csv (the file is what counts) and the limits are checked at every
// sample. Budgets are evaluations, never time: a study gives the same trajectory, bit for bit,
// on any machine, loaded or not (checked: two runs write identical files). What the optimisers
// reach within a CPU-time budget (Panda <= 33.3 in < 1 s, <= 30 in 10 s; PUMA 560 <= 6.04 in
// < 2 s) is measured by benchmarks/bench_studies.cpp (bash scripts/bench.sh studies), not here.
// What each study reaches is held to the digits docs/excitation.md §6 and the studies' comments
// print (kQuoted): a change that moves a design fails here until those figures are regenerated.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <iterator>

#include "exid/config.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace {

// cond(W) as docs/excitation.md §6 prints it (4 decimals): the same basin gives the same digits
// (the AVX2 kernels' last bits do), another basin does not.
void expectQuoted(double cond, double quoted, const char* where) {
  EXPECT_NEAR(cond, quoted, 5e-5) << where
                                  << ": the figure quoted in docs/excitation.md §6 moved; "
                                     "regenerate it (bash scripts/bench.sh studies)";
}

struct Outcome {
  double cond = HUGE_VAL, wall_s = 0, cpu_s = HUGE_VAL, reported = 0, violation = HUGE_VAL;
  long evaluations = 0;
  std::string stop, csv;
};

// starts > 0 replaces the study's starts, with start_evaluations per start and max_evaluations
// in all (the study's own evaluation budget otherwise).
// The trajectory a study wrote (t, q, qd, qdd of n joints).
exid::Samples writtenTrajectory(const exid::CsvTable& T, int n) {
  exid::Samples s;
  s.t = T.column("t");
  s.q.resize(s.t.size(), n);
  s.qd = s.q;
  s.qdd = s.q;
  for (int j = 0; j < n; ++j) {
    s.q.col(j) = T.column("q" + std::to_string(j + 1));
    s.qd.col(j) = T.column("qd" + std::to_string(j + 1));
    s.qdd.col(j) = T.column("qdd" + std::to_string(j + 1));
  }
  return s;
}

// The study's model bound to its robot as the study binds it (seed, base columns).
std::shared_ptr<exid::ObservationModel> boundModel(const exid::StudyConfig& cfg) {
  exid::RunContext ctx;
  ctx.seed = cfg.seed;
  auto robot =
      exid_test::registry().create<exid::Robot>(cfg.robot->type, cfg.robot->params)->build(ctx);
  std::shared_ptr<exid::ObservationModel> model =
      exid_test::registry().create<exid::ObservationModel>(cfg.models[0].type,
                                                           cfg.models[0].params);
  if (!cfg.base_columns.empty()) model->preferBaseColumns(cfg.base_columns);
  if (cfg.base_columns_pivoted) model->baseColumnRule(exid::BaseParameterOptions::Rule::Pivoted);
  model->bind(robot, ctx);
  return model;
}

// pivoted: the study on `base_columns: pivoted` (the baselines' rule).
Outcome runBench(const std::string& file, double vcap, int starts = 0, int start_evaluations = 0,
                 int max_evaluations = 0, const std::string& suffix = "", bool pivoted = false) {
  const auto path = exid_test::sourceDir() / "examples" / "bench" / file;
  exid::StudyConfig cfg = exid::loadStudy(path, exid_test::registry());
  if (pivoted) {
    cfg.base_columns_pivoted = true;
    cfg.name += "_pivoted";
  }
  if (starts > 0) {
    cfg.optimizer->params.set("starts", static_cast<std::int64_t>(starts));
    cfg.optimizer->params.set("start_evaluations", static_cast<std::int64_t>(start_evaluations));
    cfg.optimizer->params.set("max_evaluations", static_cast<std::int64_t>(max_evaluations));
    cfg.name += "_starts" + std::to_string(starts);
  }
  cfg.name += suffix;
  const auto out = std::filesystem::temp_directory_path() / ("exid_bench_" + cfg.name);
  std::filesystem::remove_all(out);
  exid::RunOptions opt;
  opt.out_dir = out;
  const auto t0 = std::chrono::steady_clock::now();
  exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), opt);
  Outcome o;
  o.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(r.ok) << r.message;
  if (!r.ok) return o;
  const exid::Json* x = r.summary.find("excitation");
  if (x && x->find("wall_s")) o.wall_s = x->find("wall_s")->asDouble();
  if (x && x->find("criterion_final")) o.reported = x->find("criterion_final")->asDouble();
  if (x && x->find("details") && x->find("details")->find("cpu_s"))
    o.cpu_s = x->find("details")->find("cpu_s")->asDouble();
  // recompute from the CSV with a freshly bound model
  exid::CsvTable T = exid::readCsv(out / "trajectory_optimal.csv");
  const auto model = boundModel(cfg);
  const exid::RobotModel& robot_model = model->robot();
  const int n = robot_model.dof();
  const exid::Samples s = writtenTrajectory(T, n);
  EXPECT_EQ(s.size(), 100);
  o.cond = exid::conditionNumber(model->design(s));
  double v = 0;
  const double margin = cfg.trajectory->params.getDouble("position_margin_rad");
  for (int j = 0; j < n; ++j) {
    const auto& L = robot_model.limits[static_cast<std::size_t>(j)];
    v = std::max(v, s.q.col(j).maxCoeff() - (L.q_max - margin));
    v = std::max(v, (L.q_min + margin) - s.q.col(j).minCoeff());
    if (L.qd_max < 1e299) v = std::max(v, s.qd.col(j).cwiseAbs().maxCoeff() - L.qd_max);
    if (vcap > 0) v = std::max(v, s.qd.col(j).cwiseAbs().maxCoeff() - vcap);
  }
  o.violation = v;
  o.evaluations = static_cast<long>(x->find("evaluations")->asDouble());
  o.stop = x->find("stop_reason")->asString();
  {
    std::ifstream in(out / "trajectory_optimal.csv", std::ios::binary);
    o.csv.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  EXPECT_TRUE(x->find("reproducible")->asBool()) << o.stop;
  EXPECT_EQ(r.summary.find("warnings")->size(), 0u) << r.summary.find("warnings")->dump(0);
  std::cout << "[bench] " << cfg.name << ": cond(W) from CSV " << o.cond << " (reported "
            << o.reported << "), " << o.evaluations << " evaluations (" << o.stop
            << "), excitation CPU " << o.cpu_s << " s, wall " << o.wall_s << " s, max violation "
            << v << "\n";
  return o;
}

TEST(BenchStudies, PandaFourierTwoStarts) {
  // the small budget (the "1 s" question of the benchmark): two starts of at most 300
  // evaluations each, 1000 in all; reached 28.5854 in 601 evaluations (the polish converges)
  Outcome o = runBench("panda_fourier.yaml", 0.0, 2, 300, 1000);
  EXPECT_LE(o.cond, 33.3);
  expectQuoted(o.cond, 28.5854, "panda_fourier, two starts");
  EXPECT_LE(o.evaluations, 1000);
  EXPECT_LE(o.violation, 1e-9);
  EXPECT_NEAR(o.cond, o.reported, 1e-6 * o.reported);
}

TEST(BenchStudies, PandaFourierTorqueLimited) {
  // the Panda study with its torque limited to 80 % of Franka's published limits (two starts,
  // 1000 evaluations): as good as the SciPy baseline without torque limits (<= 33.3), and every
  // design sample's torque, recomputed from the written trajectory, within the margin; reached
  // 31.7088 in 727 evaluations
  Outcome o = runBench("panda_fourier_torque.yaml", 0.0);
  EXPECT_LE(o.cond, 33.3);
  expectQuoted(o.cond, 31.7088, "panda_fourier_torque");
  EXPECT_LE(o.evaluations, 1000);
  EXPECT_LE(o.violation, 1e-9);
  EXPECT_NEAR(o.cond, o.reported, 1e-6 * o.reported);
  const exid::CsvTable T =
      exid::readCsv(std::filesystem::temp_directory_path() / "exid_bench_panda_fourier_torque" /
                    "trajectory_optimal.csv");
  const Eigen::MatrixXd tau =
      exid::predictedTorques(*exid_test::robot("panda"), writtenTrajectory(T, 7));
  const double tau_max[7] = {87, 87, 87, 87, 12, 12, 12};
  double ratio = 0;
  for (int j = 0; j < 7; ++j)
    ratio = std::max(ratio, tau.col(j).cwiseAbs().maxCoeff() / tau_max[j]);
  EXPECT_LE(ratio, 0.8 + 1e-9);
}

TEST(BenchStudies, PandaFourier) {
  // the study as shipped (40 starts, 8000 evaluations): at least as good as the SciPy baseline
  // (33.3); reached 28.5854 in 5822 evaluations, the same bits on every CPU since exid evaluates
  // its own sin/cos/exp/log (LibmPaths.*; before, the same binary ended at 27.87, 29.76 and 30.53
  // on x86-64 machines whose glibc picked other variants: docs/excitation.md §6).
  Outcome o = runBench("panda_fourier.yaml", 0.0);
  EXPECT_LE(o.cond, 33.3);
  expectQuoted(o.cond, 28.5854, "panda_fourier");
  EXPECT_LE(o.evaluations, 8000);
  EXPECT_LE(o.violation, 1e-9);
  EXPECT_NEAR(o.cond, o.reported, 1e-6 * o.reported);
}

TEST(BenchStudies, Puma560FourierOnThePivotedColumns) {
  // The study on the SciPy baseline's rule (`base_columns: pivoted`, docs/excitation.md §10):
  // cond recomputed from the CSV on a model bound with that rule equals the study's own, and
  // the trajectory's cond on the natural columns differs (the rule took effect). As shipped
  // (2000 evaluations) it reaches 6.5327, not the baseline's 6.04 (a goal not met, §6).
  Outcome o = runBench("puma560_fourier.yaml", 3.0, 0, 0, 0, "", true);
  EXPECT_NEAR(o.cond, o.reported, 1e-6 * o.reported);
  expectQuoted(o.cond, 6.5327, "puma560_fourier on pivoted columns");
  EXPECT_LE(o.violation, 1e-9);
  Outcome natural_cols;
  {
    const auto model = boundModel(
        exid::loadStudy(exid_test::sourceDir() / "examples" / "bench" / "puma560_fourier.yaml",
                        exid_test::registry()));
    const exid::CsvTable T =
        exid::readCsv(std::filesystem::temp_directory_path() /
                      "exid_bench_puma560_fourier_pivoted" / "trajectory_optimal.csv");
    natural_cols.cond = exid::conditionNumber(model->design(writtenTrajectory(T, 6)));
  }
  EXPECT_GT(std::abs(natural_cols.cond / o.cond - 1.0), 0.05) << natural_cols.cond;
}

TEST(BenchStudies, Puma560FourierIsReproducibleBitForBit) {
  // the study as shipped (one start, then the epigraph polish; 2000 evaluations): <= 6.04;
  // reached 6.00000. Run twice: the same file, byte for byte.
  Outcome a = runBench("puma560_fourier.yaml", 3.0, 0, 0, 0, "_a");
  EXPECT_LE(a.cond, 6.04);
  expectQuoted(a.cond, 6.0000, "puma560_fourier");
  EXPECT_EQ(a.evaluations, 2000);
  EXPECT_EQ(a.stop, "max_evaluations");
  EXPECT_LE(a.violation, 1e-9);
  EXPECT_NEAR(a.cond, a.reported, 1e-6 * a.reported);
  Outcome b = runBench("puma560_fourier.yaml", 3.0, 0, 0, 0, "_b");
  EXPECT_FALSE(a.csv.empty());
  EXPECT_EQ(a.csv, b.csv) << "two runs of the same study gave different trajectories";
  EXPECT_EQ(a.cond, b.cond);
}

}  // namespace

TEST(BenchStudies, PandaFourierTableWithSelfCollision) {
  // the torque-limited study with self-collision and a table 2 cm away at every design sample
  // (two starts, 1000 evaluations): cond <= 40, feasible; reached 38.2566 in 789 evaluations.
  // Every design sample's distances, recomputed from the written trajectory, hold the margin.
  Outcome o = runBench("panda_fourier_table.yaml", 0.0);
  EXPECT_LE(o.cond, 40.0);
  expectQuoted(o.cond, 38.2566, "panda_fourier_table");
  EXPECT_LE(o.evaluations, 1000);
  EXPECT_LE(o.violation, 1e-9);
  const exid::CsvTable T =
      exid::readCsv(std::filesystem::temp_directory_path() / "exid_bench_panda_fourier_table" /
                    "trajectory_optimal.csv");
  const exid::StudyConfig cfg =
      exid::loadStudy(exid_test::sourceDir() / "examples" / "bench" / "panda_fourier_table.yaml",
                      exid_test::registry());
  ASSERT_TRUE(cfg.excitation_collision);
  exid::CollisionModel cm(*exid_test::robot("panda"), *cfg.excitation_collision);
  EXPECT_EQ(cm.numPairs(), 28);
  double smallest = HUGE_VAL;
  Eigen::VectorXd q(7), d;
  for (Eigen::Index k = 0; k < T.data.rows(); ++k) {
    for (int j = 0; j < 7; ++j) q(j) = T.column("q" + std::to_string(j + 1))(k);
    cm.distances(q, &d);
    smallest = std::min(smallest, d.minCoeff());
  }
  EXPECT_GE(smallest, 0.02 - 1e-9);
}
