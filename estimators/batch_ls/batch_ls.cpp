// exid — estimator `batch_ls`: ordinary least squares on the base regressor, streamed.
//
// The dataset is processed in chunks of samples (model.rows on slices) and folded into a
// (p+1) x (p+1) factor of [W y] (exid::estimators::RowAccumulator): memory is O(p^2 + chunk),
// independent of the number of samples. Two ways to fold:
//   qr:     incremental Householder QR of [R; chunk]; cond(R) = cond([W y]), nothing squared;
//   normal: the Gram matrix [W y]^T [W y] (a symmetric rank-k update, BLAS-3 speed); squares
//           cond(W), so the solution's relative error grows like eps cond(W)^2.
//   auto (default): normal, then the column-scaled cond(W) is checked; above normal_max_cond
//           (1e3: at most ~2e-10 relative error from squaring) the data are folded again by
//           QR. Well-conditioned problems (the usual case: an excited robot has cond ~ 10-100)
//           get the speed, ill-conditioned ones the accuracy; the report says which was used.
// The solve is an SVD of the column-scaled factor: rank revealing, and a rank-deficient problem
// is refused with the unidentifiable directions named. See docs/estimators.md.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/interfaces.hpp"

namespace {

class BatchLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "batch_ls";
  static constexpr const char* kVersion = "1.1";
  static constexpr double kMinRelativeRss = 1e-8;
  static constexpr const char* kDoc =
      "ordinary least squares, streamed in chunks (incremental Householder QR of [W y]), "
      "rank-revealing SVD solve, covariance sigma^2 (W^T W)^-1 and %std";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_int(
            "chunk_samples", 128,
            "samples per chunk passed to the model (memory ~ chunk x rows per sample x p)", 1.0,
            1e9),
        exid::param_string(
            "accumulate", std::string("auto"),
            "qr: incremental Householder QR of [W y] (cond not squared); normal: accumulate "
            "[W y]^T [W y] (about twice as fast, squares cond(W)); auto: normal, and a second "
            "pass by qr when the column-scaled cond(W) exceeds normal_max_cond",
            {"auto", "qr", "normal"}),
        exid::param_double("normal_max_cond", 1e3, "",
                           "accumulate: auto keeps the normal equations while the column-scaled "
                           "cond(W) is at most this (relative error ~ 2.2e-16 cond^2)",
                           1.0, 1e8),
        exid::param_int(
            "threads", 0,
            "threads building the rows (0: the cores this process may run on, at most 8); each "
            "thread's block of samples is merged in order, so the result is the "
            "same for any count",
            0, 256),
        exid::estimators::rankToleranceParam(),
    };
  }

  explicit BatchLs(const exid::ParamSet& p)
      : chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        accumulate_(p.getString("accumulate")),
        normal_max_cond_(p.getDouble("normal_max_cond")),
        threads_(exid::resolveThreads(p.getInt("threads"))) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
  }

  exid::EstimatorSpecs specs() const override { return exid::estimators::streamingSpecs(); }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    using Method = exid::estimators::RowAccumulator::Method;
    auto fold = [&](Method m, double lo, double hi) {
      return exid::estimators::accumulateRows(model, data, chunk_, ctx, kName, lo, hi, m, threads_);
    };
    const bool automatic = accumulate_ == "auto";
    exid::estimators::RowAccumulator acc =
        fold(accumulate_ == "qr" ? Method::Qr : Method::Normal, 0.0, automatic ? 0.5 : 0.95);
    exid::Json choice = exid::Json::object();
    choice["requested"] = accumulate_;
    if (automatic) {
      const double kappa = acc.scaledCondition();
      choice["cond_W_scaled_from_gram"] = kappa;
      choice["normal_max_cond"] = normal_max_cond_;
      // The residual from the Gram matrix is yTy - 2 thetaT WTy + thetaT WTW theta: its
      // absolute error is ~eps yTy, so a fit closer than 1e-8 yTy (noise-free data) needs QR
      // for a meaningful residual and sigma^2.
      double rel_rss = HUGE_VAL;
      if (kappa <= normal_max_cond_) {
        const double yy = acc.ySquaredNorm();
        if (yy > 0.0) rel_rss = acc.minimumResidualSquared() / yy;
        choice["rss_over_yTy"] = rel_rss;
      }
      if (!(kappa <= normal_max_cond_) || !(rel_rss >= kMinRelativeRss)) {
        const bool cond_bad = !(kappa <= normal_max_cond_);
        ctx.report(0.5, "batch_ls: folding again by QR");
        acc = fold(Method::Qr, 0.5, 0.95);
        choice["reason"] =
            cond_bad ? fmt::format(
                           "column-scaled cond(W) = {:.4g} > normal_max_cond = {:g}: the normal "
                           "equations would lose ~{:.0f} digits, so the data were folded "
                           "again by Householder QR",
                           kappa, normal_max_cond_, std::log10(kappa * kappa))
                     : fmt::format(
                           "residual ||y - W theta||^2 = {:.3g} yTy < {:g} yTy: too small to "
                           "resolve from the Gram matrix (noise-free data?), so the data were "
                           "folded again by Householder QR",
                           rel_rss, kMinRelativeRss);
      } else {
        choice["reason"] = fmt::format(
            "column-scaled cond(W) = {:.4g} <= normal_max_cond = {:g}: normal equations "
            "(relative error <~ {:.1e})",
            kappa, normal_max_cond_, 2.2e-16 * kappa * kappa);
      }
    }
    choice["used"] = acc.method() == Method::Qr ? "qr" : "normal";
    ctx.report(0.97, "batch_ls: solving");
    exid::Estimate e;
    if (!prior) {
      const exid::estimators::LsSolution s =
          exid::estimators::solveLeastSquares(acc, model.base().names, opt_, kName);
      exid::estimators::fillEstimate(&e, model, s, s.rss, s.m);
    } else {
      // Regularised least squares: the data rows divided by their noise std (from the
      // rank-tolerant fit), stacked with the prior's pseudo-observations S (theta - theta0) = 0,
      // S^T S = Sigma^-1. Directions the data do not excite fall back to the prior.
      double noise = 0.0;
      const exid::estimators::LsSolution s = exid::estimators::solveWithPrior(
          acc, *prior, model.base().names, opt_, kName, 1.0, &noise);
      exid::estimators::fillEstimate(&e, model, s, acc.residualSquared(s.theta), acc.rows());
      e.rows = acc.rows();
      e.details["noise_std"] = noise;
      e.details["prior"] = exid::estimators::priorDetails(*prior, s.theta, s.std);
      e.details["covariance_definition"] =
          "posterior (W^T W / noise_std^2 + Sigma_prior^-1)^-1, noise_std^2 = rss / (m - rank) of "
          "the rank-tolerant fit of the data alone";
    }
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["method"] = acc.method() == Method::Qr
                      ? "incremental Householder QR of [W y], SVD of the column-scaled R"
                      : "accumulated [W y]^T [W y] (cond squared), eigendecomposition, SVD";
    d["accumulate"] = choice;
    d["samples"] = data.size();
    d["chunk_samples"] = exid::estimators::modelIsPerSample(model) ? chunk_ : data.size();
    d["threads"] = threads_;
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ctx.report(1.0, "batch_ls: done");
    return e;
  }

 private:
  int chunk_;
  std::string accumulate_;
  double normal_max_cond_;
  int threads_ = 1;
  exid::estimators::SolveOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(BatchLs)
