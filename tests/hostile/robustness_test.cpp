// Issue 16, "nothing crashes, nothing stale, every stop honoured" (docs/hostile_input.md): the
// exid program, run as a child process, on option values at and beyond their ranges, strict
// input, run folders as units, matrices keyed by what determines a cell, and stops.
// Here: crashes, wrong results, stale or mixed output and large chains; matrices and stops in
// robustness_matrix_test.cpp.
#include "robustness.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "exid/context.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"
#include "exid/robot_loaders.hpp"
#include "exid_test.hpp"

using namespace robustness;

// ------------------------------------------------------------------ 1. crashes

// trim_edges beyond int (it was narrowed to int: 2^31 - 1 segfaulted, 2^63 - 1 read before the
// buffer, 2^30 grew to 6.7 GB): refused by `exid validate` with the key and the range.
TEST(Robustness, CsvTrimEdgesBeyondItsRangeIsRefusedByValidate) {
  const fs::path dir = tempDir("trim");
  writeRecording(dir / "rec.csv");
  for (const char* v : {"2147483647", "9223372036854775807", "1073741824", "-2"}) {
    SCOPED_TRACE(v);
    std::ofstream(dir / "study.yaml")
        << kPlanar << "experiment: {type: csv, params: {file: rec.csv, differentiate_cutoff_hz: 5, "
        << "trim_edges: " << v << "}}\n";
    const CmdResult r = runExid({"validate", "study.yaml"}, dir);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_TRUE(contains(r.out, "study.yaml:4: experiment.params.trim_edges")) << r.out;
    EXPECT_TRUE(contains(r.out, "must be in [-1, 1000000000]")) << r.out;
  }
  // In range but longer than the data: a failed stage naming the setting, not a crash.
  std::ofstream(dir / "study.yaml")
      << kPlanar
      << "experiment: {type: csv, params: {file: rec.csv, differentiate_cutoff_hz: 5, "
         "trim_edges: 999999999}}\n";
  const CmdResult r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.signal, 0) << r.out;
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "trim_edges")) << r.out;
  EXPECT_EQ(statusOf(dir / "out"), "failed");
  fs::remove_all(dir);
}

// Every integer option of every plugin has a declared, finite range that fits an int: no value
// `exid validate` accepts can wrap when a plugin narrows it (trim_edges, samples, ...).
TEST(Robustness, EveryIntegerOptionOfEveryPluginHasARangeThatFitsAnInt) {
  int ints = 0;
  for (const auto& info : exid_test::registry().plugins())
    for (const auto& d : info.params) {
      if (d.type != exid::ParamType::Int && d.type != exid::ParamType::IntList) continue;
      ++ints;
      SCOPED_TRACE(info.name + "." + d.name);
      ASSERT_TRUE(d.min && d.max);
      EXPECT_GE(*d.min, -2147483647.0);
      EXPECT_LE(*d.max, 2147483647.0);
      EXPECT_FALSE(d.rangeText().empty());
    }
  EXPECT_GT(ints, 20);
}

// differentiate_cutoff_hz of 1e-10 or less: ceil(2 fs / cutoff) overflowed an int (segfault).
TEST(Robustness, CsvTinyCutoffIsAFailedStageNotACrash) {
  const fs::path dir = tempDir("cutoff");
  writeRecording(dir / "rec.csv");
  for (const char* v : {"1e-10", "1e-300", "5e-324"}) {
    SCOPED_TRACE(v);
    std::ofstream(dir / "study.yaml")
        << kPlanar
        << "experiment: {type: csv, params: {file: rec.csv, differentiate_cutoff_hz: " << v
        << "}}\n";
    const CmdResult r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir);
    EXPECT_EQ(r.signal, 0) << r.out;
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_TRUE(contains(r.out, "differentiate_cutoff_hz")) << r.out;
    EXPECT_EQ(statusOf(dir / "out"), "failed");
  }
  fs::remove_all(dir);
}

