// The embedding facade (exid/exid.hpp): a study and a matrix run from a program through it give
// what `exid run` and `exid matrix` give; a study or matrix that cannot run says why without
// throwing, and writes nothing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "exid/exid.hpp"
#include "exid/registry.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

fs::path tmp(const std::string& name) {
  const fs::path p =
      fs::temp_directory_path() / ("exid_api_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(p);
  return p;
}

void write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

const char* kStudy =
    "name: embedded\n"
    "robot: {type: planar2r}\n"
    "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
    "false}}\n"
    "experiment: {type: simulate, params: {duration_s: 4, drive_terms: false}}\n"
    "estimator: {type: batch_ls}\n";

}  // namespace

TEST(EmbeddingFacade, AStudyFileRunsAndJudgesItself) {
  const fs::path dir = tmp("study");
  write(dir / "study.yaml", kStudy);
  exid::StudySettings s;
  s.out_dir = dir / "out";
  int progress_calls = 0;
  s.progress = [&](const std::string&, double, const std::string&) { ++progress_calls; };
  const exid::StudyOutcome r = exid::runStudyFile(dir / "study.yaml", exid_test::registry(), s);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.status, "ok");
  EXPECT_TRUE(r.message.empty());
  EXPECT_EQ(r.verdict, "ok");  // noise-free: the truth, held out by itself
  EXPECT_TRUE(r.verdict_reasons.empty());
  EXPECT_GT(progress_calls, 0);
  EXPECT_EQ(r.written_to, s.out_dir);
  EXPECT_TRUE(fs::exists(s.out_dir / "summary.json"));
  ASSERT_TRUE(r.summary.find("identification"));
  EXPECT_LT(r.summary.find("identification")->find("param_rel_err")->asDouble(), 1e-8);
  fs::remove_all(dir);
}

TEST(EmbeddingFacade, AStudyThatCannotRunSaysWhyAndWritesNothing) {
  const fs::path dir = tmp("bad");
  exid::StudySettings s;
  s.out_dir = dir / "out";
  // a file that is not there
  exid::StudyOutcome r = exid::runStudyFile(dir / "missing.yaml", exid_test::registry(), s);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.status, "failed");
  EXPECT_NE(r.message.find("missing.yaml"), std::string::npos) << r.message;
  EXPECT_EQ(r.verdict, "");  // no verdict for what did not run
  // an unknown plugin, named with the key it is under
  r = exid::runStudyText(std::string(kStudy) + "validation: {type: nonesuch}\n", "inline.yaml", dir,
                         exid_test::registry(), s);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("nonesuch"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("inline.yaml"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(s.out_dir));
}

TEST(EmbeddingFacade, AMatrixRunsItsCellsAndResumes) {
  const fs::path dir = tmp("matrix");
  write(dir / "m.yaml",
        "name: embedded_matrix\n"
        "study:\n"
        "  robot: {type: planar2r}\n"
        "  model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
        "false}}\n"
        "  experiment: {type: simulate, params: {duration_s: 3, drive_terms: false}}\n"
        "  estimator: {type: batch_ls}\n"
        "axes:\n"
        "  seed: [1, 2]\n");
  exid::MatrixSettings s;
  s.out_dir = dir / "out";
  exid::MatrixOutcome r = exid::runMatrixFile(dir / "m.yaml", exid_test::registry(), s);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.cells, 2);
  EXPECT_EQ(r.succeeded, 2);
  EXPECT_EQ(r.skipped, 0);
  EXPECT_EQ(r.failed, 0);
  EXPECT_TRUE(fs::exists(r.database));
  // again: both finished before, so both skipped, none run
  r = exid::runMatrixFile(dir / "m.yaml", exid_test::registry(), s);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.skipped, 2);
  EXPECT_EQ(r.succeeded, 0);
  // no output folder: refused, naming the file
  r = exid::runMatrixFile(dir / "m.yaml", exid_test::registry(), exid::MatrixSettings{});
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("m.yaml"), std::string::npos) << r.message;
  fs::remove_all(dir);
}
