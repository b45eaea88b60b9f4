// Observation model `differential`: rows reproduce noise-free simulated torques, batch least
// squares recovers the true base parameters, fullDesignVjp matches finite differences.
#include <random>

#include "exid/drive.hpp"
#include "model_test_util.hpp"

namespace {

const char* kSim = "{rtol: 1e-10, atol: 1e-12, duration_s: 10}";

void checkRobot(const std::string& name, const std::string& params, int expect_base = -1) {
  auto r = mtest::robot(name);
  if (!r) {
    FAIL() << "robot " << name << " unavailable (its plugin did not load)";
  }
  const exid::Dataset d = mtest::simulate(r, kSim);
  auto m = mtest::model("differential", params, r);
  if (expect_base > 0) {
    EXPECT_EQ(m->numBase(), expect_base);
  }
  const mtest::Recovery rec = mtest::recover(*m, d);
  mtest::print((name + " differential " + params).c_str(), rec);
  EXPECT_LT(rec.rows_rel, 1e-9);
  EXPECT_LT(rec.est_rel, 1e-6);
}

// The models declare their capabilities: rows per sample (streamed in chunks by the estimators)
// or over windows, and the signals a dataset must carry.
TEST(Models, DeclareTheirRowsAndSignals) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> per_sample = {
      {"differential", {"q", "qd", "qdd", "tau"}},
      {"load_torque", {"q", "qd", "qdd", "tau"}},
      {"load_wrench", {"q", "qd", "qdd", "wrench"}}};
  for (const auto& [name, signals] : per_sample) {
    const exid::ModelSpecs sp = exid_test::create<exid::ObservationModel>(name)->specs();
    EXPECT_TRUE(sp.per_sample) << name;
    EXPECT_EQ(sp.required_signals, signals) << name;
  }
  EXPECT_FALSE(exid_test::create<exid::ObservationModel>("integral")->specs().per_sample);
}

TEST(Differential, PumaAllDriveTermsRecovered) { checkRobot("puma560", "{offset: true}"); }

TEST(Differential, PumaFrictionSubtracted40BaseParameters) {
  // The paper's approach: friction precomputed from the drive data and subtracted; the rotor
  // inertia would add 4 base parameters (40), so it is identified too here.
  checkRobot("puma560", "{friction: subtract, rotor_inertia: true}", 40);
}

TEST(Differential, PumaJointOneOnly) {
  // Paper eqn 3 with i = 1.
  checkRobot("puma560", "{joints: [1], friction: subtract}");
}

// The model reuses its dynamics workspaces from call to call; bound to another robot (other
// sizes), it gives what a model bound to that robot from the start gives, and again after
// going back (ASan in CI: no workspace of the first robot is used for the second).
TEST(Differential, ReboundToAnotherRobotItsDesignIsThatRobots) {
  const auto puma = mtest::robot("puma560"), panda = mtest::robot("panda");
  auto m = mtest::model("differential", "{}", puma);
  const exid::Samples sp = mtest::randomSamples(*puma, 4, 0.0, 3);
  const exid::Samples sq = mtest::randomSamples(*panda, 4, 0.0, 3);
  const Eigen::MatrixXd w_puma = m->design(sp);
  m->bind(panda, mtest::context(11));
  const Eigen::MatrixXd w_panda = m->design(sq);
  EXPECT_EQ(w_panda, mtest::model("differential", "{}", panda)->design(sq));
  m->bind(puma, mtest::context(11));
  EXPECT_EQ(m->design(sp), w_puma);
}

TEST(Differential, Panda) { checkRobot("panda", "{offset: true}"); }

TEST(Differential, Irp6) { checkRobot("irp6", "{offset: true}"); }

TEST(Differential, FrictionNoneIgnoresFrictionAndSubtractRemovesIt) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 2}");
  auto none = mtest::model("differential", "{friction: none, offset: true}", r);
  auto sub = mtest::model("differential", "{friction: subtract}", r);
  // 'none' on data with friction does not reproduce the torques; 'subtract' does.
  EXPECT_GT(mtest::recover(*none, d).rows_rel, 1e-3);
  EXPECT_LT(mtest::recover(*sub, d).rows_rel, 1e-9);
  EXPECT_EQ(none->fullNames().size(), 60u + 12u);  // Ia, OFF per joint
}

// The model's design VJP against finite differences, for each drive-term setting on robot r.
void expectExactVjp(const std::shared_ptr<const exid::RobotModel>& r, const std::string& name,
                    std::initializer_list<const char*> settings) {
  for (const char* p : settings) {
    auto m = mtest::model("differential", p, r);
    const double err = mtest::vjpError(*m, mtest::randomSamples(*r, 3, 0.01, 5), true);
    std::printf("[%s %s] VJP vs FD relative error %.2e\n", name.c_str(), p, err);
    EXPECT_LT(err, 1e-6) << name << " " << p;
  }
}

