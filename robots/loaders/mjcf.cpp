// exid — MJCF (MuJoCo XML) robot descriptions, read with TinyXML: the body tree, inertials,
// hinge and slide joints with their ranges, armature, damping and frictionloss, motors' ranges,
// gravity and the exid_sensor site. Format and what is refused: docs/robots.md, "MJCF and SDF".
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "read_text.hpp"
#include "xml_text.hpp"

namespace exid {
namespace {

using detail::xmlAt;
using detail::xmlAttr;
using detail::xmlNumbers;

constexpr double kPi = 3.14159265358979323846;

/// The joint attributes exid reads, with their MuJoCo defaults.
const std::map<std::string, std::string>& jointDefaults() {
  static const std::map<std::string, std::string> d = {
      {"type", "hinge"},   {"pos", "0 0 0"},  {"axis", "0 0 1"}, {"range", ""},
      {"limited", "auto"}, {"armature", "0"}, {"damping", "0"},  {"frictionloss", "0"},
      {"stiffness", "0"},  {"ref", "0"},      {"springref", "0"}};
  return d;
}

struct DefaultClass {
  std::string parent;  // "" for the root class "main"
  std::map<std::string, std::string> joint, motor;
};

struct Reader {
  std::string src;
  bool degree = true;  // <compiler angle>: MuJoCo's default is degrees
  std::string eulerseq = "xyz";
  std::string inertiafromgeom = "auto";
  bool autolimits = true;  // MuJoCo 2.3's default (2.2: false, then a range needs `limited`)
  std::map<std::string, DefaultClass> classes;
  LoadOptions options;
  RobotModel m;
  std::map<std::string, int> joint_body;                   // joint name -> body index
  std::map<std::string, std::pair<int, Pose>> body_place;  // MJCF body -> exid body, frame in it
  std::vector<double> refs;                                // each joint's `ref`
  std::vector<std::string> motor_joints;                   // joints with a motor, in order
  std::vector<const TiXmlElement*> connects;               // <equality><connect>
  std::vector<std::string> ignored_dynamics, geoms;

  [[noreturn]] void fail(const TiXmlElement* e, const std::string& rule) const {
    std::string owner = "<" + std::string(e->Value()) + ">";
    if (const char* n = e->Attribute("name")) owner += std::string(" '") + n + "'";
    throw Error(xmlAt(src, e) + ": " + owner + ": " + rule);
  }

  double angle(double v) const { return degree ? v * kPi / 180.0 : v; }

  // ---------------------------------------------------------------- <default> classes
  void readDefaults(const TiXmlElement* d, const std::string& parent) {
    std::string name = xmlAttr(d, "class");
    if (name.empty()) {
      if (!parent.empty()) fail(d, "a nested <default> needs a class attribute");
      name = "main";
    }
    if (classes.count(name)) fail(d, "default class '" + name + "' is defined twice");
    DefaultClass c;
    c.parent = parent;
    for (const TiXmlElement* e = d->FirstChildElement(); e; e = e->NextSiblingElement()) {
      const std::string tag = e->Value();
      if (tag == "default") continue;
      std::map<std::string, std::string>* into =
          tag == "joint" ? &c.joint : (tag == "motor" || tag == "general" ? &c.motor : nullptr);
      if (!into) continue;  // geoms, sites, ...: not read by exid
      for (const TiXmlAttribute* a = e->FirstAttribute(); a; a = a->Next())
        (*into)[a->Name()] = a->Value();
    }
    classes[name] = c;
    for (const TiXmlElement* e = d->FirstChildElement("default"); e;
         e = e->NextSiblingElement("default"))
      readDefaults(e, name);
  }

  /// Attribute `name` of a joint (or motor) element: its own, else its class's (inherited).
  std::string attrOf(const TiXmlElement* e, const char* name, const std::string& cls,
                     bool joint) const {
    if (const char* v = e->Attribute(name)) return v;
    std::string c = xmlAttr(e, "class");
    if (c.empty()) c = cls;
    while (!c.empty()) {
      auto it = classes.find(c);
      if (it == classes.end()) fail(e, "unknown default class '" + c + "'");
      const auto& map = joint ? it->second.joint : it->second.motor;
      auto v = map.find(name);
      if (v != map.end()) return v->second;
      c = it->second.parent;
    }
    if (joint) {
      auto d = jointDefaults().find(name);
      if (d != jointDefaults().end()) return d->second;
    }
    return {};
  }

