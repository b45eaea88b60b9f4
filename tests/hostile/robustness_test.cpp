// Issue 16, "nothing crashes, nothing stale, every stop honoured" (docs/hostile_input.md): the
// exid program, run as a child process, on option values at and beyond their ranges, strict
// input, run folders as units, matrices keyed by what determines a cell, and stops.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
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

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_robust_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

struct CmdResult {
  int code = -1;    // exit code; -1 when killed by a signal
  int signal = 0;   // the signal that killed it
  std::string out;  // stdout and stderr
};

/// Runs exid with args (no shell) in dir, stdout+stderr captured; killed after timeout_s
/// (reported as signal 9) so that a hang is a failure, not a stuck test.
CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir, double timeout_s = 120,
                  long fsize_limit = 0) {
  const fs::path log = dir / "exid_log.txt";
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    if (fsize_limit > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      rlimit rl{static_cast<rlim_t>(fsize_limit), static_cast<rlim_t>(fsize_limit)};
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(EXID_EXE));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(EXID_EXE, argv.data());
    ::_exit(127);
  }
  CmdResult r;
  int status = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  r.out = slurp(log);
  return r;
}

bool contains(const std::string& s, const std::string& what) {
  return s.find(what) != std::string::npos;
}

exid::Json summaryOf(const fs::path& dir) { return exid::Json::parse(slurp(dir / "summary.json")); }

std::string statusOf(const fs::path& dir) {
  if (!fs::exists(dir / "summary.json")) return "(no summary.json)";
  const exid::Json s = summaryOf(dir);
  return s.find("status") ? s.find("status")->asString() : "(no status)";
}

bool noTemporaries(const fs::path& dir) {
  for (auto& e : fs::recursive_directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (contains(n, ".tmp.") || contains(n, ".staging.")) return false;
  }
  return true;
}

const char* kPlanar =
    "robot: {type: planar2r}\n"
    "model: {type: differential}\n"
    "estimator: {type: batch_ls}\n";

// A two-joint recording (t, q1, q2, tau1, tau2) that moves both joints, 400 rows at 100 Hz.
void writeRecording(const fs::path& file, double tau_scale = 1.0) {
  std::ofstream f(file);
  f << "t,q1,q2,tau1,tau2\n";
  for (int k = 0; k < 400; ++k) {
    const double t = 0.01 * k;
    f << t << "," << std::sin(t) << "," << std::cos(1.3 * t) << "," << tau_scale * std::sin(3 * t)
      << "," << tau_scale * std::cos(2 * t) << "\n";
  }
}

}  // namespace

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

// ------------------------------------------------------------------ 4. matrix

namespace {
const char* kCsvMatrix = R"(name: m
cell_budget_s: 120
study:
  robot: {type: planar2r}
  model: {type: differential}
  experiment: {type: csv, params: {file: rec.csv, differentiate_cutoff_hz: 5}}
  estimator: {type: batch_ls}
  report: {params: {plots: false}}
axes:
  seed: [1, 2]
)";

std::string metric(const fs::path& out, const std::string& name, const fs::path& dir) {
  return runExid({"matrix", "table", out.string(), "--rows", "seed", "--metric", name}, dir).out;
}
}  // namespace

// Cells were keyed by the YAML alone: doubling every torque of the data file left the matrix
// reporting "skipped (finished before)" with the old numbers. --force re-runs every cell.
TEST(Robustness, MatrixCellsAreKeyedByTheirInputFilesAndForceReruns) {
  const fs::path dir = tempDir("mkey");
  writeRecording(dir / "rec.csv");
  std::ofstream(dir / "m.yaml") << kCsvMatrix;
  CmdResult r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "2 ok")) << r.out;
  const std::string before = metric(dir / "o", "residual_rms", dir);
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_TRUE(contains(r.out, "2 skipped")) << r.out;
  writeRecording(dir / "rec.csv", 2.0);  // the data changed: the cells must run again
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "2 ok, 0 failed, 0 timeout, 0 skipped")) << r.out;
  EXPECT_NE(metric(dir / "o", "residual_rms", dir), before);
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o", "--force"}, dir);
  EXPECT_TRUE(contains(r.out, "2 ok, 0 failed, 0 timeout, 0 skipped")) << r.out;
  fs::remove_all(dir);
}

