// Shipped robot descriptions: every file loads; PUMA 560 URDF == DH; IRp-6 transmission;
// physical-consistency warnings and strict mode; URDF fixed-joint merging.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "exid/dh.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

namespace {

using exid::Body;
using exid::JointType;
using exid::LoadOptions;
using exid::Pose;
using exid::RobotModel;
using Vec10 = Eigen::Matrix<double, 10, 1>;

std::string robotFile(const std::string& rel) {
  return std::string(EXID_SOURCE_DIR) + "/robots/" + rel;
}

RobotModel load(const std::string& rel, std::vector<std::string>* warnings = nullptr,
                bool strict = false, bool urdf_dynamics = false) {
  LoadOptions o;
  o.strict = strict;
  o.urdf_dynamics_as_friction = urdf_dynamics;
  std::vector<std::string> sink;
  o.warnings = warnings ? warnings : &sink;
  return exid::loadRobotFile(robotFile(rel), o);
}

/// Independent forward kinematics: pose of every body frame in the base frame.
std::vector<Pose> bodyPoses(const RobotModel& m, const Eigen::VectorXd& q) {
  std::vector<Pose> X(static_cast<size_t>(m.dof()));
  for (int i = 0; i < m.dof(); ++i) {
    const Body& b = m.bodies[static_cast<size_t>(i)];
    Pose motion;
    if (b.type == JointType::Revolute) {
      motion.R = Eigen::AngleAxisd(q(i), b.axis).toRotationMatrix();
    } else {
      motion.p = q(i) * b.axis;
    }
    const Pose parent = b.parent < 0 ? Pose{} : X[static_cast<size_t>(b.parent)];
    X[static_cast<size_t>(i)] = parent * b.pre * motion * b.post;
  }
  return X;
}

Eigen::VectorXd randomConfig(const RobotModel& m, std::mt19937* rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd q(m.dof());
  for (int i = 0; i < m.dof(); ++i) {
    const auto& L = m.limits[static_cast<size_t>(i)];
    if (L.q_min > -1e100 && L.q_max < 1e100) {
      q(i) = 0.5 * (L.q_min + L.q_max) + 0.5 * (L.q_max - L.q_min) * u(*rng);
    } else {
      q(i) = 2.0 * u(*rng);
    }
  }
  return q;
}

TEST(RobotFiles, EveryShippedFileLoads) {
  const std::vector<std::pair<std::string, int>> files = {
      {"planar2r/planar2r.yaml", 2}, {"puma560/puma560.yaml", 6},   {"puma560/puma560.urdf", 6},
      {"irp6/irp6.yaml", 5},         {"stanford/stanford.yaml", 6}, {"panda/panda.yaml", 7}};
  for (const auto& [file, dof] : files) {
    SCOPED_TRACE(file);
    RobotModel m;
    ASSERT_NO_THROW(m = load(file));
    EXPECT_EQ(m.dof(), dof);
    EXPECT_EQ(static_cast<int>(m.limits.size()), dof);
    EXPECT_EQ(static_cast<int>(m.drives.size()), dof);
    EXPECT_NO_THROW(m.validateStructure());
    EXPECT_TRUE(m.inertialParameters().allFinite());
  }
}

TEST(RobotFiles, Planar2rMovesInAVerticalPlane) {
  const RobotModel m = load("planar2r/planar2r.yaml");
  // Both joint axes are the base z axis, perpendicular to gravity.
  const auto X = bodyPoses(m, Eigen::Vector2d(0.3, -0.7));
  EXPECT_NEAR(m.gravity.norm(), 9.81, 1e-12);
  EXPECT_NEAR(m.gravity.dot(Eigen::Vector3d::UnitZ()), 0.0, 1e-12);
  EXPECT_NEAR((X[1].R.col(2) - Eigen::Vector3d::UnitZ()).norm(), 0.0, 1e-12);
  // Tip at (cos q1 + cos(q1+q2), sin q1 + sin(q1+q2)).
  EXPECT_NEAR(X[1].p.x(), std::cos(0.3) + std::cos(-0.4), 1e-12);
  EXPECT_NEAR(X[1].p.y(), std::sin(0.3) + std::sin(-0.4), 1e-12);
  // Centre of mass of link 1 at mid-length.
  EXPECT_NEAR(m.bodies[0].inertia(6) / m.bodies[0].inertia(9), -0.5, 1e-12);
}

TEST(RobotFiles, PumaLoadsWithWarningsAndFailsWhenStrict) {
  std::vector<std::string> w;
  const RobotModel m = load("puma560/puma560.yaml", &w);
  auto has = [&](const std::string& link, const std::string& rule) {
    for (const auto& s : w) {
      if (s.find("puma560.yaml") != std::string::npos &&
          s.find("'" + link + "'") != std::string::npos && s.find(rule) != std::string::npos) {
        return true;
      }
    }
    return false;
  };
  std::string all;
  for (const auto& s : w) all += s + "\n";
  EXPECT_TRUE(has("link1", "triangle")) << all;
  EXPECT_TRUE(has("link3", "triangle")) << all;
  EXPECT_TRUE(has("link1", "zero mass")) << all;
  for (const std::string ok : {"link2", "link4", "link5", "link6"}) {
    EXPECT_FALSE(has(ok, "")) << all;
  }
  // Reflected rotor inertia Jm * G^2 and the friction conversion.
  EXPECT_NEAR(m.drives[0].rotor_inertia, 200e-6 * 62.6111 * 62.6111, 1e-12);
  EXPECT_NEAR(m.drives[0].coulomb + m.drives[0].offset, 62.6111 * 0.395, 1e-3);
  EXPECT_NEAR(-m.drives[0].coulomb + m.drives[0].offset, -62.6111 * 0.435, 1e-3);
  EXPECT_NEAR(m.limits[1].q_max, 225.0 * M_PI / 180.0, 1e-12);

  try {
    load("puma560/puma560.yaml", nullptr, true);
    FAIL() << "strict mode accepted the PUMA 560 data";
  } catch (const exid::Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("puma560.yaml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("link1"), std::string::npos) << msg;
    EXPECT_NE(msg.find("strict"), std::string::npos) << msg;
  }
  EXPECT_THROW(load("puma560/puma560.urdf", nullptr, true), exid::Error);
}

TEST(RobotFiles, WarningsGoToStderrWithoutASink) {
  testing::internal::CaptureStderr();
  exid::loadDhYaml(robotFile("puma560/puma560.yaml"));
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("triangle"), std::string::npos) << err;
  EXPECT_NE(err.find("link3"), std::string::npos) << err;
}

TEST(RobotFiles, PumaUrdfEqualsDh) {
  const RobotModel dh = load("puma560/puma560.yaml");
  // the shipped URDF carries the published friction in <dynamics> (read when asked)
  const RobotModel ur = load("puma560/puma560.urdf", nullptr, false, true);
  ASSERT_EQ(dh.dof(), ur.dof());
  EXPECT_EQ(ur.name, "puma560");
  for (int i = 0; i < 6; ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(dh.bodies[i].joint_name, ur.bodies[i].joint_name);
    EXPECT_EQ(dh.bodies[i].parent, ur.bodies[i].parent);
    const auto &a = dh.drives[i], &b = ur.drives[i];
    EXPECT_NEAR(a.rotor_inertia, b.rotor_inertia, 1e-12);
    EXPECT_NEAR(a.gear_ratio, b.gear_ratio, 1e-12);
    EXPECT_NEAR(a.coulomb, b.coulomb, 1e-12);
    EXPECT_NEAR(a.viscous, b.viscous, 1e-12);
    EXPECT_NEAR(a.offset, b.offset, 1e-12);
    EXPECT_NEAR(dh.limits[i].q_min, ur.limits[i].q_min, 1e-9);
    EXPECT_NEAR(dh.limits[i].q_max, ur.limits[i].q_max, 1e-9);
  }
  EXPECT_NEAR((dh.gravity - ur.gravity).norm(), 0.0, 1e-12);

  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::VectorXd q = randomConfig(dh, &rng);
    const auto Xd = bodyPoses(dh, q), Xu = bodyPoses(ur, q);
    for (int i = 0; i < 6; ++i) {
      SCOPED_TRACE(i);
      // Same body in the base frame: inertial parameters, and the joint axis line.
      const Vec10 pd = exid::transformInertial(dh.bodies[i].inertia, Xd[i]);
      const Vec10 pu = exid::transformInertial(ur.bodies[i].inertia, Xu[i]);
      EXPECT_LT((pd - pu).cwiseAbs().maxCoeff(), 1e-8) << pd.transpose() << "\n" << pu.transpose();
      // The DH frame is the URDF frame moved by Tx(a) Rx(alpha): same origin after a shift.
      const Pose rel = Xu[i].inverse() * Xd[i];
      EXPECT_NEAR(rel.p.y(), 0.0, 1e-9);
      EXPECT_NEAR(rel.p.z(), 0.0, 1e-9);
    }
  }
  // Torques (rigid body), through the dynamics library.
  auto dd = exid::makeDynamicsData(dh);
  auto du = exid::makeDynamicsData(ur);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::VectorXd q = randomConfig(dh, &rng);
    Eigen::VectorXd qd(6), qdd(6);
    for (int i = 0; i < 6; ++i) {
      qd(i) = n(rng);
      qdd(i) = n(rng);
    }
    const Eigen::VectorXd td = exid::inverseDynamics(dh, *dd, q, qd, qdd);
    const Eigen::VectorXd tu = exid::inverseDynamics(ur, *du, q, qd, qdd);
    EXPECT_LT((td - tu).cwiseAbs().maxCoeff(), 1e-8) << td.transpose() << "\n" << tu.transpose();
  }
}

