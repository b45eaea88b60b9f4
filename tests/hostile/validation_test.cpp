// Issue 37, "one validation" (docs/hostile_input.md): `exid run` refuses before any stage what
// `exid validate` refuses, with the same message and exit 2; `exid validate` loads the robot;
// every command taking a robot file gives the xacro hint; no exit 3 and no overflowed number for
// a fault in the input (a prior's std of 1e300, varpro's delay bound of 1e300 s); `--out`
// naming a symbolic link writes into its target. The exid program runs as a child process.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "exid/json.hpp"
#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_validation_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

using exid_cli::slurp;

using CmdResult = exid_cli::RunResult;

CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir,
                  double timeout_s = 120) {
  return exid_cli::runExidIn(args, dir, timeout_s);
}

using exid_cli::contains;

std::string statusOf(const fs::path& dir) {
  if (!fs::exists(dir / "summary.json")) return "(no summary.json)";
  const exid::Json s = exid::Json::parse(slurp(dir / "summary.json"));
  return s.find("status") ? s.find("status")->asString() : "(no status)";
}

// The message after "exid: " (the error line of a refused command).
std::string errorLine(const std::string& out) {
  const auto at = out.find("exid: ");
  if (at == std::string::npos) return "";
  const auto end = out.find('\n', at);
  return out.substr(at, end == std::string::npos ? std::string::npos : end - at);
}

const char* kPlanar =
    "robot: {type: planar2r}\n"
    "model: {type: differential}\n";

// An excitation design of a few seconds: what `exid run` did first before it reached the
// estimator it could have refused at once.
const char* kExcitation =
    "excitation:\n"
    "  trajectory: {type: fourier, params: {harmonics: 5}}\n"
    "  criterion: {type: cond}\n"
    "  optimizer: {type: nlopt}\n"
    "experiment: {type: simulate, params: {duration_s: 2}}\n"
    "report: {params: {plots: false}}\n";

}  // namespace

