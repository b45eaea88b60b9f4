// Energy regressor: against the reference energies, 1/2 qd^T M qd, and power balance dH/dt = tau^T
// qd.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/isa.hpp"

using namespace exid;
using namespace exid::testing;

namespace {
std::vector<RobotModel> robots(std::mt19937& rng) {
  std::vector<RobotModel> r = {puma560Standard(), puma560Akb(), panda()};
  for (int t = 0; t < 6; ++t) r.push_back(randomTree(rng, 1 + t, t % 2 == 0));
  return r;
}
}  // namespace

TEST(EnergyRegressor, MatchesReferenceAndMassMatrix) {
  std::mt19937 rng(11);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    const Eigen::VectorXd pi = m.inertialParameters();
    Eigen::RowVectorXd K(10 * n), U(10 * n);
    for (int s = 0; s < 20; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0);
      energyRegressor(m, *d, q, qd, K, U);
      double T = 0, V = 0;
      refEnergy(m, q, qd, pi, &T, &V);
      EXPECT_NEAR(K.dot(pi), T, 1e-10 * (1 + std::abs(T))) << m.name;
      EXPECT_NEAR(U.dot(pi), V, 1e-10 * (1 + std::abs(V))) << m.name;
      const Eigen::MatrixXd M = massMatrix(m, *d, q);
      EXPECT_NEAR(K.dot(pi), 0.5 * qd.dot(M * qd), 1e-10 * (1 + std::abs(T))) << m.name;
    }
  }
}

TEST(EnergyRegressor, PowerBalanceAlongSmoothTrajectory) {
  std::mt19937 rng(12);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    const Eigen::VectorXd pi = m.inertialParameters();
    const Eigen::VectorXd A = randomVec(rng, n, 1.0), w = randomVec(rng, n, 3.0),
                          ph = randomVec(rng, n, 3.0);
    auto traj = [&](double t, Eigen::VectorXd* q, Eigen::VectorXd* qd, Eigen::VectorXd* qdd) {
      *q = *qd = *qdd = Eigen::VectorXd(n);
      for (int j = 0; j < n; ++j) {
        const double a = w[j] * t + ph[j];
        (*q)[j] = A[j] * std::sin(a);
        (*qd)[j] = A[j] * w[j] * std::cos(a);
        (*qdd)[j] = -A[j] * w[j] * w[j] * std::sin(a);
      }
    };
    Eigen::RowVectorXd K(10 * n), U(10 * n);
    auto H = [&](double t) {
      Eigen::VectorXd q, qd, qdd;
      traj(t, &q, &qd, &qdd);
      energyRegressor(m, *d, q, qd, K, U);
      return (K + U).dot(pi);
    };
    for (int s = 0; s < 10; ++s) {
      const double t = 0.37 * s, h = 1e-4;
      const double dH = (H(t + h) - H(t - h)) / (2 * h);
      Eigen::VectorXd q, qd, qdd;
      traj(t, &q, &qd, &qdd);
      const double P = inverseDynamics(m, *d, q, qd, qdd).dot(qd);
      EXPECT_NEAR(dH, P, 1e-6 * (1 + std::abs(P))) << m.name << " t=" << t;
    }
  }
}

// energyRegressors computes several samples at once, one per vector lane
// (kernels_lanes.hpp): on every instruction set and lane copy this CPU runs, each sample's rows
// are the bits energyRegressor gives for that sample alone, whatever the sample count; and they
// are the energies (against the independent reference).
TEST(EnergyRegressors, SameBitsAsOneSampleAtATime) {
  std::mt19937 rng(12);
  const Isa isa0 = activeIsa();
  const Lanes lanes0 = activeLanes();
  int compared = 0;
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    for (int K : {1, 2, 3, 4, 5, 7, 9}) {
      Eigen::MatrixXd Q(K, n), QD(K, n);
      for (int k = 0; k < K; ++k) {
        Q.row(k) = randomVec(rng, n, 3.0).transpose();
        QD.row(k) = randomVec(rng, n, 2.0).transpose();
      }
      for (Isa isa : availableIsas()) {
        setActiveIsa(isa);
        Eigen::MatrixXd kin1(K, 10 * n), pot1(K, 10 * n);
        Eigen::RowVectorXd kk(10 * n), uu(10 * n);
        for (int k = 0; k < K; ++k) {
          energyRegressor(m, *d, Q.row(k).transpose(), QD.row(k).transpose(), kk, uu);
          kin1.row(k) = kk;
          pot1.row(k) = uu;
        }
        for (Lanes lanes : availableLanes()) {
          setActiveLanes(lanes);
          Eigen::MatrixXd kin = Eigen::MatrixXd::Constant(K, 10 * n, 7.0), pot = kin;
          energyRegressors(m, *d, Q, QD, kin, pot);
          EXPECT_EQ(0, std::memcmp(kin.data(), kin1.data(), sizeof(double) * kin.size()))
              << m.name << " K=" << K << " " << isaName(isa) << " " << lanesName(lanes)
              << ": kinetic, largest difference " << (kin - kin1).cwiseAbs().maxCoeff();
          EXPECT_EQ(0, std::memcmp(pot.data(), pot1.data(), sizeof(double) * pot.size()))
              << m.name << " K=" << K << " " << isaName(isa) << " " << lanesName(lanes)
              << ": potential, largest difference " << (pot - pot1).cwiseAbs().maxCoeff();
          ++compared;
        }
      }
      const Eigen::VectorXd pi = m.inertialParameters();
      Eigen::MatrixXd kin(K, 10 * n), pot(K, 10 * n);
      energyRegressors(m, *d, Q, QD, kin, pot);
      for (int k = 0; k < K; ++k) {
        double T = 0, V = 0;
        refEnergy(m, Q.row(k).transpose(), QD.row(k).transpose(), pi, &T, &V);
        EXPECT_NEAR(kin.row(k).dot(pi), T, 1e-10 * (1 + std::abs(T))) << m.name;
        EXPECT_NEAR(pot.row(k).dot(pi), V, 1e-10 * (1 + std::abs(V))) << m.name;
      }
    }
  }
  setActiveIsa(isa0);
  setActiveLanes(lanes0);
  EXPECT_GE(compared, 9 * 7);
  // sizes
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(3, 6), kin(3, 60), pot(3, 60), bad(2, 60);
  EXPECT_THROW(energyRegressors(m, *d, Q, Eigen::MatrixXd::Zero(2, 6), kin, pot), Error);
  EXPECT_THROW(energyRegressors(m, *d, Q, Q, bad, pot), Error);
  Eigen::MatrixXd pot_bad(3, 59);
  EXPECT_THROW(energyRegressors(m, *d, Q, Q, kin, pot_bad), Error);
  EXPECT_NO_THROW(energyRegressors(m, *d, Q, Q, kin, pot));
}
