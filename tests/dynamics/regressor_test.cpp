// Torque regressor, RNEA, CRBA and forward dynamics against the independent reference.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/isa.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

double relErr(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / (1.0 + b.cwiseAbs().maxCoeff());
}

void checkRobot(const RobotModel& m, std::mt19937& rng, int samples, double vel = 2.0,
                double acc = 5.0) {
  auto d = makeDynamicsData(m);
  const int n = m.dof();
  const Eigen::VectorXd pi = m.inertialParameters();
  Eigen::MatrixXd Y(n, 10 * n);
  for (int s = 0; s < samples; ++s) {
    const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, vel),
                          qdd = randomVec(rng, n, acc);
    torqueRegressor(m, *d, q, qd, qdd, Y);
    const Eigen::VectorXd ref = refTorques(m, q, qd, qdd, pi);
    EXPECT_LT(relErr(Y * pi, ref), 1e-10) << m.name << " sample " << s;
    // every column against the reference with a unit parameter
    if (s < 3) {
      for (int c = 0; c < 10 * n; ++c) {
        Eigen::VectorXd e = Eigen::VectorXd::Zero(10 * n);
        e[c] = 1.0;
        // reference needs m != 0 for its COM form, fine: massless branch handles it
        EXPECT_LT(relErr(Y.col(c), refTorques(m, q, qd, qdd, e)), 1e-10)
            << m.name << " column " << c;
      }
    }
    const Eigen::VectorXd tau = inverseDynamics(m, *d, q, qd, qdd);
    EXPECT_LT(relErr(tau, ref), 1e-10);
    const Eigen::VectorXd pi2 = randomVec(rng, 10 * n, 1.0);
    EXPECT_LT(relErr(inverseDynamics(m, *d, q, qd, qdd, &pi2), Y * pi2), 1e-10);
  }
}

}  // namespace

TEST(TorqueRegressor, Puma560StandardDh) {
  std::mt19937 rng(1);
  checkRobot(puma560Standard(), rng, 25);
}

TEST(TorqueRegressor, Puma560ModifiedDhAkb) {
  std::mt19937 rng(2);
  checkRobot(puma560Akb(), rng, 25);
}

TEST(TorqueRegressor, PandaModifiedDh) {
  std::mt19937 rng(3);
  checkRobot(panda(), rng, 25);
}

TEST(TorqueRegressor, RandomTrees) {
  std::mt19937 rng(4);
  for (int t = 0; t < 12; ++t) {
    const int n = 1 + t % 9;
    checkRobot(randomTree(rng, n, t % 3 == 0), rng, 20);
  }
}

TEST(TorqueRegressor, StaticGravityByHand) {
  // Static gravity torque of a horizontal 1-link arm: tau = m g l_c.
  RobotModel m = planar2R(true);
  m.bodies[1].inertia.setZero();
  auto d = makeDynamicsData(m);
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(2);
  const Eigen::VectorXd tau = inverseDynamics(m, *d, z, z, z);
  // link 1: mass 2, COM at x = 1 - 0.5 = 0.5 from the joint (standard DH frame at the tip)
  EXPECT_NEAR(tau[0], 2.0 * 9.81 * 0.5, 1e-12);
  EXPECT_NEAR(tau[1], 0.0, 1e-12);
}

TEST(MassMatrix, SymmetricPositiveDefiniteAndMatchesRnea) {
  std::mt19937 rng(5);
  std::vector<RobotModel> robots = {puma560Standard(), puma560Akb(), panda()};
  for (int t = 0; t < 6; ++t) robots.push_back(randomTree(rng, 2 + t, false));
  for (const RobotModel& m : robots) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    for (int s = 0; s < 20; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0);
      const Eigen::MatrixXd M = massMatrix(m, *d, q);
      EXPECT_LT((M - M.transpose()).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(M).info(), Eigen::Success) << m.name;
      const Eigen::VectorXd h = inverseDynamics(m, *d, q, qd, Eigen::VectorXd::Zero(n));
      for (int k = 0; k < n; ++k) {
        const Eigen::VectorXd e = Eigen::VectorXd::Unit(n, k);
        const Eigen::VectorXd col = inverseDynamics(m, *d, q, qd, e) - h;
        EXPECT_LT(relErr(M.col(k), col), 1e-10) << m.name;
      }
      // forward dynamics inverts inverse dynamics
      const Eigen::VectorXd qdd = randomVec(rng, n, 5.0);
      const Eigen::VectorXd tau = inverseDynamics(m, *d, q, qd, qdd);
      EXPECT_LT(relErr(forwardDynamics(m, *d, q, qd, tau), qdd), 1e-9) << m.name;
    }
  }
}

