// Partial derivatives of the inverse dynamics (and of the full actuator torque) against central
// finite differences, and their torque against inverseDynamics / actuatorTorque.
#include <gtest/gtest.h>

#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dh.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

std::vector<RobotModel> robots(std::mt19937& rng) {
  std::vector<RobotModel> r = {puma560Standard(), puma560Akb(), panda(), planar2R(true)};
  for (int t = 0; t < 8; ++t) r.push_back(randomTree(rng, 1 + t, t % 2 == 1));
  return r;
}

// Central differences of f along each coordinate of block `which` (0 q, 1 qd, 2 qdd): n x n.
template <class F>
Eigen::MatrixXd centralDifferences(const F& f, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                   const Eigen::VectorXd& qdd, int which, double h) {
  const Eigen::Index n = q.size();
  Eigen::MatrixXd D(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    Eigen::VectorXd x[3] = {q, qd, qdd}, y[3] = {q, qd, qdd};
    x[which][i] += h;
    y[which][i] -= h;
    D.col(i) = (f(x[0], x[1], x[2]) - f(y[0], y[1], y[2])) / (2 * h);
  }
  return D;
}

void expectClose(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, double rel,
                 const std::string& what) {
  const double scale = std::max(1.0, b.cwiseAbs().maxCoeff());
  EXPECT_LE((a - b).cwiseAbs().maxCoeff(), rel * scale) << what << "\nexact\n"
                                                        << a << "\nfinite differences\n"
                                                        << b;
}

}  // namespace

TEST(InverseDynamicsDerivatives, MatchCentralDifferences) {
  std::mt19937 rng(71);
  for (const RobotModel& m : robots(rng)) {
    auto d = makeDynamicsData(m);
    const int n = m.dof();
    for (int s = 0; s < 3; ++s) {
      const Eigen::VectorXd q = randomVec(rng, n, 3.0), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      Eigen::VectorXd tau;
      Eigen::MatrixXd Dq, Dqd, Dqdd;
      inverseDynamicsDerivatives(m, *d, q, qd, qdd, nullptr, &tau, &Dq, &Dqd, &Dqdd);
      EXPECT_LE((tau - inverseDynamics(m, *d, q, qd, qdd)).cwiseAbs().maxCoeff(), 1e-12) << m.name;
      auto f = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& c) {
        return inverseDynamics(m, *d, a, b, c);
      };
      expectClose(Dq, centralDifferences(f, q, qd, qdd, 0, 1e-6), 1e-6, m.name + " dtau/dq");
      expectClose(Dqd, centralDifferences(f, q, qd, qdd, 1, 1e-6), 1e-6, m.name + " dtau/dqd");
      expectClose(Dqdd, centralDifferences(f, q, qd, qdd, 2, 1e-6), 1e-6, m.name + " dtau/dqdd");
      // dtau/dqdd is the mass matrix
      expectClose(Dqdd, massMatrix(m, *d, q), 1e-12, m.name + " mass matrix");
      // other parameters than the model's own
      const Eigen::VectorXd pi = 0.5 * m.inertialParameters();
      Eigen::VectorXd tau_pi;
      Eigen::MatrixXd Dq_pi;
      inverseDynamicsDerivatives(m, *d, q, qd, qdd, &pi, &tau_pi, &Dq_pi, nullptr, nullptr);
      EXPECT_LE((tau_pi - inverseDynamics(m, *d, q, qd, qdd, &pi)).cwiseAbs().maxCoeff(), 1e-12);
      expectClose(Dq_pi, 0.5 * Dq, 1e-12, m.name + " linear in the parameters");
    }
  }
}

TEST(InverseDynamicsDerivatives, ActuatorTorqueThroughTransmissionAndDrives) {
  // Vertical planar 3R measured in absolute angles (coupled transmission) with every drive term.
  RobotModel m = serialDh({{JointType::Revolute, 0.5, 0, 0, 0},
                           {JointType::Revolute, 0.4, 0, 0, 0},
                           {JointType::Revolute, 0.3, 0, 0, 0.2}},
                          DhConvention::Standard);
  m.gravity = Eigen::Vector3d(0, -9.81, 0);
  std::mt19937 rng(72);
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
  const DriveColumns all{true, true, true, true};
  auto d = makeDynamicsData(m);
  for (int s = 0; s < 4; ++s) {
    // velocities away from zero: the Coulomb term sign(qd) is smooth there
    Eigen::VectorXd qd = randomVec(rng, 3, 2.0);
    for (int j = 0; j < 3; ++j) qd[j] += qd[j] > 0 ? 0.5 : -0.5;
    const Eigen::VectorXd q = randomVec(rng, 3, 3.0), qdd = randomVec(rng, 3, 5.0);
    Eigen::VectorXd tau;
    Eigen::MatrixXd Dq, Dqd, Dqdd;
    actuatorTorqueDerivatives(m, *d, all, q, qd, qdd, &tau, &Dq, &Dqd, &Dqdd);
    EXPECT_LE((tau - actuatorTorque(m, *d, all, q, qd, qdd)).cwiseAbs().maxCoeff(), 1e-12);
    auto f = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& c) {
      return actuatorTorque(m, *d, all, a, b, c);
    };
    expectClose(Dq, centralDifferences(f, q, qd, qdd, 0, 1e-6), 1e-6, "dtau_m/dqm");
    expectClose(Dqd, centralDifferences(f, q, qd, qdd, 1, 1e-6), 1e-6, "dtau_m/dqdm");
    expectClose(Dqdd, centralDifferences(f, q, qd, qdd, 2, 1e-6), 1e-6, "dtau_m/dqddm");
  }
}
