// exid — the figures a person reads a study by, as plot specifications (plot.hpp draws them):
// a prediction against its measurement over time with the residual in a panel below, and
// torques over their limits with the limits drawn as limits.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/data.hpp"
#include "plot.hpp"

namespace exid {

/// Equation eq of rows (0-based): measured (a thick light line underneath) and predicted (a thin
/// dark line on top) against the rows' time t [s] (the row index when the rows carry no time),
/// and measured - predicted in a panel below. Named by rows.equation_names (joint and unit) when
/// given. The CSV: t_s (or sample), measured, predicted, residual.
PlotSpec validationPlot(const Rows& rows, const Eigen::VectorXd& predicted, int eq);

/// tau(:, j) / tau_max(j) against t for every joint (labelled by joint_labels when given, else
/// tau1..), the torque limit +-1 and the design's margin +-margin (when in (0, 1)) as dashed
/// labelled lines inside the y range.
PlotSpec torqueRatioPlot(const std::string& name, const std::string& title,
                         const Eigen::VectorXd& t, const Eigen::MatrixXd& tau,
                         const Eigen::VectorXd& tau_max, double margin,
                         const std::vector<std::string>& joint_labels);

/// "<prefix><j+1>" with the joint's name after it when known: "tau2 (shoulder)".
std::string jointLabel(const std::string& prefix, int j, const std::vector<std::string>& names);

}  // namespace exid
