// Comparison matrices: cells are isolated (a failing or over-budget cell does not lose the
// others), results are keyed by configuration hash (re-running skips finished cells), shards
// merge to the single-process result, and a run killed part-way loses only cells in flight.
#include "exid/matrix.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "exid/error.hpp"
#include "exid/version.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_matrix_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

const char* kMatrix = R"(name: t
cell_budget_s: 30
study:
  robot: {type: planar2r}
  model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}
  experiment: {type: simulate, params: {duration_s: 2, drive_terms: false, noise_tau_Nm: 0.01}}
  estimator: {type: batch_ls}
axes:
  estimator: [{type: batch_ls}, {type: wls}]
  seed: [1, 2, 3]
)";

}  // namespace

TEST(Matrix, ProductOfAxesAndEveryCellValidatedFirst) {
  fs::path d = tempDir("axes");
  std::ofstream(d / "m.yaml") << kMatrix;
  exid::MatrixSpec spec = exid::loadMatrix(d / "m.yaml", exid_test::registry());
  ASSERT_EQ(spec.cells.size(), 6u);
  EXPECT_EQ(spec.cells[1].label, "estimator=batch_ls seed=2");
  EXPECT_NE(spec.cells[0].hash, spec.cells[1].hash);
  std::string bad = kMatrix;
  bad.replace(bad.find("{type: wls}"), 11, "{type: wlss}");
  std::ofstream(d / "bad.yaml") << bad;
  try {
    exid::loadMatrix(d / "bad.yaml", exid_test::registry());
    FAIL() << "expected an error";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("cell 3 (estimator=wlss seed=1)"), std::string::npos) << m;
    EXPECT_NE(m.find("did you mean 'wls'?"), std::string::npos) << m;
  }
  fs::remove_all(d);
}

// The budget separates cells far apart on any machine: the good cells take ~0.1 s (a few s
// sanitized and loaded), the slow one minutes of CPU (2 M samples integrated at rtol 1e-12; 17 s
// at the default tolerances on the development machine), so no machine's speed changes which
// cell times out.
TEST(Matrix, AFailingCellAndATimeoutDoNotLoseTheOthers) {
  fs::path d = tempDir("isolation");
  std::ofstream(d / "m.yaml") << R"(name: iso
cell_budget_s: 6
study:
  robot: {type: planar2r}
  model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}
  experiment: {type: simulate, params: {duration_s: 2, drive_terms: false}}
  estimator: {type: batch_ls}
cells:
  - {seed: 1}
  - {experiment: {type: csv, params: {file: does_not_exist.csv}}}
  - {experiment: {type: simulate, params: {duration_s: 2000, sample_period_s: 0.001, drive_terms: false, rtol: 1e-12, atol: 1e-14}}}
  - {seed: 2}
)";
  exid::MatrixSpec spec = exid::loadMatrix(d / "m.yaml", exid_test::registry());
  exid::MatrixOptions opt;
  opt.out_dir = d / "out";
  opt.jobs = 2;
  exid::MatrixRunSummary s = exid::runMatrix(spec, exid_test::registry(), opt);
  EXPECT_EQ(s.total, 4);
  EXPECT_EQ(s.ok, 2);
  EXPECT_EQ(s.failed, 1);
  EXPECT_EQ(s.timeout, 1);
  // The table shows the two good cells and marks the others.
  exid::MatrixTable t =
      exid::matrixTable(opt.out_dir / "results.sqlite", {"seed"}, {}, "residual_rms");
  EXPECT_NE(t.markdown.find("n/a"), std::string::npos) << t.markdown;
  // Re-running skips every finished cell (failed ones too, unless asked).
  s = exid::runMatrix(spec, exid_test::registry(), opt);
  EXPECT_EQ(s.skipped, 4);
  fs::remove_all(d);
}

