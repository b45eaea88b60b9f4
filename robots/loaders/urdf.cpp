// exid — URDF robot descriptions (urdfdom for the values, TinyXML for structure checks with line
// numbers and for the <exid> extension element). Format: docs/robots.md.
#include <console_bridge/console.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "read_text.hpp"
#include "xml_text.hpp"

namespace exid {
namespace {

std::string at(const std::string& source, const TiXmlNode* node) {
  return detail::xmlAt(source, node);
}

void checkUtf8(const std::string& text, const std::string& src) {
  detail::checkXmlUtf8(text, src, "a URDF (XML) file");
}

// ------------------------------------------------------------------ structure (TinyXML pass)
struct XJoint {
  std::string name, type, parent, child;
  int line = 0;
};
struct XLink {
  std::string name;
  int line = 0;
};
struct XRobot {
  std::string name;
  std::vector<XLink> links;
  std::vector<XJoint> joints;  // document order
  const TiXmlElement* exid = nullptr;
  std::string root;
  std::string floating_joint;  // the 'floating' joint from the world link to the base link
  std::string world;           // its parent (the root of the document) when there is one
  std::map<std::string, std::vector<int>> children;  // link -> joint indices (document order)
};

std::string attr(const TiXmlElement* e, const char* name) {
  const char* v = e->Attribute(name);
  return v ? std::string(v) : std::string();
}

/// Checks that attribute `name` of e (when present) holds `count` finite numbers.
void checkNumbers(const TiXmlElement* e, const char* name, int count, const std::string& src,
                  const std::string& owner) {
  const char* v = e->Attribute(name);
  if (!v) return;
  std::istringstream ss(v);
  std::string tok;
  int found = 0;
  while (ss >> tok) {
    errno = 0;
    char* end = nullptr;
    const double d = std::strtod(tok.c_str(), &end);
    const std::string where =
        at(src, e) + ": " + owner + ": <" + e->Value() + "> attribute '" + name + "': ";
    if (end == tok.c_str() || *end != '\0' || errno == ERANGE) {
      throw Error(where + "expected a number, found '" + tok + "'");
    }
    if (!std::isfinite(d)) throw Error(where + "expected a finite number, found '" + tok + "'");
    ++found;
  }
  if (found != count) {
    throw Error(at(src, e) + ": " + owner + ": <" + e->Value() + "> attribute '" + name +
                "': expected " + std::to_string(count) + " number(s), found " +
                std::to_string(found));
  }
}

/// Numbers of the elements exid reads, checked with their line (urdfdom's own checks are
/// incomplete: e.g. a bad <mass> only logs an error and leaves the mass zero).
void checkLinkNumbers(const TiXmlElement* link, const std::string& src, const std::string& owner) {
  for (const TiXmlElement* in = link->FirstChildElement("inertial"); in;
       in = in->NextSiblingElement("inertial")) {
    if (const TiXmlElement* o = in->FirstChildElement("origin")) {
      checkNumbers(o, "xyz", 3, src, owner);
      checkNumbers(o, "rpy", 3, src, owner);
    }
    const TiXmlElement* mass = in->FirstChildElement("mass");
    if (!mass || !mass->Attribute("value")) {
      throw Error(at(src, in) + ": " + owner + ": <inertial> without <mass value=\"...\"/>");
    }
    checkNumbers(mass, "value", 1, src, owner);
    const TiXmlElement* I = in->FirstChildElement("inertia");
    if (!I) throw Error(at(src, in) + ": " + owner + ": <inertial> without <inertia .../>");
    for (const char* k : {"ixx", "ixy", "ixz", "iyy", "iyz", "izz"}) {
      if (!I->Attribute(k)) {
        throw Error(at(src, I) + ": " + owner + ": <inertia> without attribute '" + k + "'");
      }
      checkNumbers(I, k, 1, src, owner);
    }
  }
}

void checkJointNumbers(const TiXmlElement* j, const std::string& src, const std::string& owner) {
  if (const TiXmlElement* o = j->FirstChildElement("origin")) {
    checkNumbers(o, "xyz", 3, src, owner);
    checkNumbers(o, "rpy", 3, src, owner);
  }
  if (const TiXmlElement* a = j->FirstChildElement("axis")) checkNumbers(a, "xyz", 3, src, owner);
  if (const TiXmlElement* l = j->FirstChildElement("limit")) {
    for (const char* k : {"lower", "upper", "effort", "velocity"})
      checkNumbers(l, k, 1, src, owner);
  }
  if (const TiXmlElement* d = j->FirstChildElement("dynamics")) {
    for (const char* k : {"damping", "friction"}) checkNumbers(d, k, 1, src, owner);
  }
}

// One <joint>: name, type (supported ones only), parent and child links, numbers checked.
XJoint readJointElement(const TiXmlElement* e, const std::string& src,
                        std::map<std::string, int>* lines) {
  XJoint j;
  j.name = attr(e, "name");
  j.type = attr(e, "type");
  j.line = e->Row();
  if (j.name.empty()) throw Error(at(src, e) + ": <joint> without a name attribute");
  if (lines->count(j.name)) {
    throw Error(at(src, e) + ": joint '" + j.name + "': duplicate joint (first at line " +
                std::to_string(lines->at(j.name)) + ")");
  }
  (*lines)[j.name] = j.line;
  static const std::set<std::string> kSupported = {"revolute", "continuous", "prismatic", "fixed",
                                                   "floating"};
  if (!kSupported.count(j.type)) {
    throw Error(at(src, e) + ": joint '" + j.name +
                "': " + (j.type.empty() ? std::string("missing type") : j.type + " joints are") +
                " not supported (only revolute, continuous, prismatic, fixed, and one floating "
                "joint from the world link to the base link)");
  }
  if (e->FirstChildElement("mimic")) {
    throw Error(at(src, e) + ": joint '" + j.name +
                "': <mimic> is not supported (use the <exid><transmission> matrix)");
  }
  const TiXmlElement* p = e->FirstChildElement("parent");
  const TiXmlElement* c = e->FirstChildElement("child");
  if (!p || attr(p, "link").empty()) {
    throw Error(at(src, e) + ": joint '" + j.name + "': missing <parent link=\"...\"/>");
  }
  if (!c || attr(c, "link").empty()) {
    throw Error(at(src, e) + ": joint '" + j.name + "': missing <child link=\"...\"/>");
  }
  checkJointNumbers(e, src, "joint '" + j.name + "'");
  j.parent = attr(p, "link");
  j.child = attr(c, "link");
  return j;
}

// The joints form one tree over the links: every joint names existing links, every link has
// at most one parent joint, no cycle, one root (x->root); fills x->children.
void linkTree(const std::string& src, const std::map<std::string, int>& link_line, XRobot* xp) {
  XRobot& x = *xp;
  // Every joint names existing links; every link has at most one parent joint.
  std::map<std::string, int> parent_joint;
  for (size_t k = 0; k < x.joints.size(); ++k) {
    const XJoint& j = x.joints[k];
    for (const auto* l : {&j.parent, &j.child}) {
      if (!link_line.count(*l)) {
        throw Error(src + ":" + std::to_string(j.line) + ": joint '" + j.name +
                    "': unknown link '" + *l + "' (missing <link name=\"" + *l + "\">)");
      }
    }
    if (j.parent == j.child) {
      throw Error(src + ":" + std::to_string(j.line) + ": joint '" + j.name +
                  "': kinematic loop: link '" + j.parent + "' is its own parent");
    }
    auto it = parent_joint.find(j.child);
    if (it != parent_joint.end()) {
      const XJoint& o = x.joints[static_cast<size_t>(it->second)];
      throw Error(src + ":" + std::to_string(j.line) + ": joint '" + j.name +
                  "': kinematic loop: link '" + j.child + "' already is the child of joint '" +
                  o.name + "' (line " + std::to_string(o.line) +
                  "); a URDF must be a tree (close a loop with an <exid><loop> element)");
    }
    parent_joint[j.child] = static_cast<int>(k);
    x.children[j.parent].push_back(static_cast<int>(k));
  }
  // Cycles: walk up from every link.
  for (const auto& l : x.links) {
    std::vector<std::string> path{l.name};
    std::set<std::string> seen{l.name};
    std::string cur = l.name;
    while (parent_joint.count(cur)) {
      cur = x.joints[static_cast<size_t>(parent_joint[cur])].parent;
      path.push_back(cur);
      if (!seen.insert(cur).second) {
        std::string chain;
        for (const auto& s : path) chain += (chain.empty() ? "" : " -> ") + s;
        throw Error(src + ": link '" + l.name + "': kinematic loop (" + chain +
                    "); a URDF must be a tree");
      }
    }
  }
  std::vector<std::string> roots;
  for (const auto& l : x.links) {
    if (!parent_joint.count(l.name)) roots.push_back(l.name);
  }
  if (roots.size() != 1) {
    std::string list;
    for (const auto& s : roots) list += (list.empty() ? "'" : ", '") + s + "'";
    throw Error(src + ": several root links (" + list +
                "): every link but one must be the child of a joint");
  }
  x.root = roots.front();
  // A floating base: one 'floating' joint, from the root (the world link, massless, nothing else
  // attached) to the base link, which becomes the root of the bodies.
  for (const XJoint& j : x.joints) {
    if (j.type != "floating") continue;
    const std::string w = src + ":" + std::to_string(j.line) + ": joint '" + j.name + "': ";
    if (!x.floating_joint.empty())
      throw Error(w + "a second floating joint (one floating base is modelled, joint '" +
                  x.floating_joint + "' is the first)");
    if (j.parent != x.root)
      throw Error(w + "a floating joint must connect the world (root) link '" + x.root +
                  "' to the base link; its parent is '" + j.parent + "'");
    if (x.children[x.root].size() != 1)
      throw Error(w + "the world link '" + x.root +
                  "' has other joints besides the floating one (expected only the floating "
                  "joint to the base link)");
    x.floating_joint = j.name;
  }
  if (!x.floating_joint.empty()) {
    x.world = x.root;
    for (const XJoint& j : x.joints)
      if (j.name == x.floating_joint) x.root = j.child;
  }
}

XRobot readStructure(const TiXmlDocument& doc, const std::string& src) {
  const TiXmlElement* robot = doc.RootElement();
  if (!robot || std::string(robot->Value()) != "robot") {
    throw Error(at(src, robot) + ": the root element must be <robot>, found <" +
                (robot ? robot->Value() : "nothing") + ">");
  }
  XRobot x;
  x.name = attr(robot, "name");
  std::map<std::string, int> link_line, joint_line;
  // A xacro file (named *.xacro, or with xacro: elements beside the links: macros, includes,
  // properties) is not a URDF: its macros would be ignored and its ${...} read as names.
  const bool xacro_name = src.size() >= 6 && src.compare(src.size() - 6, 6, ".xacro") == 0;
  const TiXmlElement* macro = nullptr;
  for (const TiXmlElement* e = robot->FirstChildElement(); e && !macro; e = e->NextSiblingElement())
    if (std::string(e->Value()).rfind("xacro:", 0) == 0) macro = e;
  if (xacro_name || macro)
    throw Error((macro ? at(src, macro) + ": <" + macro->Value() + ">" : src) +
                ": this is a xacro file (macros, not a URDF); expand it first: xacro " + src +
                " > robot.urdf");
  for (const TiXmlElement* e = robot->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const std::string tag = e->Value();
    if (tag == "link") {
      XLink l{attr(e, "name"), e->Row()};
      if (l.name.empty()) throw Error(at(src, e) + ": <link> without a name attribute");
      if (link_line.count(l.name)) {
        throw Error(at(src, e) + ": link '" + l.name + "': duplicate link (first at line " +
                    std::to_string(link_line[l.name]) + ")");
      }
      link_line[l.name] = l.line;
      checkLinkNumbers(e, src, "link '" + l.name + "'");
      x.links.push_back(l);
    } else if (tag == "joint") {
      x.joints.push_back(readJointElement(e, src, &joint_line));
    } else if (tag == "exid") {
      if (x.exid) throw Error(at(src, e) + ": a second <exid> element (one is allowed)");
      x.exid = e;
    }
  }
  if (x.links.empty()) {
    throw Error(src + ": no <link> in the robot");
  }

  linkTree(src, link_line, &x);
  return x;
}

// ------------------------------------------------------------------ urdfdom with captured errors
class CaptureHandler : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR) {
      errors += (errors.empty() ? "" : "; ") + text;
    }
  }
  std::string errors;
};