// Two writers on one --out both computed every cell; now the second is refused naming the
// first's pid and host.
TEST(Robustness, MatrixFolderHasOneWriter) {
  const fs::path dir = tempDir("mlock");
  writeRecording(dir / "rec.csv");
  std::ofstream(dir / "m.yaml") << kCsvMatrix;
  fs::create_directories(dir / "o");
  const int fd = ::open((dir / "o" / ".lock").c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
  const std::string holder = "4242 on host testhost\n";
  ASSERT_EQ(::write(fd, holder.data(), holder.size()), static_cast<ssize_t>(holder.size()));
  CmdResult r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "in use by another exid (pid 4242 on host testhost)")) << r.out;
  EXPECT_FALSE(fs::exists(dir / "o" / "results.sqlite"));
  ::close(fd);  // released: the next writer proceeds
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

// A cell that hit a full disk (here: the file size limit, EFBIG, as ENOSPC) was counted finished
// and skipped on resume, with a SQLite rollback error as its message.
TEST(Robustness, MatrixCellOnAFullDiskIsIncompleteAndRetriedOnResume) {
  const fs::path dir = tempDir("mfull");
  std::ofstream(dir / "m.yaml") << R"(name: m
study:
  robot: {type: planar2r}
  model: {type: differential}
  experiment: {type: simulate, params: {duration_s: 4, sample_period_s: 0.001}}
  estimator: {type: batch_ls}
  report: {params: {plots: false}}
)";
  CmdResult r = runExid({"matrix", "m.yaml", "--out", "o"}, dir, 300, 256 * 1024);
  EXPECT_EQ(r.signal, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "no space left on device")) << r.out;
  EXPECT_TRUE(contains(r.out, "File too large")) << r.out;  // the cause, not a rollback error
  EXPECT_TRUE(contains(r.out, "1 incomplete")) << r.out;
  r = runExid({"matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "1 ok, 0 failed, 0 timeout, 0 skipped")) << r.out;
  fs::remove_all(dir);
}

// A merge that failed part-way left the destination half merged.
TEST(Robustness, MatrixMergeIsAtomic) {
  const fs::path dir = tempDir("mmerge");
  writeRecording(dir / "rec.csv");
  std::ofstream(dir / "m.yaml") << kCsvMatrix;
  ASSERT_EQ(runExid({"-q", "matrix", "m.yaml", "--out", "a"}, dir).code, 0);
  fs::create_directories(dir / "bad");
  std::ofstream(dir / "bad" / "results.sqlite") << "not a database, just text\n";
  CmdResult r = runExid({"matrix", "merge", "dest", "a", "bad"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "bad/results.sqlite")) << r.out;
  if (fs::exists(dir / "dest" / "results.sqlite")) {
    r = runExid({"matrix", "table", "dest", "--metric", "residual_rms"}, dir);
    EXPECT_FALSE(contains(r.out, "seed")) << r.out;  // nothing of a merged
  }
  r = runExid({"matrix", "merge", "dest", "a"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "merged 2 runs")) << r.out;
  fs::remove_all(dir);
}

// A 12-line matrix expanding to 10^8 cells died of bad_alloc after 21 s; the product is checked
// first.
TEST(Robustness, MatrixExpansionIsCheckedBeforeAllocation) {
  const fs::path dir = tempDir("mbig");
  std::ofstream m(dir / "m.yaml");
  m << "name: m\nstudy:\n  robot: {type: planar2r}\naxes:\n";
  for (int a = 0; a < 8; ++a) {
    m << "  \"@a" << a << "\": [";
    for (int v = 0; v < 10; ++v) m << (v ? ", " : "") << "{label: v" << v << ", seed: " << v << "}";
    m << "]\n";
  }
  m.close();
  const CmdResult r = runExid({"matrix", "m.yaml", "--out", "o"}, dir, 60);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "more than 100000 cells")) << r.out;
  fs::remove_all(dir);
}

