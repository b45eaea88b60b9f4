// Real data: the Staubli TX40 recording (../shared/data/staubli_tx40, FIGAROH) identified by
// examples/real/tx40_{filtered_ls,wls,consistent_ls,consistent_ls_cv}.yaml and validated on the
// held-out segment 6 - 7.6 s.
// A regression guard: the bounds are the errors measured when the studies were written
// (docs/real_data.md) plus about 15 %. Skipped when the data folder is absent.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include "exid/json.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

fs::path dataDir() { return exid_test::sharedDir() / "data/staubli_tx40"; }

struct Run {
  int code = -1;
  std::string out;
  exid::Json summary;
};

Run runStudy(const std::string& study) {
  const fs::path out =
      fs::temp_directory_path() / ("exid_real_" + study + "_" + std::to_string(::getpid()));
  fs::remove_all(out);
  const std::string cmd = std::string(EXID_EXE) + " -q run " +
                          (exid_test::sourceDir() / "examples/real" / (study + ".yaml")).string() +
                          " --out " + out.string() + " 2>&1";
  Run r;
  FILE* p = ::popen(cmd.c_str(), "r");
  std::array<char, 4096> buf{};
  while (p && std::fgets(buf.data(), buf.size(), p)) r.out += buf.data();
  const int status = p ? ::pclose(p) : -1;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(out / "summary.json");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!text.empty()) r.summary = exid::Json::parse(text);
  fs::remove_all(out);
  return r;
}

std::map<std::string, std::pair<double, double>> params(const exid::Json& s) {
  std::map<std::string, std::pair<double, double>> m;
  const exid::Json& ps = *s.find("identification")->find("parameters");
  for (std::size_t i = 0; i < ps.size(); ++i)
    m[ps.at(i).find("name")->asString()] = {ps.at(i).find("value")->asDouble(),
                                            ps.at(i).find("std")->asDouble()};
  return m;
}

void check(const std::string& study, const std::array<double, 6>& bound, double bound_all) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"))
      << "no data in " << dataDir() << " (../shared/data beside the repository)";
  const Run r = runStudy(study);
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json& s = r.summary;
  EXPECT_EQ(s.find("robot")->find("n_base_parameters")->asInt(), 58);
  const exid::Json& v = *s.find("validation");
  const exid::Json& rel = *v.find("relative_error_per_joint");
  ASSERT_EQ(rel.size(), 6u);
  for (std::size_t j = 0; j < 6; ++j) {
    EXPECT_LT(rel.at(j).asDouble(), bound[j]) << study << ": joint " << j + 1;
    std::printf("%s: joint %zu validation relative error %.4f (bound %.2f)\n", study.c_str(), j + 1,
                rel.at(j).asDouble(), bound[j]);
  }
  EXPECT_LT(v.find("relative_error")->asDouble(), bound_all) << study;
  // Well-identified rigid-body base parameters agree with FIGAROH's OLS values
  // (results/TX40_bp_5.csv; same regrouping) within 2.5 combined standard deviations.
  const auto p = params(s);
  const std::map<std::string, std::pair<double, double>> figaroh = {
      {"ZZ1R", {1.247943, 0.0098}}, {"XX2R", {-0.46452, 0.0218}}, {"XZ2R", {-0.157168, 0.0336}},
      {"ZZ2R", {1.07996, 0.0084}},  {"MX2R", {2.241472, 0.0191}}, {"MY3R", {-0.592391, 0.0206}}};
  for (const auto& [name, ref] : figaroh) {
    ASSERT_TRUE(p.count(name)) << name;
    const auto [value, std] = p.at(name);
    const double comb = std::hypot(std, std::abs(ref.first) * ref.second);
    EXPECT_LT(std::abs(value - ref.first), 2.5 * comb)
        << study << ": " << name << " = " << value << " vs " << ref.first;
  }
}

}  // namespace

// Measured (2025, this commit): filtered_ls 0.0857 0.0745 0.1406 0.1568 0.2200 0.2156, all 0.0893.
TEST(RealTx40, FilteredLsValidatesOnTheHeldOutSegment) {
  check("tx40_filtered_ls", {0.10, 0.09, 0.17, 0.18, 0.25, 0.25}, 0.105);
}

// Measured: wls 0.0877 0.0774 0.1456 0.1544 0.2211 0.2127, all 0.0916.
TEST(RealTx40, WlsValidatesOnTheHeldOutSegment) {
  check("tx40_wls", {0.10, 0.09, 0.17, 0.18, 0.25, 0.25}, 0.105);
}

