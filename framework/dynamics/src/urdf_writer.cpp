// exid — RobotModel -> URDF text (see urdf_writer.hpp).
#include "exid/urdf_writer.hpp"

#include <cmath>
#include <set>
#include <sstream>

#include "exid/error.hpp"
#include "model_text.hpp"

namespace exid {

namespace {

using detail::finiteLimit;
using detail::num;
using detail::rpy;
using detail::vec3;
using detail::xmlEscape;

std::string origin(const Pose& X) {
  return "<origin xyz=\"" + vec3(X.p) + "\" rpy=\"" + vec3(rpy(X.R)) + "\"/>";
}

}  // namespace

std::string writeUrdf(const RobotModel& model, const UrdfWriteOptions& opt) {
  model.validateStructure();
  // (a closed chain: its spanning tree, limits per tree joint, drives on the actuated joints;
  // the loops in <exid> below)
  Eigen::VectorXd ref;
  const RobotModel m = detail::writtenTree(model, &ref);
  std::set<std::string> names, joint_names;
  for (const auto& b : m.bodies) {
    names.insert(b.name);
    joint_names.insert(b.joint_name);
  }
  // <inertial> of a link from its parameters about the link frame origin (link axes)
  std::ostringstream x;
  auto linkElement = [&](const std::string& name, const Eigen::Matrix<double, 10, 1>& pi) {
    check(pi.allFinite(), "writeUrdf: body '" + name + "': non-finite inertial parameters");
    x << "  <link name=\"" << xmlEscape(name) << "\">\n";
    if (pi(9) > 0.0) {
      double mass = 0;
      Eigen::Vector3d c;
      Eigen::Matrix3d Ic;
      comFromInertial(pi, &mass, &c, &Ic);
      x << "    <inertial>\n      " << origin(Pose{Eigen::Matrix3d::Identity(), c}) << "\n"
        << "      <mass value=\"" << num(mass) << "\"/>\n"
        << "      <inertia ixx=\"" << num(Ic(0, 0)) << "\" ixy=\""
        << num(0.5 * (Ic(0, 1) + Ic(1, 0))) << "\" ixz=\"" << num(0.5 * (Ic(0, 2) + Ic(2, 0)))
        << "\" iyy=\"" << num(Ic(1, 1)) << "\" iyz=\"" << num(0.5 * (Ic(1, 2) + Ic(2, 1)))
        << "\" izz=\"" << num(Ic(2, 2)) << "\"/>\n    </inertial>\n";
    } else {
      check(pi.cwiseAbs().maxCoeff() == 0.0, "writeUrdf: body '" + name + "' has mass " +
                                                 num(pi(9)) +
                                                 " and non-zero inertial parameters: URDF cannot "
                                                 "describe it (identify with consistent_ls)");
    }
    x << "  </link>\n";
  };
  x << "<?xml version=\"1.0\"?>\n" << detail::xmlComment(opt.comment);
  x << "<robot name=\"" << xmlEscape(m.name) << "\">\n";
  std::string root;  // the link the bodies with parent -1 hang from
  if (m.floating_base) {
    // A floating base: a massless world link, a `floating` joint from it to the base link
    // (exid's URDF loader reads the base frame as the base link's frame; the joint's origin is
    // the base's reference pose, here the identity).
    root = m.base.link.empty() ? detail::freeName("base", names) : m.base.link;
    check(!names.count(root), "writeUrdf: the base link '" + root +
                                  "' has the name of a body (URDF links share one namespace)");
    names.insert(root);
    const std::string world =
        detail::freeName(opt.root_link.empty() ? "world" : opt.root_link, names);
    const std::string joint = m.base.joint_name.empty()
                                  ? detail::freeName("floating_base", joint_names)
                                  : m.base.joint_name;
    check(!joint_names.count(joint), "writeUrdf: the floating joint '" + joint +
                                         "' has the name of a body's joint (rename one)");
    x << "  <link name=\"" << xmlEscape(world) << "\"/>\n";
    linkElement(root, m.base.inertia);
    x << "  <joint name=\"" << xmlEscape(joint) << "\" type=\"floating\">\n"
      << "    <parent link=\"" << xmlEscape(world) << "\"/>\n    <child link=\"" << xmlEscape(root)
      << "\"/>\n  </joint>\n";
  } else {
    root = detail::freeName(opt.root_link.empty() ? "base_link" : opt.root_link, names);
    x << "  <link name=\"" << xmlEscape(root) << "\"/>\n";
  }
  for (int j = 0; j < m.numJoints(); ++j) {
    const Body& b = m.bodies[static_cast<std::size_t>(j)];
    // Link frame = moved joint frame: parameters moved from the body frame by `post`.
    linkElement(b.name, transformInertial(b.inertia, b.post));
    const JointLimits& L = m.limits[static_cast<std::size_t>(j)];
    const bool bounded = finiteLimit(L.q_min) && finiteLimit(L.q_max);
    std::string type =
        b.type == JointType::Prismatic ? "prismatic" : (bounded ? "revolute" : "continuous");
    const Pose X = b.parent < 0 ? b.pre : m.bodies[static_cast<std::size_t>(b.parent)].post * b.pre;
    x << "  <joint name=\"" << xmlEscape(b.joint_name) << "\" type=\"" << type << "\">\n"
      << "    <parent link=\""
      << xmlEscape(b.parent < 0 ? root : m.bodies[static_cast<std::size_t>(b.parent)].name)
      << "\"/>\n    <child link=\"" << xmlEscape(b.name) << "\"/>\n    " << origin(X) << "\n"
      << "    <axis xyz=\"" << vec3(b.axis) << "\"/>\n";
    const double eff = finiteLimit(L.tau_max) ? L.tau_max : 0.0;
    const double vel = finiteLimit(L.qd_max) ? L.qd_max : 0.0;
    if (type == "continuous") {
      x << "    <limit effort=\"" << num(eff) << "\" velocity=\"" << num(vel) << "\"/>\n";
    } else {
      x << "    <limit lower=\"" << num(bounded ? L.q_min : -1e300) << "\" upper=\""
        << num(bounded ? L.q_max : 1e300) << "\" effort=\"" << num(eff) << "\" velocity=\""
        << num(vel) << "\"/>\n";
    }
    x << "  </joint>\n";
  }
  x << "  <exid>\n    <gravity xyz=\"" << vec3(m.gravity) << "\"/>\n";
  std::vector<bool> actuated(static_cast<std::size_t>(m.numJoints()), !model.hasLoops());
  for (int k = 0; k < model.dof() && model.hasLoops(); ++k)
    actuated[static_cast<std::size_t>(model.actuatedJoint(k))] = true;
  for (int j = 0; j < m.numJoints(); ++j) {
    const Body& b = m.bodies[static_cast<std::size_t>(j)];
    if (j < static_cast<int>(m.drives.size()) && actuated[static_cast<std::size_t>(j)]) {
      const Drive& d = m.drives[static_cast<std::size_t>(j)];
      x << "    <drive joint=\"" << xmlEscape(b.joint_name) << "\" gear_ratio=\""
        << num(d.gear_ratio) << "\" rotor_inertia=\"" << num(d.rotor_inertia) << "\" coulomb=\""
        << num(d.coulomb) << "\" viscous=\"" << num(d.viscous) << "\" offset=\"" << num(d.offset)
        << "\"/>\n";
    }
    const JointLimits& L = m.limits[static_cast<std::size_t>(j)];
    if (finiteLimit(L.qdd_max))
      x << "    <limit joint=\"" << xmlEscape(b.joint_name) << "\" qdd_max=\"" << num(L.qdd_max)
        << "\"/>\n";
  }
  if (m.hasTransmission()) {
    x << "    <transmission matrix=\"";
    for (Eigen::Index r = 0; r < m.transmission.rows(); ++r)
      for (Eigen::Index c = 0; c < m.transmission.cols(); ++c)
        x << (r || c ? " " : "") << num(m.transmission(r, c));
    x << "\"";
    if (m.transmission_offset.size() > 0) {
      x << " offset=\"";
      for (Eigen::Index r = 0; r < m.transmission_offset.size(); ++r)
        x << (r ? " " : "") << num(m.transmission_offset(r));
      x << "\"";
    }
    x << "/>\n";
  }
  if (model.hasLoops()) {
    // the cut frames in the URDF link frames (a link frame is its body's moved joint frame:
    // the body frame is at `post` in it)
    auto link = [&](int b, const Pose& X, const char* side) {
      const Pose L = b < 0 ? X : m.bodies[static_cast<std::size_t>(b)].post * X;
      return std::string(" link_") + side + "=\"" +
             xmlEscape(b < 0 ? root : m.bodies[static_cast<std::size_t>(b)].name) + "\" xyz_" +
             side + "=\"" + vec3(L.p) + "\" rpy_" + side + "=\"" + vec3(rpy(L.R)) + "\"";
    };
    for (const LoopJoint& l : model.closed.loops)
      x << "    <loop name=\"" << xmlEscape(l.name) << "\" type=\""
        << (l.kind == LoopJoint::Kind::Revolute ? "revolute" : "spherical") << "\""
        << link(l.body_a, l.pose_a, "a") << link(l.body_b, l.pose_b, "b") << " axis=\""
        << vec3(l.axis) << "\"/>\n";
    x << "    <actuated joints=\"";
    for (int k = 0; k < model.dof(); ++k)
      x << (k ? " " : "")
        << xmlEscape(m.bodies[static_cast<std::size_t>(model.actuatedJoint(k))].joint_name);
    x << "\"/>\n";
    for (int j = 0; j < m.numJoints(); ++j)
      if (ref(j) != 0.0)
        x << "    <reference joint=\""
          << xmlEscape(m.bodies[static_cast<std::size_t>(j)].joint_name) << "\" value=\""
          << num(ref(j)) << "\"/>\n";
  }
  const int sb = m.sensorBody();
  const Pose S = m.bodies[static_cast<std::size_t>(sb)].post * m.sensor_pose;
  x << "    <sensor link=\"" << xmlEscape(m.bodies[static_cast<std::size_t>(sb)].name)
    << "\" xyz=\"" << vec3(S.p) << "\" rpy=\"" << vec3(rpy(S.R)) << "\"/>\n";
  x << "  </exid>\n</robot>\n";
  return x.str();
}

}  // namespace exid
