// exid — DH / modified DH YAML robot descriptions. Format: docs/robots.md.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "exid/collision_yaml.hpp"
#include "exid/dh.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/yaml_strict.hpp"
#include "read_text.hpp"

namespace exid {
namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr double kInf = 1e300;

/// Reads one YAML document, turning every problem into an exid::Error that names the source,
/// the line, the key path and the rule.
class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}
  const std::string& source() const { return source_; }

  [[noreturn]] void fail(const YAML::Node& at, const std::string& where,
                         const std::string& rule) const {
    std::string msg = source_;
    if (at.IsDefined() && at.Mark().line >= 0) msg += ":" + std::to_string(at.Mark().line + 1);
    msg += ": ";
    if (!where.empty()) msg += where + ": ";
    throw Error(msg + rule);
  }

  static std::string describe(const YAML::Node& n) {
    if (!n.IsDefined() || n.IsNull()) return "nothing";
    if (n.IsScalar()) return "'" + n.Scalar() + "'";
    if (n.IsSequence()) return "a list";
    return "a map";
  }

  /// Map with only the allowed keys (each once).
  void requireMap(const YAML::Node& n, const std::string& where,
                  const std::set<std::string>& allowed) const {
    if (!n.IsMap()) fail(n, where, "expected a map, found " + describe(n));
    std::set<std::string> seen;
    for (const auto& kv : n) {
      if (!kv.first.IsScalar()) fail(kv.first, where, "keys must be plain names");
      const std::string key = kv.first.Scalar();
      if (!allowed.count(key)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        fail(kv.first, where, "unknown key '" + key + "' (allowed: " + list + ")");
      }
      if (!seen.insert(key).second) fail(kv.first, where, "duplicate key '" + key + "'");
    }
  }

  double number(const YAML::Node& n, const std::string& where) const {
    if (!n.IsScalar()) fail(n, where, "expected a number, found " + describe(n));
    double v = 0.0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, where, "expected a number, found " + describe(n));
    }
    if (!std::isfinite(v)) fail(n, where, "expected a finite number, found " + describe(n));
    return v;
  }

  std::string text(const YAML::Node& n, const std::string& where) const {
    if (!n.IsScalar()) fail(n, where, "expected a text, found " + describe(n));
    return n.Scalar();
  }

  Eigen::VectorXd vector(const YAML::Node& n, const std::string& where, int size) const {
    if (!n.IsSequence()) fail(n, where, "expected a list of numbers, found " + describe(n));
    if (size >= 0 && static_cast<int>(n.size()) != size) {
      fail(n, where,
           "expected " + std::to_string(size) + " numbers, found " + std::to_string(n.size()));
    }
    Eigen::VectorXd v(static_cast<Eigen::Index>(n.size()));
    for (size_t i = 0; i < n.size(); ++i) {
      v(static_cast<Eigen::Index>(i)) = number(n[i], where + "[" + std::to_string(i) + "]");
    }
    return v;
  }

  /// Value of `key` in radians (or metres): either `key` or `key_deg` (degrees, revolute only).
  bool angle(const YAML::Node& map, const std::string& key, const std::string& where,
             bool degrees_allowed, double* out) const {
    const YAML::Node plain = map[key];
    const YAML::Node deg = map[key + "_deg"];
    if (plain && deg) {
      fail(deg, where, "give either '" + key + "' or '" + key + "_deg', not both");
    }
    if (plain) {
      *out = number(plain, where + "." + key);
      return true;
    }
    if (deg) {
      if (!degrees_allowed) {
        fail(deg, where,
             "'" + key + "_deg' is for revolute joints (a prismatic joint's " +
                 "coordinate is a length in m)");
      }
      *out = number(deg, where + "." + key + "_deg") * kDeg;
      return true;
    }
    return false;
  }

 private:
  std::string source_;
};

