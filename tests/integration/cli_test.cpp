// The exid program end to end: a study runs and writes its files; a failure exits non-zero with
// a message, records why in summary.json and leaves no half-written file.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "exid/json.hpp"

namespace fs = std::filesystem;

namespace {

struct CmdResult {
  int code = -1;
  std::string out;  // stdout and stderr
};

CmdResult runExid(const std::string& args) {
  std::string cmd = std::string(EXID_EXE) + " " + args + " 2>&1";
  CmdResult r;
  FILE* p = ::popen(cmd.c_str(), "r");
  std::array<char, 4096> buf{};
  while (p && std::fgets(buf.data(), buf.size(), p)) r.out += buf.data();
  int status = p ? ::pclose(p) : -1;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

fs::path tempDir(const std::string& name) {
  fs::path d = fs::temp_directory_path() / ("exid_cli_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

bool noTemporaries(const fs::path& dir) {
  for (auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().string().find(".tmp.") != std::string::npos) return false;
  return true;
}

}  // namespace

TEST(Cli, DefaultStudyRunsAndWritesItsResults) {
  fs::path out = tempDir("default");
  CmdResult r = runExid("-q run " + std::string(EXID_SOURCE_DIR) + "/examples/default.yaml --out " +
                        out.string());
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("| status | ok |"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("report.md"), std::string::npos) << r.out;
  for (const char* f : {"summary.json", "report.md", "study.resolved.yaml", "experiment.csv",
                        "parameters.csv", "validation.csv"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  exid::Json s = exid::Json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(s.find("status")->asString(), "ok");
  EXPECT_EQ(s.find("config_hash")->asString().size(), 16u);
  const exid::Json* id = s.find("identification");
  ASSERT_NE(id, nullptr);
  // Noise 0.05 N m on the torques: the residual RMS is the noise level, the estimate is close.
  EXPECT_NEAR(id->find("residual_rms")->asDouble(), 0.05, 0.005);
  EXPECT_LT(id->find("param_rel_err")->asDouble(), 0.01);
  EXPECT_LT(s.find("validation")->find("relative_error")->asDouble(), 0.01);
  EXPECT_EQ(s.find("robot")->find("dof")->asInt(), 6);
  EXPECT_TRUE(noTemporaries(out));
  fs::remove_all(out);
}

TEST(Cli, AFailingStudyExitsNonZeroAndSaysWhyInSummary) {
  fs::path dir = tempDir("failing");
  std::ofstream(dir / "bad.yaml") << "robot: {type: puma560}\nmodel: {type: differential}\n"
                                     "experiment: {type: csv, params: {file: missing.csv}}\n"
                                     "estimator: {type: batch_ls}\n";
  CmdResult r =
      runExid("-q run " + (dir / "bad.yaml").string() + " --out " + (dir / "out").string());
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("missing.csv"), std::string::npos) << r.out;
  exid::Json s = exid::Json::parse(slurp(dir / "out" / "summary.json"));
  EXPECT_EQ(s.find("status")->asString(), "failed");
  EXPECT_EQ(s.find("failed_stage")->asString(), "experiment");
  EXPECT_NE(s.find("message")->asString().find("missing.csv"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "out" / "report.md"));  // no report of a failed study
  EXPECT_FALSE(fs::exists(dir / "out" / "experiment.csv"));
  EXPECT_TRUE(noTemporaries(dir));
  fs::remove_all(dir);
}

TEST(Cli, ConfigErrorsAreReportedBeforeAnyWork) {
  fs::path dir = tempDir("config");
  std::ofstream(dir / "typo.yaml") << "robot: {type: puma560}\nmodel: {type: differential}\n"
                                      "experiment: {type: simulate}\n"
                                      "estimator: {type: rls, params: {forgetting_factor: 1.2}}\n";
  CmdResult r = runExid("run " + (dir / "typo.yaml").string() + " --out " + (dir / "out").string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("typo.yaml:4: estimator.params.forgetting_factor = 1.2: must be in (0, 1]"),
            std::string::npos)
      << r.out;
  EXPECT_FALSE(fs::exists(dir / "out"));  // nothing started
  std::ofstream(dir / "unknown.yaml") << "robot: {type: puma561}\n";
  r = runExid("validate " + (dir / "unknown.yaml").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("did you mean 'puma560'?"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

TEST(Cli, PluginsListsEveryKindWithParameters) {
  CmdResult r = runExid("plugins");
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* k : {"robot (", "model (", "criterion (", "trajectory (", "optimizer (",
                        "experiment (", "estimator ("})
    EXPECT_NE(r.out.find(k), std::string::npos) << k;
  EXPECT_NE(r.out.find("forgetting_factor"), std::string::npos);
  EXPECT_EQ(r.out.find("refused"), std::string::npos) << r.out;
  r = runExid("plugins info batch_ls");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("estimator 'batch_ls'"), std::string::npos) << r.out;
  r = runExid("plugins info bach_ls");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("did you mean 'batch_ls'?"), std::string::npos) << r.out;
  r = runExid("plugins estimater");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("did you mean 'estimator'?"), std::string::npos) << r.out;
}

TEST(Cli, RobotInfoPrintsBaseParametersAsJson) {
  CmdResult r = runExid(
      "-q robot info puma560 --json --model-params '{rotor_inertia: false, coulomb: false, "
      "viscous: false}'");
  ASSERT_EQ(r.code, 0) << r.out;
  exid::Json j = exid::Json::parse(r.out.substr(r.out.find('{')));
  EXPECT_EQ(j.find("dof")->asInt(), 6);
  EXPECT_EQ(j.find("parameters")->size(), 60u);
  EXPECT_EQ(j.find("base_parameters")->size(), 36u);  // the classical PUMA 560 count
}

TEST(Cli, SimulateThenIdentifyReadsTheCsvBack) {
  fs::path dir = tempDir("stages");
  std::ofstream(dir / "s.yaml") << "robot: {type: planar2r}\nmodel: {type: differential, params: "
                                   "{rotor_inertia: false, coulomb: false, viscous: false}}\n"
                                   "experiment: {type: simulate, params: {duration_s: 5}}\n"
                                   "estimator: {type: batch_ls}\n";
  CmdResult r =
      runExid("-q simulate " + (dir / "s.yaml").string() + " --out " + (dir / "sim").string());
  ASSERT_EQ(r.code, 0) << r.out;
  ASSERT_TRUE(fs::exists(dir / "sim" / "experiment.csv"));
  r = runExid("-q identify " + (dir / "s.yaml").string() + " --data " +
              (dir / "sim" / "experiment.csv").string() + " --out " + (dir / "id").string());
  ASSERT_EQ(r.code, 0) << r.out;
  exid::Json s = exid::Json::parse(slurp(dir / "id" / "summary.json"));
  EXPECT_LT(s.find("identification")->find("residual_rms")->asDouble(), 1e-9);
  fs::remove_all(dir);
}

TEST(Cli, ReportHasPlotsOrSaysWhyNot) {
  fs::path dir = tempDir("report");
  std::ofstream(dir / "s.yaml")
      << "robot: {type: planar2r}\n"
         "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
         "false}}\n"
         "experiment: {type: simulate, params: {duration_s: 4, noise_tau_Nm: 0.01, drive_terms: "
         "false}}\n"
         "estimator: {type: rls, params: {history_stride: 10}}\n"
         "validation: {type: simulate, params: {duration_s: 2, drive_terms: false}}\n";
  CmdResult r =
      runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "with").string());
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* f :
       {"plots/estimate_1.svg", "plots/estimate_1.png", "plots/estimate_1.csv",
        "plots/validation_equation1.svg", "plots/residual_histogram.png", "estimate_history.csv"})
    EXPECT_TRUE(fs::exists(dir / "with" / f)) << f;
  const std::string html = slurp(dir / "with" / "report.html");
  EXPECT_NE(html.find("<svg"), std::string::npos);  // self-contained: pictures inline
  EXPECT_EQ(slurp(dir / "with" / "report.md").find("Missing plots"), std::string::npos);
  // Without gnuplot the study still succeeds and the report says which plots are missing and why.
  ASSERT_EQ(::setenv("EXID_GNUPLOT", "none", 1), 0);
  r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "without").string());
  ::unsetenv("EXID_GNUPLOT");
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string md = slurp(dir / "without" / "report.md");
  EXPECT_NE(md.find("## Missing plots"), std::string::npos) << md;
  EXPECT_NE(md.find("gnuplot is not installed"), std::string::npos) << md;
  EXPECT_TRUE(fs::exists(dir / "without" / "plots" / "estimate_1.csv"));  // the data is still there
  fs::remove_all(dir);
}

