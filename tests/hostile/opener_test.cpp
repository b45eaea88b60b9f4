// Issue 37, "one way in for every file" (docs/hostile_input.md): every file exid reads goes
// through one opener (exid/input_file.hpp): regular files only, checked before opening and on
// the descriptor; no control byte in a path; a size cap per kind; during a run an entry in the
// input manifest (summary.json `inputs`). The exid program runs as a child process, killed
// after a timeout (a hang is a failure, not a stuck test) and with its address space capped (a
// read without end is a failure, not a machine out of memory).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "exid/input_file.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_opener_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

using exid_cli::slurp;

using exid_cli::contains;

using CmdResult = exid_cli::RunResult;

CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir,
                  double timeout_s = 60) {
  return exid_cli::runExidIn(args, dir, timeout_s,
                             exid_cli::Limits{exid_cli::underAddressSanitizer() ? 0 : 3072});
}

exid::Json summaryOf(const fs::path& dir) { return exid::Json::parse(slurp(dir / "summary.json")); }

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "(no error)";
}

// A two-joint recording (t, q1, q2, tau1, tau2) that moves both joints, 400 rows at 100 Hz.
void writeRecording(const fs::path& file) {
  std::ofstream f(file);
  f << "t,q1,q2,tau1,tau2\n";
  for (int k = 0; k < 400; ++k) {
    const double t = 0.01 * k;
    f << t << "," << std::sin(t) << "," << std::cos(1.3 * t) << "," << std::sin(3 * t) << ","
      << std::cos(2 * t) << "\n";
  }
}

const char* kPlanar =
    "robot: {type: planar2r}\n"
    "model: {type: differential}\n"
    "estimator: {type: batch_ls}\n"
    "report: {params: {plots: false}}\n";

// A two-link DH arm (planar2r's numbers) with a sphere at the end of each link, for studies
// with obstacles.
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

// A study designing an excitation for the arm with a mesh obstacle (file `mesh`).
std::string meshStudy(const std::string& mesh) {
  return std::string(
             "robot: {type: dh, params: {file: arm.yaml}}\n"
             "model: {type: differential}\n"
             "excitation:\n"
             "  trajectory: {type: fourier, params: {harmonics: 2}}\n"
             "  criterion: {type: cond}\n"
             "  optimizer: {type: nlopt, params: {max_evaluations: 10}}\n"
             "  collision:\n"
             "    margin_m: 0.01\n"
             "    obstacles:\n"
             "      - {name: block, mesh: {file: \"") +
         mesh +
         "\"}, xyz_m: [0, 0, 3]}\n"
         "report: {params: {plots: false}}\n";
}

