// Choosing the scale of a prior from the identification data: blocked cross-validation and
// type-II maximum likelihood (evidence). See prior_scale.hpp and docs/consistent.md.
#include "exid/estimators/prior_scale.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/consistent.hpp"

namespace exid::estimators {

Prior scaledPrior(const Prior& prior, double scale) {
  Prior out = prior;
  out.covariance *= scale * scale;
  out.standard_std *= scale;
  return out;
}

std::vector<double> logGrid(double lo, double hi, int per_decade) {
  check(lo > 0 && hi >= lo && std::isfinite(hi) && per_decade > 0,
        fmt::format("prior scale grid: need 0 < lo <= hi < inf and points per decade > 0 (got "
                    "[{}, {}], {})",
                    lo, hi, per_decade));
  const double decades = std::log10(hi / lo);
  const int n = std::max(1, static_cast<int>(std::ceil(decades * per_decade - 1e-9)));
  std::vector<double> g;
  for (int i = 0; i <= n; ++i)
    g.push_back(i == n ? hi : lo * std::pow(10.0, decades * i / static_cast<double>(n)));
  if (hi == lo) g.resize(1);
  return g;
}

std::string PriorScaleChoice::edgeText(const std::string& who) const {
  if (at_edge.empty() || grid.empty()) return "";
  return fmt::format(
      "{}: the prior scale chosen by {} ({:.4g}) sits at the {} end of the searched range [{:.4g}, "
      "{:.4g}] (prior_scale_range): the best scale may lie beyond it; widen the range, or state "
      "the scale (prior_scale_selection: none, prior_scale)",
      who, method == "cv" ? "cross-validation" : "the evidence", scale,
      at_edge == "low" ? "lower" : "upper", grid.front(), grid.back());
}

Json PriorScaleChoice::toJson() const {
  Json j = Json::object();
  j["method"] = method;
  j["scale"] = scale;
  j["at_range_edge"] = at_edge.empty() ? Json() : Json(at_edge);
  if (method == "cv") {
    j["grid"] = Json(grid);
    j["cv_error"] = Json(criterion);
    j["cv_error_definition"] =
        "sum over the blocks of the weighted squared prediction error of the block by the fit "
        "of the other blocks with the prior scaled by the candidate";
  } else {
    j["noise_variance"] = noise_variance;
    j["effective_parameters"] = effective_parameters;
    j["log_evidence"] = log_evidence;
    j["iterations"] = iterations;
    if (!grid.empty()) {
      j["grid"] = Json(grid);
      j["log_evidence_on_grid"] = Json(criterion);
    }
  }
  return j;
}

PriorScaleChoice selectPriorScaleCv(const std::vector<RowAccumulator>& folds, const Prior& prior,
                                    const std::vector<double>& grid, const std::string& who) {
  check(!grid.empty(), fmt::format("{}: no candidate prior scale", who));
  std::vector<int> used;
  for (std::size_t k = 0; k < folds.size(); ++k)
    if (folds[k].cols() > 0 && folds[k].rows() > 0) used.push_back(static_cast<int>(k));
  check(used.size() >= 2,
        fmt::format("{}: prior scale by cross-validation needs at least two blocks of samples "
                    "with rows (found {})",
                    who, used.size()));
  const int p = folds[static_cast<std::size_t>(used[0])].cols();
  const Eigen::MatrixXd S = priorSqrtInformation(prior, p, who);
  const Eigen::VectorXd s0 = S * prior.value;
  PriorScaleChoice out;
  out.method = "cv";
  out.grid = grid;
  out.criterion.assign(grid.size(), 0.0);
  for (int k : used) {
    // The other blocks, compressed once per held-out block.
    RowAccumulator train(p);
    for (int j : used)
      if (j != k) train.merge(folds[static_cast<std::size_t>(j)]);
    const Eigen::MatrixXd& T = train.factor();
    const Eigen::MatrixXd& H = folds[static_cast<std::size_t>(k)].factor();
    Eigen::MatrixXd stack(T.rows() + p, p + 1);
    stack.topRows(T.rows()) = T;
    for (std::size_t g = 0; g < grid.size(); ++g) {
      stack.bottomLeftCorner(p, p) = S / grid[g];
      stack.bottomRightCorner(p, 1) = s0 / grid[g];
      const Eigen::VectorXd theta =
          stack.leftCols(p).colPivHouseholderQr().solve(stack.col(p).eval());
      out.criterion[g] += (H.leftCols(p) * theta - H.col(p)).squaredNorm();
    }
  }
  std::size_t best = 0;
  for (std::size_t g = 1; g < grid.size(); ++g)
    if (std::isfinite(out.criterion[g]) && out.criterion[g] <= out.criterion[best]) best = g;
  check(std::isfinite(out.criterion[best]),
        fmt::format("{}: the cross-validation error is not finite", who));
  out.scale = grid[best];
  if (grid.size() > 1) out.at_edge = best == 0 ? "low" : best + 1 == grid.size() ? "high" : "";
  return out;
}

PriorScaleChoice selectPriorScaleEvidence(const RowAccumulator& rows, const Prior& prior, double lo,
                                          double hi, const std::string& who) {
  const int p = rows.cols();
  const double m = static_cast<double>(rows.rows());
  check(m > p, fmt::format("{}: prior scale by evidence needs more rows than parameters", who));
  (void)priorSqrtInformation(prior, p, who);  // validates
  const Eigen::MatrixXd L =
      Eigen::LLT<Eigen::MatrixXd>(0.5 * (prior.covariance + prior.covariance.transpose()))
          .matrixL();
  // Whitened prior coordinates u = L^-1 (theta - theta0) ~ N(0, a^2 I); the data residual is
  // G u - r0 with G = F_w L, r0 = f_y - F_w theta0 (all p + 1 rows of the factor: exact rss).
  const Eigen::MatrixXd& F = rows.factor();
  const Eigen::MatrixXd G = F.leftCols(p) * L;
  const Eigen::VectorXd r0 = F.col(p) - F.leftCols(p) * prior.value;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(G, Eigen::ComputeThinU);
  const Eigen::VectorXd sv = svd.singularValues();
  const Eigen::VectorXd d = svd.matrixU().transpose() * r0;
  const double outside = std::max(0.0, r0.squaredNorm() - d.squaredNorm());
  struct Terms {
    double ed, ep, gamma, logdet;
  };
  // Everything in closed form from the singular values (lambda_i = sv_i^2, kappa = s^2 / a^2).
  auto terms = [&](double a2, double s2) {
    Terms t{outside, 0.0, 0.0, 0.0};
    const double kappa = s2 / a2;
    for (Eigen::Index i = 0; i < sv.size(); ++i) {
      const double l = sv(i) * sv(i);
      const double q = l + kappa;
      t.ed += d(i) * d(i) * (kappa / q) * (kappa / q);
      t.ep += l * d(i) * d(i) / (q * q);
      t.gamma += l / q;
      t.logdet += std::log(l / s2 + 1.0 / a2);
    }
    return t;
  };
  auto logEvidence = [&](double a2, double s2, const Terms& t) {
    return -0.5 * t.ed / s2 - 0.5 * t.ep / a2 - 0.5 * t.logdet -
           0.5 * m * std::log(2.0 * M_PI * s2) - 0.5 * p * std::log(a2);
  };
  // Noise variance at a fixed a: its own fixed point s^2 = rss / (m - gamma).
  auto profile = [&](double a2, double* s2) {
    for (int it = 0; it < 200; ++it) {
      const Terms t = terms(a2, *s2);
      const double next = std::max(t.ed, 1e-300) / std::max(m - t.gamma, 1.0);
      const bool done = std::abs(next - *s2) <= 1e-12 * *s2;
      *s2 = next;
      if (done) break;
    }
    return logEvidence(a2, *s2, terms(a2, *s2));
  };
  PriorScaleChoice out;
  out.method = "evidence";
  // Grid (reported; the start of the fixed point), then MacKay's updates.
  out.grid = logGrid(lo, hi, 8);
  double best_le = -std::numeric_limits<double>::infinity(), best_a = 1.0, best_s2 = 1.0;
  for (double a : out.grid) {
    double s2 = 1.0;
    const double le = profile(a * a, &s2);
    out.criterion.push_back(le);
    if (le >= best_le) {
      best_le = le;
      best_a = a;
      best_s2 = s2;
    }
  }
  double a2 = best_a * best_a, s2 = best_s2;
  int it = 0;
  for (; it < 1000; ++it) {
    const Terms t = terms(a2, s2);
    const double a2n = std::clamp(t.ep / std::max(t.gamma, 1e-300), lo * lo, hi * hi);
    const double s2n = std::max(t.ed, 1e-300) / std::max(m - t.gamma, 1.0);
    const bool done = std::abs(a2n - a2) <= 1e-10 * a2 && std::abs(s2n - s2) <= 1e-10 * s2;
    a2 = a2n;
    s2 = s2n;
    if (done) break;
  }
  const Terms t = terms(a2, s2);
  const double le = logEvidence(a2, s2, t);
  if (!(le >= best_le)) {  // the fixed point wandered off: keep the grid's best
    a2 = best_a * best_a;
    s2 = best_s2;
  }
  const Terms tf = terms(a2, s2);
  out.scale = std::sqrt(a2);
  if (hi > lo) {  // the fixed point clamped to the range, or the grid's best at its end
    if (a2 <= lo * lo * (1 + 1e-9)) out.at_edge = "low";
    if (a2 >= hi * hi * (1 - 1e-9)) out.at_edge = "high";
  }
  out.noise_variance = s2;
  out.effective_parameters = tf.gamma;
  out.log_evidence = logEvidence(a2, s2, tf);
  out.iterations = it;
  check(std::isfinite(out.scale) && std::isfinite(out.log_evidence),
        fmt::format("{}: the evidence is not finite", who));
  return out;
}

}  // namespace exid::estimators
