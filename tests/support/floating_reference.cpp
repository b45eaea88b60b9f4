// exid tests — the virtual-chain reference of floating-base robots (floating_reference.hpp).
#include "floating_reference.hpp"

#include <Eigen/Geometry>

#include "dyn_reference.hpp"

namespace exid::testing {

RobotModel virtualChain(const RobotModel& f, const Eigen::Vector3d& g_w) {
  RobotModel m;
  m.name = f.name + "_virtual_chain";
  const char* names[6] = {"vx", "vy", "vz", "vyaw", "vpitch", "vroll"};
  const Eigen::Vector3d axes[6] = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                   Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitZ(),
                                   Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitX()};
  for (int k = 0; k < 6; ++k) {
    Body b;
    b.name = names[k];
    b.joint_name = std::string(names[k]) + "_joint";
    b.parent = k - 1;
    b.type = k < 3 ? JointType::Prismatic : JointType::Revolute;
    b.axis = axes[k];
    m.bodies.push_back(b);  // massless
  }
  Body base;
  base.name = f.base.link.empty() ? "base" : f.base.link;
  base.joint_name = "vfix";
  base.parent = 5;
  // a revolute joint held at q = 0 with zero velocity and acceleration: the base link rigidly
  // on the roll body (its row is not compared)
  base.type = JointType::Revolute;
  base.inertia = f.base.inertia;
  m.bodies.push_back(base);
  for (const Body& b0 : f.bodies) {
    Body b = b0;
    b.parent = b0.parent < 0 ? 6 : b0.parent + 7;
    m.bodies.push_back(b);
  }
  m.limits.assign(m.bodies.size(), JointLimits{});
  m.drives.assign(m.bodies.size(), Drive{});
  m.gravity = g_w;
  return m;
}

Eigen::VectorXd virtualCoordinates(const Eigen::Matrix<double, 6, 1>& v, const Eigen::VectorXd& q) {
  Eigen::VectorXd x(7 + q.size());
  x.head<6>() = v;
  x[6] = 0.0;
  x.tail(q.size()) = q;
  return x;
}

BaseMotion virtualBaseMotion(const RobotModel& chain, const Eigen::VectorXd& qv,
                             const Eigen::VectorXd& qdv, const Eigen::VectorXd& qddv) {
  const auto st = refKinematics(chain, qv, qdv, qddv, true);
  const RefBodyState& b = st[6];
  BaseMotion m;
  m.segment<3>(0) = b.R.transpose() * b.w;
  m.segment<3>(3) = b.R.transpose() * b.wd;
  m.segment<3>(6) = b.R.transpose() * b.a;  // includes -g
  return m;
}

Eigen::Matrix<double, 6, 6> virtualRowMap(const Eigen::Matrix<double, 6, 1>& v) {
  const Eigen::Matrix3d Rz = refRot(Eigen::Vector3d::UnitZ(), v[3]);
  const Eigen::Matrix3d Ry = refRot(Eigen::Vector3d::UnitY(), v[4]);
  const Eigen::Matrix3d Rx = refRot(Eigen::Vector3d::UnitX(), v[5]);
  const Eigen::Matrix3d R = Rz * Ry * Rx;
  Eigen::Matrix<double, 6, 6> T = Eigen::Matrix<double, 6, 6>::Zero();
  T.block<3, 3>(0, 0) = R;  // rows e_x, e_y, e_z
  const Eigen::Vector3d a[3] = {Eigen::Vector3d::UnitZ(), Rz * Eigen::Vector3d::UnitY(),
                                Rz * Ry * Eigen::Vector3d::UnitX()};
  for (int k = 0; k < 3; ++k) T.block<1, 3>(3 + k, 3) = a[k].transpose() * R;
  return T;
}

}  // namespace exid::testing
