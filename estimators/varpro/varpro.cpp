// exid — estimator `varpro`: least squares over a model's linear parameters and the few
// parameters its columns depend on nonlinearly (ObservationModel::nonlinearParameters: a
// Stribeck velocity, the width of a smoothed sign), by variable projection (Golub-Pereyra).
//
// For given nonlinear parameters eta the linear parameters are the usual least-squares fit,
// theta(eta); the outer problem min_eta ||y - W(eta) theta(eta)||^2 is small (a handful of
// parameters) and is solved by Levenberg-Marquardt on lambda = log(eta) (eta stays positive)
// with Kaufman's Jacobian J = -P_W^perp (dW/dlambda) theta, exact column derivatives from the
// model (ObservationModel::rowsAt).
//
// One pass over the data per evaluation, streamed in chunks: the rows [W D y], D the columns
// the nonlinear parameters move and their derivatives, are folded into the triangular factor R
// of a QR (exid::estimators::RowAccumulator). Everything the step needs is in R:
//   theta:  R11 theta = r1y (the rank-revealing solve of batch_ls);
//   J^T J = (R22 Theta)^T (R22 Theta),  J^T r = -(R22 Theta)^T r2y,
// with V = D Theta the derivative of W theta (Theta: theta's entries placed by column).
// Standard deviations of every parameter, linear and nonlinear, from the Gauss-Newton matrix
// of the whole problem [W V] at the optimum: sigma^2 ([W V]^T [W V])^-1, sigma^2 = rss / (m -
// p - q). Memory: one chunk and the (p + L + 1)^2 factor, whatever the number of samples.
//
// A delay d between the measurement (torque, wrench) and the positions (measurement_delay:
// true) is one more nonlinear parameter, taken directly (lambda = d / median sample period).
// The measurement is never interpolated (interpolating noise lowers its variance by an amount
// that depends on d, which would pull d towards half samples): the model's rows of sample k
// are read at t_k - d instead (exid::shiftedRows, cubic Hermite across the samples), with
// their exact derivative in d, p more columns in D. The model must be per-sample. The first
// and last M samples (M from measurement_delay_max_s) give no rows, for every d: the rows
// compared are always the same.
#include "varpro.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "exid/delay.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid::varpro {

std::vector<exid::ParamDecl> VarPro::params() {
  std::vector<exid::ParamDecl> p = {
      exid::param_int("max_evaluations", 60,
                      "passes over the data at most (each evaluates the fit at one set of "
                      "nonlinear parameters)",
                      2, 10000),
      exid::param_double("step_tolerance", 1e-10, "",
                         "stop when the largest step in log(eta) is below this", 0.0, 1.0, true),
      exid::param_double("rss_tolerance", 1e-10, "",
                         "stop when an accepted step lowers the residual sum of squares by "
                         "less than this fraction of it",
                         0.0, 1.0),
      exid::param_int("chunk_samples", 2048, "samples per chunk passed to the model", 1, 1e9),
      exid::param_string("accumulate", std::string("qr"),
                         "qr: Householder QR of [W D y] (cond not squared); normal: the Gram "
                         "matrix (faster, squares cond)",
                         {"qr", "normal"}),
      exid::param_int("starts", 3,
                      "globalisation: the multiples of the study's nonlinear parameters tried, "
                      "the first `starts` of x1, x1/2, x2, x1/4, x4, x1/8, ... (both sides), "
                      "per group of parameters moving the same columns (a joint's eps and vs), "
                      "the other groups at the best point so far, in sweeps until one improves "
                      "nothing (3 at most); the linear part solved exactly at each point; "
                      "Levenberg-Marquardt from "
                      "the best point and from the study's values, the better kept; 1: the "
                      "study's values only",
                      1, 9),
      exid::param_string("grid_points", std::string("projected"),
                         "projected: a point of the grid or a scan moves a few columns, the "
                         "others' QR is kept and only the moved columns are projected (the "
                         "same residual; a point taken is confirmed by a whole evaluation); "
                         "whole: every point a whole evaluation (slower; the reference)",
                         {"projected", "whole"}),
      exid::param_double("gradient_tolerance", 1e-6, "",
                         "first-order test of convergence: a Gauss-Newton step from the result "
                         "would remove at most this fraction of the residual sum of squares "
                         "(or the fit is exact to rounding)",
                         0.0, 1.0, true),
      exid::estimators::rankToleranceParam(),
  };
  for (auto& d : exid::estimators::DelaySettings::params(
           "fit a delay d of the measurement (torque or wrench) behind the positions, with the "
           "other parameters: the model's rows of sample k are read at t_k - d (d > 0: the "
           "measurement lags); needs measurement_delay_max_s and a per-sample model",
           "the largest |d| searched: the samples within it (plus 3) of either end give no "
           "rows, whatever d is (counted in the details)"))
    p.push_back(d);
  return p;
}

