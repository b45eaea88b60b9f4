// Closed chains through a whole study: the palletiser (elbow driven through a parallelogram)
// identified from noise-free simulated data by every estimator recovers the base parameters
// (param_rel_err: the identified base parameters against the truth's, relative); didim and iv
// from a tracking recording; varpro and gains_ls; excitation design by gradient runs through the
// loops. (Long computations on the libraries the sanitized CI stage already runs through
// tests/integration/closed_chain_example_test.cpp: they run in the first stage only.)
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "closed_chain_study_util.hpp"
#include "closed_loop_test_util.hpp"
#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

using closed_study::relErr;
using closed_study::run;

TEST(ClosedChainStudy, PalletizerIdentifiesWithEveryEstimator) {
  // (rls with a wide prior: its default p0 = 1e6 leaves a prior bias of 3e-6 here, 1e-7 on the
  // irp6 tree. filtered_ls differentiates a Butterworth-filtered q: its noise-free floor is the
  // filter's, 5.5e-7 here and 1.2e-7 on the irp6 tree, so it is held to 1e-5.)
  for (const std::string est :
       {"{type: batch_ls}", "{type: wls}", "{type: rls, params: {p0: 1e14}}",
        "{type: consistent_ls}", "{type: filtered_ls}"}) {
    const exid::StudyResult r = run("palletizer", est);
    ASSERT_TRUE(r.ok) << est << ": " << r.message;
    EXPECT_LT(relErr(r), est == "{type: filtered_ls}" ? 1e-5 : 1e-9) << est;
    std::ostringstream os;
    os << std::scientific << relErr(r);
    RecordProperty(est, os.str());
  }
}

TEST(ClosedChainStudy, PalletizerIdentifiesWithDidimAndIvFromATrackingRecording) {
  // the estimators that simulate the closed loop need the commanded trajectory and the PD gains:
  // the palletiser tracks a reference (sums of sines, about 15 deg per joint around its
  // reference configuration) under PD and feed-forward, recorded and read back by a study (the
  // plant integrated at rtol 1e-13 with a smooth (tanh) Coulomb friction: didim's floor is the
  // plant's integration error, 1.5e-5 at the default 1e-8, 2.7e-9 at 1e-12, 1.2e-7 with a
  // sign(qd) Coulomb; tests/models/closed_chain_loop_test.cpp)
  auto robot = exid_test::robot("palletizer");
  exid::Samples ref = cltest::reference(robot->dof(), 2.0);
  ref.q *= 0.25;
  ref.qd *= 0.25;
  ref.qdd *= 0.25;
  ref.q.col(2).array() += M_PI / 2;  // joint5 (measured coordinate 3) at 90 deg
  const exid::Dataset d = mtest::simulate(
      robot,
      "{controller: pd_feedforward, kp: 4000, kd: 400, sample_period_s: 0.005, rtol: 1e-13, "
      "atol: 1e-15, coulomb: tanh, coulomb_velocity_scale: 0.05}",
      7, &ref);
  const std::filesystem::path dir = exid_cli::freshTempDir("exid_closed_study_", "loop");
  cltest::writeReference(ref, dir / "reference.csv");
  mtest::writeCsv(d, dir / "rec.csv");
  const std::string loop =
      "reference_file: " + (dir / "reference.csv").string() + ", " + cltest::gains(d.meta);
  for (const std::string& est :
       {"{type: didim, params: {" + loop + ", rtol: 1e-13, atol: 1e-15, step_tolerance: 1e-12}}",
        "{type: iv, params: {" + loop + "}}"}) {
    const std::string study =
        "robot: {type: palletizer}\n"
        "model: {type: differential, params: {rotor_inertia: true, viscous: true, coulomb: true, "
        "offset: true, coulomb_smoothing_rad_s: [0.05]}}\n"
        "experiment: {type: csv, params: {file: " +
        (dir / "rec.csv").string() + "}}\nestimator: " + est + "\n";
    exid::StudyConfig cfg =
        exid::parseStudy(study, "closed_loop.yaml", exid_test::sourceDir(), exid_test::registry());
    exid::RunOptions o;
    o.out_dir = dir / ("out_" + est.substr(7, 5));
    const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), o);
    ASSERT_TRUE(r.ok) << est << ": " << r.message;
    // a recording carries no truth: the estimate against the robot's own (nominal) base
    // parameters, which the plant simulated
    double err2 = 0, tru2 = 0;
    int count = 0;
    for (const auto& [v, nom] : cltest::estimateAndNominal(o.out_dir)) {
      err2 += (v - nom) * (v - nom);
      tru2 += nom * nom;
      ++count;
    }
    EXPECT_EQ(count, 38);  // 25 inertial base parameters + Ia, Fc, Fv, OFF of the 4 drives - 3
    const double err = std::sqrt(err2 / tru2);
    std::cout << "  " << est.substr(0, 12) << ": parameters " << err << "\n";
    RecordProperty(est.substr(7, 5), std::to_string(err));
    EXPECT_LT(err, 1e-9) << est;
  }
}