TEST(Cli, EvalWritesTorqueRegressorAndEnergyConsistently) {
  fs::path dir = tempDir("eval");
  {
    std::ofstream s(dir / "samples.csv");
    s << "q1,q2,qd1,qd2,qdd1,qdd2\n0.1,0.2,0.3,-0.4,1.0,2.0\n-0.5,1.1,0.0,0.7,-1.5,0.25\n";
  }
  for (const char* what :
       {"torque", "regressor", "energy", "energy_regressor", "wrench_regressor"}) {
    CmdResult r =
        runExid("-q eval planar2r --samples " + (dir / "samples.csv").string() + " --what " + what +
                " --out " + (dir / (std::string(what) + ".csv")).string());
    ASSERT_EQ(r.code, 0) << what << ": " << r.out;
  }
  // tau = Y pi: the regressor rows times the robot's parameters (from robot info) give the torques.
  CmdResult info = runExid(
      "-q robot info planar2r --json --model-params '{rotor_inertia: false, coulomb: false, "
      "viscous: false}'");
  exid::Json j = exid::Json::parse(info.out.substr(info.out.find('{')));
  const exid::Json& values = *j.find("values");
  std::ifstream reg(dir / "regressor.csv"), tau(dir / "torque.csv"), en(dir / "energy.csv");
  std::string header, line;
  std::getline(reg, header);
  std::getline(tau, line);
  std::vector<double> torques;
  while (std::getline(tau, line)) {
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) torques.push_back(std::stod(cell));
  }
  ASSERT_EQ(torques.size(), 4u);
  for (std::size_t row = 0; row < 4; ++row) {
    ASSERT_TRUE(std::getline(reg, line));
    std::stringstream ss(line);
    std::string cell;
    double sum = 0;
    std::size_t c = 0;
    while (std::getline(ss, cell, ',')) sum += std::stod(cell) * values.at(c++).asDouble();
    EXPECT_NEAR(sum, torques[row], 1e-9 * (1 + std::abs(sum)));
  }
  std::getline(en, header);
  EXPECT_EQ(header, "kinetic,potential,total");
  // A missing column is an error naming the file and the column.
  std::ofstream(dir / "bad.csv") << "q1,q2\n0,0\n";
  CmdResult r = runExid("-q eval planar2r --samples " + (dir / "bad.csv").string() +
                        " --what torque --out " + (dir / "x.csv").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("missing column 'qd1'"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "x.csv"));
  fs::remove_all(dir);
}
