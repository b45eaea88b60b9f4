// Closed kinematic chains: the four-bar linkage against a closed-form Lagrangian derivation, the
// loop-closure constraint's Jacobian and bias against finite differences, and the errors.
#include "exid/closed_chain.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <sstream>

#include "dyn_reference.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

using V2 = Eigen::Vector2d;

// Four-bar linkage in the base x-y plane, revolute joints about z, gravity -g along y (in the
// plane). Ground pivots A = (0, 0) and D = (d, 0); crank AB (length a, joint 1, actuated, angle
// phi1 from x), coupler BC (length b, joint 2 at B, relative angle q2: absolute phi2 = phi1 +
// q2), rocker DC (length c, joint 3 at D on the base, absolute angle phi3). The cut joint is the
// revolute at C between the coupler's end (b, 0, 0) and the rocker's end (c, 0, 0). Each link's
// body frame has x along the link.
struct FourBar {
  double a = 0.1, b = 0.35, c = 0.3, d = 0.4, g = 9.81;
  double m[3], rx[3], ry[3], Izz[3];  // mass, centre of mass in the link frame, Izz about it
  int branch = +1;                    // which of the two assemblies (sign of the cross product)
};

RobotModel fourBarModel(const FourBar& f, std::mt19937& rng, FourBar* out) {
  RobotModel m;
  m.name = "fourbar_test";
  m.gravity = Eigen::Vector3d(0, -f.g, 0);
  Body b1, b2, b3;
  b1.name = "crank", b1.joint_name = "j1", b1.parent = -1;
  b2.name = "coupler", b2.joint_name = "j2", b2.parent = 0, b2.pre.p = {f.a, 0, 0};
  b3.name = "rocker", b3.joint_name = "j3", b3.parent = -1, b3.pre.p = {f.d, 0, 0};
  m.bodies = {b1, b2, b3};
  *out = f;
  for (int i = 0; i < 3; ++i) {
    m.bodies[static_cast<size_t>(i)].inertia = randomInertia(rng, 0.2);
    double mass;
    Eigen::Vector3d com;
    Eigen::Matrix3d Ic;
    comFromInertial(m.bodies[static_cast<size_t>(i)].inertia, &mass, &com, &Ic);
    out->m[i] = mass, out->rx[i] = com.x(), out->ry[i] = com.y(), out->Izz[i] = Ic(2, 2);
  }
  LoopJoint L;
  L.name = "C";
  L.body_a = 1, L.body_b = 2;
  L.pose_a.p = {f.b, 0, 0};
  L.pose_b.p = {f.c, 0, 0};
  m.closed.loops = {L};
  m.closed.actuated = {0};
  m.limits.assign(1, JointLimits{});
  m.drives.assign(1, Drive{});
  return m;
}

V2 e(double p) { return {std::cos(p), std::sin(p)}; }
V2 ep(double p) { return {-std::sin(p), std::cos(p)}; }

