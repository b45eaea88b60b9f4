// Every vector-Jacobian product against central finite differences.
#include <gtest/gtest.h>

#include <functional>
#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

std::vector<RobotModel> robots(std::mt19937& rng) {
  std::vector<RobotModel> r = {puma560Standard(), puma560Akb(), panda()};
  r[0].sensor_pose = randomPose(rng, 0.1);
  for (int t = 0; t < 8; ++t) r.push_back(randomTree(rng, 1 + t, t % 2 == 1));
  return r;
}

// f(q, qd, qdd) scalar; checks gradient g (3 blocks, any may be empty = not checked).
void checkGrad(const std::function<double(const Eigen::VectorXd&, const Eigen::VectorXd&,
                                          const Eigen::VectorXd&)>& f,
               const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
               const Eigen::VectorXd* gq, const Eigen::VectorXd* gqd, const Eigen::VectorXd* gqdd,
               const std::string& what) {
  const double h = 1e-5;
  const int n = static_cast<int>(q.size());
  const Eigen::VectorXd* grads[3] = {gq, gqd, gqdd};
  double scale = 1.0;
  for (auto* g : grads)
    if (g) scale = std::max(scale, g->cwiseAbs().maxCoeff());
  for (int which = 0; which < 3; ++which) {
    if (!grads[which]) continue;
    for (int k = 0; k < n; ++k) {
      Eigen::VectorXd x[3] = {q, qd, qdd}, y[3] = {q, qd, qdd};
      x[which][k] += h;
      y[which][k] -= h;
      const double fd = (f(x[0], x[1], x[2]) - f(y[0], y[1], y[2])) / (2 * h);
      EXPECT_NEAR((*grads[which])[k], fd, 1e-6 * scale)
          << what << " block " << which << " coordinate " << k;
    }
  }
}

}  // namespace

TEST(Vjp, TorqueRegressor) {
  std::mt19937 rng(31);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    Eigen::MatrixXd Y(n, 10 * n);
    for (int s = 0; s < 4; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      const Eigen::MatrixXd G =
          Eigen::MatrixXd::NullaryExpr(n, 10 * n, [&] { return randomVec(rng, 1)[0]; });
      Eigen::VectorXd gq, gqd, gqdd;
      torqueRegressorVjp(m, *d, q, qd, qdd, G, &gq, &gqd, &gqdd);
      auto f = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& c) {
        torqueRegressor(m, *d, a, b, c, Y);
        return (G.array() * Y.array()).sum();
      };
      checkGrad(f, q, qd, qdd, &gq, &gqd, &gqdd, m.name + " torque");
      // null outputs are allowed
      Eigen::VectorXd only;
      torqueRegressorVjp(m, *d, q, qd, qdd, G, nullptr, &only, nullptr);
      EXPECT_LT((only - gqd).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
}

TEST(Vjp, EnergyRegressor) {
  std::mt19937 rng(32);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    Eigen::RowVectorXd K(10 * n), U(10 * n);
    for (int s = 0; s < 4; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            z = Eigen::VectorXd::Zero(n);
      const Eigen::RowVectorXd Gk = randomVec(rng, 10 * n).transpose(),
                               Gu = randomVec(rng, 10 * n).transpose();
      Eigen::VectorXd gq, gqd;
      energyRegressorVjp(m, *d, q, qd, Gk, Gu, &gq, &gqd);
      auto f = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd&) {
        energyRegressor(m, *d, a, b, K, U);
        return Gk.dot(K) + Gu.dot(U);
      };
      checkGrad(f, q, qd, z, &gq, &gqd, nullptr, m.name + " energy");
    }
  }
}

TEST(Vjp, WrenchRegressor) {
  std::mt19937 rng(33);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    Eigen::Matrix<double, 6, 10> A;
    for (int s = 0; s < 4; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      Eigen::Matrix<double, 6, 10> G;
      for (int k = 0; k < 60; ++k) G.data()[k] = randomVec(rng, 1)[0];
      Eigen::VectorXd gq, gqd, gqdd;
      wrenchRegressorVjp(m, *d, q, qd, qdd, G, &gq, &gqd, &gqdd);
      auto f = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& c) {
        wrenchRegressor(m, *d, a, b, c, A);
        return (G.array() * A.array()).sum();
      };
      checkGrad(f, q, qd, qdd, &gq, &gqd, &gqdd, m.name + " wrench");
    }
  }
}

TEST(Vjp, PayloadTorqueRegressor) {
  std::mt19937 rng(34);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    Eigen::MatrixXd Yp(n, 10);
    for (int s = 0; s < 4; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      const Eigen::MatrixXd G =
          Eigen::MatrixXd::NullaryExpr(n, 10, [&] { return randomVec(rng, 1)[0]; });
      Eigen::VectorXd gq, gqd, gqdd;
      payloadTorqueRegressorVjp(m, *d, q, qd, qdd, G, &gq, &gqd, &gqdd);
      auto f = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& c) {
        payloadTorqueRegressor(m, *d, a, b, c, Yp);
        return (G.array() * Yp.array()).sum();
      };
      checkGrad(f, q, qd, qdd, &gq, &gqd, &gqdd, m.name + " payload torque");
    }
  }
}