Eigen::Matrix3d readInertia(const Reader& r, const YAML::Node& n, const std::string& where) {
  r.requireMap(n, where, {"xx", "xy", "xz", "yy", "yz", "zz"});
  auto get = [&](const char* k) { return n[k] ? r.number(n[k], where + "." + k) : 0.0; };
  for (const char* k : {"xx", "yy", "zz"}) {
    if (!n[k]) r.fail(n, where, std::string("missing key '") + k + "'");
  }
  // Read every value before the comma initialiser: a throw inside `I << a, b, ...` unwinds
  // through Eigen's CommaInitializer destructor, which asserts (aborts) on too few coefficients
  // (found by tests/fuzz/fuzz_dh).
  const double xx = get("xx"), xy = get("xy"), xz = get("xz"), yy = get("yy"), yz = get("yz"),
               zz = get("zz");
  Eigen::Matrix3d I;
  I << xx, xy, xz, xy, yy, yz, xz, yz, zz;
  return I;
}

Pose readPose(const Reader& r, const YAML::Node& n, const std::string& where) {
  Pose P;
  if (n["xyz"]) P.p = r.vector(n["xyz"], where + ".xyz", 3);
  if (n["rpy"] && n["rpy_deg"]) r.fail(n, where, "give either 'rpy' or 'rpy_deg', not both");
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
  if (n["rpy"]) rpy = r.vector(n["rpy"], where + ".rpy", 3);
  if (n["rpy_deg"]) rpy = r.vector(n["rpy_deg"], where + ".rpy_deg", 3) * kDeg;
  P.R = detail::rpyToMatrix(rpy(0), rpy(1), rpy(2));
  return P;
}

struct LinkInfo {
  int line = 0;
};

void readInertial(const Reader& r, const YAML::Node& L, const std::string& lw, Body* body) {
  Body& b = *body;
  const double mass = L["mass"] ? r.number(L["mass"], lw + ".mass") : 0.0;
  const Eigen::Vector3d com =
      L["com"] ? Eigen::Vector3d(r.vector(L["com"], lw + ".com", 3)) : Eigen::Vector3d::Zero();
  if (L["inertia_com"] && L["inertia_origin"]) {
    r.fail(L["inertia_origin"], lw,
           "give either 'inertia_com' (about the centre of mass) or 'inertia_origin' (about "
           "the link frame origin), not both");
  }
  if (L["inertia_origin"]) {
    const Eigen::Matrix3d I = readInertia(r, L["inertia_origin"], lw + ".inertia_origin");
    b.inertia << I(0, 0), I(0, 1), I(0, 2), I(1, 1), I(1, 2), I(2, 2), mass * com.x(),
        mass * com.y(), mass * com.z(), mass;
  } else {
    const Eigen::Matrix3d I = L["inertia_com"]
                                  ? readInertia(r, L["inertia_com"], lw + ".inertia_com")
                                  : Eigen::Matrix3d::Zero().eval();
    b.inertia = inertialFromCom(mass, com, I);
  }
}

JointLimits readLimits(const Reader& r, const YAML::Node& L, const std::string& lw, bool revolute) {
  JointLimits lim;
  if (const YAML::Node Y = L["limits"]) {
    const std::string w = lw + ".limits";
    r.requireMap(Y, w,
                 {"q_min", "q_max", "q_min_deg", "q_max_deg", "qd_max", "qd_max_deg", "qdd_max",
                  "qdd_max_deg", "tau_max"});
    r.angle(Y, "q_min", w, revolute, &lim.q_min);
    r.angle(Y, "q_max", w, revolute, &lim.q_max);
    r.angle(Y, "qd_max", w, revolute, &lim.qd_max);
    r.angle(Y, "qdd_max", w, revolute, &lim.qdd_max);
    if (Y["tau_max"]) lim.tau_max = r.number(Y["tau_max"], w + ".tau_max");
    if (lim.q_min >= lim.q_max) r.fail(Y, w, "q_min must be below q_max");
    if (lim.qd_max <= 0 || lim.qdd_max <= 0 || lim.tau_max <= 0) {
      r.fail(Y, w, "qd_max, qdd_max and tau_max must be positive");
    }
  }
  return lim;
}