TEST(ClosedChainStudy, PalletizerIdentifiesWithTheEnergyModel) {
  // the `integral` (energy) model: the tree's energy at q = phi(qa), qd = G qd_a is the
  // mechanism's
  const std::string study =
      "robot: {type: palletizer}\n"
      "model: {type: integral, params: {rotor_inertia: true, offset: true, window_s: 0.05}}\n"
      "experiment: {type: simulate, params: {period_s: 10, harmonics: 5, duration_s: 10, "
      "sample_period_s: 0.002, output_qd_qdd: true}}\n"
      "estimator: {type: batch_ls}\n";
  exid::StudyConfig cfg = exid::parseStudy(study, "closed_integral.yaml", exid_test::sourceDir(),
                                           exid_test::registry());
  const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
  ASSERT_TRUE(r.ok) << r.message;
  std::ostringstream os;
  os << std::scientific << relErr(r);
  RecordProperty("integral", os.str());
  // (the energy model's noise-free floor is the quadrature of the friction work over the
  // windows: 1.8e-5 on the irp6 tree, 1.9e-4 here with the palletiser's larger Coulomb friction;
  // the energy itself is checked exactly in tests/robots/closed_chain_robots_test.cpp)
  EXPECT_LT(relErr(r), 1e-3);
}

TEST(ClosedChainStudy, ExcitationDesignByGradientRunsThroughTheLoops) {
  // the design's gradient through the loop constraints (dG/dqa): a designed palletiser study
  // identifies from its designed trajectory, as the same study on a tree does
  const std::string exc =
      "excitation:\n"
      "  trajectory: {type: fourier, params: {harmonics: 2, period_s: 4}}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt, params: {max_evaluations: 20, objective: log}}\n";
  // (objective: log, the scaling docs/excitation.md advises for cond: on J itself, NLopt's SLSQP
  // returns FTOL_REACHED after its first evaluation of this start with some last bits of the
  // kernels, and goes on with others)
  const exid::StudyResult r = run("palletizer", "{type: batch_ls}", exc, "{duration_s: 3.9}");
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LT(relErr(r), 1e-9);
  const exid::Json* x = r.summary.find("excitation");
  ASSERT_TRUE(x && x->find("criterion_final") && x->find("criterion_initial")) << r.summary.dump();
  EXPECT_LT(x->find("criterion_final")->asDouble(), x->find("criterion_initial")->asDouble());
  RecordProperty("cond_initial", std::to_string(x->find("criterion_initial")->asDouble()));
  RecordProperty("cond_final", std::to_string(x->find("criterion_final")->asDouble()));
  const exid::StudyResult tree = run("irp6", "{type: batch_ls}", exc, "{duration_s: 3.9}");
  EXPECT_TRUE(tree.ok) << tree.message;
  // on J itself SLSQP stops at this start (tests/excitation/optimizers_test.cpp,
  // Nlopt.ConvergedOnlyAfterAStep): the study says so, as a stop reason and a warning, never
  // "converged"; the design above has no such warning
  auto noProgressWarning = [](const exid::StudyResult& s) {
    const exid::Json* w = s.summary.find("warnings");
    return w && w->dump(0).find("made no progress") != std::string::npos;
  };
  EXPECT_FALSE(noProgressWarning(r)) << r.summary.find("warnings")->dump(0);
  std::string on_j = exc;
  on_j.replace(on_j.find(", objective: log"), 16, "");
  const exid::StudyResult stuck = run("palletizer", "{type: batch_ls}", on_j, "{duration_s: 3.9}");
  ASSERT_TRUE(stuck.ok) << stuck.message;
  EXPECT_TRUE(noProgressWarning(stuck)) << stuck.summary.find("warnings")->dump(0);
  EXPECT_EQ(
      stuck.summary.find("excitation")->find("stop_reason")->asString().rfind("no progress", 0),
      0u);
}

TEST(ClosedChainStudy, PalletizerVarproAndGainsLs) {
  // varpro: the friction's tanh width (the model's nonlinear parameter) fitted with the base
  // parameters, from a start twice the plant's; gains_ls: the load-dependent Coulomb columns
  // (the plant has none: FcL = 0) fitted by Levenberg-Marquardt with the recorded torque in them
  const std::string sim =
      "experiment: {type: simulate, params: {period_s: 10, harmonics: 5, duration_s: 10, "
      "sample_period_s: 0.005";
  for (const auto& [model, est] : std::vector<std::pair<std::string, std::string>>{
           {"{rotor_inertia: true, viscous: true, coulomb: true, offset: true, "
            "coulomb_smoothing_rad_s: [0.1]}",
            "{type: varpro}"},
           {"{rotor_inertia: true, viscous: true, coulomb: true, offset: true, "
            "coulomb_load: true}",
            "{type: gains_ls}"}}) {
    const std::string exp =
        sim + (est == "{type: varpro}" ? ", coulomb: tanh, coulomb_velocity_scale: 0.05" : "") +
        "}}\n";
    const std::string study =
        "robot: {type: palletizer}\nmodel: {type: differential, params: " + model + "}\n" + exp +
        "estimator: " + est + "\n";
    exid::StudyConfig cfg = exid::parseStudy(study, "closed_nonlinear.yaml", exid_test::sourceDir(),
                                             exid_test::registry());
    const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
    ASSERT_TRUE(r.ok) << est << ": " << r.message;
    std::ostringstream os;
    os << std::scientific << relErr(r);
    std::cout << "  " << est << ": param_rel_err " << os.str() << "\n";
    RecordProperty(est, os.str());
    EXPECT_LT(relErr(r), 1e-9) << est;
  }
}
