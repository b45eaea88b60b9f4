// exid — SDFormat (1.5 to 1.9) robot descriptions, read with TinyXML: one <model> of links and
// revolute, continuous, prismatic and fixed joints, fixed to the world, with poses resolved
// through the frame graph (relative_to, <frame>), inertials, limits and joint dynamics. Format and
// what is refused: docs/robots.md, "MJCF and SDF".
#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "read_text.hpp"
#include "xml_text.hpp"

namespace exid {
namespace {

using detail::xmlAt;
using detail::xmlAttr;

constexpr double kPi = 3.14159265358979323846;

struct SFrame {
  const TiXmlElement* e = nullptr;
  std::string relative_to;  // "" = the model frame
  Pose X;                   // in the frame `relative_to`
};

struct SJoint {
  const TiXmlElement* e = nullptr;
  std::string name, type, parent, child;
};

struct Reader {
  std::string src;
  LoadOptions options;
  RobotModel m;
  std::map<std::string, SFrame> frames;  // links, joints and <frame>s: the frame graph
  std::map<std::string, const TiXmlElement*> links;
  std::vector<std::string> link_order;
  std::vector<SJoint> joints;
  std::map<std::string, Pose> resolved;
  std::vector<std::string> ignored_dynamics, defaulted_inertials;
  const TiXmlElement* closed = nullptr;     // <exid:closed_chain>
  std::set<std::string> cut;                // its loop-closure joints
  std::vector<double> refs;                 // each tree joint's position in the written pose
  std::map<std::string, double> reference;  // <exid:closed_chain reference>
  std::map<std::string, std::pair<int, Pose>> link_place;  // link -> exid body, frame in it

  [[noreturn]] void fail(const TiXmlElement* e, const std::string& rule) const {
    std::string owner = "<" + std::string(e->Value()) + ">";
    if (const char* n = e->Attribute("name")) owner += std::string(" '") + n + "'";
    throw Error(xmlAt(src, e) + ": " + owner + ": " + rule);
  }

  /// <pose> child of e (identity when absent) and its relative_to (`fallback` when not given).
  SFrame poseOf(const TiXmlElement* e, const std::string& fallback) const {
    SFrame f;
    f.e = e;
    f.relative_to = fallback;
    const TiXmlElement* p = e->FirstChildElement("pose");
    if (!p) return f;
    if (p->NextSiblingElement("pose")) fail(p, "a second <pose>");
    if (p->Attribute("relative_to")) f.relative_to = xmlAttr(p, "relative_to");
    if (p->Attribute("frame") && !xmlAttr(p, "frame").empty())
      fail(p, "the frame attribute (SDFormat 1.5) is not supported; use relative_to");
    const std::string format =
        p->Attribute("rotation_format") ? xmlAttr(p, "rotation_format") : "euler_rpy";
    const bool degrees = xmlAttr(p, "degrees") == "true";
    if (format == "euler_rpy") {
      const auto v = detail::xmlTextNumbers(p, src, 6);
      const double s = degrees ? kPi / 180.0 : 1.0;
      f.X.p = Eigen::Vector3d(v[0], v[1], v[2]);
      f.X.R = (Eigen::AngleAxisd(v[5] * s, Eigen::Vector3d::UnitZ()) *
               Eigen::AngleAxisd(v[4] * s, Eigen::Vector3d::UnitY()) *
               Eigen::AngleAxisd(v[3] * s, Eigen::Vector3d::UnitX()))
                  .toRotationMatrix();
    } else if (format == "quat_xyzw") {
      const auto v = detail::xmlTextNumbers(p, src, 7);
      const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
      if (q.norm() < 1e-12) fail(p, "a zero quaternion");
      f.X.p = Eigen::Vector3d(v[0], v[1], v[2]);
      f.X.R = q.normalized().toRotationMatrix();
    } else {
      fail(p, "rotation_format: expected euler_rpy or quat_xyzw, found '" + format + "'");
    }
    return f;
  }