Drive readDrive(const Reader& r, const YAML::Node& L, const std::string& lw,
                const LoadOptions& options) {
  Drive drv;
  if (const YAML::Node D = L["drive"]) {
    const std::string w = lw + ".drive";
    r.requireMap(D, w,
                 {"gear_ratio", "motor_inertia", "rotor_inertia", "coulomb", "viscous", "offset"});
    if (D["gear_ratio"]) drv.gear_ratio = r.number(D["gear_ratio"], w + ".gear_ratio");
    if (drv.gear_ratio == 0.0) r.fail(D["gear_ratio"], w, "gear_ratio must not be zero");
    if (D["motor_inertia"] && D["rotor_inertia"]) {
      r.fail(D, w,
             "give either 'motor_inertia' (motor side Jm, reflected as Jm*G^2) or "
             "'rotor_inertia' (already reflected to the joint), not both");
    }
    if (D["motor_inertia"]) {
      drv.rotor_inertia =
          r.number(D["motor_inertia"], w + ".motor_inertia") * drv.gear_ratio * drv.gear_ratio;
    }
    if (D["rotor_inertia"]) drv.rotor_inertia = r.number(D["rotor_inertia"], w + ".rotor_inertia");
    if (D["coulomb"]) drv.coulomb = r.number(D["coulomb"], w + ".coulomb");
    if (D["viscous"]) drv.viscous = r.number(D["viscous"], w + ".viscous");
    if (D["offset"]) drv.offset = r.number(D["offset"], w + ".offset");
    if (drv.rotor_inertia < 0 || drv.coulomb < 0 || drv.viscous < 0) {
      // Published identified models contain such values (Panda fv6): always a warning.
      reportWarning(options, r.source() + ":" + std::to_string(D.Mark().line + 1) + ": " + w +
                                 ": negative rotor inertia or friction coefficient");
    }
  }
  return drv;
}

// Transmission between measured and joint coordinates.
void readTransmission(const Reader& r, const YAML::Node& T, RobotModel* m) {
  RobotModel& model = *m;
  const int n = model.dof();
  const std::string w = "transmission";
  r.requireMap(T, w,
               {"matrix", "offset", "q_min_measured", "q_max_measured", "q_min_measured_deg",
                "q_max_measured_deg", "notes"});
  if (!T["matrix"]) r.fail(T, w, "missing key 'matrix' (q = matrix * q_measured + offset)");
  const YAML::Node M = T["matrix"];
  if (!M.IsSequence() || static_cast<int>(M.size()) != n) {
    r.fail(M, w + ".matrix",
           "expected " + std::to_string(n) + " rows (one per link), found " +
               (M.IsSequence() ? std::to_string(M.size()) : Reader::describe(M)));
  }
  model.transmission.resize(n, n);
  for (int i = 0; i < n; ++i) {
    model.transmission.row(i) =
        r.vector(M[static_cast<size_t>(i)], w + ".matrix[" + std::to_string(i) + "]", n)
            .transpose();
  }
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(model.transmission);
  if (!lu.isInvertible()) r.fail(M, w + ".matrix", "the matrix is singular (not invertible)");
  model.transmission_offset =
      T["offset"] ? r.vector(T["offset"], w + ".offset", n) : Eigen::VectorXd::Zero(n);
  // Limits of the measured coordinates -> interval hull in joint coordinates.
  auto measured = [&](const char* key, double fallback, Eigen::VectorXd* out) {
    const std::string k = key, kd = k + "_deg";
    if (T[k] && T[kd]) r.fail(T[kd], w, "give either '" + k + "' or '" + kd + "', not both");
    if (T[k]) {
      *out = r.vector(T[k], w + "." + k, n);
    } else if (T[kd]) {
      *out = r.vector(T[kd], w + "." + kd, n) * kDeg;
      for (int i = 0; i < n; ++i) {
        if (model.bodies[static_cast<size_t>(i)].type == JointType::Prismatic) {
          r.fail(T[kd], w + "." + kd, "degrees given for prismatic joint " + std::to_string(i + 1));
        }
      }
    } else {
      *out = Eigen::VectorXd::Constant(n, fallback);
      return false;
    }
    return true;
  };
  Eigen::VectorXd lo, hi;
  const bool has_lo = measured("q_min_measured", -kInf, &lo);
  const bool has_hi = measured("q_max_measured", kInf, &hi);
  if (has_lo || has_hi) {
    if ((lo.array() >= hi.array()).any()) {
      r.fail(T, w, "q_min_measured must be below q_max_measured");
    }
    Eigen::VectorXd qlo, qhi;
    detail::transmissionHull(model.transmission, model.transmission_offset, lo, hi, &qlo, &qhi);
    for (int i = 0; i < n; ++i) {
      auto& L = model.limits[static_cast<size_t>(i)];
      L.q_min = std::max(L.q_min, std::max(qlo(i), -kInf));
      L.q_max = std::min(L.q_max, std::min(qhi(i), kInf));
      if (L.q_min >= L.q_max) {
        r.fail(T, w,
               "joint " + std::to_string(i + 1) +
                   ": the link's limits and the measured limits do not overlap");
      }
    }
  }
}