TEST(BodyPose, MatchesReference) {
  std::mt19937 rng(6);
  for (int t = 0; t < 5; ++t) {
    const RobotModel m = randomTree(rng, 6, false);
    auto d = makeDynamicsData(m);
    const Eigen::VectorXd q = randomVec(rng, 6, 3.0), z = Eigen::VectorXd::Zero(6);
    const auto st = refKinematics(m, q, z, z);
    for (int j = 0; j < 6; ++j) {
      const Pose X = bodyPose(m, *d, q, j);
      EXPECT_LT((X.R - st[static_cast<size_t>(j)].R).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_LT((X.p - st[static_cast<size_t>(j)].o).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
}

TEST(TorqueRegressor, SharedWorkspaceAcrossModels) {
  // A workspace made for one model adapts when used with another (it is re-initialised).
  const RobotModel a = puma560Standard(), b = panda();
  auto d = makeDynamicsData(a);
  std::mt19937 rng(7);
  const Eigen::VectorXd q = randomVec(rng, 7, 1.0), qd = randomVec(rng, 7, 1.0),
                        qdd = randomVec(rng, 7, 1.0);
  const Eigen::VectorXd tau = inverseDynamics(b, *d, q, qd, qdd);
  EXPECT_LT(relErr(tau, refTorques(b, q, qd, qdd, b.inertialParameters())), 1e-10);
  EXPECT_THROW(inverseDynamics(a, *d, q, qd, qdd), Error);
}

// torqueRegressors computes several samples at once, one per vector lane (kernels_lanes.hpp):
// on every instruction set and lane copy this CPU runs, each sample's rows are the bits
// torqueRegressor gives for that sample alone, whatever the sample count (remainders of the lane
// width included) and wherever the sample sits in the batch.
TEST(TorqueRegressors, SameBitsAsOneSampleAtATime) {
  std::mt19937 rng(11);
  std::vector<RobotModel> robots = {puma560Standard(), panda()};
  for (int t = 0; t < 6; ++t) robots.push_back(randomTree(rng, 2 + t, t % 2 == 0));
  const Isa isa0 = activeIsa();
  const Lanes lanes0 = activeLanes();
  int compared = 0;
  for (const RobotModel& m : robots) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    for (int K : {1, 2, 3, 4, 5, 7, 9}) {
      Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n);
      for (int k = 0; k < K; ++k) {
        Q.row(k) = randomVec(rng, n, 3.0).transpose();
        QD.row(k) = randomVec(rng, n, 2.0).transpose();
        QDD.row(k) = randomVec(rng, n, 5.0).transpose();
      }
      for (Isa isa : availableIsas()) {
        setActiveIsa(isa);
        Eigen::MatrixXd one(K * n, 10 * n);
        Eigen::MatrixXd Yk(n, 10 * n);
        for (int k = 0; k < K; ++k) {
          torqueRegressor(m, *d, Q.row(k).transpose(), QD.row(k).transpose(),
                          QDD.row(k).transpose(), Yk);
          one.middleRows(k * n, n) = Yk;
        }
        for (Lanes lanes : availableLanes()) {
          setActiveLanes(lanes);
          Eigen::MatrixXd Y = Eigen::MatrixXd::Constant(K * n, 10 * n, 7.0);
          torqueRegressors(m, *d, Q, QD, QDD, Y);
          EXPECT_EQ(0, std::memcmp(Y.data(), one.data(), sizeof(double) * Y.size()))
              << m.name << " K=" << K << " " << isaName(isa) << " " << lanesName(lanes)
              << ": largest difference " << (Y - one).cwiseAbs().maxCoeff();
          ++compared;
        }
      }
      // and it is the torque regressor: tau = Y pi against the independent reference
      const Eigen::VectorXd pi = m.inertialParameters();
      Eigen::MatrixXd Y(K * n, 10 * n);
      torqueRegressors(m, *d, Q, QD, QDD, Y);
      for (int k = 0; k < K; ++k) {
        const Eigen::VectorXd ref =
            refTorques(m, Q.row(k).transpose(), QD.row(k).transpose(), QDD.row(k).transpose(), pi);
        EXPECT_LT(relErr(Y.middleRows(k * n, n) * pi, ref), 1e-10) << m.name << " sample " << k;
      }
    }
  }
  setActiveIsa(isa0);
  setActiveLanes(lanes0);
  EXPECT_GE(compared, static_cast<int>(robots.size()) * 7);
}

// inverseDynamicsSamples likewise: each sample's torques are the bits inverseDynamics gives for
// it alone (with the model's parameters and with others), on every copy; and they are the
// torques of the independent reference.
TEST(InverseDynamicsSamples, SameBitsAsOneSampleAtATime) {
  std::mt19937 rng(13);
  std::vector<RobotModel> robots = {puma560Standard(), panda()};
  for (int t = 0; t < 6; ++t) robots.push_back(randomTree(rng, 2 + t, t % 2 == 0));
  const Isa isa0 = activeIsa();
  const Lanes lanes0 = activeLanes();
  int compared = 0;
  for (const RobotModel& m : robots) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    const Eigen::VectorXd other = 1.5 * m.inertialParameters();
    for (int K : {1, 2, 3, 4, 5, 7, 9}) {
      Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n);
      for (int k = 0; k < K; ++k) {
        Q.row(k) = randomVec(rng, n, 3.0).transpose();
        QD.row(k) = randomVec(rng, n, 2.0).transpose();
        QDD.row(k) = randomVec(rng, n, 5.0).transpose();
      }
      for (const Eigen::VectorXd* pi : {static_cast<const Eigen::VectorXd*>(nullptr), &other})
        for (Isa isa : availableIsas()) {
          setActiveIsa(isa);
          Eigen::MatrixXd one(K, n);
          for (int k = 0; k < K; ++k)
            one.row(k) = inverseDynamics(m, *d, Q.row(k).transpose(), QD.row(k).transpose(),
                                         QDD.row(k).transpose(), pi)
                             .transpose();
          for (Lanes lanes : availableLanes()) {
            setActiveLanes(lanes);
            Eigen::MatrixXd T = Eigen::MatrixXd::Constant(K, n, 7.0);
            inverseDynamicsSamples(m, *d, Q, QD, QDD, T, pi);
            EXPECT_EQ(0, std::memcmp(T.data(), one.data(), sizeof(double) * T.size()))
                << m.name << " K=" << K << " " << isaName(isa) << " " << lanesName(lanes)
                << ": largest difference " << (T - one).cwiseAbs().maxCoeff();
            ++compared;
          }
        }
      Eigen::MatrixXd T(K, n);
      inverseDynamicsSamples(m, *d, Q, QD, QDD, T, &other);
      for (int k = 0; k < K; ++k) {
        const Eigen::VectorXd ref = refTorques(m, Q.row(k).transpose(), QD.row(k).transpose(),
                                               QDD.row(k).transpose(), other);
        EXPECT_LT(relErr(T.row(k).transpose(), ref), 1e-10) << m.name << " sample " << k;
      }
    }
  }
  setActiveIsa(isa0);
  setActiveLanes(lanes0);
  EXPECT_GE(compared, static_cast<int>(robots.size()) * 7 * 2);
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(3, 6), T(3, 6);
  EXPECT_THROW(inverseDynamicsSamples(m, *d, Q, Q, Eigen::MatrixXd::Zero(2, 6), T), Error);
  Eigen::MatrixXd Tbad(3, 5);
  EXPECT_THROW(inverseDynamicsSamples(m, *d, Q, Q, Q, Tbad), Error);
  const Eigen::VectorXd short_pi = Eigen::VectorXd::Zero(59);
  EXPECT_THROW(inverseDynamicsSamples(m, *d, Q, Q, Q, T, &short_pi), Error);
  EXPECT_NO_THROW(inverseDynamicsSamples(m, *d, Q, Q, Q, T));
}

