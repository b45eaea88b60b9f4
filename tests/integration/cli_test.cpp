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

#include "exid/config.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"
#include "exid/version.hpp"
#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace {

using exid_cli::CmdResult;
using exid_cli::runExid;
using exid_cli::slurp;

fs::path tempDir(const std::string& name) { return exid_cli::freshTempDir("exid_cli_", name); }

bool noTemporaries(const fs::path& dir) {
  for (auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().string().find(".tmp.") != std::string::npos) return false;
  return true;
}

}  // namespace

TEST(Cli, DefaultStudyRunsAndWritesItsResults) {
  fs::path out = tempDir("default");
  // not quiet: the default study prints no warning a newcomer cannot act on
  CmdResult r = runExid("run " + std::string(EXID_SOURCE_DIR) + "/examples/default.yaml --out " +
                        out.string());
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.out.find("warning"), std::string::npos) << r.out;
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
  EXPECT_EQ(s.find("warnings")->size(), 0u) << s.find("warnings")->dump(2);
  // the published PUMA 560 data's known defects: said once, as a note in the report
  ASSERT_NE(s.find("robot")->find("notes"), nullptr);
  EXPECT_NE(s.find("robot")->find("notes")->at(0).asString().find("triangle inequality"),
            std::string::npos);
  const std::string md = slurp(out / "report.md");
  EXPECT_NE(md.find("## Notes on the robot"), std::string::npos);
  EXPECT_EQ(md.find("## Warnings"), std::string::npos);
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

