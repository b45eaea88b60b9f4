// Every vector-Jacobian product against central finite differences.
#include <gtest/gtest.h>

#include <cstring>
#include <functional>
#include <random>
#include <string>

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

// torqueRegressorVjps and energyRegressorVjps compute several samples at once, one per vector
// lane (kernels_lanes.hpp): on every instruction set and lane copy this CPU runs, each sample's
// gradients are the bits the one-sample VJP gives for that sample alone, whatever the sample
// count (the lanes past the last sample repeat it); and they are the gradients (finite
// differences of <G, Y>).
TEST(Vjps, SameBitsAsOneSampleAtATime) {
  std::mt19937 rng(37);
  const Isa isa0 = activeIsa();
  const Lanes lanes0 = activeLanes();
  int compared = 0;
  auto same = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    return a.rows() == b.rows() && a.cols() == b.cols() &&
           std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
  };
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    for (int K : {1, 2, 3, 4, 5, 7, 9}) {
      Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n), G(K * n, 10 * n), Gk(K, 10 * n), Gu(K, 10 * n);
      for (int k = 0; k < K; ++k) {
        Q.row(k) = randomVec(rng, n, 3.0).transpose();
        QD.row(k) = randomVec(rng, n, 2.0).transpose();
        QDD.row(k) = randomVec(rng, n, 5.0).transpose();
      }
      G = Eigen::MatrixXd::NullaryExpr(K * n, 10 * n, [&] { return randomVec(rng, 1)[0]; });
      Gk = Eigen::MatrixXd::NullaryExpr(K, 10 * n, [&] { return randomVec(rng, 1)[0]; });
      Gu = Eigen::MatrixXd::NullaryExpr(K, 10 * n, [&] { return randomVec(rng, 1)[0]; });
      for (Isa isa : availableIsas()) {
        setActiveIsa(isa);
        Eigen::MatrixXd tq1(K, n), tqd1(K, n), tqdd1(K, n), eq1(K, n), eqd1(K, n);
        Eigen::VectorXd a, b, c;
        for (int k = 0; k < K; ++k) {
          const Eigen::MatrixXd Gs = G.middleRows(k * n, n);
          torqueRegressorVjp(m, *d, Q.row(k).transpose(), QD.row(k).transpose(),
                             QDD.row(k).transpose(), Gs, &a, &b, &c);
          tq1.row(k) = a.transpose();
          tqd1.row(k) = b.transpose();
          tqdd1.row(k) = c.transpose();
          energyRegressorVjp(m, *d, Q.row(k).transpose(), QD.row(k).transpose(), Gk.row(k),
                             Gu.row(k), &a, &b);
          eq1.row(k) = a.transpose();
          eqd1.row(k) = b.transpose();
        }
        for (Lanes lanes : availableLanes()) {
          setActiveLanes(lanes);
          const std::string what =
              m.name + " K=" + std::to_string(K) + " " + isaName(isa) + " " + lanesName(lanes);
          Eigen::MatrixXd tq, tqd, tqdd, eq, eqd;
          torqueRegressorVjps(m, *d, Q, QD, QDD, G, &tq, &tqd, &tqdd);
          EXPECT_TRUE(same(tq, tq1))
              << what << ": d/dq, largest difference " << (tq - tq1).cwiseAbs().maxCoeff();
          EXPECT_TRUE(same(tqd, tqd1)) << what << ": d/dqd";
          EXPECT_TRUE(same(tqdd, tqdd1)) << what << ": d/dqdd";
          energyRegressorVjps(m, *d, Q, QD, Gk, Gu, &eq, &eqd);
          EXPECT_TRUE(same(eq, eq1))
              << what << ": energy d/dq, largest difference " << (eq - eq1).cwiseAbs().maxCoeff();
          EXPECT_TRUE(same(eqd, eqd1)) << what << ": energy d/dqd";
          // the outputs asked for alone: the same bits
          Eigen::MatrixXd only;
          torqueRegressorVjps(m, *d, Q, QD, QDD, G, nullptr, &only, nullptr);
          EXPECT_TRUE(same(only, tqd1)) << what << ": d/dqd alone";
          energyRegressorVjps(m, *d, Q, QD, Gk, Gu, nullptr, &only);
          EXPECT_TRUE(same(only, eqd1)) << what << ": energy d/dqd alone";
          ++compared;
        }
      }
      // the gradients of <G, Y> and <Gk, kinetic> + <Gu, potential>, sample by sample
      Eigen::MatrixXd tq, tqd, tqdd, eq, eqd;
      torqueRegressorVjps(m, *d, Q, QD, QDD, G, &tq, &tqd, &tqdd);
      energyRegressorVjps(m, *d, Q, QD, Gk, Gu, &eq, &eqd);
      for (int k = 0; k < K; ++k) {
        const Eigen::MatrixXd Gs = G.middleRows(k * n, n);
        const Eigen::RowVectorXd gk = Gk.row(k), gu = Gu.row(k);
        Eigen::MatrixXd Y(n, 10 * n);
        Eigen::RowVectorXd kin(10 * n), pot(10 * n);
        const Eigen::VectorXd a = tq.row(k).transpose(), b = tqd.row(k).transpose(),
                              c = tqdd.row(k).transpose(), e = eq.row(k).transpose(),
                              f = eqd.row(k).transpose();
        checkGrad(
            [&](const Eigen::VectorXd& x, const Eigen::VectorXd& y, const Eigen::VectorXd& z) {
              torqueRegressor(m, *d, x, y, z, Y);
              return (Gs.array() * Y.array()).sum();
            },
            Q.row(k).transpose(), QD.row(k).transpose(), QDD.row(k).transpose(), &a, &b, &c,
            m.name + " torque sample " + std::to_string(k));
        checkGrad(
            [&](const Eigen::VectorXd& x, const Eigen::VectorXd& y, const Eigen::VectorXd&) {
              energyRegressor(m, *d, x, y, kin, pot);
              return gk.dot(kin) + gu.dot(pot);
            },
            Q.row(k).transpose(), QD.row(k).transpose(), QDD.row(k).transpose(), &e, &f, nullptr,
            m.name + " energy sample " + std::to_string(k));
      }
    }
  }
  setActiveIsa(isa0);
  setActiveLanes(lanes0);
  EXPECT_GE(compared, 11 * 7);
  // sizes
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  const Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(3, 6), G = Eigen::MatrixXd::Zero(18, 60),
                        Ge = Eigen::MatrixXd::Zero(3, 60);
  Eigen::MatrixXd out;
  EXPECT_THROW(torqueRegressorVjps(m, *d, Q, Eigen::MatrixXd::Zero(2, 6), Q, G, &out, &out, &out),
               Error);
  EXPECT_THROW(
      torqueRegressorVjps(m, *d, Q, Q, Q, Eigen::MatrixXd::Zero(12, 60), &out, nullptr, nullptr),
      Error);
  EXPECT_THROW(energyRegressorVjps(m, *d, Q, Q, Ge, Eigen::MatrixXd::Zero(3, 59), &out, nullptr),
               Error);
  EXPECT_NO_THROW(energyRegressorVjps(m, *d, Q, Q, Ge, Ge, &out, nullptr));
  EXPECT_EQ(out.rows(), 3);
}