urdf::ModelInterfaceSharedPtr parseWithUrdfdom(const std::string& xml, const std::string& src) {
  static std::mutex mutex;  // console_bridge's handler is process-wide
  std::lock_guard<std::mutex> lock(mutex);
  CaptureHandler handler;
  console_bridge::OutputHandler* previous = console_bridge::getOutputHandler();
  console_bridge::useOutputHandler(&handler);
  urdf::ModelInterfaceSharedPtr model;
  std::string exception;
  try {
    model = urdf::parseURDF(xml);
  } catch (const std::exception& e) {
    exception = e.what();
  }
  console_bridge::useOutputHandler(previous);
  if (!model || !handler.errors.empty()) {
    std::string why = handler.errors;
    if (!exception.empty()) why += (why.empty() ? "" : "; ") + exception;
    throw Error(src + ": invalid URDF (urdfdom): " + (why.empty() ? "unknown error" : why));
  }
  return model;
}

// ------------------------------------------------------------------ conversions
Pose toPose(const urdf::Pose& u) {
  Pose P;
  double x = 0, y = 0, z = 0, w = 1;
  u.rotation.getQuaternion(x, y, z, w);
  P.R = Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
  P.p = Eigen::Vector3d(u.position.x, u.position.y, u.position.z);
  return P;
}

