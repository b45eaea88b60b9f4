#include "exid/collision.hpp"

#include <fcl/fcl.h>
#include <fmt/format.h>

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include "exid/collision_yaml.hpp"  // kMaxGeometryCoordinate_m
#include "exid/error.hpp"
#include "exid/fmath.hpp"
#include "exid/input_file.hpp"

namespace exid {

namespace {

namespace fs = std::filesystem;

// The largest distance two shapes within the coordinates' bound can have, with a robot of
// any sensible reach: beyond it a distance is an overflow, not a margin.
constexpr double kMaxDistance_m = 1e3 * kMaxGeometryCoordinate_m;

// ---------------------------------------------------------------- STL meshes
struct Mesh {
  std::vector<fcl::Vector3d> vertices;
  std::vector<fcl::Triangle> triangles;
};

// Binary STL: 80-byte header, uint32 count, then 50 bytes a triangle (normal, 3 vertices as
// float32, uint16 attribute). ASCII STL: "solid" ... "vertex x y z" ... "endsolid". A file that
// starts with "solid" but whose size is exactly that of a binary file of its count is binary
// (some exporters write "solid" into the binary header).
Mesh readStl(const fs::path& file, const Eigen::Vector3d& scale, const std::string& who) {
  // Through the input-file checks: a FIFO (it blocked forever), a directory (exit 3) or a device
  // (/dev/zero read until memory ran out) is refused before it is read; at most
  // kMaxMeshFileBytes.
  std::string bytes;
  try {
    bytes = readInputFile(file, "mesh", kMaxMeshFileBytes);
  } catch (const Error& e) {
    throw Error(fmt::format("{}: {}", who, e.what()));
  }
  Mesh m;
  auto add = [&](const std::array<Eigen::Vector3d, 3>& v) {
    const int base = static_cast<int>(m.vertices.size());
    for (const auto& p : v) {
      check(p.allFinite(), fmt::format("{}: mesh {}: a vertex is not finite", who, file.string()));
      const Eigen::Vector3d x = p.cwiseProduct(scale);
      check(x.cwiseAbs().maxCoeff() <= kMaxGeometryCoordinate_m,
            fmt::format("{}: mesh {}: vertex {} of triangle {} is ({:g}, {:g}, {:g}) m after the "
                        "scale, beyond the bound of {:g} m on geometry coordinates",
                        who, file.string(), &p - v.data() + 1, m.triangles.size() + 1, x(0), x(1),
                        x(2), kMaxGeometryCoordinate_m));
      m.vertices.push_back(x);
    }
    m.triangles.emplace_back(base, base + 1, base + 2);
  };
  bool binary = bytes.size() >= 84;
  std::uint32_t count = 0;
  if (binary) {
    std::memcpy(&count, bytes.data() + 80, 4);
    binary = bytes.size() == 84 + 50ull * count;
  }
  if (binary) {
    for (std::uint32_t t = 0; t < count; ++t) {
      const char* p = bytes.data() + 84 + 50ull * t + 12;
      std::array<Eigen::Vector3d, 3> v;
      for (int i = 0; i < 3; ++i) {
        float xyz[3];
        std::memcpy(xyz, p + 12 * i, 12);
        v[static_cast<std::size_t>(i)] = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
      }
      add(v);
    }
  } else {
    check(bytes.compare(0, 5, "solid") == 0,
          fmt::format("{}: mesh {}: not an STL file (neither binary, whose size is 84 + 50 bytes "
                      "a triangle, nor ASCII, starting with 'solid'); exid reads STL meshes",
                      who, file.string()));
    std::istringstream ss(bytes);
    std::string tok;
    std::array<Eigen::Vector3d, 3> v;
    int nv = 0;
    long line_vertices = 0;
    while (ss >> tok) {
      if (tok != "vertex") continue;
      double x = 0, y = 0, z = 0;
      check(static_cast<bool>(ss >> x >> y >> z),
            fmt::format("{}: mesh {}: vertex {}: expected three numbers", who, file.string(),
                        line_vertices + 1));
      ++line_vertices;
      v[static_cast<std::size_t>(nv++)] = Eigen::Vector3d(x, y, z);
      if (nv == 3) {
        add(v);
        nv = 0;
      }
    }
    check(nv == 0, fmt::format("{}: mesh {}: {} vertices, not a multiple of 3 (one facet has "
                               "three)",
                               who, file.string(), line_vertices));
  }
  check(!m.triangles.empty(),
        fmt::format("{}: mesh {}: no triangle in the file", who, file.string()));
  return m;
}

// ---------------------------------------------------------------- shapes
std::string describe(const CollisionShape& s) {
  switch (s.kind) {
    case CollisionShape::Kind::Sphere:
      return fmt::format("sphere r={:g} m", s.radius);
    case CollisionShape::Kind::Capsule:
      return fmt::format("capsule r={:g} m, length {:g} m", s.radius, s.length);
    case CollisionShape::Kind::Cylinder:
      return fmt::format("cylinder r={:g} m, length {:g} m", s.radius, s.length);
    case CollisionShape::Kind::Box:
      return fmt::format("box {:g} x {:g} x {:g} m", s.size(0), s.size(1), s.size(2));
    case CollisionShape::Kind::Mesh:
      return fmt::format("mesh {}", s.mesh_file);
  }
  return "shape";
}

std::shared_ptr<fcl::CollisionGeometryd> makeGeometry(const CollisionShape& s,
                                                      const std::string& mesh_dir,
                                                      const std::string& who) {
  auto positive = [&](double v, const char* what) {
    check(std::isfinite(v) && v > 0,
          fmt::format("{}: {}: {} must be a positive finite length [m], found {}", who, describe(s),
                      what, v));
    check(v <= kMaxGeometryCoordinate_m,
          fmt::format("{}: {}: {} {:g} m is beyond the bound of {:g} m on geometry coordinates",
                      who, describe(s), what, v, kMaxGeometryCoordinate_m));
  };
  switch (s.kind) {
    case CollisionShape::Kind::Sphere:
      positive(s.radius, "radius");
      return std::make_shared<fcl::Sphered>(s.radius);
    case CollisionShape::Kind::Capsule:
      positive(s.radius, "radius");
      check(std::isfinite(s.length) && s.length >= 0 && s.length <= kMaxGeometryCoordinate_m,
            fmt::format("{}: {}: length must be finite, >= 0 and at most {:g} [m]", who,
                        describe(s), kMaxGeometryCoordinate_m));
      return std::make_shared<fcl::Capsuled>(s.radius, s.length);
    case CollisionShape::Kind::Cylinder:
      positive(s.radius, "radius");
      positive(s.length, "length");
      return std::make_shared<fcl::Cylinderd>(s.radius, s.length);
    case CollisionShape::Kind::Box:
      for (int i = 0; i < 3; ++i) positive(s.size(i), "each edge");
      return std::make_shared<fcl::Boxd>(s.size(0), s.size(1), s.size(2));
    case CollisionShape::Kind::Mesh: {
      std::string f = s.mesh_file;
      check(f.rfind("package://", 0) != 0,
            fmt::format("{}: mesh '{}': package:// URIs are not resolved by exid (no ROS package "
                        "path); give the mesh file's path, or simpler geometry in the study's "
                        "excitation.collision",
                        who, f));
      if (f.rfind("file://", 0) == 0) f = f.substr(7);
      fs::path p(f);
      if (p.is_relative() && !mesh_dir.empty()) p = fs::path(mesh_dir) / p;
      check(s.mesh_scale.allFinite() && s.mesh_scale.minCoeff() > 0 &&
                s.mesh_scale.maxCoeff() <= kMaxMeshScale,
            fmt::format("{}: mesh '{}': scale must be three positive numbers, at most {:g}", who, f,
                        kMaxMeshScale));
      const Mesh m = readStl(p, s.mesh_scale, who);
      auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
      model->beginModel();
      model->addSubModel(m.vertices, m.triangles);
      model->endModel();
      model->computeLocalAABB();
      return model;
    }
  }
  throw Error(who + ": unknown shape kind");
}

fcl::Transform3d toFcl(const Pose& X) {
  fcl::Transform3d T = fcl::Transform3d::Identity();
  T.linear() = X.R;
  T.translation() = X.p;
  return T;
}

}  // namespace

// ---------------------------------------------------------------- the model
struct CollisionModel::Impl {
  const RobotModel* robot = nullptr;
  double margin = 0.0;
  struct Part {
    int body;  // -1: fixed (base or environment)
    Pose pose;
    std::shared_ptr<fcl::CollisionGeometryd> geom;
    bool round;  // sphere or capsule: FCL's closed forms give signed distances
    std::unique_ptr<fcl::CollisionObjectd> obj;
    CollisionShape::Kind kind;
    double radius = 0, length = 0;                   // round shapes (a sphere: length 0)
    Eigen::Vector3d half = Eigen::Vector3d::Zero();  // boxes
    Pose world;                                      // the shape frame in the base frame
  };
  // A side: the base, a body, or an obstacle; its parts.
  struct Side {
    std::string name;
    int body;  // -1 for the base and obstacles
    std::vector<int> parts;
  };
  std::vector<Part> parts;
  std::vector<Side> sides;
  std::vector<std::pair<int, int>> pairs;  // side indices
  std::vector<std::string> names, excluded;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> witness;
  Eigen::MatrixXd T;  // transmission (empty: identity)
  Eigen::VectorXd q0;
  // kinematics scratch
  std::vector<Pose> X;  // body frames in the base frame
  std::vector<Eigen::Vector3d> axis_w, origin_w;
  fcl::DistanceRequestd request;
  fcl::CollisionRequestd contact_request;

