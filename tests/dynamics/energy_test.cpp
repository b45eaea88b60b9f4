// Energy regressor: against the reference energies, 1/2 qd^T M qd, and power balance dH/dt = tau^T
// qd.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"

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
