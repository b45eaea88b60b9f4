// exid — RobotModel -> MJCF text (see mjcf_writer.hpp).
#include "exid/mjcf_writer.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "model_text.hpp"

namespace exid {

namespace {

using detail::finiteLimit;
using detail::massCentreInertia;
using detail::num;
using detail::vec3;
using detail::xmlEscape;

/// MuJoCo's mjMINVAL: it refuses a moving body whose mass or a principal moment is below it.
constexpr double kMujocoMinValue = 1e-15;

std::string quat(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;
  return num(q.w()) + " " + num(q.x()) + " " + num(q.y()) + " " + num(q.z());
}

/// `<inertial>` of one body (its parameters about the body frame origin, in body axes).
std::string inertial(const Body& b, std::vector<std::string>* raised) {
  double mass = 0.0;
  Eigen::Vector3d c;
  Eigen::Matrix3d Ic;
  massCentreInertia(b.inertia, &mass, &c, &Ic);
  Eigen::Vector3d l(Ic(0, 0), Ic(1, 1), Ic(2, 2));
  Eigen::Matrix3d V = Eigen::Matrix3d::Identity();
  const bool diagonal = Ic(0, 1) == 0.0 && Ic(0, 2) == 0.0 && Ic(1, 2) == 0.0;
  if (!diagonal) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(Ic);
    l = es.eigenvalues();
    V = es.eigenvectors();
    if (V.determinant() < 0) V.col(2) *= -1.0;
  }
  // MuJoCo checks A + B >= C exactly; exid's check allows rounding (1e-12 of the largest).
  bool adjusted = false;
  for (int k = 0; k < 3; ++k) {
    const double others = l((k + 1) % 3) + l((k + 2) % 3);
    if (l(k) > others) {
      l(k) = others;
      adjusted = true;
    }
  }
  bool minimum = mass < kMujocoMinValue;
  mass = std::max(mass, kMujocoMinValue);
  for (int k = 0; k < 3; ++k)
    if (l(k) < kMujocoMinValue) {
      l(k) = kMujocoMinValue;
      minimum = true;
    }
  if (minimum)
    raised->push_back("body '" + b.name +
                      "': a mass or principal moment of inertia below MuJoCo's minimum 1e-15 "
                      "(it refuses massless moving bodies) was written as 1e-15");
  if (adjusted)
    raised->push_back("body '" + b.name +
                      "': principal moments moved by rounding to satisfy MuJoCo's exact "
                      "A + B >= C");
  std::string s = "<inertial pos=\"" + vec3(c) + "\" mass=\"" + num(mass) + "\" diaginertia=\"" +
                  vec3(l) + "\"";
  if (!diagonal) s += " quat=\"" + quat(V) + "\"";
  return s + "/>";
}

}  // namespace

