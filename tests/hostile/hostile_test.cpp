// Hostile input and hostile environments (docs/hostile_input.md): the exid program, run as a
// child process, must answer with a message naming the file and the place, a non-zero exit, no
// half-written output (no *.tmp.* files, no truncated result) and nothing already finished lost.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "exid/json.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_hostile_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

bool noTemporaries(const fs::path& dir) {
  for (auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().string().find(".tmp.") != std::string::npos) return false;
  return true;
}

struct Child {
  pid_t pid = -1;
  fs::path log;
};

/// Starts `exid -q run study --out out` with stdout+stderr to dir/log.txt; `limit_bytes` > 0 caps
/// the size of any file it writes (RLIMIT_FSIZE, SIGXFSZ ignored: writes fail with EFBIG, as on
/// a full disk); `plugin_path`, when given, is the child's EXID_PLUGIN_PATH.
Child start(const fs::path& study, const fs::path& out, const fs::path& dir, long limit_bytes = 0,
            const std::string& plugin_path = "") {
  Child c;
  c.log = dir / "log.txt";
  c.pid = ::fork();
  if (c.pid == 0) {
    if (!plugin_path.empty()) ::setenv("EXID_PLUGIN_PATH", plugin_path.c_str(), 1);
    FILE* f = std::freopen(c.log.c_str(), "w", stdout);
    (void)f;
    ::dup2(STDOUT_FILENO, STDERR_FILENO);
    if (limit_bytes > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      rlimit rl{static_cast<rlim_t>(limit_bytes), static_cast<rlim_t>(limit_bytes)};
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    ::execl(EXID_EXE, EXID_EXE, "-q", "run", study.c_str(), "--out", out.c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  return c;
}

int wait(const Child& c, int* signal_no = nullptr) {
  int status = 0;
  ::waitpid(c.pid, &status, 0);
  if (signal_no) *signal_no = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

const char* kPlanar =
    "robot: {type: planar2r}\n"
    "model: {type: differential}\n"
    "estimator: {type: batch_ls}\n";

}  // namespace

// Disk full while writing the results: the file that could not be written is named, the exit is
// non-zero, summary.json (small, written last) says why, and no partial file is left.
TEST(Hostile, DiskFullOnOutputIsReportedAndLeavesNoPartialFile) {
  const fs::path dir = tempDir("diskfull");
  std::ofstream(dir / "study.yaml") << kPlanar
                                    << "experiment: {type: simulate, params: {duration_s: 4, "
                                       "sample_period_s: 0.001, noise_tau_Nm: 0.01}}\n";
  const Child c = start(dir / "study.yaml", dir / "out", dir, 64 * 1024);
  const int code = wait(c);
  const std::string log = slurp(c.log);
  EXPECT_EQ(code, 1) << log;
  EXPECT_NE(log.find("experiment.csv"), std::string::npos) << log;
  EXPECT_NE(log.find("File too large"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(dir / "out" / "experiment.csv"));  // never half-written
  ASSERT_TRUE(fs::exists(dir / "out" / "summary.json")) << log;
  const exid::Json s = exid::Json::parse(slurp(dir / "out" / "summary.json"));
  EXPECT_EQ(s.find("status")->asString(), "failed");
  EXPECT_NE(s.find("message")->asString().find("experiment.csv"), std::string::npos);
  EXPECT_TRUE(fs::exists(dir / "out" / "study.resolved.yaml"));  // written before: kept whole
  EXPECT_TRUE(noTemporaries(dir));
  fs::remove_all(dir);
}

// SIGTERM in the middle of a long experiment: the run stops at the next check, exits non-zero,
// summary.json says it was interrupted, nothing is half-written.
TEST(Hostile, SigtermMidRunStopsCleanlyAndSaysWhy) {
  const fs::path dir = tempDir("sigterm");
  std::ofstream(dir / "study.yaml") << kPlanar
                                    << "experiment: {type: simulate, params: {duration_s: 2000, "
                                       "period_s: 2000, sample_period_s: 0.001}}\n";
  const Child c = start(dir / "study.yaml", dir / "out", dir);
  // Wait until the run has started (the resolved study is written first, into the staging
  // folder .out.staging.PID), then a little more.
  const fs::path staged = dir / (".out.staging." + std::to_string(c.pid)) / "study.resolved.yaml";
  for (int i = 0; i < 200 && !fs::exists(staged); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  ASSERT_EQ(::kill(c.pid, SIGTERM), 0);
  const auto t0 = std::chrono::steady_clock::now();
  int sig = 0;
  const int code = wait(c, &sig);
  const double waited =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string log = slurp(c.log);
  EXPECT_EQ(sig, 0) << "killed by signal " << sig << "\n" << log;
  EXPECT_NE(code, 0) << log;
  EXPECT_LT(waited, 30.0) << "the stop request took too long";
  ASSERT_TRUE(fs::exists(dir / "out" / "summary.json")) << log;
  const exid::Json s = exid::Json::parse(slurp(dir / "out" / "summary.json"));
  EXPECT_EQ(s.find("status")->asString(), "cancelled");
  EXPECT_EQ(code, 128 + SIGTERM) << log;
  EXPECT_NE(s.find("message")->asString().find("interrupted"), std::string::npos)
      << s.find("message")->asString();
  EXPECT_TRUE(noTemporaries(dir));
  fs::remove_all(dir);
}

// A joint that never moves: its friction, rotor inertia and offset columns are zero or constant;
// the estimator refuses and names the unidentifiable directions, with the data file.
TEST(Hostile, AJointThatNeverMovesIsNamed) {
  const fs::path dir = tempDir("still");
  {
    std::ofstream f(dir / "data.csv");
    f << "t,q1,q2,qd1,qd2,qdd1,qdd2,tau1,tau2\n";
    for (int k = 0; k < 2000; ++k) {
      const double t = 0.005 * k;
      f << t << "," << std::sin(t) << ",0.3," << std::cos(t) << ",0," << -std::sin(t) << ",0,"
        << std::sin(3 * t) << "," << std::cos(2 * t) << "\n";
    }
  }
  std::ofstream(dir / "study.yaml")
      << kPlanar << "experiment: {type: csv, params: {file: data.csv}}\n";
  const Child c = start(dir / "study.yaml", dir / "out", dir);
  const int code = wait(c);
  const std::string log = slurp(c.log);
  EXPECT_EQ(code, 1) << log;
  EXPECT_NE(log.find("do not identify"), std::string::npos) << log;
  EXPECT_NE(log.find("2"), std::string::npos) << log;  // joint 2's parameters are named
  const exid::Json s = exid::Json::parse(slurp(dir / "out" / "summary.json"));
  EXPECT_EQ(s.find("failed_stage")->asString(), "identification");
  EXPECT_TRUE(fs::exists(dir / "out" / "experiment.csv"));  // the finished stage is kept
  EXPECT_TRUE(noTemporaries(dir));
  fs::remove_all(dir);
}

// Two row-aligned files of different length (experiment csv, torque_file): both files and their
// row counts are named, with the line of the first row that has no counterpart; exit 1, the
// resolved study is kept, no experiment.csv and no temporary file.
TEST(Hostile, TorqueFileRowMismatchNamesBothFiles) {
  const fs::path dir = tempDir("rows");
  {
    std::ofstream q(dir / "q.csv"), tau(dir / "tau.csv");
    q << "t,q1,q2\n";
    tau << "tau1,tau2\n";
    for (int k = 0; k < 500; ++k) {
      const double t = 0.01 * k;
      q << t << "," << std::sin(t) << "," << std::cos(2 * t) << "\n";
      if (k < 499) tau << std::sin(3 * t) << "," << std::cos(t) << "\n";  // one row short
    }
  }
  std::ofstream(dir / "study.yaml")
      << kPlanar
      << "experiment: {type: csv, params: {file: q.csv, q_columns: [q1, q2], torque_file: "
         "tau.csv, tau_columns: [tau1, tau2]}}\n";
  const Child c = start(dir / "study.yaml", dir / "out", dir);
  const int code = wait(c);
  const std::string log = slurp(c.log);
  EXPECT_EQ(code, 1) << log;
  EXPECT_NE(log.find((dir / "tau.csv").string() + " has 499 data rows"), std::string::npos) << log;
  EXPECT_NE(log.find((dir / "q.csv").string() + " has 500"), std::string::npos) << log;
  EXPECT_NE(log.find("row-aligned"), std::string::npos) << log;
  // Header at line 1, data row 500 at line 501 of q.csv: the first row without a counterpart.
  EXPECT_NE(log.find("line 501"), std::string::npos) << log;
  ASSERT_TRUE(fs::exists(dir / "out" / "summary.json")) << log;
  const exid::Json s = exid::Json::parse(slurp(dir / "out" / "summary.json"));
  EXPECT_EQ(s.find("status")->asString(), "failed");
  EXPECT_EQ(s.find("failed_stage")->asString(), "experiment");
  EXPECT_NE(s.find("message")->asString().find("row-aligned"), std::string::npos);
  EXPECT_TRUE(fs::exists(dir / "out" / "study.resolved.yaml"));
  EXPECT_FALSE(fs::exists(dir / "out" / "experiment.csv"));
  EXPECT_TRUE(noTemporaries(dir));
  fs::remove_all(dir);
}

namespace {

// An excitation study whose criterion (a test plugin, tests/plugins/nan_criterion_plugin.cpp)
// fails at every point, run with `optimizer`: its exit code, log and summary.json.
struct FailingExcitation {
  fs::path dir;
  int code = -1;
  std::string log;
  exid::Json summary;
};

FailingExcitation runFailingCriterion(const std::string& criterion, const std::string& optimizer) {
  FailingExcitation r;
  r.dir = tempDir(criterion + "_" + optimizer);
  std::ofstream(r.dir / "study.yaml") << "robot: {type: planar2r}\n"
                                         "model: {type: differential}\n"
                                         "excitation:\n"
                                         "  trajectory: {type: fourier, params: {harmonics: 2}}\n"
                                         "  criterion: {type: "
                                      << criterion << "}\n  optimizer: {type: " << optimizer
                                      << ", params: {max_evaluations: 30}}\n"
                                         "experiment: {type: simulate, params: {duration_s: 2}}\n"
                                         "estimator: {type: batch_ls}\n";
  const Child c = start(r.dir / "study.yaml", r.dir / "out", r.dir, 0,
                        std::string(EXID_TEST_PLUGIN_DIR) + "/nan_criterion_plugin");
  r.code = wait(c);
  r.log = slurp(c.log);
  if (fs::exists(r.dir / "out" / "summary.json"))
    r.summary = exid::Json::parse(slurp(r.dir / "out" / "summary.json"));
  return r;
}

// What every such study must do: exit 1, summary.json says the excitation stage failed, the
// resolved study is kept, and none of the stage's files (trajectories, criterion history) nor
// any later stage's is written; no temporary file is left.
void expectExcitationFailedCleanly(const FailingExcitation& r) {
  EXPECT_EQ(r.code, 1) << r.log;
  ASSERT_TRUE(r.summary.find("status")) << r.log;
  EXPECT_EQ(r.summary.find("status")->asString(), "failed");
  EXPECT_EQ(r.summary.find("failed_stage")->asString(), "excitation");
  EXPECT_TRUE(fs::exists(r.dir / "out" / "study.resolved.yaml"));
  for (const char* f : {"trajectory_initial.csv", "trajectory_optimal.csv", "criterion_history.csv",
                        "experiment.csv", "report.md"}) {
    EXPECT_FALSE(fs::exists(r.dir / "out" / f)) << f;
  }
  EXPECT_TRUE(noTemporaries(r.dir));
}

}  // namespace

// A criterion that evaluates to NaN at every point (test_nan), with each optimiser: the study
// file, the line of the criterion and the criterion are named, and the optimiser itself says it
// found no finite point (not a follow-on error elsewhere).
TEST(Hostile, NanCriterionDuringExcitationIsNamedAndWritesNothing) {
  for (const char* optimizer : {"nlopt", "adjoint_gradient", "sundials"}) {
    SCOPED_TRACE(optimizer);
    const FailingExcitation r = runFailingCriterion("test_nan", optimizer);
    expectExcitationFailedCleanly(r);
    EXPECT_NE(r.log.find((r.dir / "study.yaml").string() + ":5: excitation.criterion 'test_nan'"),
              std::string::npos)
        << r.log;
    EXPECT_NE(r.log.find("nan"), std::string::npos) << r.log;
    EXPECT_EQ(r.log.find("variables given"), std::string::npos) << r.log;
    const std::string msg =
        r.summary.find("message") ? r.summary.find("message")->asString() : std::string();
    EXPECT_NE(msg.find("test_nan"), std::string::npos) << msg;
    fs::remove_all(r.dir);
  }
}

// A criterion that throws at every point (test_singular, as on a singular information matrix):
// no optimiser may return one of those points as its result (nlopt used to offer them with the
// stand-in value 1e30 it gives NLopt); the message says why.
TEST(Hostile, CriterionThatFailsEverywhereFailsTheExcitation) {
  for (const char* optimizer : {"nlopt", "adjoint_gradient", "sundials"}) {
    SCOPED_TRACE(optimizer);
    const FailingExcitation r = runFailingCriterion("test_singular", optimizer);
    expectExcitationFailedCleanly(r);
    const std::string msg =
        r.summary.find("message") ? r.summary.find("message")->asString() : std::string();
    EXPECT_TRUE(msg.find("singular") != std::string::npos ||
                msg.find("no point could be evaluated") != std::string::npos)
        << msg;
    fs::remove_all(r.dir);
  }
}
