// exid — a delay between the measurement channels (torque, wrench) and the position channel of
// a recording: a sampled signal read at shifted times (piecewise cubic Hermite interpolation),
// its exact derivative in the shift, and data or rows compensated for a delay
// (docs/estimators.md, "Measurement delay").
#pragma once

#include <Eigen/Core>
#include <string>

#include "exid/data.hpp"
#include "exid/export.hpp"

namespace exid {

/// Convention: a delay d > 0 means the measurement lags the positions, measured(t) =
/// true(t - d). It is compensated by pairing the measurement at t_k with the model at t_k - d
/// (the positions, or the model's rows, read d earlier); the measurement itself is never
/// interpolated, so its noise stays as recorded (interpolating noise lowers its variance by an
/// amount that depends on d, which would bias a fitted delay towards half samples).
///
/// The interpolant is the cubic Hermite spline through the samples with slopes from the
/// five-point Lagrange derivative at each sample (fourth-order accurate, also on uneven steps):
/// continuous with its first derivative in the shift, exact for cubics. It is defined on
/// [t_2, t_{K-3}].
///
/// X holds `per_sample` rows per sample, sample-major (row k per_sample + j), K = t.size()
/// samples. For samples [first, last): out row (k - first) per_sample + j is X's row j read at
/// t_k + shift_s, d_out (if not null) its derivative with respect to shift_s. Every t_k +
/// shift_s must lie in [t_2, t_{K-3}] (else exid::Error); t strictly increasing.
EXID_API void shiftedRows(const Eigen::VectorXd& t, const Eigen::MatrixXd& X, int per_sample,
                          double shift_s, int first, int last, Eigen::MatrixXd* out,
                          Eigen::MatrixXd* d_out);

/// The samples [*first, *last) of t whose t_k + shift_s lies in [t_2, t_{K-3}] (empty: first
/// == last).
EXID_API void shiftedRange(const Eigen::VectorXd& t, double shift_s, int* first, int* last);

/// A dataset in memory compensated for a known measurement delay: q, qd, qdd of sample k are
/// read at t_k - delay_s, the torque and wrench stay as recorded. The samples without
/// positions at t_k - delay_s are dropped (*dropped_front, *dropped_back; counted, the caller
/// reports them). `who` starts the messages. Fewer than 4 samples left is an exid::Error.
EXID_API Dataset compensateDelay(const Dataset& d, double delay_s, const std::string& who,
                                 int* dropped_front, int* dropped_back);

/// Rows of a per-sample model (ModelSpecs::per_sample: the same number of rows per sample,
/// sample-major) of the samples at times t, compensated for a measurement delay: W of sample
/// k read at t_k - delay_s, y as measured. The samples whose t_k - delay_s cannot be read
/// give no rows (counted in *dropped_front, *dropped_back). `who` starts the messages.
EXID_API Rows delayedRows(const Rows& rows, const Eigen::VectorXd& t, double delay_s,
                          const std::string& who, int* dropped_front, int* dropped_back);

}  // namespace exid