// Wrist sensor frame.
void readSensor(const Reader& r, const YAML::Node& S, const std::map<std::string, int>& link_index,
                RobotModel* m) {
  RobotModel& model = *m;
  const int n = model.dof();
  r.requireMap(S, "sensor", {"link", "xyz", "rpy", "rpy_deg", "notes"});
  if (S["link"]) {
    const std::string l = r.text(S["link"], "sensor.link");
    auto it = link_index.find(l);
    if (it != link_index.end()) {
      model.sensor_body = it->second;
    } else {
      int k = 0;
      try {
        k = S["link"].as<int>();
      } catch (const YAML::Exception&) {
        r.fail(S["link"], "sensor.link",
               "unknown link '" + l + "' (a link name or 1.." + std::to_string(n) + ")");
      }
      if (k < 1 || k > n) {
        r.fail(S["link"], "sensor.link",
               "link number " + l + " is out of range 1.." + std::to_string(n));
      }
      model.sensor_body = k - 1;
    }
  }
  model.sensor_pose = readPose(r, S, "sensor");
}

// Collision geometry of a link (body >= 0) or of the base (-1): a list of shapes
// (exid::parseCollisionShape).
void readCollision(const Reader& r, const YAML::Node& C, const std::string& where, int body,
                   RobotModel* model) {
  if (!C) return;
  if (!C.IsSequence()) r.fail(C, where, "expected a list of shapes, found " + Reader::describe(C));
  for (std::size_t k = 0; k < C.size(); ++k) {
    CollisionShape s = parseCollisionShape(C[k], r.source(), where + "[" + std::to_string(k) + "]");
    s.body = body;
    model->collision.push_back(s);
  }
}

// The DH row of a link: joint type, a, d, alpha, theta.
DhRow readDhRow(const Reader& r, const YAML::Node& L, const std::string& lw) {
  DhRow row;
  std::string type = L["type"] ? r.text(L["type"], lw + ".type") : "revolute";
  if (type == "revolute") {
    row.type = JointType::Revolute;
  } else if (type == "prismatic") {
    row.type = JointType::Prismatic;
  } else {
    r.fail(L["type"], lw + ".type", "expected 'revolute' or 'prismatic', found '" + type + "'");
  }
  if (L["a"]) row.a = r.number(L["a"], lw + ".a");
  if (L["d"]) row.d = r.number(L["d"], lw + ".d");
  r.angle(L, "alpha", lw, true, &row.alpha);
  r.angle(L, "theta", lw, true, &row.theta);
  return row;
}

// The parent body of link i: the previous link, `base` (-1) or a link listed before it.
int readParent(const Reader& r, const YAML::Node& L, const std::string& lw, int i,
               const std::map<std::string, int>& link_index) {
  int parent = i - 1;
  if (L["parent"]) {
    const std::string p = r.text(L["parent"], lw + ".parent");
    if (p == "base") {
      parent = -1;
    } else {
      auto it = link_index.find(p);
      if (it == link_index.end()) {
        r.fail(L["parent"], lw + ".parent",
               "unknown link '" + p + "' (a parent must be listed before its children, or " +
                   "be 'base')");
      }
      parent = it->second;
    }
  }
  return parent;
}