// Closed-form kinematics: absolute angles, rates and accelerations of the three links.
struct Planar {
  double phi[3], w[3], al[3];
};
Planar solve(const FourBar& f, double th, double thd, double thdd) {
  const V2 B = f.a * e(th), D(f.d, 0.0);
  const V2 BD = D - B;
  const double L = BD.norm();
  // C on the circles |C - B| = b and |C - D| = c
  const double x = (f.b * f.b - f.c * f.c + L * L) / (2 * L);
  const double h = std::sqrt(f.b * f.b - x * x);
  const V2 u = BD / L, nrm(-u.y(), u.x());
  const V2 C = B + x * u + f.branch * h * nrm;
  Planar p;
  p.phi[0] = th;
  p.phi[1] = std::atan2((C - B).y(), (C - B).x());
  p.phi[2] = std::atan2((C - D).y(), (C - D).x());
  // a e'(1) w1 + b e'(2) w2 - c e'(3) w3 = 0  ->  A [w2; w3] = -a e'(1) w1
  Eigen::Matrix2d A;
  A.col(0) = f.b * ep(p.phi[1]);
  A.col(1) = -f.c * ep(p.phi[2]);
  p.w[0] = thd;
  const Eigen::Vector2d w23 = A.lu().solve(-f.a * ep(th) * thd);
  p.w[1] = w23[0], p.w[2] = w23[1];
  // differentiated once more: a e'1 al1 - a e1 w1^2 + b e'2 al2 - b e2 w2^2 - c e'3 al3
  // + c e3 w3^2 = 0
  p.al[0] = thdd;
  const Eigen::Vector2d rhs =
      -(f.a * ep(th) * thdd - f.a * e(th) * thd * thd - f.b * e(p.phi[1]) * p.w[1] * p.w[1] +
        f.c * e(p.phi[2]) * p.w[2] * p.w[2]);
  const Eigen::Vector2d a23 = A.lu().solve(rhs);
  p.al[1] = a23[0], p.al[2] = a23[1];
  return p;
}

// Lagrange for the one coordinate theta (T quadratic in thd, V(theta)):
//   tau = d/dt dL/dthd - dL/dth.
// Multiplying by thd, thd (d/dt dL/dthd - dL/dth) = d/dt (thd dL/dthd - L) = d/dt (T + V)
// (Euler: thd dT/dthd = 2T), so tau = (dT/dt + dV/dt) / thd for thd != 0, with
//   T = sum_i 1/2 m_i |v_Gi|^2 + 1/2 Izz_i w_i^2,  V = sum_i m_i g y_Gi,
//   dT/dt = sum_i m_i v_Gi . a_Gi + Izz_i w_i al_i,  dV/dt = sum_i m_i g vy_Gi,
// each centre of mass G_i = P_i + R(phi_i) r_i on link i pivoting at P_i (A for the crank, B for
// the coupler, D for the rocker), v_G = v_P + w k x (R r), a_G = a_P + al k x (R r) - w^2 R r.
// The mass coefficient m(theta) = sum_i m_i |dG_i/dtheta|^2 + Izz_i (dphi_i/dtheta)^2 is the
// kinetic energy's at thd = 1 times two.
struct Closed {
  double tau, mass;
};
Closed lagrange(const FourBar& f, double th, double thd, double thdd) {
  const Planar p = solve(f, th, thd, thdd);
  const Planar k = solve(f, th, 1.0, 0.0);  // kinematic coefficients dphi/dtheta
  double dT = 0, dV = 0, mass = 0;
  for (int i = 0; i < 3; ++i) {
    V2 vP = V2::Zero(), aP = V2::Zero(), kP = V2::Zero();
    if (i == 1) {  // the coupler pivots at B on the crank
      vP = f.a * ep(th) * thd;
      aP = f.a * ep(th) * thdd - f.a * e(th) * thd * thd;
      kP = f.a * ep(th);
    }
    const double ph = p.phi[i];
    const V2 Rr = Eigen::Rotation2Dd(ph) * V2(f.rx[i], f.ry[i]);
    const V2 kRr(-Rr.y(), Rr.x());  // k x (R r)
    const V2 vG = vP + p.w[i] * kRr;
    const V2 aG = aP + p.al[i] * kRr - p.w[i] * p.w[i] * Rr;
    dT += f.m[i] * vG.dot(aG) + f.Izz[i] * p.w[i] * p.al[i];
    dV += f.m[i] * f.g * vG.y();
    const V2 kG = kP + k.w[i] * kRr;
    mass += f.m[i] * kG.squaredNorm() + f.Izz[i] * k.w[i] * k.w[i];
  }
  return {(dT + dV) / thd, mass};
}

Eigen::Vector3d treeAngles(const Planar& p) {
  return {p.phi[0], std::remainder(p.phi[1] - p.phi[0], 2 * M_PI), p.phi[2]};
}

