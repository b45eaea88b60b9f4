// DH conversion, inertial helpers, validation and physical consistency.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dh.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"

using namespace exid;
using namespace exid::testing;

namespace {
Eigen::Matrix4d H(const Pose& P) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = P.R;
  T.topRightCorner<3, 1>() = P.p;
  return T;
}
Eigen::Matrix4d rz(double t) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(t, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}
Eigen::Matrix4d rx(double t) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(t, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return T;
}
Eigen::Matrix4d tz(double d) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T(2, 3) = d;
  return T;
}
Eigen::Matrix4d tx(double d) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T(0, 3) = d;
  return T;
}
}  // namespace

TEST(Dh, ForwardKinematicsMatchesTheDhProducts) {
  std::mt19937 rng(61);
  for (auto conv : {DhConvention::Standard, DhConvention::Modified}) {
    std::vector<DhRow> rows;
    for (int j = 0; j < 6; ++j) {
      const Eigen::VectorXd r = randomVec(rng, 4, 1.5);
      rows.push_back(
          {j == 2 || j == 4 ? JointType::Prismatic : JointType::Revolute, r[0], r[1], r[2], r[3]});
    }
    const RobotModel m = serialDh(rows, conv);
    EXPECT_NO_THROW(m.validateStructure());
    EXPECT_EQ(m.bodies[2].name, "link3");
    EXPECT_EQ(m.bodies[2].joint_name, "joint3");
    auto d = makeDynamicsData(m);
    for (int s = 0; s < 10; ++s) {
      const Eigen::VectorXd q = randomVec(rng, 6, 3.0);
      Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
      for (int j = 0; j < 6; ++j) {
        const DhRow& r = rows[static_cast<size_t>(j)];
        const bool rev = r.type == JointType::Revolute;
        const double th = r.theta + (rev ? q[j] : 0.0), dd = r.d + (rev ? 0.0 : q[j]);
        if (conv == DhConvention::Standard)
          T = T * rz(th) * tz(dd) * tx(r.a) * rx(r.alpha);
        else
          T = T * rx(r.alpha) * tx(r.a) * rz(th) * tz(dd);
        EXPECT_LT((H(bodyPose(m, *d, q, j)) - T).cwiseAbs().maxCoeff(), 1e-12);
      }
    }
  }
}

TEST(Dh, Puma560KnownPose) {
  // RTB: p560.fkine(qz) translation = [0.4521, -0.1501, 0.4318] (standard DH, no base offset).
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  const Pose X = bodyPose(m, *d, Eigen::VectorXd::Zero(6), 5);
  EXPECT_NEAR(X.p.x(), 0.4521, 1e-4);
  EXPECT_NEAR(X.p.y(), -0.15005, 1e-4);
  EXPECT_NEAR(X.p.z(), 0.4318, 1e-4);
}

TEST(Inertial, ComRoundTripAndTransform) {
  std::mt19937 rng(62);
  for (int s = 0; s < 20; ++s) {
    const Eigen::Matrix<double, 10, 1> pi = randomInertia(rng);
    double m;
    Eigen::Vector3d c;
    Eigen::Matrix3d Ic;
    comFromInertial(pi, &m, &c, &Ic);
    EXPECT_LT((inertialFromCom(m, c, Ic) - pi).cwiseAbs().maxCoeff(), 1e-12);
    const Pose A = randomPose(rng), B = randomPose(rng);
    // composition and inverse
    const auto p1 = transformInertial(transformInertial(pi, B), A);
    EXPECT_LT((p1 - transformInertial(pi, A * B)).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((transformInertial(transformInertial(pi, A), A.inverse()) - pi).cwiseAbs().maxCoeff(),
              1e-12);
    // against the COM path
    const Eigen::Matrix<double, 10, 1> viaCom =
        inertialFromCom(m, A.R * c + A.p, A.R * Ic * A.R.transpose());
    EXPECT_LT((transformInertial(pi, A) - viaCom).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_TRUE(checkPhysical(pi).ok);
  }
  EXPECT_THROW(comFromInertial(Eigen::Matrix<double, 10, 1>::Zero(), nullptr, nullptr, nullptr),
               Error);
}

TEST(Inertial, CheckPhysicalRules) {
  Eigen::Matrix<double, 10, 1> p =
      inertialFromCom(1.0, {0.1, 0, 0}, Eigen::Vector3d(1, 1, 1).asDiagonal());
  EXPECT_TRUE(checkPhysical(p).ok);
  auto neg = p;
  neg[9] = -1;
  EXPECT_EQ(checkPhysical(neg).rule, "negative mass");
  const auto notpsd = inertialFromCom(1.0, {0, 0, 0}, Eigen::Vector3d(1, 1, -0.1).asDiagonal());
  EXPECT_EQ(checkPhysical(notpsd).rule,
            "inertia about the centre of mass not positive semi-definite");
  const auto tri = inertialFromCom(1.0, {0, 0, 0}, Eigen::Vector3d(0.1, 0.1, 1.0).asDiagonal());
  EXPECT_FALSE(checkPhysical(tri).ok);
  EXPECT_NE(checkPhysical(tri).rule.find("triangle"), std::string::npos);
}

TEST(RobotModel, NamesAndValidation) {
  RobotModel m = puma560Standard();
  const auto names = m.inertialParameterNames();
  ASSERT_EQ(names.size(), 60u);
  EXPECT_EQ(names[0], "XX1");
  EXPECT_EQ(names[15], "ZZ2");
  EXPECT_EQ(names[59], "M6");
  EXPECT_EQ(m.inertialParameters().size(), 60);
  EXPECT_NO_THROW(m.validateStructure());
  auto expectThrow = [](const RobotModel& bad, const std::string& needle) {
    try {
      bad.validateStructure();
      ADD_FAILURE() << "no exception, expected " << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  RobotModel a = m;
  a.bodies[3].parent = 3;
  expectThrow(a, "link4");
  RobotModel b = m;
  b.bodies[2].axis = Eigen::Vector3d(1, 1, 0);
  expectThrow(b, "unit");
  RobotModel c = m;
  c.bodies[1].pre.R(0, 0) = 2;
  expectThrow(c, "orthonormal");
  RobotModel e = m;
  e.limits.pop_back();
  expectThrow(e, "limit");
  RobotModel f = m;
  f.transmission = Eigen::MatrixXd::Identity(5, 5);
  expectThrow(f, "transmission");
}