  std::vector<double> numbersOf(const TiXmlElement* e, const char* name, const std::string& cls,
                                int count) const {
    const std::string v = attrOf(e, name, cls, true);
    // (only a range may be absent: every other attribute has MuJoCo's default; one given empty,
    // as axis="", is an error naming it, not an empty vector read from)
    if (v.empty() && std::string(name) == "range") return {};
    return detail::parseNumbers(
        v, xmlAt(src, e) + ": <joint> '" + xmlAttr(e, "name") + "' attribute '" + name + "'",
        count);
  }

  // ---------------------------------------------------------------- frames
  /// The orientation of an element with a spatial frame (quat, axisangle, euler, xyaxes, zaxis;
  /// at most one), identity when none is given.
  Eigen::Matrix3d orientation(const TiXmlElement* e) const {
    int given = 0;
    for (const char* k : {"quat", "axisangle", "euler", "xyaxes", "zaxis"})
      if (e->Attribute(k)) ++given;
    if (given > 1) fail(e, "more than one of quat, axisangle, euler, xyaxes, zaxis");
    if (auto q = xmlNumbers(e, "quat", src, 4); !q.empty()) {
      Eigen::Quaterniond Q(q[0], q[1], q[2], q[3]);
      if (Q.norm() < 1e-12) fail(e, "quat: a zero quaternion");
      return Q.normalized().toRotationMatrix();
    }
    if (auto a = xmlNumbers(e, "axisangle", src, 4); !a.empty()) {
      const Eigen::Vector3d ax(a[0], a[1], a[2]);
      if (ax.norm() < 1e-12) fail(e, "axisangle: a zero axis");
      return Eigen::AngleAxisd(angle(a[3]), ax.normalized()).toRotationMatrix();
    }
    if (auto a = xmlNumbers(e, "euler", src, 3); !a.empty()) {
      Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
      for (int k = 0; k < 3; ++k) {
        const char c = eulerseq[static_cast<std::size_t>(k)];
        const Eigen::Matrix3d Rk = Eigen::AngleAxisd(angle(a[static_cast<std::size_t>(k)]),
                                                     Eigen::Vector3d::Unit(std::tolower(c) - 'x'))
                                       .toRotationMatrix();
        R = std::islower(static_cast<unsigned char>(c)) ? Eigen::Matrix3d(R * Rk)
                                                        : Eigen::Matrix3d(Rk * R);
      }
      return R;
    }
    if (auto a = xmlNumbers(e, "xyaxes", src, 6); !a.empty()) {
      Eigen::Vector3d x(a[0], a[1], a[2]), y(a[3], a[4], a[5]);
      if (x.norm() < 1e-12) fail(e, "xyaxes: a zero x axis");
      x.normalize();
      y -= x * x.dot(y);
      if (y.norm() < 1e-12) fail(e, "xyaxes: the y axis is parallel to the x axis");
      y.normalize();
      Eigen::Matrix3d R;
      R << x, y, x.cross(y);
      return R;
    }
    if (auto a = xmlNumbers(e, "zaxis", src, 3); !a.empty()) {
      const Eigen::Vector3d z(a[0], a[1], a[2]);
      if (z.norm() < 1e-12) fail(e, "zaxis: a zero vector");
      return Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), z.normalized())
          .toRotationMatrix();
    }
    return Eigen::Matrix3d::Identity();
  }

  Pose frame(const TiXmlElement* e) const {
    Pose X;
    X.R = orientation(e);
    if (auto p = xmlNumbers(e, "pos", src, 3); !p.empty()) X.p = Eigen::Vector3d(p[0], p[1], p[2]);
    return X;
  }