// Physically consistent identification with the CAD prior (examples/real/tx40_consistent_ls.yaml,
// docs/consistent.md) against wls on the held-out segment. Measured: consistent_ls + prior
// 0.0857 0.0786 0.1463 0.1486 0.2139 0.2088, all 0.0909; wls 0.0877 0.0774 0.1456 0.1544 0.2211
// 0.2127, all 0.0916: better overall and on joints 1, 4, 5, 6; joints 2 and 3 slightly worse
// (+0.0012, +0.0007), so only overall and joints 4-6 are asserted.
TEST(RealTx40, ConsistentLsWithCadPriorPredictsAtLeastAsWellAsWls) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"))
      << "no data in " << dataDir() << " (../shared/data beside the repository)";
  const ::Run w = runStudy("tx40_wls");
  const ::Run c = runStudy("tx40_consistent_ls");
  ASSERT_EQ(w.code, 0) << w.out;
  ASSERT_EQ(c.code, 0) << c.out;
  const exid::Json& I = *c.summary.find("identification");
  EXPECT_EQ(c.summary.find("robot")->find("n_base_parameters")->asInt(), 58);
  const exid::Json& d = *I.find("details");
  EXPECT_TRUE(d.find("consistent")->asBool());
  const exid::Json& bodies = *d.find("bodies");
  ASSERT_EQ(bodies.size(), 6u);
  for (std::size_t b = 0; b < 6; ++b)
    EXPECT_EQ(bodies.at(b).find("check")->asString(), "ok") << "body " << b + 1;
  const exid::Json& rw = *w.summary.find("validation")->find("relative_error_per_joint");
  const exid::Json& rc = *c.summary.find("validation")->find("relative_error_per_joint");
  const double aw = w.summary.find("validation")->find("relative_error")->asDouble();
  const double ac = c.summary.find("validation")->find("relative_error")->asDouble();
  for (std::size_t j = 0; j < 6; ++j)
    std::printf("joint %zu: wls %.4f  consistent_ls + CAD prior %.4f\n", j + 1, rw.at(j).asDouble(),
                rc.at(j).asDouble());
  std::printf(
      "all: wls %.4f  consistent_ls + CAD prior %.4f; residual rms ratio %.4f, Mahalanobis %.3g\n",
      aw, ac, d.find("residual_rms_ratio")->asDouble(),
      d.find("mahalanobis_from_unconstrained")->asDouble());
  EXPECT_LE(ac, aw);
  for (std::size_t j = 3; j < 6; ++j)
    EXPECT_LT(rc.at(j).asDouble(), rw.at(j).asDouble()) << "joint " << j + 1;
  const std::array<double, 6> bound = {0.10, 0.09, 0.17, 0.18, 0.25, 0.25};
  for (std::size_t j = 0; j < 6; ++j) EXPECT_LT(rc.at(j).asDouble(), bound[j]) << "joint " << j + 1;
}

// The same with the prior's scale chosen by blocked cross-validation on the identification part
// (examples/real/tx40_consistent_ls_cv.yaml, docs/consistent.md "Prior scale"). Measured: scale
// 0.316; consistent_ls 0.0841 0.0778 0.1441 0.1456 0.2128 0.2084, all 0.0897 (wls 0.0877 0.0774
// 0.1456 0.1544 0.2211 0.2127, all 0.0916). Asserted: the identification data ask for a tighter
// prior than stated (scale < 1; every block count from 3 to 10 selects 0.02 - 0.42), overall and
// joints 4-6 better than wls. Joint 3 is printed, not asserted: it beats wls with 5 blocks
// (0.1441 < 0.1456) but not with 3, 4, 6, 8 or 10 (selected scales 0.056 - 0.1, joint 3 0.1466 -
// 0.1473), nor with the cross-validation error pooled over those block counts (scale 0.075) --
// the margin is smaller than the spread of equally justified selections (docs/real_data.md).
TEST(RealTx40, ConsistentLsWithCrossValidatedPriorScale) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"))
      << "no data in " << dataDir() << " (../shared/data beside the repository)";
  const ::Run w = runStudy("tx40_wls");
  const ::Run c = runStudy("tx40_consistent_ls_cv");
  ASSERT_EQ(w.code, 0) << w.out;
  ASSERT_EQ(c.code, 0) << c.out;
  const exid::Json& d = *c.summary.find("identification")->find("details");
  EXPECT_TRUE(d.find("consistent")->asBool());
  const exid::Json& sc = *d.find("prior")->find("scale");
  EXPECT_EQ(sc.find("method")->asString(), "cv");
  const double scale = sc.find("scale")->asDouble();
  EXPECT_LT(scale, 1.0);
  EXPECT_GE(scale, 0.01);
  // the criterion is reported over the whole grid and its minimum is the selected scale
  const exid::Json& grid = *sc.find("grid");
  const exid::Json& cv = *sc.find("cv_error");
  ASSERT_EQ(grid.size(), cv.size());
  std::size_t at = cv.size();
  for (std::size_t i = 0; i < cv.size(); ++i)
    if (grid.at(i).asDouble() == scale) at = i;
  ASSERT_LT(at, cv.size()) << "the selected scale is not on the grid";
  for (std::size_t k = 0; k < cv.size(); ++k)
    EXPECT_LE(cv.at(at).asDouble(), cv.at(k).asDouble()) << "grid " << k;
  const exid::Json& rw = *w.summary.find("validation")->find("relative_error_per_joint");
  const exid::Json& rc = *c.summary.find("validation")->find("relative_error_per_joint");
  const double aw = w.summary.find("validation")->find("relative_error")->asDouble();
  const double ac = c.summary.find("validation")->find("relative_error")->asDouble();
  for (std::size_t j = 0; j < 6; ++j)
    std::printf("joint %zu: wls %.4f  consistent_ls + CAD prior x %.3g (cv) %.4f\n", j + 1,
                rw.at(j).asDouble(), scale, rc.at(j).asDouble());
  std::printf("all: wls %.4f  consistent_ls + CAD prior x %.3g (cv) %.4f\n", aw, scale, ac);
  EXPECT_LE(ac, aw);
  for (std::size_t j = 3; j < 6; ++j)
    EXPECT_LT(rc.at(j).asDouble(), rw.at(j).asDouble()) << "joint " << j + 1;
}