  /// Pose of frame `name` in the model frame, through the frame graph.
  Pose inModel(const std::string& name, std::vector<std::string>* path) {
    if (name.empty() || name == "__model__") return Pose{};
    if (auto it = resolved.find(name); it != resolved.end()) return it->second;
    auto f = frames.find(name);
    if (f == frames.end())
      throw Error(src + ": relative_to / attached_to '" + name +
                  "': no link, joint or frame of "
                  "that name in the model");
    for (const auto& s : *path)
      if (s == name) {
        std::string chain;
        for (const auto& t : *path) chain += t + " -> ";
        fail(f->second.e, "the poses form a cycle (" + chain + name + ")");
      }
    path->push_back(name);
    const Pose X = inModel(f->second.relative_to, path) * f->second.X;
    path->pop_back();
    resolved[name] = X;
    return X;
  }
  Pose inModel(const std::string& name) {
    std::vector<std::string> path;
    return inModel(name, &path);
  }

  void addFrame(const std::string& name, const SFrame& f) {
    if (name.empty()) fail(f.e, "a name is required");
    if (name == "world" || name == "__model__") fail(f.e, "the name '" + name + "' is reserved");
    if (frames.count(name))
      fail(f.e, "the name '" + name +
                    "' is given twice (links, joints and frames share one "
                    "namespace)");
    frames[name] = f;
  }

  Eigen::Matrix<double, 10, 1> inertial(const TiXmlElement* link) {
    const std::string name = xmlAttr(link, "name");
    const TiXmlElement* in = link->FirstChildElement("inertial");
    // SDFormat's defaults: a mass of 1 kg and a unit inertia at the link origin
    double mass = 1.0;
    Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
    Pose X;
    bool defaulted = !in;
    if (in) {
      const SFrame f = poseOf(in, "");
      if (!f.relative_to.empty())
        fail(in->FirstChildElement("pose"), "an inertial pose is relative to its link only");
      X = f.X;
      defaulted = !in->FirstChildElement("mass");
      mass = detail::xmlChildNumber(in, "mass", src, 1.0);
      if (mass < 0.0) fail(in, "<mass>: expected a non-negative number");
      const TiXmlElement* t = in->FirstChildElement("inertia");
      auto v = [&](const char* k, double d) {
        if (!t || !t->FirstChildElement(k)) {
          defaulted = true;
          return d;
        }
        return detail::xmlChildNumber(t, k, src, d);
      };
      const double ixx = v("ixx", 1.0), ixy = v("ixy", 0.0), ixz = v("ixz", 0.0),
                   iyy = v("iyy", 1.0), iyz = v("iyz", 0.0), izz = v("izz", 1.0);
      I << ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz;
    }
    if (defaulted) defaulted_inertials.push_back(name);
    return transformInertial(inertialFromCom(mass, Eigen::Vector3d::Zero(), I), X);
  }

  void readModel(const TiXmlElement* model) {
    for (const TiXmlElement* e = model->FirstChildElement(); e; e = e->NextSiblingElement()) {
      const std::string tag = e->Value();
      if (tag == "link") {
        const std::string name = xmlAttr(e, "name");
        addFrame(name, poseOf(e, ""));
        links[name] = e;
        link_order.push_back(name);
      } else if (tag == "joint") {
        SJoint j{e, xmlAttr(e, "name"), xmlAttr(e, "type"), detail::xmlChildText(e, "parent"),
                 detail::xmlChildText(e, "child")};
        if (j.parent.empty() || j.child.empty()) fail(e, "expected <parent> and <child>");
        addFrame(j.name, poseOf(e, j.child));
        joints.push_back(j);
      } else if (tag == "frame") {
        const std::string attached = xmlAttr(e, "attached_to");
        addFrame(xmlAttr(e, "name"), poseOf(e, attached));
      } else if (tag == "exid:closed_chain") {
        if (closed) fail(e, "a second <exid:closed_chain>");
        closed = e;
        std::istringstream names(xmlAttr(e, "cut"));
        for (std::string c; names >> c;) cut.insert(c);
        if (cut.empty()) fail(e, "cut: expected the names of the loop-closure joints");
      } else if (tag == "model" || tag == "include") {
        fail(e, "nested models and includes are not supported: give exid one flat <model>");
      } else if (tag == "static") {
        if (detail::xmlChildText(model, "static") == "true")
          fail(e, "a static model does not move; nothing to identify");
      }
    }
    if (links.empty()) fail(model, "no <link>");
  }

