// exid — internal helpers shared by the dynamics sources (not installed).
#pragma once

#include <Eigen/Core>

#include "exid/dynamics.hpp"

namespace exid::detail {
/// Per-workspace scratch storage (slots 0..3), so that callers avoid per-sample allocation.
Eigen::MatrixXd& scratchMatrix(DynamicsData& d, int slot);
Eigen::VectorXd& scratchVector(DynamicsData& d, int slot);
}  // namespace exid::detail
