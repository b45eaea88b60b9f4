// Payload wrench regressor and payload torque regressor.
#include <gtest/gtest.h>

#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"

using namespace exid;
using namespace exid::testing;

namespace {
Eigen::Matrix<double, 10, 1> toPi(
    const Eigen::Matrix<double, 10, 1>& phi) {  // payload order -> pi order
  Eigen::Matrix<double, 10, 1> p;
  p << phi.segment<6>(4), phi.segment<3>(1), phi[0];
  return p;
}
Eigen::Matrix<double, 10, 1> randomPhi(std::mt19937& rng) {
  const Eigen::Matrix<double, 10, 1> p = randomInertia(rng, 0.1);
  Eigen::Matrix<double, 10, 1> phi;
  phi << p[9], p.segment<3>(6), p.head<6>();
  return phi;
}
std::vector<RobotModel> robots(std::mt19937& rng) {
  std::vector<RobotModel> r = {puma560Standard(), puma560Akb(), panda()};
  r[0].sensor_pose = randomPose(rng, 0.1);
  for (int t = 0; t < 8; ++t) r.push_back(randomTree(rng, 1 + t, t % 2 == 1));
  return r;
}
}  // namespace

TEST(WrenchRegressor, EqualsNewtonEulerOfTheRigidPayload) {
  std::mt19937 rng(21);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    Eigen::Matrix<double, 6, 10> A;
    for (int s = 0; s < 20; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      const Eigen::Matrix<double, 10, 1> phi = randomPhi(rng);
      wrenchRegressor(m, *d, q, qd, qdd, A);
      const Eigen::Matrix<double, 6, 1> ref = refPayloadWrench(m, q, qd, qdd, phi);
      EXPECT_LT((A * phi - ref).cwiseAbs().maxCoeff(), 1e-10 * (1 + ref.cwiseAbs().maxCoeff()))
          << m.name;
    }
  }
}

TEST(WrenchRegressor, StaticPayloadWeighsMg) {
  RobotModel m = panda();
  auto d = makeDynamicsData(m);
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(7);
  Eigen::Matrix<double, 6, 10> A;
  wrenchRegressor(m, *d, z, z, z, A);
  // at rest the payload column of the force is -g in the sensor frame: norm g per kg
  const double norm = A.block<3, 1>(0, 0).norm();
  EXPECT_NEAR(norm, 9.81, 1e-12);
}

TEST(PayloadTorqueRegressor, EqualsTorquesWithPayloadMergedIntoSensorBody) {
  std::mt19937 rng(22);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    Eigen::MatrixXd Yp(n, 10);
    for (int s = 0; s < 20; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      const Eigen::Matrix<double, 10, 1> phi = randomPhi(rng);
      payloadTorqueRegressor(m, *d, q, qd, qdd, Yp);
      RobotModel merged = m;
      merged.bodies[static_cast<size_t>(m.sensorBody())].inertia +=
          transformInertial(toPi(phi), m.sensor_pose);
      const Eigen::VectorXd ref = refTorques(merged, q, qd, qdd, merged.inertialParameters()) -
                                  refTorques(m, q, qd, qdd, m.inertialParameters());
      EXPECT_LT((Yp * phi - ref).cwiseAbs().maxCoeff(), 1e-9 * (1 + ref.cwiseAbs().maxCoeff()))
          << m.name;
    }
  }
}
