// exid — DH tables to bodies. See dh.hpp for the conventions.
#include "exid/dh.hpp"

#include <cmath>
#include <string>

#include "exid/fmath.hpp"

namespace exid {

Pose rotX(double a) {
  Pose P;
  const double c = exid::fmath::cos(a), s = exid::fmath::sin(a);
  P.R << 1, 0, 0, 0, c, -s, 0, s, c;
  return P;
}
Pose rotZ(double a) {
  Pose P;
  const double c = exid::fmath::cos(a), s = exid::fmath::sin(a);
  P.R << c, -s, 0, s, c, 0, 0, 0, 1;
  return P;
}
Pose transX(double d) {
  Pose P;
  P.p.x() = d;
  return P;
}
Pose transZ(double d) {
  Pose P;
  P.p.z() = d;
  return P;
}

Body dhBody(const DhRow& row, DhConvention conv, int parent) {
  Body b;
  b.parent = parent;
  b.type = row.type;
  b.axis = Eigen::Vector3d::UnitZ();
  if (conv == DhConvention::Standard) {
    b.pre = rotZ(row.theta) * transZ(row.d);
    b.post = transX(row.a) * rotX(row.alpha);
  } else {
    b.pre = rotX(row.alpha) * transX(row.a) * rotZ(row.theta) * transZ(row.d);
    b.post = Pose{};
  }
  return b;
}

RobotModel serialDh(const std::vector<DhRow>& rows, DhConvention conv) {
  RobotModel m;
  m.name = conv == DhConvention::Standard ? "dh" : "modified_dh";
  m.source = "serialDh";
  const int n = static_cast<int>(rows.size());
  for (int i = 0; i < n; ++i) {
    Body b = dhBody(rows[static_cast<size_t>(i)], conv, i - 1);
    b.name = "link" + std::to_string(i + 1);
    b.joint_name = "joint" + std::to_string(i + 1);
    m.bodies.push_back(b);
  }
  m.limits.assign(static_cast<size_t>(n), JointLimits{});
  m.drives.assign(static_cast<size_t>(n), Drive{});
  return m;
}

}  // namespace exid