// A floating-base robot's info uses the floating_base model unless --model says otherwise (the
// fixed-base models refuse it), and says so; a fixed-base robot keeps differential, unsaid.
TEST(Cli, RobotInfoOfAFloatingBaseUsesItsOwnModelAndSaysSo) {
  CmdResult r = runExid("-q robot info humanoid --json");
  ASSERT_EQ(r.code, 0) << r.out;
  exid::Json j = exid::Json::parse(r.out.substr(r.out.find('{')));
  EXPECT_EQ(j.find("model")->asString(), "floating_base");
  EXPECT_NE(j.find("model_rule")->asString().find("floating base"), std::string::npos);
  EXPECT_EQ(j.find("parameters")->size(), 110u);  // the torso's 10 and 10 per body
  r = runExid("-q robot info humanoid");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("model floating_base (the robot has a floating base"), std::string::npos)
      << r.out;
  r = runExid("-q robot info humanoid --model differential");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("floating_base observation model"), std::string::npos) << r.out;
  r = runExid("-q robot info puma560 --json");
  ASSERT_EQ(r.code, 0) << r.out;
  j = exid::Json::parse(r.out.substr(r.out.find('{')));
  EXPECT_EQ(j.find("model")->asString(), "differential");
  EXPECT_EQ(j.find("model_rule")->asString().find("floating"), std::string::npos);
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
    // the PUMA 560 describes its drives (rotor inertia, Coulomb and viscous friction)
    std::ofstream s(dir / "samples.csv");
    s << "q1,q2,q3,q4,q5,q6,qd1,qd2,qd3,qd4,qd5,qd6,qdd1,qdd2,qdd3,qdd4,qdd5,qdd6\n"
         "0.1,0.2,-0.3,0.4,0.5,-0.6,0.3,-0.4,0.5,0.1,-0.2,0.7,1.0,2.0,-1.0,0.5,0.25,-0.5\n"
         "-0.5,1.1,0.2,-0.1,0.3,0.2,0.0,0.7,-0.3,0.2,0.4,-0.1,-1.5,0.25,0.5,1.0,-2.0,0.75\n";
  }
  for (const char* what :
       {"torque", "regressor", "energy", "energy_regressor", "wrench_regressor"}) {
    CmdResult r =
        runExid("-q eval puma560 --samples " + (dir / "samples.csv").string() + " --what " + what +
                " --out " + (dir / (std::string(what) + ".csv")).string());
    ASSERT_EQ(r.code, 0) << what << ": " << r.out;
  }
  // the rigid bodies alone, asked for explicitly; global options also after the subcommand
  CmdResult rb =
      runExid("eval puma560 --samples " + (dir / "samples.csv").string() +
              " --what torque --rigid-body-only --out " + (dir / "rigid.csv").string() + " -q");
  ASSERT_EQ(rb.code, 0) << rb.out;
  EXPECT_NE(slurp(dir / "torque.csv")
                .find("# exid eval torque puma560: full torque: rigid "
                      "bodies + drives"),
            std::string::npos)
      << slurp(dir / "torque.csv");
  EXPECT_NE(slurp(dir / "rigid.csv").find("rigid bodies alone"), std::string::npos)
      << slurp(dir / "rigid.csv");
  // Rigid bodies: tau = Y pi with the regressor rows and the robot's inertial parameters.
  // Full torque: the same plus every drive term the robot describes (Ia qdd + Fc sign(qd) +
  // Fv qd + OFF), i.e. the differential model's full regressor times its nominal values.
  CmdResult info = runExid(
      "-q robot info puma560 --json --model-params '{rotor_inertia: false, coulomb: false, "
      "viscous: false}'");
  exid::Json j = exid::Json::parse(info.out.substr(info.out.find('{')));
  const exid::Json& values = *j.find("values");
  CmdResult full_info = runExid(
      "-q robot info puma560 --json --model-params '{rotor_inertia: true, coulomb: true, "
      "viscous: true, offset: true}'");
  exid::Json jf = exid::Json::parse(full_info.out.substr(full_info.out.find('{')));
  const exid::Json& fvalues = *jf.find("values");
  const exid::CsvTable Y = exid::readCsv(dir / "regressor.csv");
  const exid::CsvTable T = exid::readCsv(dir / "torque.csv");
  const exid::CsvTable R = exid::readCsv(dir / "rigid.csv");
  const exid::CsvTable S = exid::readCsv(dir / "samples.csv");
  constexpr int n = 6;
  ASSERT_EQ(T.data.rows(), 2);
  ASSERT_EQ(R.data.rows(), 2);
  ASSERT_EQ(Y.data.rows(), 2 * n);
  ASSERT_EQ(fvalues.size(), static_cast<std::size_t>(14 * n));
  double drive_part = 0;
  for (int k = 0; k < 2; ++k)
    for (int jn = 0; jn < n; ++jn) {
      double rigid = 0;
      for (Eigen::Index c = 0; c < Y.data.cols(); ++c)
        rigid += Y.data(n * k + jn, c) * values.at(static_cast<std::size_t>(c)).asDouble();
      EXPECT_NEAR(R.data(k, jn), rigid, 1e-9 * (1 + std::abs(rigid)));
      // drive columns of joint jn: Ia, Fc, Fv, OFF after the 10 n inertial parameters
      const std::size_t o = 10 * n + 4 * static_cast<std::size_t>(jn);
      const double qd = S.column("qd" + std::to_string(jn + 1))(k);
      const double qdd = S.column("qdd" + std::to_string(jn + 1))(k);
      const double drive = fvalues.at(o).asDouble() * qdd +
                           fvalues.at(o + 1).asDouble() * (qd > 0 ? 1.0 : (qd < 0 ? -1.0 : 0.0)) +
                           fvalues.at(o + 2).asDouble() * qd + fvalues.at(o + 3).asDouble();
      EXPECT_NEAR(T.data(k, jn), rigid + drive, 1e-9 * (1 + std::abs(rigid + drive)));
      drive_part += std::abs(drive);
    }
  EXPECT_GT(drive_part, 1e-3) << "the PUMA 560 describes drives: the full torque must include them";
  const exid::CsvTable E = exid::readCsv(dir / "energy.csv");
  EXPECT_EQ(E.columns, (std::vector<std::string>{"kinetic", "potential", "total"}));
  // A missing column is an error naming the file and the column.
  std::ofstream(dir / "bad.csv") << "q1,q2\n0,0\n";
  CmdResult r = runExid("-q eval planar2r --samples " + (dir / "bad.csv").string() +
                        " --what torque --out " + (dir / "x.csv").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("missing column 'qd1'"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "x.csv"));
  // A joint column beyond the robot's joints: the file is for another robot.
  std::ofstream(dir / "three.csv") << "q1,q2,q3,qd1,qd2,qd3,qdd1,qdd2,qdd3\n0,0,0,0,0,0,0,0,0\n";
  r = runExid("-q eval planar2r --samples " + (dir / "three.csv").string() +
              " --what torque --out " + (dir / "x.csv").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("column 'q3' but robot"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "x.csv"));
  fs::remove_all(dir);
}

