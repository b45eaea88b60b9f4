// Issue 37, "nothing stale comes out" (docs/hostile_input.md): a matrix cell is finished only
// while every file of its input manifest (summary.json `inputs`: what the cell read, inside a
// bag folder too, an obstacle's mesh) still hashes the same; an export replaces its folder whole.
// The exid program runs as a child process, killed after a timeout.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) { return exid_cli::freshTempDir("exid_stale_", name); }

using exid_cli::slurp;

using exid_cli::contains;

using CmdResult = exid_cli::RunResult;

CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir,
                  double timeout_s = 180) {
  return exid_cli::runExidIn(args, dir, timeout_s);
}

// ------------------------------------------------------------------ a rosbag2 bag (SQLite)
using Bytes = std::vector<std::uint8_t>;

// sensor_msgs/msg/JointState in CDR (little endian).
struct Cdr {
  Bytes b{0x00, 0x01, 0x00, 0x00};
  void put(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void align(std::size_t a) {
    while ((b.size() - 4) % a != 0) b.push_back(0);
  }
  void u32(std::uint32_t v) {
    align(4);
    put(v, 4);
  }
  void f64(double d) {
    align(8);
    std::uint64_t u;
    std::memcpy(&u, &d, 8);
    put(u, 8);
  }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    b.insert(b.end(), s.begin(), s.end());
    b.push_back(0);
  }
  void doubles(const std::vector<double>& v) {
    u32(static_cast<std::uint32_t>(v.size()));
    for (double d : v) f64(d);
  }
};

Bytes jointState(std::int64_t ns, const std::vector<double>& q, const std::vector<double>& tau) {
  Cdr w;
  w.u32(static_cast<std::uint32_t>(ns / 1000000000LL));
  w.u32(static_cast<std::uint32_t>(ns % 1000000000LL));
  w.str("base");
  w.u32(2);
  w.str("joint1");
  w.str("joint2");
  w.doubles(q);
  w.doubles({});
  w.doubles(tau);
  return w.b;
}

void sql(sqlite3* db, const std::string& s) {
  char* err = nullptr;
  ASSERT_EQ(sqlite3_exec(db, s.c_str(), nullptr, nullptr, &err), SQLITE_OK) << err;
}

// A bag folder of planar2r's joints (400 joint states at 100 Hz, both joints moving), the
// torques scaled by tau_scale.
void writeBag(const fs::path& dir, double tau_scale) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path file = dir / "bag_0.db3";
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.string().c_str(), &db), SQLITE_OK);
  sql(db,
      "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
      "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)");
  sql(db,
      "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp "
      "INTEGER NOT NULL, data BLOB NOT NULL)");
  sql(db,
      "INSERT INTO topics VALUES (1, '/joint_states', 'sensor_msgs/msg/JointState', 'cdr', '')");
  sql(db, "BEGIN");
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "INSERT INTO messages(topic_id, timestamp, data) VALUES (1,?,?)",
                               -1, &st, nullptr),
            SQLITE_OK);
  const std::int64_t t0 = 1700000000LL * 1000000000LL;
  for (int k = 0; k < 400; ++k) {
    const double t = 0.01 * k;
    const std::int64_t ns = t0 + 10000000LL * k;
    const Bytes m = jointState(ns, {std::sin(t), std::cos(1.3 * t)},
                               {tau_scale * std::sin(3 * t), tau_scale * std::cos(2 * t)});
    sqlite3_bind_int64(st, 1, ns + 1000000);
    sqlite3_bind_blob(st, 2, m.data(), static_cast<int>(m.size()), SQLITE_TRANSIENT);
    ASSERT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_reset(st);
  }
  sqlite3_finalize(st);
  sql(db, "COMMIT");
  sqlite3_close(db);
  std::ofstream(dir / "metadata.yaml")
      << "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
         "  topics_with_message_count:\n"
         "    - topic_metadata:\n        name: /joint_states\n"
         "        type: sensor_msgs/msg/JointState\n        serialization_format: cdr\n"
         "      message_count: 400\n"
         "  compression_format: \"\"\n  compression_mode: \"\"\n"
         "  relative_file_paths:\n    - bag_0.db3\n";
}

std::string metric(const fs::path& dir, const std::string& name) {
  return runExid({"matrix", "table", "o", "--rows", "seed", "--metric", name}, dir).out;
}