bool finitePose(const Pose& P) { return P.R.allFinite() && P.p.allFinite(); }

Eigen::Matrix<double, 10, 1> linkInertial(const urdf::Link& link, const std::string& src) {
  Eigen::Matrix<double, 10, 1> pi = Eigen::Matrix<double, 10, 1>::Zero();
  if (!link.inertial) return pi;
  const urdf::Inertial& in = *link.inertial;
  Eigen::Matrix3d I;
  I << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
  const Pose X = toPose(in.origin);  // centre-of-mass frame in the link frame
  if (!std::isfinite(in.mass) || !I.allFinite() || !finitePose(X)) {
    throw Error(src + ": link '" + link.name + "': <inertial>: non-finite number");
  }
  return transformInertial(inertialFromCom(in.mass, Eigen::Vector3d::Zero(), I), X);
}

// ------------------------------------------------------------------ <exid> extension
struct ExtReader {
  std::string src;
  [[noreturn]] void fail(const TiXmlElement* e, const std::string& rule) const {
    throw Error(at(src, e) + ": <exid><" + e->Value() + ">: " + rule);
  }
  void allow(const TiXmlElement* e, const std::set<std::string>& names) const {
    for (const TiXmlAttribute* a = e->FirstAttribute(); a; a = a->Next()) {
      if (!names.count(a->Name())) {
        std::string list;
        for (const auto& s : names) list += (list.empty() ? "" : ", ") + s;
        fail(e, std::string("unknown attribute '") + a->Name() + "' (allowed: " + list + ")");
      }
    }
  }
  std::vector<double> numbers(const TiXmlElement* e, const char* name, int size) const {
    const char* v = e->Attribute(name);
    std::vector<double> out;
    if (!v) return out;
    std::istringstream ss(v);
    std::string tok;
    while (ss >> tok) {
      errno = 0;
      char* end = nullptr;
      const double d = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || errno == ERANGE) {
        fail(e, std::string("attribute '") + name + "': expected numbers, found '" + tok + "'");
      }
      if (!std::isfinite(d)) {
        fail(e, std::string("attribute '") + name + "': non-finite number '" + tok + "'");
      }
      out.push_back(d);
    }
    if (size >= 0 && static_cast<int>(out.size()) != size) {
      fail(e, std::string("attribute '") + name + "': expected " + std::to_string(size) +
                  " numbers, found " + std::to_string(out.size()));
    }
    return out;
  }
  bool number(const TiXmlElement* e, const char* name, double* out) const {
    auto v = numbers(e, name, -1);
    if (v.empty()) {
      if (e->Attribute(name)) fail(e, std::string("attribute '") + name + "' is empty");
      return false;
    }
    if (v.size() != 1) fail(e, std::string("attribute '") + name + "': expected one number");
    *out = v.front();
    return true;
  }
};