  void build(const TiXmlElement* model) {
    if (closed) readReference();
    // the tree: parent joint of every link, the link fixed to the world
    std::map<std::string, std::vector<const SJoint*>> children;
    std::map<std::string, const SJoint*> parent_joint;
    std::string root;
    std::vector<const SJoint*> loops;
    for (const SJoint& j : joints) {
      if (!links.count(j.child)) fail(j.e, "<child> '" + j.child + "' is not a link of the model");
      if (cut.count(j.name)) {
        if (j.parent == "world") fail(j.e, "a loop-closure joint to the world");
        loops.push_back(&j);
        continue;
      }
      if (j.parent != "world" && !links.count(j.parent))
        fail(j.e, "<parent> '" + j.parent + "' is not a link of the model (nor world)");
      if (parent_joint.count(j.child))
        fail(j.e, "link '" + j.child + "' already is the child of joint '" +
                      parent_joint[j.child]->name +
                      "': a closed kinematic chain; name its loop-closure joint (and the "
                      "actuated joints) in <exid:closed_chain cut=\"...\" actuated=\"...\">");
      parent_joint[j.child] = &j;
      if (j.parent == "world") {
        if (j.type != "fixed")
          fail(j.e, "a " + j.type +
                        " joint to the world: exid needs the model fixed to the "
                        "world by a fixed joint");
        if (!root.empty()) fail(j.e, "a second link fixed to the world ('" + root + "')");
        root = j.child;
      } else {
        children[j.parent].push_back(&j);
      }
    }
    // No joint to the world: the model is free (SDFormat's meaning), a floating base whose
    // base link is the one link that is no joint's child.
    std::vector<std::string> unattached;
    for (const auto& l : link_order)
      if (!parent_joint.count(l)) unattached.push_back(l);
    if (!root.empty() && !unattached.empty())
      fail(links[unattached.front()],
           "link '" + unattached.front() +
               "' is not attached to the world nor to another link: it would float freely while "
               "the rest is fixed to the world (link '" +
               root + "'); attach it by a joint");
    if (root.empty()) {
      if (unattached.size() != 1) {
        std::string list;
        for (const auto& l : unattached) list += (list.empty() ? "'" : ", '") + l + "'";
        fail(model, "no joint to the world and " + std::to_string(unattached.size()) +
                        " links that are no joint's child (" + list +
                        "): a free (floating-base) model has exactly one, its base link; a "
                        "model fixed to the world has a fixed joint with <parent>world</parent>");
      }
      root = unattached.front();
      m.floating_base = true;
      m.base.link = root;
      m.base.inertia = inertial(links[root]);
      m.notes.push_back(src +
                        ": no joint to the world: a free model in SDFormat, read as a "
                        "floating base (base link '" +
                        root + "', its frame the base frame)");
    }
    // depth first from the root; fixed joints merge the child into its owner
    struct Item {
      std::string link;
      int body;
      Pose X;  // the link's frame in the owning body's frame
    };
    std::vector<Item> stack{{root, -1, Pose{}}};
    std::set<std::string> seen;
    while (!stack.empty()) {
      const Item it = stack.back();
      stack.pop_back();
      if (!seen.insert(it.link).second) fail(links[it.link], "a kinematic loop");
      link_place[it.link] = {it.body, it.X};
      std::vector<Item> next;
      const Pose W_parent = inModel(it.link);
      for (const SJoint* j : children[it.link]) {
        const Pose W_child = inModel(j->child);
        const Pose X = it.X * (W_parent.inverse() * W_child);  // child link in the owner
        const Eigen::Matrix<double, 10, 1> pi = inertial(links[j->child]);
        if (j->type == "fixed") {
          if (it.body >= 0)
            m.bodies[static_cast<std::size_t>(it.body)].inertia += transformInertial(pi, X);
          else if (m.floating_base)
            m.base.inertia += transformInertial(pi, X);  // welded to the floating base
          next.push_back({j->child, it.body, X});
          continue;
        }
        next.push_back({j->child, addJoint(*j, it.body, X, W_child, pi), Pose{}});
      }
      for (auto r = next.rbegin(); r != next.rend(); ++r) stack.push_back(*r);
    }
    if (closed) closeLoops(loops);
    // the sensor frame
    if (frames.count("exid_sensor")) {
      const SFrame& f = frames["exid_sensor"];
      const std::string attached = xmlAttr(f.e, "attached_to");
      if (!links.count(attached)) fail(f.e, "the exid_sensor frame must be attached_to a link");
      // the body the link belongs to: walk up through fixed joints
      std::string l = attached;
      while (parent_joint.count(l) && parent_joint[l]->type == "fixed" &&
             parent_joint[l]->parent != "world")
        l = parent_joint[l]->parent;
      if (!parent_joint.count(l) || parent_joint[l]->parent == "world")
        fail(f.e, "the exid_sensor frame must be on a moving link");
      for (int b = 0; b < m.numJoints(); ++b)
        if (m.bodies[static_cast<std::size_t>(b)].name == l) {
          m.sensor_body = b;
          m.sensor_pose = inModel(l).inverse() * inModel("exid_sensor");
        }
    }
  }

