// exid — estimator `consistent_ls`: (weighted) least squares of the base parameters with the
// STANDARD parameters behind them physically consistent by construction.
//
//   theta_b = K pi(z),  pi(z): per body the log-Cholesky map of the pseudo-inertia (J = U U^T,
//   U upper triangular with exp on the diagonal: mass > 0, inertia about the COM positive
//   definite, triangle inequalities), rotor inertias and friction coefficients Ia, Fc, Fv >= 0
//   (scaled, bound-constrained), offsets and any other column free (scaled);
//   minimise ||F_w K pi(z) - f_y||^2 (+ prior)
// where [F_w f_y] is the QR-compressed factor of the (noise-normalised) rows [W y] stacked with
// the prior's pseudo-observations, so one evaluation costs O(p * n_full), not O(rows). NLopt
// (LD_LBFGS by default) with exact gradients, then a Levenberg-Marquardt polish with the exact
// Jacobian. The prior's scale is fixed or chosen on the identification data (blocked
// cross-validation or evidence, exid/estimators/prior_scale.hpp). See docs/consistent.md.
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <nlopt.hpp>
#include <optional>

#include "consistent_problem.hpp"
#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/estimators/prior_scale.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"

namespace exid::consistent_ls {
namespace {

class ConsistentLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "consistent_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "least squares of the base parameters with physically consistent standard parameters behind "
      "them (log-Cholesky pseudo-inertia per body, Ia/Fc/Fv >= 0), per-equation weights, optional "
      "prior (scale fixed, or by blocked cross-validation or evidence); NLopt with exact "
      "gradients + Levenberg-Marquardt polish";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_string(
            "weighting", std::string("equation"),
            "equation: each equation's rows divided by its residual std (wls, Gautier); "
            "none: one std for all rows (OLS)",
            {"equation", "none"}),
        exid::param_double("prior_scale", 1.0, "",
                           "with prior_scale_selection: none, every prior standard deviation "
                           "is multiplied by this",
                           0.0, std::nullopt, true),
        exid::param_string(
            "prior_on", std::string("standard"),
            "standard: the prior acts on the standard parameters inside the consistent fit "
            "(||D^-1 (pi - pi0)||^2, D = the prior's standard deviations; needs a prior from the "
            "robot, otherwise base is used); base: on the base parameters only (K pi), the "
            "standard parameters are then any consistent completion",
            {"standard", "base"}),
        exid::param_string(
            "prior_scale_selection", std::string("none"),
            "none: prior_scale as given; cv: blocked cross-validation on the identification "
            "samples (cv_blocks contiguous blocks) over a log grid in prior_scale_range; "
            "evidence: type-II maximum likelihood (MacKay) of the scale and a common noise "
            "variance. Both on the weighted linear (prior-regularised) problem",
            {"none", "cv", "evidence"}),
        exid::param_int("cv_blocks", 5,
                        "contiguous blocks of samples for prior_scale_selection: cv", 2.0, 1000.0),
        exid::param_doubles("prior_scale_range", std::vector<double>{0.01, 100.0}, "",
                            "[lo, hi] of the scales searched by prior_scale_selection (cv: 8 "
                            "log-spaced candidates per decade)",
                            2, 2),
        exid::param_string(
            "algorithm", std::string("LD_LBFGS"),
            "NLopt algorithm (exact gradients); none: Levenberg-Marquardt only",
            {"LD_LBFGS", "LD_SLSQP", "LD_MMA", "LD_TNEWTON_PRECOND_RESTART", "none"}),
        exid::param_int("max_evaluations", 3000, "NLopt evaluations (each O(p n_full))", 1.0, 1e8),
        exid::param_int("polish_iterations", 300,
                        "Levenberg-Marquardt iterations after NLopt (0: none)", 0.0, 1e6),
        exid::param_string(
            "start", std::string("best"),
            "nominal: the robot description projected to consistency; unconstrained: "
            "the (prior-regularised) least-squares solution completed with the nominal "
            "values and projected; best: whichever fits better",
            {"nominal", "unconstrained", "best"}),
        exid::param_int("chunk_samples", 4096, "samples per chunk passed to the model", 1.0, 1e9),
        exid::param_int("max_equations", 1000, "refuse more distinct equations than this", 1.0,
                        1e6),
        exid::estimators::rankToleranceParam(),
    };
  }

  explicit ConsistentLs(const exid::ParamSet& p)
      : weighting_(p.getString("weighting")),
        prior_on_(p.getString("prior_on")),
        algorithm_(p.getString("algorithm")),
        start_(p.getString("start")),
        scale_selection_(p.getString("prior_scale_selection")),
        scale_range_(p.getDoubles("prior_scale_range")),
        prior_scale_(p.getDouble("prior_scale")),
        cv_blocks_(static_cast<int>(p.getInt("cv_blocks"))),
        max_eval_(static_cast<int>(p.getInt("max_evaluations"))),
        polish_(static_cast<int>(p.getInt("polish_iterations"))),
        chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        max_eq_(static_cast<int>(p.getInt("max_equations"))) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
    exid::check(
        scale_range_.size() == 2 && scale_range_[0] > 0 && scale_range_[1] >= scale_range_[0] &&
            std::isfinite(scale_range_[1]),
        fmt::format("{}: prior_scale_range must be [lo, hi] with 0 < lo <= hi < inf", kName));
  }

  exid::EstimatorSpecs specs() const override { return exid::estimators::streamingSpecs(); }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int p = model.numBase();
    const exid::BaseParameters& base = model.base();
    LinearStage lin = linearStage(model, data, prior, ctx);

    // ---- the consistent problem (setObjective)
    const StandardMap map(base.full_names, model.fullNominal());
    const int nfull = static_cast<int>(base.full_names.size());
    const bool std_prior = lin.used_prior && prior_on_ == "standard" &&
                           lin.used_prior->standard_value.size() == nfull &&
                           lin.used_prior->standard_std.size() == nfull;
    Problem P;
    P.map = &map;
    P.ctx = &ctx;
    Eigen::VectorXd dinv;  // D^-1 (standard prior)
    setObjective(lin, base.K, p, nfull, std_prior, &P, &dinv, kName);
    const Eigen::VectorXd pi0 = std_prior ? lin.used_prior->standard_value : model.fullNominal();
    StartPoint st = startPoint(map, P, base.K, lin.unc.theta, pi0, dinv, std_prior, start_);
    P.best_f = HUGE_VAL;
    const double f_start = P.value(st.z0, nullptr);
    const double f_unc = (P.A * st.pi_unc - P.b).squaredNorm();
    ctx.report(0.85, fmt::format("{}: optimising {} variables", kName, map.nz()));

    std::vector<double> lb;
    map.lowerBounds(&lb);
    for (int k = 0; k < map.nz(); ++k)
      st.z0(k) = std::max(st.z0(k), lb[static_cast<std::size_t>(k)]);
    const std::string stop = runNlopt(P, lb, st.z0);
    Eigen::VectorXd z = P.best_z.size() == map.nz() ? P.best_z : st.z0;
    const long nlopt_evals = P.evaluations;
    const int lm_iters = polishLm(P, lb, &z);
    if (ctx.shouldStop()) throw exid::Error(fmt::format("{}: stopped", kName));

    // ---- results
    const Eigen::VectorXd pi = map.pi(z);
    const Eigen::VectorXd theta = base.K * pi;
    const double f_final = (P.A * pi - P.b).squaredNorm();
    int lin_rank = 0;
    const Eigen::MatrixXd cov = linearisedCovariance(map, P, base.K, z, pi, lb, &lin_rank);

    double rss_c = 0.0, rss_u = 0.0;
    for (const auto& [eq, a] : lin.acc) {
      rss_c += a.residualSquared(theta);
      rss_u += a.residualSquared(lin.unc.theta);
    }
    const long m = lin.m;
    const double rms_c = std::sqrt(rss_c / static_cast<double>(m));
    const double rms_u = std::sqrt(rss_u / static_cast<double>(m));

    exid::estimators::LsSolution sol = lin.unc;
    sol.theta = theta;
    sol.covariance = cov;
    sol.std = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
    sol.rss = f_final;
    sol.sigma2 = f_final / static_cast<double>(std::max<long>(1, lin.total.rows() - p));
    // (with the standard prior, f_final also holds the standard prior's terms)
    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, sol, rss_c, m);
    e.rows = m;
    Json& d = e.details;
    d["estimator"] = kName;
    d["weighting"] = weighting_;
    d["equations"] = lin.eq_table;
    d["covariance_definition"] =
        "linearised: J (J^T F^T F J)^+ J^T with J = K dpi/dz at the estimate (variables at an "
        "active "
        "bound fixed), F the factor of the noise-normalised rows" +
        std::string(prior ? " stacked with the prior" : "") +
        "; equals the unconstrained covariance when no constraint is active";
    d["residual_rms_unconstrained"] = rms_u;
    d["residual_rms_ratio"] = rms_u > 0 ? rms_c / rms_u : 1.0;
    // Distance from the unconstrained (prior-regularised) least-squares solution in units of its
    // covariance: sqrt((theta - theta_u)^T Cov_u^-1 (theta - theta_u)) = ||F_w (theta - theta_u)||.
    d["mahalanobis_from_unconstrained"] = (lin.Fw * (theta - lin.unc.theta)).norm();
    Json u = Json::object();
    u["value"] = Json(toStd(lin.unc.theta));
    u["std"] = Json(toStd(lin.unc.std));
    u["cost"] = f_unc;
    d["unconstrained"] = u;
    Json o = Json::object();
    o["algorithm"] = algorithm_;
    o["start"] = st.started;
    o["bodies_projected_at_start"] =
        st.started == "nominal" ? st.projected_nominal : st.projected_unc;
    o["cost_start"] = f_start;
    o["cost_final"] = f_final;
    o["cost_unconstrained"] = f_unc;
    o["nlopt_evaluations"] = Json(static_cast<long long>(nlopt_evals));
    o["nlopt_stop"] = stop;
    o["lm_iterations"] = lm_iters;
    o["variables"] = map.nz();
    o["linearised_rank"] = lin_rank;
    d["optimization"] = o;
    if (lin.used_prior) priorDetails(lin, theta, sol.std, pi, dinv, std_prior, nfull, d);

    // Consistent standard parameters (exid export writes them into a URDF).
    Json sp = Json::object();
    sp["names"] = Json(base.full_names);
    sp["values"] = Json(toStd(pi));
    d["standard_parameters"] = sp;
    bool all_ok = true;
    d["bodies"] = bodyChecks(map, pi, &all_ok);
    d["consistent"] = all_ok;
    {
      Json w = plausibilityWarnings(map, pi, model.fullNominal(), rms_c, rms_u, kName);
      if (w.size() > 0 && !d.find("warnings")) d["warnings"] = exid::Json::array();
      for (std::size_t i = 0; i < w.size(); ++i) d["warnings"].push_back(w.at(i));
    }
    d["samples"] = data.size();
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    writeStandardCsv(ctx, base.full_names, pi, d);
    ctx.report(1.0, fmt::format("{}: done", kName));
    return e;
  }

 private:
  /// The rows, per equation (and per block of samples and equation for cross-validation, when
  /// blocks > 0), compressed chunk by chunk.
  EquationRows compressRows(const exid::ObservationModel& model, const exid::Dataset& data,
                            const exid::RunContext& ctx, int blocks) const {
    const int p = model.numBase();
    const int n_samples = data.size();
    EquationRows out;
    std::map<int, RowAccumulator>& acc = out.acc;
    std::vector<std::map<int, RowAccumulator>>& block_acc = out.blocks;
    block_acc.resize(static_cast<std::size_t>(blocks));
    std::map<int, std::vector<int>> idx;
    std::vector<int> sample_of_row, order;
    exid::estimators::forEachChunk(
        model, data, chunk_, ctx, kName, 0.0, 0.8, [&](const exid::Rows& r, int begin, int end) {
          for (auto& [eq, v] : idx) v.clear();
          const bool labelled = r.equation.size() == static_cast<std::size_t>(r.y.size());
          if (blocks > 0) exid::estimators::rowTimeOrder(r, end - begin, &sample_of_row, &order);
          for (Eigen::Index i = 0; i < r.y.size(); ++i)
            idx[labelled ? r.equation[static_cast<std::size_t>(i)] : 0].push_back(
                static_cast<int>(i));
          exid::check(
              static_cast<int>(idx.size()) <= max_eq_,
              fmt::format("{}: the model labels more than max_equations = {} distinct equations",
                          kName, max_eq_));
          for (const auto& [eq, v] : idx) {
            if (v.empty()) continue;
            const auto n = static_cast<Eigen::Index>(v.size());
            exid::estimators::addEquationRows(r, v, eq, &acc);
            for (Eigen::Index k = 0; k < n && blocks > 0; ++k) {
              // contiguous blocks in time: sample s of n_samples -> block s * blocks / n_samples
              const long s =
                  begin + sample_of_row[static_cast<std::size_t>(v[static_cast<std::size_t>(k)])];
              const auto blk = static_cast<std::size_t>(
                  std::min<long>(blocks - 1, s * blocks / std::max(1, n_samples)));
              auto bt = block_acc[blk].find(eq);
              if (bt == block_acc[blk].end())
                bt = block_acc[blk]
                         .emplace(eq, RowAccumulator(p, RowAccumulator::Method::Qr, 64))
                         .first;
              bt->second.addRow(r.W.row(v[static_cast<std::size_t>(k)]),
                                r.y(v[static_cast<std::size_t>(k)]));
            }
          }
        });
    return out;
  }

  /// Each equation's residual std (weighting: equation) or one for all rows, floored so that
  /// exactly fitted data get finite weights; returns the rows divided by it (eq_table: the
  /// weights).
  RowAccumulator weightRows(const std::map<int, RowAccumulator>& acc, const RowAccumulator& all,
                            int p, bool has_prior, std::map<int, double>* sigma,
                            Json* eq_table) const {
    const long m = all.rows();
    int rank = 0;
    const Eigen::VectorXd theta_mn =
        exid::estimators::solveMinimumNorm(all, opt_.rank_tolerance, &rank);
    RowAccumulator weighted(p);
    double smax = 0.0;
    const double global = std::sqrt(std::max(0.0, all.residualSquared(theta_mn)) /
                                    static_cast<double>(std::max<long>(1, m - rank)));
    for (const auto& [eq, a] : acc) {
      double s = global;
      if (weighting_ == "equation") {
        const Eigen::VectorXd nrm = a.columnNorms();
        const double big = nrm.maxCoeff();
        int pe = 0;
        for (Eigen::Index j = 0; j < nrm.size(); ++j) pe += nrm(j) > 1e-12 * big ? 1 : 0;
        double dof = static_cast<double>(a.rows() - pe);
        if (dof <= 0)
          dof = static_cast<double>(a.rows()) * static_cast<double>(std::max<long>(1, m - rank)) /
                static_cast<double>(m);
        s = std::sqrt(std::max(0.0, a.residualSquared(theta_mn)) / std::max(dof, 1e-300));
      }
      (*sigma)[eq] = s;
      smax = std::max(smax, s);
    }
    // Floor: exactly fitted (noise-free) data must not get infinite weights.
    double yrms = all.factor().col(p).norm() / std::sqrt(static_cast<double>(std::max<long>(1, m)));
    const double floor =
        std::max(smax > 0 ? 1e-6 * smax : 0.0, (has_prior ? 1e-9 : 1e-12) * std::max(yrms, 1e-300));
    for (auto& [eq, s] : *sigma) {
      Json row = Json::object();
      row["equation"] = eq;
      row["rows"] = Json(static_cast<long long>(acc.at(eq).rows()));
      row["residual_std"] = s;
      s = std::max(s, floor);
      row["weight"] = 1.0 / s;
      eq_table->push_back(row);
      weighted.merge(acc.at(eq), 1.0 / s);
    }
    return weighted;
  }

  /// The prior, its scale fixed or chosen on the weighted rows (docs/consistent.md); details in
  /// scale_details.
  std::optional<exid::Prior> scalePrior(const exid::Prior& prior, bool select_cv,
                                        const std::vector<std::map<int, RowAccumulator>>& blocks,
                                        const std::map<int, double>& sigma,
                                        const RowAccumulator& weighted, int p,
                                        Json* scale_details) const {
    double scale = prior_scale_;
    (*scale_details)["method"] = "fixed";
    if (scale_selection_ != "none") {
      exid::estimators::PriorScaleChoice c;
      if (select_cv) {
        std::vector<RowAccumulator> folds;
        for (const auto& blk : blocks) {
          RowAccumulator f(p);
          for (const auto& [eq, a] : blk) f.merge(a, 1.0 / sigma.at(eq));
          folds.push_back(std::move(f));
        }
        c = exid::estimators::selectPriorScaleCv(
            folds, prior, exid::estimators::logGrid(scale_range_[0], scale_range_[1], 8), kName);
      } else {
        c = exid::estimators::selectPriorScaleEvidence(weighted, prior, scale_range_[0],
                                                       scale_range_[1], kName);
      }
      scale = c.scale;
      *scale_details = c.toJson();
      if (const std::string doubt = c.edgeText(kName); !doubt.empty())
        (*scale_details)["suspect"] = doubt;
    }
    (*scale_details)["scale"] = scale;
    return exid::estimators::scaledPrior(prior, scale);
  }

  /// The rows compressed per equation, noise-normalised, stacked with the prior: one factor, and
  /// its unconstrained least-squares solution.
  LinearStage linearStage(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) const {
    const int p = model.numBase();
    const std::vector<std::string>& names = model.base().names;
    const bool select_cv = prior && scale_selection_ == "cv";
    EquationRows rows = compressRows(model, data, ctx, select_cv ? cv_blocks_ : 0);
    LinearStage lin;
    lin.acc = std::move(rows.acc);
    RowAccumulator all(p);
    for (const auto& [eq, a] : lin.acc) all.merge(a);
    lin.m = all.rows();
    if (!prior) {
      // Without a prior every base parameter must be identified by the data (the message names
      // the directions that are not); with one, they fall back to it.
      (void)exid::estimators::solveLeastSquares(all, names, opt_, kName);
    }
    std::map<int, double> sigma;
    lin.weighted = weightRows(lin.acc, all, p, prior != nullptr, &sigma, &lin.eq_table);
    if (prior)
      lin.used_prior =
          scalePrior(*prior, select_cv, rows.blocks, sigma, lin.weighted, p, &lin.scale_details);
    lin.total = lin.weighted;
    if (lin.used_prior) exid::estimators::addPriorRows(&lin.total, *lin.used_prior, kName);
    exid::estimators::SolveOptions uo = opt_;
    uo.unit_variance = true;
    if (prior) uo.rank_tolerance = 0.0;  // positive definite with the prior
    lin.unc = exid::estimators::solveLeastSquares(lin.total, names, uo, kName);
    const Eigen::MatrixXd& F = lin.total.factor();
    lin.Fw = F.leftCols(p);
    lin.fy = F.col(p);
    return lin;
  }

  /// NLopt from z0 (algorithm: none: not run); the best point is kept in P. Returns how it
  /// stopped.
  std::string runNlopt(Problem& P, const std::vector<double>& lb, const Eigen::VectorXd& z0) const {
    std::string stop = "not run";
    if (algorithm_ == "none") return stop;
    nlopt::opt o(algorithmFromName(algorithm_), static_cast<unsigned>(P.map->nz()));
    o.set_lower_bounds(lb);
    o.set_min_objective(nloptObjective, &P);
    o.set_maxeval(max_eval_);
    o.set_ftol_rel(1e-14);
    o.set_xtol_rel(1e-12);
    std::vector<double> x(z0.data(), z0.data() + z0.size());
    double fx = 0;
    try {
      const nlopt::result r = o.optimize(x, fx);
      stop = fmt::format("nlopt result {}", static_cast<int>(r));
    } catch (const nlopt::forced_stop&) {
      throw exid::Error(fmt::format("{}: stopped", kName));
    } catch (const std::exception& e) {
      stop = fmt::format("nlopt: {} (best point kept)", e.what());
    }
    return stop;
  }

  /// d["prior"]: the prior's details, its scale and where it acts.
  void priorDetails(const LinearStage& lin, const Eigen::VectorXd& theta,
                    const Eigen::VectorXd& theta_std, const Eigen::VectorXd& pi,
                    const Eigen::VectorXd& dinv, bool std_prior, int nfull, Json& d) const {
    d["prior"] = exid::estimators::priorDetails(*lin.used_prior, theta, theta_std);
    d["prior"]["scale"] = lin.scale_details;
    if (const exid::Json* doubt = lin.scale_details.find("suspect")) {
      if (!d.find("suspect")) d["suspect"] = exid::Json::array();
      d["suspect"].push_back(*doubt);
      if (!d.find("warnings")) d["warnings"] = exid::Json::array();
      d["warnings"].push_back(*doubt);
    }
    d["prior"]["on"] = std_prior ? "standard" : "base";
    if (std_prior) {
      // ||D^-1 (pi - pi0)||: the standard parameters' distance from the prior, in its std.
      d["prior"]["standard_mahalanobis"] =
          dinv.cwiseProduct(pi - lin.used_prior->standard_value).norm();
      d["prior"]["standard_parameters"] = nfull;
    } else if (prior_on_ == "standard") {
      d["prior"]["on_note"] =
          "prior_on: standard asked, but the prior has no standard parameters (from: study): "
          "it acts on the base parameters";
    }
  }
  /// Levenberg-Marquardt on r(z) = A pi(z) - b with the exact Jacobian A dpi/dz; variables with
  /// a lower bound stay feasible (projected steps, active bounds held). Returns the iterations.
  int polishLm(Problem& P, const std::vector<double>& lb, Eigen::VectorXd* z) const {
    if (polish_ <= 0) return 0;
    const StandardMap& map = *P.map;
    const int n = map.nz();
    double f = P.value(*z, nullptr);
    double lambda = 1e-6;
    int it = 0, small = 0;
    for (; it < polish_ && small < 3; ++it) {
      if (P.ctx && P.ctx->shouldStop()) break;
      const Eigen::VectorXd r = P.A * map.pi(*z) - P.b;
      const Eigen::MatrixXd Jr = P.A * map.jacobian(*z);
      const Eigen::VectorXd g = Jr.transpose() * r;
      std::vector<bool> fixed(static_cast<std::size_t>(n), false);
      for (int k = 0; k < n; ++k)
        fixed[static_cast<std::size_t>(k)] = std::isfinite(lb[static_cast<std::size_t>(k)]) &&
                                             (*z)(k) <= lb[static_cast<std::size_t>(k)] && g(k) > 0;
      Eigen::MatrixXd H = Jr.transpose() * Jr;
      const double hmax = std::max(H.diagonal().maxCoeff(), 1e-300);
      bool accepted = false;
      for (int tries = 0; tries < 30 && !accepted; ++tries) {
        Eigen::MatrixXd Hd = H;
        for (int k = 0; k < n; ++k) Hd(k, k) += lambda * (H(k, k) + 1e-12 * hmax);
        Eigen::VectorXd rhs = -g;
        for (int k = 0; k < n; ++k)
          if (fixed[static_cast<std::size_t>(k)]) {
            Hd.row(k).setZero();
            Hd.col(k).setZero();
            Hd(k, k) = 1.0;
            rhs(k) = 0.0;
          }
        const Eigen::VectorXd step = Hd.ldlt().solve(rhs);
        Eigen::VectorXd zn = *z + step;
        for (int k = 0; k < n; ++k) zn(k) = std::max(zn(k), lb[static_cast<std::size_t>(k)]);
        const double fn = P.value(zn, nullptr);
        if (std::isfinite(fn) && fn <= f) {
          small = (f - fn) <= 1e-12 * f ? small + 1 : 0;
          *z = zn;
          f = fn;
          lambda = std::max(lambda / 3.0, 1e-15);
          accepted = true;
        } else {
          lambda *= 4.0;
        }
      }
      if (!accepted) break;
    }
    return it;
  }

  std::string weighting_, prior_on_, algorithm_, start_, scale_selection_;
  std::vector<double> scale_range_;
  double prior_scale_;
  int cv_blocks_;
  int max_eval_, polish_, chunk_, max_eq_;
  exid::estimators::SolveOptions opt_;
};

}  // namespace
}  // namespace exid::consistent_ls

EXID_REGISTER_PLUGIN(exid::consistent_ls::ConsistentLs)
