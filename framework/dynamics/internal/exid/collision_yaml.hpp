// exid — one collision shape read from YAML: a DH description's `collision` entries and a
// study's obstacles (excitation.collision.obstacles). Header-only, like yaml_strict.hpp: the DH
// robot loader (exid_robots) and the study parser (exid_core) share it without linking each
// other.
//   {capsule: {radius_m: 0.06, length_m: 0.28}, xyz_m: [0, 0, -0.19], rpy_rad: [0, 0, 0]}
// with exactly one of sphere {radius_m}, capsule or cylinder {radius_m, length_m}, box
// {size_m: [x, y, z]}, mesh {file, scale} (STL); xyz_m and rpy_rad (the shape frame in the
// body's; roll-pitch-yaw about fixed x, y, z as in URDF) optional; `name` read into *name when it
// is given (obstacles), refused otherwise. Errors: exid::Error "source:line: path: rule".
#pragma once

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <set>
#include <string>

#include "exid/error.hpp"
#include "exid/export.hpp"
#include "exid/input_file.hpp"
#include "exid/robot_model.hpp"

namespace exid {

/// Geometry coordinates (positions, lengths, sizes, mesh vertices after scaling) are refused
/// beyond this [m]: a robot's cell is metres across, and coordinates near the double range make
/// distances overflow (an obstacle 1e200 m away gave a minimum distance of 1.8e308, "feasible").
inline constexpr double kMaxGeometryCoordinate_m = 1e4;
/// A mesh's scale factors are refused beyond this.
inline constexpr double kMaxMeshScale = 1e4;

namespace detail {

struct EXID_API ShapeReader {
  const std::string& source;

  [[noreturn]] void fail(const YAML::Node& at, const std::string& path,
                         const std::string& rule) const {
    std::string msg = source;
    if (at.IsDefined() && at.Mark().line >= 0) msg += ":" + std::to_string(at.Mark().line + 1);
    throw Error(msg + ": " + path + ": " + rule);
  }

  void keys(const YAML::Node& n, const std::string& path,
            const std::set<std::string>& allowed) const {
    if (!n.IsMap()) fail(n, path, "expected a mapping");
    for (const auto& kv : n) {
      const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
      if (!allowed.count(k))
        fail(kv.first, path,
             fmt::format("unknown key '{}' (allowed: {})", k, fmt::join(allowed, ", ")));
    }
  }

  double number(const YAML::Node& n, const std::string& path) const {
    if (!n.IsDefined()) fail(n, path, "missing");
    if (!n.IsScalar()) fail(n, path, "expected a number");
    double v = 0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, path, "expected a number, found '" + n.Scalar() + "'");
    }
    if (!std::isfinite(v)) fail(n, path, "expected a finite number");
    return v;
  }

  double length(const YAML::Node& parent, const char* key, const std::string& path,
                bool zero_ok = false) const {
    const YAML::Node n = parent[key];
    if (!n) fail(parent, path, std::string("missing ") + key);
    const double v = number(n, path + "." + key);
    if (v < 0 || (!zero_ok && v == 0))
      fail(n, path + "." + key,
           fmt::format("must be {} [m], found {}", zero_ok ? ">= 0" : "> 0", v));
    bounded(n, path + "." + key, v);
    return v;
  }

  // |v| <= kMaxGeometryCoordinate_m
  void bounded(const YAML::Node& n, const std::string& path, double v) const {
    if (std::abs(v) > kMaxGeometryCoordinate_m)
      fail(n, path,
           fmt::format("{:g} m is beyond the bound of {:g} m on geometry coordinates (positions, "
                       "sizes, mesh vertices)",
                       v, kMaxGeometryCoordinate_m));
  }

  // three coordinates [m], each within the bound
  Eigen::Vector3d coords(const YAML::Node& n, const std::string& path) const {
    const Eigen::Vector3d v = vec3(n, path);
    for (std::size_t i = 0; i < 3; ++i)
      bounded(n[i], fmt::format("{}[{}]", path, i), v(static_cast<Eigen::Index>(i)));
    return v;
  }

  Eigen::Vector3d vec3(const YAML::Node& n, const std::string& path) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, path, "expected a list of three numbers");
    Eigen::Vector3d v;
    for (std::size_t i = 0; i < 3; ++i)
      v(static_cast<Eigen::Index>(i)) = number(n[i], fmt::format("{}[{}]", path, i));
    return v;
  }
};

}  // namespace detail

