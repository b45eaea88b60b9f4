// Fuzz target: the STL mesh reader (binary and ASCII) of the collision model
// (framework/collision/src/collision.cpp), through exid::CollisionModel: the input is written as an
// STL file of this process's own temporary folder and becomes an obstacle beside a one-link robot
// whose link is a sphere; then the distances and their derivatives at two configurations. Every
// input must end in a result or an exid::Error: never a crash, a sanitizer report or a hang.
#include <unistd.h>

#include <Eigen/Core>
#include <filesystem>
#include <fstream>
#include <string>

#include "exid/collision.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

namespace {

namespace fs = std::filesystem;

const char* kRobot = R"(name: ball_on_a_stick
convention: standard
links:
  - name: link1
    joint: joint1
    a: 0.5
    alpha: 0.0
    d: 0.0
    mass: 1.0
    com: [-0.25, 0.0, 0.0]
    inertia_com: {xx: 0.001, yy: 0.02, zz: 0.02}
    limits: {q_min: -3, q_max: 3, qd_max: 3.0, qdd_max: 10.0}
    collision:
      - {sphere: {radius_m: 0.05}}
)";

const exid::RobotModel& robot() {
  static const exid::RobotModel r = exid::loadDhYamlString(kRobot, "fuzz_mesh_robot.yaml");
  return r;
}

/// The mesh file of this process (its folder removed at exit).
const fs::path& meshFile() {
  static const struct File {
    fs::path dir = fs::temp_directory_path() / ("exid_fuzz_mesh_" + std::to_string(::getpid()));
    fs::path p = dir / "fuzz.stl";
    File() { fs::create_directories(dir); }
    ~File() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } f;
  return f.p;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::ofstream(meshFile(), std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  try {
    exid::CollisionOptions o;
    o.self = false;
    exid::Obstacle ob;
    ob.name = "mesh";
    ob.shape.kind = exid::CollisionShape::Kind::Mesh;
    ob.shape.mesh_file = meshFile().string();
    ob.shape.pose.p = Eigen::Vector3d(0.3, 0.2, 0.0);
    o.obstacles = {ob};
    exid::CollisionModel cm(robot(), o);
    Eigen::VectorXd d;
    Eigen::MatrixXd ddq;
    for (double q : {0.0, 1.0}) cm.distances(Eigen::VectorXd::Constant(1, q), &d, &ddq);
  } catch (const exid::Error&) {
  }
  return 0;
}