TEST(TorqueRegressors, RefusesMismatchedSizes) {
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(3, 6), Y(18, 60);
  EXPECT_THROW(torqueRegressors(m, *d, Q, Q, Eigen::MatrixXd::Zero(2, 6), Y), Error);
  Eigen::MatrixXd Ybad(17, 60);
  EXPECT_THROW(torqueRegressors(m, *d, Q, Q, Q, Ybad), Error);
  EXPECT_NO_THROW(torqueRegressors(m, *d, Q, Q, Q, Y));
}

// The lanes take their joints' sines and cosines several at once (exid/fmath_kernels.hpp); each
// lane's are the bits of exid::fmath::sincos whatever its neighbours: angles in every case the
// sine distinguishes (zero, tiny, either side of pi/4, near multiples of pi/2 where the
// reduction takes two or three rounds, and beyond the vector path, where the lanes go through the
// scalar function), mixed in every lane position.
TEST(TorqueRegressors, SameBitsAtEverySineAndCosineCase) {
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  const int n = m.dof();
  const double pio2 = 1.5707963267948966;
  const std::vector<double> angles = {0.0,
                                      -0.0,
                                      1e-300,
                                      1e-9,
                                      -0x1.6a09ep-27,
                                      0x1.921fcp-1,
                                      std::nextafter(0x1.921fcp-1, 0.0),
                                      -M_PI / 4,
                                      pio2,
                                      -std::nextafter(pio2, 0.0),
                                      M_PI,
                                      3 * pio2,
                                      1000 * pio2,
                                      std::nextafter(0x1.921fbp+20, 0.0),
                                      0x1.921fbp+20,
                                      -1e7,
                                      2.5,
                                      -0.3};
  const int K = 23;
  std::mt19937 rng(12);
  Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n);
  for (int k = 0; k < K; ++k) {
    for (int j = 0; j < n; ++j)
      Q(k, j) = angles[static_cast<std::size_t>(k * n + j) % angles.size()];
    QD.row(k) = randomVec(rng, n, 2.0).transpose();
    QDD.row(k) = randomVec(rng, n, 5.0).transpose();
  }
  Eigen::MatrixXd one(K * n, 10 * n), Yk(n, 10 * n);
  for (int k = 0; k < K; ++k) {
    torqueRegressor(m, *d, Q.row(k).transpose(), QD.row(k).transpose(), QDD.row(k).transpose(), Yk);
    one.middleRows(k * n, n) = Yk;
  }
  const Lanes lanes0 = activeLanes();
  for (Lanes lanes : availableLanes()) {
    setActiveLanes(lanes);
    // every window of the samples, so that each angle meets others in each lane position
    for (int k0 = 0; k0 < 4; ++k0) {
      const int cnt = K - k0;
      Eigen::MatrixXd Y = Eigen::MatrixXd::Constant(cnt * n, 10 * n, 7.0);
      torqueRegressors(m, *d, Q.bottomRows(cnt), QD.bottomRows(cnt), QDD.bottomRows(cnt), Y);
      const Eigen::MatrixXd ref = one.bottomRows(cnt * n);
      EXPECT_EQ(0, std::memcmp(Y.data(), ref.data(), sizeof(double) * Y.size()))
          << lanesName(lanes) << " from sample " << k0 << ": largest difference "
          << (Y - ref).cwiseAbs().maxCoeff();
    }
  }
  setActiveLanes(lanes0);
}