  /// The body's inertial parameters about its frame origin, in its frame.
  Eigen::Matrix<double, 10, 1> inertial(const TiXmlElement* body) const {
    const TiXmlElement* in = body->FirstChildElement("inertial");
    if (!in) {
      if (body->FirstChildElement("geom") && inertiafromgeom != "false")
        fail(body,
             "no <inertial>: MuJoCo would compute the inertia from the geoms, which exid "
             "does not do; give an <inertial> element");
      return Eigen::Matrix<double, 10, 1>::Zero();
    }
    if (in->NextSiblingElement("inertial")) fail(in, "a second <inertial> in one body");
    if (!in->Attribute("pos")) fail(in, "missing attribute 'pos'");
    if (!in->Attribute("mass")) fail(in, "missing attribute 'mass'");
    const double mass = xmlNumbers(in, "mass", src, 1).front();
    if (mass < 0.0) fail(in, "mass: expected a non-negative number");
    const Pose X = frame(in);
    Eigen::Matrix3d I = Eigen::Matrix3d::Zero();
    const auto d = xmlNumbers(in, "diaginertia", src, 3);
    const auto f = xmlNumbers(in, "fullinertia", src, 6);
    if (d.empty() == f.empty()) fail(in, "expected exactly one of diaginertia and fullinertia");
    if (!d.empty()) {
      I.diagonal() << d[0], d[1], d[2];
    } else {
      // MuJoCo's order: Ixx Iyy Izz Ixy Ixz Iyz
      I << f[0], f[3], f[4], f[3], f[1], f[5], f[4], f[5], f[2];
    }
    return transformInertial(inertialFromCom(mass, Eigen::Vector3d::Zero(), I), X);
  }

  // ---------------------------------------------------------------- bodies
  static constexpr const char* kDeepFree =
      "a free joint below another body: only a body of the worldbody can float (the floating "
      "base); a free joint deeper in the tree is not supported";

  /// The free joint of a body of the worldbody (<freejoint/> or <joint type="free">), null when
  /// it has none; it must be the body's only joint.
  const TiXmlElement* freeJoint(const TiXmlElement* body) const {
    const TiXmlElement* free = nullptr;
    int joints = 0;
    for (const TiXmlElement* e = body->FirstChildElement(); e; e = e->NextSiblingElement()) {
      const std::string tag = e->Value();
      if (tag != "freejoint" && tag != "joint") continue;
      ++joints;
      const std::string cls =
          xmlAttr(body, "childclass").empty() ? "main" : xmlAttr(body, "childclass");
      if (tag == "freejoint" || attrOf(e, "type", cls, true) == "free") free = e;
    }
    if (free && joints > 1)
      fail(free, "a free joint and another joint in body '" + xmlAttr(body, "name") +
                     "': the floating base's body has the free joint only (put the other joint "
                     "in a child body)");
    return free;
  }

  /// A body of the worldbody with a free joint: the floating base link (its frame the base
  /// frame; its pos/quat, the reference pose in the world, do not enter the dynamics). Bodies
  /// welded to it join its inertia; its child bodies are attached to the base.
  void addFloatingBase(const TiXmlElement* e, const TiXmlElement* free) {
    if (xmlAttr(e, "mocap") == "true")
      fail(e, "a mocap body (moved by the user, not by dynamics) is not supported");
    if (m.floating_base)
      fail(e, "a second body with a free joint (one floating base is modelled, body '" +
                  m.base.link + "' is the first)");
    m.floating_base = true;
    m.base.link = xmlAttr(e, "name");
    if (m.base.link.empty()) fail(e, "the floating base's body needs a name");
    m.base.joint_name = xmlAttr(free, "name");
    m.base.inertia = inertial(e);
    std::string cls = xmlAttr(e, "childclass");
    if (cls.empty()) cls = "main";
    if (body_place.count(m.base.link)) fail(e, "duplicate body name '" + m.base.link + "'");
    body_place[m.base.link] = {-1, Pose{}};
    for (const TiXmlElement* s = e->FirstChildElement("site"); s; s = s->NextSiblingElement("site"))
      if (xmlAttr(s, "name") == "exid_sensor")
        fail(s, "the exid_sensor site must be on a moving body (not the floating base)");
    if (e->FirstChildElement("geom")) geoms.push_back(m.base.link);
    for (const TiXmlElement* c = e->FirstChildElement("body"); c; c = c->NextSiblingElement("body"))
      addBody(c, -1, Pose{}, cls);
  }

  void refuseUnsupported(const TiXmlElement* body) const {
    if (xmlAttr(body, "mocap") == "true")
      fail(body, "a mocap body (moved by the user, not by dynamics) is not supported");
    for (const TiXmlElement* e = body->FirstChildElement(); e; e = e->NextSiblingElement()) {
      const std::string tag = e->Value();
      if (tag == "freejoint") fail(e, kDeepFree);
    }
  }