// An estimator whose parameters contradict each other (validate refused it with exit 2; run
// designed the excitation first and failed at the identification stage with exit 1).
TEST(Validation, RunRefusesWhatValidateRefusesBeforeAnyStage) {
  const fs::path dir = tempDir("one");
  std::ofstream(dir / "bad.yaml")
      << kPlanar << kExcitation
      << "estimator: {type: varpro, params: {measurement_delay_max_s: 0.01}}\n";
  std::ofstream(dir / "good.yaml") << kPlanar << kExcitation
                                   << "estimator: {type: varpro, params: {measurement_delay: true, "
                                      "measurement_delay_max_s: 0.01}}\n";
  const CmdResult v = runExid({"validate", "bad.yaml"}, dir);
  EXPECT_EQ(v.code, 2) << v.out;
  EXPECT_TRUE(contains(v.out, "bad.yaml:9: estimator: ")) << v.out;
  EXPECT_TRUE(contains(v.out, "measurement_delay is false")) << v.out;
  const CmdResult r = runExid({"run", "bad.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_EQ(errorLine(r.out), errorLine(v.out)) << r.out;
  EXPECT_FALSE(fs::exists(dir / "out")) << r.out;  // nothing ran, nothing written
  EXPECT_FALSE(contains(r.out, "excitation")) << r.out;
  // The same study with its parameters agreeing passes both.
  const CmdResult v2 = runExid({"validate", "good.yaml"}, dir);
  EXPECT_EQ(v2.code, 0) << v2.out;
  EXPECT_TRUE(contains(v2.out, "good.yaml: valid")) << v2.out;
  fs::remove_all(dir);
}

// A valid study still runs (the robot loaded by the check is the one the run uses).
TEST(Validation, AValidStudyStillRuns) {
  const fs::path dir = tempDir("valid");
  std::ofstream(dir / "s.yaml") << kPlanar
                                << "experiment: {type: simulate, params: {duration_s: 2}}\n"
                                   "estimator: {type: batch_ls}\nreport: {params: {plots: "
                                   "false}}\n";
  const CmdResult r = runExid({"-q", "run", "s.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(statusOf(dir / "out"), "ok");
  const exid::Json s = exid::Json::parse(slurp(dir / "out" / "summary.json"));
  ASSERT_NE(s.find("robot"), nullptr);
  EXPECT_EQ(s.find("robot")->find("dof")->asInt(), 2);
  fs::remove_all(dir);
}

// `exid validate` loads the robot: a xacro file or a broken URDF is refused (it passed), with the
// study's line and the loader's message; a loadable URDF passes.
TEST(Validation, ValidateLoadsTheRobot) {
  const fs::path dir = tempDir("robot");
  std::ofstream(dir / "arm.urdf.xacro")
      << "<?xml version=\"1.0\"?>\n<robot name=\"r\" "
         "xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n"
         "  <xacro:macro name=\"arm\" params=\"prefix\">\n"
         "    <link name=\"${prefix}base\"/>\n  </xacro:macro>\n  <xacro:arm prefix=\"\"/>\n"
         "</robot>\n";
  std::ofstream(dir / "broken.urdf") << "<robot name=\"r\"><link name=\"a\"/><joint name=\"j\" "
                                        "type=\"revolute\"><parent link=\"a\"/><child "
                                        "link=\"missing\"/></joint></robot>\n";
  const fs::path puma = fs::path(EXID_SOURCE_DIR) / "robots/puma560/puma560.urdf";
  auto study = [&](const std::string& file) {
    return "robot: {type: urdf, params: {file: '" + file +
           "'}}\nmodel: {type: differential}\nestimator: {type: batch_ls}\n"
           "experiment: {type: simulate, params: {duration_s: 2}}\n";
  };
  std::ofstream(dir / "xacro.yaml") << study("arm.urdf.xacro");
  std::ofstream(dir / "broken.yaml") << study("broken.urdf");
  std::ofstream(dir / "good.yaml") << study(puma.string());
  CmdResult r = runExid({"validate", "xacro.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "xacro.yaml:1: robot: ")) << r.out;
  EXPECT_TRUE(contains(r.out, "this is a xacro file")) << r.out;
  EXPECT_TRUE(contains(r.out, "expand it first: xacro ")) << r.out;
  r = runExid({"validate", "broken.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "broken.yaml:1: robot: ")) << r.out;
  EXPECT_TRUE(contains(r.out, "missing")) << r.out;
  EXPECT_FALSE(contains(r.out, "xacro")) << r.out;
  r = runExid({"validate", "good.yaml"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(contains(r.out, "xacro")) << r.out;
  fs::remove_all(dir);
}

// Every command that takes a robot file gives the xacro hint (robot info said "unknown robot");
// a URDF that xacro wrote (it keeps xmlns:xacro, no macros) is read as any URDF.
TEST(Validation, EveryCommandTakingARobotGivesTheXacroHint) {
  const fs::path dir = tempDir("robot_files");  // (no "xacro" in the path)
  const std::string macro =
      "<?xml version=\"1.0\"?>\n<robot name=\"r\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n"
      "  <xacro:macro name=\"arm\" params=\"prefix\">\n"
      "    <link name=\"${prefix}base\"/>\n  </xacro:macro>\n  <xacro:arm prefix=\"\"/>\n"
      "</robot>\n";
  std::ofstream(dir / "arm.urdf.xacro") << macro;
  // links beside an include: named .urdf, the macros give it away (its include was ignored)
  std::ofstream(dir / "mixed.urdf") << "<?xml version=\"1.0\"?>\n<robot name=\"r\" "
                                       "xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n"
                                       "  <xacro:include filename=\"more.xacro\"/>\n"
                                       "  <link name=\"base\"/>\n</robot>\n";
  // what xacro writes: the namespace kept, no macros
  const std::string puma = slurp(fs::path(EXID_SOURCE_DIR) / "robots/puma560/puma560.urdf");
  std::string expanded = puma;
  const auto root = expanded.find("<robot ");
  ASSERT_NE(root, std::string::npos);
  expanded.insert(root + 7, "xmlns:xacro=\"http://www.ros.org/wiki/xacro\" ");
  std::ofstream(dir / "expanded.urdf") << expanded;
  fs::create_directories(dir / "run");
  std::ofstream(dir / "run" / "summary.json")
      << "{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": [], "
         "\"values\": []}}}}\n";
  std::ofstream(dir / "samples.csv") << "q1,qd1,qdd1\n0,0,0\n";
  for (const std::string robot : {"arm.urdf.xacro", "mixed.urdf"}) {
    const std::vector<std::vector<std::string>> commands = {
        {"robot", "info", robot},
        {"eval", robot, "--samples", "samples.csv", "--what", "torque", "--out", "t.csv"},
        {"check-trajectory", robot, "samples.csv"},
        {"inspect", robot, "samples.csv"},
        {"export", robot, "--study", "run", "--out", "x.urdf"}};
    for (const auto& c : commands) {
      SCOPED_TRACE(c[0] + " " + robot);
      const CmdResult r = runExid(c, dir);
      EXPECT_EQ(r.code, 2) << r.out;
      EXPECT_TRUE(contains(r.out, "this is a xacro file")) << r.out;
      EXPECT_TRUE(contains(r.out, "expand it first: xacro " + robot + " > robot.urdf")) << r.out;
      EXPECT_FALSE(contains(r.out, "unknown robot")) << r.out;
    }
  }
  const CmdResult r = runExid({"robot", "info", "expanded.urdf"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(contains(r.out, "xacro")) << r.out;
  // A file that is no robot description at all is not an "unknown robot" plugin either.
  std::ofstream(dir / "arm.stl") << "solid arm\n";
  const CmdResult s = runExid({"robot", "info", "arm.stl"}, dir);
  EXPECT_EQ(s.code, 2) << s.out;
  EXPECT_TRUE(contains(s.out, "arm.stl: a file, but not a robot description")) << s.out;
  // An SDF file goes to the SDF loader, which says what is wrong with it.
  std::ofstream(dir / "arm.sdf") << "<sdf/>\n";
  const CmdResult f = runExid({"robot", "info", "arm.sdf"}, dir);
  EXPECT_EQ(f.code, 2) << f.out;
  EXPECT_TRUE(contains(f.out, "arm.sdf:1: <sdf> attribute 'version'")) << f.out;
  fs::remove_all(dir);
}

// A prior's std of 1e300 squares to infinity: it was reported as "zero variance" at the
// identification stage (from: robot) or accepted (from: study). Now: refused before anything
// runs, naming the study's line or parameters.csv's, and saying the std is too large.
TEST(Validation, APriorStdTooLargeIsRefusedNamingTheFileAndRow) {
  const fs::path dir = tempDir("prior");
  const std::string head = std::string(kPlanar) +
                           "experiment: {type: simulate, params: {duration_s: 2}}\n"
                           "estimator: {type: batch_ls}\nreport: {params: {plots: false}}\n";
  std::ofstream(dir / "earlier.yaml") << head;
  CmdResult r = runExid({"-q", "run", "earlier.yaml", "--out", "earlier"}, dir);
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string params = slurp(dir / "earlier" / "parameters.csv");

  std::ofstream(dir / "robot_huge.yaml")
      << head << "prior: {from: robot, relative_std: 0.1, absolute_std: 1e300}\n";
  r = runExid({"validate", "robot_huge.yaml"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "robot_huge.yaml:6: prior.absolute_std = 1e300: too large")) << r.out;
  EXPECT_FALSE(contains(r.out, "zero variance")) << r.out;
  r = runExid({"run", "robot_huge.yaml", "--out", "o1"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_FALSE(fs::exists(dir / "o1"));

  // parameters.csv with its second row's std 1e300
  fs::create_directories(dir / "huge");
  {
    std::istringstream in(params);
    std::ofstream out(dir / "huge" / "parameters.csv");
    std::string line;
    int n = 0;
    while (std::getline(in, line)) {
      if (++n == 3) {  // name,index,value,std,...: the std replaced
        std::vector<std::string> cells;
        std::istringstream cs(line);
        for (std::string c; std::getline(cs, c, ',');) cells.push_back(c);
        ASSERT_GT(cells.size(), 3u);
        cells[3] = "1e300";
        line.clear();
        for (std::size_t i = 0; i < cells.size(); ++i) line += (i ? "," : "") + cells[i];
      }
      out << line << "\n";
    }
  }
  ASSERT_TRUE(contains(slurp(dir / "huge" / "parameters.csv"), ",1e300,"));
  std::ofstream(dir / "study_huge.yaml") << head << "prior: {from: study, study: huge}\n";
  r = runExid({"run", "study_huge.yaml", "--out", "o2"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "study_huge.yaml:6: prior: ")) << r.out;
  EXPECT_TRUE(contains(r.out, "parameters.csv:3: ")) << r.out;
  EXPECT_TRUE(contains(r.out, "too large to be used as a prior")) << r.out;
  EXPECT_FALSE(contains(r.out, "zero variance")) << r.out;
  EXPECT_FALSE(fs::exists(dir / "o2"));

  // must not: a wide but usable std, from the robot and from the earlier study
  std::ofstream(dir / "robot_wide.yaml")
      << head << "prior: {from: robot, relative_std: 0.1, absolute_std: 1e3}\n";
  r = runExid({"-q", "run", "robot_wide.yaml", "--out", "o3"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  std::ofstream(dir / "study_ok.yaml") << head << "prior: {from: study, study: earlier}\n";
  r = runExid({"-q", "run", "study_ok.yaml", "--out", "o4"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(contains(r.out, "too large")) << r.out;
  fs::remove_all(dir);
}

// varpro's delay bound of 1e300 s formatted an overflowed integer ("-2147483648 without rows");
// now the bound as given, and a failed stage (exit 1), never exit 3.
TEST(Validation, VarproHugeDelayBoundIsReportedWithoutOverflow) {
  const fs::path dir = tempDir("varpro");
  std::ofstream(dir / "s.yaml") << kPlanar
                                << "experiment: {type: simulate, params: {duration_s: 2}}\n"
                                   "estimator: {type: varpro, params: {measurement_delay: true, "
                                   "measurement_delay_max_s: 1e300}}\n"
                                   "report: {params: {plots: false}}\n";
  CmdResult r = runExid({"run", "s.yaml", "--out", "out"}, dir);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "measurement_delay_max_s = 1e+300 s leaves 0 of")) << r.out;
  EXPECT_FALSE(contains(r.out, "2147483")) << r.out;
  EXPECT_FALSE(contains(r.out, "-9223372")) << r.out;
  EXPECT_FALSE(contains(r.out, "unexpected error")) << r.out;
  // must not: a bound the recording allows
  std::ofstream(dir / "t.yaml") << kPlanar
                                << "experiment: {type: simulate, params: {duration_s: 2}}\n"
                                   "estimator: {type: varpro, params: {measurement_delay: true, "
                                   "measurement_delay_max_s: 0.01}}\n"
                                   "report: {params: {plots: false}}\n";
  r = runExid({"-q", "run", "t.yaml", "--out", "out2"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(contains(r.out, "leaves")) << r.out;
  fs::remove_all(dir);
}

// --out naming a symbolic link to a folder: the link was replaced by a folder. Now the results
// go into the link's target and the link stays; a dangling link is refused, nothing written.
TEST(Validation, OutThroughASymbolicLinkWritesIntoItsTarget) {
  const fs::path dir = tempDir("symlink");
  std::ofstream(dir / "s.yaml") << kPlanar
                                << "experiment: {type: simulate, params: {duration_s: 2}}\n"
                                   "estimator: {type: batch_ls}\nreport: {params: {plots: "
                                   "false}}\n";
  fs::create_directories(dir / "store" / "real");
  fs::create_directory_symlink("store/real", dir / "link");
  for (int i = 0; i < 2; ++i) {  // into the empty target, then over the earlier run
    SCOPED_TRACE(i);
    const CmdResult r = runExid({"-q", "run", "s.yaml", "--out", "link"}, dir);
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(fs::is_symlink(dir / "link"));
    EXPECT_EQ(fs::read_symlink(dir / "link"), fs::path("store/real"));
    EXPECT_EQ(statusOf(dir / "store" / "real"), "ok");
    EXPECT_TRUE(fs::exists(dir / "store" / "real" / "parameters.csv"));
  }
  for (const auto& e : fs::directory_iterator(dir))  // no staging folder left beside the link
    EXPECT_FALSE(contains(e.path().filename().string(), "staging")) << e.path();
  for (const auto& e : fs::directory_iterator(dir / "store"))
    EXPECT_FALSE(contains(e.path().filename().string(), "staging")) << e.path();

  fs::create_directory_symlink("missing_folder", dir / "dangling");
  const CmdResult r = runExid({"-q", "run", "s.yaml", "--out", "dangling"}, dir);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.code, 3) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "--out dangling: a symbolic link to missing_folder, which does not "
                       "exist"))
      << r.out;
  EXPECT_TRUE(fs::is_symlink(dir / "dangling"));
  EXPECT_FALSE(fs::exists(dir / "missing_folder"));
  fs::remove_all(dir);
}

// A drive parameter name with more digits than an int holds in an identified summary.json
// (exid export): std::stoi threw out of range, "unexpected error", exit 3. Now: not a joint of
// the robot, ignored by name like any other.
TEST(Validation, ExportOfAParameterNameBeyondAnIntIsNoInternalError) {
  const fs::path dir = tempDir("export");
  fs::create_directories(dir / "run");
  std::ofstream(dir / "run" / "summary.json")
      << "{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": "
         "[\"Fc99999999999\", \"Fv1\"], \"values\": [1.0, 0.5]}}}}\n";
  const CmdResult r = runExid({"export", "planar2r", "--study", "run", "--out", "x.urdf"}, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(contains(r.out, "unexpected error")) << r.out;
  EXPECT_TRUE(contains(r.out, "1 identified parameters written")) << r.out;
  EXPECT_TRUE(contains(r.out, "not part of the robot, ignored: Fc99999999999")) << r.out;
  // A damaged summary.json is named (JSON's message gave only an offset; a value that is no
  // number was "Json: not a number", a null one NaN written into the URDF).
  for (const std::string& text :
       {std::string("{\"identification\": [1,"),
        std::string("{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": "
                    "[\"Fv1\"], \"values\": [\"x\"]}}}}"),
        std::string("{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": "
                    "[\"Fv1\"], \"values\": [null]}}}}")}) {
    SCOPED_TRACE(text);
    std::ofstream(dir / "run" / "summary.json") << text << "\n";
    const CmdResult b = runExid({"export", "planar2r", "--study", "run", "--out", "y.urdf"}, dir);
    EXPECT_EQ(b.code, 2) << b.out;
    EXPECT_TRUE(contains(b.out, "exid: run/summary.json: ")) << b.out;
    EXPECT_FALSE(fs::exists(dir / "y.urdf"));
  }
  fs::remove_all(dir);
}