TEST(Cli, VersionAndGlobalOptionsAfterTheSubcommand) {
  CmdResult v = runExid("--version");
  EXPECT_EQ(v.code, 0) << v.out;
  EXPECT_EQ(v.out.rfind("exid " EXID_VERSION_STRING " (commit ", 0), 0u) << v.out;
  // the commit is 12 hex digits (optionally -dirty) or 'unknown' outside a checkout
  const std::string commit = v.out.substr(v.out.find("(commit ") + 8);
  EXPECT_TRUE(commit.rfind("unknown", 0) == 0 || commit.find_first_not_of("0123456789abcdef") >= 12)
      << commit;
  // -q, -v and --plugin-path before or after the subcommand, nested subcommands included
  for (const std::string args :
       {"plugins robot -q", "-q plugins robot", "plugins robot -v", "robot info planar2r -q",
        "plugins robot --plugin-path /nonexistent -q"}) {
    CmdResult r = runExid(args);
    EXPECT_EQ(r.code, 0) << args << ": " << r.out;
  }
  const fs::path out = tempDir("quiet_after");
  std::ofstream(out / "s.yaml") << "robot: {type: planar2r}\nmodel: {type: differential, params: "
                                   "{rotor_inertia: false, coulomb: false, viscous: false}}\n"
                                   "experiment: {type: simulate, params: {duration_s: 3}}\n"
                                   "estimator: {type: batch_ls}\n";
  CmdResult r =
      runExid("run " + (out / "s.yaml").string() + " --out " + (out / "o").string() + " -q");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.out.find("[exid]"), std::string::npos) << "-q after the subcommand: " << r.out;
  const exid::Json S = exid::Json::parse(slurp(out / "o" / "summary.json"));
  EXPECT_EQ(S.find("exid_version")->asString(), EXID_VERSION_STRING);
  EXPECT_EQ(S.find("exid_commit")->asString(), commit.substr(0, commit.find(')')));
  fs::remove_all(out);
}

TEST(Cli, ValidationRunsItsOwnTrajectoryAndDataWarningsReachTheSummary) {
  fs::path dir = tempDir("own_validation");
  // An excitation stage, then a validation experiment with its own period and harmonics.
  std::ofstream(dir / "s.yaml")
      << "robot: {type: planar2r}\n"
         "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
         "false}}\n"
         "excitation:\n"
         "  trajectory: {type: fourier, params: {period_s: 4, harmonics: 3, sample_period_s: "
         "0.1}}\n"
         "  criterion: {type: cond}\n"
         "  optimizer: {type: nlopt, params: {max_evaluations: 50}}\n"
         "experiment: {type: simulate, params: {duration_s: 3.9, drive_terms: false}}\n"
         "estimator: {type: batch_ls}\n"
         "validation: {type: simulate, params: {period_s: 3, harmonics: 2, duration_s: 3, "
         "drive_terms: false}}\n";
  CmdResult r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  exid::Json S = exid::Json::parse(slurp(dir / "o" / "summary.json"));
  const exid::Json& ref = *S.find("validation")->find("meta")->find("reference");
  EXPECT_EQ(ref.find("type")->asString(), "fourier") << ref.dump(0);
  EXPECT_EQ(ref.find("period_s")->asDouble(), 3.0);
  EXPECT_EQ(ref.find("harmonics")->asInt(), 2);
  EXPECT_NE(S.find("experiment")->find("meta")->find("reference")->find("type")->asString(),
            "fourier");  // the identification experiment follows the excitation's trajectory
  // Data warnings of the csv experiment land in summary.json's warnings and the report.
  {
    std::ofstream f(dir / "rec.csv");
    f << "t,q1,q2,tau1,tau2\n";
    for (int k = 0; k < 400; ++k) {
      const double t = 0.01 * k;
      f << t << "," << std::sin(t) << "," << std::cos(1.3 * t) << "," << 0.1 * k << "," << -0.05 * k
        << "\n";
    }
  }
  std::ofstream(dir / "c.yaml")
      << "robot: {type: planar2r}\n"
         "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
         "false}}\n"
         "experiment: {type: csv, params: {file: rec.csv, differentiate_cutoff_hz: 5, "
         "trim_edges: 30}}\n"
         "estimator: {type: batch_ls}\n";
  r = runExid("-q run " + (dir / "c.yaml").string() + " --out " + (dir / "c").string());
  ASSERT_EQ(r.code, 0) << r.out;
  S = exid::Json::parse(slurp(dir / "c" / "summary.json"));
  // (its torques are ramps, not the robot's: the inspection warns of that too)
  const exid::Json& w = *S.find("warnings");
  ASSERT_GE(w.size(), 1u) << w.dump(0);
  EXPECT_NE(w.at(0).asString().find("experiment: experiment 'csv'"), std::string::npos);
  EXPECT_NE(w.at(0).asString().find("discards 60 of the segment's 400"), std::string::npos);
  for (std::size_t i = 1; i < w.size(); ++i)
    EXPECT_EQ(w.at(i).asString().rfind("inspection (experiment): ", 0), 0u) << w.at(i).asString();
  EXPECT_NE(slurp(dir / "c" / "report.md").find("## Warnings"), std::string::npos);
  fs::remove_all(dir);
}