  /// One moving joint of body `e`; null when the body is welded to its parent.
  const TiXmlElement* theJoint(const TiXmlElement* e, const std::string& cls) const {
    const TiXmlElement* joint = nullptr;
    for (const TiXmlElement* j = e->FirstChildElement("joint"); j;
         j = j->NextSiblingElement("joint")) {
      if (joint)
        fail(j, "a second joint in body '" + xmlAttr(e, "name") +
                    "': exid needs one joint per body (put each joint in its own body)");
      joint = j;
    }
    if (!joint) return nullptr;
    const std::string type = attrOf(joint, "type", cls, true);
    if (type == "free") fail(joint, kDeepFree);
    if (type != "hinge" && type != "slide")
      fail(joint, "type '" + type + "' is not supported (only hinge and slide)");
    return joint;
  }

  void addBody(const TiXmlElement* e, int owner, const Pose& X_owner, const std::string& cls) {
    refuseUnsupported(e);
    const std::string name = xmlAttr(e, "name");
    std::string child_cls = xmlAttr(e, "childclass");
    if (child_cls.empty()) child_cls = cls;
    const Pose X = X_owner * frame(e);  // body frame in the owner's frame (q = 0)
    const Eigen::Matrix<double, 10, 1> pi = inertial(e);
    const TiXmlElement* j = theJoint(e, child_cls);
    int index = owner;
    Pose X_here = X;  // this body's frame in the frame of the exid body it belongs to
    if (!j) {
      if (owner >= 0)
        m.bodies[static_cast<std::size_t>(owner)].inertia += transformInertial(pi, X);
      else if (m.floating_base)
        m.base.inertia += transformInertial(pi, X);  // welded to the floating base
    } else {
      index = addJoint(e, j, child_cls, owner, X, pi);
      X_here = Pose{};
    }
    if (!name.empty()) {
      if (body_place.count(name)) fail(e, "duplicate body name '" + name + "'");
      body_place[name] = {index, X_here};
    }
    for (const TiXmlElement* s = e->FirstChildElement("site"); s; s = s->NextSiblingElement("site"))
      if (xmlAttr(s, "name") == "exid_sensor") {
        if (index < 0) fail(s, "the exid_sensor site must be on a moving body");
        m.sensor_body = index;
        m.sensor_pose = X_here * frame(s);
      }
    if (e->FirstChildElement("geom")) geoms.push_back(name.empty() ? "(unnamed)" : name);
    for (const TiXmlElement* c = e->FirstChildElement("body"); c; c = c->NextSiblingElement("body"))
      addBody(c, index, X_here, child_cls);
  }

  int addJoint(const TiXmlElement* e, const TiXmlElement* j, const std::string& cls, int owner,
               const Pose& X, const Eigen::Matrix<double, 10, 1>& pi) {
    const std::string jname = xmlAttr(j, "name");
    if (jname.empty()) fail(j, "a joint needs a name (measured coordinates are named by it)");
    if (joint_body.count(jname)) fail(j, "duplicate joint name '" + jname + "'");
    if (numbersOf(j, "stiffness", cls, 1).front() != 0.0)
      fail(j, "stiffness is not zero: exid models no joint springs (remove it, or set it to 0)");
    // the body is written at the joint value `ref` (MuJoCo's qpos0)
    const double ref = numbersOf(j, "ref", cls, 1).front();
    const auto pos = numbersOf(j, "pos", cls, 3);
    const auto axis = numbersOf(j, "axis", cls, 3);
    Eigen::Vector3d a(axis[0], axis[1], axis[2]);
    if (a.norm() < 1e-12) fail(j, "axis: expected a non-zero vector");
    const Pose J{Eigen::Matrix3d::Identity(), Eigen::Vector3d(pos[0], pos[1], pos[2])};
    Body b;
    b.name = xmlAttr(e, "name");
    if (b.name.empty()) fail(e, "a moving body needs a name");
    b.joint_name = jname;
    b.parent = owner;
    const bool slide = attrOf(j, "type", cls, true) == "slide";
    b.pre = X * J;
    if (ref != 0.0) {  // the joint frame at q = 0: moved back by ref
      Pose back;
      if (slide)
        back.p = -ref * a.normalized();
      else
        back.R = Eigen::AngleAxisd(-angle(ref), a.normalized()).toRotationMatrix();
      b.pre = b.pre * back;
    }
    if (!J.isIdentity()) b.post = J.inverse();
    b.type = slide ? JointType::Prismatic : JointType::Revolute;
    b.axis = a.normalized();
    b.inertia = pi;
    JointLimits lim;
    const auto range = numbersOf(j, "range", cls, 2);
    const std::string limited = attrOf(j, "limited", cls, true);
    if (limited != "true" && limited != "false" && limited != "auto")
      fail(j, "limited: expected true, false or auto, found '" + limited + "'");
    if (limited == "true" && range.empty()) fail(j, "limited=\"true\" without a range");
    if (limited == "auto" && !range.empty() && !autolimits)
      fail(j,
           "a range without `limited` while <compiler autolimits=\"false\">: say limited=\"true\" "
           "or \"false\"");
    if (!range.empty() && limited != "false") {
      lim.q_min = slide ? range[0] : angle(range[0]);
      lim.q_max = slide ? range[1] : angle(range[1]);
      if (lim.q_min >= lim.q_max) fail(j, "range: the lower bound must be below the upper");
    }
    Drive drv;
    const double armature = numbersOf(j, "armature", cls, 1).front();
    const double damping = numbersOf(j, "damping", cls, 1).front();
    const double friction = numbersOf(j, "frictionloss", cls, 1).front();
    if (options.urdf_dynamics_as_friction) {
      drv.rotor_inertia = armature;
      drv.viscous = damping;
      drv.coulomb = friction;
    } else if (armature != 0.0 || damping != 0.0 || friction != 0.0) {
      ignored_dynamics.push_back(jname);
    }
    const int index = m.numJoints();
    m.bodies.push_back(b);
    m.limits.push_back(lim);
    m.drives.push_back(drv);
    refs.push_back(slide ? ref : angle(ref));
    joint_body[jname] = index;
    return index;
  }

