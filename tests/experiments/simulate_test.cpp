// Experiment `simulate`: integrators agree, references are tracked, the recorded torques satisfy
// the equations of motion, noise and quantisation are as requested, meta is filled.
#include <cmath>

#include "../models/model_test_util.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"

namespace {

TEST(Simulate, OwnFourierReferenceWithinLimitsAndMeta) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(r, "{}");
  EXPECT_EQ(d.size(), 1001);  // one period of 10 s at 100 Hz, both ends
  EXPECT_NEAR(d.t[d.size() - 1], 10.0, 1e-12);
  ASSERT_TRUE(d.facts.simulated);  // the plant's truth: the robot's own, no payload
  EXPECT_TRUE(d.facts.simulated->drive_terms);
  EXPECT_TRUE(d.facts.simulated->payload.empty());
  for (const char* key :
       {"integrator", "rtol", "atol", "steps", "seed", "noise", "controller", "reference"})
    EXPECT_TRUE(d.meta.contains(key)) << key;
  EXPECT_GT(d.meta.find("steps")->asInt(), 10);
  for (int j = 0; j < r->dof(); ++j) {
    const auto& L = r->limits[static_cast<std::size_t>(j)];
    EXPECT_GE(d.q.col(j).minCoeff(), L.q_min) << "joint " << j + 1;
    EXPECT_LE(d.q.col(j).maxCoeff(), L.q_max) << "joint " << j + 1;
    if (L.qd_max < 1e3) {
      EXPECT_LE(d.qd.col(j).cwiseAbs().maxCoeff(), L.qd_max) << "joint " << j + 1;
    }
  }
  // Computed torque with the true model tracks perfectly from a state on the reference.
  EXPECT_LT(d.meta.find("max_tracking_error_rad")->asDouble(), 1e-6);
}

TEST(Simulate, RecordedTorqueSatisfiesTheEquationsOfMotion) {
  auto r = mtest::robot("puma560");
  for (const char* ctl : {"computed_torque", "pd_feedforward"}) {
    const exid::Dataset d =
        mtest::simulate(r, std::string("{duration_s: 2, controller: ") + ctl + "}");
    auto data = exid::makeDynamicsData(*r);
    exid::DriveColumns all{true, true, true, true};
    double worst = 0;
    for (int k = 0; k < d.size(); ++k) {
      const Eigen::VectorXd tau =
          exid::actuatorTorque(*r, *data, all, d.q.row(k).transpose(), d.qd.row(k).transpose(),
                               d.qdd.row(k).transpose());
      worst = std::max(worst, (tau - d.tau.row(k).transpose()).cwiseAbs().maxCoeff());
    }
    std::printf("[%s] max |tau - ID(q, qd, qdd)| = %.2e N m, tracking error %.2e rad\n", ctl, worst,
                d.meta.find("max_tracking_error_rad")->asDouble());
    EXPECT_LT(worst, 1e-9 * d.tau.cwiseAbs().maxCoeff());
  }
}

TEST(Simulate, CvodeAndArkodeAgree) {
  auto r = mtest::robot("puma560");
  const std::string base =
      "{duration_s: 3, controller: pd_feedforward, kp: 25, kd: 10, coulomb: tanh, "
      "coulomb_velocity_scale: 0.01, rtol: 1e-10, atol: 1e-12, integrator: ";
  const exid::Dataset a = mtest::simulate(r, base + "cvode}");
  const exid::Dataset b = mtest::simulate(r, base + "arkode}");
  const double dq = (a.q - b.q).cwiseAbs().maxCoeff();
  std::printf("CVODE steps %lld, ARKODE steps %lld, max |q_cvode - q_arkode| = %.2e rad\n",
              static_cast<long long>(a.meta.find("steps")->asInt()),
              static_cast<long long>(b.meta.find("steps")->asInt()), dq);
  EXPECT_LT(dq, 1e-7);
}

TEST(Simulate, TracksAGivenReference) {
  auto r = mtest::robot("puma560");
  // A reference from another simulation's samples (coarser, 50 Hz), then re-simulated at 200 Hz.
  const exid::Dataset ref = mtest::simulate(r, "{duration_s: 4, sample_period_s: 0.02}", 5);
  exid::Samples s = ref.samples();
  const exid::Dataset d = mtest::simulate(r, "{sample_period_s: 0.005}", 99, &s);
  EXPECT_NEAR(d.t[d.size() - 1] - d.t[0], 4.0, 1e-12);
  EXPECT_EQ(d.size(), 801);
  // At the reference's knots the tracked positions equal the reference.
  double worst = 0;
  for (int k = 0; k < ref.size(); ++k)
    worst = std::max(worst, (d.q.row(4 * k) - ref.q.row(k)).cwiseAbs().maxCoeff());
  EXPECT_LT(worst, 1e-6);
  EXPECT_EQ(d.meta.find("reference")->find("type")->asString().rfind("excitation", 0), 0u);
}

