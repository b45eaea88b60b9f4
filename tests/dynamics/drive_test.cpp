// Actuator-side regressor: transmission and drive columns.
#include "exid/drive.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <tuple>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dh.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"

using namespace exid;
using namespace exid::testing;

namespace {
RobotModel coupled3() {
  // Vertical planar 3R with absolute-angle measurement: q1 = qm1, q2 = qm2 - qm1, q3 = qm3 - qm2.
  RobotModel m = serialDh({{JointType::Revolute, 0.5, 0, 0, 0},
                           {JointType::Revolute, 0.4, 0, 0, 0},
                           {JointType::Revolute, 0.3, 0, 0, 0.2}},
                          DhConvention::Standard);
  m.gravity = Eigen::Vector3d(0, -9.81, 0);
  std::mt19937 rng(50);
  for (auto& b : m.bodies) b.inertia = randomInertia(rng, 0.2);
  m.transmission = Eigen::MatrixXd(3, 3);
  m.transmission << 1, 0, 0, -1, 1, 0, 0, -1, 1;
  m.transmission_offset = Eigen::VectorXd::Constant(3, 0.1);
  for (int j = 0; j < 3; ++j) {
    m.drives[static_cast<size_t>(j)].rotor_inertia = 0.01 * (j + 1);
    m.drives[static_cast<size_t>(j)].coulomb = 0.3 + j;
    m.drives[static_cast<size_t>(j)].viscous = 0.05 * (j + 1);
    m.drives[static_cast<size_t>(j)].offset = -0.2 * j;
  }
  return m;
}
}  // namespace

TEST(Drive, NamesAndValues) {
  const RobotModel m = coupled3();
  DriveColumns all{true, true, true, true};
  const auto names = parameterNames(m, all);
  ASSERT_EQ(static_cast<int>(names.size()), 30 + 12);
  EXPECT_EQ(names[30], "Ia1");
  EXPECT_EQ(names[31], "Fc1");
  EXPECT_EQ(names[32], "Fv1");
  EXPECT_EQ(names[33], "OFF1");
  EXPECT_EQ(names[41], "OFF3");
  DriveColumns fv;
  fv.viscous = true;
  EXPECT_EQ(parameterNames(m, fv)[31], "Fv2");
  EXPECT_EQ(numParameters(m, fv), 33);
  EXPECT_DOUBLE_EQ(parameterValues(m, all)[32], 0.05);
}