  // ---------------------------------------------------------------- top level
  void readCompiler(const TiXmlElement* c) {
    if (c->Attribute("angle")) {
      const std::string a = xmlAttr(c, "angle");
      if (a != "radian" && a != "degree") fail(c, "angle: expected radian or degree");
      degree = a == "degree";
    }
    if (c->Attribute("eulerseq")) {
      const std::string s = xmlAttr(c, "eulerseq");
      const bool ok = s.size() == 3 && std::all_of(s.begin(), s.end(), [](char ch) {
                        return std::string("xyzXYZ").find(ch) != std::string::npos;
                      });
      if (!ok) fail(c, "eulerseq: expected three of x y z X Y Z");
      eulerseq = s;
    }
    if (c->Attribute("inertiafromgeom")) inertiafromgeom = xmlAttr(c, "inertiafromgeom");
    if (c->Attribute("autolimits")) {
      const std::string a = xmlAttr(c, "autolimits");
      if (a != "true" && a != "false") fail(c, "autolimits: expected true or false");
      autolimits = a == "true";
    }
  }

  void readMotor(const TiXmlElement* a) {
    const std::string jn = xmlAttr(a, "joint");
    if (jn.empty()) fail(a, "only actuators on a joint are read (joint=\"...\")");
    auto it = joint_body.find(jn);
    if (it == joint_body.end()) fail(a, "unknown joint '" + jn + "'");
    for (const auto& o : motor_joints)
      if (o == jn) fail(a, "a second actuator on joint '" + jn + "'");
    motor_joints.push_back(jn);
    const std::string cls = xmlAttr(a, "class").empty() ? "main" : xmlAttr(a, "class");
    auto number = [&](const char* k) -> std::vector<double> {
      const std::string v = attrOf(a, k, classes.count(cls) ? cls : "", false);
      return v.empty() ? std::vector<double>{}
                       : detail::parseNumbers(v, xmlAt(src, a) + ": attribute '" + k + "'", -1);
    };
    const auto gear = number("gear");
    const auto range = number("ctrlrange");
    const std::string limited = attrOf(a, "ctrllimited", classes.count(cls) ? cls : "", false);
    if (range.size() == 2 && limited != "false") {
      const double g = gear.empty() ? 1.0 : std::abs(gear.front());
      const double t = g * std::min(std::abs(range[0]), std::abs(range[1]));
      if (t > 0.0) m.limits[static_cast<std::size_t>(it->second)].tau_max = t;
    }
  }

