#include "dyn_robots.hpp"

#include <cmath>
#include <vector>

#include "exid/dh.hpp"

namespace exid::testing {

namespace {
constexpr double kPi2 = 1.5707963268;
constexpr double kDeg = M_PI / 180.0;

Eigen::Matrix3d inertia(double xx, double yy, double zz, double xy, double yz, double xz) {
  Eigen::Matrix3d I;
  I << xx, xy, xz, xy, yy, yz, xz, yz, zz;
  return I;
}
}  // namespace

RobotModel puma560Standard() {
  // d, a, alpha per row; m, r, I = [Ixx Iyy Izz Ixy Iyz Ixz] about COM; Jm, G, B, Tc+; qlim (deg)
  struct Row {
    double d, a, alpha, m, rx, ry, rz, I[6], Jm, G, B, Tc, qmin, qmax;
  };
  const Row rows[6] = {{0.0,
                        0.0,
                        kPi2,
                        0.0,
                        0,
                        0,
                        0,
                        {0, 0.35, 0, 0, 0, 0},
                        200e-6,
                        -62.6111,
                        1.48e-3,
                        0.395,
                        -160,
                        160},
                       {0.0,
                        0.4318,
                        0.0,
                        17.4,
                        -0.3638,
                        0.006,
                        0.2275,
                        {0.13, 0.524, 0.539, 0, 0, 0},
                        200e-6,
                        107.815,
                        0.817e-3,
                        0.126,
                        -45,
                        225},
                       {0.15005,
                        0.0203,
                        -kPi2,
                        4.8,
                        -0.0203,
                        -0.0141,
                        0.070,
                        {0.066, 0.086, 0.0125, 0, 0, 0},
                        200e-6,
                        -53.7063,
                        1.38e-3,
                        0.132,
                        -225,
                        45},
                       {0.4318,
                        0.0,
                        kPi2,
                        0.82,
                        0,
                        0.019,
                        0,
                        {1.8e-3, 1.3e-3, 1.8e-3, 0, 0, 0},
                        33e-6,
                        76.0364,
                        71.2e-6,
                        11.2e-3,
                        -110,
                        170},
                       {0.0,
                        0.0,
                        -kPi2,
                        0.34,
                        0,
                        0,
                        0,
                        {0.3e-3, 0.4e-3, 0.3e-3, 0, 0, 0},
                        33e-6,
                        71.923,
                        82.6e-6,
                        9.26e-3,
                        -100,
                        100},
                       {0.0,
                        0.0,
                        0.0,
                        0.09,
                        0,
                        0,
                        0.032,
                        {0.15e-3, 0.15e-3, 0.04e-3, 0, 0, 0},
                        33e-6,
                        76.686,
                        36.7e-6,
                        3.96e-3,
                        -266,
                        266}};
  std::vector<DhRow> dh;
  for (const Row& r : rows) dh.push_back({JointType::Revolute, r.a, r.alpha, r.d, 0.0});
  RobotModel m = serialDh(dh, DhConvention::Standard);
  m.name = "puma560";
  for (int j = 0; j < 6; ++j) {
    const Row& r = rows[j];
    m.bodies[static_cast<size_t>(j)].inertia = inertialFromCom(
        r.m, {r.rx, r.ry, r.rz}, inertia(r.I[0], r.I[1], r.I[2], r.I[3], r.I[4], r.I[5]));
    m.limits[static_cast<size_t>(j)].q_min = r.qmin * kDeg;
    m.limits[static_cast<size_t>(j)].q_max = r.qmax * kDeg;
    Drive& d = m.drives[static_cast<size_t>(j)];
    d.gear_ratio = r.G;
    d.rotor_inertia = r.Jm * r.G * r.G;
    d.viscous = r.B * r.G * r.G;
    d.coulomb = r.Tc * std::abs(r.G);
  }
  return m;
}

RobotModel puma560Akb() {
  struct Row {
    double d, a, alpha, m, rx, ry, rz, I[6];
  };
  const Row rows[6] = {
      {0.0, 0.0, 0.0, 0.0, 0, 0, 0, {0, 0, 0.35, 0, 0, 0}},
      {0.2435, 0.0, -kPi2, 17.4, 0.068, 0.006, -0.016, {0.13, 0.524, 0.539, 0, 0, 0}},
      {-0.0934, 0.4318, 0.0, 4.8, 0, -0.070, 0.014, {0.066, 0.0125, 0.066, 0, 0, 0}},
      {0.4331, -0.0203, kPi2, 0.82, 0, 0, -0.019, {1.8e-3, 1.8e-3, 1.3e-3, 0, 0, 0}},
      {0.0, 0.0, -kPi2, 0.34, 0, 0, 0, {0.3e-3, 0.3e-3, 0.4e-3, 0, 0, 0}},
      {0.0, 0.0, kPi2, 0.09, 0, 0, 0.032, {0.15e-3, 0.15e-3, 0.04e-3, 0, 0, 0}}};
  std::vector<DhRow> dh;
  for (const Row& r : rows) dh.push_back({JointType::Revolute, r.a, r.alpha, r.d, 0.0});
  RobotModel m = serialDh(dh, DhConvention::Modified);
  m.name = "puma560_akb";
  for (int j = 0; j < 6; ++j) {
    const Row& r = rows[j];
    m.bodies[static_cast<size_t>(j)].inertia = inertialFromCom(
        r.m, {r.rx, r.ry, r.rz}, inertia(r.I[0], r.I[1], r.I[2], r.I[3], r.I[4], r.I[5]));
    m.limits[static_cast<size_t>(j)].q_min = -M_PI;
    m.limits[static_cast<size_t>(j)].q_max = M_PI;
  }
  return m;
}

RobotModel panda() {
  const double a[7] = {0, 0, 0, 0.0825, -0.0825, 0, 0.088};
  const double al[7] = {0, -kPi2, kPi2, kPi2, -kPi2, kPi2, kPi2};
  const double d[7] = {0.333, 0, 0.316, 0, 0.384, 0, 0};
  const double mass[7] = {4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 7.35522e-01};
  const double c[7][3] = {{3.875e-03, 2.081e-03, 0.0},
                          {-3.141e-03, -2.872e-02, 3.495e-03},
                          {2.7518e-02, 3.9252e-02, -6.6502e-02},
                          {-5.317e-02, 1.04419e-01, 2.7454e-02},
                          {-1.1953e-02, 4.1065e-02, -3.8437e-02},
                          {6.0149e-02, -1.4117e-02, -1.0517e-02},
                          {1.0517e-02, -4.252e-03, 6.1597e-02}};
  // [Ixx, Ixy, Ixz, Iyy, Iyz, Izz] about the COM
  const double I[7][6] = {
      {7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03},
      {7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02},
      {3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02, 1.0830e-02},
      {2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02},
      {3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03},
      {1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03},
      {1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04, 4.8150e-03}};
  const double qmin[7] = {-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973};
  const double qmax[7] = {2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973};
  std::vector<DhRow> dh;
  for (int j = 0; j < 7; ++j) dh.push_back({JointType::Revolute, a[j], al[j], d[j], 0.0});
  RobotModel m = serialDh(dh, DhConvention::Modified);
  m.name = "panda";
  for (int j = 0; j < 7; ++j) {
    m.bodies[static_cast<size_t>(j)].inertia =
        inertialFromCom(mass[j], {c[j][0], c[j][1], c[j][2]},
                        inertia(I[j][0], I[j][3], I[j][5], I[j][1], I[j][4], I[j][2]));
    m.limits[static_cast<size_t>(j)].q_min = qmin[j];
    m.limits[static_cast<size_t>(j)].q_max = qmax[j];
  }
  m.sensor_pose.p = Eigen::Vector3d(0, 0, 0.107);
  return m;
}

RobotModel planar2R(bool vertical) {
  RobotModel m = serialDh(
      {{JointType::Revolute, 1.0, 0.0, 0.0, 0.0}, {JointType::Revolute, 0.8, 0.0, 0.0, 0.0}},
      DhConvention::Standard);
  m.name = vertical ? "planar2r_vertical" : "planar2r_horizontal";
  m.gravity = vertical ? Eigen::Vector3d(0, -9.81, 0) : Eigen::Vector3d(0, 0, -9.81);
  m.bodies[0].inertia = inertialFromCom(2.0, {-0.5, 0.01, 0.0}, inertia(0.01, 0.2, 0.2, 0, 0, 0));
  m.bodies[1].inertia = inertialFromCom(1.0, {-0.4, 0.0, 0.0}, inertia(0.005, 0.1, 0.1, 0, 0, 0));
  return m;
}

}  // namespace exid::testing
