// exid — what the robot description writers share (see model_text.hpp).
#include "model_text.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>

#include "exid/closed_chain.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid::detail {

std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v == 0.0 ? 0.0 : v);  // (no "-0")
  return buf;
}

std::string vec3(const Eigen::Vector3d& v) {
  return num(v.x()) + " " + num(v.y()) + " " + num(v.z());
}

Eigen::Vector3d rpy(const Eigen::Matrix3d& R) {
  const double cp = std::hypot(R(2, 1), R(2, 2));
  if (cp < 1e-10) {
    const double pitch = R(2, 0) < 0 ? M_PI / 2 : -M_PI / 2;
    return {std::atan2(-R(1, 2), R(1, 1)), pitch, 0.0};
  }
  return {std::atan2(R(2, 1), R(2, 2)), std::atan2(-R(2, 0), cp), std::atan2(R(1, 0), R(0, 0))};
}

std::string xmlEscape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '&':
        o += "&amp;";
        break;
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '"':
        o += "&quot;";
        break;
      default:
        o += c;
    }
  }
  return o;
}

std::string xmlComment(const std::string& text) {
  if (text.empty()) return {};
  std::string c = text;
  for (std::size_t k; (k = c.find("--")) != std::string::npos;) c.replace(k, 2, "- -");
  return "<!--\n" + c + "\n-->\n";
}

bool finiteLimit(double v) { return std::isfinite(v) && std::abs(v) < 1e299; }

std::string freeName(std::string base, const std::set<std::string>& taken) {
  while (taken.count(base)) base += "_";
  return base;
}

std::vector<JointDriveTerms> jointDriveTerms(const RobotModel& m, std::vector<int>* coupled) {
  const int n = m.dof();
  const int nd = std::min(n, static_cast<int>(m.drives.size()));
  std::vector<JointDriveTerms> out(static_cast<std::size_t>(n));
  Eigen::MatrixXd Tinv = Eigen::MatrixXd::Identity(n, n);
  if (m.hasTransmission()) {
    const Eigen::FullPivLU<Eigen::MatrixXd> lu(m.transmission);
    if (!lu.isInvertible()) {
      for (int j = 0; j < nd; ++j) coupled->push_back(j);
      return out;
    }
    Tinv = lu.inverse();
  }
  for (int j = 0; j < nd; ++j) {
    // Entries below 1e-12 of the row's largest are the rounding of an exact zero of T^-1.
    const double big = Tinv.row(j).cwiseAbs().maxCoeff();
    int at = -1, count = 0;
    for (int i = 0; i < n; ++i)
      if (std::abs(Tinv(j, i)) > 1e-12 * big) {
        at = i;
        ++count;
      }
    if (count != 1) {
      coupled->push_back(j);
      continue;
    }
    const double r = Tinv(j, at);
    const Drive& d = m.drives[static_cast<std::size_t>(j)];
    JointDriveTerms& t = out[static_cast<std::size_t>(at)];
    t.rotor_inertia += d.rotor_inertia * r * r;
    t.viscous += d.viscous * r * r;
    t.coulomb += d.coulomb * std::abs(r);
  }
  return out;
}

std::string joinNumbers(const std::vector<int>& zero_based) {
  std::string s;
  for (std::size_t k = 0; k < zero_based.size(); ++k)
    s += (k ? ", " : "") + std::to_string(zero_based[k] + 1);
  return s;
}