// The matrix parent killed with SIGKILL left its cells running as orphans.
TEST(Robustness, MatrixCellsDieWithTheirParent) {
  const fs::path dir = tempDir("morphan");
  std::ofstream(dir / "m.yaml") << R"(name: m
study:
  robot: {type: planar2r}
  model: {type: differential}
  experiment: {type: simulate, params: {duration_s: 2000, period_s: 2000, sample_period_s: 0.001}}
  estimator: {type: batch_ls}
axes:
  seed: [1, 2]
)";
  const pid_t parent = ::fork();
  if (parent == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int fd = ::open("log.txt", O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::execl(EXID_EXE, EXID_EXE, "matrix", "m.yaml", "--out", "o", "-j", "2",
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // The cells: children of the parent (from /proc), once both run.
  std::vector<pid_t> cells;
  for (int i = 0; i < 600 && cells.size() < 2; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    cells.clear();
    std::ifstream ch("/proc/" + std::to_string(parent) + "/task/" + std::to_string(parent) +
                     "/children");
    pid_t p = 0;
    while (ch >> p) cells.push_back(p);
  }
  ASSERT_EQ(cells.size(), 2u) << slurp(dir / "log.txt");
  ::kill(parent, SIGKILL);
  ::waitpid(parent, nullptr, 0);
  bool gone = false;
  for (int i = 0; i < 200 && !gone; ++i) {  // generous: 10 s
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    gone = true;
    for (pid_t c : cells) {
      std::ifstream st("/proc/" + std::to_string(c) + "/stat");
      std::string pid_s, comm, state;
      if (st >> pid_s >> comm >> state && state != "Z") gone = false;
    }
  }
  for (pid_t c : cells) ::kill(c, SIGKILL);  // no orphan even when the test fails
  EXPECT_TRUE(gone) << "cells outlived their parent";
  fs::remove_all(dir);
}

// ------------------------------------------------------------------ 5. stops

// A robot file that is a FIFO hung forever (only SIGKILL ended it); /dev/zero ended in bad_alloc.
TEST(Robustness, InputsThatAreNotRegularFilesAreRefusedBeforeOpening) {
  const fs::path dir = tempDir("fifo");
  ASSERT_EQ(::mkfifo((dir / "robot.urdf").c_str(), 0644), 0);
  CmdResult r = runExid({"robot", "info", "robot.urdf"}, dir, 30);
  EXPECT_EQ(r.signal, 0) << "hung on the FIFO";
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "robot.urdf: the robot file is a FIFO (named pipe)")) << r.out;
  std::ofstream(dir / "study.yaml") << "robot: {type: urdf, params: {file: /dev/zero}}\n";
  r = runExid({"-q", "run", "study.yaml", "--out", "out"}, dir, 30);
  EXPECT_EQ(r.signal, 0) << r.out;
  EXPECT_EQ(r.code, 2) << r.out;  // the robot is loaded before any stage (exid::checkStudy)
  EXPECT_TRUE(contains(r.out, "/dev/zero: the URDF file is a character device")) << r.out;
  mkfifo((dir / "data.csv").c_str(), 0644);
  std::ofstream(dir / "s2.yaml") << kPlanar
                                 << "experiment: {type: csv, params: {file: data.csv}}\n";
  r = runExid({"-q", "run", "s2.yaml", "--out", "out2"}, dir, 30);
  EXPECT_EQ(r.signal, 0) << r.out;
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "a FIFO")) << r.out;
  fs::remove_all(dir);
}

