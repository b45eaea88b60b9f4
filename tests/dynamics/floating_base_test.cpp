// Floating-base dynamics (exid/floating_base.hpp) against the independent reference: the same
// robot as a fixed-base chain with six massless virtual joints (tests/support/floating_reference),
// computed by the fixed-base regressor and by the plain Newton-Euler of dyn_reference.
#include "exid/floating_base.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "dyn_reference.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "floating_reference.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

double relErr(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / (1.0 + b.cwiseAbs().maxCoeff());
}

RobotModel floatingTree(std::mt19937& rng, int n) {
  RobotModel m = randomTree(rng, n);
  m.name = "floating_tree";
  m.floating_base = true;
  m.base.link = "torso";
  m.base.inertia = randomInertia(rng, 0.4);
  return m;
}

struct VirtualState {
  Eigen::Matrix<double, 6, 1> v, vd, vdd;
  Eigen::VectorXd q, qd, qdd, qv, qdv, qddv;
};

VirtualState randomState(std::mt19937& rng, int n) {
  VirtualState s;
  s.v = randomVec(rng, 6, 1.5);
  s.vd = randomVec(rng, 6, 2.0);
  s.vdd = randomVec(rng, 6, 5.0);
  s.q = randomVec(rng, n, 3.0);
  s.qd = randomVec(rng, n, 2.0);
  s.qdd = randomVec(rng, n, 5.0);
  s.qv = virtualCoordinates(s.v, s.q);
  s.qdv = virtualCoordinates(s.vd, s.qd);
  s.qddv = virtualCoordinates(s.vdd, s.qdd);
  return s;
}

}  // namespace

// Base rows and joint rows equal the virtual chain's fixed-base regressor: the virtual joints'
// rows are T * (base rows), the joint rows are the same; columns: the chain's without the 60 of
// the massless virtual bodies.
TEST(FloatingBase, RegressorEqualsVirtualChain) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 6; ++trial) {
    const int n = 1 + trial * 2;
    const RobotModel m = floatingTree(rng, n);
    const Eigen::Vector3d g_w(0.3, -0.2, -9.81);
    const RobotModel chain = virtualChain(m, g_w);
    auto d = makeDynamicsData(chain);
    Eigen::MatrixXd Yv(n + 7, 10 * (n + 7)), Yf;
    for (int s = 0; s < 8; ++s) {
      const VirtualState st = randomState(rng, n);
      const BaseMotion base = virtualBaseMotion(chain, st.qv, st.qdv, st.qddv);
      floatingRegressor(m, st.q, st.qd, st.qdd, base, Yf);
      ASSERT_EQ(Yf.rows(), 6 + n);
      ASSERT_EQ(Yf.cols(), 10 * (n + 1));
      torqueRegressor(chain, *d, st.qv, st.qdv, st.qddv, Yv);
      const Eigen::MatrixXd Yv_cols = Yv.rightCols(10 * (n + 1));
      const Eigen::Matrix<double, 6, 6> T = virtualRowMap(st.v);
      EXPECT_LT(relErr(T * Yf.topRows(6), Yv_cols.topRows(6)), 1e-12) << "trial " << trial;
      EXPECT_LT(relErr(Yf.bottomRows(n), Yv_cols.bottomRows(n)), 1e-12) << "trial " << trial;
      // T is invertible away from the Euler singularity: the base rows are determined
      EXPECT_GT(std::abs(T.determinant()), 1e-3);
    }
  }
}

// The recursive Newton-Euler pass (own parameters and given ones) against Y * pi_f, and against
// the plain base-frame Newton-Euler of dyn_reference on the virtual chain.
TEST(FloatingBase, InverseDynamicsEqualsRegressorAndReference) {
  std::mt19937 rng(12);
  for (int trial = 0; trial < 5; ++trial) {
    const int n = 2 + trial * 2;
    const RobotModel m = floatingTree(rng, n);
    const Eigen::Vector3d g_w(0.0, 0.0, -9.81);
    const RobotModel chain = virtualChain(m, g_w);
    Eigen::MatrixXd Yf;
    for (int s = 0; s < 6; ++s) {
      const VirtualState st = randomState(rng, n);
      const BaseMotion base = virtualBaseMotion(chain, st.qv, st.qdv, st.qddv);
      floatingRegressor(m, st.q, st.qd, st.qdd, base, Yf);
      const Eigen::VectorXd pi = floatingParameters(m);
      const Eigen::VectorXd id = floatingInverseDynamics(m, st.q, st.qd, st.qdd, base);
      EXPECT_LT(relErr(id, Yf * pi), 1e-12);
      const Eigen::VectorXd pi2 = randomVec(rng, 10 * (n + 1), 1.0);
      EXPECT_LT(relErr(floatingInverseDynamics(m, st.q, st.qd, st.qdd, base, &pi2), Yf * pi2),
                1e-12);
      Eigen::VectorXd piv = Eigen::VectorXd::Zero(10 * (n + 7));
      piv.tail(10 * (n + 1)) = pi;
      const Eigen::VectorXd ref = refTorques(chain, st.qv, st.qdv, st.qddv, piv);
      const Eigen::Matrix<double, 6, 6> T = virtualRowMap(st.v);
      EXPECT_LT(relErr(T * id.head<6>(), ref.head<6>()), 1e-10);
      EXPECT_LT(relErr(id.tail(n), ref.tail(n)), 1e-10);
    }
  }
}

