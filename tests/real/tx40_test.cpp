// Real data: the Staubli TX40 recording (data/staubli_tx40, FIGAROH) identified by
// examples/real/tx40_{filtered_ls,wls,consistent_ls,consistent_ls_cv}.yaml and validated on the
// held-out segment 6 - 7.6 s.
// A regression guard: the bounds are the errors measured when the studies were written
// (docs/real_data.md) plus about 15 %.
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

fs::path dataDir() { return exid_test::dataDir() / "staubli_tx40"; }

struct Run {
  int code = -1;
  std::string out;
  exid::Json summary;
};

Run runStudyFile(const fs::path& file, const std::string& tag) {
  const fs::path out =
      fs::temp_directory_path() / ("exid_real_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(out);
  const std::string cmd =
      std::string(EXID_EXE) + " -q run " + file.string() + " --out " + out.string() + " 2>&1";
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

Run runStudy(const std::string& study) {
  return runStudyFile(exid_test::sourceDir() / "examples/real" / (study + ".yaml"), study);
}

/// A variant of examples/real/STUDY.yaml: `from` replaced by `to` (which must occur), relative
/// paths made absolute, written to a temporary folder and run.
Run runVariant(const std::string& study, const std::string& from, const std::string& to) {
  const fs::path src = exid_test::sourceDir() / "examples/real" / (study + ".yaml");
  std::ifstream in(src);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::size_t at = text.find(from);
  if (at == std::string::npos) return Run{-1, "'" + from + "' not in " + src.string(), {}};
  text.replace(at, from.size(), to);
  const std::string rel = " ../../", abs = " " + (src.parent_path() / "../../").string();
  for (std::size_t p = text.find(rel); p != std::string::npos; p = text.find(rel, p + abs.size()))
    text.replace(p, rel.size(), abs);
  const std::string tag = study + "_variant";
  const fs::path file =
      fs::temp_directory_path() / ("exid_real_" + tag + "_" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(file) << text;
  Run r = runStudyFile(file, tag);
  fs::remove(file);
  return r;
}

/// The bodies of a consistent_ls estimate near the URDF's CAD masses (tx40_mdh_modified.urdf,
/// links 1-6: 10.5, 3.6, 4.07, 3.62, 1.02, 0.2 kg): within a factor 2, centres of mass within
/// 0.3 m of their link frame.
void expectPlausibleBodies(const exid::Json& details) {
  const std::array<double, 6> cad = {10.5, 3.6, 4.07, 3.62, 1.02, 0.2};
  const exid::Json& bodies = *details.find("bodies");
  ASSERT_EQ(bodies.size(), 6u);
  for (std::size_t b = 0; b < 6; ++b) {
    const double m = bodies.at(b).find("mass")->asDouble();
    const exid::Json& c = *bodies.at(b).find("com");
    const double r = std::sqrt(std::pow(c.at(0).asDouble(), 2) + std::pow(c.at(1).asDouble(), 2) +
                               std::pow(c.at(2).asDouble(), 2));
    std::printf("body %zu: mass %.3f kg (CAD %.3g), |com| %.3f m\n", b + 1, m, cad[b], r);
    EXPECT_GT(m, 0.5 * cad[b]) << "body " << b + 1;
    EXPECT_LT(m, 2.0 * cad[b]) << "body " << b + 1;
    EXPECT_LT(r, 0.3) << "body " << b + 1;
  }
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
      << "no data in " << dataDir() << " (data/staubli_tx40, shipped in the repository)";
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
// docs/consistent.md) against wls on the held-out segment. The prior (as stated, scale 1) acts on
// the standard parameters inside the consistent fit; the drive values are left to the data.
// Measured: consistent_ls 0.0845 0.0788 0.1447 0.1493 0.2139 0.2084, all 0.0904; wls 0.0877
// 0.0774 0.1456 0.1544 0.2211 0.2127, all 0.0916: better overall and on joints 1, 3, 4, 5, 6.
// Asserted: overall, joints 3-6, consistent and plausible bodies (CAD masses within a factor 2).
TEST(RealTx40, ConsistentLsWithCadPriorPredictsAtLeastAsWellAsWls) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"))
      << "no data in " << dataDir() << " (data/staubli_tx40, shipped in the repository)";
  const ::Run w = runStudy("tx40_wls");
  const ::Run c = runStudy("tx40_consistent_ls");
  ASSERT_EQ(w.code, 0) << w.out;
  ASSERT_EQ(c.code, 0) << c.out;
  const exid::Json& I = *c.summary.find("identification");
  EXPECT_EQ(c.summary.find("robot")->find("n_base_parameters")->asInt(), 58);
  const exid::Json& d = *I.find("details");
  EXPECT_TRUE(d.find("consistent")->asBool());
  EXPECT_EQ(d.find("prior")->find("on")->asString(), "standard");
  const exid::Json& bodies = *d.find("bodies");
  ASSERT_EQ(bodies.size(), 6u);
  for (std::size_t b = 0; b < 6; ++b)
    EXPECT_EQ(bodies.at(b).find("check")->asString(), "ok") << "body " << b + 1;
  expectPlausibleBodies(d);
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
  for (std::size_t j = 2; j < 6; ++j)
    EXPECT_LT(rc.at(j).asDouble(), rw.at(j).asDouble()) << "joint " << j + 1;
  const std::array<double, 6> bound = {0.10, 0.09, 0.17, 0.18, 0.25, 0.25};
  for (std::size_t j = 0; j < 6; ++j) EXPECT_LT(rc.at(j).asDouble(), bound[j]) << "joint " << j + 1;
}

// The same with the prior's scale chosen by blocked cross-validation on the identification part
// (examples/real/tx40_consistent_ls_cv.yaml, docs/consistent.md "Prior scale"). Measured: scale
// 0.42; consistent_ls 0.0843 0.0778 0.1431 0.1482 0.2149 0.2080, all 0.0898 (wls 0.0877 0.0774
// 0.1456 0.1544 0.2211 0.2127, all 0.0916). Asserted: scale < 1 at the minimum of the reported
// curve, overall and joints 3-6 better than wls, plausible bodies.
TEST(RealTx40, ConsistentLsWithCrossValidatedPriorScale) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"))
      << "no data in " << dataDir() << " (data/staubli_tx40, shipped in the repository)";
  const ::Run w = runStudy("tx40_wls");
  const ::Run c = runStudy("tx40_consistent_ls_cv");
  ASSERT_EQ(w.code, 0) << w.out;
  ASSERT_EQ(c.code, 0) << c.out;
  const exid::Json& d = *c.summary.find("identification")->find("details");
  EXPECT_TRUE(d.find("consistent")->asBool());
  expectPlausibleBodies(d);
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
  for (std::size_t j = 2; j < 6; ++j)
    EXPECT_LT(rc.at(j).asDouble(), rw.at(j).asDouble()) << "joint " << j + 1;
}

// The win over wls must not hang on an arbitrary choice: with 3, 4, 6, 8 or 10 cross-validation
// blocks (the study uses 5) the selected scale is 0.18 - 0.42 and joints 3-6 and the whole
// held-out segment are still predicted better than by wls. Measured joint 3: 0.1424 - 0.1431
// (wls 0.1456).
TEST(RealTx40, ConsistentLsWinOverWlsHoldsForEveryCrossValidationBlockCount) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"))
      << "no data in " << dataDir() << " (data/staubli_tx40, shipped in the repository)";
  const ::Run w = runStudy("tx40_wls");
  ASSERT_EQ(w.code, 0) << w.out;
  const exid::Json& rw = *w.summary.find("validation")->find("relative_error_per_joint");
  const double aw = w.summary.find("validation")->find("relative_error")->asDouble();
  for (int blocks : {3, 4, 6, 8, 10}) {
    SCOPED_TRACE(blocks);
    const ::Run c =
        runVariant("tx40_consistent_ls_cv", "cv_blocks: 5", "cv_blocks: " + std::to_string(blocks));
    ASSERT_EQ(c.code, 0) << c.out;
    const exid::Json& d = *c.summary.find("identification")->find("details");
    EXPECT_TRUE(d.find("consistent")->asBool());
    const exid::Json& rc = *c.summary.find("validation")->find("relative_error_per_joint");
    const double ac = c.summary.find("validation")->find("relative_error")->asDouble();
    std::printf("%2d blocks: scale %.3g, joints 3-6 %.4f %.4f %.4f %.4f, all %.4f\n", blocks,
                d.find("prior")->find("scale")->find("scale")->asDouble(), rc.at(2).asDouble(),
                rc.at(3).asDouble(), rc.at(4).asDouble(), rc.at(5).asDouble(), ac);
    EXPECT_LE(ac, aw);
    for (std::size_t j = 2; j < 6; ++j)
      EXPECT_LT(rc.at(j).asDouble(), rw.at(j).asDouble()) << "joint " << j + 1;
  }
}

// The data's documented facts and every processing default (examples/real/tx40_defaults.yaml:
// filtered_ls with its defaults, one `split` key) against the best tuned study on the same split
// and the same held-out error definition: consistent_ls with the CAD prior on q and tau
// low-passed at 25 Hz (examples/real/tx40_consistent_split.yaml, tx40_consistent_ls.yaml's
// processing on the split). Measured: defaults
// 0.0970, tuned 0.0903 (the defaults 7.4 % worse; filtered_ls tuned at 25 Hz: 0.0957).
TEST(RealTx40, DocumentedFactsAndDefaultsPredictWithinTenPercentOfTheBestTunedStudy) {
  const auto d = runStudy("tx40_defaults");
  ASSERT_EQ(d.code, 0) << d.out;
  const auto t = runStudy("tx40_consistent_split");
  ASSERT_EQ(t.code, 0) << t.out;
  const double ed = d.summary.find("validation")->find("relative_error")->asDouble();
  const double et = t.summary.find("validation")->find("relative_error")->asDouble();
  std::printf("TX40 held-out relative error: defaults %.4f, tuned consistent_ls %.4f (%.1f %%)\n",
              ed, et, 100.0 * (ed / et - 1.0));
  EXPECT_LT(ed, 1.10 * et);
  // the split is the one asked for, and nothing was discarded silently
  const exid::Json& sp = *d.summary.find("split");
  EXPECT_NEAR(sp.find("split_at_s")->asDouble(), 0.65 * 7.7, 1e-9);
  EXPECT_EQ(d.summary.find("warnings")->size(), 0u);
}

// FIGAROH's processing expressed as an exid study (examples/real/tx40_figaroh_pipeline.yaml) on
// FIGAROH's split (first 65 % of the 7.7 s moving span) and error definition (the held-out part
// processed the same way): FIGAROH's pipeline gives 0.076 (OLS). Measured: 0.0718. The step
// that makes the difference is the removal of the samples where a joint is nearly at rest
// (min_speed): without it the same pipeline gives 0.0898.
TEST(RealTx40, FigarohPipelineAsAStudyMatchesOrBeatsFigaroh) {
  const auto f = runStudy("tx40_figaroh_pipeline");
  ASSERT_EQ(f.code, 0) << f.out;
  const double e = f.summary.find("validation")->find("relative_error")->asDouble();
  EXPECT_LE(e, 0.076);
  EXPECT_NE(f.summary.find("validation")->find("rows_processing")->asString().find("filtered_ls"),
            std::string::npos);
  const auto n = runVariant("tx40_figaroh_pipeline", "    min_speed: [", "    # min_speed: [");
  ASSERT_EQ(n.code, 0) << n.out;
  const double en = n.summary.find("validation")->find("relative_error")->asDouble();
  std::printf("FIGAROH pipeline in exid: %.4f; without min_speed: %.4f\n", e, en);
  EXPECT_GT(en, e + 0.01);
}

// Friction beyond Coulomb + viscous on the real recording (examples/real/tx40_varpro.yaml:
// asymmetric Coulomb levels, tanh widths and Stribeck terms, eps_j and vs_j fitted by varpro)
// against wls with Coulomb + offset on the same split and processing. Measured: held-out relative
// error 0.0591 against 0.0915, every joint lower; with sign() instead of tanh 0.0659. The wide
// scan around the best end finds a lower residual with joint 3's Stribeck velocity running off
// (vs3 = 3.0e3 +- 3.3e4 rad/s: its term acts as a Coulomb term), which varpro says is not
// determined; the earlier end (0.0608) was a local minimum.
TEST(RealTx40, VarproFrictionLowersTheHeldOutErrorOfEveryJoint) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"));
  const ::Run w = runStudy("tx40_wls");
  ASSERT_EQ(w.code, 0) << w.out;
  const ::Run v = runStudy("tx40_varpro");
  ASSERT_EQ(v.code, 0) << v.out;
  const double aw = w.summary.find("validation")->find("relative_error")->asDouble();
  const double av = v.summary.find("validation")->find("relative_error")->asDouble();
  std::printf("held-out relative error: wls %.4f, varpro %.4f\n", aw, av);
  EXPECT_LT(av, 0.75 * aw);
  // the grid and its scans reach the lower end (0.0591), not the local minimum at 0.0608: a
  // projected residual that misjudges points (the screen skips what it should take) ends there
  // (the coupled wrist joints 5 and 6 share rows, so the other groups' columns enter A^T B)
  EXPECT_LT(av, 0.0600);
  // and the projection checked where it is used: every point taken and each held rows' own
  // point (the coupled wrist's groups among them) against their whole evaluations. Measured
  // 6.7e-9 of ||y||^2, at the scan of vs3 around the winning end (vs3 2.4e4 to 6.8e4 rad/s:
  // joint 3's Stribeck column is nearly its Coulomb columns there, and the semi-normal form's
  // rounding grows as eps ||B||^2 / ||B_perp||^2); without the other groups' columns in
  // A^T B, 1.8e-3
  const exid::Json& pw = *v.summary.find("identification")
                              ->find("details")
                              ->find("grid")
                              ->find("projected_against_whole");
  EXPECT_GT(pw.find("points")->asInt(), 5);
  EXPECT_GE(pw.find("held_points")->asInt(), 12);
  EXPECT_LT(pw.find("max_difference_relative_to_yy")->asDouble(), 1e-7) << pw.dump();
  const exid::Json& rw = *w.summary.find("validation")->find("relative_error_per_joint");
  const exid::Json& rv = *v.summary.find("validation")->find("relative_error_per_joint");
  for (std::size_t j = 0; j < 6; ++j)
    EXPECT_LT(rv.at(j).asDouble(), rw.at(j).asDouble()) << "joint " << j + 1;
  const exid::Json& I = *v.summary.find("identification");
  EXPECT_TRUE(I.find("details")->find("converged")->asBool());
  const exid::Json& nl = *I.find("nonlinear_parameters");
  ASSERT_EQ(nl.size(), 12u);
  const exid::Json* wv = I.find("details")->find("warnings");
  const std::string warned = wv ? wv->dump() : std::string();
  int determined = 0;
  for (std::size_t k = 0; k < nl.size(); ++k) {
    const double x = nl.at(k).find("value")->asDouble(), s = nl.at(k).find("std")->asDouble();
    EXPECT_TRUE(x > 0 && s > 0) << nl.at(k).dump();
    const std::string name = nl.at(k).find("name")->asString();
    const bool said = warned.find(name + " = ") != std::string::npos &&
                      warned.find("is not determined") != std::string::npos;
    if (s < x) {
      ++determined;
      EXPECT_FALSE(said) << name << ": " << warned;
    } else {
      EXPECT_TRUE(said) << name << " (std above its value) is not warned about: " << warned;
    }
  }
  EXPECT_GE(determined, 11);
  // sign() instead of tanh: the Stribeck terms alone still lower it
  const ::Run sg = runVariant("tx40_varpro", "coulomb_smoothing_rad_s: [1], ", "");
  ASSERT_EQ(sg.code, 0) << sg.out;
  EXPECT_LT(sg.summary.find("validation")->find("relative_error")->asDouble(), 0.8 * aw);
}