  /// The axis of a joint in its own frame (<xyz>, or in its expressed_in frame).
  Eigen::Vector3d jointAxis(const SJoint& j) {
    const TiXmlElement* axis = j.e->FirstChildElement("axis");
    if (!axis) fail(j.e, "no <axis>");
    const TiXmlElement* xyz = axis->FirstChildElement("xyz");
    if (!xyz) fail(axis, "no <xyz>");
    const auto a = detail::xmlTextNumbers(xyz, src, 3);
    Eigen::Vector3d ax(a[0], a[1], a[2]);
    if (ax.norm() < 1e-12) fail(xyz, "expected a non-zero axis");
    if (detail::xmlChildText(axis, "use_parent_model_frame") == "true")
      fail(axis,
           "use_parent_model_frame (SDFormat 1.5/1.6) is not supported; express the axis "
           "in the joint frame or with expressed_in");
    if (xyz->Attribute("expressed_in")) {
      const std::string in = xmlAttr(xyz, "expressed_in");
      ax = inModel(j.name).R.transpose() * (inModel(in).R * ax);
    }
    return ax.normalized();
  }

  /// <exid:closed_chain>: its reference configuration (read before the tree is built).
  void readReference() {
    std::istringstream pairs(xmlAttr(closed, "reference"));
    for (std::string pr; pairs >> pr;) {
      const auto eq = pr.find('=');
      if (eq == std::string::npos)
        fail(closed, "reference: expected joint=value pairs, found '" + pr + "'");
      reference[pr.substr(0, eq)] = detail::parseNumbers(
          pr.substr(eq + 1), xmlAt(src, closed) + ": reference of '" + pr.substr(0, eq) + "'",
          1)[0];
    }
  }