// SIGINT and SIGTERM: exit 130 and 143, status "cancelled", the stop within a generous 10 s
// (the requirement is 1 s; the margin keeps the test from depending on the machine's load).
TEST(Robustness, SignalsStopARunWithTheirExitCodes) {
  const fs::path dir = tempDir("signals");
  std::ofstream(dir / "study.yaml") << kPlanar
                                    << "experiment: {type: simulate, params: {duration_s: 2000, "
                                       "period_s: 2000, sample_period_s: 0.001}}\n";
  for (int sig : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(sig);
    const pid_t pid = ::fork();
    if (pid == 0) {
      if (::chdir(dir.c_str()) != 0) ::_exit(126);
      const int fd = ::open("log.txt", O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(fd, STDOUT_FILENO);
      ::dup2(fd, STDERR_FILENO);
      ::execl(EXID_EXE, EXID_EXE, "-q", "run", "study.yaml", "--out", "out",
              static_cast<char*>(nullptr));
      ::_exit(127);
    }
    // Started: the staging folder holds the resolved study.
    bool started = false;
    for (int i = 0; i < 600 && !started; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      started = fs::exists(dir / (".out.staging." + std::to_string(pid)) / "study.resolved.yaml");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    ASSERT_TRUE(started);
    ASSERT_EQ(::kill(pid, sig), 0);
    const auto t0 = std::chrono::steady_clock::now();
    int status = 0;
    ::waitpid(pid, &status, 0);
    const double waited =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string log = slurp(dir / "log.txt");
    ASSERT_TRUE(WIFEXITED(status)) << log;
    EXPECT_EQ(WEXITSTATUS(status), 128 + sig) << log;
    EXPECT_LT(waited, 10.0);
    EXPECT_EQ(statusOf(dir / "out"), "cancelled") << log;
    EXPECT_TRUE(noTemporaries(dir));
    fs::remove_all(dir / "out");
  }
  fs::remove_all(dir);
}

// SIGTERM during one long call into an optimiser (harmonics: 1000, the documented maximum, ran
// for minutes and ignored SIGTERM for > 20 s): the runner's watchdog ends the stage 0.5 s after
// the request; exit 143, status cancelled, the excitation stage named, no partial file. 10 s
// is a generous margin for a loaded machine.
TEST(Robustness, SignalDuringALongOptimiserCallIsHonoured) {
  const fs::path dir = tempDir("optstop");
  std::ofstream(dir / "study.yaml") << "robot: {type: planar2r}\nmodel: {type: differential}\n"
                                       "excitation:\n"
                                       "  trajectory: {type: fourier, params: {harmonics: 1000}}\n"
                                       "  criterion: {type: cond}\n  optimizer: {type: nlopt}\n"
                                       "report: {params: {plots: false}}\n";
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int fd = ::open("log.txt", O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::execl(EXID_EXE, EXID_EXE, "-q", "run", "study.yaml", "--out", "out",
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  bool started = false;
  for (int i = 0; i < 600 && !started; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    started = fs::exists(dir / (".out.staging." + std::to_string(pid)) / "study.resolved.yaml");
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(2000));
  ASSERT_TRUE(started);
  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  const auto t0 = std::chrono::steady_clock::now();
  int status = 0;
  ::waitpid(pid, &status, 0);
  const double waited =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string log = slurp(dir / "log.txt");
  ASSERT_TRUE(WIFEXITED(status)) << log;
  EXPECT_EQ(WEXITSTATUS(status), 143) << log;
  EXPECT_LT(waited, 10.0);
  ASSERT_EQ(statusOf(dir / "out"), "cancelled") << log;
  EXPECT_EQ(summaryOf(dir / "out").find("failed_stage")->asString(), "excitation");
  EXPECT_FALSE(fs::exists(dir / "out" / "trajectory_optimal.csv"));
  EXPECT_TRUE(noTemporaries(dir));
  fs::remove_all(dir);
}

// Matrix cells had a time budget but no memory cap: `cell_memory_mb` caps what a cell may add
// to its address space (RLIMIT_AS in the cell's process); the cell over it fails saying so, the
// matrix goes on. (Not under AddressSanitizer: its shadow memory exceeds any such cap.)
TEST(Robustness, MatrixCellMemoryCap) {
#if defined(__SANITIZE_ADDRESS__)  // gcc
  GTEST_SKIP() << "RLIMIT_AS and AddressSanitizer do not mix";
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)  // clang
  GTEST_SKIP() << "RLIMIT_AS and AddressSanitizer do not mix";
#endif
#endif
  const fs::path dir = tempDir("mmem");
  std::ofstream(dir / "m.yaml") << R"(name: m
cell_memory_mb: 50
study:
  robot: {type: planar2r}
  model: {type: differential}
  experiment: {type: simulate, params: {duration_s: 2, sample_period_s: 0.001}}
  estimator: {type: batch_ls}
  report: {params: {plots: false}}
cells:
  - {seed: 1}
  - {experiment: {type: simulate, params: {duration_s: 2000, sample_period_s: 0.001}}}
)";
  const CmdResult r = runExid({"matrix", "m.yaml", "--out", "o"}, dir, 300);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "1 ok, 1 failed")) << r.out;
  EXPECT_TRUE(contains(r.out, "over the cell memory cap cell_memory_mb = 50 MB")) << r.out;
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
