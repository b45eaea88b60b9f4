// exid — RobotModel -> SDFormat 1.9 text (see sdf_writer.hpp).
#include "exid/sdf_writer.hpp"

#include <cmath>
#include <set>
#include <sstream>

#include "exid/error.hpp"
#include "model_text.hpp"

namespace exid {

namespace {

using detail::finiteLimit;
using detail::massCentreInertia;
using detail::num;
using detail::rpy;
using detail::vec3;
using detail::xmlEscape;

std::string pose(const Pose& X, const std::string& relative_to = "") {
  return "<pose" + (relative_to.empty() ? "" : " relative_to=\"" + xmlEscape(relative_to) + "\"") +
         ">" + vec3(X.p) + " " + vec3(rpy(X.R)) + "</pose>";
}

std::string element(const char* name, double v) {
  return std::string("<") + name + ">" + num(v) + "</" + name + ">";
}

/// `<inertial>` of a link from its parameters about the link frame origin (link axes).
std::string inertialOf(const Eigen::Matrix<double, 10, 1>& pi) {
  double mass = 0.0;
  Eigen::Vector3d c;
  Eigen::Matrix3d Ic;
  massCentreInertia(pi, &mass, &c, &Ic);
  std::ostringstream x;
  x << "      <inertial>\n        " << pose(Pose{Eigen::Matrix3d::Identity(), c}) << "\n"
    << "        " << element("mass", mass) << "\n        <inertia>" << element("ixx", Ic(0, 0))
    << element("ixy", 0.5 * (Ic(0, 1) + Ic(1, 0))) << element("ixz", 0.5 * (Ic(0, 2) + Ic(2, 0)))
    << element("iyy", Ic(1, 1)) << element("iyz", 0.5 * (Ic(1, 2) + Ic(2, 1)))
    << element("izz", Ic(2, 2)) << "</inertia>\n      </inertial>\n";
  return x.str();
}

}  // namespace

std::string writeSdf(const RobotModel& model, const SdfWriteOptions& opt,
                     std::vector<std::string>* left_out) {
  model.validateStructure();
  detail::requirePhysical(model, "SDF");
  // (a closed chain: its spanning tree at the loops' reference configuration)
  Eigen::VectorXd ref;
  const RobotModel m = detail::writtenTree(model, &ref);
  const int n = m.numJoints();
  std::set<std::string> names;
  for (const auto& b : m.bodies) names.insert(b.name);
  for (const auto& b : m.bodies)
    check(!names.count(b.joint_name),
          "writeSdf: '" + b.joint_name +
              "' names both a link and a joint; SDFormat frames share one namespace (rename one)");
  for (const auto& b : m.bodies) names.insert(b.joint_name);
  for (const LoopJoint& l : model.closed.loops) {
    check(!names.count(l.name), "writeSdf: loop-closure joint '" + l.name +
                                    "' has the name of a link or joint (SDFormat frames share one "
                                    "namespace; rename one)");
    names.insert(l.name);
  }
  // A floating base: the base link is the root link, with its inertial and no joint to the
  // world (SDFormat: a model without one is free). Fixed: a massless root link welded to it.
  const bool floating = m.floating_base;
  const std::string root =
      floating ? (m.base.link.empty() ? detail::freeName("base", names) : m.base.link)
               : detail::freeName(opt.root_link.empty() ? "base_link" : opt.root_link, names);
  check(!floating || !names.count(root),
        "writeSdf: the base link '" + root +
            "' has the name of a link or joint (SDFormat frames share one namespace; rename one)");
  names.insert(root);
  const std::string weld = detail::freeName(root + "_to_world", names);
  names.insert(weld);
  const std::string sensor = detail::freeName("exid_sensor", names);

  std::vector<int> coupled;
  const std::vector<detail::JointDriveTerms> drive = detail::jointDriveTerms(m, &coupled);
  std::vector<std::string> notes;
  std::vector<int> rotor;
  for (int j = 0; j < n; ++j)
    if (drive[static_cast<std::size_t>(j)].rotor_inertia != 0.0) rotor.push_back(j);
  if (!rotor.empty())
    notes.push_back("rotor inertias (joints " + detail::joinNumbers(rotor) +
                    "): SDF has no joint armature");
  detail::leftOutOfEveryFormat(m, coupled, "SDF", &notes);
  if (ref.cwiseAbs().maxCoeff() > 0.0)
    notes.push_back(
        "the joint positions' zero: the file is written at the loops' reference "
        "configuration (<exid:closed_chain reference>, joint=value), which SDF takes as "
        "every joint's zero; exid's q is the SDF joint position plus the reference");
  notes.push_back("gravity (" + vec3(m.gravity) +
                  " m/s^2 in the base frame): an SDF model carries none, its world's <gravity> "
                  "does");

  std::ostringstream x;
  x << "<?xml version=\"1.0\"?>\n" << detail::xmlComment(opt.comment);
  if (!notes.empty()) {
    std::string c = "  Not carried by SDF (exid's own description has them):";
    for (const auto& s : notes) c += "\n  - " + s;
    x << detail::xmlComment(c);
  }
  x << "<sdf version=\"1.9\"" << (model.hasLoops() ? " xmlns:exid=\"urn:exid\"" : "")
    << ">\n  <model name=\"" << xmlEscape(m.name) << "\">\n"
    << "    <link name=\"" << xmlEscape(root) << "\">\n";
  if (floating) {
    x << inertialOf(m.base.inertia);
  } else {
    x << "      <inertial><mass>0</mass><inertia><ixx>0</ixx><ixy>0</ixy><ixz>0</ixz><iyy>0</iyy>"
         "<iyz>0</iyz><izz>0</izz></inertia></inertial>\n";
  }
  x << "    </link>\n";
  if (!floating)
    x << "    <joint name=\"" << xmlEscape(weld) << "\" type=\"fixed\">\n"
      << "      <parent>world</parent>\n      <child>" << xmlEscape(root) << "</child>\n"
      << "    </joint>\n";
  for (int j = 0; j < n; ++j) {
    const Body& b = m.bodies[static_cast<std::size_t>(j)];
    const std::string parent =
        b.parent < 0 ? root : m.bodies[static_cast<std::size_t>(b.parent)].name;
    x << "    <link name=\"" << xmlEscape(b.name) << "\">\n"
      << "      " << pose(detail::bodyFrameAt(b, ref(j)), parent) << "\n"
      << inertialOf(b.inertia);
    x << "    </link>\n";
    const JointLimits& L = m.limits[static_cast<std::size_t>(j)];
    const bool bounded = finiteLimit(L.q_min) && finiteLimit(L.q_max);
    const char* type =
        b.type == JointType::Prismatic ? "prismatic" : (bounded ? "revolute" : "continuous");
    const detail::JointDriveTerms& d = drive[static_cast<std::size_t>(j)];
    x << "    <joint name=\"" << xmlEscape(b.joint_name) << "\" type=\"" << type << "\">\n"
      << "      <parent>" << xmlEscape(parent) << "</parent>\n      <child>" << xmlEscape(b.name)
      << "</child>\n      " << pose(b.post.inverse()) << "\n"
      << "      <axis>\n        <xyz>" << vec3(b.axis) << "</xyz>\n        <limit>";
    if (bounded) x << element("lower", L.q_min) << element("upper", L.q_max);
    if (finiteLimit(L.tau_max)) x << element("effort", L.tau_max);
    if (finiteLimit(L.qd_max)) x << element("velocity", L.qd_max);
    x << "</limit>\n        <dynamics>" << element("damping", d.viscous)
      << element("friction", d.coulomb) << "</dynamics>\n      </axis>\n    </joint>\n";
  }
  // Loop-closure joints: SDF joints whose child already has its tree joint (the file is written
  // at an assembled configuration, where the cut joint's frame is the same in both links); which
  // joints are cut and which are actuated is exid's own element, <exid:closed_chain>.
  if (model.hasLoops()) {
    std::string cut, actuated, reference;
    for (const LoopJoint& l : model.closed.loops) {
      const std::string pa =
          l.body_a < 0 ? root : m.bodies[static_cast<std::size_t>(l.body_a)].name;
      const std::string cb =
          l.body_b < 0 ? root : m.bodies[static_cast<std::size_t>(l.body_b)].name;
      const bool revolute = l.kind == LoopJoint::Kind::Revolute;
      x << "    <joint name=\"" << xmlEscape(l.name) << "\" type=\""
        << (revolute ? "revolute" : "ball") << "\">\n      <parent>" << xmlEscape(pa)
        << "</parent>\n      <child>" << xmlEscape(cb) << "</child>\n      " << pose(l.pose_b)
        << "\n";
      if (revolute) x << "      <axis><xyz>" << vec3(l.axis) << "</xyz></axis>\n";
      x << "    </joint>\n";
      cut += (cut.empty() ? "" : " ") + xmlEscape(l.name);
    }
    for (int k = 0; k < model.dof(); ++k)
      actuated += (k ? " " : "") +
                  xmlEscape(m.bodies[static_cast<std::size_t>(model.actuatedJoint(k))].joint_name);
    for (int j = 0; j < n; ++j)
      if (ref(j) != 0.0)
        reference += (reference.empty() ? "" : " ") +
                     xmlEscape(m.bodies[static_cast<std::size_t>(j)].joint_name) + "=" +
                     num(ref(j));
    x << "    <exid:closed_chain cut=\"" << cut << "\" actuated=\"" << actuated << "\" reference=\""
      << reference << "\"/>\n";
  }
  const Body& sb = m.bodies[static_cast<std::size_t>(m.sensorBody())];
  x << "    <frame name=\"" << xmlEscape(sensor) << "\" attached_to=\"" << xmlEscape(sb.name)
    << "\">\n      " << pose(m.sensor_pose, sb.name) << "\n    </frame>\n";
  x << "  </model>\n</sdf>\n";
  if (left_out) left_out->insert(left_out->end(), notes.begin(), notes.end());
  return x.str();
}

}  // namespace exid