  /// The cut joints as loop-closure joints (their frame in both links, where the file puts it:
  /// an assembled configuration) and the actuated joints of <exid:closed_chain>.
  void closeLoops(const std::vector<const SJoint*>& cuts) {
    std::vector<LoopJoint> loops;
    for (const SJoint* j : cuts) {
      if (j->type != "revolute" && j->type != "ball")
        fail(j->e, "a loop-closure joint must be revolute or ball, found '" + j->type + "'");
      const Pose W = inModel(j->name);
      LoopJoint l;
      l.name = j->name;
      l.where = xmlAt(src, j->e);
      l.kind = j->type == "ball" ? LoopJoint::Kind::Spherical : LoopJoint::Kind::Revolute;
      if (j->type == "revolute") l.axis = jointAxis(*j);
      for (const auto& [link, body, pose] :
           {std::tuple<std::string, int*, Pose*>{j->parent, &l.body_a, &l.pose_a},
            std::tuple<std::string, int*, Pose*>{j->child, &l.body_b, &l.pose_b}}) {
        const auto& [owner, X] = link_place.at(link);
        *body = owner;
        *pose = X * (inModel(link).inverse() * W);
      }
      loops.push_back(l);
    }
    for (const auto& c : cut) {
      bool found = false;
      for (const SJoint* j : cuts) found = found || j->name == c;
      if (!found) fail(closed, "cut: '" + c + "' is not a joint of the model");
    }
    std::vector<int> actuated;
    std::istringstream names(xmlAttr(closed, "actuated"));
    for (std::string a; names >> a;) {
      int found = -1;
      for (int b = 0; b < m.numJoints(); ++b)
        if (m.bodies[static_cast<std::size_t>(b)].joint_name == a) found = b;
      if (found < 0) fail(closed, "actuated: '" + a + "' is not a moving joint of the tree");
      actuated.push_back(found);
    }
    for (const auto& [name, value] : reference) {
      (void)value;
      bool found = false;
      for (const auto& b : m.bodies) found = found || b.joint_name == name;
      if (!found) fail(closed, "reference: '" + name + "' is not a moving joint of the tree");
    }
    detail::makeClosedChain(&m, std::move(loops), std::move(actuated),
                            Eigen::Map<const Eigen::VectorXd>(refs.data(), m.numJoints()), src);
  }

  int addJoint(const SJoint& j, int owner, const Pose& X, const Pose& W_child,
               const Eigen::Matrix<double, 10, 1>& pi) {
    static const std::set<std::string> kMoving = {"revolute", "continuous", "prismatic"};
    if (!kMoving.count(j.type))
      fail(j.e, "type '" + j.type +
                    "' is not supported (only revolute, continuous, prismatic "
                    "and fixed)");
    const Pose J = W_child.inverse() * inModel(j.name);  // joint frame in the child link
    const Eigen::Vector3d ax = jointAxis(j);
    const TiXmlElement* axis = j.e->FirstChildElement("axis");
    if (axis->NextSiblingElement("axis2")) fail(j.e, "<axis2> (two degrees of freedom)");
    Body b;
    b.name = j.child;
    b.joint_name = j.name;
    b.parent = owner;
    b.type = j.type == "prismatic" ? JointType::Prismatic : JointType::Revolute;
    b.axis = ax;
    b.pre = X * J;
    // written at exid's q = reference (SDF's zero): the joint frame at q = 0 is moved back
    const double ref = reference.count(j.name) ? reference.at(j.name) : 0.0;
    if (ref != 0.0) {
      Pose back;
      if (b.type == JointType::Prismatic)
        back.p = -ref * b.axis;
      else
        back.R = Eigen::AngleAxisd(-ref, b.axis).toRotationMatrix();
      b.pre = b.pre * back;
    }
    refs.push_back(ref);
    if (!J.isIdentity()) b.post = J.inverse();
    b.inertia = pi;
    JointLimits lim;
    if (const TiXmlElement* l = axis->FirstChildElement("limit")) {
      auto v = [&](const char* k, double d) { return detail::xmlChildNumber(l, k, src, d); };
      if (j.type != "continuous" && l->FirstChildElement("lower") &&
          l->FirstChildElement("upper")) {
        lim.q_min = v("lower", 0.0);
        lim.q_max = v("upper", 0.0);
        if (lim.q_min >= lim.q_max) fail(l, "<lower> must be below <upper>");
      }
      if (v("effort", -1.0) > 0.0) lim.tau_max = v("effort", -1.0);
      if (v("velocity", -1.0) > 0.0) lim.qd_max = v("velocity", -1.0);
    }
    Drive drv;
    if (const TiXmlElement* d = axis->FirstChildElement("dynamics")) {
      if (detail::xmlChildNumber(d, "spring_stiffness", src, 0.0) != 0.0)
        fail(d, "<spring_stiffness> is not zero: exid models no joint springs");
      const double damping = detail::xmlChildNumber(d, "damping", src, 0.0);
      const double friction = detail::xmlChildNumber(d, "friction", src, 0.0);
      if (options.urdf_dynamics_as_friction) {
        drv.viscous = damping;
        drv.coulomb = friction;
      } else if (damping != 0.0 || friction != 0.0) {
        ignored_dynamics.push_back(j.name);
      }
    }
    const int index = m.numJoints();
    m.bodies.push_back(b);
    m.limits.push_back(lim);
    m.drives.push_back(drv);
    return index;
  }