// Power balance: with the base at the world origin, dE/dt (kinetic plus potential energy, by the
// reference's energy) equals the power of the virtual joints' and the real joints' torques; the
// virtual ones are the base rows through T.
TEST(FloatingBase, PowerBalance) {
  std::mt19937 rng(13);
  const int n = 5;
  const RobotModel m = floatingTree(rng, n);
  const Eigen::Vector3d g_w(0.0, 0.0, -9.81);
  const RobotModel chain = virtualChain(m, g_w);
  Eigen::VectorXd piv = Eigen::VectorXd::Zero(10 * (n + 7));
  piv.tail(10 * (n + 1)) = floatingParameters(m);
  for (int s = 0; s < 4; ++s) {
    const VirtualState st = randomState(rng, n);
    const BaseMotion base = virtualBaseMotion(chain, st.qv, st.qdv, st.qddv);
    const Eigen::VectorXd id = floatingInverseDynamics(m, st.q, st.qd, st.qdd, base);
    const Eigen::VectorXd tv = virtualRowMap(st.v) * id.head<6>();
    const double power = tv.dot(st.vd) + id.tail(n).dot(st.qd);
    const double h = 1e-5;
    auto energy = [&](double t) {
      const Eigen::VectorXd x = st.qv + t * st.qdv + 0.5 * t * t * st.qddv;
      const Eigen::VectorXd xd = st.qdv + t * st.qddv;
      double T = 0, U = 0;
      refEnergy(chain, x, xd, piv, &T, &U);
      return T + U;
    };
    const double dE = (energy(h) - energy(-h)) / (2 * h);
    EXPECT_NEAR(power, dE, 1e-6 * (1.0 + std::abs(power)));
  }
}

// The contact map against finite differences of the virtual chain's sensor-frame pose (the
// fixed-base bodyPose): J_v^T w in all 6 + n virtual coordinates equals [T C_top; C_bottom] w.
TEST(FloatingBase, ContactMapEqualsVirtualJacobian) {
  std::mt19937 rng(14);
  const int n = 6;
  const RobotModel m = floatingTree(rng, n);
  const RobotModel chain = virtualChain(m, Eigen::Vector3d(0, 0, -9.81));
  auto d = makeDynamicsData(chain);
  for (int body = -1; body < n; ++body) {
    const VirtualState st = randomState(rng, n);
    const Pose sensor = randomPose(rng, 0.3);
    const Eigen::MatrixXd C = contactMap(m, st.q, body, sensor);
    ASSERT_EQ(C.rows(), 6 + n);
    const int vb = body < 0 ? 6 : body + 7;
    const Pose P = bodyPose(chain, *d, st.qv, vb) * sensor;
    Eigen::MatrixXd J(6, n + 7);  // [v; omega] in the sensor frame
    const double h = 1e-6;
    for (int k = 0; k < n + 7; ++k) {
      Eigen::VectorXd xp = st.qv, xm = st.qv;
      xp[k] += h;
      xm[k] -= h;
      const Pose Pp = bodyPose(chain, *d, xp, vb) * sensor;
      const Pose Pm = bodyPose(chain, *d, xm, vb) * sensor;
      J.block<3, 1>(0, k) = P.R.transpose() * (Pp.p - Pm.p) / (2 * h);
      const Eigen::Matrix3d W = P.R.transpose() * (Pp.R - Pm.R) / (2 * h);
      J.block<3, 1>(3, k) = Eigen::Vector3d(W(2, 1), W(0, 2), W(1, 0));
    }
    const Eigen::Matrix<double, 6, 1> w = randomVec(rng, 6, 10.0);
    const Eigen::VectorXd ref = J.transpose() * w;
    const Eigen::VectorXd cw = C * w;
    EXPECT_LT(relErr(virtualRowMap(st.v) * cw.head<6>(), ref.head<6>()), 1e-8) << body;
    EXPECT_LT(relErr(cw.tail(n), ref.tail(n)), 1e-8) << body;
  }
}

// A contact wrench that balances the base rows exactly: the equations of motion with that wrench
// and the joint torques of the bottom rows hold (the simulation's construction).
TEST(FloatingBase, ContactBalancesBaseRows) {
  std::mt19937 rng(15);
  const int n = 4;
  const RobotModel m = floatingTree(rng, n);
  const VirtualState st = randomState(rng, n);
  const BaseMotion base = randomVec(rng, 9, 3.0);
  const Eigen::VectorXd id = floatingInverseDynamics(m, st.q, st.qd, st.qdd, base);
  const Eigen::MatrixXd C = contactMap(m, st.q, 2, randomPose(rng, 0.3));
  const Eigen::Matrix<double, 6, 1> w = C.topRows(6).lu().solve(id.head<6>());
  const Eigen::VectorXd tau = id.tail(n) - C.bottomRows(n) * w;
  Eigen::VectorXd rhs(6 + n);
  rhs << Eigen::VectorXd::Zero(6), tau;
  EXPECT_LT(relErr(id, rhs + C * w), 1e-12);
}