// Output error on the real recording (examples/real/tx40_didim_open.yaml: 30 torque-driven
// windows of 0.2 s fitted to the recorded positions). The residual stays large (the model cannot
// reproduce the recording exactly), so Gauss-Newton's J^T J misses the residual's second-order
// term and creeps along a valley; the secant term (hessian: secant, the default) reaches the
// minimum. Measured (rtol 1e-5, atol 1e-6): secant 13 iterations, rss 6681.7, 0.63 std from the
// predicted minimum (the minimum: 6680.8); Gauss-Newton after 39 iterations well above it (not
// converged). Held-out torque error 0.110: fitting the positions does not lower it (wls 0.0915).
TEST(RealTx40, OutputErrorReachesTheMinimumWhereGaussNewtonCreeps) {
  ASSERT_TRUE(fs::exists(dataDir() / "data/pos_read_data.csv"));
  const ::Run s = runStudy("tx40_didim_open");
  ASSERT_EQ(s.code, 0) << s.out;
  const exid::Json& ds = *s.summary.find("identification")->find("details");
  EXPECT_EQ(ds.find("hessian")->asString(), "secant");
  EXPECT_TRUE(ds.find("converged")->asBool()) << ds.find("stop")->asString();
  const long its = ds.find("iterations")->asInt();
  const double rss = ds.find("rss")->asDouble();
  EXPECT_LE(its, 20);
  EXPECT_LT(rss, 6690.0);
  EXPECT_GT(rss, 6600.0);  // (6680.8 is the minimum)
  const exid::Json& rem = *ds.find("remaining");
  EXPECT_LT(rem.find("relative")->asDouble(), 1e-4);
  EXPECT_LT(rem.find("distance_std")->asDouble(), 1.0);
  const double held_out = s.summary.find("validation")->find("relative_error")->asDouble();
  EXPECT_LT(held_out, 0.12);
  // Gauss-Newton with three times the iterations stays well above it and says it has not
  // converged (the damped step's prediction, the old stop, reported "converged" at the 40th,
  // rss 7184)
  const ::Run g =
      runVariant("tx40_didim_open", "max_iterations: 60",
                 "max_iterations: " + std::to_string(3 * its) + ", hessian: gauss_newton");
  ASSERT_EQ(g.code, 0) << g.out;
  const exid::Json& dg = *g.summary.find("identification")->find("details");
  EXPECT_EQ(dg.find("hessian")->asString(), "gauss_newton");
  const double rss_gn = dg.find("rss")->asDouble();
  std::printf(
      "output error: secant %ld iterations, rss %.1f, held-out %.4f; Gauss-Newton after "
      "%ld: %.1f (%s)\n",
      its, rss, held_out, 3 * its, rss_gn, dg.find("stop")->asString().c_str());
  EXPECT_GT(rss_gn, 1.05 * rss);
  EXPECT_FALSE(dg.find("converged")->asBool()) << dg.find("stop")->asString();
}