  struct Contact {
    double d = HUGE_VAL;
    Eigen::Vector3d pa = Eigen::Vector3d::Zero(), pb = Eigen::Vector3d::Zero();
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
  };

  // A sphere or capsule against a box, in closed form (FCL's GJK gives witness points to ~1e-5
  // only, and no depth when they overlap). The signed distance to a box is convex, so along the
  // capsule's segment it has one minimum: golden-section search to the last bit, then the
  // witness points and the box's outward normal m there. `swapped`: the box is side a.
  Contact roundBox(const Part& r, const Part& box, bool swapped) const {
    const Eigen::Matrix3d& R = box.world.R;
    const Eigen::Vector3d& h = box.half;
    const Eigen::Vector3d c0 = R.transpose() * (r.world.p - box.world.p);  // in the box frame
    const Eigen::Vector3d u = R.transpose() * r.world.R.col(2);
    auto sd = [&](const Eigen::Vector3d& p) {
      const Eigen::Vector3d q = p.cwiseAbs() - h;
      return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
    };
    double lo = -0.5 * r.length, hi = 0.5 * r.length;
    const double g = 0.5 * (std::sqrt(5.0) - 1.0);
    double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
    double f1 = sd(c0 + x1 * u), f2 = sd(c0 + x2 * u);
    for (int it = 0; it < 200 && hi - lo > 1e-15 * (1.0 + r.length); ++it) {
      if (f1 <= f2) {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - g * (hi - lo);
        f1 = sd(c0 + x1 * u);
      } else {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + g * (hi - lo);
        f2 = sd(c0 + x2 * u);
      }
    }
    const Eigen::Vector3d p = c0 + 0.5 * (lo + hi) * u;  // the segment's point, box frame
    const Eigen::Vector3d q = p.cwiseAbs() - h;
    Eigen::Vector3d onbox, m;
    if (q.maxCoeff() > 0) {  // outside: the nearest point of the box, m towards p
      onbox = p.cwiseMax(-h).cwiseMin(h);
      m = (p - onbox).normalized();
    } else {  // inside: the nearest face
      Eigen::Index i = 0;
      q.maxCoeff(&i);
      onbox = p;
      onbox(i) = p(i) < 0 ? -h(i) : h(i);
      m = Eigen::Vector3d::Zero();
      m(i) = p(i) < 0 ? -1.0 : 1.0;
    }
    Contact c;
    c.d = sd(p) - r.radius;
    const Eigen::Vector3d mw = R * m;
    const Eigen::Vector3d on_box = box.world.p + R * onbox;
    const Eigen::Vector3d on_round = box.world.p + R * p - r.radius * mw;
    c.pa = swapped ? on_box : on_round;
    c.pb = swapped ? on_round : on_box;
    c.n = swapped ? mw : Eigen::Vector3d(-mw);  // moving b away from a along n increases d
    return c;
  }