  void read(const TiXmlDocument& doc) {
    const TiXmlElement* root = doc.RootElement();
    if (!root || std::string(root->Value()) != "mujoco")
      throw Error(xmlAt(src, root) + ": the root element of an MJCF file must be <mujoco>, found " +
                  (root ? "<" + std::string(root->Value()) + ">" : std::string("nothing")));
    m.name = xmlAttr(root, "model").empty() ? "robot" : xmlAttr(root, "model");
    m.source = src;
    classes["main"] = DefaultClass{};
    bool main_seen = false;
    static const std::set<std::string> kIgnored = {"size",     "visual",  "statistic",
                                                   "asset",    "contact", "sensor",
                                                   "keyframe", "custom",  "extension"};
    for (const TiXmlElement* e = root->FirstChildElement(); e; e = e->NextSiblingElement()) {
      const std::string tag = e->Value();
      if (tag == "compiler") {
        readCompiler(e);
      } else if (tag == "option") {
        if (auto g = xmlNumbers(e, "gravity", src, 3); !g.empty())
          m.gravity = Eigen::Vector3d(g[0], g[1], g[2]);
      } else if (tag == "default") {
        if (main_seen) fail(e, "a second top-level <default>");
        main_seen = true;
        classes.erase("main");
        readDefaults(e, "");
      } else if (tag == "include") {
        fail(e,
             "<include> is not supported: give exid one file (MuJoCo can save it: "
             "mj_saveLastXML)");
      } else if (tag == "equality") {
        for (const TiXmlElement* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) {
          if (std::string(c->Value()) != "connect")
            fail(c,
                 "only `connect` equality constraints (loop-closure ball joints) are read; "
                 "weld, joint and tendon constraints couple what exid cannot represent");
          connects.push_back(c);
        }
      } else if (tag == "tendon") {
        if (e->FirstChildElement())
          fail(e, "tendons (coupled joints, springs) are not supported by the MJCF loader");
      } else if (tag != "worldbody" && tag != "actuator" && !kIgnored.count(tag)) {
        fail(e, "unknown element (expected compiler, option, default, worldbody, actuator, ...)");
      }
    }
    if (inertiafromgeom != "false" && inertiafromgeom != "auto" && inertiafromgeom != "true")
      throw Error(src + ": <compiler> inertiafromgeom: expected false, auto or true");
    const TiXmlElement* world = root->FirstChildElement("worldbody");
    if (!world) throw Error(xmlAt(src, root) + ": no <worldbody>");
    if (inertiafromgeom == "true")
      throw Error(src +
                  ": <compiler inertiafromgeom=\"true\">: MuJoCo computes every inertia "
                  "from the geoms, which exid does not do; give <inertial> elements and "
                  "inertiafromgeom=\"false\" or \"auto\"");
    // A body of the worldbody with a free joint is the floating base; then it is the only
    // body there (the other bodies would be fixed to the world, which does not move with it).
    int top = 0;
    const TiXmlElement* base = nullptr;
    for (const TiXmlElement* b = world->FirstChildElement("body"); b;
         b = b->NextSiblingElement("body")) {
      ++top;
      if (freeJoint(b) && !base) base = b;
    }
    if (base && top > 1)
      fail(base,
           "a floating base (free joint) and other bodies in the worldbody: exid models one "
           "robot, all of whose bodies hang from the floating base (remove the other bodies, or "
           "the free joint)");
    if (base) {
      addFloatingBase(base, freeJoint(base));
    } else {
      for (const TiXmlElement* b = world->FirstChildElement("body"); b;
           b = b->NextSiblingElement("body"))
        addBody(b, -1, Pose{}, "main");
    }
    if (m.dof() == 0) throw Error(src + ": no moving joint (hinge or slide) in the model");
    if (const TiXmlElement* act = root->FirstChildElement("actuator"))
      for (const TiXmlElement* a = act->FirstChildElement(); a; a = a->NextSiblingElement()) {
        const std::string tag = a->Value();
        if (tag == "motor" || tag == "general") readMotor(a);
      }
    if (!connects.empty()) closeLoops();
  }

