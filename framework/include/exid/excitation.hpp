// exid — the excitation-design problem assembled from plugins:
//   J(z) = F(M),  M = S W(z)^T W(z) S,  W = model.design(trajectory.evaluate(z))
// (S = optional diagonal column scaling by nominal parameter magnitudes), with the exact
// gradient by reverse accumulation: dJ/dW = 2 W S dF/dM S, then the model's and the
// trajectory's vector-Jacobian products (the paper's adjoint, eqns 10-15, generalised).
// Constraints g(z) <= 0: joint positions within limits less a margin, velocities and
// accelerations within limits, at every sample (only limits that are finite).
#pragma once

#include <memory>

#include "exid/interfaces.hpp"

namespace exid {

struct ExcitationOptions {
  double position_margin = 0.0;  // [rad or m] kept inside the position limits
  bool velocity_limits = true;
  bool acceleration_limits = true;
  bool scale_columns = false;  // scale base columns by |nominal base parameter|
};

std::unique_ptr<ExcitationProblem> makeExcitationProblem(std::shared_ptr<Trajectory> trajectory,
                                                         std::shared_ptr<ObservationModel> model,
                                                         std::shared_ptr<Criterion> criterion,
                                                         const ExcitationOptions& options = {});

/// cond(W) = sigma_max / sigma_min of the base design rows of a trajectory (for reports).
double conditionNumber(const Eigen::MatrixXd& W);

}  // namespace exid
