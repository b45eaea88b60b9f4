// exid — RobotModel helpers: parameter names, validation, inertial conversions and checks.
#include "exid/robot_model.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "exid/closed_chain.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

Eigen::Matrix3d inertiaMatrix(const Eigen::Matrix<double, 10, 1>& pi) {
  Eigen::Matrix3d I;
  I << pi[0], pi[1], pi[2], pi[1], pi[3], pi[4], pi[2], pi[4], pi[5];
  return I;
}

std::string bodyLabel(const RobotModel& m, int i) {
  std::ostringstream os;
  const Body& b = m.bodies[static_cast<size_t>(i)];
  os << "body " << (i + 1);
  if (!b.name.empty()) os << " '" << b.name << "'";
  if (!b.joint_name.empty()) os << " (joint '" << b.joint_name << "')";
  return os.str();
}

std::string where(const RobotModel& m) {
  std::string s = "robot '" + m.name + "'";
  if (!m.source.empty()) s += " from " + m.source;
  return s;
}

bool finite(const Pose& P) { return P.R.allFinite() && P.p.allFinite(); }

void checkRotation(const RobotModel& m, int i, const Eigen::Matrix3d& R, const char* which) {
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(orth <= 1e-9) || !(R.determinant() > 0.0)) {
    std::ostringstream os;
    os << where(m) << ": " << bodyLabel(m, i) << ": " << which
       << " rotation is not a proper orthonormal matrix (max |R^T R - I| = " << orth
       << ", det = " << R.determinant() << "; expected <= 1e-9 and det = +1)";
    throw Error(os.str());
  }
}

}  // namespace

std::vector<std::string> RobotModel::inertialParameterNames() const {
  std::vector<std::string> names;
  names.reserve(static_cast<size_t>(numInertialParameters()));
  for (int j = 0; j < numJoints(); ++j)
    for (int k = 0; k < 10; ++k)
      names.push_back(std::string(kInertialNames[k]) + std::to_string(j + 1));
  return names;
}

Eigen::VectorXd RobotModel::inertialParameters() const {
  Eigen::VectorXd pi(numInertialParameters());
  for (int j = 0; j < numJoints(); ++j)
    pi.segment<10>(10 * j) = bodies[static_cast<size_t>(j)].inertia;
  return pi;
}

void RobotModel::validateStructure() const {
  const int n = numJoints();
  if (n == 0)
    throw Error(where(*this) + ": the model has no moving body (expected at least one joint)");
  std::set<std::string> body_names, joint_names;
  for (int i = 0; i < n; ++i) {
    const Body& b = bodies[static_cast<size_t>(i)];
    if (b.parent < -1 || b.parent >= i) {
      std::ostringstream os;
      os << where(*this) << ": " << bodyLabel(*this, i) << ": parent index " << b.parent
         << " violates the ordering rule (expected -1 for the base or 0 <= parent < " << i << ")";
      throw Error(os.str());
    }
    if (!b.name.empty() && !body_names.insert(b.name).second)
      throw Error(where(*this) + ": " + bodyLabel(*this, i) + ": duplicate body name '" + b.name +
                  "'");
    if (!b.joint_name.empty() && !joint_names.insert(b.joint_name).second)
      throw Error(where(*this) + ": " + bodyLabel(*this, i) + ": duplicate joint name '" +
                  b.joint_name + "'");
    if (!finite(b.pre) || !finite(b.post) || !b.axis.allFinite() || !b.inertia.allFinite())
      throw Error(where(*this) + ": " + bodyLabel(*this, i) +
                  ": non-finite number in pre/post pose, axis or inertial parameters");
    const double an = b.axis.norm();
    if (std::abs(an - 1.0) > 1e-9) {
      std::ostringstream os;
      os << where(*this) << ": " << bodyLabel(*this, i) << ": joint axis has norm " << an
         << " (expected a unit vector)";
      throw Error(os.str());
    }
    checkRotation(*this, i, b.pre.R, "pre");
    checkRotation(*this, i, b.post.R, "post");
  }
  {
    const int nm = dof();  // limits, drives, transmission: per measured coordinate
    if (static_cast<int>(limits.size()) != nm) {
      std::ostringstream os;
      os << where(*this) << ": " << limits.size()
         << " joint limit entries (expected one per joint, " << nm << ")";
      throw Error(os.str());
    }
    for (int i = 0; i < nm; ++i) {
      const JointLimits& L = limits[static_cast<size_t>(i)];
      if (std::isnan(L.q_min) || std::isnan(L.q_max) || std::isnan(L.qd_max) ||
          std::isnan(L.qdd_max) || std::isnan(L.tau_max) || L.q_min > L.q_max || L.qd_max < 0 ||
          L.qdd_max < 0 || L.tau_max < 0)
        throw Error(
            where(*this) + ": " +
            (hasLoops() ? "measured coordinate " + std::to_string(i + 1) : bodyLabel(*this, i)) +
            ": invalid limits (expected q_min <= q_max and non-negative qd/qdd/tau limits)");
    }
    if (static_cast<int>(drives.size()) != nm) {
      std::ostringstream os;
      os << where(*this) << ": " << drives.size()
         << " drive entries (expected one per measured coordinate, " << nm << ")";
      throw Error(os.str());
    }
    if (hasTransmission()) {
      if (transmission.rows() != nm || transmission.cols() != nm || !transmission.allFinite()) {
        std::ostringstream os;
        os << where(*this) << ": transmission is " << transmission.rows() << "x"
           << transmission.cols() << " (expected a finite " << nm << "x" << nm << " matrix)";
        throw Error(os.str());
      }
    }
    if (transmission_offset.size() != 0 && transmission_offset.size() != nm) {
      std::ostringstream os;
      os << where(*this) << ": transmission_offset has " << transmission_offset.size()
         << " entries (expected 0 or " << nm << ")";
      throw Error(os.str());
    }
    if (hasLoops() && (hasTransmission() || transmission_offset.size() != 0))
      throw Error(where(*this) +
                  ": a closed chain with a transmission is not supported (expected "
                  "no `transmission` on a robot with loop-closure joints)");
  }
  if (sensor_body < -1 || sensor_body >= n) {
    std::ostringstream os;
    os << where(*this) << ": sensor_body " << sensor_body << " out of range (expected -1 or 0.."
       << n - 1 << ")";
    throw Error(os.str());
  }
  if (!finite(sensor_pose)) throw Error(where(*this) + ": non-finite sensor_pose");
  checkRotation(*this, sensorBody(), sensor_pose.R, "sensor_pose");
  if (!gravity.allFinite()) throw Error(where(*this) + ": non-finite gravity");
  if (hasLoops() && floating_base)
    throw Error(where(*this) +
                ": a floating base with loop-closure joints is not supported "
                "(a closed chain is fixed to the world)");
  if (hasLoops()) validateClosedChain(*this);
  if (floating_base) {
    if (!base.inertia.allFinite())
      throw Error(where(*this) + ": floating base link '" + base.link +
                  "': non-finite inertial parameters");
    for (int i = 0; i < n; ++i)
      if (bodies[static_cast<size_t>(i)].name == base.link && !base.link.empty())
        throw Error(where(*this) + ": floating base link '" + base.link + "' is also " +
                    bodyLabel(*this, i) + " (the base link is not a body)");
  }
}

