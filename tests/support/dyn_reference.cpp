#include "dyn_reference.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <string>

namespace exid::testing {

namespace {
Eigen::Matrix3d symI(const Eigen::Matrix<double, 10, 1>& p) {
  Eigen::Matrix3d I;
  I << p[0], p[1], p[2], p[1], p[3], p[4], p[2], p[4], p[5];
  return I;
}
}  // namespace

Eigen::Matrix3d refRot(const Eigen::Vector3d& k, double t) {
  Eigen::Matrix3d K;
  K << 0, -k.z(), k.y(), k.z(), 0, -k.x(), -k.y(), k.x(), 0;
  return Eigen::Matrix3d::Identity() + std::sin(t) * K + (1 - std::cos(t)) * K * K;
}

std::vector<RefBodyState> refKinematics(const RobotModel& m, const Eigen::VectorXd& q,
                                        const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                        bool with_gravity) {
  const int n = m.numJoints();  // the tree (a closed chain's spanning tree)
  std::vector<RefBodyState> st(static_cast<size_t>(n));
  for (int j = 0; j < n; ++j) {
    const Body& b = m.bodies[static_cast<size_t>(j)];
    Eigen::Matrix3d Rp = Eigen::Matrix3d::Identity();
    Eigen::Vector3d op = Eigen::Vector3d::Zero(), wp = op, wdp = op, vp = op;
    Eigen::Vector3d ap = with_gravity ? Eigen::Vector3d(-m.gravity) : Eigen::Vector3d::Zero();
    if (b.parent >= 0) {
      const RefBodyState& P = st[static_cast<size_t>(b.parent)];
      Rp = P.R;
      op = P.o;
      wp = P.w;
      wdp = P.wd;
      ap = P.a;
      vp = P.v;
    }
    // joint frame (before motion) in base
    const Eigen::Matrix3d RJ = Rp * b.pre.R;
    const Eigen::Vector3d oJ = op + Rp * b.pre.p;
    const Eigen::Vector3d z = RJ * b.axis;
    Eigen::Matrix3d Rm = Eigen::Matrix3d::Identity();
    Eigen::Vector3d pm = Eigen::Vector3d::Zero();
    if (b.type == JointType::Revolute)
      Rm = refRot(b.axis, q[j]);
    else
      pm = b.axis * q[j];
    RefBodyState& S = st[static_cast<size_t>(j)];
    const Eigen::Matrix3d RJm = RJ * Rm;       // moved joint frame
    const Eigen::Vector3d oJm = oJ + RJ * pm;  // its origin
    S.R = RJm * b.post.R;
    S.o = oJm + RJm * b.post.p;
    if (b.type == JointType::Revolute) {
      S.w = wp + z * qd[j];
      S.wd = wdp + z * qdd[j] + wp.cross(z * qd[j]);
      // joint origin is fixed in parent and in the body
      const Eigen::Vector3d r1 = oJ - op, r2 = S.o - oJ;
      const Eigen::Vector3d vJ = vp + wp.cross(r1);
      const Eigen::Vector3d aJ = ap + wdp.cross(r1) + wp.cross(wp.cross(r1));
      S.v = vJ + S.w.cross(r2);
      S.a = aJ + S.wd.cross(r2) + S.w.cross(S.w.cross(r2));
    } else {
      S.w = wp;
      S.wd = wdp;
      const Eigen::Vector3d r = S.o - op;  // point of the parent at the body origin, plus sliding
      S.v = vp + wp.cross(r) + z * qd[j];
      S.a = ap + wdp.cross(r) + wp.cross(wp.cross(r)) + 2.0 * wp.cross(z * qd[j]) + z * qdd[j];
    }
  }
  return st;
}

Eigen::VectorXd refTorques(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                           const Eigen::VectorXd& qdd, const Eigen::VectorXd& pi) {
  const int n = m.numJoints();  // the tree (a closed chain's spanning tree)
  const auto st = refKinematics(m, q, qd, qdd, true);
  std::vector<Eigen::Vector3d> F(static_cast<size_t>(n)),
      N(static_cast<size_t>(n));  // N about base origin
  for (int j = 0; j < n; ++j) {
    const RefBodyState& S = st[static_cast<size_t>(j)];
    const Eigen::Matrix<double, 10, 1> p = pi.segment<10>(10 * j);
    const double mass = p[9];
    Eigen::Vector3d f, nc, c;
    if (mass != 0.0) {
      const Eigen::Vector3d cb = p.segment<3>(6) / mass;
      const Eigen::Matrix3d Ic =
          symI(p) - mass * (cb.squaredNorm() * Eigen::Matrix3d::Identity() - cb * cb.transpose());
      c = S.o + S.R * cb;
      const Eigen::Matrix3d Icw = S.R * Ic * S.R.transpose();
      const Eigen::Vector3d r = c - S.o;
      const Eigen::Vector3d ac = S.a + S.wd.cross(r) + S.w.cross(S.w.cross(r));
      f = mass * ac;
      nc = Icw * S.wd + S.w.cross(Icw * S.w);
    } else {
      // massless: only the (about-origin) inertia and first moment terms
      const Eigen::Matrix3d Iw = S.R * symI(p) * S.R.transpose();
      const Eigen::Vector3d h = S.R * p.segment<3>(6);
      c = S.o;
      f = S.wd.cross(h) + S.w.cross(S.w.cross(h));
      nc = Iw * S.wd + S.w.cross(Iw * S.w) + h.cross(S.a);
    }
    F[static_cast<size_t>(j)] = f;
    N[static_cast<size_t>(j)] = nc + c.cross(f);
  }
  for (int j = n - 1; j >= 0; --j) {
    const int par = m.bodies[static_cast<size_t>(j)].parent;
    if (par >= 0) {
      F[static_cast<size_t>(par)] += F[static_cast<size_t>(j)];
      N[static_cast<size_t>(par)] += N[static_cast<size_t>(j)];
    }
  }
  Eigen::VectorXd tau(n);
  for (int j = 0; j < n; ++j) {
    const Body& b = m.bodies[static_cast<size_t>(j)];
    Eigen::Matrix3d Rp = Eigen::Matrix3d::Identity();
    Eigen::Vector3d op = Eigen::Vector3d::Zero();
    if (b.parent >= 0) {
      Rp = st[static_cast<size_t>(b.parent)].R;
      op = st[static_cast<size_t>(b.parent)].o;
    }
    const Eigen::Vector3d z = Rp * b.pre.R * b.axis;
    const Eigen::Vector3d oJ = op + Rp * b.pre.p;
    if (b.type == JointType::Revolute)
      tau[j] = z.dot(N[static_cast<size_t>(j)] - oJ.cross(F[static_cast<size_t>(j)]));
    else
      tau[j] = z.dot(F[static_cast<size_t>(j)]);
  }
  return tau;
}

void refEnergy(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
               const Eigen::VectorXd& pi, double* T, double* U) {
  const int n = m.numJoints();  // the tree (a closed chain's spanning tree)
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
  const auto st = refKinematics(m, q, qd, z, false);
  double t = 0, u = 0;
  for (int j = 0; j < n; ++j) {
    const RefBodyState& S = st[static_cast<size_t>(j)];
    const Eigen::Matrix<double, 10, 1> p = pi.segment<10>(10 * j);
    // T = 1/2 m v^2 + v . (w x h) + 1/2 w^T I w  (about the origin, base frame)
    const Eigen::Matrix3d Iw = S.R * symI(p) * S.R.transpose();
    const Eigen::Vector3d h = S.R * p.segment<3>(6);
    t += 0.5 * p[9] * S.v.squaredNorm() + S.v.dot(S.w.cross(h)) + 0.5 * S.w.dot(Iw * S.w);
    u += -m.gravity.dot(h + p[9] * S.o);
  }
  *T = t;
  *U = u;
}

Eigen::Matrix<double, 6, 1> refPayloadWrench(const RobotModel& m, const Eigen::VectorXd& q,
                                             const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                             const Eigen::Matrix<double, 10, 1>& phi) {
  const auto st = refKinematics(m, q, qd, qdd, true);
  const RefBodyState& B = st[static_cast<size_t>(m.sensorBody())];
  const Eigen::Matrix3d Rs = B.R * m.sensor_pose.R;
  const Eigen::Vector3d os = B.o + B.R * m.sensor_pose.p;
  const Eigen::Vector3d r = os - B.o;
  const Eigen::Vector3d as = B.a + B.wd.cross(r) + B.w.cross(B.w.cross(r));
  const double mass = phi[0];
  const Eigen::Vector3d cs = phi.segment<3>(1) / mass;  // in sensor frame
  Eigen::Matrix3d I;
  I << phi[4], phi[5], phi[6], phi[5], phi[7], phi[8], phi[6], phi[8], phi[9];
  const Eigen::Matrix3d Ic =
      I - mass * (cs.squaredNorm() * Eigen::Matrix3d::Identity() - cs * cs.transpose());
  const Eigen::Vector3d c = os + Rs * cs;
  const Eigen::Vector3d rc = c - os;
  const Eigen::Vector3d ac = as + B.wd.cross(rc) + B.w.cross(B.w.cross(rc));
  const Eigen::Vector3d f = mass * ac;
  const Eigen::Matrix3d Icw = Rs * Ic * Rs.transpose();
  const Eigen::Vector3d nO =
      Icw * B.wd + B.w.cross(Icw * B.w) + rc.cross(f);  // about sensor origin
  Eigen::Matrix<double, 6, 1> w;
  w << Rs.transpose() * f, Rs.transpose() * nO;
  return w;
}

Eigen::VectorXd randomVec(std::mt19937& rng, int n, double s) {
  std::uniform_real_distribution<double> U(-s, s);
  Eigen::VectorXd x(n);
  for (int i = 0; i < n; ++i) x[i] = U(rng);
  return x;
}

Eigen::Matrix<double, 10, 1> randomInertia(std::mt19937& rng, double size) {
  std::uniform_real_distribution<double> U(-size, size), M(0.1, 2.0);
  Eigen::Matrix<double, 10, 1> p = Eigen::Matrix<double, 10, 1>::Zero();
  for (int k = 0; k < 6; ++k) {  // point masses: always physically consistent
    const double mk = M(rng);
    const Eigen::Vector3d x(U(rng), U(rng), U(rng));
    const Eigen::Matrix3d I =
        mk * (x.squaredNorm() * Eigen::Matrix3d::Identity() - x * x.transpose());
    p[0] += I(0, 0);
    p[1] += I(0, 1);
    p[2] += I(0, 2);
    p[3] += I(1, 1);
    p[4] += I(1, 2);
    p[5] += I(2, 2);
    p.segment<3>(6) += mk * x;
    p[9] += mk;
  }
  return p;
}

Pose randomPose(std::mt19937& rng, double scale) {
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::Vector3d k(N(rng), N(rng), N(rng));
  Pose P;
  P.R = refRot(k.normalized(), 3.0 * std::uniform_real_distribution<double>(-1, 1)(rng));
  P.p = randomVec(rng, 3, scale);
  return P;
}

RobotModel randomTree(std::mt19937& rng, int n, bool identity_post) {
  RobotModel m;
  m.name = "random_tree";
  std::normal_distribution<double> N(0.0, 1.0);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int j = 0; j < n; ++j) {
    Body b;
    b.name = "b" + std::to_string(j + 1);
    b.joint_name = "j" + std::to_string(j + 1);
    b.parent = j == 0 ? -1 : static_cast<int>(std::floor(U(rng) * (j + 1))) - 1;
    if (b.parent >= j) b.parent = j - 1;
    b.pre = randomPose(rng);
    b.post = identity_post ? Pose{} : randomPose(rng);
    const double r = U(rng);
    if (r < 0.25)
      b.axis = Eigen::Vector3d::UnitZ();
    else if (r < 0.3)
      b.axis = -Eigen::Vector3d::UnitZ();
    else
      b.axis = Eigen::Vector3d(N(rng), N(rng), N(rng)).normalized();
    b.type = U(rng) < 0.25 ? JointType::Prismatic : JointType::Revolute;
    b.inertia = randomInertia(rng);
    m.bodies.push_back(b);
  }
  m.limits.assign(static_cast<size_t>(n), JointLimits{});
  m.drives.assign(static_cast<size_t>(n), Drive{});
  m.gravity = Eigen::Vector3d(N(rng), N(rng), N(rng)).normalized() * 9.81;
  m.sensor_body = static_cast<int>(U(rng) * n);
  if (m.sensor_body >= n) m.sensor_body = n - 1;
  m.sensor_pose = randomPose(rng, 0.2);
  return m;
}

}  // namespace exid::testing