struct LinkPlace {
  int body = -1;  // -1: the fixed base
  Pose X;         // link frame in that body's frame
};

void applyExtension(const TiXmlElement* ext, const std::string& src, RobotModel* m,
                    const std::map<std::string, int>& joint_body,
                    const std::map<std::string, LinkPlace>& link_place,
                    const LoadOptions& options) {
  const ExtReader r{src};
  const int n = m->dof();
  auto bodyOfJoint = [&](const TiXmlElement* e) {
    const std::string j = attr(e, "joint");
    if (j.empty()) r.fail(e, "missing attribute 'joint'");
    auto it = joint_body.find(j);
    if (it == joint_body.end()) {
      r.fail(e, "joint '" + j + "': no such movable joint in the robot");
    }
    return it->second;
  };
  bool had_transmission = false;
  // closed chains: loop-closure joints, actuated joints, reference values (tree joints)
  std::vector<LoopJoint> loops;
  std::vector<int> actuated;
  const TiXmlElement* actuated_el = nullptr;
  std::map<int, double> reference;
  std::map<int, const TiXmlElement*> drive_el;
  auto pose = [&](const TiXmlElement* e, const char* xyz_key, const char* rpy_key) {
    Pose P;
    auto xyz = r.numbers(e, xyz_key, e->Attribute(xyz_key) ? 3 : -1);
    auto rpy = r.numbers(e, rpy_key, e->Attribute(rpy_key) ? 3 : -1);
    if (!xyz.empty()) P.p = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
    if (!rpy.empty()) P.R = detail::rpyToMatrix(rpy[0], rpy[1], rpy[2]);
    return P;
  };
  for (const TiXmlElement* e = ext->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const std::string tag = e->Value();
    if (tag == "loop") {
      r.allow(e, {"name", "type", "link_a", "link_b", "xyz_a", "rpy_a", "xyz_b", "rpy_b", "axis"});
      LoopJoint lj;
      lj.name = attr(e, "name");
      lj.where = at(src, e);
      const std::string type = e->Attribute("type") ? attr(e, "type") : "revolute";
      if (type == "revolute")
        lj.kind = LoopJoint::Kind::Revolute;
      else if (type == "spherical")
        lj.kind = LoopJoint::Kind::Spherical;
      else
        r.fail(e, "type '" + type + "': expected revolute or spherical");
      LinkPlace side[2];
      const char* keys[2] = {"link_a", "link_b"};
      for (int k = 0; k < 2; ++k) {
        const std::string l = attr(e, keys[k]);
        if (l.empty()) r.fail(e, std::string("missing attribute '") + keys[k] + "'");
        auto it = link_place.find(l);
        if (it == link_place.end()) r.fail(e, std::string(keys[k]) + " '" + l + "': no such link");
        side[k] = it->second;
      }
      lj.body_a = side[0].body;
      lj.body_b = side[1].body;
      if (lj.body_a == lj.body_b)
        r.fail(e, "link_a and link_b move together (the same body): nothing to close");
      lj.pose_a = side[0].X * pose(e, "xyz_a", "rpy_a");
      lj.pose_b = side[1].X * pose(e, "xyz_b", "rpy_b");
      auto ax = r.numbers(e, "axis", e->Attribute("axis") ? 3 : -1);
      if (!ax.empty()) {
        const Eigen::Vector3d a(ax[0], ax[1], ax[2]);
        if (!(a.norm() > 1e-12)) r.fail(e, "axis must not be zero");
        lj.axis = a.normalized();
      }
      loops.push_back(lj);
    } else if (tag == "actuated") {
      r.allow(e, {"joints"});
      if (actuated_el) r.fail(e, "a second <actuated>");
      actuated_el = e;
      std::istringstream ss(attr(e, "joints"));
      std::string j;
      while (ss >> j) {
        auto it = joint_body.find(j);
        if (it == joint_body.end()) r.fail(e, "joint '" + j + "': no such movable joint");
        if (std::find(actuated.begin(), actuated.end(), it->second) != actuated.end())
          r.fail(e, "joint '" + j + "' named twice");
        actuated.push_back(it->second);
      }
      if (actuated.empty()) r.fail(e, "attribute 'joints' names no joint");
    } else if (tag == "reference") {
      r.allow(e, {"joint", "value"});
      double v = 0;
      if (!r.number(e, "value", &v)) r.fail(e, "missing attribute 'value' (rad or m)");
      reference[bodyOfJoint(e)] = v;
    } else if (tag == "drive") {
      drive_el[bodyOfJoint(e)] = e;
      r.allow(e, {"joint", "gear_ratio", "motor_inertia", "rotor_inertia", "coulomb", "viscous",
                  "offset"});
      Drive& d = m->drives[static_cast<size_t>(bodyOfJoint(e))];
      r.number(e, "gear_ratio", &d.gear_ratio);
      if (d.gear_ratio == 0.0) r.fail(e, "gear_ratio must not be zero");
      double jm = 0;
      const bool has_jm = r.number(e, "motor_inertia", &jm);
      const bool has_ia = r.number(e, "rotor_inertia", &d.rotor_inertia);
      if (has_jm && has_ia) {
        r.fail(e,
               "give either motor_inertia (motor side, reflected as Jm*G^2) or "
               "rotor_inertia (reflected), not both");
      }
      if (has_jm) d.rotor_inertia = jm * d.gear_ratio * d.gear_ratio;
      r.number(e, "coulomb", &d.coulomb);
      r.number(e, "viscous", &d.viscous);
      r.number(e, "offset", &d.offset);
    } else if (tag == "limit") {
      r.allow(e, {"joint", "q_min", "q_max", "qd_max", "qdd_max", "tau_max"});
      JointLimits& L = m->limits[static_cast<size_t>(bodyOfJoint(e))];
      r.number(e, "q_min", &L.q_min);
      r.number(e, "q_max", &L.q_max);
      r.number(e, "qd_max", &L.qd_max);
      r.number(e, "qdd_max", &L.qdd_max);
      r.number(e, "tau_max", &L.tau_max);
      if (L.q_min >= L.q_max) r.fail(e, "q_min must be below q_max");
      if (L.qd_max <= 0 || L.qdd_max <= 0 || L.tau_max <= 0) {
        r.fail(e, "qd_max, qdd_max and tau_max must be positive");
      }
    } else if (tag == "gravity") {
      r.allow(e, {"xyz"});
      auto g = r.numbers(e, "xyz", 3);
      if (g.empty()) r.fail(e, "missing attribute 'xyz' (gravity in m/s^2, in the base frame)");
      m->gravity = Eigen::Vector3d(g[0], g[1], g[2]);
    } else if (tag == "transmission") {
      r.allow(e, {"matrix", "offset"});
      if (had_transmission) r.fail(e, "a second <transmission>");
      had_transmission = true;
      auto T = r.numbers(e, "matrix", n * n);
      if (T.empty()) r.fail(e, "missing attribute 'matrix' (row-major, dof x dof)");
      m->transmission =
          Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
              T.data(), n, n);
      if (!Eigen::FullPivLU<Eigen::MatrixXd>(m->transmission).isInvertible()) {
        r.fail(e, "the matrix is singular (not invertible)");
      }
      auto off = r.numbers(e, "offset", e->Attribute("offset") ? n : -1);
      m->transmission_offset =
          off.empty() ? Eigen::VectorXd::Zero(n)
                      : Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(off.data(), n));
    } else if (tag == "sensor") {
      r.allow(e, {"link", "xyz", "rpy"});
      const std::string l = attr(e, "link");
      auto it = link_place.find(l);
      if (it == link_place.end()) r.fail(e, "link '" + l + "': no such link");
      if (it->second.body < 0) r.fail(e, "link '" + l + "' is fixed to the base (no motion)");
      Pose P;
      auto xyz = r.numbers(e, "xyz", e->Attribute("xyz") ? 3 : -1);
      auto rpy = r.numbers(e, "rpy", e->Attribute("rpy") ? 3 : -1);
      if (!xyz.empty()) P.p = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
      if (!rpy.empty()) P.R = detail::rpyToMatrix(rpy[0], rpy[1], rpy[2]);
      m->sensor_body = it->second.body;
      m->sensor_pose = it->second.X * P;
    } else {
      r.fail(e,
             "unknown element (allowed: drive, limit, gravity, transmission, sensor, loop, "
             "actuated, reference)");
    }
  }
  if (!loops.empty() || actuated_el || !reference.empty()) {
    if (loops.empty())
      r.fail(actuated_el ? actuated_el : ext->FirstChildElement("reference"),
             "no <loop> (loop-closure joint): <actuated> and <reference> describe closed chains");
    if (!actuated_el)
      r.fail(ext->FirstChildElement("loop"),
             "a closed chain must name its actuated joints (<actuated joints=\"...\"/>)");
    if (had_transmission)
      r.fail(ext->FirstChildElement("transmission"),
             "a closed chain with a <transmission> is not supported");
    for (const auto& [body, el] : drive_el)
      if (std::find(actuated.begin(), actuated.end(), body) == actuated.end())
        r.fail(el, "joint '" + m->bodies[static_cast<size_t>(body)].joint_name +
                       "' is passive (not in <actuated>): a drive belongs to an actuated joint");
    m->closed.loops = loops;
    m->closed.actuated = actuated;
    if (!reference.empty()) {
      m->closed.reference = Eigen::VectorXd::Zero(n);
      for (const auto& [body, v] : reference) m->closed.reference[body] = v;
    }
    m->closed.tree_limits = m->limits;
    std::vector<JointLimits> lim;
    std::vector<Drive> drv;
    for (int a : actuated) {
      lim.push_back(m->limits[static_cast<size_t>(a)]);
      drv.push_back(m->drives[static_cast<size_t>(a)]);
    }
    m->limits = lim;
    m->drives = drv;
  }
  (void)options;
}