// An ASCII STL tetrahedron of edge `size` m.
void writeTetrahedron(const fs::path& file, double size = 0.1) {
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

// A NUL inside a path silently cut it: `good.csv\0.ignored` read good.csv (the opener and the
// study's path parameters refuse control bytes). The same path without the NUL still reads.
TEST(Opener, ControlBytesInAPathAreRefused) {
  const fs::path dir = tempDir("nul");
  writeRecording(dir / "good.csv");
  const std::string cut = (dir / "good.csv").string() + std::string(1, '\0') + ".ignored";
  std::string m = errorOf([&] { exid::readInputFile(cut, "CSV", 1 << 20); });
  EXPECT_TRUE(contains(m,
                       "good.csv\\x00.ignored: the path of the CSV file holds the control "
                       "byte 0x00"))
      << m;
  m = errorOf([&] { exid::CsvReader r{fs::path(cut)}; });
  EXPECT_TRUE(contains(m, "control byte 0x00")) << m;
  m = errorOf([&] { exid::readInputFile((dir / "good.csv").string() + "\n", "CSV", 1 << 20); });
  EXPECT_TRUE(contains(m, "control byte 0x0A")) << m;
  EXPECT_EQ(exid::readInputFile(dir / "good.csv", "CSV", 1 << 20), slurp(dir / "good.csv"));

  // In a study: refused before anything runs, naming the key (exit 2).
  std::ofstream(dir / "s.yaml") << kPlanar
                                << "experiment: {type: csv, params: {file: \"good.csv\\0.ignored\","
                                   " differentiate_cutoff_hz: 5}}\n";
  CmdResult r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "experiment.params.file")) << r.out;
  EXPECT_TRUE(contains(r.out, "control byte 0x00")) << r.out;
  EXPECT_FALSE(fs::exists(dir / "out"));
  std::ofstream(dir / "s.yaml") << kPlanar
                                << "experiment: {type: csv, params: {file: good.csv, "
                                   "differentiate_cutoff_hz: 5}}\n";
  r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;

  // A mesh path with a NUL: refused at its key (it read the mesh before the NUL).
  std::ofstream(dir / "arm.yaml") << kArmYaml;
  writeTetrahedron(dir / "block.stl");
  std::ofstream(dir / "m.yaml") << meshStudy("block.stl\\0.ignored");
  r = runExid({"validate", "m.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "obstacles[0].mesh.file")) << r.out;
  EXPECT_TRUE(contains(r.out, "block.stl\\x00.ignored")) << r.out;
  std::ofstream(dir / "m.yaml") << meshStudy("block.stl");
  r = runExid({"validate", "m.yaml"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

// A FIFO as a mesh blocked forever, a directory exited 3 ("basic_filebuf::underflow"),
// /dev/zero read until memory ran out: each is refused before it is read, naming the file.
// A regular mesh in the same place is read.
TEST(Opener, AMeshThatIsNotARegularFileIsRefusedNotAHang) {
  const fs::path dir = tempDir("mesh");
  std::ofstream(dir / "arm.yaml") << kArmYaml;
  ASSERT_EQ(::mkfifo((dir / "fifo.stl").c_str(), 0644), 0);
  fs::create_directories(dir / "folder.stl");
  struct Case {
    std::string file, says;
  };
  for (const Case& c : {Case{"fifo.stl", "fifo.stl: the mesh file is a FIFO (named pipe)"},
                        Case{"folder.stl", "folder.stl: the mesh file is a directory"},
                        Case{"/dev/zero", "/dev/zero: the mesh file is a character device"}}) {
    SCOPED_TRACE(c.file);
    std::ofstream(dir / "m.yaml") << meshStudy(c.file);
    const CmdResult r = runExid({"-q", "run", "m.yaml", "--out", "out"}, dir, 60);
    EXPECT_EQ(r.signal, 0) << "hung or ran out of memory: " << r.out;
    EXPECT_EQ(r.code, 1) << r.out;  // a failed stage, named
    EXPECT_TRUE(contains(r.out, c.says)) << r.out;
    EXPECT_FALSE(contains(r.out, "unexpected error")) << r.out;
  }
  writeTetrahedron(dir / "block.stl");
  std::ofstream(dir / "m.yaml") << meshStudy("block.stl");
  const CmdResult r = runExid({"-q", "run", "m.yaml", "--out", "out"}, dir, 120);
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

// A FIFO as the metadata.yaml inside a bag folder blocked forever; a directory there exited 3.
// Both are refused before they are read, naming the file; a metadata.yaml that is a file is read
// (and its own problem named).
TEST(Opener, BagMetadataThatIsNotARegularFileIsRefusedNotAHang) {
  const fs::path dir = tempDir("bagmeta");
  std::ofstream(dir / "s.yaml") << kPlanar << "experiment: {type: rosbag2, params: {path: bag}}\n";
  fs::create_directories(dir / "bag");
  ASSERT_EQ(::mkfifo((dir / "bag" / "metadata.yaml").c_str(), 0644), 0);
  CmdResult r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir, 60);
  EXPECT_EQ(r.signal, 0) << "hung: " << r.out;
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "metadata.yaml: the bag metadata file is a FIFO")) << r.out;
  fs::remove(dir / "bag" / "metadata.yaml");
  fs::create_directories(dir / "bag" / "metadata.yaml");
  r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir, 60);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "metadata.yaml: the bag metadata file is a directory")) << r.out;
  EXPECT_FALSE(contains(r.out, "underflow")) << r.out;
  fs::remove_all(dir / "bag" / "metadata.yaml");
  std::ofstream(dir / "bag" / "metadata.yaml") << "rosbag2_bagfile_information: {version: 5}\n";
  r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir, 60);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "storage_identifier: missing")) << r.out;
  // over the cap of a bag's metadata.yaml: refused before it is parsed
  std::ofstream(dir / "bag" / "metadata.yaml")
      << "rosbag2_bagfile_information: {version: 5}\n#" << std::string(1 << 20, 'x') << "\n";
  r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir, 60);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "more than the limit of 1048576 bytes")) << r.out;
  fs::remove_all(dir);
}