// Closed kinematic chains (docs/robots.md, "Closed chains"): the loop-closure (cut) joints, the
// actuated joints and the reference configuration. Limits and drives become per actuated joint
// (the passive joints' limits are kept as the tree's).
void readClosedChain(const Reader& r, const YAML::Node& C, const YAML::Node& links,
                     const std::map<std::string, int>& link_index, RobotModel* model) {
  const std::string w = "closed_chain";
  r.requireMap(C, w, {"loops", "actuated", "reference", "reference_deg", "notes"});
  if (!C["loops"] || !C["loops"].IsSequence() || C["loops"].size() == 0)
    r.fail(C, w, "missing or empty 'loops' (the list of loop-closure joints)");
  if (!C["actuated"] || !C["actuated"].IsSequence() || C["actuated"].size() == 0)
    r.fail(C, w, "missing or empty 'actuated' (the names of the actuated joints)");
  const int n = model->numJoints();
  auto linkOf = [&](const YAML::Node& v, const std::string& where) {
    const std::string l = r.text(v, where);
    if (l == "base") return -1;
    auto it = link_index.find(l);
    if (it == link_index.end())
      r.fail(v, where, "unknown link '" + l + "' (expected a link of 'links' or 'base')");
    return it->second;
  };
  const YAML::Node L = C["loops"];
  for (std::size_t k = 0; k < L.size(); ++k) {
    const YAML::Node J = L[k];
    const std::string lw = w + ".loops[" + std::to_string(k) + "]";
    r.requireMap(J, lw, {"name", "type", "link_a", "link_b", "pose_a", "pose_b", "axis", "notes"});
    LoopJoint lj;
    lj.name = J["name"] ? r.text(J["name"], lw + ".name") : "loop" + std::to_string(k + 1);
    lj.where = r.source() + ":" + std::to_string(J.Mark().line + 1) + " (" + lw + ")";
    const std::string type = J["type"] ? r.text(J["type"], lw + ".type") : "revolute";
    if (type == "revolute")
      lj.kind = LoopJoint::Kind::Revolute;
    else if (type == "spherical")
      lj.kind = LoopJoint::Kind::Spherical;
    else
      r.fail(J["type"], lw + ".type", "expected 'revolute' or 'spherical', found '" + type + "'");
    if (!J["link_a"] || !J["link_b"])
      r.fail(J, lw, "missing 'link_a' or 'link_b' (the two links the loop-closure joint joins)");
    lj.body_a = linkOf(J["link_a"], lw + ".link_a");
    lj.body_b = linkOf(J["link_b"], lw + ".link_b");
    if (lj.body_a == lj.body_b) r.fail(J, lw, "link_a and link_b are the same link");
    for (const char* side : {"pose_a", "pose_b"})
      if (const YAML::Node P = J[side]) {
        r.requireMap(P, lw + "." + side, {"xyz", "rpy", "rpy_deg"});
        (std::string(side) == "pose_a" ? lj.pose_a : lj.pose_b) = readPose(r, P, lw + "." + side);
      }
    if (J["axis"]) {
      const Eigen::Vector3d a = r.vector(J["axis"], lw + ".axis", 3);
      if (!(a.norm() > 1e-12)) r.fail(J["axis"], lw + ".axis", "axis must not be zero");
      lj.axis = a.normalized();
    }
    model->closed.loops.push_back(lj);
  }
  std::map<std::string, int> joint_index;
  for (int i = 0; i < n; ++i)
    joint_index[model->bodies[static_cast<std::size_t>(i)].joint_name] = i;
  const YAML::Node A = C["actuated"];
  for (std::size_t k = 0; k < A.size(); ++k) {
    const std::string aw = w + ".actuated[" + std::to_string(k) + "]";
    const std::string j = r.text(A[k], aw);
    auto it = joint_index.find(j);
    if (it == joint_index.end()) r.fail(A[k], aw, "unknown joint '" + j + "'");
    for (int a : model->closed.actuated)
      if (a == it->second) r.fail(A[k], aw, "joint '" + j + "' named twice");
    model->closed.actuated.push_back(it->second);
  }
  if (C["reference"] && C["reference_deg"])
    r.fail(C, w, "give either 'reference' or 'reference_deg', not both");
  if (C["reference"]) model->closed.reference = r.vector(C["reference"], w + ".reference", n);
  if (C["reference_deg"]) {
    model->closed.reference = r.vector(C["reference_deg"], w + ".reference_deg", n);
    for (int i = 0; i < n; ++i)  // degrees for revolute joints, metres for prismatic ones
      if (model->bodies[static_cast<std::size_t>(i)].type == JointType::Revolute)
        model->closed.reference[i] *= kDeg;
  }
  // limits and drives per actuated joint; a drive on a passive joint is refused
  model->closed.tree_limits = model->limits;
  std::vector<JointLimits> lim;
  std::vector<Drive> drv;
  for (int a : model->closed.actuated) {
    lim.push_back(model->limits[static_cast<std::size_t>(a)]);
    drv.push_back(model->drives[static_cast<std::size_t>(a)]);
  }
  for (int i = 0; i < n; ++i) {
    const YAML::Node Li = links[static_cast<std::size_t>(i)];
    if (Li["drive"] && std::find(model->closed.actuated.begin(), model->closed.actuated.end(), i) ==
                           model->closed.actuated.end())
      r.fail(Li["drive"], "links[" + std::to_string(i) + "].drive",
             "joint '" + model->bodies[static_cast<std::size_t>(i)].joint_name +
                 "' is passive (not in closed_chain.actuated): a drive belongs to an actuated "
                 "joint");
  }
  model->limits = lim;
  model->drives = drv;
}

