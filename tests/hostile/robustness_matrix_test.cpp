// Issue 16, "nothing crashes, nothing stale, every stop honoured" (docs/hostile_input.md): the
// exid program, run as a child process, on matrices keyed by what determines a cell, and stops
// (signals, limits, inputs that are not regular files). The other robustness tests are in
// robustness_test.cpp.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "exid/json.hpp"
#include "robustness.hpp"

using namespace robustness;

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