  void read(const TiXmlDocument& doc) {
    const TiXmlElement* root = doc.RootElement();
    if (!root || std::string(root->Value()) != "sdf")
      throw Error(xmlAt(src, root) + ": the root element of an SDF file must be <sdf>, found " +
                  (root ? "<" + std::string(root->Value()) + ">" : std::string("nothing")));
    const auto version = detail::parseNumbers(xmlAttr(root, "version"),
                                              xmlAt(src, root) + ": <sdf> attribute 'version'", 1);
    if (version.front() < 1.5 || version.front() > 1.9 + 1e-9)
      throw Error(xmlAt(src, root) + ": SDFormat version " + xmlAttr(root, "version") +
                  " (expected 1.5 to 1.9)");
    const TiXmlElement* model = root->FirstChildElement("model");
    if (root->FirstChildElement("world"))
      fail(root->FirstChildElement("world"),
           "a world file: give exid the robot's <model> alone (one <model> under <sdf>)");
    if (!model) fail(root, "no <model>");
    if (model->NextSiblingElement("model"))
      fail(model->NextSiblingElement("model"), "a second <model> (exid reads one robot)");
    m.name = xmlAttr(model, "name").empty() ? "robot" : xmlAttr(model, "name");
    m.source = src;
    readModel(model);
    build(model);
    if (m.dof() == 0) throw Error(src + ": no moving joint (revolute, continuous or prismatic)");
  }
};

}  // namespace

RobotModel loadSdfString(const std::string& xml, const std::string& src,
                         const LoadOptions& options) {
  Reader r;
  r.src = src;
  r.options = options;
  TiXmlDocument doc;
  detail::readXml(xml, src, "an SDF (XML) file", &doc);
  r.read(doc);
  RobotModel& m = r.m;
  detail::checkLoaded(m, src, options);
  auto list = [](const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
    return s;
  };
  m.notes.push_back(src +
                    ": an SDF model carries no gravity; exid's (0, 0, -9.81) m/s^2 in the "
                    "model frame is used (the robot's gravity key sets another)");
  if (!r.ignored_dynamics.empty())
    m.notes.push_back(src + ": <dynamics> damping and friction of joint(s) " +
                      list(r.ignored_dynamics) +
                      " not used as nominal friction (they are usually a simulator's values, "
                      "not identified ones); the sdf robot's dynamics_as_friction: true uses them");
  if (!r.defaulted_inertials.empty()) {
    const std::string msg = src + ": link(s) " + list(r.defaulted_inertials) +
                            " without a complete <inertial> (mass and six inertia elements): "
                            "SDFormat's defaults (1 kg, unit inertia at the link origin) are "
                            "used where missing";
    if (options.strict) throw Error(msg + " (strict mode)");
    reportWarning(options, msg);
  }
  return m;
}

RobotModel loadSdf(const std::filesystem::path& file, const LoadOptions& options) {
  return loadSdfString(detail::readTextFile(file, "SDF"), file.string(), options);
}

}  // namespace exid
