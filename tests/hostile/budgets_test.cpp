// Issue 37, "check-trajectory validates like the csv experiment" and "a work budget per stage"
// (docs/hostile_input.md): the exid program, run as a child process, on trajectory files that
// are not what they claim, non-finite limits, YAML aliases that multiply a study, stacks of
// thousands of models, unstable PD gains, resampled sizes, a cell memory cap too small to run
// anything and geometry beyond any robot cell. Each bad input is refused naming the file and
// the key (or row); each test shows the normal case still working beside it.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "../models/closed_loop_test_util.hpp"
#include "../models/model_test_util.hpp"
#include "exid/collision.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/robot_loaders.hpp"
#include "exid_cli.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_budgets_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

using CmdResult = exid_cli::RunResult;

CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir, double timeout_s = 120,
                  long address_space_mb = 0) {
  return exid_cli::runExidIn(args, dir, timeout_s, exid_cli::Limits{address_space_mb});
}

using exid_cli::contains;

using exid_cli::underAddressSanitizer;

// A trajectory file of planar2r (2 joints): t, q1, q2, qd1, qd2, qdd1, qdd2 at 100 Hz, a slow
// motion well within the robot's limits (qd_max 3 rad/s, qdd_max 10 rad/s^2).
std::vector<std::vector<double>> slowMotion(int K) {
  std::vector<std::vector<double>> rows;
  for (int k = 0; k < K; ++k) {
    const double t = 0.01 * k;
    rows.push_back({t, 0.3 * std::sin(t), 0.2 * std::cos(t), 0.3 * std::cos(t), -0.2 * std::sin(t),
                    -0.3 * std::sin(t), -0.2 * std::cos(t)});
  }
  return rows;
}

void writeRows(const fs::path& f, const std::string& header,
               const std::vector<std::vector<double>>& rows) {
  std::ofstream o(f);
  o << header << "\n";
  for (const auto& r : rows) {
    for (std::size_t i = 0; i < r.size(); ++i) o << (i ? "," : "") << fmt::format("{:.17g}", r[i]);
    o << "\n";
  }
}

constexpr const char* kHeader2 = "t,q1,q2,qd1,qd2,qdd1,qdd2";

// ------------------------------------------------------------------ check-trajectory

// A file whose time runs backwards passed ("2001 samples at 0 Hz ... every limit holds"), so
// did swapped and repeated rows, gaps, and a 3-joint file for a 2-joint robot (q3 ignored).
// Each is now refused with exit 2, naming the file and the line; the good file still passes and
// a file over a limit still fails.
TEST(Budgets, CheckTrajectoryRefusesFilesThatAreNotUniformTrajectoriesOfTheRobot) {
  const fs::path dir = tempDir("checktraj");
  const auto good = slowMotion(201);
  writeRows(dir / "good.csv", kHeader2, good);
  CmdResult r = runExid({"check-trajectory", "planar2r", "good.csv"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "every limit holds")) << r.out;

  auto over = good;  // qd1 = 3.5 rad/s at one sample: over the limit of 3
  over[100][3] = 3.5;
  writeRows(dir / "over.csv", kHeader2, over);
  r = runExid({"check-trajectory", "planar2r", "over.csv"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "exceeds a limit")) << r.out;

  auto backwards = good;  // time runs backwards
  for (std::size_t k = 0; k < backwards.size(); ++k) backwards[k][0] = -0.01 * k;
  writeRows(dir / "backwards.csv", kHeader2, backwards);
  r = runExid({"check-trajectory", "planar2r", "backwards.csv"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "backwards.csv: line 3 (data row 2): column 't': time must strictly "
                       "increase"))
      << r.out;

  auto swapped = good;  // rows 50 and 51 (data rows 51, 52) swapped
  std::swap(swapped[50], swapped[51]);
  writeRows(dir / "swapped.csv", kHeader2, swapped);
  r = runExid({"check-trajectory", "planar2r", "swapped.csv"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "swapped.csv: line 53 (data row 52)")) << r.out;

  auto repeated = good;  // data row 81 written twice
  repeated.insert(repeated.begin() + 80, repeated[80]);
  writeRows(dir / "repeated.csv", kHeader2, repeated);
  r = runExid({"check-trajectory", "planar2r", "repeated.csv"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "repeated.csv: line 83 (data row 82)")) << r.out;
  EXPECT_TRUE(contains(r.out, "time must strictly increase")) << r.out;

  auto gap = good;  // 20 rows missing after data row 120
  gap.erase(gap.begin() + 120, gap.begin() + 140);
  writeRows(dir / "gap.csv", kHeader2, gap);
  r = runExid({"check-trajectory", "planar2r", "gap.csv"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "gap.csv: line 122 (data row 121): time step")) << r.out;
  EXPECT_TRUE(contains(r.out, "a gap")) << r.out;

  std::vector<std::vector<double>> three;  // a 3-joint file for the 2-joint robot
  for (const auto& g : good)
    three.push_back({g[0], g[1], g[2], 0.1, g[3], g[4], 0.0, g[5], g[6], 0.0});
  writeRows(dir / "three.csv", "t,q1,q2,q3,qd1,qd2,qd3,qdd1,qdd2,qdd3", three);
  r = runExid({"check-trajectory", "planar2r", "three.csv"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "three.csv: column 'q3': joint 3 is not a joint of the robot"))
      << r.out;
  fs::remove_all(dir);
}

