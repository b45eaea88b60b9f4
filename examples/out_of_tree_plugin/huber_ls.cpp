// An out-of-tree estimator built on the installed estimator helpers (exid::estimators_common):
// least squares robust to outliers in the measured torques, by iteratively reweighted least
// squares with Huber weights w_i = min(1, k s / |r_i|), s = 1.4826 MAD(r) (a robust noise
// scale), from the ordinary least-squares start. The rows are streamed and folded by the
// helpers' RowAccumulator; only the residuals (one number per row) are kept between passes.
// Standard deviations: the weighted fit's sigma^2 (W^T D W)^-1 (Huber's first approximation).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace {

class HuberLs final : public exid::Estimator {
 public:
  static constexpr const char* kName = "huber_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "least squares with Huber weights by IRLS (example out-of-tree estimator on the installed "
      "estimator helpers)";
  static std::vector<exid::ParamDecl> params() {
    return {exid::param_double("k", 1.345, "", "Huber threshold in robust standard deviations", 0.0,
                               std::nullopt, true),
            exid::param_int("iterations", 20, "reweighting passes at most", 1.0, 1000.0),
            exid::param_double("tolerance", 1e-10, "",
                               "stop when no estimate moves by more than this times its std", 0.0)};
  }
  explicit HuberLs(const exid::ParamSet& p)
      : k_(p.getDouble("k")),
        iterations_(static_cast<int>(p.getInt("iterations"))),
        tol_(p.getDouble("tolerance")) {}

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior*, const exid::RunContext& ctx) override {
    const int p = model.numBase();
    const auto& names = model.base().names;
    std::vector<double> weight;  // per row; empty: ordinary least squares
    auto fit = [&](double lo, double hi) {
      exid::estimators::RowAccumulator acc(p);
      std::size_t row = 0;
      exid::estimators::forEachChunk(
          model, data, 256, ctx, kName, lo, hi, [&](const exid::Rows& r, int, int) {
            for (Eigen::Index i = 0; i < r.W.rows(); ++i, ++row)
              acc.addRow(r.W.row(i), r.y(i), weight.empty() ? 1.0 : std::sqrt(weight[row]));
          });
      return acc;
    };
    exid::estimators::RowAccumulator acc = fit(0.0, 0.1);
    exid::estimators::LsSolution s = exid::estimators::solveLeastSquares(acc, names, {}, kName);
    int it = 0;
    double scale = 0.0;
    for (; it < iterations_; ++it) {
      std::vector<double> res;  // residuals of the current estimate, row by row
      exid::estimators::forEachChunk(model, data, 256, ctx, kName, 0.1, 0.1,
                                     [&](const exid::Rows& r, int, int) {
                                       const Eigen::VectorXd e = r.y - r.W * s.theta;
                                       res.insert(res.end(), e.data(), e.data() + e.size());
                                     });
      std::vector<double> a(res.size());
      std::transform(res.begin(), res.end(), a.begin(), [](double v) { return std::abs(v); });
      std::nth_element(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(a.size() / 2), a.end());
      scale = 1.4826 * a[a.size() / 2];
      if (!(scale > 0.0)) break;  // an exact fit: nothing to reweight
      weight.resize(res.size());
      for (std::size_t i = 0; i < res.size(); ++i)
        weight[i] = std::min(1.0, k_ * scale / std::max(std::abs(res[i]), 1e-300));
      acc = fit(0.1 + 0.8 * it / iterations_, 0.1 + 0.8 * (it + 1) / iterations_);
      const exid::estimators::LsSolution next =
          exid::estimators::solveLeastSquares(acc, names, {}, kName);
      const double moved =
          ((next.theta - s.theta).array() / next.std.array().max(1e-300)).abs().maxCoeff();
      s = next;
      if (moved <= tol_) {
        ++it;
        break;
      }
    }
    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, s, s.rss, s.m);
    long down = 0;
    for (double w : weight) down += w < 1.0;
    e.details["estimator"] = kName;
    e.details["iterations"] = it;
    e.details["robust_scale"] = scale;
    e.details["rows_downweighted"] = static_cast<double>(down);
    ctx.report(1.0, fmt::format("{}: {} reweighting passes", kName, it));
    return e;
  }

 private:
  double k_;
  int iterations_;
  double tol_;
};

}  // namespace

EXID_REGISTER_PLUGIN(HuberLs)
