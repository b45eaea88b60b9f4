// exid — choosing the scale of a prior from the identification data alone (part of
// exid_estimators_common). The prior N(theta0, Sigma) is used as N(theta0, a^2 Sigma); the data
// rows are noise-normalised (each in units of its noise std). Two criteria, see
// docs/consistent.md "Prior scale":
//   cv:       blocked K-fold cross-validation: the identification samples are cut into K
//             contiguous blocks in time; for each a, fit on K - 1 blocks (+ the prior) and
//             predict the held-out block; a minimises the summed weighted prediction error;
//   evidence: type-II maximum likelihood (MacKay): a and a common noise variance s^2 of the
//             rows maximise the marginal likelihood p(y | a, s^2) of the linear Gaussian model.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"

namespace exid::estimators {

/// The prior with every standard deviation multiplied by `scale` (covariance by scale^2).
Prior scaledPrior(const Prior& prior, double scale);

/// Candidate scales: `per_decade` log-spaced values from lo to hi (both included).
std::vector<double> logGrid(double lo, double hi, int per_decade);

struct PriorScaleChoice {
  double scale = 1.0;
  std::string method;                 // "cv" | "evidence"
  std::vector<double> grid;           // candidates (cv)
  std::vector<double> criterion;      // cv: summed weighted prediction error per candidate
  double noise_variance = 1.0;        // evidence: s^2 at the optimum (rows already normalised: ~1)
  double effective_parameters = 0.0;  // evidence: gamma = p - tr(posterior cov * prior info)
  double log_evidence = 0.0;          // evidence: at the optimum
  int iterations = 0;                 // evidence: fixed-point iterations
  /// "low" / "high": the choice sits at that end of the searched range (the best scale may lie
  /// beyond it: widen the range or state the scale); "" inside it.
  std::string at_edge;
  /// The doubt about the choice in words ("" when inside the range), for the study's verdict.
  std::string edgeText(const std::string& who) const;
  Json toJson() const;
};

/// Blocked K-fold cross-validation over `grid` on noise-normalised rows: folds[k] holds block
/// k's rows (already weighted). For each candidate a and block k, theta_k(a) is the regularised
/// least-squares solution of the other blocks stacked with the prior scaled by a; the
/// criterion is sum_k ||F_k theta_k(a) - f_k||^2 (F_k, f_k: block k's factor). Needs at least two
/// non-empty blocks. Ties go to the larger scale (the weaker prior). Throws exid::Error
/// prefixed with `who`.
PriorScaleChoice selectPriorScaleCv(const std::vector<RowAccumulator>& folds, const Prior& prior,
                                    const std::vector<double>& grid, const std::string& who);

/// Type-II maximum likelihood of (a, s^2) for y = W theta + e, e ~ N(0, s^2 I), theta ~
/// N(theta0, a^2 Sigma), from the factor of the noise-normalised rows (m rows). MacKay's
/// fixed point a^2 = (theta - theta0)^T Sigma^-1 (theta - theta0) / gamma, s^2 = rss / (m -
/// gamma), started at a = 1, s^2 = 1; a clamped to [lo, hi].
PriorScaleChoice selectPriorScaleEvidence(const RowAccumulator& rows, const Prior& prior, double lo,
                                          double hi, const std::string& who);

}  // namespace exid::estimators