// The bodies, depth first from the root, children in document order (parents get lower
// indices): a movable joint makes a body; a fixed one merges its child link into the owning body.
void buildBodies(const XRobot& x, const urdf::ModelInterface& u0, const std::string& src,
                 const LoadOptions& options, RobotModel* mp, std::map<std::string, int>* jb,
                 std::map<std::string, LinkPlace>* lp, std::vector<std::string>* ignored) {
  const urdf::ModelInterface* u = &u0;
  RobotModel& m = *mp;
  std::map<std::string, int>& joint_body = *jb;
  std::map<std::string, LinkPlace>& link_place = *lp;
  std::vector<std::string>& ignored_dynamics = *ignored;
  struct Item {
    std::string link;
    LinkPlace place;
  };
  std::vector<Item> stack{{x.root, LinkPlace{}}};
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    link_place[it.link] = it.place;
    auto ch = x.children.find(it.link);
    if (ch == x.children.end()) continue;
    std::vector<Item> next;
    for (int k : ch->second) {
      const XJoint& xj = x.joints[static_cast<size_t>(k)];
      const urdf::JointConstSharedPtr j = u->getJoint(xj.name);
      const urdf::LinkConstSharedPtr child = u->getLink(xj.child);
      const std::string jw = src + ":" + std::to_string(xj.line) + ": joint '" + xj.name + "'";
      if (!j || !child) throw Error(jw + ": not found by urdfdom");
      const Pose origin = toPose(j->parent_to_joint_origin_transform);
      if (!finitePose(origin)) throw Error(jw + ": <origin>: non-finite number");
      const Pose X = it.place.X * origin;  // child link frame in the owning body's frame
      const Eigen::Matrix<double, 10, 1> pi = linkInertial(*child, src);
      if (j->type == urdf::Joint::FIXED) {
        // Merged into the owning body (nothing moves between them).
        if (it.place.body >= 0) {
          m.bodies[static_cast<size_t>(it.place.body)].inertia += transformInertial(pi, X);
        } else if (m.floating_base) {
          m.base.inertia += transformInertial(pi, X);  // fixed to the floating base link
        }
        next.push_back({xj.child, LinkPlace{it.place.body, X}});
        continue;
      }
      Body b;
      b.name = xj.child;
      b.joint_name = xj.name;
      b.parent = it.place.body;
      b.pre = X;
      b.type = j->type == urdf::Joint::PRISMATIC ? JointType::Prismatic : JointType::Revolute;
      const Eigen::Vector3d axis(j->axis.x, j->axis.y, j->axis.z);
      if (!axis.allFinite() || axis.norm() < 1e-12) {
        throw Error(jw + ": <axis>: expected a non-zero finite vector");
      }
      b.axis = axis.normalized();
      b.inertia = pi;
      JointLimits lim;
      if (j->limits) {
        const auto& L = *j->limits;
        if (!std::isfinite(L.lower) || !std::isfinite(L.upper) || !std::isfinite(L.effort) ||
            !std::isfinite(L.velocity)) {
          throw Error(jw + ": <limit>: non-finite number");
        }
        if (j->type != urdf::Joint::CONTINUOUS) {
          if (L.lower >= L.upper) throw Error(jw + ": <limit>: lower must be below upper");
          lim.q_min = L.lower;
          lim.q_max = L.upper;
        }
        if (L.velocity > 0) lim.qd_max = L.velocity;
        if (L.effort > 0) lim.tau_max = L.effort;
      }
      Drive drv;
      if (j->dynamics) {
        if (!std::isfinite(j->dynamics->damping) || !std::isfinite(j->dynamics->friction)) {
          throw Error(jw + ": <dynamics>: non-finite number");
        }
        if (options.urdf_dynamics_as_friction) {
          drv.viscous = j->dynamics->damping;
          drv.coulomb = j->dynamics->friction;
        } else if (j->dynamics->damping != 0.0 || j->dynamics->friction != 0.0) {
          ignored_dynamics.push_back(xj.name);
        }
      }
      const int index = m.dof();
      m.bodies.push_back(b);
      m.limits.push_back(lim);
      m.drives.push_back(drv);
      joint_body[xj.name] = index;
      next.push_back({xj.child, LinkPlace{index, Pose{}}});
    }
    // Push in reverse so that the first child in document order is visited first.
    for (auto r = next.rbegin(); r != next.rend(); ++r) stack.push_back(*r);
  }
}

