// `exid export --format urdf|mjcf|sdf`: the format from --format or the extension of --out
// (contradicting: refused, nothing written), what a format leaves out printed as notes, and
// physically inconsistent identified parameters refused by every format with the same message.
// The exid program runs as a child process.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "robustness.hpp"

namespace {

using robustness::contains;
using robustness::runExid;
using robustness::slurp;

fs::path studyWith(const std::string& name, const std::string& names, const std::string& values) {
  const fs::path dir = robustness::tempDir(name);
  fs::create_directories(dir / "run");
  std::ofstream(dir / "run" / "summary.json")
      << "{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": [" << names
      << "], \"values\": [" << values << "]}}}}\n";
  return dir;
}

TEST(ExportFormat, FormatFromOptionOrExtension) {
  const fs::path dir = studyWith("export_format", "\"Fv1\", \"OFF1\"", "0.5, 0.25");
  struct Case {
    std::vector<std::string> args;
    std::string file, format, start;
  };
  const std::vector<Case> cases = {
      {{"--out", "a.urdf"}, "a.urdf", "URDF", "<robot name=\"planar2r_identified\">"},
      {{"--out", "a.mjcf"}, "a.mjcf", "MJCF", "<mujoco model=\"planar2r_identified\">"},
      {{"--out", "a.sdf"}, "a.sdf", "SDF", "<sdf version=\"1.9\">"},
      {{"--out", "b.xml", "--format", "mjcf"}, "b.xml", "MJCF", "<mujoco model="},
      {{"--out", "c.SDF", "--format", "sdf"}, "c.SDF", "SDF", "<sdf version="},
      {{"--out", "d.xml"}, "d.xml", "URDF", "<robot name="}};  // (the default)
  for (const auto& c : cases) {
    SCOPED_TRACE(c.file);
    std::vector<std::string> args = {"export", "planar2r", "--study", "run"};
    args.insert(args.end(), c.args.begin(), c.args.end());
    const auto r = runExid(args, dir);
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(contains(r.out, c.file + ": planar2r_identified (" + c.format +
                                    ", 2 joints), 2 "
                                    "identified "
                                    "parameters "
                                    "written"))
        << r.out;
    EXPECT_TRUE(contains(slurp(dir / c.file), c.start));
    // What the format cannot carry is said, never dropped silently: the drive's offset, the
    // acceleration limits (URDF carries both in its <exid> element).
    const bool urdf = c.format == "URDF";
    EXPECT_EQ(contains(r.out, "note: not carried by " + c.format +
                                  ": drive torque offsets OFF (coordinates 1)"),
              !urdf)
        << r.out;
    EXPECT_EQ(contains(r.out, "acceleration limits (joints 1, 2)"), !urdf) << r.out;
    EXPECT_EQ(contains(r.out, "MuJoCo's minimum 1e-15"), c.format == "MJCF") << r.out;
    EXPECT_EQ(contains(r.out, "note:"), !urdf) << r.out;
  }
  fs::remove_all(dir);
}

TEST(ExportFormat, ContradictingOrUnknownFormatIsRefused) {
  const fs::path dir = studyWith("export_contradiction", "\"Fv1\"", "0.5");
  auto r =
      runExid({"export", "planar2r", "--study", "run", "--out", "a.urdf", "--format", "mjcf"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out,
                       "--out a.urdf: the extension .urdf says urdf, but --format says mjcf; "
                       "give a matching extension or leave --format out"))
      << r.out;
  EXPECT_FALSE(fs::exists(dir / "a.urdf"));
  r = runExid({"export", "planar2r", "--study", "run", "--out", "a.sdf", "--format", "urdf"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "the extension .sdf says sdf, but --format says urdf")) << r.out;
  EXPECT_FALSE(fs::exists(dir / "a.sdf"));
  r = runExid({"export", "planar2r", "--study", "run", "--out", "a.obj", "--format", "obj"}, dir);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_TRUE(contains(r.out, "--format obj: expected urdf, mjcf (MuJoCo) or sdf (SDFormat)"))
      << r.out;
  EXPECT_FALSE(fs::exists(dir / "a.obj"));
  fs::remove_all(dir);
}

TEST(ExportFormat, InconsistentParametersAreRefusedByEveryFormat) {
  struct Case {
    std::string names, values, rule;
  };
  for (const Case& k : {Case{"\"M1\"", "-1.0", "body 1 ('link1'): negative mass"},
                        Case{"\"ZZ2\"", "100.0",
                             "body 2 ('link2'): triangle inequality violated (principal moments: "
                             "I1 + I2 >= I3)"}}) {
    const fs::path dir = studyWith("export_inconsistent", k.names, k.values);
    for (const std::string format : {"urdf", "mjcf", "sdf"}) {
      SCOPED_TRACE(format + " " + k.names);
      const std::string out = "x." + format;
      const auto r = runExid({"export", "planar2r", "--study", "run", "--out", out}, dir);
      EXPECT_EQ(r.code, 2) << r.out;
      std::string name = format;
      for (auto& ch : name) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
      EXPECT_TRUE(contains(r.out, k.rule +
                                      "; the identified parameters are not physically "
                                      "consistent and cannot be written as " +
                                      name))
          << r.out;
      EXPECT_FALSE(fs::exists(dir / out));
    }
    fs::remove_all(dir);
  }
}

}  // namespace