VarPro::VarPro(const exid::ParamSet& p)
    : max_evals_(static_cast<int>(p.getInt("max_evaluations"))),
      xtol_(p.getDouble("step_tolerance")),
      ftol_(p.getDouble("rss_tolerance")),
      starts_(static_cast<int>(p.getInt("starts"))),
      gtol_(p.getDouble("gradient_tolerance")),
      project_(p.getString("grid_points") == "projected"),
      chunk_(static_cast<int>(p.getInt("chunk_samples"))),
      method_(p.getString("accumulate") == "normal" ? RowAccumulator::Method::Normal
                                                    : RowAccumulator::Method::Qr) {
  opt_.rank_tolerance = p.getDouble("rank_tolerance");
  const auto ds = exid::estimators::DelaySettings::from(
      p, "varpro", "the samples within it of the recording's ends give no rows");
  delay_ = ds.on;
  delay0_ = ds.initial_s;
  delay_max_ = ds.max_s;
}

exid::Estimate VarPro::estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                                const exid::Prior* prior, const exid::RunContext& ctx) {
  const auto t0 = std::chrono::steady_clock::now();
  exid::check(prior == nullptr, "varpro: a prior is not supported (use batch_ls)");
  if (delay_)
    exid::requireOnePart(
        data, kName,
        "varpro's measurement delay shifts the rows in time between neighbouring "
        "samples; estimate the delay on one recording, or fix it (the experiment's "
        "measurement_delay_s) and use batch_ls");
  rejected_singular_ = rejected_bound_ = 0;
  setUp(model, data);
  const int q = static_cast<int>(nl_.size());
  Eigen::VectorXd lambda0(q);
  for (int k = 0; k < q_model_; ++k) lambda0[k] = std::log(nl_[static_cast<std::size_t>(k)].value);
  if (delay_) lambda0[q - 1] = delay0_ / ts_;
  // At the study's values: a regressor without full rank there is refused by
  // solveLeastSquares, naming the directions the data do not determine (the evidence).
  Eval at_study = evaluate(model, data, lambda0, ctx);
  // The grid's points are compared on every k-th sample of a long recording (at most
  // kGridSamples; a per-sample model without a delay, whose rows need no neighbours): a
  // ranking of candidate starts, the runs on every sample.
  const exid::Dataset* gd = &data;
  exid::Dataset sub;
  long stride = 1;
  if (!delay_ && model.specs().per_sample && data.size() > kGridSamples && starts_ > 1) {
    stride = (data.size() + kGridSamples - 1) / kGridSamples;
    sub = strided(data, stride);
    gd = &sub;
  }
  auto onGrid = [&](const Eigen::VectorXd& lambda, const Eval& full) {
    return gd == &data ? full : evaluate(model, *gd, lambda, ctx);
  };
  auto onData = [&](const Eigen::VectorXd& lambda, const Eval& g) {
    return gd == &data ? g : evaluate(model, data, lambda, ctx);
  };
  // ---- globalisation: a grid over each group's multiples, the linear part exact
  Grid grid = searchGrid(model, *gd, lambda0, onGrid(lambda0, at_study), ctx);
  grid.sample_stride = stride;
  // ---- Levenberg-Marquardt from the study's values and from the grid's best point
  std::vector<Run> runs;
  runs.push_back(levenbergMarquardt(model, data, lambda0, at_study, "the study's values", ctx));
  // (a point the sample subset ranked may be singular on every sample: not a start then)
  auto start = [&](const Eigen::VectorXd& lambda, const Eval& g, const char* origin) {
    try {
      runs.push_back(levenbergMarquardt(model, data, lambda, onData(lambda, g), origin, ctx));
      return true;
    } catch (const exid::Error&) {
      if (ctx.shouldStop()) throw;
      ++grid.singular;
      return false;
    }
  };
  if (grid.best != lambda0) start(grid.best, grid.best_eval, "the grid's best point");
  // ---- the best end checked against the points around it: the grid's multiples of its own
  // values per group, and each parameter alone over a wider bracket (x1/32 .. x32): a point
  // there with a lower residual is one more start (kRounds times at most). A local minimum
  // where one joint's term settled far off (the others right) is left this way.
  for (int round = 0; round < kRounds && grid.multipliers.size() > 1; ++round) {
    const Run* best = &runs.front();
    for (const Run& r : runs)
      if (r.cur.rss < best->cur.rss) best = &r;
    Grid around;
    around.best = best->lambda;
    around.best_eval = onGrid(best->lambda, best->cur);
    around.groups = grid.groups;
    around.multipliers = grid.multipliers;
    const Eigen::VectorXd centre = best->lambda;
    sweep(model, *gd, centre, &around, ctx);
    axisScan(model, *gd, centre, &around, ctx);
    grid.evaluations += around.evaluations + (gd == &data ? 0 : 1);
    grid.singular += around.singular;
    grid.projected_checked += around.projected_checked;
    grid.held_checked += around.held_checked;
    grid.projected_difference = std::max(grid.projected_difference, around.projected_difference);
    ++grid.checks;
    if (around.best == centre) break;  // no point around it is lower
    if (gd != &data) ++grid.evaluations;
    if (!start(around.best, around.best_eval, "a point around the best end")) break;
  }
  for (Run& r : runs) firstOrder(model, &r);
  // the winner: the lowest residual among the runs whose joint problem is regular there
  int won = -1;
  for (std::size_t i = 0; i < runs.size(); ++i)
    if (!runs[i].singular &&
        (won < 0 || runs[i].cur.rss < runs[static_cast<std::size_t>(won)].cur.rss))
      won = static_cast<int>(i);
  if (won < 0) {
    const Run& r = runs.front().cur.rss <= runs.back().cur.rss ? runs.front() : runs.back();
    throw exid::Error(fmt::format(
        "varpro: no start ended where the nonlinear parameters are determined together with "
        "the linear ones: the best, from {}, stopped at {} with rss {:.6g} and gradient norm "
        "{:.3g} ({}), where the joint problem [W V] is singular (e.g. a Stribeck velocity so "
        "large that its term is a Coulomb term, or a width so large that the sign is flat). "
        "The regressor at the study's values has full rank: start elsewhere (the model's "
        "values) or remove the term",
        r.origin, where(r.cur.eta), r.cur.rss, r.gradient_norm, r.stop));
  }
  return finish(model, runs, won, grid, t0);
}