TEST(Differential, VjpMatchesFiniteDifferences) {
  for (const char* name : {"puma560", "panda", "irp6"}) {
    auto r = mtest::robot(name);
    if (!r) continue;
    expectExactVjp(r, name,
                   {"{offset: true}", "{joints: [1, 3], friction: subtract}",
                    "{rotor_inertia: true, coulomb_asymmetric: true, coulomb_smoothing_rad_s: "
                    "[1], stribeck: true, stribeck_velocity_rad_s: [2]}"});
  }
}

// The Staubli TX40 as the real studies read it: a coupled wrist (motor 6 turns with joints 5 and
// 6) under the drive terms of examples/real/tx40_varpro.yaml.
TEST(Differential, VjpMatchesFiniteDifferencesThroughACoupledWrist) {
  auto r = exid_test::robot("urdf",
                            "{file: data/staubli_tx40/urdf/tx40_mdh_modified.urdf, extension: "
                            "robots/tx40/tx40_exid.xml}");
  expectExactVjp(r, "tx40",
                 {"{}", "{rotor_inertia: true, coulomb: true, viscous: true}",
                  "{rotor_inertia: true, coulomb: true, viscous: true, coulomb_asymmetric: true, "
                  "coulomb_smoothing_rad_s: [1], stribeck: true, stribeck_velocity_rad_s: [2]}"});
}

// The torque at given full parameters (fullTorqueAt, which a simulation calls at every step):
// the design times them, and its derivatives those of the design's VJP (row by row), both
// exact, on the robots above and the TX40's coupled wrist, with every drive term; with the
// mass matrix alone, the same. Where the model cannot give it (not every joint's row, a torque
// column in phi) it says so.
TEST(Differential, TorqueAtParametersIsTheDesignTimesThemWithExactDerivatives) {
  std::vector<std::pair<std::string, std::shared_ptr<const exid::RobotModel>>> robots;
  for (const char* name : {"puma560", "panda"}) robots.emplace_back(name, mtest::robot(name));
  robots.emplace_back("tx40", exid_test::robot("urdf",
                                               "{file: data/staubli_tx40/urdf/"
                                               "tx40_mdh_modified.urdf, extension: "
                                               "robots/tx40/tx40_exid.xml}"));
  const std::vector<const char*> settings = {
      "{offset: true}", "{friction: subtract, rotor_inertia: true}",
      "{rotor_inertia: true, coulomb_asymmetric: true, coulomb_smoothing_rad_s: [1], stribeck: "
      "true, stribeck_velocity_rad_s: [2]}",
      "{rotor_inertia: true, coulomb_smoothing_rad_s: [0.5], stribeck: true, "
      "stribeck_velocity_rad_s: [0.3], stribeck_exponent: 1.5, drive_gains: true, "
      "drive_gains_scale: prior}"};
  std::mt19937_64 rng(3);
  std::normal_distribution<double> nd(0.0, 1.0);
  for (const auto& [name, r] : robots) {
    ASSERT_TRUE(r) << name;
    const int n = r->dof();
    for (const char* p : settings) {
      auto m = mtest::model("differential", p, r);
      const std::vector<std::string> names = m->fullNames();
      Eigen::VectorXd eta(static_cast<Eigen::Index>(m->nonlinearParameters().size()));
      for (Eigen::Index k = 0; k < eta.size(); ++k)
        eta[k] = m->nonlinearParameters()[static_cast<std::size_t>(k)].value * (1.0 + 0.2 * k);
      const exid::Samples s = mtest::randomSamples(*r, 4, 0.01, 7);
      for (int k = 0; k < s.size(); ++k) {
        exid::Samples one;
        one.t = Eigen::VectorXd::Zero(1);
        one.q = s.q.row(k);
        one.qd = s.qd.row(k);
        one.qdd = s.qdd.row(k);
        Eigen::VectorXd phi = m->fullNominal();
        for (Eigen::Index i = 0; i < phi.size(); ++i) {
          phi[i] *= 1.0 + 0.1 * nd(rng);
          if (exid::torqueColumnKind(names[static_cast<std::size_t>(i)]) != 0) phi[i] = 0.0;
        }
        const Eigen::MatrixXd W = m->fullDesignAt(one, eta, nullptr);
        const Eigen::VectorXd want = W * phi;
        Eigen::VectorXd tau, tau2;
        Eigen::MatrixXd dq, dqd, dqdd, M;
        const Eigen::VectorXd q = one.q.row(0).transpose(), qd = one.qd.row(0).transpose(),
                              qdd = one.qdd.row(0).transpose();
        ASSERT_TRUE(m->fullTorqueAt(q, qd, qdd, eta, phi, &tau, &dq, &dqd, &dqdd)) << name << p;
        const double scale = std::max(1.0, want.norm());
        EXPECT_LT((tau - want).norm() / scale, 1e-12) << name << " " << p;
        // the derivatives: row i is the VJP of row i of W phi
        for (int i = 0; i < n; ++i) {
          Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, phi.size());
          G.row(i) = phi.transpose();
          exid::Samples grad;
          m->fullDesignVjpAt(one, eta, G, &grad);
          const double gs = std::max(1.0, grad.q.norm() + grad.qd.norm() + grad.qdd.norm());
          EXPECT_LT((dq.row(i) - grad.q.row(0)).norm() / gs, 1e-11) << name << " " << p << " " << i;
          EXPECT_LT((dqd.row(i) - grad.qd.row(0)).norm() / gs, 1e-11) << name << " " << p;
          EXPECT_LT((dqdd.row(i) - grad.qdd.row(0)).norm() / gs, 1e-11) << name << " " << p;
        }
        ASSERT_TRUE(m->fullTorqueAt(q, qd, qdd, eta, phi, &tau2, nullptr, nullptr, &M));
        EXPECT_LT((tau2 - want).norm() / scale, 1e-12) << name << " " << p;
        EXPECT_LT((M - dqdd).norm() / std::max(1.0, dqdd.norm()), 1e-12) << name << " " << p;
      }
    }
  }
  // where the model does not give it
  auto r = mtest::robot("puma560");
  const exid::Samples s = mtest::randomSamples(*r, 1, 0.01, 7);
  const Eigen::VectorXd q = s.q.row(0).transpose(), qd = s.qd.row(0).transpose(),
                        qdd = s.qdd.row(0).transpose();
  Eigen::VectorXd tau;
  auto part = mtest::model("differential", "{joints: [1, 3]}", r);
  EXPECT_FALSE(part->fullTorqueAt(q, qd, qdd, Eigen::VectorXd(), part->fullNominal(), &tau, nullptr,
                                  nullptr, nullptr));
  auto gains = mtest::model("differential", "{drive_gains: true, drive_gains_scale: prior}", r);
  Eigen::VectorXd phi = gains->fullNominal();
  phi.tail(6).setConstant(0.1);  // the dK columns: the recorded torque's, not the model's
  EXPECT_FALSE(
      gains->fullTorqueAt(q, qd, qdd, Eigen::VectorXd(), phi, &tau, nullptr, nullptr, nullptr));
  EXPECT_THROW(gains->fullTorqueAt(q, qd, qdd, Eigen::VectorXd(), phi.head(10), &tau, nullptr,
                                   nullptr, nullptr),
               exid::Error);
}