// A two-link DH arm (planar2r's numbers) with a sphere at the end of each link.
const char* kArmYaml = R"(name: arm2
convention: standard
gravity: [0.0, -9.81, 0.0]
links:
  - name: link1
    joint: joint1
    type: revolute
    a: 1.0
    alpha: 0.0
    d: 0.0
    theta: 0.0
    mass: 1.0
    com: [-0.5, 0.0, 0.0]
    inertia_com: {xx: 0.0, yy: 0.08333333333333333, zz: 0.08333333333333333}
    limits: {q_min_deg: -180, q_max_deg: 180, qd_max: 3.0, qdd_max: 10.0}
    collision:
      - {sphere: {radius_m: 0.05}}
  - name: link2
    joint: joint2
    type: revolute
    a: 1.0
    alpha: 0.0
    d: 0.0
    theta: 0.0
    mass: 1.0
    com: [-0.5, 0.0, 0.0]
    inertia_com: {xx: 0.0, yy: 0.08333333333333333, zz: 0.08333333333333333}
    limits: {q_min_deg: -160, q_max_deg: 160, qd_max: 3.0, qdd_max: 10.0}
    collision:
      - {sphere: {radius_m: 0.05}}
)";

// An ASCII STL tetrahedron of edge `size` m.
void writeTetrahedron(const fs::path& file, double size) {
  std::ofstream stl(file);
  const double v[4][3] = {{0, 0, 0}, {size, 0, 0}, {0, size, 0}, {0, 0, size}};
  const int f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  stl << "solid tet\n";
  for (const auto& t : f) {
    stl << " facet normal 0 0 0\n  outer loop\n";
    for (int k : t) stl << "   vertex " << v[k][0] << " " << v[k][1] << " " << v[k][2] << "\n";
    stl << "  endloop\n endfacet\n";
  }
  stl << "endsolid tet\n";
}

}  // namespace