TEST(Simulate, NoiseQuantisationAndRecordedSignals) {
  auto r = mtest::robot("puma560");
  const exid::Dataset clean =
      mtest::simulate(r, "{duration_s: 5, wrench: true, payload_mass_kg: 1.0}", 3);
  const exid::Dataset noisy =
      mtest::simulate(r,
                      "{duration_s: 5, wrench: true, payload_mass_kg: 1.0, noise_q_rad: 0.001, "
                      "noise_tau_Nm: 0.2, noise_wrench: [0.5, 0.05]}",
                      3);
  auto stdOf = [](const Eigen::MatrixXd& x) {
    const double mean = x.mean();
    return std::sqrt((x.array() - mean).square().sum() / (x.size() - 1));
  };
  EXPECT_NEAR(stdOf(noisy.q - clean.q), 0.001, 0.0001);
  EXPECT_NEAR(stdOf(noisy.tau - clean.tau), 0.2, 0.02);
  EXPECT_NEAR(stdOf(noisy.wrench.leftCols(3) - clean.wrench.leftCols(3)), 0.5, 0.05);
  EXPECT_NEAR(stdOf(noisy.wrench.rightCols(3) - clean.wrench.rightCols(3)), 0.05, 0.005);
  EXPECT_EQ(noisy.qd, clean.qd);  // true states recorded
  // A static payload of 1 kg: |f| = 9.81 N at rest-like moments; here check only it is finite.
  EXPECT_TRUE(noisy.wrench.allFinite());

  const exid::Dataset q =
      mtest::simulate(r, "{duration_s: 1, encoder_resolution_rad: 0.001, output_qd_qdd: false}");
  EXPECT_FALSE(q.hasVelocity());
  EXPECT_FALSE(q.hasAcceleration());
  EXPECT_TRUE(q.hasTorque());
  const Eigen::ArrayXXd steps = q.q.array() / 0.001;
  EXPECT_LT((steps - steps.round()).abs().maxCoeff(), 1e-6);
}

TEST(Simulate, StaticPayloadWrenchIsItsWeight) {
  // Reference at rest: the wrench the sensor exerts on a 2 kg payload balances gravity.
  auto r = mtest::robot("puma560");
  exid::Samples s;
  s.t = Eigen::VectorXd::LinSpaced(3, 0.0, 1.0);
  s.q = Eigen::MatrixXd::Zero(3, 6);
  s.q.col(1).setConstant(0.3);
  s.qd = Eigen::MatrixXd::Zero(3, 6);
  s.qdd = Eigen::MatrixXd::Zero(3, 6);
  const exid::Dataset d =
      mtest::simulate(r, "{wrench: true, payload_mass_kg: 2.0, drive_terms: false}", 1, &s);
  EXPECT_NEAR(d.wrench.row(0).head(3).norm(), 2.0 * 9.81, 1e-9);
}

TEST(Simulate, ErrorsAreClear) {
  auto r = mtest::robot("puma560");
  exid::Samples s;
  s.t = Eigen::VectorXd::LinSpaced(3, 0.0, 1.0);
  s.q = Eigen::MatrixXd::Zero(3, 6);
  s.qd = Eigen::MatrixXd::Zero(3, 6);
  s.qdd = Eigen::MatrixXd::Zero(3, 6);
  try {
    mtest::simulate(r, "{duration_s: 5}", 1, &s);
    FAIL();
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("exceeds the reference"), std::string::npos) << e.what();
  }
}

// A floating base's options on a fixed-base robot are refused by name (they would be ignored:
// a fixed base has no base motion or contact wrench to record); their defaults are accepted.
TEST(Simulate, AFloatingBasesOptionsAreRefusedOnAFixedBase) {
  auto r = mtest::robot("puma560");
  for (const char* opt :
       {"contact_link: link3", "base_omega_rad_s: 1", "base_acceleration_m_s2: 0.5",
        "contact_pose: [0, 0, 0.1, 0, 0, 0]", "noise_base: [0.01]", "noise_contact: [1, 0.1]"}) {
    try {
      mtest::simulate(r, std::string("{duration_s: 0.1, ") + opt + "}");
      ADD_FAILURE() << opt << ": no error";
    } catch (const exid::Error& e) {
      const std::string key = std::string(opt).substr(0, std::string(opt).find(':'));
      EXPECT_NE(std::string(e.what()).find(key + " set, but robot 'puma560' has a fixed base"),
                std::string::npos)
          << e.what();
    }
  }
  EXPECT_NO_THROW(mtest::simulate(r, "{duration_s: 0.1, base_omega_rad_s: 0.5, noise_base: [0]}"));
}

TEST(Simulate, IntegralRowsOnArkodeData) {
  // The energy balance holds on ARKODE data too (the integrator's accuracy shows in the rows).
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(
      r, "{duration_s: 10, integrator: arkode, rtol: 1e-11, atol: 1e-12, sample_period_s: 0.005}");
  auto m = mtest::model("integral", "{offset: true, window_s: 0.1}", r);
  const mtest::Recovery rec = mtest::recover(*m, d);
  mtest::print("integral on ARKODE data", rec);
  EXPECT_LT(rec.rows_rel, 1e-8);
}

}  // namespace

namespace {
// An integrator that cannot reach the next sample fails in exid's words (what happened, which
// key to change) with SUNDIALS' own text quoted, and prints nothing of its own on stderr.
TEST(Simulate, AnIntegratorFailureIsSaidInExidsWordsAndPrintsNothingOfItsOwn) {
  auto r = mtest::robot("puma560");
  for (const char* integrator : {"cvode", "arkode"}) {
    SCOPED_TRACE(integrator);
    testing::internal::CaptureStderr();
    std::string msg;
    try {
      (void)mtest::simulate(
          r, fmt::format("{{duration_s: 1, max_steps: 1, integrator: {}}}", integrator));
    } catch (const exid::Error& e) {
      msg = e.what();
    }
    const std::string err = testing::internal::GetCapturedStderr();
    ASSERT_FALSE(msg.empty()) << "one internal step per sample was enough";
    EXPECT_NE(msg.find("max_steps internal steps did not reach the next sample: raise max_steps"),
              std::string::npos)
        << msg;
    EXPECT_NE(msg.find("TOO_MUCH_WORK"), std::string::npos) << msg;
    EXPECT_EQ(err.find("ERROR]"), std::string::npos) << err;  // no "[CVODE ERROR]" of its own
  }
  // a reachable sample: no failure
  EXPECT_NO_THROW((void)mtest::simulate(r, "{duration_s: 0.2}"));
}
}  // namespace