TEST(Drive, CoupledTransmission) {
  const RobotModel m = coupled3();
  auto d = makeDynamicsData(m);
  std::mt19937 rng(51);
  DriveColumns all{true, true, true, true};
  Eigen::MatrixXd Y(3, numParameters(m, all));
  const Eigen::MatrixXd& T = m.transmission;
  for (int s = 0; s < 20; ++s) {
    const Eigen::VectorXd qm = randomVec(rng, 3, 3.0), qdm = randomVec(rng, 3, 2.0),
                          qddm = randomVec(rng, 3, 5.0);
    Eigen::VectorXd q, qd, qdd;
    measuredToJoint(m, qm, qdm, qddm, &q, &qd, &qdd);
    EXPECT_LT((q - (T * qm + m.transmission_offset)).norm(), 1e-14);
    Eigen::VectorXd qm2, qdm2, qddm2;
    jointToMeasured(m, q, qd, qdd, &qm2, &qdm2, &qddm2);
    EXPECT_LT((qm2 - qm).norm() + (qdm2 - qdm).norm() + (qddm2 - qddm).norm(), 1e-12);
    const Eigen::VectorXd tau = refTorques(m, q, qd, qdd, m.inertialParameters());
    Eigen::VectorXd expect = T.transpose() * tau;
    for (int j = 0; j < 3; ++j) {
      const Drive& dr = m.drives[static_cast<size_t>(j)];
      expect[j] += dr.rotor_inertia * qddm[j] + dr.coulomb * (qdm[j] > 0 ? 1 : -1) +
                   dr.viscous * qdm[j] + dr.offset;
    }
    const Eigen::VectorXd tm = actuatorTorque(m, *d, all, qm, qdm, qddm);
    EXPECT_LT((tm - expect).cwiseAbs().maxCoeff(), 1e-10);
    actuatorRegressor(m, *d, all, qm, qdm, qddm, Y);
    EXPECT_LT((Y * parameterValues(m, all) - expect).cwiseAbs().maxCoeff(), 1e-10);
    // VJP vs finite differences
    const Eigen::MatrixXd G =
        Eigen::MatrixXd::NullaryExpr(3, Y.cols(), [&] { return randomVec(rng, 1)[0]; });
    Eigen::VectorXd gq, gqd, gqdd;
    actuatorRegressorVjp(m, *d, all, qm, qdm, qddm, G, &gq, &gqd, &gqdd);
    const double h = 1e-6;
    for (int k = 0; k < 3; ++k) {
      Eigen::VectorXd x[3] = {qm, qdm, qddm};
      const Eigen::VectorXd* g[3] = {&gq, &gqd, &gqdd};
      for (int w = 0; w < 3; ++w) {
        Eigen::VectorXd a[3] = {x[0], x[1], x[2]}, b[3] = {x[0], x[1], x[2]};
        a[w][k] += h;
        b[w][k] -= h;
        actuatorRegressor(m, *d, all, a[0], a[1], a[2], Y);
        const double fa = (G.array() * Y.array()).sum();
        actuatorRegressor(m, *d, all, b[0], b[1], b[2], Y);
        const double fb = (G.array() * Y.array()).sum();
        EXPECT_NEAR((*g[w])[k], (fa - fb) / (2 * h), 1e-6 * (1 + std::abs((*g[w])[k])));
      }
    }
  }
}

TEST(Drive, IdentityTransmissionMatchesTorqueRegressor) {
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  std::mt19937 rng(52);
  const Eigen::VectorXd q = randomVec(rng, 6), qd = randomVec(rng, 6), qdd = randomVec(rng, 6);
  Eigen::MatrixXd Y(6, 60), Ya(6, 60);
  torqueRegressor(m, *d, q, qd, qdd, Y);
  actuatorRegressor(m, *d, {}, q, qd, qdd, Ya);
  EXPECT_EQ((Y - Ya).cwiseAbs().maxCoeff(), 0.0);
}

// actuatorRegressors: the rows of K samples, each the bits actuatorRegressor gives for that
// sample alone: with drive columns (the lane path) and with a coupled transmission (sample by
// sample).
TEST(Drive, ActuatorRegressorsSameBitsAsOneSampleAtATime) {
  std::mt19937 rng(61);
  RobotModel plain = panda();
  for (std::size_t j = 0; j < plain.drives.size(); ++j) {
    plain.drives[j].coulomb = 0.5;
    plain.drives[j].viscous = 0.1;
  }
  const DriveColumns all{true, true, true, true};
  for (const RobotModel& m : {plain, coupled3()}) {
    auto d = makeDynamicsData(m);
    const int n = m.dof(), P = numParameters(m, all);
    const int K = 6;
    Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n);
    for (int k = 0; k < K; ++k) {
      Q.row(k) = randomVec(rng, n, 2.0).transpose();
      QD.row(k) = randomVec(rng, n, 1.5).transpose();
      QDD.row(k) = randomVec(rng, n, 4.0).transpose();
    }
    QD(2, 0) = 0.0;  // the Coulomb column's sign at rest
    Eigen::MatrixXd one(K * n, P), Yk(n, P);
    for (int k = 0; k < K; ++k) {
      actuatorRegressor(m, *d, all, Q.row(k).transpose(), QD.row(k).transpose(),
                        QDD.row(k).transpose(), Yk);
      one.middleRows(k * n, n) = Yk;
    }
    Eigen::MatrixXd Y = Eigen::MatrixXd::Constant(K * n, P, 7.0);
    actuatorRegressors(m, *d, all, Q, QD, QDD, Y);
    EXPECT_EQ(0, std::memcmp(Y.data(), one.data(), sizeof(double) * Y.size()))
        << m.name << ": largest difference " << (Y - one).cwiseAbs().maxCoeff();
    Eigen::MatrixXd Ybad(K * n, P - 1);
    EXPECT_THROW(actuatorRegressors(m, *d, all, Q, QD, QDD, Ybad), Error);
  }
}