std::string writeMjcf(const RobotModel& model, const MjcfWriteOptions& opt,
                      std::vector<std::string>* left_out) {
  model.validateStructure();
  detail::requirePhysical(model, "MJCF");
  // (a closed chain: its spanning tree at the loops' reference configuration, see below)
  Eigen::VectorXd ref;
  const RobotModel m = detail::writtenTree(model, &ref);
  check(std::isfinite(opt.timestep_s) && opt.timestep_s > 0.0,
        "writeMjcf: timestep_s must be a positive number of seconds");
  const int n = m.numJoints();
  std::vector<int> coupled;
  const std::vector<detail::JointDriveTerms> drive = detail::jointDriveTerms(m, &coupled);
  std::vector<std::string> notes;
  detail::leftOutOfEveryFormat(m, coupled, "MJCF", &notes);
  std::vector<int> negative_coulomb, velocity;
  for (int j = 0; j < n; ++j) {
    if (drive[static_cast<std::size_t>(j)].coulomb < 0.0) negative_coulomb.push_back(j);
    if (finiteLimit(m.limits[static_cast<std::size_t>(j)].qd_max)) velocity.push_back(j);
  }
  if (!negative_coulomb.empty())
    notes.push_back("negative Coulomb friction (joints " + detail::joinNumbers(negative_coulomb) +
                    "): MJCF's frictionloss is a magnitude");
  if (!velocity.empty())
    notes.push_back("velocity limits (joints " + detail::joinNumbers(velocity) + ")");

  std::vector<std::vector<int>> children(static_cast<std::size_t>(n));
  std::vector<int> roots;
  for (int j = 0; j < n; ++j) {
    const int p = m.bodies[static_cast<std::size_t>(j)].parent;
    (p < 0 ? roots : children[static_cast<std::size_t>(p)]).push_back(j);
  }
  std::vector<std::string> raised;
  std::ostringstream w;
  const int sb = m.sensorBody();
  // depth-first, children nested in their parent
  auto body = [&](auto&& self, int j, int depth) -> void {
    const Body& b = m.bodies[static_cast<std::size_t>(j)];
    const std::string in(static_cast<std::size_t>(2 * depth), ' ');
    // body frame in the parent body frame at q = ref (a tree: 0); MuJoCo's joint `ref` says so
    const Pose X = detail::bodyFrameAt(b, ref(j));
    w << in << "<body name=\"" << xmlEscape(b.name) << "\" pos=\"" << vec3(X.p) << "\" quat=\""
      << quat(X.R) << "\">\n";
    w << in << "  " << inertial(b, &raised) << "\n";
    const Pose J = b.post.inverse();  // moved joint frame in the body frame
    const JointLimits& L = m.limits[static_cast<std::size_t>(j)];
    const bool bounded = finiteLimit(L.q_min) && finiteLimit(L.q_max);
    const detail::JointDriveTerms& d = drive[static_cast<std::size_t>(j)];
    w << in << "  <joint name=\"" << xmlEscape(b.joint_name) << "\" type=\""
      << (b.type == JointType::Prismatic ? "slide" : "hinge") << "\" pos=\"" << vec3(J.p)
      << "\" axis=\"" << vec3(J.R * b.axis) << "\" limited=\"" << (bounded ? "true" : "false")
      << "\"";
    if (bounded) w << " range=\"" << num(L.q_min) << " " << num(L.q_max) << "\"";
    if (ref(j) != 0.0) w << " ref=\"" << num(ref(j)) << "\"";
    w << " armature=\"" << num(d.rotor_inertia) << "\" damping=\"" << num(d.viscous)
      << "\" frictionloss=\"" << num(std::max(d.coulomb, 0.0)) << "\"/>\n";
    if (j == sb)
      w << in << "  <site name=\"exid_sensor\" pos=\"" << vec3(m.sensor_pose.p) << "\" quat=\""
        << quat(m.sensor_pose.R) << "\"/>\n";
    for (int c : children[static_cast<std::size_t>(j)]) self(self, c, depth + 1);
    w << in << "</body>\n";
  };
  if (m.floating_base) {
    // The base link: the root body, with a free joint (MuJoCo's qpos: the base frame's position
    // and orientation in the world), at the base's reference pose (the identity: the world
    // frame); the bodies attached to the base are its children. No motor on the free joint.
    std::set<std::string> body_names, joint_names;
    for (const Body& b : m.bodies) {
      body_names.insert(b.name);
      joint_names.insert(b.joint_name);
    }
    Body base;
    base.name = m.base.link.empty() ? detail::freeName("base", body_names) : m.base.link;
    base.inertia = m.base.inertia;
    const std::string joint = m.base.joint_name.empty()
                                  ? detail::freeName("floating_base", joint_names)
                                  : m.base.joint_name;
    check(!joint_names.count(joint),
          "writeMjcf: the free joint '" + joint + "' has the name of a body's joint (rename one)");
    w << "    <body name=\"" << xmlEscape(base.name) << "\" pos=\"0 0 0\" quat=\"1 0 0 0\">\n"
      << "      " << inertial(base, &raised) << "\n"
      << "      <freejoint name=\"" << xmlEscape(joint) << "\"/>\n";
    for (int r : roots) body(body, r, 3);
    w << "    </body>\n";
  } else {
    for (int r : roots) body(body, r, 2);
  }
  notes.insert(notes.end(), raised.begin(), raised.end());

  std::ostringstream x;
  x << "<?xml version=\"1.0\"?>\n" << detail::xmlComment(opt.comment);
  if (!notes.empty()) {
    std::string c = "  Not carried by MJCF (exid's own description has them):";
    for (const auto& s : notes) c += "\n  - " + s;
    x << detail::xmlComment(c);
  }
  x << "<mujoco model=\"" << xmlEscape(m.name) << "\">\n"
    << "  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n"
    << "  <option timestep=\"" << num(opt.timestep_s) << "\" gravity=\"" << vec3(m.gravity)
    << "\" integrator=\"Euler\"/>\n"
    << "  <worldbody>\n"
    << w.str() << "  </worldbody>\n";
  // Loop-closure joints: MuJoCo's `connect` (a ball joint between two bodies: the anchor in
  // body1's frame, body2's point where it is in the written configuration, an assembled one);
  // a revolute cut joint is two of them, the second one metre along its axis. The actuated
  // joints are the ones with a motor, in the order of the measured coordinates.
  if (model.hasLoops()) {
    x << "  <equality>\n";
    auto bodyName = [&](int b) {
      return b < 0 ? std::string("world") : xmlEscape(m.bodies[static_cast<std::size_t>(b)].name);
    };
    for (const LoopJoint& l : model.closed.loops) {
      std::vector<Eigen::Vector3d> anchors{l.pose_a.p};
      if (l.kind == LoopJoint::Kind::Revolute) anchors.push_back(l.pose_a.p + l.pose_a.R * l.axis);
      for (std::size_t k = 0; k < anchors.size(); ++k)
        x << "    <connect name=\"" << xmlEscape(l.name) << (k ? "_axis" : "") << "\" body1=\""
          << bodyName(l.body_a) << "\" body2=\"" << bodyName(l.body_b) << "\" anchor=\""
          << vec3(anchors[k]) << "\"/>\n";
    }
    x << "  </equality>\n";
  }
  x << "  <actuator>\n";
  for (int k = 0; k < model.dof(); ++k) {
    const int j = model.actuatedJoint(k);
    const Body& b = m.bodies[static_cast<std::size_t>(j)];
    const double t = m.limits[static_cast<std::size_t>(j)].tau_max;
    x << "    <motor name=\"" << xmlEscape(b.joint_name) << "\" joint=\"" << xmlEscape(b.joint_name)
      << "\" gear=\"1\" ctrllimited=\"" << (finiteLimit(t) ? "true" : "false") << "\"";
    if (finiteLimit(t)) x << " ctrlrange=\"" << num(-t) << " " << num(t) << "\"";
    x << "/>\n";
  }
  x << "  </actuator>\n</mujoco>\n";
  if (left_out) left_out->insert(left_out->end(), notes.begin(), notes.end());
  return x.str();
}

}  // namespace exid