// A companion file's <exid> element (options.urdf_extension), refused beside the URDF's own.
void applyCompanion(const XRobot& x, const std::string& src, const LoadOptions& options,
                    RobotModel* mp, const std::map<std::string, int>& joint_body,
                    const std::map<std::string, LinkPlace>& link_place) {
  RobotModel& m = *mp;
  const std::string esrc = options.urdf_extension.string();
  if (x.exid) {
    throw Error(at(src, x.exid) + ": the URDF has its own <exid> element and a companion " + esrc +
                " is given as well (use one of them)");
  }
  const std::string ext_text =
      detail::readTextFile(options.urdf_extension, "URDF companion (<exid>)");
  checkUtf8(ext_text, esrc);
  TiXmlDocument ext;
  ext.Parse(ext_text.c_str());
  if (ext.Error()) {
    throw Error(esrc + ":" + std::to_string(ext.ErrorRow()) + ": invalid XML: " + ext.ErrorDesc());
  }
  const TiXmlElement* root = ext.RootElement();
  if (!root || std::string(root->Value()) != "exid") {
    throw Error(at(esrc, root) + ": the root element of a URDF companion must be <exid>, found " +
                (root ? "<" + std::string(root->Value()) + ">" : std::string("no element")));
  }
  if (root->NextSiblingElement()) {
    throw Error(at(esrc, root->NextSiblingElement()) +
                ": a second root element (one <exid> is allowed)");
  }
  applyExtension(root, esrc, &m, joint_body, link_place, options);
}