  // The signed distance of two shapes, witness points and the direction n along which moving b
  // relative to a increases it. Separated: FCL's distance (closed forms for sphere and capsule
  // pairs, GJK otherwise). Penetrating: sphere and capsule pairs keep the closed form's negative
  // distance; other shapes take the deepest contact of FCL's collision query (its penetration
  // depth and normal). FCL's signed-distance EPA is not used: it aborts on some configurations.
  Contact signedDistance(const Part& a, const Part& b) const {
    if (a.round && b.kind == CollisionShape::Kind::Box) return roundBox(a, b, false);
    if (b.round && a.kind == CollisionShape::Kind::Box) return roundBox(b, a, true);
    Contact c;
    fcl::DistanceResultd r;
    fcl::distance(a.obj.get(), b.obj.get(), request, r);
    // a closed form's penetration has witness points |pb - pa| = -d apart; FCL's "in collision"
    // answer (-1 without points) does not
    const bool measured =
        r.min_distance > 0 ||
        (a.round && b.round &&
         std::abs((r.nearest_points[1] - r.nearest_points[0]).norm() + r.min_distance) <= 1e-9);
    if (measured) {
      c.d = r.min_distance;
      c.pa = r.nearest_points[0];
      c.pb = r.nearest_points[1];
      const Eigen::Vector3d v = c.pb - c.pa;
      const double len = v.norm();
      if (len > 1e-12) c.n = (c.d < 0 ? -1.0 : 1.0) * v / len;
      return c;
    }
    fcl::CollisionResultd cr;
    fcl::collide(a.obj.get(), b.obj.get(), contact_request, cr);
    c.d = 0.0;  // touching (or a contact FCL cannot measure)
    for (std::size_t i = 0; i < cr.numContacts(); ++i) {
      const auto& ct = cr.getContact(i);
      if (-ct.penetration_depth < c.d || c.n.squaredNorm() == 0.0) {
        c.d = -ct.penetration_depth;
        c.pa = ct.pos;
        c.pb = ct.pos;
        c.n = ct.normal.normalized();  // from a to b: moving b along it separates them
      }
    }
    return c;
  }

