// exid — estimator `batch_ls`: ordinary least squares on the base regressor, streamed.
//
// The dataset is processed in chunks of samples (model.rows on slices), and every chunk of
// augmented rows [W y] is folded into an upper-triangular factor R by Householder QR of
// [R; chunk] (exid::est::RowAccumulator). Memory is O(p^2 + chunk), independent of the number of
// samples, and cond(R) = cond([W y]) — the normal matrix W^T W is never formed, so no digits are
// lost to squaring the condition number. The solve is an SVD of the column-scaled R: rank
// revealing, and a rank-deficient problem is refused with the unidentifiable directions named.
// See docs/estimators.md.
#include <fmt/format.h>

#include <chrono>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/interfaces.hpp"

namespace {

class BatchLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "batch_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "ordinary least squares, streamed in chunks (incremental Householder QR of [W y]), "
      "rank-revealing SVD solve, covariance sigma^2 (W^T W)^-1 and %std";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_int(
            "chunk_samples", 4096,
            "samples per chunk passed to the model (memory ~ chunk x rows per sample x p)", 1.0,
            1e9),
        exid::param_string("accumulate", std::string("qr"),
                           "qr: incremental Householder QR of [W y] (cond not squared); normal: "
                           "accumulate W^T W (faster, squares cond(W); for comparison)",
                           {"qr", "normal"}),
        exid::param_double("rank_tolerance", 1e-8, "",
                           "a direction is unidentifiable when its singular value of the "
                           "column-scaled W is below this times the largest",
                           0.0, 1.0, true, true),
    };
  }

  explicit BatchLs(const exid::ParamSet& p)
      : chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        method_(p.getString("accumulate") == "normal" ? exid::est::RowAccumulator::Method::Normal
                                                      : exid::est::RowAccumulator::Method::Qr) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
  }

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.accepts_prior = true;
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int p = model.numBase();
    exid::est::RowAccumulator acc(p, method_);
    exid::est::forEachChunk(model, data, chunk_, ctx, kName, 0.0, 0.95,
                            [&](const exid::Rows& r, int, int) { acc.add(r.W, r.y); });
    ctx.report(0.97, "batch_ls: solving");
    exid::Estimate e;
    if (!prior) {
      const exid::est::LsSolution s =
          exid::est::solveLeastSquares(acc, model.base().names, opt_, kName);
      exid::est::fillEstimate(&e, model, s, s.rss, s.m);
    } else {
      // Regularised least squares: the data rows divided by their noise std (from the
      // rank-tolerant fit), stacked with the prior's pseudo-observations S (theta - theta0) = 0,
      // S^T S = Sigma^-1. Directions the data do not excite fall back to the prior.
      const double noise = exid::est::noiseStdForPrior(acc, opt_.rank_tolerance);
      exid::est::RowAccumulator tot(p);
      tot.merge(acc, 1.0 / noise);
      exid::est::addPriorRows(&tot, *prior, kName);
      exid::est::SolveOptions o = opt_;
      o.unit_variance = true;
      // The prior makes the problem positive definite: no rank decision (noise-free data with
      // a prior are legitimately ill-conditioned: tiny noise std, large weights).
      o.rank_tolerance = 0.0;
      const exid::est::LsSolution s =
          exid::est::solveLeastSquares(tot, model.base().names, o, kName);
      exid::est::fillEstimate(&e, model, s, acc.residualSquared(s.theta), acc.rows());
      e.rows = acc.rows();
      e.details["noise_std"] = noise;
      e.details["prior"] = exid::est::priorDetails(*prior, s.theta, s.std);
      e.details["covariance_definition"] =
          "posterior (W^T W / noise_std^2 + Sigma_prior^-1)^-1, noise_std^2 = rss / (m - rank) of "
          "the rank-tolerant fit of the data alone";
    }
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["method"] = method_ == exid::est::RowAccumulator::Method::Qr
                      ? "incremental Householder QR of [W y], SVD of the column-scaled R"
                      : "accumulated W^T W (cond squared), eigendecomposition, SVD";
    d["samples"] = data.size();
    d["chunk_samples"] = exid::est::modelIsPerSample(model) ? chunk_ : data.size();
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ctx.report(1.0, "batch_ls: done");
    return e;
  }

 private:
  int chunk_;
  exid::est::RowAccumulator::Method method_;
  exid::est::SolveOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(BatchLs)