TEST(Cli, SplitIdentifiesOnOnePartAndValidatesOnTheRestOfOneRecording) {
  fs::path dir = tempDir("split");
  // A recording simulated by exid itself, written as the csv experiment reads it.
  std::ofstream(dir / "sim.yaml")
      << "robot: {type: planar2r}\n"
         "experiment: {type: simulate, params: {duration_s: 8, drive_terms: false, "
         "noise_tau_Nm: 0.01}}\n";
  CmdResult r =
      runExid("-q run " + (dir / "sim.yaml").string() + " --out " + (dir / "sim").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string study =
      "robot: {type: planar2r}\n"
      "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
      "false}}\n"
      "experiment: {type: csv, params: {file: sim/experiment.csv}}\n"
      "estimator: {type: batch_ls}\n";
  std::ofstream(dir / "s.yaml") << study << "split: {identification_fraction: 0.65}\n";
  r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  exid::Json S = exid::Json::parse(slurp(dir / "o" / "summary.json"));
  const exid::Json& sp = *S.find("split");
  EXPECT_EQ(sp.find("identification_fraction")->asDouble(), 0.65);
  const int ni = sp.find("identification_samples")->asInt();
  const int nv = sp.find("validation_samples")->asInt();
  EXPECT_EQ(ni + nv,
            S.find("validation")->find("meta")->find("split")->find("segment_samples")->asInt());
  EXPECT_NEAR(static_cast<double>(ni) / (ni + nv), 0.65, 0.01);
  EXPECT_EQ(S.find("experiment")->find("samples")->asInt(), ni);
  const double cut = sp.find("split_at_s")->asDouble();
  EXPECT_EQ(sp.find("identification_s")->at(1).asDouble(), cut);
  EXPECT_EQ(sp.find("validation_s")->at(0).asDouble(), cut);
  EXPECT_LT(S.find("validation")->find("relative_error")->asDouble(), 0.05);
  // The resolved study spells the two parts out (and runs again as it is).
  const std::string resolved = slurp(dir / "o" / "study.resolved.yaml");
  EXPECT_NE(resolved.find("split_part: identification"), std::string::npos) << resolved;
  EXPECT_NE(resolved.find("split_part: validation"), std::string::npos) << resolved;
  r = runExid("-q run " + (dir / "o" / "study.resolved.yaml").string() + " --out " +
              (dir / "o2").string());
  EXPECT_EQ(r.code, 0) << r.out;
  // split and a validation section exclude each other; a simulated experiment cannot split
  std::ofstream(dir / "both.yaml") << study << "split: {at_s: 3}\nvalidation: {type: simulate}\n";
  r = runExid("-q validate " + (dir / "both.yaml").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("give split or a validation section, not both"), std::string::npos) << r.out;
  std::ofstream(dir / "sim_split.yaml")
      << "robot: {type: planar2r}\nmodel: {type: differential}\n"
         "experiment: {type: simulate}\nestimator: {type: batch_ls}\n"
         "split: {identification_fraction: 0.5}\n";
  r = runExid("-q validate " + (dir / "sim_split.yaml").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("cannot split its data"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

TEST(Cli, APayloadStudyIsJudgedAgainstTheSimulatedPayloadNotTheNominal) {
  fs::path dir = tempDir("payload_truth");
  // The model's nominal payload is zero (unknown); the simulation carries 1.5 kg.
  std::ofstream(dir / "s.yaml")
      << "robot: {type: planar2r}\n"
         "model: {type: load_wrench}\n"
         "experiment: {type: simulate, params: {duration_s: 4, wrench: true, drive_terms: false, "
         "payload_mass_kg: 1.5, payload_com_m: [0.01, 0.02, 0.05], payload_inertia_kg_m2: "
         "[0.004, 0, 0, 0.005, 0, 0.003]}}\n"
         "estimator: {type: batch_ls}\n";
  CmdResult r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const exid::Json S = exid::Json::parse(slurp(dir / "o" / "summary.json"));
  const exid::Json& I = *S.find("identification");
  ASSERT_NE(I.find("param_rel_err"), nullptr) << I.dump(0);
  EXPECT_LT(I.find("param_rel_err")->asDouble(), 1e-6);
  const exid::Json& p0 = I.find("parameters")->at(0);  // L_M
  EXPECT_EQ(p0.find("name")->asString(), "L_M");
  EXPECT_DOUBLE_EQ(p0.find("true")->asDouble(), 1.5);
  EXPECT_DOUBLE_EQ(p0.find("nominal")->asDouble(), 0.0);
  fs::remove_all(dir);
}

TEST(Cli, AnImplausibleConsistentFitIsAWarningNamingTheLikelyCause) {
  fs::path dir = tempDir("implausible");
  std::ofstream(dir / "sim.yaml")
      << "robot: {type: puma560}\n"
         "experiment: {type: simulate, params: {duration_s: 6, drive_terms: true, "
         "noise_tau_Nm: 0.01}}\n";
  CmdResult r =
      runExid("-q run " + (dir / "sim.yaml").string() + " --out " + (dir / "sim").string());
  ASSERT_EQ(r.code, 0) << r.out;
  auto warnings =
      [&](const std::string& tau_scale) {
        std::ofstream(dir / "s.yaml")
            << "robot: {type: puma560}\nmodel: {type: differential}\n"
               "experiment: {type: csv, params: {file: sim/experiment.csv, tau_scale: "
            << tau_scale << "}}\nestimator: {type: consistent_ls}\n";
        CmdResult c =
            runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
        EXPECT_EQ(c.code, 0) << c.out;
        const exid::Json S = exid::Json::parse(slurp(dir / "o" / "summary.json"));
        std::string all;
        for (std::size_t i = 0; S.find("warnings") && i < S.find("warnings")->size(); ++i)
          all += S.find("warnings")->at(i).asString() + "\n";
        return all;
      };
  // the torque of joint 2 recorded with the opposite sign: the consistent fit cannot follow
  // (friction and rotor inertia are >= 0), and body 2 comes out far too heavy
  const std::string flipped = warnings("[1, -1, 1, 1, 1, 1]");
  EXPECT_NE(flipped.find("physically impossible model"), std::string::npos) << flipped;
  EXPECT_NE(flipped.find("opposite sign"), std::string::npos) << flipped;
  EXPECT_NE(flipped.find("body 2 has a mass of"), std::string::npos) << flipped;
  // the same data with the right sign: no such warning
  const std::string right = warnings("[1, 1, 1, 1, 1, 1]");
  EXPECT_EQ(right.find("consistent_ls"), std::string::npos) << right;
  fs::remove_all(dir);
}

TEST(Cli, ExperimentAndValidationCsvCarryTimeAndJointNames) {
  fs::path dir = tempDir("csv_names");
  std::ofstream(dir / "s.yaml")
      << "robot: {type: planar2r}\n"
         "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: "
         "false}}\n"
         "experiment: {type: simulate, params: {duration_s: 2, drive_terms: false}}\n"
         "estimator: {type: batch_ls}\n"
         "validation: {type: simulate, params: {duration_s: 1, drive_terms: false}}\n";
  CmdResult r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string e = slurp(dir / "o" / "experiment.csv");
  EXPECT_EQ(e.rfind("# exid experiment of study", 0), 0u) << e.substr(0, 200);
  EXPECT_NE(e.find("joints 1 = "), std::string::npos);
  const std::string v = slurp(dir / "o" / "validation.csv");
  EXPECT_NE(v.find("\nt,row,equation,measured,predicted\n"), std::string::npos) << v.substr(0, 300);
  EXPECT_NE(v.find("0 = tau1 "), std::string::npos) << v.substr(0, 300);
  // the t column is the time of each row's sample: rows of one sample share it
  const exid::CsvTable T = exid::readCsv(dir / "o" / "validation.csv");
  ASSERT_GT(T.data.rows(), 4);
  EXPECT_EQ(T.data(0, 0), T.data(1, 0));
  EXPECT_LT(T.data(1, 0), T.data(2, 0));
  // experiment.csv reads back as data (exid identify --data)
  r = runExid("-q identify " + (dir / "s.yaml").string() + " --data " +
              (dir / "o" / "experiment.csv").string() + " --out " + (dir / "i").string());
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

TEST(Cli, ALongRecordingIsNotCopiedIntoExperimentCsvUnlessAsked) {
  fs::path dir = tempDir("no_copy");
  {
    std::ofstream f(dir / "rec.csv");
    f << "t,q1,q2,qd1,qd2,qdd1,qdd2,tau1,tau2\n";
    for (long k = 0; k <= exid::kExperimentCsvAutoSamples; ++k) {
      const double t = 0.001 * static_cast<double>(k);
      f << t << "," << std::sin(t) << ",0.5," << std::cos(t) << ",0," << -std::sin(t) << ",0,1,2\n";
    }
  }
  auto run = [&](const std::string& policy) {
    std::ofstream(dir / "s.yaml") << "robot: {type: planar2r}\n"
                                     "experiment: {type: csv, params: {file: rec.csv}}\n"
                                     "report: {params: {plots: false" +
                                         (policy.empty() ? "" : ", experiment_csv: " + policy) +
                                         "}}\n";
    fs::remove_all(dir / "o");
    CmdResult r = runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
    EXPECT_EQ(r.code, 0) << r.out;
    return exid::Json::parse(slurp(dir / "o" / "summary.json"));
  };
  exid::Json S = run("");
  EXPECT_FALSE(fs::exists(dir / "o" / "experiment.csv"));
  EXPECT_NE(S.find("experiment")->find("csv_not_written")->asString().find("100001 samples"),
            std::string::npos);
  S = run("always");
  EXPECT_TRUE(fs::exists(dir / "o" / "experiment.csv"));
  EXPECT_EQ(S.find("experiment")->find("csv")->asString(), "experiment.csv");
  fs::remove_all(dir);
}

// A summary's JSON without the lines that hold times measured (wall, CPU, rates).
std::string withoutTimes(const exid::Json& j) {
  std::istringstream in(j.dump());
  std::string line, out;
  while (std::getline(in, line))
    if (line.find("wall_s") == std::string::npos && line.find("cpu_s") == std::string::npos &&
        line.find("per_s") == std::string::npos)
      out += line + "\n";
  return out;
}

// A recording streamed from its file (estimators that stream, experiment.csv not asked for)
// gives the same bits as the same recording read whole: estimates, statistics of the recording,
// inspection, held-out error; bad rows dropped and a segment cut the same way.
TEST(Cli, AStreamedRecordingGivesTheSameResultsAsTheWholeRead) {
  fs::path dir = tempDir("streamed");
  std::ofstream(dir / "sim.yaml")
      << "robot: {type: planar2r}\n"
         "model: {type: differential}\n"
         "experiment: {type: simulate, params: {duration_s: 6, noise_q_rad: 1e-4, noise_tau_Nm: "
         "0.05}}\n"
         "report: {params: {plots: false}}\n";
  CmdResult r =
      runExid("-q run " + (dir / "sim.yaml").string() + " --out " + (dir / "sim").string());
  ASSERT_EQ(r.code, 0) << r.out;
  // the recording, with one row made bad (dropped by drop_bad_rows)
  {
    std::ifstream in(dir / "sim" / "experiment.csv");
    std::ofstream out(dir / "rec.csv");
    std::string line;
    int k = 0;
    while (std::getline(in, line)) {
      if (k++ == 40)
        line = line.substr(0, line.find(',')) + ",nan" +
               line.substr(line.find(',', line.find(',') + 1));
      out << line << "\n";
    }
  }
  for (const std::string est : {"batch_ls", "wls", "rls", "consistent_ls", "filtered_ls"}) {
    // filtered_ls: its position filter, differences and decimation over chunks with margins,
    // several chunks
    const std::string params =
        est == "consistent_ls" ? ", params: {}"
        : est == "filtered_ls"
            ? ", params: {cutoff_hz: 20, differentiate: true, chunk_samples: 64, threads: 2}"
            : "";
    auto run = [&](const std::string& policy) {
      std::ofstream(dir / "s.yaml")
          << "robot: {type: planar2r}\n"
             "model: {type: differential}\n"
             "experiment: {type: csv, params: {file: rec.csv, drop_bad_rows: true, t_start_s: "
             "0.2}}\n"
             "split: {identification_fraction: 0.7}\n"
             "estimator: {type: "
          << est << params << "}\n"
          << (est == "consistent_ls" || est == "rls"
                  ? "prior: {from: robot, relative_std: 0.5, absolute_std: 1}\n"
                  : "")
          << "report: {params: {plots: false, experiment_csv: " << policy << "}}\n";
      fs::remove_all(dir / "o");
      CmdResult c =
          runExid("-q run " + (dir / "s.yaml").string() + " --out " + (dir / "o").string());
      EXPECT_EQ(c.code, 0) << est << " " << policy << ": " << c.out;
      return exid::Json::parse(slurp(dir / "o" / "summary.json"));
    };
    const exid::Json whole = run("always"), streamed = run("never");
    if (est == "batch_ls") {  // the same bits on 1 and 3 threads (the file read beside them)
      for (const char* th : {"1", "3"}) {
        std::ofstream(dir / "t.yaml")
            << "robot: {type: planar2r}\nmodel: {type: differential}\n"
               "experiment: {type: csv, params: {file: rec.csv, drop_bad_rows: true, t_start_s: "
               "0.2}}\nsplit: {identification_fraction: 0.7}\n"
               "estimator: {type: batch_ls, params: {threads: "
            << th << "}}\nreport: {params: {plots: false, experiment_csv: never}}\n";
        fs::remove_all(dir / "t");
        CmdResult c =
            runExid("-q run " + (dir / "t.yaml").string() + " --out " + (dir / "t").string());
        ASSERT_EQ(c.code, 0) << c.out;
        const exid::Json S = exid::Json::parse(slurp(dir / "t" / "summary.json"));
        EXPECT_EQ(withoutTimes(*S.find("identification")->find("parameters")),
                  withoutTimes(*streamed.find("identification")->find("parameters")))
            << th << " threads";
      }
    }
    ASSERT_NE(streamed.find("experiment"), nullptr);
    EXPECT_NE(streamed.find("experiment")->find("streamed"), nullptr) << est;
    EXPECT_EQ(whole.find("experiment")->find("streamed"), nullptr) << est;
    for (const char* key : {"identification", "validation", "inspection"}) {
      ASSERT_NE(whole.find(key), nullptr) << est << " " << key;
      EXPECT_EQ(withoutTimes(*whole.find(key)), withoutTimes(*streamed.find(key)))
          << est << " " << key;
    }
    const exid::Json& mw = *whole.find("experiment")->find("meta");
    const exid::Json& ms = *streamed.find("experiment")->find("meta");
    EXPECT_EQ(mw.dump(), ms.dump()) << est;
    EXPECT_EQ(ms.find("accounting")->find("dropped_bad_rows")->asInt(), 1);
    EXPECT_NE(ms.find("recording")->find("duplicate_rows"), nullptr);
  }
  fs::remove_all(dir);
}
