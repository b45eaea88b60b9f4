// exid — minimum distances between a robot's bodies and between its bodies and a static
// environment, with their exact derivatives, for collision-free excitation design
// (docs/excitation.md §12). Distances come from FCL; the derivative of the signed distance d of
// a pair (A, B) with witness points a (on A) and b (on B) is
//   dd/dq = n^T (J_B(b) - J_A(a)),   n = sign(d) (b - a) / |b - a|,
// J_X(p) the Jacobian of the point p fixed to X's body (zero for the base and the environment).
// A pair's distance is the minimum over the shapes of its two sides.
//
// Which pairs are checked: every two bodies that both carry geometry (self-collision, when
// asked) and every body against every obstacle, except
//   - a body and its parent (they touch at their joint by construction; the base counts as the
//     parent of the first bodies), and
//   - the pairs the study lists as allowed (by body or obstacle name).
// Shapes fixed to the base belong to the base, which is checked like a body.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

/// An obstacle of the static environment: a shape fixed in the base frame, with a name.
struct EXID_API Obstacle {
  std::string name;
  CollisionShape shape;  // body -1
};

struct EXID_API CollisionOptions {
  double margin_m = 0.0;  // required minimum distance [m]
  bool self = true;       // check body against body
  std::vector<Obstacle> obstacles;
  /// Pairs never checked, by body name ("base" for the base) or obstacle name.
  std::vector<std::pair<std::string, std::string>> allowed_pairs;
  /// Folder relative mesh files are read from (the robot description's, for its own shapes).
  std::string mesh_dir;
};

/// The collision model of a robot in an environment. Thread-compatible: one instance per
/// thread (distances() keeps scratch state).
class EXID_API CollisionModel {
 public:
  /// Throws exid::Error naming the shape (and its origin) when geometry is invalid or a mesh
  /// cannot be read, and when nothing is left to check.
  CollisionModel(const RobotModel& robot, const CollisionOptions& options);
  ~CollisionModel();
  CollisionModel(const CollisionModel&) = delete;
  CollisionModel& operator=(const CollisionModel&) = delete;

  int numPairs() const;
  /// "link3 ~ link6", "link7 ~ table": one per pair, in the order of the distances.
  const std::vector<std::string>& pairNames() const;
  /// Pairs excluded by the rules (parent ~ child, the allowed list), for the report.
  const std::vector<std::string>& excludedPairs() const;
  double margin() const;

  /// Signed distances (one per pair) at the measured coordinates qm (the robot's transmission
  /// applied), and when ddq is given their derivatives d d / d qm (pairs x dof). Separated pairs
  /// and penetrating sphere/capsule pairs: exact distances. Other penetrating pairs (boxes,
  /// cylinders, meshes): the depth and normal of FCL's deepest contact (an estimate).
  void distances(const Eigen::VectorXd& qm, Eigen::VectorXd* d, Eigen::MatrixXd* ddq = nullptr);

  /// The witness points of the last call (world frame), pair by pair, for reports and tests.
  const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& witnessPoints() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace exid