// A cell's key left out what a bag folder holds: changing the bag's storage file left the matrix
// saying "skipped (finished before)" with the old results. Unchanged, the cells are still
// skipped; changed, they run again and the table holds the new result.
TEST(StaleInputs, AChangedFileInsideABagFolderRunsTheCellsAgain) {
  const fs::path dir = tempDir("bag");
  writeBag(dir / "bag", 1.0);
  std::ofstream(dir / "m.yaml") << R"(name: m
cell_budget_s: 120
study:
  robot: {type: planar2r}
  model: {type: differential}
  experiment: {type: rosbag2, params: {path: bag}}
  estimator: {type: filtered_ls, params: {cutoff_hz: 5}}
  report: {params: {plots: false}}
axes:
  seed: [1, 2]
)";
  CmdResult r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  ASSERT_TRUE(contains(r.out, "2 ok")) << r.out;
  const std::string before = metric(dir, "residual_rms");
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "0 ok, 0 failed, 0 timeout, 2 skipped (finished before)")) << r.out;
  writeBag(dir / "bag", 2.0);  // the same folder and metadata.yaml, other torques
  r = runExid({"matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "2 ok, 0 failed, 0 timeout, 0 skipped")) << r.out;
  EXPECT_TRUE(contains(r.out, "bag_0.db3 changed since the cell ran")) << r.out;
  const std::string after = metric(dir, "residual_rms");
  EXPECT_NE(after, before);
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_TRUE(contains(r.out, "2 skipped (finished before)")) << r.out;
  EXPECT_EQ(metric(dir, "residual_rms"), after);
  // manifests an earlier exid wrote (FNV-1a hashes, key fnv1a64) cannot vouch for the files:
  // the cells run again and say why
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir / "o" / "results.sqlite").string().c_str(), &db), SQLITE_OK);
    sql(db, "UPDATE runs SET summary = replace(summary, '\"xxh3_64\"', '\"fnv1a64\"')");
    sqlite3_close(db);
  }
  r = runExid({"matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "2 ok, 0 failed, 0 timeout, 0 skipped")) << r.out;
  EXPECT_TRUE(contains(r.out, "holds the hashes of an earlier exid (FNV-1a; now XXH3)")) << r.out;
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_TRUE(contains(r.out, "2 skipped (finished before)")) << r.out;
  fs::remove_all(dir);
}

// The same for an obstacle's mesh (a file named inside the study's collision section): a
// changed mesh runs the cell again; unchanged, it is skipped.
TEST(StaleInputs, AChangedObstacleMeshRunsTheCellAgain) {
  const fs::path dir = tempDir("mesh");
  std::ofstream(dir / "arm.yaml") << kArmYaml;
  writeTetrahedron(dir / "block.stl", 0.1);
  std::ofstream(dir / "m.yaml") << R"(name: m
cell_budget_s: 120
study:
  robot: {type: dh, params: {file: arm.yaml}}
  model: {type: differential}
  excitation:
    trajectory: {type: fourier, params: {harmonics: 2}}
    criterion: {type: cond}
    optimizer: {type: nlopt, params: {max_evaluations: 10}}
    collision:
      margin_m: 0.01
      obstacles:
        - {name: block, mesh: {file: block.stl}, xyz_m: [0, 0, 3]}
  report: {params: {plots: false}}
axes:
  seed: [1]
)";
  CmdResult r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  ASSERT_TRUE(contains(r.out, "1 ok")) << r.out;
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_TRUE(contains(r.out, "0 ok, 0 failed, 0 timeout, 1 skipped (finished before)")) << r.out;
  writeTetrahedron(dir / "block.stl", 0.5);
  r = runExid({"matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "1 ok, 0 failed, 0 timeout, 0 skipped")) << r.out;
  EXPECT_TRUE(contains(r.out, "block.stl changed since the cell ran (mesh:")) << r.out;
  r = runExid({"-q", "matrix", "m.yaml", "--out", "o"}, dir);
  EXPECT_TRUE(contains(r.out, "1 skipped (finished before)")) << r.out;
  fs::remove_all(dir);
}

// An export left an earlier export's plots/ beside its new files: the folder now holds the new
// export only. A folder holding something else than an export is refused and left as it was.
TEST(StaleInputs, AnExportReplacesItsFolderWhole) {
  const fs::path dir = tempDir("export");
  std::ofstream(dir / "x.yaml") << R"(robot: {type: planar2r}
model: {type: differential}
excitation:
  trajectory: {type: fourier, params: {harmonics: 2}}
  criterion: {type: cond}
  optimizer: {type: nlopt, params: {max_evaluations: 10}}
report: {params: {plots: false}}
)";
  // an earlier export, with plots
  fs::create_directories(dir / "exp" / "plots");
  std::ofstream(dir / "exp" / "trajectory_check.json") << "{}\n";
  std::ofstream(dir / "exp" / "trajectory.csv") << "t,q1\n0,0\n";
  std::ofstream(dir / "exp" / "plots" / "trajectory_q.svg") << "<svg/>\n";
  // (exit 1 or 0: a budget of 10 evaluations may leave a limit exceeded at the controller rate)
  CmdResult r = runExid({"excite", "x.yaml", "--out", "run", "--export", "exp"}, dir);
  ASSERT_TRUE(contains(r.out, "Trajectory for execution in exp/")) << r.out;
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir / "exp"))
    names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"joint_trajectory.yaml", "trajectory.csv",
                                             "trajectory.params.yaml", "trajectory_check.json"}));
  EXPECT_NE(slurp(dir / "exp" / "trajectory.csv"), "t,q1\n0,0\n");
  for (const auto& e : fs::directory_iterator(dir))  // no staging folder left beside it
    EXPECT_FALSE(contains(e.path().filename().string(), "staging")) << e.path();
  // exported again into the same folder: replaced
  r = runExid({"excite", "x.yaml", "--out", "run", "--export", "exp"}, dir);
  EXPECT_TRUE(contains(r.out, "Trajectory for execution in exp/")) << r.out;
  EXPECT_TRUE(fs::exists(dir / "exp" / "trajectory_check.json"));
  // a folder of something else: refused, untouched
  fs::create_directories(dir / "mine");
  std::ofstream(dir / "mine" / "notes.txt") << "keep me\n";
  r = runExid({"-q", "excite", "x.yaml", "--out", "run2", "--export", "mine"}, dir);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "--export mine: the folder holds 'notes.txt'")) << r.out;
  EXPECT_EQ(slurp(dir / "mine" / "notes.txt"), "keep me\n");
  EXPECT_FALSE(fs::exists(dir / "mine" / "trajectory.csv"));
  fs::remove_all(dir);
}