double wrapDiff(double x, double y) { return std::abs(std::remainder(x - y, 2 * M_PI)); }

RobotModel assembledFourBar(std::mt19937& rng, FourBar* f) {
  FourBar base;
  RobotModel m = fourBarModel(base, rng, f);
  const Planar p0 = solve(*f, 0.3, 0.0, 0.0);
  m.closed.reference = treeAngles(p0);
  m.validateStructure();
  return m;
}

}  // namespace

TEST(ClosedChain, FourBarPositionsVelocitiesAccelerations) {
  std::mt19937 rng(401);
  FourBar f;
  const RobotModel m = assembledFourBar(rng, &f);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int t = 0; t < 50; ++t) {
    const double th = M_PI * U(rng), thd = 3 * U(rng), thdd = 5 * U(rng);
    const Planar p = solve(f, th, thd, thdd);
    Eigen::VectorXd q, qd, qdd;
    const Eigen::VectorXd qa = Eigen::VectorXd::Constant(1, th),
                          qda = Eigen::VectorXd::Constant(1, thd),
                          qdda = Eigen::VectorXd::Constant(1, thdd);
    closedChainState(m, qa, &qda, &qdda, &q, &qd, &qdd, nullptr, nullptr);
    const Eigen::Vector3d q_ref = treeAngles(p);
    for (int i = 0; i < 3; ++i) EXPECT_LT(wrapDiff(q[i], q_ref[i]), 1e-11) << "joint " << i;
    EXPECT_NEAR(qd[1], p.w[1] - p.w[0], 1e-11);
    EXPECT_NEAR(qd[2], p.w[2], 1e-11);
    EXPECT_NEAR(qdd[1], p.al[1] - p.al[0], 1e-10);
    EXPECT_NEAR(qdd[2], p.al[2], 1e-10);
    Eigen::VectorXd c;
    loopConstraint(m, q, &c, nullptr);
    EXPECT_LT(c.lpNorm<Eigen::Infinity>(), 1e-12);
  }
}

TEST(ClosedChain, FourBarTorqueAgainstLagrange) {
  std::mt19937 rng(402);
  FourBar f;
  const RobotModel m = assembledFourBar(rng, &f);
  auto data = makeDynamicsData(m);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const DriveColumns none;
  double worst = 0.0;
  for (int t = 0; t < 100; ++t) {
    const double th = M_PI * U(rng);
    const double thd = (0.5 + 2.5 * std::abs(U(rng))) * (U(rng) < 0 ? -1 : 1);
    const double thdd = 5 * U(rng);
    const Closed ref = lagrange(f, th, thd, thdd);
    const Eigen::VectorXd qa = Eigen::VectorXd::Constant(1, th),
                          qda = Eigen::VectorXd::Constant(1, thd),
                          qdda = Eigen::VectorXd::Constant(1, thdd);
    const Eigen::VectorXd tau = actuatorTorque(m, *data, none, qa, qda, qdda);
    ASSERT_EQ(tau.size(), 1);
    const double scale = std::max(1.0, std::abs(ref.tau));
    EXPECT_NEAR(tau[0], ref.tau, 1e-10 * scale) << "theta " << th;
    worst = std::max(worst, std::abs(tau[0] - ref.tau) / scale);
    // a crank that has turned seven times more: the same state
    const Eigen::VectorXd qa7 = Eigen::VectorXd::Constant(1, th + 14 * M_PI);
    EXPECT_NEAR(actuatorTorque(m, *data, none, qa7, qda, qdda)[0], ref.tau, 1e-10 * scale);
    // the regressor times the standard parameters
    Eigen::MatrixXd Y(1, numParameters(m, none));
    actuatorRegressor(m, *data, none, qa, qda, qdda, Y);
    EXPECT_NEAR((Y * parameterValues(m, none))[0], ref.tau, 1e-10 * scale);
    // the mass matrix G^T M G against the closed-form mass coefficient
    Eigen::VectorXd tm;
    Eigen::MatrixXd Mq;
    actuatorTorqueDerivatives(m, *data, none, qa, qda, qdda, &tm, nullptr, nullptr, &Mq);
    EXPECT_NEAR(Mq(0, 0), ref.mass, 1e-10 * std::max(1.0, ref.mass));
    EXPECT_NEAR(tm[0], tau[0], 1e-12 * scale);
  }
  {
    std::ostringstream os;
    os << std::scientific << worst;
    RecordProperty("worst_relative", os.str());
  }
}

