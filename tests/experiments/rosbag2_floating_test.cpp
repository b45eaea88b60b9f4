// The rosbag2 experiment on a floating base: the base's IMU (sensor_msgs/msg/Imu, off the base
// origin and turned) and a contact's wrench (geometry_msgs/msg/WrenchStamped) from a bag give
// the dataset's base motion and contact signals; the simulated humanoid identifies from the bag
// as from the simulation; what is missing or contradictory is refused by name, and samples cut
// for the IMU's time range are counted.
#include <Eigen/Geometry>
#include <cmath>

#include "exid/floating_base.hpp"
#include "rosbag2_test_util.hpp"

namespace {

using namespace rbtest;

const char* kContact = "contact_link: l_shank, contact_pose: [0.03, 0, -0.36, 0, 0, 0]";
const char* kModel = "contact_links: [l_shank], contact_poses: [0.03, 0, -0.36, 0, 0, 0]";
// the IMU's frame in the base link's frame: off the origin and turned, so that the lever arm
// and the rotation both matter
const double kImuPose[6] = {0.05, -0.02, 0.1, 0.3, -0.2, 0.5};
const char* kImuPoseYaml = "[0.05, -0.02, 0.1, 0.3, -0.2, 0.5]";

std::shared_ptr<const exid::RobotModel> humanoid() { return exid_test::robot("humanoid"); }

Bytes imuMessage(std::int64_t ns, const Eigen::Vector3d& gyro, const Eigen::Vector3d& accel) {
  CdrWriter w;
  w.stamp(ns);
  w.str("imu_link");
  for (double v : {0.0, 0.0, 0.0, 1.0}) w.f64(v);  // orientation (not used)
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  for (int c = 0; c < 3; ++c) w.f64(gyro[c]);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  for (int c = 0; c < 3; ++c) w.f64(accel[c]);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  return w.b;
}

struct Floating {
  exid::Dataset d;  // the simulation: q, qd, qdd, tau, base (omega, alpha, f), contact
  std::vector<std::int64_t> ns;
};

const Floating& floating() {
  static const Floating f = [] {
    Floating r;
    r.d = mtest::simulate(humanoid(),
                          fmt::format("{{duration_s: 4, sample_period_s: 0.002, {}}}", kContact));
    for (int k = 0; k < r.d.size(); ++k) r.ns.push_back(kEpoch + std::llround(r.d.t[k] * 1e9));
    return r;
  }();
  return f;
}

// The bag: joint states, the IMU's readings (what an IMU at kImuPose measures of the simulated
// base motion) and the contact's wrench, at the same stamps; `imu_from` / `imu_to`: the IMU's
// messages only for samples [imu_from, imu_to).
fs::path floatingBag(const std::string& tag, int imu_from = 0, int imu_to = -1) {
  const Floating& F = floating();
  const exid::Dataset& d = F.d;
  const exid::Pose imu = exid::poseFromXyzRpy(kImuPose);
  BagSpec s;
  s.types = {{"/joint_states", "sensor_msgs/msg/JointState"},
             {"/imu", "sensor_msgs/msg/Imu"},
             {"/foot_ft", "geometry_msgs/msg/WrenchStamped"}};
  std::vector<std::string> names;
  for (int j = 0; j < humanoid()->dof(); ++j)
    names.push_back(
        humanoid()->bodies[static_cast<std::size_t>(humanoid()->actuatedJoint(j))].joint_name);
  if (imu_to < 0) imu_to = d.size();
  for (int k = 0; k < d.size(); ++k) {
    const std::int64_t ns = F.ns[static_cast<std::size_t>(k)];
    std::vector<double> q, tau;
    for (int j = 0; j < d.q.cols(); ++j) {
      q.push_back(d.q(k, j));
      tau.push_back(d.tau(k, j));
    }
    s.msgs.push_back({"/joint_states", ns, jointState(ns, names, q, {}, tau)});
    const Eigen::Vector3d w = d.base.row(k).segment<3>(0).transpose();
    const Eigen::Vector3d al = d.base.row(k).segment<3>(3).transpose();
    const Eigen::Vector3d f = d.base.row(k).segment<3>(6).transpose();
    // the accelerometer at r measures f + alpha x r + omega x (omega x r), in its own axes
    const Eigen::Vector3d f_imu = f + al.cross(imu.p) + w.cross(w.cross(imu.p));
    if (k >= imu_from && k < imu_to)
      s.msgs.push_back(
          {"/imu", ns + 100, imuMessage(ns, imu.R.transpose() * w, imu.R.transpose() * f_imu)});
    double c[6];
    for (int e = 0; e < 6; ++e) c[e] = d.contact(k, e);
    s.msgs.push_back({"/foot_ft", ns + 200, wrenchStamped(ns, c)});
  }
  return writeBag(tmpDir() / tag, s);
}

exid::Dataset readFloating(const fs::path& bag, const std::string& extra) {
  auto e =
      exid_test::create<exid::Experiment>("rosbag2", "{path: " + bag.string() + ", " + extra + "}");
  return e->run(humanoid(), nullptr, mtest::context());
}

std::string floatingError(const fs::path& bag, const std::string& extra,
                          std::shared_ptr<const exid::RobotModel> robot = humanoid()) {
  try {
    exid_test::create<exid::Experiment>("rosbag2", "{path: " + bag.string() + ", " + extra + "}")
        ->run(robot, nullptr, mtest::context());
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "(no error)";
}

const std::string kTopics =
    fmt::format("imu_topic: /imu, imu_pose_xyz_rpy: {}, contact_topics: [/foot_ft]", kImuPoseYaml);

}  // namespace

// The base motion read from the IMU equals the simulated one: omega and f (lever arm removed,
// axes turned) to rounding; alpha, the gyro's central difference at 500 Hz, to the difference
// formula's error. The contact's wrench is the simulated one.
TEST(Rosbag2Floating, TheImuAndTheContactGiveTheBaseMotionAndTheContactWrench) {
  const exid::Dataset& s = floating().d;
  const exid::Dataset d = readFloating(floatingBag("floating"), kTopics);
  ASSERT_EQ(d.size(), s.size());
  ASSERT_EQ(d.base.cols(), 9);
  ASSERT_EQ(d.contact.cols(), 6);
  EXPECT_LT((d.q - s.q).cwiseAbs().maxCoeff(), 1e-15);
  const auto rel = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
  };
  const double e_omega = rel(d.base.leftCols(3), s.base.leftCols(3));
  const double e_f = rel(d.base.rightCols(3), s.base.rightCols(3));
  // (the ends use one-sided formulas: compared inside)
  const Eigen::Index K = s.size();
  const double e_alpha = rel(d.base.middleCols(3, 3).middleRows(1, K - 2),
                             s.base.middleCols(3, 3).middleRows(1, K - 2));
  std::printf("[rosbag2 floating] omega %.2e, f %.2e, alpha %.2e (relative)\n", e_omega, e_f,
              e_alpha);
  EXPECT_LT(e_omega, 1e-14);
  EXPECT_LT(e_alpha, 1e-3);
  EXPECT_GT(e_alpha, 0.0);  // (a difference, not the simulation's own alpha)
  // f carries the lever arm's alpha x r: as close as alpha is, times |alpha| |r| / |f|
  EXPECT_LT(e_f, 1e-4);
  EXPECT_LT((d.contact - s.contact).cwiseAbs().maxCoeff(), 1e-12);
  const std::vector<std::string> sig = {"q", "tau", "base", "contact"};
  EXPECT_EQ(d.meta.find("signals")->dump(), exid::Json(sig).dump());
  EXPECT_EQ(acc(d, "outside_imu_range"), 0);
  EXPECT_EQ(acc(d, "imu_messages"), s.size());
  EXPECT_EQ(acc(d, "contact1_messages"), s.size());
  ASSERT_NE(d.meta.find("base_motion"), nullptr);
}