inline CollisionShape parseCollisionShape(const YAML::Node& node, const std::string& source,
                                          const std::string& path, std::string* name = nullptr) {
  const detail::ShapeReader r{source};
  std::set<std::string> allowed = {"sphere", "capsule", "cylinder", "box",
                                   "mesh",   "xyz_m",   "rpy_rad"};
  if (name) allowed.insert("name");
  r.keys(node, path, allowed);
  CollisionShape s;
  s.where = fmt::format("{}:{}: {}", source, node.Mark().line + 1, path);
  int kinds = 0;
  for (const char* k : {"sphere", "capsule", "cylinder", "box", "mesh"}) kinds += node[k] ? 1 : 0;
  if (kinds != 1)
    r.fail(node, path,
           "give exactly one of sphere {radius_m}, capsule {radius_m, length_m}, cylinder "
           "{radius_m, length_m}, box {size_m: [x, y, z]}, mesh {file, scale}");
  if (const YAML::Node n = node["sphere"]) {
    r.keys(n, path + ".sphere", {"radius_m"});
    s.kind = CollisionShape::Kind::Sphere;
    s.radius = r.length(n, "radius_m", path + ".sphere");
  } else if (const YAML::Node c = node["capsule"]) {
    r.keys(c, path + ".capsule", {"radius_m", "length_m"});
    s.kind = CollisionShape::Kind::Capsule;
    s.radius = r.length(c, "radius_m", path + ".capsule");
    s.length = r.length(c, "length_m", path + ".capsule", true);
  } else if (const YAML::Node y = node["cylinder"]) {
    r.keys(y, path + ".cylinder", {"radius_m", "length_m"});
    s.kind = CollisionShape::Kind::Cylinder;
    s.radius = r.length(y, "radius_m", path + ".cylinder");
    s.length = r.length(y, "length_m", path + ".cylinder");
  } else if (const YAML::Node b = node["box"]) {
    r.keys(b, path + ".box", {"size_m"});
    s.kind = CollisionShape::Kind::Box;
    if (!b["size_m"]) r.fail(b, path + ".box", "missing size_m: [x, y, z]");
    s.size = r.coords(b["size_m"], path + ".box.size_m");
    if (s.size.minCoeff() <= 0) r.fail(b["size_m"], path + ".box.size_m", "edges must be > 0");
  } else {
    const YAML::Node m = node["mesh"];
    r.keys(m, path + ".mesh", {"file", "scale"});
    s.kind = CollisionShape::Kind::Mesh;
    if (!m["file"] || !m["file"].IsScalar() || m["file"].Scalar().empty())
      r.fail(m, path + ".mesh", "missing file (an STL mesh)");
    s.mesh_file = m["file"].Scalar();
    for (std::size_t i = 0; i < s.mesh_file.size(); ++i)  // a NUL would cut the path short
      if (static_cast<unsigned char>(s.mesh_file[i]) < 0x20 || s.mesh_file[i] == 0x7F)
        r.fail(
            m["file"], path + ".mesh.file",
            fmt::format("the path '{}' holds the control byte 0x{:02X} at byte {}; a file "
                        "path must not hold control bytes",
                        printablePath(s.mesh_file),
                        static_cast<unsigned>(static_cast<unsigned char>(s.mesh_file[i])), i + 1));
    if (m["scale"]) {
      s.mesh_scale = r.vec3(m["scale"], path + ".mesh.scale");
      if (s.mesh_scale.minCoeff() <= 0)
        r.fail(m["scale"], path + ".mesh.scale", "must be three positive numbers");
      if (s.mesh_scale.maxCoeff() > kMaxMeshScale)
        r.fail(m["scale"], path + ".mesh.scale",
               fmt::format("{:g} is beyond the bound of {:g} on a mesh's scale factors",
                           s.mesh_scale.maxCoeff(), kMaxMeshScale));
    }
  }
  if (node["xyz_m"]) s.pose.p = r.coords(node["xyz_m"], path + ".xyz_m");
  if (node["rpy_rad"]) {
    const Eigen::Vector3d a = r.vec3(node["rpy_rad"], path + ".rpy_rad");
    s.pose.R = (Eigen::AngleAxisd(a(2), Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(a(1), Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(a(0), Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  }
  if (name) {
    if (!node["name"] || !node["name"].IsScalar() || node["name"].Scalar().empty())
      r.fail(node, path, "missing name (obstacles are named in reports and allowed_pairs)");
    *name = node["name"].Scalar();
  }
  return s;
}

}  // namespace exid
