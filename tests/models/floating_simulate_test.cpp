// The `simulate` experiment's closed loop on a floating base: the shipped humanoid's joints
// under PD and feed-forward (controller: pd_feedforward) while its base moves along the
// prescribed harmonics and the sensor between the base link and its mount carries the contact
// wrench that balances the base rows (a contact on a limb is refused under pd_feedforward: the
// joints' torques are the controller's and cannot hold the prescribed base motion). The recording,
// written as CSV and read back by a study (`csv`), gives didim and iv (reference_file and the
// meta's pd_gains) the humanoid's base parameters; its joints do not follow the reference, and the
// rows of the floating regressor (not the inverse dynamics the plant integrates) hold on it;
// computed_torque still tracks exactly; what a floating base does not simulate is refused by name.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "closed_loop_test_util.hpp"
#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"
#include "exid/sampled_reference.hpp"
#include "exid/tables.hpp"
#include "exid_test.hpp"
#include "model_test_util.hpp"

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// the sensor between the base link and its mount, 0.12 m below the base origin, turned 0.3 rad
const char* kContact = "contact_link: torso, contact_pose: [0.02, 0, -0.12, 0, 0, 0.3]";
// the model with the drives' columns; its Coulomb law is the plant's (tanh, 0.05 rad/s)
const char* kModel =
    "{rows: all, contact_links: [torso], contact_poses: [0.02, 0, -0.12, 0, 0, 0.3], "
    "rotor_inertia: true, coulomb: true, viscous: true, "
    "coulomb_smoothing_rad_s: [0.05]}";
// the plant's Coulomb law (the feed-forward's is sign(qdr): the joints leave the reference)
const char* kPlant = "coulomb: tanh, coulomb_velocity_scale: 0.05";

// The shipped humanoid's URDF with drives on its ten joints (an <exid> companion in a fresh
// folder): `robot` yaml for a study, and the model.
struct Humanoid {
  std::string yaml;
  std::shared_ptr<const exid::RobotModel> robot;
};

Humanoid humanoidWithDrives() {
  const std::filesystem::path dir = exid_cli::freshTempDir("exid_floating_simulate_", "robot");
  std::ofstream x(dir / "drives.xml");
  x << "<exid>\n";
  int j = 0;
  for (const char* joint : {"l_hip_roll", "l_hip_pitch", "l_knee", "r_hip_roll", "r_hip_pitch",
                            "r_knee", "l_shoulder", "l_elbow", "r_shoulder", "r_elbow"}) {
    x << fmt::format("  <drive joint=\"{}\" rotor_inertia=\"{}\" coulomb=\"{}\" viscous=\"{}\"/>\n",
                     joint, 0.01 + 0.002 * j, 0.2 + 0.03 * j, 0.05 + 0.01 * j);
    ++j;
  }
  x << "</exid>\n";
  x.close();
  Humanoid h;
  h.yaml = "{file: " + (exid_test::sourceDir() / "robots/humanoid/humanoid.urdf").string() +
           ", extension: " + (dir / "drives.xml").string() + "}";
  h.robot = exid_test::robot("urdf", h.yaml);
  return h;
}

// cltest::reference's sums of sines scaled by 0.5 (about 30 deg per joint), `duration` s.
exid::Samples humanoidReference(int n, double duration) {
  exid::Samples ref = cltest::reference(n, duration);
  ref.q *= 0.5;
  ref.qd *= 0.5;
  ref.qdd *= 0.5;
  return ref;
}

// `robot` simulated by `simulate` with `params` (the contact added) tracking the reference.
exid::Dataset humanoidRecording(const std::shared_ptr<const exid::RobotModel>& robot,
                                const exid::Samples& ref, const std::string& params,
                                const std::string& contact = kContact) {
  return mtest::simulate(robot, "{" + contact + ", sample_period_s: 0.005, " + params + "}", 7,
                         &ref);
}