// <collision> elements of every link, attached to the body the link is merged into (the base
// for links fixed to it). Mesh file names relative to the URDF's folder; package:// URIs are kept
// as given and refused only when a study asks for collision avoidance.
void readCollisions(const urdf::ModelInterface& u, const std::string& src,
                    const std::map<std::string, LinkPlace>& link_place, RobotModel* m) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(src).parent_path();
  for (const auto& [name, place] : link_place) {
    const urdf::LinkConstSharedPtr link = u.getLink(name);
    if (!link) continue;
    int k = 0;
    for (const auto& c : link->collision_array) {
      const std::string where = fmt::format("{}: link '{}' <collision> {}", src, name, ++k);
      if (!c || !c->geometry) continue;
      CollisionShape s;
      s.body = place.body;
      s.where = where;
      const Pose origin = toPose(c->origin);
      if (!finitePose(origin)) throw Error(where + ": <origin>: non-finite number");
      s.pose = place.X * origin;
      const urdf::Geometry& g = *c->geometry;
      switch (g.type) {
        case urdf::Geometry::SPHERE:
          s.kind = CollisionShape::Kind::Sphere;
          s.radius = static_cast<const urdf::Sphere&>(g).radius;
          break;
        case urdf::Geometry::BOX: {
          const auto& b = static_cast<const urdf::Box&>(g);
          s.kind = CollisionShape::Kind::Box;
          s.size = Eigen::Vector3d(b.dim.x, b.dim.y, b.dim.z);
          break;
        }
        case urdf::Geometry::CYLINDER: {
          const auto& y = static_cast<const urdf::Cylinder&>(g);
          s.kind = CollisionShape::Kind::Cylinder;
          s.radius = y.radius;
          s.length = y.length;
          break;
        }
        case urdf::Geometry::MESH: {
          const auto& h = static_cast<const urdf::Mesh&>(g);
          s.kind = CollisionShape::Kind::Mesh;
          s.mesh_file = h.filename;
          if (fs::path(h.filename).is_relative() && h.filename.find("://") == std::string::npos)
            s.mesh_file = (dir / h.filename).string();
          s.mesh_scale = Eigen::Vector3d(h.scale.x, h.scale.y, h.scale.z);
          break;
        }
        default:
          throw Error(where + ": unknown geometry");
      }
      m->collision.push_back(s);
    }
  }
}

}  // namespace