void leftOutOfEveryFormat(const RobotModel& m, const std::vector<int>& coupled,
                          const std::string& format, std::vector<std::string>* out) {
  const int nd = std::min(m.dof(), static_cast<int>(m.drives.size()));
  std::vector<int> offset, coupled_terms, gear, qdd;
  for (int j = 0; j < nd; ++j) {
    const Drive& d = m.drives[static_cast<std::size_t>(j)];
    if (d.offset != 0.0) offset.push_back(j);
    if (d.gear_ratio != 1.0) gear.push_back(j);
  }
  for (int j : coupled) {
    const Drive& d = m.drives[static_cast<std::size_t>(j)];
    if (d.rotor_inertia != 0.0 || d.viscous != 0.0 || d.coulomb != 0.0) coupled_terms.push_back(j);
  }
  for (int j = 0; j < m.dof(); ++j)
    if (finiteLimit(m.limits[static_cast<std::size_t>(j)].qdd_max)) qdd.push_back(j);
  if (!offset.empty())
    out->push_back("drive torque offsets OFF (coordinates " + joinNumbers(offset) + "): " + format +
                   " has no constant joint torque");
  if (!coupled_terms.empty())
    out->push_back("rotor inertia, viscous and Coulomb friction of the drives of coordinates " +
                   joinNumbers(coupled_terms) +
                   ", which move several joints through the transmission: " + format +
                   " puts drive terms on single joints");
  if (m.hasTransmission())
    out->push_back("the transmission (measured coordinates q = T qm + q0): " + format +
                   " has the joint coordinates only; drive terms of a coordinate that moves one "
                   "joint were reflected to that joint");
  if (!qdd.empty()) out->push_back("acceleration limits (joints " + joinNumbers(qdd) + ")");
  if (!gear.empty())
    out->push_back("gear ratios (coordinates " + joinNumbers(gear) +
                   "; informative in exid, the drive terms are already reflected)");
  if (!m.collision.empty())
    out->push_back(std::to_string(m.collision.size()) + " collision shape" +
                   (m.collision.size() == 1 ? "" : "s") + " (exid's collision geometry)");
}

void massCentreInertia(const Eigen::Matrix<double, 10, 1>& pi, double* mass, Eigen::Vector3d* c,
                       Eigen::Matrix3d* Ic) {
  *mass = pi(9);
  *c = Eigen::Vector3d::Zero();
  if (*mass > 0.0) {
    comFromInertial(pi, mass, c, Ic);
  } else {
    *mass = 0.0;
    *Ic << pi(0), pi(1), pi(2), pi(1), pi(3), pi(4), pi(2), pi(4), pi(5);
  }
  *Ic = 0.5 * (*Ic + Ic->transpose()).eval();
}

void requirePhysical(const RobotModel& m, const std::string& format) {
  for (int j = 0; j < m.dof(); ++j) {
    const Body& b = m.bodies[static_cast<std::size_t>(j)];
    const InertiaCheck c = checkPhysical(b.inertia);
    if (!c.ok)
      throw Error("body " + std::to_string(j + 1) + " ('" + b.name + "'): " + c.rule +
                  "; the parameters are not physically consistent and cannot be written as " +
                  format);
  }
  if (m.floating_base) {
    const InertiaCheck c = checkPhysical(m.base.inertia);
    if (!c.ok)
      throw Error("floating base link '" + m.base.link + "': " + c.rule +
                  "; the parameters are not physically consistent and cannot be written as " +
                  format);
  }
}

Pose bodyFrameAt(const Body& b, double q) {
  if (q == 0.0) return b.pre * b.post;
  Pose motion;
  if (b.type == JointType::Revolute)
    motion.R = Eigen::AngleAxisd(q, b.axis).toRotationMatrix();
  else
    motion.p = q * b.axis;
  return b.pre * motion * b.post;
}

RobotModel writtenTree(const RobotModel& m, Eigen::VectorXd* reference) {
  const int n = m.numJoints();
  *reference = Eigen::VectorXd::Zero(n);
  if (!m.hasLoops()) return m;
  RobotModel t = m;
  t.closed = ClosedChain{};
  // an exactly assembled configuration: the one the position solve reaches at the actuated
  // joints' reference values (a description's reference is a first guess, often rounded)
  Eigen::VectorXd qa(m.dof());
  for (int k = 0; k < m.dof(); ++k)
    qa(k) = m.closed.reference.size() == n ? m.closed.reference(m.actuatedJoint(k)) : 0.0;
  closedChainState(m, qa, nullptr, nullptr, reference, nullptr, nullptr, nullptr, nullptr);
  t.limits = m.closed.tree_limits.size() == static_cast<std::size_t>(n)
                 ? m.closed.tree_limits
                 : std::vector<JointLimits>(static_cast<std::size_t>(n));
  t.drives.assign(static_cast<std::size_t>(n), Drive{});
  for (int k = 0; k < m.dof(); ++k) {
    const auto a = static_cast<std::size_t>(m.actuatedJoint(k));
    t.limits[a] = m.limits[static_cast<std::size_t>(k)];
    if (static_cast<std::size_t>(k) < m.drives.size())
      t.drives[a] = m.drives[static_cast<std::size_t>(k)];
  }
  return t;
}

}  // namespace exid::detail