// Galilean invariance is built in; the helpers: world data and a displaced, rotated IMU give the
// same base motion as the base origin's own (finite differences of a base trajectory).
TEST(FloatingBase, BaseMotionHelpers) {
  auto Rw = [](double t) -> Eigen::Matrix3d {
    return refRot(Eigen::Vector3d(1, 2, 3).normalized(), 0.7 * std::sin(1.3 * t)) *
           refRot(Eigen::Vector3d::UnitX(), 0.4 * t);
  };
  auto pw = [](double t) -> Eigen::Vector3d {
    return Eigen::Vector3d(std::sin(t), 0.5 * std::cos(2 * t), 0.2 * t * t);
  };
  const double t = 0.37, h = 1e-4;
  const Eigen::Vector3d g(0, 0, -9.81);
  const Eigen::Matrix3d R = Rw(t);
  auto omega_w = [&](double s) -> Eigen::Vector3d {
    const Eigen::Matrix3d W = (Rw(s + 1e-6) - Rw(s - 1e-6)) / 2e-6 * Rw(s).transpose();
    return Eigen::Vector3d(W(2, 1), W(0, 2), W(1, 0));
  };
  const Eigen::Vector3d w_w = omega_w(t), al_w = (omega_w(t + h) - omega_w(t - h)) / (2 * h);
  const Eigen::Vector3d a_w = (pw(t + h) - 2 * pw(t) + pw(t - h)) / (h * h);
  const BaseMotion b = baseMotionFromWorld(R, w_w, al_w, a_w, g);
  EXPECT_LT((b.head<3>() - R.transpose() * w_w).norm(), 1e-12);
  EXPECT_LT((b.tail<3>() - R.transpose() * (a_w - g)).norm(), 1e-12);
  // an IMU at r, rotated by Ri: its accelerometer reads the specific force of its own point
  Pose imu;
  imu.R = refRot(Eigen::Vector3d(0.3, -1, 0.2).normalized(), 0.9);
  imu.p = Eigen::Vector3d(0.12, -0.05, 0.3);
  auto ppt = [&](double s) { return Eigen::Vector3d(pw(s) + Rw(s) * imu.p); };
  const Eigen::Vector3d a_pt = (ppt(t + h) - 2 * ppt(t) + ppt(t - h)) / (h * h);
  const Eigen::Matrix3d Ri = R * imu.R;  // IMU frame in the world
  const BaseMotion bi = baseMotionFromImu(imu, Ri.transpose() * w_w, Ri.transpose() * al_w,
                                          Ri.transpose() * (a_pt - g));
  EXPECT_LT((bi - b).cwiseAbs().maxCoeff(), 1e-5) << (bi - b).transpose();
  // and not the same without the lever arm correction
  Pose imu0 = imu;
  imu0.p.setZero();
  const BaseMotion bw = baseMotionFromImu(imu0, Ri.transpose() * w_w, Ri.transpose() * al_w,
                                          Ri.transpose() * (a_pt - g));
  EXPECT_GT((bw - b).cwiseAbs().maxCoeff(), 1e-2);
}

TEST(FloatingBase, RefusesFixedBaseAndBadSizes) {
  std::mt19937 rng(16);
  RobotModel fixed = randomTree(rng, 3);
  Eigen::MatrixXd Y;
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(3);
  EXPECT_THROW(floatingRegressor(fixed, z, z, z, BaseMotion::Zero(), Y), Error);
  try {
    floatingRegressor(fixed, z, z, z, BaseMotion::Zero(), Y);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fixed base"), std::string::npos) << e.what();
  }
  RobotModel f = floatingTree(rng, 3);
  EXPECT_THROW(floatingRegressor(f, Eigen::VectorXd::Zero(2), z, z, BaseMotion::Zero(), Y), Error);
  EXPECT_THROW(contactMap(f, z, 3, Pose{}), Error);
  EXPECT_NO_THROW(contactMap(f, z, -1, Pose{}));
  // fixed-base consumers refuse a floating robot with its name
  try {
    f.requireFixedBase("the differential model");
    ADD_FAILURE() << "no refusal";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the differential model"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("floating base"), std::string::npos);
  }
  EXPECT_NO_THROW(fixed.requireFixedBase("the differential model"));
  const auto names = floatingParameterNames(f);
  ASSERT_EQ(names.size(), 40u);
  EXPECT_EQ(names[0], "XX0");
  EXPECT_EQ(names[9], "M0");
  EXPECT_EQ(names[10], "XX1");
}