// The estimate at the winning run's end: theta and the nonlinear parameters with their
// covariance (the joint problem [W V]) and the details.
exid::Estimate VarPro::finish(const exid::ObservationModel& model, const std::vector<Run>& runs,
                              int won, const Grid& grid,
                              std::chrono::steady_clock::time_point t0) const {
  const Run& run = runs[static_cast<std::size_t>(won)];
  const Eval& cur = run.cur;
  const Eigen::VectorXd& lambda = run.lambda;
  const int p = model.numBase(), q = static_cast<int>(nl_.size());
  exid::Estimate e;
  exid::estimators::fillEstimate(&e, model, solve(model, cur, true), cur.rss, cur.m);
  e.rows = cur.m;
  e.details["rows"] = static_cast<long long>(cur.m);
  const Eigen::MatrixXd& M = run.M;
  const long dof = cur.m - p - q;
  exid::check(dof > 0, fmt::format("varpro: {} rows for {} linear and {} nonlinear parameters",
                                   cur.m, p, q));
  const double sigma2 = cur.rss / static_cast<double>(dof);
  // column-scaled SVD: (M^T M)^-1 = S (Ms^T Ms)^-1 S
  const Eigen::VectorXd sc = columnScale(M);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(M * sc.asDiagonal(), Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  const Eigen::MatrixXd Vs = svd.matrixV() * sv.cwiseInverse().asDiagonal();
  const Eigen::MatrixXd cov = sigma2 * sc.asDiagonal() * (Vs * Vs.transpose()) * sc.asDiagonal();
  e.covariance = cov.topLeftCorner(p, p);
  e.std = e.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  e.sigma = std::sqrt(sigma2);
  e.nonlinear_names = names();
  e.nonlinear = etaOf(lambda);
  e.nonlinear_std = Eigen::VectorXd(q);
  for (int k = 0; k < q; ++k) {  // delta method: sigma_eta = eta sigma_lambda; d = ts lambda
    const double sl = std::sqrt(std::max(0.0, cov(p + k, p + k)));
    e.nonlinear_std[k] = k < q_model_ ? e.nonlinear[k] * sl : ts_ * sl;
  }
  exid::Json& d = e.details;
  d["parameters"] = exid::estimators::parameterTable(e);
  d["estimator"] = kName;
  d["sigma2"] = sigma2;
  d["dof"] = static_cast<long long>(dof);
  exid::Json nl = exid::Json::array();
  for (int k = 0; k < q; ++k) {
    exid::Json o = exid::Json::object();
    o["name"] = nl_[static_cast<std::size_t>(k)].name;
    o["unit"] = nl_[static_cast<std::size_t>(k)].unit;
    o["initial"] = nl_[static_cast<std::size_t>(k)].value;
    o["value"] = e.nonlinear[k];
    o["std"] = e.nonlinear_std[k];
    nl.push_back(o);
  }
  d["nonlinear_parameters"] = nl;
  int evals = grid.evaluations + 1;
  for (const Run& r : runs) evals += r.evals - 1;  // (each run's first fit is known)
  d["evaluations"] = evals;
  d["rejected_singular_trials"] = rejected_singular_;
  if (delay_) {
    exid::Json td = exid::Json::object();
    td["value_s"] = e.nonlinear[q - 1];
    td["std_s"] = e.nonlinear_std[q - 1];
    td["initial_s"] = delay0_;
    td["max_s"] = delay_max_;
    td["sample_period_s"] = ts_;
    td["samples_without_rows_each_end"] = margin_;
    td["rejected_trials_beyond_max"] = rejected_bound_;
    td["convention"] =
        "the measurement lags the positions by value_s: the rows of sample k are the model's "
        "at t_k - value_s (cubic Hermite interpolation), the measurement as recorded; the "
        "validation rows are compensated the same way";
    d["measurement_delay"] = td;
  }
  d["iterations"] = run.iterations;
  d["stop"] = run.stop;
  d["trace"] = run.trace;
  describeSearch(runs, won, grid, &d);
  describeConvergence(runs, run, e, t0, &d);
  return e;
}

// The globalisation's details: the grid, every start's end, which won.
void VarPro::describeSearch(const std::vector<Run>& runs, int won, const Grid& grid,
                            exid::Json* dp) const {
  exid::Json& d = *dp;
  const int q = static_cast<int>(nl_.size());
  // the globalisation: the grid, every start's end, which won, the first-order test
  {
    exid::Json G = exid::Json::object();
    G["multipliers"] = exid::Json(grid.multipliers);
    exid::Json groups = exid::Json::array();
    for (const auto& grp : grid.groups) {
      std::vector<std::string> n;
      for (int k : grp) n.push_back(nl_[static_cast<std::size_t>(k)].name);
      groups.push_back(exid::Json(n));
    }
    G["groups"] = groups;
    G["evaluations"] = grid.evaluations;
    G["sample_stride"] = static_cast<long long>(grid.sample_stride);
    G["axis_multipliers_around_the_best_end"] =
        exid::Json(std::vector<double>(std::begin(kAxisMultipliers), std::end(kAxisMultipliers)));
    G["sweeps"] = grid.sweeps;
    G["sweeps_around_the_best_end"] = grid.checks;
    G["singular_points"] = grid.singular;
    // the projected residuals of the points taken, and of each held rows' own point (never
    // taken by the screen), against their whole evaluations (relative to ||y||^2: a fit can be
    // exact); the sweeps around the best end included
    exid::Json P = exid::Json::object();
    P["points"] = grid.projected_checked;
    P["held_points"] = grid.held_checked;
    P["max_difference_relative_to_yy"] = grid.projected_difference;
    G["projected_against_whole"] = P;
    G["best_rss"] = grid.best_eval.rss;
    G["best_eta"] =
        exid::Json(std::vector<double>(grid.best_eval.eta.data(), grid.best_eval.eta.data() + q));
    d["grid"] = G;
  }
  exid::Json S = exid::Json::array();
  for (const Run& r : runs) {
    exid::Json o = exid::Json::object();
    o["from"] = r.origin;
    o["initial_eta"] = exid::Json(std::vector<double>(r.eta0.data(), r.eta0.data() + q));
    o["final_eta"] = exid::Json(std::vector<double>(r.cur.eta.data(), r.cur.eta.data() + q));
    o["final_rss"] = r.cur.rss;
    o["evaluations"] = r.evals;
    o["stop"] = r.stop;
    o["gradient_norm"] = r.gradient_norm;
    o["gauss_newton_fraction"] = r.gn_fraction;
    o["first_order_test"] = r.stationary;
    o["singular"] = r.singular;
    S.push_back(o);
  }
  d["starts"] = S;
  d["start_won"] = won;
}

// The first-order test, the method and, where it applies, the warnings: not converged, the
// delay at its bound, a nonlinear parameter the data do not determine.
void VarPro::describeConvergence(const std::vector<Run>& runs, const Run& run,
                                 const exid::Estimate& e, std::chrono::steady_clock::time_point t0,
                                 exid::Json* dp) const {
  exid::Json& d = *dp;
  const Eval& cur = run.cur;
  const int q = static_cast<int>(nl_.size());
  d["gradient_norm"] = run.gradient_norm;
  d["gauss_newton_fraction"] = run.gn_fraction;
  d["convergence_test"] = fmt::format(
      "converged: at the best of the starts, a Gauss-Newton step would remove at most "
      "gradient_tolerance = {:g} of the rss (or the fit is exact to rounding, rss <= 1e-24 "
      "||y||^2); gradient_norm = ||d rss / d log(eta)||",
      gtol_);
  d["method"] =
      "variable projection (Golub-Pereyra, Kaufman's Jacobian), Levenberg-Marquardt on "
      "log(eta); theta by the rank-revealing solve of batch_ls at each eta";
  d["covariance_definition"] =
      "sigma^2 ([W V]^T [W V])^-1 over the linear and the nonlinear parameters (V = "
      "d(W theta)/d log(eta)), sigma^2 = rss / (m - p - q); the linear parameters' std "
      "include the nonlinear ones' uncertainty";
  d["accumulate"] = method_ == RowAccumulator::Method::Qr ? "qr" : "normal";
  d["memory"] = "one chunk of rows and the (p + L + 1)^2 factor per pass, one pass per evaluation";
  d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // converged: the first-order test holds at a point no other start beat
  bool beaten = false;
  for (const Run& r : runs) beaten = beaten || r.cur.rss < cur.rss;
  const bool converged = run.stationary && !beaten;
  d["converged"] = converged;
  exid::Json w = exid::Json::array();
  if (!converged)
    w.push_back(exid::Json(fmt::format(
        "varpro: not converged: from {}, stopped at {} with rss {:.6g}, gradient norm {:.3g} "
        "(a Gauss-Newton step would remove {:.2g} of the rss, above gradient_tolerance = "
        "{:g}){}: {}",
        run.origin, where(cur.eta), cur.rss, run.gradient_norm, run.gn_fraction, gtol_,
        beaten ? "; a start with a lower rss ended where the joint problem is singular" : "",
        run.stop)));
  if (delay_ && std::abs(e.nonlinear[q - 1]) > 0.99 * delay_max_)
    w.push_back(exid::Json(fmt::format(
        "varpro: the fitted measurement delay {:g} s is at the bound measurement_delay_max_s = "
        "{:g} s (raise it)",
        e.nonlinear[q - 1], delay_max_)));
  // a nonlinear parameter whose std exceeds its value is not determined by the data (a
  // Stribeck velocity far above the motion's speeds: its term is a Coulomb term)
  for (int k = 0; k < q_model_; ++k)
    if (!(e.nonlinear_std[k] < std::abs(e.nonlinear[k])))
      w.push_back(exid::Json(fmt::format(
          "varpro: {} = {:.6g} +- {:.3g} {} is not determined by the data (its std exceeds its "
          "value): fix it in the model or remove its term",
          nl_[static_cast<std::size_t>(k)].name, e.nonlinear[k], e.nonlinear_std[k],
          nl_[static_cast<std::size_t>(k)].unit)));
  if (w.size() > 0) d["warnings"] = w;
}

}  // namespace exid::varpro

EXID_REGISTER_PLUGIN(exid::varpro::VarPro)