// actuatorRegressorVjps: each sample's gradients the bits actuatorRegressorVjp gives for that
// sample alone, with drive columns and with a coupled transmission, whatever the sample count
// (over several blocks of 16 too); null outputs are skipped.
TEST(Drive, ActuatorRegressorVjpsSameBitsAsOneSampleAtATime) {
  std::mt19937 rng(62);
  RobotModel plain = panda();
  for (std::size_t j = 0; j < plain.drives.size(); ++j) {
    plain.drives[j].coulomb = 0.5;
    plain.drives[j].viscous = 0.1;
  }
  const DriveColumns all{true, true, true, true};
  for (const RobotModel& m : {plain, coupled3()}) {
    auto d = makeDynamicsData(m);
    const int n = m.dof(), P = numParameters(m, all);
    for (int K : {1, 5, 67}) {
      Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n);
      for (int k = 0; k < K; ++k) {
        Q.row(k) = randomVec(rng, n, 2.0).transpose();
        QD.row(k) = randomVec(rng, n, 1.5).transpose();
        QDD.row(k) = randomVec(rng, n, 4.0).transpose();
      }
      const Eigen::MatrixXd G =
          Eigen::MatrixXd::NullaryExpr(K * n, P, [&] { return randomVec(rng, 1)[0]; });
      Eigen::MatrixXd a1(K, n), b1(K, n), c1(K, n);
      Eigen::VectorXd a, b, c;
      for (int k = 0; k < K; ++k) {
        const Eigen::MatrixXd Gk = G.middleRows(k * n, n);
        actuatorRegressorVjp(m, *d, all, Q.row(k).transpose(), QD.row(k).transpose(),
                             QDD.row(k).transpose(), Gk, &a, &b, &c);
        a1.row(k) = a.transpose();
        b1.row(k) = b.transpose();
        c1.row(k) = c.transpose();
      }
      Eigen::MatrixXd A, B, C;
      actuatorRegressorVjps(m, *d, all, Q, QD, QDD, G, &A, &B, &C);
      for (const auto& [x, y, what] :
           {std::tuple(&A, &a1, "qm"), std::tuple(&B, &b1, "qdm"), std::tuple(&C, &c1, "qddm")}) {
        ASSERT_EQ(x->rows(), K);
        EXPECT_EQ(0, std::memcmp(x->data(), y->data(), sizeof(double) * y->size()))
            << m.name << " K=" << K << " d/d" << what << ": largest difference "
            << (*x - *y).cwiseAbs().maxCoeff();
      }
      Eigen::MatrixXd only;
      actuatorRegressorVjps(m, *d, all, Q, QD, QDD, G, nullptr, nullptr, &only);
      EXPECT_EQ(0, std::memcmp(only.data(), c1.data(), sizeof(double) * c1.size())) << m.name;
    }
    Eigen::MatrixXd out;
    const Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(2, n);
    EXPECT_THROW(actuatorRegressorVjps(m, *d, all, Z, Z, Z, Eigen::MatrixXd::Zero(2 * n, P - 1),
                                       &out, nullptr, nullptr),
                 Error);
    EXPECT_THROW(actuatorRegressorVjps(m, *d, all, Z, Eigen::MatrixXd::Zero(3, n), Z,
                                       Eigen::MatrixXd::Zero(2 * n, P), &out, nullptr, nullptr),
                 Error);
  }
}