  /// The `connect` constraints as spherical loop-closure joints: the anchor in body1's frame;
  /// body2's point is where the anchor is in the written configuration (MuJoCo's rule), which
  /// is the reference configuration of the closed chain. The actuated joints are the motors'.
  void closeLoops() {
    const Eigen::VectorXd ref = Eigen::Map<const Eigen::VectorXd>(refs.data(), m.numJoints());
    DynamicsDataPtr data = makeDynamicsData(m);
    auto place = [&](const TiXmlElement* c, const char* key) -> std::pair<int, Pose> {
      const std::string name = xmlAttr(c, key);
      if (name == "world") return {-1, Pose{}};
      auto it = body_place.find(name);
      if (it == body_place.end()) fail(c, std::string(key) + ": unknown body '" + name + "'");
      return it->second;
    };
    auto world = [&](const std::pair<int, Pose>& p) {
      return (p.first < 0 ? Pose{} : bodyPose(m, *data, ref, p.first)) * p.second;
    };
    std::vector<LoopJoint> loops;
    for (const TiXmlElement* c : connects) {
      if (!c->Attribute("body1") || !c->Attribute("anchor"))
        fail(c, "a connect needs body1 and anchor (body2 defaults to the world)");
      const auto a = place(c, "body1");
      const auto b = c->Attribute("body2") ? place(c, "body2") : std::pair<int, Pose>{-1, Pose{}};
      if (a.first == b.first) fail(c, "body1 and body2 move together (the same body)");
      const auto anchor = xmlNumbers(c, "anchor", src, 3);
      LoopJoint l;
      l.name = xmlAttr(c, "name").empty() ? "connect" + std::to_string(loops.size() + 1)
                                          : xmlAttr(c, "name");
      l.kind = LoopJoint::Kind::Spherical;
      l.where = xmlAt(src, c);
      l.body_a = a.first;
      l.body_b = b.first;
      l.pose_a.p = a.second.R * Eigen::Vector3d(anchor[0], anchor[1], anchor[2]) + a.second.p;
      const Pose Wa = world({a.first, Pose{}}), Wb = world({b.first, Pose{}});
      const Eigen::Vector3d in_world = Wa.R * l.pose_a.p + Wa.p;
      l.pose_b.p = Wb.R.transpose() * (in_world - Wb.p);
      l.pose_b.R = Wb.R.transpose() * Wa.R;  // the cut frame: body1's axes where it is written
      // A second connect between the same two bodies makes the pair a revolute joint about the
      // line through both anchors (exactly: two ball joints leave only that rotation).
      bool merged = false;
      for (LoopJoint& o : loops)
        if (o.body_a == l.body_a && o.body_b == l.body_b) {
          if (o.kind == LoopJoint::Kind::Revolute)
            fail(c, "a third connect between bodies '" + xmlAttr(c, "body1") + "' and '" +
                        xmlAttr(c, "body2") + "' (a weld), which exid does not model");
          const Eigen::Vector3d axis = l.pose_a.p - o.pose_a.p;
          if (axis.norm() < 1e-9)
            fail(c, "two connects between the same bodies at the same anchor");
          o.kind = LoopJoint::Kind::Revolute;
          o.axis = o.pose_a.R.transpose() * axis.normalized();
          merged = true;
        }
      if (!merged) loops.push_back(l);
    }
    if (motor_joints.empty())
      throw Error(src +
                  ": loop-closure `connect` constraints but no motor: the actuated joints "
                  "of a closed chain are the joints with a motor (<actuator><motor joint>)");
    std::vector<int> actuated;
    for (const auto& j : motor_joints) actuated.push_back(joint_body.at(j));
    detail::makeClosedChain(&m, std::move(loops), std::move(actuated), ref, src);
  }
};

}  // namespace

RobotModel loadMjcfString(const std::string& xml, const std::string& src,
                          const LoadOptions& options) {
  Reader r;
  r.src = src;
  r.options = options;
  TiXmlDocument doc;
  detail::readXml(xml, src, "an MJCF (XML) file", &doc);
  r.read(doc);
  RobotModel& m = r.m;
  detail::checkLoaded(m, src, options);
  if (!r.ignored_dynamics.empty()) {
    std::string list;
    for (const auto& s : r.ignored_dynamics) list += (list.empty() ? "" : ", ") + s;
    m.notes.push_back(
        src + ": armature, damping and frictionloss of joint(s) " + list +
        " not used as nominal drive terms (they are usually a simulator's values, "
        "not identified ones); the mjcf robot's dynamics_as_friction: true uses them");
  }
  if (!r.geoms.empty())
    m.notes.push_back(src + ": the geoms (collision and visual shapes) are not read");
  return m;
}

RobotModel loadMjcf(const std::filesystem::path& file, const LoadOptions& options) {
  return loadMjcfString(detail::readTextFile(file, "MJCF"), file.string(), options);
}

}  // namespace exid
