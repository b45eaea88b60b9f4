// exid — estimator `wls`: weighted least squares with one weight per equation (Gautier):
//   1. OLS on all rows;
//   2. for each equation e (Rows::equation: joint, wrench component, ...), the residual
//      variance sigma_e^2 = ||y_e - W_e theta||^2 / (m_e - p_e), p_e = number of base parameters
//      whose column is non-zero in that equation;
//   3. the rows of equation e are divided by sigma_e and least squares is solved again; the
//      covariance is sigma_w^2 (W^T S^-1 W)^-1 with sigma_w^2 = weighted rss / (m - p) (~1).
// One pass over the data: each equation's rows are compressed into their own triangular factor
// R_e (Householder QR of [W_e y_e]); residuals per equation follow exactly from R_e, and the
// weighted problem is the QR of the stacked R_e / sigma_e. Steps 2-3 may be iterated.
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <map>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/interfaces.hpp"

namespace {

using exid::estimators::RowAccumulator;

class Wls : public exid::Estimator {
 public:
  static constexpr const char* kName = "wls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "weighted least squares, each equation weighted by the inverse of its residual standard "
      "deviation from a first OLS pass (Gautier); covariance of the weighted problem";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_int("iterations", 2,
                        "weighting passes: 1 = Gautier's OLS -> sigma_e -> WLS; 2 (default) "
                        "re-estimates sigma_e from the first WLS residuals, which removes the OLS "
                        "misfit from sigma_e of precise equations (cheap: on the compressed data)",
                        1.0, 50.0),
        exid::param_int("chunk_samples", 4096, "samples per chunk passed to the model", 1.0, 1e9),
        exid::param_int("max_equations", 1000,
                        "refuse more distinct equations than this (each keeps a (p+1)^2 factor)",
                        1.0, 1e6),
        exid::estimators::rankToleranceParam(),
    };
  }

  explicit Wls(const exid::ParamSet& p)
      : iterations_(static_cast<int>(p.getInt("iterations"))),
        chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        max_eq_(static_cast<int>(p.getInt("max_equations"))) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
  }

  exid::EstimatorSpecs specs() const override { return exid::estimators::streamingSpecs(); }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int p = model.numBase();
    const std::map<int, RowAccumulator> acc = compressRows(model, data, ctx);

    // ---- 1. OLS
    RowAccumulator all(p);
    for (const auto& [eq, a] : acc) all.merge(a);
    const std::vector<std::string>& names = model.base().names;
    const exid::estimators::LsSolution ols = firstPass(all, names, prior, p);
    const long m = all.rows();

    // ---- 2-3. weights and WLS
    Eigen::VectorXd theta = ols.theta;
    exid::estimators::LsSolution sol;
    exid::Json eq_table = exid::Json::array();
    for (int it = 0; it < iterations_; ++it) {
      if (ctx.shouldStop()) throw exid::Error("wls: stopped while re-weighting");
      sol = weightedPass(acc, all, theta, prior, names, &eq_table);
      theta = sol.theta;
    }
    double rss_unweighted = 0.0;
    for (const auto& [eq, a] : acc) rss_unweighted += a.residualSquared(theta);

    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, sol, rss_unweighted, m);
    if (prior) {
      e.rows = m;
      e.details["prior"] = exid::estimators::priorDetails(*prior, theta, sol.std);
      e.details["covariance_definition"] =
          "posterior (W^T S^-1 W + Sigma_prior^-1)^-1 of the weighted rows stacked with the prior";
    }
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["equations"] = eq_table;
    d["iterations"] = iterations_;
    d["weighting"] =
        "rows of equation e divided by sigma_e = sqrt(||y_e - W_e theta||^2 / (m_e - p_e)), theta "
        "from "
        "the previous pass (OLS first)";
    exid::Json o = exid::Json::object();
    o["value"] =
        exid::Json(std::vector<double>(ols.theta.data(), ols.theta.data() + ols.theta.size()));
    o["std"] = exid::Json(std::vector<double>(ols.std.data(), ols.std.data() + ols.std.size()));
    o["sigma"] = std::sqrt(ols.sigma2);
    o["cond_W"] = ols.cond_W;
    d["ols"] = o;
    d["samples"] = data.size();
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ctx.report(1.0, "wls: done");
    return e;
  }

 private:
  using Json = exid::Json;

  /// Every row, compressed per equation (one pass over the data).
  std::map<int, RowAccumulator> compressRows(const exid::ObservationModel& model,
                                             const exid::Dataset& data,
                                             const exid::RunContext& ctx) const {
    std::map<int, RowAccumulator> acc;
    std::map<int, std::vector<int>> idx;
    exid::estimators::forEachChunk(
        model, data, chunk_, ctx, kName, 0.0, 0.9, [&](const exid::Rows& r, int, int) {
          for (auto& [eq, v] : idx) v.clear();
          const bool labelled = r.equation.size() == static_cast<std::size_t>(r.y.size());
          for (Eigen::Index i = 0; i < r.y.size(); ++i)
            idx[labelled ? r.equation[static_cast<std::size_t>(i)] : 0].push_back(
                static_cast<int>(i));
          exid::check(
              static_cast<int>(idx.size()) <= max_eq_,
              fmt::format("wls: the model labels more than max_equations = {} distinct equations; "
                          "per-equation weighting needs many rows per equation",
                          max_eq_));
          for (const auto& [eq, v] : idx) {
            exid::estimators::addEquationRows(r, v, eq, &acc);
          }
        });
    return acc;
  }

  /// The first (unweighted) pass. With a prior, the data alone may not identify every
  /// direction: the first pass is the rank-tolerant (minimum-norm) fit, whose residuals give the
  /// weights.
  exid::estimators::LsSolution firstPass(const RowAccumulator& all,
                                         const std::vector<std::string>& names,
                                         const exid::Prior* prior, int p) const {
    exid::estimators::LsSolution ols;
    if (prior) {
      int rank = 0;
      ols.theta = exid::estimators::solveMinimumNorm(all, opt_.rank_tolerance, &rank);
      ols.std = Eigen::VectorXd::Constant(p, NAN);
      ols.rss = all.residualSquared(ols.theta);
      ols.sigma2 = ols.rss / static_cast<double>(std::max<long>(1, all.rows() - rank));
      ols.cond_W = NAN;
    } else {
      ols = exid::estimators::solveLeastSquares(all, names, opt_, "wls (first OLS pass)");
    }
    return ols;
  }

  /// One weighting pass: each equation's residual std at theta, its rows divided by it (floored),
  /// least squares again (with the prior stacked). eq_table: the weights.
  exid::estimators::LsSolution weightedPass(const std::map<int, RowAccumulator>& acc,
                                            const RowAccumulator& all, const Eigen::VectorXd& theta,
                                            const exid::Prior* prior,
                                            const std::vector<std::string>& names,
                                            exid::Json* eq_table) const {
    const int p = all.cols();
    const long m = all.rows();
    std::map<int, double> sigma;
    std::map<int, int> params_in;
    double smax = 0.0;
    for (const auto& [eq, a] : acc) {
      const Eigen::VectorXd nrm = a.columnNorms();
      const double big = nrm.maxCoeff();
      int pe = 0;
      for (Eigen::Index j = 0; j < nrm.size(); ++j) pe += nrm(j) > 1e-12 * big ? 1 : 0;
      double dof = static_cast<double>(a.rows() - pe);
      if (dof <= 0)
        dof = static_cast<double>(a.rows()) * static_cast<double>(m - p) / static_cast<double>(m);
      const double rss = a.residualSquared(theta);
      sigma[eq] = std::sqrt(std::max(rss, 0.0) / std::max(dof, 1e-300));
      params_in[eq] = pe;
      smax = std::max(smax, sigma[eq]);
    }
    // Floor: an equation fitted exactly (noise-free data) must not get an infinite weight.
    double floor = smax > 0 ? 1e-6 * smax : 1.0;
    // With a prior the weights' absolute size matters: not above 1e9 / rms(y) (as batch_ls).
    if (prior)
      floor = std::max(floor, 1e-9 * all.factor().col(p).norm() /
                                  std::sqrt(static_cast<double>(std::max<long>(1, m))));
    RowAccumulator weighted(p);
    *eq_table = exid::Json::array();
    for (const auto& [eq, a] : acc) {
      const double s = std::max(sigma[eq], floor);
      weighted.merge(a, 1.0 / s);
      exid::Json row = exid::Json::object();
      row["equation"] = eq;
      row["rows"] = Json(static_cast<long long>(a.rows()));
      row["parameters_in_equation"] = params_in[eq];
      row["residual_std"] = sigma[eq];
      row["weight"] = 1.0 / s;
      eq_table->push_back(row);
    }
    if (prior) {
      // Weighted rows are in units of their noise std: stack the prior's pseudo-observations.
      exid::estimators::addPriorRows(&weighted, *prior, kName);
      exid::estimators::SolveOptions o = opt_;
      o.unit_variance = true;
      // The prior makes the problem positive definite: no rank decision (noise-free data with
      // a prior are legitimately ill-conditioned: tiny noise std, large weights).
      o.rank_tolerance = 0.0;
      return exid::estimators::solveLeastSquares(weighted, names, o, kName);
    }
    return exid::estimators::solveLeastSquares(weighted, names, opt_, kName);
  }
  int iterations_, chunk_, max_eq_;
  exid::estimators::SolveOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Wls)