// The error of a 0.1 s simulation with `params`, or "no error".
std::string refusal(const std::string& params, const std::string& contact = kContact) {
  auto robot = mtest::robot("humanoid");
  const exid::Samples ref = humanoidReference(robot->dof(), 0.1);
  try {
    humanoidRecording(robot, ref, params, contact);
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

// didim and iv from a pd_feedforward recording of the humanoid read back by a study: the base
// parameters to 1e-9 of the truth (noise-free; the plant integrated at rtol 1e-13).
TEST(FloatingSimulate, HumanoidPdRecordingIdentifiesWithDidimAndIvThroughAStudy) {
  const Humanoid h = humanoidWithDrives();
  auto robot = h.robot;
  const exid::Samples ref = humanoidReference(robot->dof(), 0.6);
  const exid::Dataset d =
      humanoidRecording(robot, ref,
                        std::string(kPlant) +
                            ", controller: pd_feedforward, kp: 400, kd: 40, rtol: 1e-13, "
                            "atol: 1e-15");
  const std::filesystem::path dir = exid_cli::freshTempDir("exid_floating_simulate_", "study");
  cltest::writeReference(ref, dir / "reference.csv");
  exid::writeCsvAtomic(dir / "rec.csv", exid::datasetTable(d));
  const int nb = mtest::model("floating_base", kModel, robot)->numBase();
  const std::string loop =
      "reference_file: " + (dir / "reference.csv").string() + ", " + cltest::gains(d.meta);
  // (didim from the least-squares start, one step: each simulation with its sensitivities to
  // the 110 base parameters takes seconds; fit_nonlinear: false keeps the model's Coulomb width,
  // the plant's)
  const std::vector<std::pair<std::string, std::string>> estimators = {
      {"didim", "{type: didim, params: {" + loop +
                    ", rtol: 1e-12, atol: 1e-14, max_iterations: 1, fit_nonlinear: false}}"},
      {"iv", "{type: iv, params: {" + loop + ", rtol: 1e-10, atol: 1e-12}}"}};
  for (const auto& [name, est] : estimators) {
    const std::string study = "robot: {type: urdf, params: " + h.yaml +
                              "}\nmodel: {type: floating_base, params: " + std::string(kModel) +
                              "}\n"
                              "experiment: {type: csv, params: {file: " +
                              (dir / "rec.csv").string() + "}}\nestimator: " + est + "\n";
    exid::StudyConfig cfg = exid::parseStudy(study, "floating_simulate.yaml",
                                             exid_test::sourceDir(), exid_test::registry());
    exid::RunOptions o;
    o.out_dir = dir / ("out_" + name);
    const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), o);
    ASSERT_TRUE(r.ok) << est << ": " << r.message;
    // the estimate against the robot's own base parameters (the plant's)
    double worst = 0.0, largest = 0.0;
    int count = 0;
    for (const auto& [v, nom] : cltest::estimateAndNominal(o.out_dir)) {
      worst = std::max(worst, std::abs(v - nom));
      largest = std::max(largest, std::abs(nom));
      ++count;
    }
    EXPECT_EQ(count, nb);
    const double err = worst / largest;
    std::printf(
        "[%s] humanoid pd_feedforward recording through a study: largest error / "
        "largest parameter %.2e\n",
        name.c_str(), err);
    RecordProperty(name, fmt::format("{:.3e}", err));
    EXPECT_LT(err, 1e-9) << est;
  }
}