TEST(Matrix, ShardsMergeToTheSingleProcessResult) {
  fs::path d = tempDir("shards");
  std::ofstream(d / "m.yaml") << kMatrix;
  exid::MatrixSpec spec = exid::loadMatrix(d / "m.yaml", exid_test::registry());
  exid::MatrixOptions one;
  one.out_dir = d / "single";
  one.write_cell_files = false;
  exid::runMatrix(spec, exid_test::registry(), one);
  for (int i = 0; i < 2; ++i) {
    exid::MatrixOptions sh = one;
    sh.out_dir = d / ("shard" + std::to_string(i));
    sh.shard_index = i;
    sh.shard_count = 2;
    exid::MatrixRunSummary s = exid::runMatrix(spec, exid_test::registry(), sh);
    EXPECT_EQ(s.total, 3);
  }
  EXPECT_EQ(exid::mergeMatrixDatabases(
                d / "merged" / "results.sqlite",
                {d / "shard0" / "results.sqlite", d / "shard1" / "results.sqlite"}),
            6);
  auto a = exid::matrixTable(d / "single" / "results.sqlite", {"estimator", "seed"}, {},
                             "param_rel_err");
  auto b = exid::matrixTable(d / "merged" / "results.sqlite", {"estimator", "seed"}, {},
                             "param_rel_err");
  EXPECT_EQ(a.csv, b.csv);
  // Every row carries the exid version and the git commit it was computed with.
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((d / "merged" / "results.sqlite").string().c_str(), &db), SQLITE_OK);
    sqlite3_stmt* st = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db,
                                 "SELECT (SELECT text FROM metrics m WHERE m.run_id = r.id AND "
                                 "m.name = 'exid_version'), (SELECT text FROM metrics m WHERE "
                                 "m.run_id = r.id AND m.name = 'exid_commit') FROM runs r",
                                 -1, &st, nullptr),
              SQLITE_OK);
    int rows = 0;
    while (sqlite3_step(st) == SQLITE_ROW) {
      ++rows;
      const unsigned char* v = sqlite3_column_text(st, 0);
      const unsigned char* c = sqlite3_column_text(st, 1);
      ASSERT_TRUE(v && c);
      EXPECT_EQ(std::string(reinterpret_cast<const char*>(v)), EXID_VERSION_STRING);
      EXPECT_EQ(std::string(reinterpret_cast<const char*>(c)), exid::gitCommit());
    }
    EXPECT_EQ(rows, 6);
    sqlite3_finalize(st);
    sqlite3_close(db);
  }
  // Merging again copies nothing new.
  EXPECT_EQ(exid::mergeMatrixDatabases(d / "merged" / "results.sqlite",
                                       {d / "shard0" / "results.sqlite"}),
            0);
  fs::remove_all(d);
}

TEST(Matrix, KilledPartWayLosesOnlyTheCellsInFlight) {
  fs::path d = tempDir("killed");
  std::ofstream(d / "m.yaml") << R"(name: k
study:
  robot: {type: puma560}
  model: {type: differential}
  experiment: {type: simulate, params: {duration_s: 8, sample_period_s: 0.002}}
  estimator: {type: rls}
axes:
  seed: [1, 2, 3, 4, 5, 6]
)";
  pid_t pid = ::fork();
  if (pid == 0) {
    std::string out = (d / "out").string();
    std::string file = (d / "m.yaml").string();
    ::execl(EXID_EXE, EXID_EXE, "-q", "matrix", file.c_str(), "--out", out.c_str(), "-j", "1",
            (char*)nullptr);
    ::_exit(127);
  }
  // Wait until at least one cell is finished, then stop the matrix.
  const fs::path db = d / "out" / "results.sqlite";
  for (int i = 0; i < 600; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (fs::exists(db)) {
      try {
        auto t = exid::matrixTable(db, {"seed"}, {}, "param_rel_err");
        if (t.csv.find('\n') != t.csv.rfind('\n')) break;  // a data row exists
      } catch (const exid::Error&) {
      }
    }
  }
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGTERM);  // interrupted by SIGTERM: 143
  exid::MatrixSpec spec = exid::loadMatrix(d / "m.yaml", exid_test::registry());
  exid::MatrixOptions opt;
  opt.out_dir = d / "out";
  opt.jobs = 2;
  opt.write_cell_files = false;
  exid::MatrixRunSummary s = exid::runMatrix(spec, exid_test::registry(), opt);
  EXPECT_GE(s.skipped, 1);
  EXPECT_LT(s.skipped, 6);
  EXPECT_EQ(s.skipped + s.ok, 6);
  fs::remove_all(d);
}

// Each cell's line says how many of the run's cells are done and, while some are left, about
// how long they take at the pace so far; the last line has no estimate.
TEST(Matrix, EachCellsLineSaysHowFarTheRunIs) {
  fs::path d = tempDir("pace");
  std::ofstream(d / "m.yaml") << R"(name: pace
study:
  robot: {type: planar2r}
  model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}
  experiment: {type: simulate, params: {duration_s: 1, drive_terms: false}}
  estimator: {type: batch_ls}
axes:
  seed: [1, 2, 3]
)";
  exid::MatrixSpec spec = exid::loadMatrix(d / "m.yaml", exid_test::registry());
  exid::MatrixOptions opt;
  opt.out_dir = d / "out";
  opt.jobs = 1;
  testing::internal::CaptureStderr();
  exid::MatrixRunSummary s = exid::runMatrix(spec, exid_test::registry(), opt);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(s.ok, 3);
  EXPECT_NE(err.find("[1/3, about "), std::string::npos) << err;
  EXPECT_NE(err.find("[2/3, about "), std::string::npos) << err;
  EXPECT_NE(err.find("[3/3]\n"), std::string::npos) << err;
  EXPECT_EQ(err.find("[3/3, about"), std::string::npos) << err;
  // a second run has nothing to do: no cell line
  testing::internal::CaptureStderr();
  s = exid::runMatrix(spec, exid_test::registry(), opt);
  const std::string again = testing::internal::GetCapturedStderr();
  EXPECT_EQ(s.skipped, 3);
  EXPECT_EQ(again.find("[1/"), std::string::npos) << again;
  fs::remove_all(d);
}