  // Eigen::AngleAxisd(angle, axis).toRotationMatrix(), term for term, with exid's sin and cos
  // (the same bits on every CPU: docs/excitation.md §6)
  static Eigen::Matrix3d axisAngle(const Eigen::Vector3d& axis, double angle) {
    double s, c;
    fmath::sincos(angle, &s, &c);
    const Eigen::Vector3d sin_axis = s * axis, cos1_axis = (1.0 - c) * axis;
    Eigen::Matrix3d R;
    double t = cos1_axis.x() * axis.y();
    R(0, 1) = t - sin_axis.z();
    R(1, 0) = t + sin_axis.z();
    t = cos1_axis.x() * axis.z();
    R(0, 2) = t + sin_axis.y();
    R(2, 0) = t - sin_axis.y();
    t = cos1_axis.y() * axis.z();
    R(1, 2) = t - sin_axis.x();
    R(2, 1) = t + sin_axis.x();
    R.diagonal() = (cos1_axis.cwiseProduct(axis)).array() + c;
    return R;
  }

  void kinematics(const Eigen::VectorXd& q) {
    const int n = robot->dof();
    X.resize(static_cast<std::size_t>(n));
    axis_w.resize(static_cast<std::size_t>(n));
    origin_w.resize(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      const Body& b = robot->bodies[static_cast<std::size_t>(i)];
      const Pose F = (b.parent < 0 ? Pose{} : X[static_cast<std::size_t>(b.parent)]) * b.pre;
      Pose M;
      if (b.type == JointType::Revolute)
        M.R = axisAngle(b.axis, q(i));
      else
        M.p = b.axis * q(i);
      X[static_cast<std::size_t>(i)] = F * M * b.post;
      axis_w[static_cast<std::size_t>(i)] = F.R * b.axis;
      origin_w[static_cast<std::size_t>(i)] = F.p;
    }
  }