// --torque-max-nm=nan,nan switched the torque check off (NaN compares false): every limit must
// be a finite torque > 0, one per joint, or the command is refused naming the flag.
TEST(Budgets, CheckTrajectoryRefusesLimitsThatAreNotFinitePositiveTorques) {
  const fs::path dir = tempDir("checklimits");
  writeRows(dir / "good.csv", kHeader2, slowMotion(101));
  for (const char* bad : {"--torque-max-nm=nan,nan", "--torque-max-nm=inf,5", "--torque-max-nm=5,0",
                          "--torque-max-nm=-5,5", "--torque-max-nm=5"}) {
    const CmdResult r = runExid({"check-trajectory", "planar2r", "good.csv", bad}, dir);
    EXPECT_EQ(r.code, 2) << bad << "\n" << r.out;
    EXPECT_TRUE(contains(r.out, "--torque-max-nm: ")) << bad << "\n" << r.out;
  }
  // finite limits: the torque is checked (a limit far above holds, one far below fails)
  CmdResult r =
      runExid({"check-trajectory", "planar2r", "good.csv", "--torque-max-nm=500,500"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "every limit holds")) << r.out;
  r = runExid({"check-trajectory", "planar2r", "good.csv", "--torque-max-nm=1e-6,1e-6"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ YAML aliases, model stacks

// Aliases are shared by yaml-cpp, so a 35 KB study can stand for millions of nodes. Their
// expansion is counted from the parser's events before any node is built and refused past
// kMaxYamlAliasNodes, naming the file, the line and the key where the alias stands; a study
// that shares a block through an alias or two is read as before.
TEST(Budgets, YamlAliasesBeyondTheirBudgetAreRefusedNamingTheKey) {
  const fs::path dir = tempDir("aliases");
  std::ofstream(dir / "shared.yaml") << "robot: {type: planar2r}\n"
                                        "model: {type: differential}\n"
                                        "experiment: &sim {type: simulate, params: {duration_s: 2, "
                                        "sample_period_s: 0.01}}\n"
                                        "estimator: {type: batch_ls}\n"
                                        "validation: *sim\n";
  CmdResult r = runExid({"validate", "shared.yaml"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  // seven levels of ten aliases over a list of ten: about 10^8 nodes from 526 bytes
  std::string lol =
      "robot: {type: planar2r}\nreport:\n  params:\n    l0: &l0 [x, x, x, x, x, x, "
      "x, x, x, x]\n";
  for (int i = 1; i <= 7; ++i) {
    lol += fmt::format("    l{}: &l{} [", i, i);
    for (int j = 0; j < 10; ++j) lol += fmt::format("{}*l{}", j ? ", " : "", i - 1);
    lol += "]\n";
  }
  std::ofstream(dir / "lol.yaml") << lol;
  r = runExid({"validate", "lol.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "lol.yaml:8: report.params.l4[7]: alias *l3 takes the nodes "
                       "reached through aliases beyond 100000"))
      << r.out;
  // the same in a matrix file
  std::ofstream(dir / "m.yaml") << "name: m\nstudy: {robot: {type: planar2r}}\n" +
                                       lol.substr(lol.find("report:"));
  r = runExid({"matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "m.yaml:9: report.params.l4[7]: alias *l3")) << r.out;
  EXPECT_FALSE(fs::exists(dir / "o" / "results.sqlite"));
  // an alias inside its own anchor's node (fuzz_study found it: 2 million nodes visited, a
  // timeout): a cycle, refused at once
  std::ofstream(dir / "cycle.yaml")
      << "robot: {type: planar2r}\nreport:\n  params:\n    l0: &l0 [x, x, *l0, *l0]\n";
  r = runExid({"validate", "cycle.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "cycle.yaml:4: report.params.l0[2]: alias *l0 stands inside the "
                       "node its anchor &l0 names: a cycle"))
      << r.out;
  fs::remove_all(dir);
}

// 5,000 models stacked through one alias (a 35 KB study) took 3.2 GB: a stack holds at most
// 64 models, refused by `exid validate` before anything is built; a stack of two still runs.
TEST(Budgets, AStackOfThousandsOfModelsIsRefused) {
  const fs::path dir = tempDir("stack");
  std::string y =
      "robot: {type: planar2r}\nmodel:\n  - &m {type: differential, params: "
      "{viscous: true, coulomb: true}}\n";
  for (int i = 1; i < 5000; ++i) y += "  - *m\n";
  y += "experiment: {type: simulate, params: {duration_s: 2, sample_period_s: 0.001}}\n"
       "estimator: {type: batch_ls}\n";
  std::ofstream(dir / "stack.yaml") << y;
  const long cap_mb = underAddressSanitizer() ? 0 : 1500;  // (the old code took GBs)
  CmdResult r = runExid({"validate", "stack.yaml"}, dir, 120, cap_mb);
  EXPECT_EQ(r.code, 2) << r.out.substr(0, 2000);
  EXPECT_TRUE(contains(r.out, "stack.yaml:3: model: a stack of 5000 models; at most 64"))
      << r.out.substr(0, 2000);
  r = runExid({"run", "stack.yaml", "--out", "o"}, dir, 120, cap_mb);
  EXPECT_EQ(r.code, 2) << r.out.substr(0, 2000);
  EXPECT_FALSE(fs::exists(dir / "o"));
  std::ofstream(dir / "two.yaml")
      << "robot: {type: planar2r}\nmodel:\n  - &m {type: differential, params: {viscous: true}}\n"
         "  - *m\nexperiment: {type: simulate, params: {duration_s: 2, sample_period_s: 0.01}}\n"
         "estimator: {type: batch_ls}\nreport: {params: {plots: false}}\n";
  r = runExid({"run", "two.yaml", "--out", "o2"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ simulated closed loop

// `iv` with negative gains simulated until killed: the PD gains must be finite and >= 0
// (refused by `exid validate`, naming the key and the element), and CVODES's steps between two
// samples are bounded by max_steps (CV_ONE_STEP ignored it: nothing bounded the steps).
TEST(Budgets, ClosedLoopGainsAreCheckedAndItsStepsBounded) {
  const fs::path dir = tempDir("iv");
  auto robot = mtest::robot("planar2r");
  const exid::Samples ref = cltest::reference(robot->dof(), 1.0);
  cltest::writeReference(ref, dir / "reference.csv");
  auto study = [&](const std::string& gains) {
    return "robot: {type: planar2r}\nmodel: {type: differential}\n"
           "experiment: {type: simulate, params: {duration_s: 0.5, sample_period_s: 0.01}}\n"
           "estimator:\n  type: iv\n  params: {reference_file: reference.csv, " +
           gains + "}\n";
  };
  std::ofstream(dir / "negative.yaml")
      << study("kp_Nm_per_rad: [100, -100], kd_Nm_s_per_rad: [10]");
  CmdResult r = runExid({"validate", "negative.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "negative.yaml:5: estimator: ")) << r.out;
  EXPECT_TRUE(
      contains(r.out, "iv: kp_Nm_per_rad[1] = -100: a PD gain must be a finite number >= 0"))
      << r.out;
  std::ofstream(dir / "negative_kd.yaml") << study("kp_Nm_per_rad: [100], kd_Nm_s_per_rad: [-1]");
  r = runExid({"validate", "negative_kd.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "kd_Nm_s_per_rad[0] = -1")) << r.out;
  std::ofstream(dir / "positive.yaml") << study("kp_Nm_per_rad: [100], kd_Nm_s_per_rad: [10]");
  r = runExid({"validate", "positive.yaml"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;

  // the step bound, in process: the closed loop of planar2r at its own parameters
  const exid::Dataset data = mtest::simulate(
      robot, "{controller: pd_feedforward, kp: 100, kd: 10, sample_period_s: 0.01}", 7, &ref);
  auto model = mtest::model("differential", "{}", robot);
  auto estimateWith = [&](const std::string& extra) {
    auto iv = exid_test::create<exid::Estimator>(
        "iv", fmt::format("{{reference_file: {}, {}{}}}", (dir / "reference.csv").string(),
                          cltest::gains(data.meta), extra));
    return iv->estimate(*model, data, nullptr, mtest::context());
  };
  const exid::Estimate e = estimateWith("");  // the default max_steps: simulated as before
  EXPECT_TRUE(e.value.allFinite());
  try {
    (void)estimateWith(", max_steps: 1");
    ADD_FAILURE() << "max_steps = 1 was not honoured";
  } catch (const exid::Error& err) {
    EXPECT_TRUE(contains(err.what(), "more than max_steps = 1 steps between the samples"))
        << err.what();
  }
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ resampled sizes

// resample_hz below its cap of 1e8 samples ran out of memory without naming the key: the
// resampled size is computed first and refused past 2e7 values per signal (as simulate),
// naming resample_hz, the size and the cap. A resampling within it still runs.
TEST(Budgets, AResampledSizeIsCheckedBeforeItIsAllocated) {
  const fs::path dir = tempDir("resample");
  {
    std::ofstream o(dir / "rec.csv");
    o << "t,q1,q2,qd1,qd2,qdd1,qdd2,tau1,tau2\n";
    for (int k = 0; k <= 1000; ++k) {
      const double t = 0.01 * k;
      o << fmt::format("{},{},{},{},{},{},{},{},{}\n", t, std::sin(t), std::cos(2 * t), std::cos(t),
                       -2 * std::sin(2 * t), -std::sin(t), -4 * std::cos(2 * t), std::sin(3 * t),
                       std::cos(t));
    }
  }
  auto study = [](const std::string& rate) {
    return "robot: {type: planar2r}\nmodel: {type: differential}\n"
           "experiment: {type: csv, params: {file: rec.csv, resample_hz: " +
           rate + "}}\nestimator: {type: batch_ls}\nreport: {params: {plots: false}}\n";
  };
  std::ofstream(dir / "huge.yaml") << study("5e6");  // 5e7 samples x 2 joints
  CmdResult r =
      runExid({"run", "huge.yaml", "--out", "o"}, dir, 120, underAddressSanitizer() ? 0 : 2000);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "resample_hz = ")) << r.out;
  EXPECT_TRUE(contains(r.out,
                       " gives 5e+07 samples over 10 s x 2 joints = 1e+08 values per "
                       "signal, more than the cap of 2e+07"))
      << r.out;
  std::ofstream(dir / "fine.yaml") << study("200");
  r = runExid({"run", "fine.yaml", "--out", "o2"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ matrix cells

// cell_memory_mb: 1 failed every cell with "Resource temporarily unavailable", naming
// nothing: below 32 MB it is refused when the matrix is read, naming the key; 0 is still none.
TEST(Budgets, ACellMemoryCapTooSmallToRunIsRefusedByName) {
  const fs::path dir = tempDir("cellmem");
  const std::string cells =
      "study:\n  robot: {type: planar2r}\n  model: {type: differential}\n"
      "  experiment: {type: simulate, params: {duration_s: 1, "
      "sample_period_s: 0.01}}\n  estimator: {type: batch_ls}\n"
      "  report: {params: {plots: false}}\ncells:\n  - {seed: 1}\n";
  std::ofstream(dir / "tiny.yaml") << "name: tiny\ncell_memory_mb: 1\n" + cells;
  CmdResult r = runExid({"matrix", "tiny.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "tiny.yaml:2: cell_memory_mb = 1: too small; a cell needs at least "
                       "32 MB"))
      << r.out;
  EXPECT_FALSE(fs::exists(dir / "o" / "results.sqlite"));
  std::ofstream(dir / "none.yaml") << "name: none\ncell_memory_mb: 0\n" + cells;
  r = runExid({"matrix", "none.yaml", "--out", "o2"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "1 ok")) << r.out;
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ geometry

// An obstacle 1e200 m away gave feasible: true and a minimum distance of 1.8e308. Coordinates,
// sizes and scales beyond 1e4 m are refused naming the key (study, DH robot), mesh vertices
// naming the mesh and the vertex; an obstacle within the bound is measured as before.
TEST(Budgets, GeometryBeyondTheBoundIsRefusedNamingTheKey) {
  const fs::path dir = tempDir("geometry");
  std::vector<std::vector<double>> rows;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> r(22, 0.0);
    r[0] = 0.001 * k;
    r[4] = -1.0;  // q4 within its limits [-3.07, -0.07]
    rows.push_back(r);
  }
  std::string header = "t";
  for (const char* g : {"q", "qd", "qdd"})
    for (int j = 1; j <= 7; ++j) header += fmt::format(",{}{}", g, j);
  writeRows(dir / "home.csv", header, rows);
  auto obstacleStudy = [&](const std::string& name, const std::string& obstacle) {
    std::ofstream(dir / name) << "robot: {type: panda}\nmodel: {type: differential}\n"
                                 "excitation:\n  trajectory: {type: fourier}\n"
                                 "  criterion: {type: cond}\n  optimizer: {type: nlopt}\n"
                                 "  collision:\n    margin_m: 0.01\n    self: false\n"
                                 "    obstacles: [" +
                                     obstacle + "]\n";
  };
  auto check = [&](const std::string& study) {
    return runExid(
        {"check-trajectory", "panda", "home.csv", "--collision", study, "--json", "check.json"},
        dir);
  };
  obstacleStudy("far.yaml", "{name: ball, sphere: {radius_m: 0.05}, xyz_m: [1e200, 0, 0.1]}");
  CmdResult r = check("far.yaml");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "far.yaml:10: excitation.collision.obstacles[0].xyz_m[0]: 1e+200 m "
                       "is beyond the bound of 10000 m"))
      << r.out;
  obstacleStudy("big.yaml", "{name: ball, sphere: {radius_m: 2e4}, xyz_m: [0.5, 0, 0.1]}");
  r = check("big.yaml");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "excitation.collision.obstacles[0].sphere.radius_m: 20000 m is "
                       "beyond the bound"))
      << r.out;
  obstacleStudy("box.yaml", "{name: wall, box: {size_m: [0.1, 1e5, 1]}, xyz_m: [0.5, 0, 0]}");
  r = check("box.yaml");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "obstacles[0].box.size_m[1]: 100000 m")) << r.out;
  // a mesh: a vertex beyond the bound (after its scale), and a scale beyond its own
  std::ofstream(dir / "far.stl") << "solid far\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                                    "vertex 1e6 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n";
  std::ofstream(dir / "unit.stl")
      << "solid unit\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
         "vertex 0.1 0 0\nvertex 0 0.1 0\nendloop\nendfacet\nendsolid\n";
  obstacleStudy("farmesh.yaml",
                "{name: m, mesh: {file: " + (dir / "far.stl").string() + "}, xyz_m: [0.5, 0, 0]}");
  r = check("farmesh.yaml");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "far.stl: vertex 2 of triangle 1 is (1e+06, 0, 0) m after the "
                       "scale, beyond the bound of 10000 m"))
      << r.out;
  obstacleStudy("scaled.yaml", "{name: m, mesh: {file: " + (dir / "unit.stl").string() +
                                   ", scale: [1e5, 1, 1]}, xyz_m: [0.5, 0, 0]}");
  r = check("scaled.yaml");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "obstacles[0].mesh.scale: 100000 is beyond the bound")) << r.out;
  // within the bound: measured (0.5 - 0.06 - 0.05 m from link 1's capsule), the mesh too
  obstacleStudy("near.yaml", "{name: ball, sphere: {radius_m: 0.05}, xyz_m: [0.5, 0, 0.1]}");
  r = check("near.yaml");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(exid_cli::slurp(dir / "check.json"), "\"value\": 0.39")) << r.out;
  obstacleStudy("unitmesh.yaml",
                "{name: m, mesh: {file: " + (dir / "unit.stl").string() + "}, xyz_m: [0.5, 0, 0]}");
  r = check("unitmesh.yaml");
  EXPECT_EQ(r.code, 0) << r.out;

  // a DH robot's own collision shape beyond the bound, and the distance guard in process
  const std::string dh =
      "name: far\nconvention: standard\nlinks:\n"
      "  - {a: 0.3, alpha: 0, d: 0, mass: 1, com: [-0.15, 0, 0], "
      "inertia_com: {xx: 0.01, yy: 0.01, zz: 0.01}, "
      "collision: [{sphere: {radius_m: 0.05}, xyz_m: [0, 0, -3e4]}]}\n";
  try {
    (void)exid::loadDhYamlString(dh, "far.yaml");
    ADD_FAILURE() << "a DH collision shape 3e4 m away was accepted";
  } catch (const exid::Error& e) {
    EXPECT_TRUE(contains(e.what(), "far.yaml:4: links[0]")) << e.what();
    EXPECT_TRUE(contains(e.what(), "collision[0].xyz_m[2]: -30000 m is beyond the bound"))
        << e.what();
  }
  // shapes that come from no YAML (a URDF's <collision>): bounded where their geometry is made
  exid::RobotModel robot =
      exid::loadDhYamlString(dh.substr(0, dh.find("xyz_m")) + "xyz_m: [0, 0, 0]}]}\n", "near.yaml");
  exid::CollisionOptions opt;
  opt.self = false;
  exid::Obstacle ball;
  ball.name = "ball";
  ball.shape.kind = exid::CollisionShape::Kind::Sphere;
  ball.shape.radius = 0.1;
  ball.shape.pose.p = Eigen::Vector3d(1.0, 0.0, 0.0);
  opt.obstacles = {ball};
  {
    exid::CollisionModel near(robot, opt);  // within the bound: measured
    Eigen::VectorXd d;
    near.distances(Eigen::VectorXd::Zero(1), &d);
    ASSERT_EQ(d.size(), 1);
    EXPECT_NEAR(d(0), 1.0 - 0.3 - 0.05 - 0.1,
                1e-9);  // the link's sphere sits at its frame, x = 0.3
  }
  for (const auto& [what, shape] : std::vector<std::pair<std::string, exid::CollisionShape>>{
           {"position",
            [] {
              exid::CollisionShape c;
              c.radius = 0.05;
              c.pose.p = Eigen::Vector3d(0, 2e4, 0);
              return c;
            }()},
           {"radius", [] {
              exid::CollisionShape c;
              c.radius = 2e4;
              return c;
            }()}}) {
    exid::RobotModel far = robot;
    exid::CollisionShape c = shape;
    c.body = 0;
    c.where = "far.urdf:12";
    far.collision = {c};
    try {
      exid::CollisionModel cm(far, opt);
      ADD_FAILURE() << "a " << what << " beyond the bound was accepted";
    } catch (const exid::Error& e) {
      EXPECT_TRUE(contains(e.what(), "far.urdf:12")) << e.what();
      EXPECT_TRUE(contains(e.what(), "beyond the bound of 10000 m")) << e.what();
    }
  }
  fs::remove_all(dir);
}

}  // namespace