// A study of the bag (the positions differentiated, the IMU's alpha differentiated) identifies
// the humanoid's base parameters as closely as the same study of the simulation's own
// signals with the positions differentiated alike.
TEST(Rosbag2Floating, TheHumanoidIdentifiesFromTheBag) {
  const exid::Dataset d = readFloating(floatingBag("floating_id"),
                                       kTopics + ", differentiate_cutoff_hz: 40, trim_edges: 20");
  auto m = mtest::model("floating_base", std::string("{") + kModel + "}", humanoid());
  const Eigen::VectorXd truth = m->baseNominal();
  const exid::Estimate e = exid_test::create<exid::Estimator>("batch_ls", "{}")
                               ->estimate(*m, d, nullptr, mtest::context());
  const double err = (e.value - truth).cwiseAbs().maxCoeff() / truth.cwiseAbs().maxCoeff();
  std::printf("[rosbag2 floating] batch_ls from the bag: largest error / largest parameter %.2e\n",
              err);
  EXPECT_LT(err, 1e-3);
  // without the lever arm (the IMU said to sit at the base origin) the estimate is worse
  const exid::Dataset wrong =
      readFloating(floatingBag("floating_id_wrong"),
                   "imu_topic: /imu, imu_pose_xyz_rpy: [0, 0, 0, 0.3, -0.2, 0.5], contact_topics: "
                   "[/foot_ft], differentiate_cutoff_hz: 40, trim_edges: 20");
  const exid::Estimate ew = exid_test::create<exid::Estimator>("batch_ls", "{}")
                                ->estimate(*m, wrong, nullptr, mtest::context());
  const double err_w = (ew.value - truth).cwiseAbs().maxCoeff() / truth.cwiseAbs().maxCoeff();
  std::printf("[rosbag2 floating] with the IMU at the origin: %.2e\n", err_w);
  EXPECT_GT(err_w, 10 * err);
}