  // d p / d q (3 x n) of a point p (base frame) fixed to body b (zero for -1).
  void pointJacobian(int b, const Eigen::Vector3d& p, Eigen::Matrix3Xd* J) const {
    J->setZero(3, robot->dof());
    for (int i = b; i >= 0; i = robot->bodies[static_cast<std::size_t>(i)].parent) {
      const auto& a = axis_w[static_cast<std::size_t>(i)];
      if (robot->bodies[static_cast<std::size_t>(i)].type == JointType::Revolute)
        J->col(i) = a.cross(p - origin_w[static_cast<std::size_t>(i)]);
      else
        J->col(i) = a;
    }
  }
};

CollisionModel::CollisionModel(const RobotModel& robot, const CollisionOptions& o)
    : impl_(std::make_unique<Impl>()) {
  robot.requireFixedBase("collision avoidance (the shapes are placed relative to a fixed base)");
  Impl& m = *impl_;
  m.robot = &robot;
  check(
      std::isfinite(o.margin_m) && o.margin_m >= 0,
      fmt::format("collision: margin_m must be a finite distance >= 0 [m], found {}", o.margin_m));
  m.margin = o.margin_m;
  check(!robot.hasLoops(),
        fmt::format("collision: robot '{}' is a closed chain; collision avoidance is not "
                    "implemented for loop-closure joints (expected a kinematic tree)",
                    robot.name));
  const int n = robot.dof();
  if (robot.hasTransmission()) {
    m.T = robot.transmission;
    m.q0 = robot.transmission_offset.size() ? robot.transmission_offset : Eigen::VectorXd::Zero(n);
  }
  // Sides: the base (index 0), each body, each obstacle.
  m.sides.push_back({"base", -1, {}});
  for (int i = 0; i < n; ++i)
    m.sides.push_back({robot.bodies[static_cast<std::size_t>(i)].name, i, {}});
  auto addPart = [&](int side, const CollisionShape& s, const std::string& who,
                     const std::string& dir) {
    check(s.pose.p.allFinite() && s.pose.p.cwiseAbs().maxCoeff() <= kMaxGeometryCoordinate_m,
          fmt::format("{}: position ({:g}, {:g}, {:g}) m is beyond the bound of {:g} m on "
                      "geometry coordinates",
                      who, s.pose.p(0), s.pose.p(1), s.pose.p(2), kMaxGeometryCoordinate_m));
    Impl::Part p;
    p.body = s.body;
    p.pose = s.pose;
    p.geom = makeGeometry(s, dir, who);
    p.round = s.kind == CollisionShape::Kind::Sphere || s.kind == CollisionShape::Kind::Capsule;
    p.kind = s.kind;
    p.radius = s.radius;
    p.length = s.kind == CollisionShape::Kind::Capsule ? s.length : 0.0;
    p.half = 0.5 * s.size;
    p.obj = std::make_unique<fcl::CollisionObjectd>(p.geom, fcl::Transform3d::Identity());
    m.sides[static_cast<std::size_t>(side)].parts.push_back(static_cast<int>(m.parts.size()));
    m.parts.push_back(std::move(p));
  };
  for (const CollisionShape& s : robot.collision) {
    check(s.body >= -1 && s.body < n,
          fmt::format("collision: robot '{}': shape {} names body {} (the robot has {})",
                      robot.name, s.where, s.body, n));
    addPart(s.body + 1, s, fmt::format("robot '{}' collision {}", robot.name, s.where), o.mesh_dir);
  }
  std::set<std::string> names;
  for (const Impl::Side& s : m.sides) names.insert(s.name);
  for (const Obstacle& ob : o.obstacles) {
    check(!ob.name.empty(), "collision: every obstacle needs a name");
    check(
        names.insert(ob.name).second,
        fmt::format("collision: obstacle name '{}' is used twice (or is a body's name)", ob.name));
    m.sides.push_back({ob.name, -1, {}});
    CollisionShape s = ob.shape;
    s.body = -1;
    addPart(static_cast<int>(m.sides.size()) - 1, s, "collision obstacle '" + ob.name + "'",
            o.mesh_dir);
  }
  std::set<std::pair<std::string, std::string>> allowed;
  for (const auto& [a, b] : o.allowed_pairs) {
    check(names.count(a) && names.count(b),
          fmt::format("collision: allowed pair [{}, {}]: '{}' is neither a body of robot '{}' "
                      "nor an obstacle (known: {})",
                      a, b, names.count(a) ? b : a, robot.name, fmt::join(names, ", ")));
    allowed.insert({a, b});
    allowed.insert({b, a});
  }
  const int nb = n + 1;  // base + bodies
  auto parentSide = [&](int side) {
    return side == 0 ? -1 : robot.bodies[static_cast<std::size_t>(side - 1)].parent + 1;
  };
  for (int i = 0; i < static_cast<int>(m.sides.size()); ++i)
    for (int j = i + 1; j < static_cast<int>(m.sides.size()); ++j) {
      const Impl::Side& A = m.sides[static_cast<std::size_t>(i)];
      const Impl::Side& B = m.sides[static_cast<std::size_t>(j)];
      if (A.parts.empty() || B.parts.empty()) continue;
      const bool a_robot = i < nb, b_robot = j < nb;
      if (!a_robot && !b_robot) continue;  // obstacle ~ obstacle: both static
      if (i == 0 && !b_robot) continue;    // base ~ obstacle: both static
      if (a_robot && b_robot && !o.self) continue;
      const std::string name = A.name + " ~ " + B.name;
      if (a_robot && b_robot && (parentSide(j) == i || parentSide(i) == j)) {
        m.excluded.push_back(name + " (parent and child)");
        continue;
      }
      if (allowed.count({A.name, B.name})) {
        m.excluded.push_back(name + " (allowed by the study)");
        continue;
      }
      m.pairs.push_back({i, j});
      m.names.push_back(name);
    }
  check(!m.pairs.empty(),
        fmt::format("collision: nothing to check for robot '{}': {} (robot shapes: {}, "
                    "obstacles: {})",
                    robot.name,
                    robot.collision.empty()
                        ? "the robot description has no collision geometry (URDF <collision>, "
                          "or `collision` entries in a DH description)"
                        : "every pair is excluded",
                    robot.collision.size(), o.obstacles.size()));
  m.witness.resize(m.pairs.size());
  m.request.enable_nearest_points = true;
  m.request.enable_signed_distance = false;
  m.request.distance_tolerance = 1e-10;
  m.request.gjk_solver_type = fcl::GST_LIBCCD;
  m.contact_request.num_max_contacts = 16;
  m.contact_request.enable_contact = true;
  m.contact_request.gjk_solver_type = fcl::GST_LIBCCD;
}

CollisionModel::~CollisionModel() = default;

int CollisionModel::numPairs() const { return static_cast<int>(impl_->pairs.size()); }
const std::vector<std::string>& CollisionModel::pairNames() const { return impl_->names; }
const std::vector<std::string>& CollisionModel::excludedPairs() const { return impl_->excluded; }
double CollisionModel::margin() const { return impl_->margin; }
const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& CollisionModel::witnessPoints()
    const {
  return impl_->witness;
}

void CollisionModel::distances(const Eigen::VectorXd& qm, Eigen::VectorXd* d,
                               Eigen::MatrixXd* ddq) {
  Impl& m = *impl_;
  const int n = m.robot->dof();
  check(qm.size() == n,
        fmt::format("collision distances: {} coordinates for a robot of {}", qm.size(), n));
  const Eigen::VectorXd q = m.T.size() ? Eigen::VectorXd(m.T * qm + m.q0) : qm;
  m.kinematics(q);
  for (auto& p : m.parts) {
    const Pose W = p.body < 0 ? p.pose : m.X[static_cast<std::size_t>(p.body)] * p.pose;
    p.world = W;
    p.obj->setTransform(toFcl(W));  // (no AABB: no broad phase, every pair is measured)
  }
  const int P = numPairs();
  d->resize(P);
  if (ddq) ddq->setZero(P, n);
  Eigen::Matrix3Xd Ja, Jb;
  for (int k = 0; k < P; ++k) {
    const auto& [ia, ib] = m.pairs[static_cast<std::size_t>(k)];
    const Impl::Side& A = m.sides[static_cast<std::size_t>(ia)];
    const Impl::Side& B = m.sides[static_cast<std::size_t>(ib)];
    double best = HUGE_VAL;
    Eigen::Vector3d wa = Eigen::Vector3d::Zero(), wb = Eigen::Vector3d::Zero();
    Eigen::Vector3d nrm = Eigen::Vector3d::Zero();
    for (int pa : A.parts)
      for (int pb : B.parts) {
        const Impl::Part& a = m.parts[static_cast<std::size_t>(pa)];
        const Impl::Part& b = m.parts[static_cast<std::size_t>(pb)];
        const Impl::Contact c = m.signedDistance(a, b);
        if (c.d < best) {
          best = c.d;
          wa = c.pa;
          wb = c.pb;
          nrm = c.n;
        }
      }
    // A distance that is not finite, or beyond any geometry within the coordinates' bound, is
    // an error, never a large margin ("feasible").
    check(std::isfinite(best) && std::abs(best) <= kMaxDistance_m,
          fmt::format("collision distances: pair '{}': distance {:g} m is not a finite distance "
                      "within {:g} m (geometry beyond the bound of {:g} m on coordinates?)",
                      m.names[static_cast<std::size_t>(k)], best, kMaxDistance_m,
                      kMaxGeometryCoordinate_m));
    (*d)(k) = best;
    m.witness[static_cast<std::size_t>(k)] = {wa, wb};
    if (!ddq || nrm.squaredNorm() == 0.0) continue;  // no direction: derivative 0
    m.pointJacobian(A.body, wa, &Ja);
    m.pointJacobian(B.body, wb, &Jb);
    ddq->row(k) = nrm.transpose() * (Jb - Ja);
  }
  if (ddq && m.T.size()) *ddq = *ddq * m.T;
}

}  // namespace exid