TEST(Differential, ErrorsNameTheProblem) {
  auto r = mtest::robot("puma560");
  auto m = exid_test::create<exid::ObservationModel>("differential", "{joints: [7]}");
  try {
    m->bind(r, mtest::context());
    FAIL() << "expected an error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("joints: 7 is out of range"), std::string::npos)
        << e.what();
  }
  auto ok = mtest::model("differential", "{}", r);
  exid::Dataset d = mtest::simulate(r, "{duration_s: 0.5, output_qd_qdd: false}");
  try {
    ok->fullRows(d, mtest::context());
    FAIL() << "expected an error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("'qd'"), std::string::npos) << e.what();
  }
}

}  // namespace

// rows() and design() of a long dataset are built a block of samples at a time (about 1 MB of
// full rows each) and keep only the base columns: the same numbers, rows, equations and times
// as the base columns of the full rows of the whole dataset, for lengths around the block size.
TEST(Differential, RowsAndDesignInBlocksEqualTheBaseColumnsOfTheWholeFullRows) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential", "{offset: true}", r);
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 3, sample_period_s: 0.001}");
  for (int K : {1, 17, 259, 260, 261, 1000, d.size()}) {
    const exid::Dataset s = exid::sliceDataset(d, 0, K);
    const exid::Rows full = m->fullRows(s, mtest::context());
    const exid::Rows rows = m->rows(s, mtest::context());
    const Eigen::MatrixXd Wb = m->base().columns(full.W);
    ASSERT_EQ(rows.W.rows(), Wb.rows()) << K;
    ASSERT_EQ(rows.W.cols(), Wb.cols()) << K;
    EXPECT_EQ((rows.W - Wb).cwiseAbs().maxCoeff(), 0.0) << K;
    EXPECT_EQ((rows.y - full.y).cwiseAbs().maxCoeff(), 0.0) << K;
    EXPECT_EQ(rows.equation, full.equation) << K;
    EXPECT_EQ(rows.t, full.t) << K;
    EXPECT_EQ(rows.numEquations, full.numEquations) << K;
    EXPECT_EQ(rows.equation_names, full.equation_names) << K;
    const Eigen::MatrixXd D = m->design(s.samples());
    ASSERT_EQ(D.rows(), Wb.rows()) << K;
    EXPECT_EQ((D - m->base().columns(m->fullDesign(s.samples()))).cwiseAbs().maxCoeff(), 0.0) << K;
  }
}