// Samples outside the IMU's time range are cut and counted, with a warning; none cut: none said.
TEST(Rosbag2Floating, SamplesOutsideTheImusRangeAreCountedAndWarned) {
  const int K = floating().d.size();
  const exid::Dataset d = readFloating(floatingBag("floating_cut", 100, K - 50), kTopics);
  EXPECT_EQ(acc(d, "outside_imu_range"), 150);  // samples 0..99 and the last 50
  EXPECT_EQ(d.size(), K - 150);
  const exid::Json* w = d.meta.find("warnings");
  ASSERT_NE(w, nullptr);
  EXPECT_NE(w->dump().find("outside the time range of imu_topic '/imu'"), std::string::npos);
  const exid::Dataset full = readFloating(floatingBag("floating"), kTopics);
  EXPECT_TRUE(full.meta.find("warnings") == nullptr ||
              full.meta.find("warnings")->dump().find("imu_topic") == std::string::npos);
}

TEST(Rosbag2Floating, MissingOrContradictorySettingsAreRefusedByName) {
  const fs::path bag = floatingBag("floating");
  std::string e = floatingError(bag, "imu_topic: /imu");
  EXPECT_NE(e.find("imu_pose_xyz_rpy"), std::string::npos) << e;
  EXPECT_NE(e.find("required with imu_topic"), std::string::npos) << e;
  e = floatingError(bag, std::string("imu_pose_xyz_rpy: ") + kImuPoseYaml);
  EXPECT_NE(e.find("without imu_topic"), std::string::npos) << e;
  e = floatingError(bag, kTopics, mtest::robot("puma560"));
  EXPECT_NE(e.find("fixed base"), std::string::npos) << e;
  e = floatingError(bag, fmt::format("imu_topic: /foot_ft, imu_pose_xyz_rpy: {}", kImuPoseYaml));
  EXPECT_NE(e.find("expected sensor_msgs/msg/Imu"), std::string::npos) << e;
  e = floatingError(bag, fmt::format("imu_topic: /imu, imu_pose_xyz_rpy: {}, contact_topics: "
                                     "[/imu]",
                                     kImuPoseYaml));
  EXPECT_NE(e.find("expected geometry_msgs/msg/WrenchStamped"), std::string::npos) << e;
  e = floatingError(bag, "contact_topics: [/foot_ft, /foot_ft]");
  EXPECT_NE(e.find("already used"), std::string::npos) << e;
  e = floatingError(bag, "contact_topics: [/joint_states]");
  EXPECT_NE(e.find("contact_topics[0]"), std::string::npos) << e;
}