TEST(RobotFiles, PumaGravityLoadMatchesTheToolbox) {
  // Corke, Robotics, Vision and Control (2011), sec. 9.2: p560.gravload(qn) with
  // qn = [0, pi/4, pi, 0, pi/4, 0] gives [0, 31.6399, 6.0351, 0, 0.0283, 0] N m.
  const RobotModel m = load("puma560/puma560.yaml");
  auto d = exid::makeDynamicsData(m);
  const Eigen::VectorXd qn = (Eigen::VectorXd(6) << 0, M_PI / 4, M_PI, 0, M_PI / 4, 0).finished();
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(6);
  const Eigen::VectorXd tau = exid::inverseDynamics(m, *d, qn, z, z);
  const Eigen::VectorXd expected =
      (Eigen::VectorXd(6) << 0, 31.6399, 6.0351, 0, 0.0283, 0).finished();
  EXPECT_LT((tau - expected).cwiseAbs().maxCoeff(), 1e-3) << tau.transpose();
}

TEST(RobotFiles, Irp6Transmission) {
  const RobotModel m = load("irp6/irp6.yaml");
  ASSERT_TRUE(m.hasTransmission());
  ASSERT_EQ(m.transmission.rows(), 5);
  // th2 = q2, th3 = q3 - q2, th4 = q4 - q3 (absolute angles measured).
  const Eigen::VectorXd qm = (Eigen::VectorXd(5) << 0.1, -1.2, 0.3, 0.5, 2.0).finished();
  const Eigen::VectorXd q = m.transmission * qm + m.transmission_offset;
  EXPECT_NEAR(q(0), 0.1, 1e-15);
  EXPECT_NEAR(q(1), -1.2, 1e-15);
  EXPECT_NEAR(q(2), 0.3 + 1.2, 1e-15);
  EXPECT_NEAR(q(3), 0.5 - 0.3, 1e-15);
  EXPECT_NEAR(q(4), 2.0, 1e-15);
  // Absolute angles: the upper arm's direction depends on q3 only, the wrist's on q4 only.
  const auto X = bodyPoses(m, q);
  const Eigen::Vector3d x3 = X[2].R.col(0);  // along the upper arm
  EXPECT_NEAR(std::atan2(-x3.z(), std::hypot(x3.x(), x3.y())), 0.3, 1e-9);
  // MRROC++ forward kinematics of the flange position (reference file).
  const double c1 = std::cos(0.1), s1 = std::sin(0.1);
  const double r = 0.455 * std::cos(-1.2) + 0.67 * std::cos(0.3) + 0.095 * std::cos(0.5);
  const Eigen::Vector3d p(
      c1 * r, s1 * r, 0.7 - 0.455 * std::sin(-1.2) - 0.67 * std::sin(0.3) - 0.095 * std::sin(0.5));
  EXPECT_LT((X[4].p - p).norm(), 1e-9) << X[4].p.transpose() << " vs " << p.transpose();
  // Approach vector a = [c4 c1, c4 s1, -s4].
  const Eigen::Vector3d a(std::cos(0.5) * c1, std::cos(0.5) * s1, -std::sin(0.5));
  EXPECT_LT((X[4].R.col(2) - a).norm(), 1e-9);
  // Joint limits: interval hull of the absolute-angle limits (th3 = q3 - q2).
  EXPECT_NEAR(m.limits[0].q_max, 2.9670597, 1e-12);
  EXPECT_NEAR(m.limits[2].q_min, -0.4363323 + 0.8726646, 1e-12);
  EXPECT_NEAR(m.limits[2].q_max, 0.6981317 + 2.2689280, 1e-12);
  EXPECT_NEAR(m.limits[4].q_min, -10.0, 1e-12);
  // Plausible inertial data: physically consistent, no warnings, strict passes.
  std::vector<std::string> w;
  load("irp6/irp6.yaml", &w, true);
  EXPECT_TRUE(w.empty());
  EXPECT_NEAR(m.drives[0].rotor_inertia, 1e-4 * 158 * 158, 1e-12);
}