RobotModel parseDh(const YAML::Node& root, const Reader& r, const LoadOptions& options) {
  if (!root.IsDefined() || root.IsNull()) r.fail(root, "", "empty document");
  r.requireMap(
      root, "top level",
      {"name", "description", "source", "sources", "notes", "convention", "gravity", "links",
       "transmission", "sensor", "base_collision", "closed_chain", "floating_base"});

  RobotModel model;
  model.source = r.source();
  model.name = root["name"] ? r.text(root["name"], "name") : "robot";

  if (!root["convention"]) {
    r.fail(root, "top level", "missing key 'convention' (standard or modified)");
  }
  const std::string conv_text = r.text(root["convention"], "convention");
  DhConvention conv;
  if (conv_text == "standard") {
    conv = DhConvention::Standard;
  } else if (conv_text == "modified") {
    conv = DhConvention::Modified;
  } else {
    r.fail(root["convention"], "convention",
           "expected 'standard' or 'modified', found '" + conv_text + "'");
  }

  if (root["gravity"]) model.gravity = r.vector(root["gravity"], "gravity", 3);

  const YAML::Node links = root["links"];
  if (!links) r.fail(root, "top level", "missing key 'links' (the list of links, base first)");
  if (!links.IsSequence() || links.size() == 0) {
    r.fail(links, "links", "expected a non-empty list of links, found " + Reader::describe(links));
  }

  std::map<std::string, int> link_index;
  std::map<std::string, int> joint_line;
  std::map<std::string, int> link_line;
  const int n = static_cast<int>(links.size());
  for (int i = 0; i < n; ++i) {
    const YAML::Node L = links[static_cast<size_t>(i)];
    const std::string where = "links[" + std::to_string(i) + "]";
    r.requireMap(
        L, where,
        {"name", "joint", "type", "parent", "a", "alpha", "alpha_deg", "d", "theta", "theta_deg",
         "mass", "com", "inertia_com", "inertia_origin", "limits", "drive", "collision", "notes"});
    const int line = L.Mark().line + 1;
    const std::string name =
        L["name"] ? r.text(L["name"], where + ".name") : "link" + std::to_string(i + 1);
    const std::string joint_name =
        L["joint"] ? r.text(L["joint"], where + ".joint") : "joint" + std::to_string(i + 1);
    const std::string lw = where + " (link '" + name + "')";

    const DhRow row = readDhRow(r, L, lw);
    const bool revolute = row.type == JointType::Revolute;
    const int parent = readParent(r, L, lw, i, link_index);

    Body b = dhBody(row, conv, parent);
    b.name = name;
    b.joint_name = joint_name;
    if (link_line.count(b.name)) {
      r.fail(L, where,
             "duplicate link name '" + b.name + "' (first at line " +
                 std::to_string(link_line[b.name]) + ")");
    }
    if (joint_line.count(b.joint_name)) {
      r.fail(L, where,
             "duplicate joint name '" + b.joint_name + "' (first at line " +
                 std::to_string(joint_line[b.joint_name]) + ")");
    }
    link_line[b.name] = line;
    joint_line[b.joint_name] = line;
    link_index[b.name] = i;

    readInertial(r, L, lw, &b);

    const JointLimits lim = readLimits(r, L, lw, revolute);
    const Drive drv = readDrive(r, L, lw, options);
    readCollision(r, L["collision"], lw + ".collision", i, &model);

    model.bodies.push_back(b);
    model.limits.push_back(lim);
    model.drives.push_back(drv);
  }

  if (const YAML::Node T = root["transmission"]) readTransmission(r, T, &model);
  if (const YAML::Node C = root["closed_chain"]) {
    if (root["transmission"])
      r.fail(C, "closed_chain",
             "a closed chain with a 'transmission' is not supported (give one or the other)");
    readClosedChain(r, C, links, link_index, &model);
  }

  if (const YAML::Node S = root["sensor"]) readSensor(r, S, link_index, &model);
  readCollision(r, root["base_collision"], "base_collision", -1, &model);
  if (const YAML::Node F = root["floating_base"]) {
    // the base link moves freely: its name and inertial parameters (as a link's)
    r.requireMap(F, "floating_base", {"link", "mass", "com", "inertia_com", "inertia_origin"});
    Body base;
    readInertial(r, F, "floating_base", &base);
    model.floating_base = true;
    model.base.link = F["link"] ? r.text(F["link"], "floating_base.link") : "base";
    model.base.inertia = base.inertia;
    if (!model.collision.empty())
      r.fail(F, "floating_base",
             "collision geometry is for fixed-base robots (collision-free excitation design); "
             "a floating-base robot gives none");
  }

  try {
    model.validateStructure();
  } catch (const Error& e) {
    throw Error(r.source() + ": " + e.what());
  }
  checkModelPhysical(model, options);
  return model;
}

}  // namespace

RobotModel loadDhYamlString(const std::string& text, const std::string& source,
                            const LoadOptions& options) {
  const Reader r(source);
  checkYamlAliases(text, source);  // before any node is built
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    std::string msg = source;
    if (e.mark.line >= 0) msg += ":" + std::to_string(e.mark.line + 1);
    throw Error(msg + ": invalid YAML: " + e.msg);
  }
  std::vector<std::string> dups;
  duplicateKeys(root, source, "", &dups);
  if (!dups.empty()) {
    std::string msg = dups[0];
    for (std::size_t i = 1; i < dups.size() && i < 20; ++i) msg += "\n" + dups[i];
    throw Error(msg);
  }
  try {
    return parseDh(root, r, options);
  } catch (const YAML::Exception& e) {  // anything not caught above, with its line
    std::string msg = source;
    if (e.mark.line >= 0) msg += ":" + std::to_string(e.mark.line + 1);
    throw Error(msg + ": " + e.msg);
  }
}

RobotModel loadDhYaml(const std::filesystem::path& file, const LoadOptions& options) {
  return loadDhYamlString(detail::readTextFile(file, "DH YAML"), file.string(), options);
}

}  // namespace exid