void RobotModel::requireFixedBase(const std::string& what) const {
  if (!floating_base) return;
  throw Error(where(*this) + " has a floating base (link '" + base.link + "'): " + what +
              " needs a robot fixed to the world; for a floating-base robot use the "
              "floating_base observation model (docs/models.md) or the floating-base dynamics "
              "(exid/floating_base.hpp)");
}

Eigen::Matrix<double, 10, 1> inertialFromCom(double mass, const Eigen::Vector3d& com,
                                             const Eigen::Matrix3d& I_com) {
  const Eigen::Matrix3d I =
      I_com + mass * (com.squaredNorm() * Eigen::Matrix3d::Identity() - com * com.transpose());
  Eigen::Matrix<double, 10, 1> pi;
  pi << I(0, 0), 0.5 * (I(0, 1) + I(1, 0)), 0.5 * (I(0, 2) + I(2, 0)), I(1, 1),
      0.5 * (I(1, 2) + I(2, 1)), I(2, 2), mass * com.x(), mass * com.y(), mass * com.z(), mass;
  return pi;
}

void comFromInertial(const Eigen::Matrix<double, 10, 1>& pi, double* mass, Eigen::Vector3d* com,
                     Eigen::Matrix3d* I_com) {
  const double m = pi[9];
  check(m > 0.0, "comFromInertial: mass must be positive to define a centre of mass (found " +
                     std::to_string(m) + ")");
  const Eigen::Vector3d c = pi.segment<3>(6) / m;
  if (mass) *mass = m;
  if (com) *com = c;
  if (I_com)
    *I_com =
        inertiaMatrix(pi) - m * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
}

Eigen::Matrix<double, 10, 1> transformInertial(const Eigen::Matrix<double, 10, 1>& pi_B,
                                               const Pose& X_AB) {
  // Linear in pi (valid for any parameters, including zero mass):
  // I_A = R I_B R^T - [Rh]x [p]x - [p]x [Rh]x - m [p]x [p]x,  h_A = R h_B + m p.
  const Eigen::Matrix3d& R = X_AB.R;
  const Eigen::Vector3d& p = X_AB.p;
  const double m = pi_B[9];
  const Eigen::Vector3d Rh = R * pi_B.segment<3>(6);
  const Eigen::Matrix3d P = skew(p), H = skew(Rh);
  const Eigen::Matrix3d I = R * inertiaMatrix(pi_B) * R.transpose() - H * P - P * H - m * P * P;
  const Eigen::Vector3d h = Rh + m * p;
  Eigen::Matrix<double, 10, 1> out;
  out << I(0, 0), 0.5 * (I(0, 1) + I(1, 0)), 0.5 * (I(0, 2) + I(2, 0)), I(1, 1),
      0.5 * (I(1, 2) + I(2, 1)), I(2, 2), h.x(), h.y(), h.z(), m;
  return out;
}

InertiaCheck checkPhysical(const Eigen::Matrix<double, 10, 1>& pi, double tol) {
  InertiaCheck r;
  const double m = pi[9];
  const Eigen::Matrix3d I = inertiaMatrix(pi);
  const double scale = std::max(1.0, I.cwiseAbs().maxCoeff());
  if (!pi.allFinite()) return {false, "non-finite parameter"};
  if (m < -tol) return {false, "negative mass"};
  Eigen::Matrix3d Ic;
  if (m <= tol) {
    if (pi.segment<3>(6).norm() > tol) return {false, "first moment without mass"};
    Ic = I;
  } else {
    const Eigen::Vector3d c = pi.segment<3>(6) / m;
    Ic = I - m * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(Ic, Eigen::EigenvaluesOnly);
  const Eigen::Vector3d l = es.eigenvalues();  // ascending
  if (l[0] < -tol * scale)
    return {false, "inertia about the centre of mass not positive semi-definite"};
  if (l[0] + l[1] < l[2] - tol * scale)
    return {false, "triangle inequality violated (principal moments: I1 + I2 >= I3)"};
  return r;
}

}  // namespace exid