RobotModel loadUrdfString(const std::string& xml, const std::string& src,
                          const LoadOptions& options) {
  checkUtf8(xml, src);
  TiXmlDocument doc;
  doc.Parse(xml.c_str());
  if (doc.Error()) {
    throw Error(src + ":" + std::to_string(doc.ErrorRow()) + ": invalid XML: " + doc.ErrorDesc());
  }
  const XRobot x = readStructure(doc, src);
  const urdf::ModelInterfaceSharedPtr u = parseWithUrdfdom(xml, src);

  RobotModel m;
  m.name = x.name.empty() ? "robot" : x.name;
  m.source = src;
  std::map<std::string, int> joint_body;
  std::map<std::string, LinkPlace> link_place;
  std::vector<std::string> ignored_dynamics;  // joints whose <dynamics> were not used

  if (!x.floating_joint.empty()) {
    const urdf::LinkConstSharedPtr world = u->getLink(x.world);
    if (world && world->inertial && world->inertial->mass != 0.0)
      throw Error(src + ": link '" + world->name + "': the world link of floating joint '" +
                  x.floating_joint +
                  "' has a mass (expected none: the world does not move with the robot)");
    const urdf::LinkConstSharedPtr base = u->getLink(x.root);
    if (!base) throw Error(src + ": base link '" + x.root + "' not found by urdfdom");
    m.floating_base = true;
    m.base.link = x.root;
    m.base.joint_name = x.floating_joint;
    m.base.inertia = linkInertial(*base, src);
  }
  buildBodies(x, *u, src, options, &m, &joint_body, &link_place, &ignored_dynamics);
  if (m.dof() == 0) {
    throw Error(src + ": no movable joint (revolute, continuous or prismatic) in the robot");
  }
  readCollisions(*u, src, link_place, &m);
  if (x.exid) applyExtension(x.exid, src, &m, joint_body, link_place, options);
  if (!options.urdf_extension.empty()) applyCompanion(x, src, options, &m, joint_body, link_place);
  try {
    m.validateStructure();
  } catch (const Error& e) {
    throw Error(src + ": " + e.what());
  }
  checkModelPhysical(m, options);
  if (!ignored_dynamics.empty())
    m.notes.push_back(fmt::format(
        "{}: <dynamics damping friction> of joint(s) {} not used as nominal friction (they are "
        "usually a simulator's values, not identified ones); the urdf robot's "
        "dynamics_as_friction: true uses them",
        src, fmt::join(ignored_dynamics, ", ")));
  return m;
}

RobotModel loadUrdf(const std::filesystem::path& file, const LoadOptions& options) {
  return loadUrdfString(detail::readTextFile(file, "URDF"), file.string(), options);
}

}  // namespace exid