TEST(RobotFiles, StanfordHasAPrismaticJoint3) {
  std::vector<std::string> w;
  const RobotModel m = load("stanford/stanford.yaml", &w);
  EXPECT_EQ(m.bodies[2].type, JointType::Prismatic);
  EXPECT_NEAR(m.limits[2].q_min, 12 * 0.0254, 1e-12);
  EXPECT_NEAR(m.drives[1].rotor_inertia, 2.193, 1e-12);
  // Moving joint 3 by dq moves the wrist by dq along z2.
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  q(2) = 0.5;
  const auto A = bodyPoses(m, q);
  q(2) = 0.7;
  const auto B = bodyPoses(m, q);
  EXPECT_NEAR((B[5].p - A[5].p).norm(), 0.2, 1e-12);
  EXPECT_LT((B[5].p - A[5].p - 0.2 * A[1].R.col(2)).norm(), 1e-12);
  bool link5 = false;
  for (const auto& s : w) link5 |= s.find("link5") != std::string::npos;
  EXPECT_TRUE(link5);  // [0.003, 0.0004, 0] violates the triangle inequality
}

TEST(RobotFiles, PandaModifiedDh) {
  std::vector<std::string> w;
  const RobotModel m = load("panda/panda.yaml", &w);
  EXPECT_EQ(m.dof(), 7);
  // Modified DH: frames at q = 0; flange at x = 0.088, z = 0.333 + 0.316 + 0.384 - 0.107.
  const auto X = bodyPoses(m, Eigen::VectorXd::Zero(7));
  const Pose flange = X[6] * m.sensor_pose;
  EXPECT_NEAR(flange.p.x(), 0.088, 1e-9);
  EXPECT_NEAR(flange.p.y(), 0.0, 1e-9);
  EXPECT_NEAR(flange.p.z(), 0.333 + 0.316 + 0.384 - 0.107, 1e-9);
  EXPECT_NEAR(m.bodies[3].inertia(9), 3.587895, 1e-12);
  EXPECT_NEAR(m.bodies[3].inertia(6), 3.587895 * -5.317e-02, 1e-12);
  EXPECT_NEAR(m.drives[5].viscous, -0.0132, 1e-12);
  EXPECT_NEAR(m.limits[3].q_max, -0.0698, 1e-12);
  EXPECT_NEAR(m.limits[6].qdd_max, 20, 1e-12);
  // Feasible parameters: the only warning is the published negative viscous friction of joint 6.
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("link6"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("negative"), std::string::npos) << w[0];
  EXPECT_NO_THROW(load("panda/panda.yaml", nullptr, true));  // inertias are consistent
}

TEST(RobotFiles, EmbeddedStringVariantsNameTheirSource) {
  try {
    exid::loadDhYamlString("convention: standard\nlinks:\n  - {a: x}\n", "inline.yaml (test)");
    FAIL();
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("inline.yaml (test):3"), std::string::npos) << e.what();
  }
}

}  // namespace