// The input manifest: every file a run read, with its size and content hash, in summary.json
// `inputs`; a run that read no file lists none. Files read outside a run are not recorded.
TEST(Opener, TheRunsInputsAreInItsSummary) {
  const fs::path dir = tempDir("manifest");
  writeRecording(dir / "rec.csv");
  std::ofstream(dir / "arm.yaml") << kArmYaml;
  std::ofstream(dir / "s.yaml") << "robot: {type: dh, params: {file: arm.yaml}}\n"
                                   "model: {type: differential}\n"
                                   "estimator: {type: batch_ls}\n"
                                   "report: {params: {plots: false}}\n"
                                   "experiment: {type: csv, params: {file: rec.csv, "
                                   "differentiate_cutoff_hz: 5}}\n";
  CmdResult r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json S = summaryOf(dir / "out");
  const exid::Json* in = S.find("inputs");
  ASSERT_TRUE(in && in->isArray()) << slurp(dir / "out" / "summary.json");
  ASSERT_EQ(in->size(), 2u) << slurp(dir / "out" / "summary.json");
  for (const fs::path& f : {dir / "arm.yaml", dir / "rec.csv"}) {
    SCOPED_TRACE(f.string());
    const exid::Json* e = nullptr;
    for (std::size_t i = 0; i < in->size(); ++i)
      if (in->at(i).find("path")->asString() == f.string()) e = &in->at(i);
    ASSERT_TRUE(e);
    const std::string text = slurp(f);
    EXPECT_EQ(e->find("size_bytes")->asDouble(), static_cast<double>(text.size()));
    EXPECT_EQ(e->find("xxh3_64")->asString(), exid::hashHex(exid::xxh3_64(text)));
  }
  // a built-in robot and simulated data: no input file
  std::ofstream(dir / "sim.yaml") << kPlanar
                                  << "experiment: {type: simulate, params: {duration_s: 2}}\n";
  r = runExid({"-q", "run", "sim.yaml", "--out", "sim"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json sim = summaryOf(dir / "sim");  // (find points into it: kept alive)
  const exid::Json* none = sim.find("inputs");
  ASSERT_TRUE(none && none->isArray());
  EXPECT_EQ(none->size(), 0u);
  fs::remove_all(dir);
}

// The manifest in the library: XXH3 64 (the reference's values for "" and "a", seed 0; a
// file of several read blocks hashed in pieces as in one piece), one entry per file whether it
// is read whole or streamed, a file read again unchanged once; per thread (two runs side by
// side keep their own); nothing recorded without one. FNV-1a 64 (its published test vectors)
// still hashes the configurations and the cells' keys.
TEST(Opener, TheManifestRecordsEachFileOncePerRunAndThread) {
  EXPECT_EQ(exid::hashHex(exid::fnv1a64("")), "cbf29ce484222325");
  EXPECT_EQ(exid::hashHex(exid::fnv1a64("a")), "af63dc4c8601ec8c");
  EXPECT_EQ(exid::hashHex(exid::fnv1a64("foobar")), "85944171f73967e8");
  EXPECT_EQ(exid::hashHex(exid::xxh3_64("")), "2d06800538d394c2");
  EXPECT_EQ(exid::hashHex(exid::xxh3_64("a")), "e6c632b61e964e1f");
  {
    const fs::path big = tempDir("big") / "big.bin";
    std::string bytes(3 * (std::size_t{1} << 20) + 12345, '\0');
    for (std::size_t i = 0; i < bytes.size(); ++i)
      bytes[i] = static_cast<char>((i * 2654435761u) >> 13);
    std::ofstream(big, std::ios::binary) << bytes;
    EXPECT_EQ(exid::xxh3File(big), exid::xxh3_64(bytes));
    bytes[bytes.size() / 2] ^= 1;
    EXPECT_NE(exid::xxh3File(big), exid::xxh3_64(bytes));
    fs::remove_all(big.parent_path());
  }
  const fs::path dir = tempDir("lib");
  writeRecording(dir / "a.csv");
  std::ofstream(dir / "b.txt") << "bee";
  exid::InputManifest m1, m2;
  {
    const exid::InputManifestScope scope(&m1);
    exid::readCsv(dir / "a.csv");
    exid::readCsv(dir / "a.csv");
    exid::readInputFile(dir / "b.txt", "text", 100);
    std::thread other([&] {
      const exid::InputManifestScope s2(&m2);
      exid::readInputFile(dir / "b.txt", "other text", 100);
    });
    other.join();
  }
  exid::readInputFile(dir / "b.txt", "text", 100);  // no run: not recorded
  const auto e1 = m1.entries();
  ASSERT_EQ(e1.size(), 2u);
  EXPECT_EQ(e1[0].path, (dir / "a.csv").string());
  EXPECT_EQ(e1[0].kind, "CSV");
  EXPECT_EQ(e1[0].size_bytes, fs::file_size(dir / "a.csv"));
  EXPECT_EQ(e1[0].xxh3_64, exid::xxh3_64(slurp(dir / "a.csv")));
  EXPECT_EQ(e1[0].xxh3_64, exid::xxh3File(dir / "a.csv"));
  EXPECT_EQ(e1[1].path, (dir / "b.txt").string());
  EXPECT_EQ(e1[1].xxh3_64, exid::xxh3_64("bee"));
  const auto e2 = m2.entries();
  ASSERT_EQ(e2.size(), 1u);
  EXPECT_EQ(e2[0].kind, "other text");
  fs::remove_all(dir);
}
