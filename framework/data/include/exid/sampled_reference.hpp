// exid — a trajectory given by samples (q, qd, qdd at every knot), read between them: the
// quintic Hermite interpolant, C2 and exact at the knots. The `simulate` experiment's sampled
// reference and the closed loop of the `iv` and `didim` estimators use it.
#pragma once

#include <Eigen/Core>

#include "exid/data.hpp"
#include "exid/export.hpp"

namespace exid {

/// q, qd, qdd of the samples' quintic Hermite interpolant at time t (the polynomial of the
/// first or last interval outside the samples' span; one sample: its values).
EXID_API void quinticHermite(const Samples& s, double t, Eigen::VectorXd* q, Eigen::VectorXd* qd,
                             Eigen::VectorXd* qdd);
/// The same interpolant's third derivative (jerk) at time t: piecewise quadratic, one-sided
/// at the knots (the interval t falls in, as quinticHermite); zero for one sample.
EXID_API Eigen::VectorXd quinticHermiteJerk(const Samples& s, double t);

}  // namespace exid
