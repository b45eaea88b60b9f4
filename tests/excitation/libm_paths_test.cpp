// A design study gives the same bits whichever variants of sin, cos, exp, log glibc's libm picks
// for the CPU (docs/excitation.md §6): the Panda benchmark study (two starts, 1000 evaluations)
// run by the exid program twice, once as the machine is and once with glibc's FMA/AVX2 code paths
// switched off (GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX,-FMA4), must write the same
// trajectory byte for byte and report the same criterion value. Before exid evaluated its own
// sin/cos/exp/log (exid/fmath.hpp) the two runs parted at the last bits and ended in other basins.
// The same for the Panda beside a table (torque limits, self-collision, a table: the collision
// layer's joint rotations, FCL's distances), as shipped. On a CPU without FMA the two runs take
// the same libm paths and the tests show nothing (they say so).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "exid_cli.hpp"
#include "exid_test.hpp"

namespace {

namespace fs = std::filesystem;

bool cpuHasFma() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("flags", 0) == 0) return line.find(" fma") != std::string::npos;
  return false;
}

// the value of "key": in summary.json, as written (17 significant digits)
std::string jsonNumber(const std::string& text, const std::string& key) {
  const auto at = text.find("\"" + key + "\"");
  if (at == std::string::npos) return {};
  auto b = text.find(':', at) + 1;
  while (b < text.size() && text[b] == ' ') ++b;
  auto e = text.find_first_of(",}\n", b);
  return text.substr(b, e - b);
}

struct StudyRun {
  std::string trajectory, criterion, evaluations, log;
  int code = -1;
};

StudyRun runStudy(const fs::path& study, const fs::path& out, const std::string& env) {
  StudyRun r;
  const std::string cmd = "env " + env + " " + std::string(EXID_EXE) + " excite " + study.string() +
                          " --out " + out.string() + " -q 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  char buf[4096];
  while (p && std::fgets(buf, sizeof buf, p)) r.log += buf;
  const int status = p ? ::pclose(p) : -1;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.trajectory = exid_cli::slurp(out / "trajectory_optimal.csv");
  const std::string summary = exid_cli::slurp(out / "summary.json");
  r.criterion = jsonNumber(summary, "criterion_final");
  r.evaluations = jsonNumber(summary, "evaluations");
  return r;
}

TEST(LibmPaths, PandaDesignIsBitIdenticalWithGlibcFmaPathsOnAndOff) {
  const fs::path dir = exid_cli::freshTempDir("exid_libm_paths_", "panda");
  std::string yaml = exid_cli::slurp(exid_test::sourceDir() / "examples/bench/panda_fourier.yaml");
  const std::string shipped = "starts: 40, max_evaluations: 8000";
  const auto at = yaml.find(shipped);
  ASSERT_NE(at, std::string::npos) << "the Panda study's optimiser budget moved";
  yaml.replace(at, shipped.size(), "starts: 2, start_evaluations: 300, max_evaluations: 1000");
  std::ofstream(dir / "panda.yaml") << yaml;
  if (!cpuHasFma())
    std::cout << "[libm paths] this CPU has no FMA: both runs take glibc's baseline paths\n";
  const StudyRun on = runStudy(dir / "panda.yaml", dir / "on", "-u GLIBC_TUNABLES");
  const StudyRun off = runStudy(dir / "panda.yaml", dir / "off",
                                "GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX,-FMA4");
  ASSERT_EQ(on.code, 0) << on.log;
  ASSERT_EQ(off.code, 0) << off.log;
  ASSERT_FALSE(on.trajectory.empty());
  ASSERT_FALSE(on.criterion.empty());
  std::cout << "[libm paths] cond(W) " << on.criterion << " in " << on.evaluations
            << " evaluations (glibc as the CPU allows); " << off.criterion << " in "
            << off.evaluations << " (FMA/AVX2 paths off)\n";
  EXPECT_EQ(on.criterion, off.criterion);
  EXPECT_EQ(on.evaluations, off.evaluations);
  EXPECT_TRUE(on.trajectory == off.trajectory)
      << "the designed trajectories differ between glibc's libm paths";
}

TEST(LibmPaths, PandaTableDesignIsBitIdenticalWithGlibcFmaPathsOnAndOff) {
  const fs::path dir = exid_cli::freshTempDir("exid_libm_paths_", "table");
  const fs::path study = exid_test::sourceDir() / "examples/bench/panda_fourier_table.yaml";
  if (!cpuHasFma())
    std::cout << "[libm paths] this CPU has no FMA: both runs take glibc's baseline paths\n";
  const StudyRun on = runStudy(study, dir / "on", "-u GLIBC_TUNABLES");
  const StudyRun off =
      runStudy(study, dir / "off", "GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX,-FMA4");
  ASSERT_EQ(on.code, 0) << on.log;
  ASSERT_EQ(off.code, 0) << off.log;
  ASSERT_FALSE(on.trajectory.empty());
  std::cout << "[libm paths] table: cond(W) " << on.criterion << " in " << on.evaluations
            << " evaluations (glibc as the CPU allows); " << off.criterion << " in "
            << off.evaluations << " (FMA/AVX2 paths off)\n";
  EXPECT_EQ(on.criterion, off.criterion);
  EXPECT_EQ(on.evaluations, off.evaluations);
  EXPECT_TRUE(on.trajectory == off.trajectory)
      << "the designed trajectories differ between glibc's libm paths";
}

}  // namespace