TEST(ClosedChain, ConstraintJacobianAndBiasAgainstFiniteDifferences) {
  // A spatial mechanism (not assembled: the Jacobian is exact everywhere) with a revolute and a
  // spherical cut joint, prismatic and revolute tree joints.
  std::mt19937 rng(403);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  RobotModel m;
  m.name = "spatial";
  for (int i = 0; i < 5; ++i) {
    Body b;
    b.name = "b" + std::to_string(i);
    b.joint_name = "j" + std::to_string(i);
    b.parent = i == 0 ? -1 : (i == 3 ? 0 : i - 1);
    b.type = i == 2 ? JointType::Prismatic : JointType::Revolute;
    b.axis = Eigen::Vector3d(U(rng), U(rng), U(rng)).normalized();
    b.pre.p = Eigen::Vector3d(U(rng), U(rng), U(rng)) * 0.3;
    b.pre.R = Eigen::AngleAxisd(U(rng), Eigen::Vector3d(U(rng), U(rng), U(rng)).normalized())
                  .toRotationMatrix();
    b.post.R = Eigen::AngleAxisd(U(rng), Eigen::Vector3d::UnitX()).toRotationMatrix();
    b.post.p = Eigen::Vector3d(U(rng), U(rng), U(rng)) * 0.1;
    m.bodies.push_back(b);
  }
  LoopJoint r, s;
  r.body_a = 2, r.body_b = 4, s.body_a = -1, s.body_b = 2;
  s.kind = LoopJoint::Kind::Spherical;
  for (LoopJoint* L : {&r, &s}) {
    L->pose_a.p = Eigen::Vector3d(U(rng), U(rng), U(rng)) * 0.2;
    L->pose_b.p = Eigen::Vector3d(U(rng), U(rng), U(rng)) * 0.2;
    L->pose_a.R = Eigen::AngleAxisd(U(rng), Eigen::Vector3d::UnitY()).toRotationMatrix();
    L->pose_b.R = Eigen::AngleAxisd(U(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  r.axis = Eigen::Vector3d(0.3, -0.4, 0.5).normalized();
  m.closed.loops = {r, s};
  ASSERT_EQ(numLoopConstraints(m), 8);
  for (int t = 0; t < 5; ++t) {
    Eigen::VectorXd q(5), qd(5);
    for (int i = 0; i < 5; ++i) q[i] = U(rng), qd[i] = 2 * U(rng);
    Eigen::VectorXd c;
    Eigen::MatrixXd J;
    loopConstraint(m, q, &c, &J);
    const double h = 1e-6;
    for (int j = 0; j < 5; ++j) {
      Eigen::VectorXd qp = q, qm = q, cp, cm;
      qp[j] += h, qm[j] -= h;
      loopConstraint(m, qp, &cp, nullptr);
      loopConstraint(m, qm, &cm, nullptr);
      EXPECT_LT(((cp - cm) / (2 * h) - J.col(j)).lpNorm<Eigen::Infinity>(), 1e-8) << j;
    }
    // bias = d/dt (J qd) at qdd = 0 = (dJ/dq qd) qd
    Eigen::MatrixXd Jp, Jm;
    loopConstraint(m, q + h * qd, nullptr, &Jp);
    loopConstraint(m, q - h * qd, nullptr, &Jm);
    const Eigen::VectorXd fd = (Jp - Jm) / (2 * h) * qd;
    EXPECT_LT((loopConstraintBias(m, q, qd) - fd).lpNorm<Eigen::Infinity>(), 1e-7);
  }
}

TEST(ClosedChain, Errors) {
  std::mt19937 rng(404);
  FourBar f;
  const RobotModel good = assembledFourBar(rng, &f);
  // a linkage that cannot close at every crank angle: |BD| = 0.7 > b + c at theta = pi
  {
    FourBar g;
    g.a = 0.3, g.b = 0.2, g.c = 0.2, g.d = 0.4;
    FourBar gf;
    RobotModel m = fourBarModel(g, rng, &gf);
    m.closed.reference = treeAngles(solve(gf, 0.5, 0, 0));
    m.validateStructure();
    try {
      closedChainState(m, Eigen::VectorXd::Constant(1, M_PI), nullptr, nullptr, nullptr, nullptr,
                       nullptr, nullptr, nullptr);
      FAIL() << "expected no assembly";
    } catch (const Error& e) {
      const std::string w = e.what();
      EXPECT_NE(w.find("does not assemble"), std::string::npos) << w;
      EXPECT_NE(w.find("'C'"), std::string::npos) << w;
      EXPECT_NE(w.find("fourbar_test"), std::string::npos) << w;
      EXPECT_NE(w.find("3.14159"), std::string::npos) << w;
    }
    // where it does close, it solves
    EXPECT_NO_THROW(closedChainState(m, Eigen::VectorXd::Constant(1, 0.7), nullptr, nullptr,
                                     nullptr, nullptr, nullptr, nullptr, nullptr));
  }
  {  // two actuated joints on a mechanism of mobility 1
    RobotModel m = good;
    m.closed.actuated = {0, 2};
    m.limits.assign(2, JointLimits{});
    m.drives.assign(2, Drive{});
    try {
      m.validateStructure();
      FAIL();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("not independent"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("mobility is 1"), std::string::npos) << e.what();
    }
  }
  {  // no actuated joint
    RobotModel m = good;
    m.closed.actuated.clear();
    m.limits.clear();
    m.drives.clear();
    EXPECT_THROW(m.validateStructure(), Error);
  }
  {  // an unknown body
    RobotModel m = good;
    m.closed.loops[0].body_b = 7;
    EXPECT_THROW(m.validateStructure(), Error);
  }
  {  // a transmission on a closed chain
    RobotModel m = good;
    m.transmission = Eigen::MatrixXd::Identity(1, 1);
    EXPECT_THROW(m.validateStructure(), Error);
  }
  {  // the regressor's gradient through the loops (tests/excitation/closed_chain_gradient_test):
     // its inputs' sizes are checked
    auto d = makeDynamicsData(good);
    const DriveColumns none;
    const Eigen::VectorXd z = Eigen::VectorXd::Zero(1), z3 = Eigen::VectorXd::Zero(3);
    Eigen::VectorXd g1, g2, g3;
    EXPECT_NO_THROW(actuatorRegressorVjp(good, *d, none, z, z, z,
                                         Eigen::MatrixXd::Zero(1, numParameters(good, none)), &g1,
                                         &g2, &g3));
    EXPECT_EQ(g1.size(), 1);
    EXPECT_THROW(actuatorRegressorVjp(good, *d, none, z, z, z,
                                      Eigen::MatrixXd::Zero(1, numParameters(good, none) + 1), &g1,
                                      &g2, &g3),
                 Error);
    EXPECT_THROW(
        actuatorRegressorVjp(good, *d, none, z3, z, z,
                             Eigen::MatrixXd::Zero(1, numParameters(good, none)), &g1, &g2, &g3),
        Error);
    Eigen::VectorXd gq = z;  // a tree gradient has numJoints entries
    EXPECT_THROW(jointGradientToMeasured(good, z, z, z, &gq, nullptr, nullptr), Error);
  }
}
