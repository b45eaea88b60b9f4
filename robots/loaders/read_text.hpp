// exid — robot loaders: private helpers shared by the loaders (not installed).
#pragma once

#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/robot_model.hpp"

namespace exid::detail {

/// Only a regular file of at most kMaxRobotFileBytes (a FIFO, /dev/zero or a directory is
/// refused before it is opened for reading).
inline std::string readTextFile(const std::filesystem::path& file, const char* what) {
  return readInputFile(file, what, kMaxRobotFileBytes);
}

/// The last checks of every loader: the structure (an exid::Error naming `src`) and the
/// physical consistency of the inertial parameters (checkModelPhysical, with `options`).
inline void checkLoaded(const RobotModel& m, const std::string& src, const LoadOptions& options) {
  try {
    m.validateStructure();
  } catch (const Error& e) {
    throw Error(src + ": " + e.what());
  }
  checkModelPhysical(m, options);
}

/// Makes the tree *m a closed chain: its loop-closure joints, the actuated tree joints (in the
/// order of the measured coordinates) and the reference configuration (an assembled one; the
/// first guess of the position solve). Limits and drives become per actuated joint (the tree's
/// limits kept in closed.tree_limits); a drive term on a passive joint is an exid::Error naming
/// `src` (a passive joint has no motor).
void makeClosedChain(RobotModel* m, std::vector<LoopJoint> loops, std::vector<int> actuated,
                     Eigen::VectorXd reference, const std::string& src);

/// URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll).
inline Eigen::Matrix3d rpyToMatrix(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

/// Interval hull of q = T qm + q0 for qm in the box [lo, hi] (infinite bounds propagate).
inline void transmissionHull(const Eigen::MatrixXd& T, const Eigen::VectorXd& q0,
                             const Eigen::VectorXd& lo, const Eigen::VectorXd& hi,
                             Eigen::VectorXd* qlo, Eigen::VectorXd* qhi) {
  const Eigen::Index n = T.rows();
  *qlo = q0;
  *qhi = q0;
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < T.cols(); ++j) {
      const double t = T(i, j);
      if (t == 0.0) continue;
      const double a = t * lo(j), b = t * hi(j);
      (*qlo)(i) += std::min(a, b);
      (*qhi)(i) += std::max(a, b);
    }
  }
}

}  // namespace exid::detail