// samples: 2^63 - 1 was accepted and narrowed to int (the run silently used 40 samples).
TEST(Robustness, IntegerOptionsHaveDeclaredRanges) {
  const fs::path dir = tempDir("ints");
  std::ofstream(dir / "study.yaml")
      << "robot: {type: planar2r}\nmodel: {type: differential}\nexcitation:\n"
         "  trajectory: {type: fourier, params: {samples: 9223372036854775807}}\n"
         "  criterion: {type: cond}\n  optimizer: {type: nlopt}\n";
  CmdResult r = runExid({"validate", "study.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "study.yaml:4: excitation.trajectory.params.samples")) << r.out;
  EXPECT_TRUE(contains(r.out, "must be in [0, 1000000]")) << r.out;
  // An integer option without a declared maximum still has one (no value that wraps an int).
  std::ofstream(dir / "study.yaml") << "robot: {type: planar2r}\nmodel: {type: differential}\n"
                                       "experiment: {type: simulate, params: {max_steps: "
                                       "4294967297}}\nestimator: {type: batch_ls}\n";
  r = runExid({"validate", "study.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "experiment.params.max_steps = 4294967297")) << r.out;
  fs::remove_all(dir);
}

// budget_s: 1e308 overflowed the clock (an end in the past: an instant timeout); refused by
// validate, and a Deadline beyond 1e9 s is none.
TEST(Robustness, HugeBudgetIsRefusedNotAnInstantTimeout) {
  const fs::path dir = tempDir("budget");
  std::ofstream(dir / "study.yaml") << "budget_s: 1e308\nrobot: {type: planar2r}\n";
  const CmdResult r = runExid({"validate", "study.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "study.yaml:1: budget_s = 1e308: must be in [0, 1e9] s")) << r.out;
  EXPECT_FALSE(exid::Deadline(1e308).expired());
  EXPECT_FALSE(exid::Deadline(1e308).active());
  EXPECT_TRUE(exid::Deadline(1e6).active());
  fs::remove_all(dir);
}

// A size derived from two options is checked before anything is allocated, naming both keys
// (sample_period_s: 1e-300 gave a false message from an overflowed count; duration_s: 1e7 ended
// in bad_alloc).
TEST(Robustness, SizesDerivedFromTwoOptionsNameBothKeys) {
  const fs::path dir = tempDir("derived");
  std::ofstream(dir / "a.yaml")
      << "robot: {type: planar2r}\nmodel: {type: differential}\nexcitation:\n"
         "  trajectory: {type: pointwise, params: {duration_s: 1e308, sample_period_s: 1e-300}}\n"
         "  criterion: {type: cond}\n  optimizer: {type: nlopt}\n";
  CmdResult r = runExid({"-q", "run", "a.yaml", "--out", "a"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "duration_s") && contains(r.out, "sample_period_s")) << r.out;
  EXPECT_TRUE(contains(r.out, "allowed")) << r.out;
  std::ofstream(dir / "b.yaml") << kPlanar
                                << "experiment: {type: simulate, params: {duration_s: 1e7}}\n";
  r = runExid({"-q", "run", "b.yaml", "--out", "b"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "duration_s = 10000000 s / sample_period_s = 0.01 s")) << r.out;
  EXPECT_FALSE(contains(r.out, "bad_alloc")) << r.out;
  fs::remove_all(dir);
}

// Usage errors: exit 2 with a message naming the option (CLI11's own codes were 105, 106, ...;
// `--shard a/b` was "unexpected error: stoi").
TEST(Robustness, UsageErrorsExitTwoWithClearMessages) {
  const fs::path dir = tempDir("usage");
  std::ofstream(dir / "m.yaml") << "name: m\nstudy:\n  robot: {type: planar2r}\n";
  CmdResult r = runExid({"matrix", "m.yaml", "-j", "0"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "--jobs")) << r.out;
  for (const char* shard : {"0/2x", "a/b", "2/2", "0/0", "1", "3/2"}) {
    SCOPED_TRACE(shard);
    r = runExid({"matrix", "m.yaml", "--out", "o", "--shard", shard}, dir);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_TRUE(contains(r.out, std::string("--shard ") + shard + ":")) << r.out;
    EXPECT_FALSE(contains(r.out, "unexpected")) << r.out;
  }
  r = runExid({"run"}, dir);  // a required argument missing
  EXPECT_EQ(r.code, 2) << r.out;
  r = runExid({"no-such-command"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  for (const char* budget : {"-1", "nan", "1e400", "x"}) {
    SCOPED_TRACE(budget);
    std::ofstream(dir / "b.yaml") << "name: b\ncell_budget_s: " << budget
                                  << "\nstudy:\n  robot: {type: planar2r}\n";
    r = runExid({"matrix", "b.yaml", "--out", "o"}, dir);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_TRUE(contains(r.out, "b.yaml:2: cell_budget_s")) << r.out;
  }
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ 2. wrong results

// A URDF mass of 1e300: the nominal parameters overflow; exit 1 and a failed stage (it was exit
// 0, status ok, every parameter -nan).
TEST(Robustness, NonFiniteResultsAreAFailedStage) {
  const fs::path dir = tempDir("nan");
  std::ofstream(dir / "r.urdf") << R"(<?xml version="1.0"?>
<robot name="heavy">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0"/><mass value="1e300"/>
    <inertia ixx="1e300" ixy="0" ixz="0" iyy="1e300" iyz="0" izz="1e300"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="3" effort="100"/></joint>
</robot>
)";
  std::ofstream(dir / "study.yaml")
      << "robot: {type: urdf, params: {file: r.urdf}}\nmodel: {type: differential}\n"
         "experiment: {type: simulate, params: {duration_s: 2}}\nestimator: {type: batch_ls}\n";
  const CmdResult r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "non-finite") || contains(r.out, "not finite")) << r.out;
  EXPECT_EQ(statusOf(dir / "out"), "failed");
  EXPECT_FALSE(fs::exists(dir / "out" / "parameters.csv"));
  fs::remove_all(dir);
}

// q_columns naming one column twice ran with both joints reading it.
TEST(Robustness, CsvColumnNamedTwiceIsRefused) {
  const fs::path dir = tempDir("twice");
  writeRecording(dir / "rec.csv");
  std::ofstream(dir / "study.yaml")
      << kPlanar << "experiment: {type: csv, params: {file: rec.csv, q_columns: [q2, q2]}}\n";
  const CmdResult r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "q_columns: column 'q2' is named twice (elements 1 and 2)")) << r.out;
  fs::remove_all(dir);
}

// A NUL byte inside a number silently truncated it ("0.5\0" + "7" read 0.5).
TEST(Robustness, NulByteInsideACsvNumberIsAnError) {
  const fs::path dir = tempDir("nul");
  writeRecording(dir / "rec.csv");
  std::string text = slurp(dir / "rec.csv");
  const std::size_t at = text.find('\n', text.find('\n') + 1) + 1;  // data row 2, line 3
  const std::size_t comma = text.find(',', at);
  text.insert(comma, std::string("\0", 1) + "7");
  std::ofstream(dir / "rec.csv", std::ios::binary) << text;
  std::ofstream(dir / "study.yaml")
      << kPlanar << "experiment: {type: csv, params: {file: rec.csv}}\n";
  const CmdResult r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "rec.csv:3:" + std::to_string(comma - at + 1) + ": column 't'"))
      << r.out;
  EXPECT_TRUE(contains(r.out, "unexpected byte 0x00")) << r.out;
  fs::remove_all(dir);
}

// Duplicate keys: the first won (a second `estimator:` at the end of a study was ignored).
TEST(Robustness, DuplicateYamlKeysAreRefusedNamingBothLines) {
  const fs::path dir = tempDir("dup");
  std::ofstream(dir / "study.yaml") << kPlanar << "experiment: {type: simulate}\n"
                                    << "estimator: {type: wls}\n";
  CmdResult r = runExid({"validate", "study.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(
      contains(r.out, "study.yaml:5: estimator: duplicate key 'estimator' (first at line 3)"))
      << r.out;
  std::ofstream(dir / "m.yaml") << "name: m\nstudy:\n  robot: {type: planar2r}\n"
                                   "axes:\n  seed: [1, 2]\n  seed: [3]\n";
  r = runExid({"matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "m.yaml:6: axes.seed: duplicate key 'seed' (first at line 5)"))
      << r.out;
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ 3. stale or mixed output

// A failed re-run into an existing --out left the earlier parameters.csv beside a summary that
// said failed (and a report saying ok); now the earlier run is untouched and the failure is
// beside it in OUT.failed. A successful run of another study leaves no file of the earlier one.
TEST(Robustness, ARunFolderIsAUnit) {
  const fs::path dir = tempDir("unit");
  std::ofstream(dir / "good.yaml")
      << kPlanar << "experiment: {type: simulate, params: {duration_s: 2}}\n"
      << "validation: {type: simulate, params: {duration_s: 1}}\nreport: {params: {plots: "
         "false}}\n";
  std::ofstream(dir / "bad.yaml") << kPlanar
                                  << "experiment: {type: csv, params: {file: missing.csv}}\n";
  std::ofstream(dir / "other.yaml")
      << kPlanar << "experiment: {type: simulate, params: {duration_s: 2}}\n"
      << "report: {params: {plots: false}}\n";
  CmdResult r = runExid({"-q", "run", "good.yaml", "--out", "out"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string params = slurp(dir / "out" / "parameters.csv");
  ASSERT_TRUE(fs::exists(dir / "out" / "validation.csv"));

  r = runExid({"-q", "run", "bad.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "out.failed/summary.json")) << r.out;
  EXPECT_TRUE(contains(r.out, "untouched")) << r.out;
  EXPECT_EQ(statusOf(dir / "out"), "ok");
  EXPECT_EQ(slurp(dir / "out" / "parameters.csv"), params);
  EXPECT_EQ(statusOf(dir / "out.failed"), "failed");
  EXPECT_FALSE(fs::exists(dir / "out.failed" / "parameters.csv"));

  r = runExid({"-q", "run", "other.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(statusOf(dir / "out"), "ok");
  EXPECT_FALSE(fs::exists(dir / "out" / "validation.csv"));  // the earlier study's
  EXPECT_FALSE(fs::exists(dir / "out.failed"));              // superseded
  EXPECT_EQ(summaryOf(dir / "out").find("study")->asString(), "other");
  EXPECT_TRUE(noTemporaries(dir));

  // A folder that is not a run is never replaced.
  fs::create_directories(dir / "mine");
  std::ofstream(dir / "mine" / "notes.txt") << "keep";
  r = runExid({"-q", "run", "good.yaml", "--out", "mine"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "does not hold an exid run")) << r.out;
  EXPECT_EQ(slurp(dir / "mine" / "notes.txt"), "keep");
  fs::remove_all(dir);
}

// `name: "../../x"` without --out wrote outside out/.
TEST(Robustness, StudyNamesCannotLeaveTheOutputRoot) {
  const fs::path dir = tempDir("name");
  fs::create_directories(dir / "a" / "b");
  for (const char* name : {"../../x", "..", "a/b", ".hidden", "x\\\\y"}) {
    SCOPED_TRACE(name);
    std::ofstream(dir / "a" / "b" / "study.yaml")
        << "name: \"" << name << "\"\nrobot: {type: planar2r}\n";
    const CmdResult r = runExid({"-q", "run", "study.yaml"}, dir / "a" / "b");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_TRUE(contains(r.out, "study.yaml:1: name =")) << r.out;
  }
  EXPECT_FALSE(fs::exists(dir / "x"));
  EXPECT_FALSE(fs::exists(dir / "a" / "x"));
  fs::remove_all(dir);
}

// A NAME.tmp.PID left by a process killed with SIGKILL is removed by the next run.
TEST(Robustness, StaleTemporariesOfDeadProcessesAreCleaned) {
  const fs::path dir = tempDir("stale");
  const pid_t dead = ::fork();
  if (dead == 0) ::_exit(0);
  ::waitpid(dead, nullptr, 0);
  std::ofstream(dir / "study.yaml")
      << "robot: {type: planar2r}\nreport: {params: {plots: false}}\n";
  ASSERT_EQ(runExid({"-q", "run", "study.yaml", "--out", "out"}, dir).code, 0);
  const std::string tmp = "summary.json.tmp." + std::to_string(dead);
  std::ofstream(dir / "out" / tmp) << "half";
  std::ofstream(dir / (".out.staging." + std::to_string(dead))) << "half";
  std::ofstream(dir / ("keep.tmp." + std::to_string(::getpid()))) << "a live writer's";
  const CmdResult r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(fs::exists(dir / "out" / tmp));
  EXPECT_FALSE(fs::exists(dir / (".out.staging." + std::to_string(dead))));
  EXPECT_TRUE(fs::exists(dir / ("keep.tmp." + std::to_string(::getpid()))));
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ 6. large chains

// The base parameters of a 50-link chain (`exid robot info` took 6.2 s; now O(n^3): rows capped
// and compressed to R, short reflectors, beta from R11): on new random samples the base
// regressor times the base parameters reproduces the full regressor times the full parameters.
TEST(Robustness, BaseParametersOfALargeChainAreExact) {
  std::string dh = "name: chain\nconvention: standard\ngravity: [0, 0, -9.81]\nlinks:\n";
  for (int i = 0; i < 50; ++i)
    dh += std::string("  - {a: 0.1, alpha: ") + (i % 2 ? "-1.5707963" : "1.5707963") +
          ", d: 0.05, mass: 1, com: [-0.05, 0.01, 0.02], inertia_com: {xx: 0.01, yy: 0.02, zz: "
          "0.03, xy: 0.001}, limits: {q_min_deg: -170, q_max_deg: 170, qd_max: 3, qdd_max: 10}}\n";
  auto robot = std::make_shared<const exid::RobotModel>(exid::loadDhYamlString(dh, "chain.yaml"));
  auto model = exid_test::create<exid::ObservationModel>("differential");
  exid::RunContext ctx;
  model->bind(robot, ctx);
  const exid::BaseParameters& b = model->base();
  EXPECT_EQ(b.numFull(), 650);
  EXPECT_EQ(b.rank(), 493);
  const exid::Samples s = model->randomSamples(20, 12345);
  const Eigen::MatrixXd W = model->fullDesign(s);
  Eigen::VectorXd pi = model->fullNominal();
  for (Eigen::Index i = 0; i < pi.size(); ++i) pi(i) += 0.1 * std::sin(3.0 * i);  // any vector
  const Eigen::VectorXd full = W * pi;
  const Eigen::VectorXd base = b.columns(W) * b.reduce(pi);
  EXPECT_LT((full - base).norm(), 1e-8 * full.norm());
}

// A command that does not poll the stop flag (here `robot info` on a 150-link chain, seconds of
// work) ended only when it was done: SIGINT/SIGTERM were caught and ignored. Now it ends at once.
TEST(Robustness, SignalsEndCommandsThatDoNotPoll) {
  const fs::path dir = tempDir("infostop");
  {
    std::ofstream f(dir / "chain.yaml");
    f << "name: chain\nconvention: standard\nlinks:\n";
    for (int i = 0; i < 150; ++i)
      f << "  - {a: 0.1, alpha: " << (i % 2 ? "-1.5707963" : "1.5707963")
        << ", d: 0.05, mass: 1, com: [-0.05, 0.01, 0.02], inertia_com: {xx: 0.01, yy: 0.02, zz: "
           "0.03, xy: 0.001}}\n";
  }
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int fd = ::open("log.txt", O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::execl(EXID_EXE, EXID_EXE, "robot", "info", "chain.yaml", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  const auto t0 = std::chrono::steady_clock::now();
  int status = 0;
  ::waitpid(pid, &status, 0);
  const double waited =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << slurp(dir / "log.txt");
  EXPECT_LT(waited, 10.0);
  fs::remove_all(dir);
}