// Under pd_feedforward the joints leave the reference (the meta's figure is the recording's),
// and the floating regressor's rows hold on the recording at the truth: Y_base pi = C_b w and
// Y_joint pi + drive terms = tau + C_j w at every sample, to rounding. computed_torque tracks
// exactly and its rows hold as well.
TEST(FloatingSimulate, PdFeedforwardLeavesTheReferenceAndItsRowsHold) {
  auto robot = humanoidWithDrives().robot;
  const int n = robot->dof();
  const exid::Samples ref = humanoidReference(n, 1.0);
  const int body = exid::floatingBodyIndex(*robot, "torso", "test");
  const double xyz_rpy[6] = {0.02, 0, -0.12, 0, 0, 0.3};
  const exid::Pose sensor = exid::poseFromXyzRpy(xyz_rpy);
  const VectorXd pi = exid::floatingParameters(*robot);
  for (const std::string ctl : {"pd_feedforward", "computed_torque"}) {
    const exid::Dataset d = humanoidRecording(
        robot, ref,
        std::string(kPlant) + ", controller: " + ctl +
            (ctl == "pd_feedforward" ? ", kp: 400, kd: 40, rtol: 1e-10, atol: 1e-12" : ""));
    double err = 0.0, row_base = 0.0, row_joint = 0.0, scale = 0.0;
    MatrixXd Y;
    for (int k = 0; k < d.size(); ++k) {
      VectorXd qr, qdr, qddr;
      exid::quinticHermite(ref, d.t[k], &qr, &qdr, &qddr);
      const VectorXd q = d.q.row(k).transpose();
      err = std::max(err, (qr - q).cwiseAbs().maxCoeff());
      exid::floatingRegressor(*robot, q, d.qd.row(k).transpose(), d.qdd.row(k).transpose(),
                              d.base.row(k).transpose(), Y);
      const MatrixXd C = exid::contactMap(*robot, q, body, sensor);
      const VectorXd w = d.contact.row(k).transpose();
      VectorXd f = Y * pi;
      for (int j = 0; j < n; ++j) {  // the plant's drive terms (tanh Coulomb)
        const exid::Drive& D = robot->drives[static_cast<std::size_t>(j)];
        const double v = d.qd(k, j);
        f[6 + j] += D.rotor_inertia * d.qdd(k, j) + D.coulomb * std::tanh(v / 0.05) +
                    D.viscous * v + D.offset;
      }
      row_base = std::max(row_base, (f.head(6) - C.topRows(6) * w).cwiseAbs().maxCoeff());
      row_joint = std::max(
          row_joint,
          (f.tail(n) - C.bottomRows(n) * w - d.tau.row(k).transpose()).cwiseAbs().maxCoeff());
      scale = std::max(scale, d.tau.row(k).cwiseAbs().maxCoeff());
    }
    const double meta_err = d.meta.find("max_tracking_error_rad")->asDouble();
    std::printf(
        "[%s] tracking error %.3e rad (meta %.3e); rows' residual: base %.2e, joints "
        "%.2e (torques up to %.1f N m)\n",
        ctl.c_str(), err, meta_err, row_base, row_joint, scale);
    EXPECT_LT(row_base, 1e-9 * scale) << ctl;
    EXPECT_LT(row_joint, 1e-9 * scale) << ctl;
    EXPECT_EQ(d.meta.find("controller")->asString(), ctl);
    if (ctl == "pd_feedforward") {
      EXPECT_GT(err, 1e-3);
      EXPECT_NEAR(meta_err, err, 1e-12 + 1e-9 * err);
      ASSERT_NE(d.meta.find("pd_gains"), nullptr);
      EXPECT_EQ(d.meta.find("pd_gains")->find("kp_Nm_per_rad")->size(),
                static_cast<std::size_t>(n));
    } else {
      EXPECT_LT(err, 1e-12);
      EXPECT_EQ(meta_err, 0.0);
      EXPECT_EQ(d.meta.find("pd_gains"), nullptr);
      EXPECT_NE(d.meta.find("floating_base")->asString().find("exactly"), std::string::npos);
    }
  }
}

// What the floating base's simulation does not use is refused by name, never ignored: the
// integrator's settings with computed_torque (nothing is integrated), the wrist wrench's noise.
// The same settings with pd_feedforward, and no noise_wrench, are accepted.
TEST(FloatingSimulate, OptionsItDoesNotUseAreRefusedByName) {
  for (const char* key : {"rtol: 1e-12", "atol: 1e-13", "max_steps: 50", "integrator: arkode"}) {
    const std::string m = refusal(std::string("controller: computed_torque, ") + key);
    const std::string name = std::string(key).substr(0, std::string(key).find(':'));
    EXPECT_NE(m.find(name + " set, but controller: computed_torque on a floating base"),
              std::string::npos)
        << key << ": " << m;
  }
  EXPECT_EQ(refusal("controller: pd_feedforward, rtol: 1e-9, integrator: arkode"), "no error");
  EXPECT_EQ(refusal("controller: computed_torque"), "no error");
  std::string m = refusal("noise_wrench: [0.1]");
  EXPECT_NE(m.find("noise_wrench is the wrist wrench's noise"), std::string::npos) << m;
  // a contact on a limb: the inverse-dynamics simulation takes it, the closed loop refuses it
  const std::string shank = "contact_link: l_shank, contact_pose: [0.03, 0, -0.36, 0, 0, 0]";
  EXPECT_EQ(refusal("controller: computed_torque", shank), "no error");
  m = refusal("controller: pd_feedforward", shank);
  EXPECT_NE(m.find("contact_link = 'l_shank': controller: pd_feedforward needs the contact on the "
                   "base link ('torso')"),
            std::string::npos)
      << m;
}
