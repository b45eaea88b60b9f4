// exid — estimator `didim`: output-error refinement (DIDIM, Gautier, Janot and Vandanjon):
// starting from the inverse-model (least-squares) estimate, the base parameters are fitted so
// that the closed-loop simulation of the robot (the recording's reference through the robot's
// PD gains and feed-forward: exid::estimators::ClosedLoop) reproduces the measured torques
// (output: torque, the controller's output along the simulated motion) or positions (output:
// position). Levenberg-Marquardt on theta (J^T J plus the residual's second-order term by
// secant updates, NL2SOL's, unless hessian: gauss_newton); the Jacobian from forward sensitivities
// of the closed loop, with the sensitivity equations' right-hand side exact:
//   x = (q, qd),  f = (qd, a),  a = M^-1 (tau_c(t, q, qd) - h(q, qd)),
//   df/dtheta = (0, -M^-1 w(q, qd, a))                  (w theta = M a + h),
//   da/dq = M^-1 (-Kp - d(w theta)/dq |a),  da/dqd = M^-1 (-Kd - d(w theta)/dqd |a),
// the derivatives of w theta from the model's exact design VJP (one per joint). Outputs:
// d tau_c / dtheta = -Kp S_q - Kd S_qd, or d q / dtheta = S_q. Covariance sigma^2 (J^T J)^-1,
// sigma^2 = rss / (m - p) (docs/estimators.md, "didim").
// Drive gains (dK) and load-dependent Coulomb (FcL) act in the loop on the command
// (ClosedLoop): the drives deliver tau_c (1 + dK) - FcL |tau_c| sign(qd). The gains' common
// scale with theta needs a prior (gain_prior_std): pseudo-observations sigma (mu - dK) / s,
// sigma the output's noise std (two rounds: the fixed point of sqrt(rss / (m - q))), as gains_ls.
// A measurement delay d (torque output): the torque recorded at t_k is the command at t_k - d,
// d y_k / d d = -d tau_c / dt there (exact: the reference's jerk through the feed-forward).
// Starts (`starts`, default 3): with nonlinear parameters beyond theta (dK, FcL, eta, d), LM runs
// from the first start and from starts on both sides of it (eta x1/2, x2, ...; dK and FcL
// -+ start_spread; d -+ 2 samples; theta by least squares on the rows there), the later ones for
// start_iterations and the lowest of them on to max_iterations when below the first's end; the
// lowest objective is kept and "converged" is its first-order test (docs/estimators.md).
#include "didim.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid::didim {

std::vector<exid::ParamDecl> Didim::params() {
  std::vector<exid::ParamDecl> p = exid::estimators::ClosedLoop::params();
  p.push_back(exid::param_string(
      "sensitivities", std::string("steps"),
      "steps: the sensitivities integrated as one matrix along CVODES's steps of the state "
      "(BDF2; to about 1e-4 of central differences); cvodes: CVODES's own forward "
      "sensitivities (staggered; closer, and several times slower)",
      {"steps", "cvodes"}));
  for (auto& d : std::vector<exid::ParamDecl>{
           exid::param_string("output", std::string("torque"),
                              "torque: fit the controller's torque along the simulated motion "
                              "to the recorded one (DIDIM); position: fit the simulated "
                              "positions to the recorded ones",
                              {"torque", "position"}),
           exid::param_int("max_iterations", 30, "Levenberg-Marquardt steps at most", 1, 10000),
           exid::param_string(
               "hessian", std::string("secant"),
               "secant: J^T J plus the residual's second-order term by secant updates "
               "(Dennis, Gay and Welsch's, as NL2SOL): fast where the residual stays large (a "
               "model that cannot reproduce the recording exactly), where Gauss-Newton "
               "converges slowly; gauss_newton: J^T J alone",
               {"secant", "gauss_newton"}),
           exid::param_double("rss_tolerance", 1e-10, "",
                              "stop when the undamped model (J^T J, plus the secant term) "
                              "predicts a decrease below this fraction of the residual sum "
                              "of squares: the minimum to this precision",
                              0.0, 1.0),
           exid::param_double("step_tolerance", 1e-7, "",
                              "stop when an accepted step moves theta by less than this "
                              "relative to its norm (the simulation's precision is near)",
                              0.0, 1.0, true),
           exid::param_double("first_order_std", 1.0, "",
                              "first-order test of convergence (whatever stopped the "
                              "iterations): the minimum the undamped model predicts lies "
                              "within this many standard deviations of the result, along the "
                              "covariance's metric (or its predicted decrease is below "
                              "rss_tolerance)",
                              0.0, 1e3, true),
           exid::param_string("loop", std::string("closed"),
                              "closed: the robot's closed loop (reference_file and its PD "
                              "gains); open: driven by the recorded torque in windows of "
                              "window_s, each from its recorded start (q, qd), fitting the "
                              "positions (output: position): no reference or gains needed",
                              {"closed", "open"}),
           exid::param_double("window_s", 0.0, "s",
                              "loop: open: the length of each simulated window (required)", 0.0),
           exid::param_bool("fit_nonlinear", true,
                            "fit the model's nonlinear parameters (friction widths, Stribeck "
                            "velocities: ObservationModel::nonlinearParameters) with theta, "
                            "from the model's values, on log scale; false: keep them"),
           exid::param_doubles("gain_prior_std", std::vector<double>{}, "",
                               "prior std of each drive's dK (one value: every drive); "
                               "required with drive gains (their scale with theta)"),
           exid::param_doubles("gain_prior_dK", std::vector<double>{}, "",
                               "prior mean of each drive's dK (one value: every drive; empty: "
                               "0); the start takes the gains there"),
           exid::param_int("starts", 3,
                           "Levenberg-Marquardt starts, the lowest objective kept, where the "
                           "model has nonlinear parameters beyond theta (drive gains, load "
                           "Coulomb, the model's nonlinear parameters, a delay): the first "
                           "(least squares), then both sides of it: eta x1/2, x2, x1/sqrt2, "
                           "xsqrt2, x1/4, x4; dK and FcL -+ start_spread, -+ start_spread/2, "
                           "-+ 2 start_spread; the delay -+ 2, 1, 4 samples",
                           1, 7),
           exid::param_double("start_spread", 0.25, "",
                              "the later starts' shift of dK (a relative gain error) and FcL "
                              "(a fraction of the command)",
                              0.0, 0.45, true),
           exid::param_int("start_iterations", 5,
                           "Levenberg-Marquardt steps at most from each later start; the "
                           "lowest of them, when below the first start's end, goes on to "
                           "max_iterations",
                           1, 10000),
           exid::param_int("gradient_check", 0,
                           "> 0: compare the Jacobian along this many random directions with "
                           "central differences of the simulation at the start "
                           "(details.gradient_check)",
                           0, 1000),
       })
    p.push_back(d);
  for (auto& d : exid::estimators::DelaySettings::params(
           "fit a delay d of the recorded torque behind the controller: the torque recorded at "
           "t_k is the command at t_k - d (output: torque; needs measurement_delay_max_s)",
           "the largest |d|: the samples within it of the reference's ends are left out "
           "(counted in details.measurement_delay)"))
    p.push_back(d);
  return p;
}

Didim::Didim(const exid::ParamSet& p)
    : P_(p),
      position_(p.getString("output") == "position"),
      max_iter_(static_cast<int>(p.getInt("max_iterations"))),
      ftol_(p.getDouble("rss_tolerance")),
      xtol_(p.getDouble("step_tolerance")),
      first_order_std_(p.getDouble("first_order_std")),
      tol_loop_(withSensitivities(exid::estimators::ClosedLoop::Tolerances::from(p),
                                  p.getString("sensitivities"))),
      check_(static_cast<int>(p.getInt("gradient_check"))),
      secant_(p.getString("hessian") == "secant"),
      fit_nl_(p.getBool("fit_nonlinear")),
      prior_std_(p.getDoubles("gain_prior_std")),
      prior_mean_(p.getDoubles("gain_prior_dK")) {
  starts_ = static_cast<int>(p.getInt("starts"));
  start_iter_ = static_cast<int>(p.getInt("start_iterations"));
  spread_ = p.getDouble("start_spread");
  open_ = p.getString("loop") == "open";
  window_s_ = p.getDouble("window_s");
  if (open_) {
    exid::check(window_s_ > 0,
                "didim: loop: open needs window_s > 0 (how long each window is simulated from "
                "its recorded start: short enough that the open loop does not drift, e.g. "
                "0.1-0.5 s; exid does not guess it)");
    exid::check(position_,
                "didim: loop: open is driven by the recorded torque and fits the positions: "
                "give output: position");
    exid::check(p.getString("reference_file").empty() && p.getDoubles("kp_Nm_per_rad").empty() &&
                    p.getDoubles("kd_Nm_s_per_rad").empty(),
                "didim: reference_file, kp_Nm_per_rad and kd_Nm_s_per_rad are for loop: "
                "closed (loop: open is driven by the recorded torque)");
  } else {
    exid::check(window_s_ == 0, "didim: window_s is for loop: open");
    exid::estimators::ClosedLoop::checkParams(p, kName);
  }
  exid::estimators::checkGainPrior(prior_std_, prior_mean_, kName);
  const auto ds = exid::estimators::DelaySettings::from(
      p, kName, "the samples within it of the reference's ends are left out");
  delay_ = ds.on;
  delay0_ = ds.initial_s;
  delay_max_ = ds.max_s;
  exid::check(!delay_ || !position_,
              "didim: measurement_delay is for output: torque (the torque channel behind the "
              "controller); with output: position the positions are the controller's own");
}

exid::Estimate Didim::estimate(const exid::ObservationModel& model, const exid::Dataset& data_in,
                               const exid::Prior* prior, const exid::RunContext& ctx) {
  const auto t0 = std::chrono::steady_clock::now();
  exid::check(prior == nullptr, "didim: a prior is not supported");
  exid::requireOnePart(data_in, kName,
                       "didim simulates the robot along one continuous recording; identify from "
                       "each recording in its own study, or use an estimator that takes the "
                       "rows sample by sample (batch_ls, wls, consistent_ls, rls, filtered_ls, "
                       "gains_ls)");
  const exid::Dataset data = exid::materialize(data_in);
  loop_ = open_ ? std::make_unique<exid::estimators::ClosedLoop>(model, data, kName)
                : std::make_unique<exid::estimators::ClosedLoop>(model, P_, data, ctx, kName);
  // (copies: the loop outlives this call and its context)
  loop_->setStop([stop = ctx.cancelled, deadline = ctx.deadline] {
    return deadline.expired() || (stop && stop());
  });
  exid::check(!delay_ || !loop_->floatingBase(),
              "didim: measurement_delay is not available on a floating base (the delay's "
              "Jacobian column needs the command's rate, which the floating loop does not give)");
  const int p = model.numBase(), n = loop_->dof(), K = data.size();
  setPrior(model);
  // a floating base with the base rows (rows: all): they are fitted too (the joint torques
  // alone do not identify what only the base rows see)
  nb_ = loop_->baseRowCount();
  exid::check(nb_ == 0 || !position_,
              "didim: output: position on a floating base whose model has the base rows (rows: "
              "all) would fit positions and wrenches together: use output: torque (or rows: "
              "joints)");
  chooseSamples(model, data, n, K, ctx);
  const long m = y_.size();
  exid::check(m > p, fmt::format("didim: {} rows for {} parameters", m, p));
  L_ = fit_nl_ ? static_cast<int>(loop_->nonlinear().size()) : 0;
  exid::check(L_ == 0 || nb_ == 0,
              fmt::format("didim: the model's nonlinear parameters ({}) beside a floating base's "
                          "base rows (rows: all): the base rows' sensitivities to them are not "
                          "available; use rows: joints, or fit_nonlinear: false to keep them",
                          loop_->nonlinear().size()));
  D_ = delay_ ? 1 : 0;
  const VectorXd theta = firstStart(model, data, ctx);
  p_ = p;
  m_ = m;
  // the prior's weight sigma / s: sigma from the output's residual (floored at 1e-3 of its
  // rms: near noise-free data would give the prior no weight and the scale no anchor)
  floor_sigma_ = 1e-3 * std::sqrt(y_.squaredNorm() / static_cast<double>(m));
  sp_ = startParams(model);
  const bool several = starts_ > 1 && !sp_.empty();
  std::vector<Run> runs;
  exid::Json check_json;
  try {
    runs.push_back(startRun(theta, data, -1.0));
    if (check_ > 0) check_json = gradientCheck(theta, data, runs[0].cur);
    iterate(&runs[0], max_iter_, data, ctx);
  } catch (const exid::Error& err) {
    // with other starts, a first start that cannot be simulated is left out (said in
    // details.starts); alone, its error is the estimator's
    if (!several || ctx.shouldStop()) throw;
    runs.assign(1, failedRun(theta, err.what()));
  }
  const int best = multiStart(model, data, ctx, &runs);
  for (Run& r : runs)
    if (r.error.empty()) conclude(&r);
  const Run& r = runs[static_cast<std::size_t>(best)];
  sigma_ = r.sigma;
  exid::Estimate e = finish(model, r.cur, r.x, m);
  describeResult(r, best, runs, std::move(check_json), data, t0, &e);
  return e;
}

// The estimate's details from the kept run r (runs[best]): the distance from the predicted
// minimum, the counts, the stop and the convergence test, the starts, the gradient check (at the
// start, check_json, and at the end), the wall time since t0 and, not converged, a warning.
void Didim::describeResult(const Run& r, int best, const std::vector<Run>& runs,
                           exid::Json check_json, const exid::Dataset& data,
                           std::chrono::steady_clock::time_point t0, exid::Estimate* ep) const {
  exid::Estimate& e = *ep;
  const int p = p_;
  // "converged" only where the first-order test holds at the start of lowest objective (no
  // other start ended lower: multiStart), whatever stopped its iterations
  const bool converged = r.stopped && r.first_order;
  exid::Json& d = e.details;
  {
    // how far the estimate is from the minimum the undamped model predicts: the decrease
    // it predicts, and that decrease over sigma^2 = rss / (m - q), whose square root is the
    // distance in standard deviations along the covariance's metric
    exid::Json rem = exid::Json::object();
    if (std::isfinite(r.undamped)) {
      rem["predicted_decrease"] = r.undamped;
      rem["relative"] = r.undamped_relative;
      rem["distance_std"] = r.distance_std;
    } else {
      rem["predicted_decrease"] = exid::Json();
    }
    rem["definition"] =
        "at the estimate: g^T (J^T J + S)^-1 g, the decrease of the residual sum of squares "
        "the undamped model predicts (S the secant term, or 0; null where that matrix is not "
        "positive definite); relative: over the residual; distance_std: sqrt(it / sigma^2), "
        "the estimate's distance from the predicted minimum in standard deviations along the "
        "covariance's metric";
    d["remaining"] = rem;
  }
  int sims = 0, jacobians = 0;
  for (const Run& s : runs) {
    sims += s.sims;
    jacobians += s.jacobians;
  }
  d["iterations"] = r.iterations;
  d["simulations"] = sims;
  d["jacobians"] = jacobians;
  d["hessian"] = secant_ ? "secant" : "gauss_newton";
  if (!prior_col_.empty()) d["gain_prior"]["rounds"] = r.round;
  d["stop"] = r.stop;
  d["converged"] = converged;
  d["trace"] = r.trace;
  d["start"] = startName(best);
  d["start_change"] = (r.x.head(p) - r.x0.head(p)).norm() / std::max(r.x.head(p).norm(), 1e-300);
  describeStarts(runs, best, &d);
  if (!check_json.isNull()) {
    // and at the end, where the Jacobian was taken along an accepted trial's path
    if (r.jacobians > 1 || best > 0) {
      const exid::Json end = gradientCheck(r.x, data, r.cur);
      const double worst = std::max(check_json.find("max_relative_difference")->asDouble(),
                                    end.find("max_relative_difference")->asDouble());
      check_json["at_start"] = *check_json.find("max_relative_difference");
      check_json["at_end"] = *end.find("max_relative_difference");
      check_json["max_relative_difference"] = worst;
    }
    d["gradient_check"] = check_json;
  }
  d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  d["gradient_norm"] = 2.0 * r.g.norm();
  d["convergence_test"] = fmt::format(
      "converged: at the start of lowest objective (details.starts), a stop test held and the "
      "minimum the undamped model predicts lies within first_order_std = {:g} standard "
      "deviations (remaining.distance_std), or its decrease below rss_tolerance; "
      "gradient_norm = ||d objective / d theta||",
      first_order_std_);
  if (!converged) {
    exid::Json w = d.find("warnings") ? *d.find("warnings") : exid::Json::array();
    std::vector<std::string> names = e.names;
    Eigen::VectorXd values(e.value.size() + e.nonlinear.size());
    values << e.value, e.nonlinear;
    names.insert(names.end(), e.nonlinear_names.begin(), e.nonlinear_names.end());
    w.push_back(exid::Json(fmt::format(
        "didim: not converged: from {} (start {} of {}, the lowest objective of the starts), "
        "stopped after {} iterations at {} with rss {:.6g}, gradient norm {:.3g}, the "
        "predicted minimum {:.3g} standard deviations away (first_order_std = {:g}): {}",
        startName(best), best + 1, runs.size(), r.iterations,
        exid::estimators::describePoint(names, values), r.cur.rss, 2.0 * r.g.norm(), r.distance_std,
        first_order_std_, r.stop)));
    d["warnings"] = w;
  }
}

// The estimate at the kept run's point x (its simulation s, m outputs): theta, its covariance
// (solution), the nonlinear parameters and the details.
exid::Estimate Didim::finish(const exid::ObservationModel& model, const Sim& s, const VectorXd& x,
                             long m) const {
  const int p = model.numBase();
  MatrixXd C;
  const exid::estimators::LsSolution L = solution(model, s, x, m, &C);
  exid::Estimate e;
  exid::estimators::fillEstimate(&e, model, L, s.rss, m);
  if (L_ + D_ > 0) {  // eta = exp(lambda): std eta * std(lambda); the delay as it is
    const std::vector<exid::NonlinearParameter> nl = model.nonlinearParameters();
    e.nonlinear.resize(L_ + D_);
    e.nonlinear_std.resize(L_ + D_);
    for (int k = 0; k < L_; ++k) {
      e.nonlinear_names.push_back(nl[static_cast<std::size_t>(k)].name);
      e.nonlinear[k] = std::exp(x[p + k]);
      e.nonlinear_std[k] = e.nonlinear[k] * std::sqrt(std::max(0.0, C(p + k, p + k)));
    }
    if (D_) {
      e.nonlinear_names.push_back("measurement_delay_s");
      e.nonlinear[L_] = x[p + L_];
      e.nonlinear_std[L_] = std::sqrt(std::max(0.0, C(p + L_, p + L_)));
    }
  }
  exid::Json& d = e.details;
  describeDelay(x, e, &d);
  describeGainPrior(model, L, x, &d);
  describeMethod(&d);
  return e;
}

// The least-squares solution at x: sigma^2 (J^T J + P)^-1 from the column-scaled SVD of J with
// the gain prior's rows; C: the whole covariance of x (theta, log eta, d).
exid::estimators::LsSolution Didim::solution(const exid::ObservationModel& model, const Sim& s,
                                             const VectorXd& x, long m, MatrixXd* Cout) const {
  const int p = model.numBase(), q = p + L_ + D_;
  exid::estimators::LsSolution L;
  L.p = p;
  L.m = m;
  L.theta = x.head(p);
  L.rss = s.rss;
  L.sigma2 = s.rss / static_cast<double>(m - q);
  // with a gain prior: the noise std its weight used (floored), so that the covariance is
  // the posterior of the problem solved
  if (!prior_col_.empty()) L.sigma2 = sigma_ * sigma_;
  // J with the gain prior's pseudo-observations (sigma / s on each dK): the posterior
  MatrixXd Jp(s.J.rows() + static_cast<Eigen::Index>(prior_col_.size()), s.J.cols());
  Jp.topRows(s.J.rows()) = s.J;
  Jp.bottomRows(static_cast<Eigen::Index>(prior_col_.size())).setZero();
  for (std::size_t i = 0; i < prior_col_.size(); ++i)
    Jp(s.J.rows() + static_cast<Eigen::Index>(i), prior_col_[i]) =
        std::sqrt(L.sigma2) / prior_sd_[static_cast<Eigen::Index>(i)];
  VectorXd sc = Jp.colwise().norm().transpose();
  for (Eigen::Index i = 0; i < sc.size(); ++i) sc[i] = sc[i] > 0 ? 1.0 / sc[i] : 0.0;
  Eigen::JacobiSVD<MatrixXd> svd(Jp * sc.asDiagonal(), Eigen::ComputeThinV);
  const VectorXd sv = svd.singularValues();
  exid::check(sv.size() == q && sv[q - 1] > 1e-10 * sv[0],
              "didim: the simulated output does not identify every parameter (its Jacobian is "
              "singular)");
  const MatrixXd Vs = svd.matrixV() * sv.cwiseInverse().asDiagonal();
  const MatrixXd C = L.sigma2 * sc.asDiagonal() * (Vs * Vs.transpose()) * sc.asDiagonal();
  *Cout = C;
  L.covariance = C.topLeftCorner(p, p);
  L.std = L.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  L.rel_std_percent = exid::estimators::relativeStdPercent(L.theta, L.std);
  Eigen::JacobiSVD<MatrixXd> raw(s.J);
  L.singular_values = raw.singularValues();
  L.cond_W = L.singular_values[0] / L.singular_values[q - 1];
  L.singular_values_scaled = sv;
  L.cond_W_scaled = sv[0] / sv[q - 1];
  return L;
}

// details.measurement_delay (the fitted delay, its std, bound and the samples left out) and a
// warning at the bound.
void Didim::describeDelay(const VectorXd& x, const exid::Estimate& e, exid::Json* dp) const {
  exid::Json& d = *dp;
  const int p = p_;
  if (D_) {
    exid::Json td = exid::Json::object();
    td["value_s"] = x[p + L_];
    td["std_s"] = e.nonlinear_std[L_];
    td["initial_s"] = delay0_;
    td["max_s"] = delay_max_;
    td["samples_left_out"] = dropped_;
    td["rejected_trials_beyond_max"] = rejected_bound_;
    td["convention"] =
        "the torque recorded at t_k is the controller's command at t_k - value_s; the samples "
        "whose t_k -+ max_s leave the reference are left out";
    d["measurement_delay"] = td;
    if (std::abs(x[p + L_]) > 0.99 * delay_max_) {
      exid::Json w = exid::Json::array();
      w.push_back(exid::Json(fmt::format(
          "didim: the fitted measurement delay {:g} s is at the bound measurement_delay_max_s "
          "= {:g} s",
          x[p + L_], delay_max_)));
      d["warnings"] = w;
    }
  }
}

// details.gain_prior: each drive gain's prior, value, std and the prior's share of its variance.
void Didim::describeGainPrior(const exid::ObservationModel& model,
                              const exid::estimators::LsSolution& L, const VectorXd& x,
                              exid::Json* dp) const {
  exid::Json& d = *dp;
  if (!prior_col_.empty()) {
    exid::Json gp = exid::Json::object();
    gp["noise_std"] = std::sqrt(L.sigma2);
    gp["prior_weight_noise_std"] = sigma_;
    exid::Json gs = exid::Json::array();
    for (std::size_t i = 0; i < prior_col_.size(); ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      const int c = prior_col_[i];
      exid::Json g = exid::Json::object();
      g["name"] = model.base().names[static_cast<std::size_t>(c)];
      g["prior_dK"] = prior_mu_[k];
      g["prior_std"] = prior_sd_[k];
      g["value"] = x[c];
      g["std"] = L.std[c];
      g["prior_share"] = L.std[c] * L.std[c] / (prior_sd_[k] * prior_sd_[k]);
      gs.push_back(g);
    }
    gp["gains"] = gs;
    gp["definition"] =
        "pseudo-observations sigma (mu - dK) / s added to the output's residual, sigma the "
        "output's noise std (sqrt(rss / (m - q)), floored at 1e-3 of its rms); prior_share: "
        "posterior variance over prior variance";
    d["gain_prior"] = gp;
  }
}

// The method's details: output, method, sensitivities, covariance's definition, controller,
// the loop and its windows.
void Didim::describeMethod(exid::Json* dp) const {
  exid::Json& d = *dp;
  d["estimator"] = kName;
  d["output"] = position_ ? "position" : "torque";
  d["method"] =
      std::string(
          "output error: Levenberg-Marquardt on theta, the closed-loop simulation "
          "(CVODES BDF) against the recorded output; ") +
      (secant_ ? "J^T J plus the second-order term by secant updates (NL2SOL's); "
               : "Gauss-Newton's J^T J; ") +
      "Jacobian from forward sensitivities with an exact right-hand side, " +
      (tol_loop_.cvodes_sensitivities ? "CVODES's own (staggered)"
                                      : "integrated by BDF2 along CVODES's steps of the state");
  d["sensitivities"] = tol_loop_.cvodes_sensitivities ? "cvodes" : "steps";
  d["covariance_definition"] =
      "sigma^2 (J^T J + P)^-1, J = d y_sim / d (theta, log eta, d), sigma^2 = rss / (m - p - "
      "L - D); P = sigma^2 / s^2 on each drive gain with a prior (gain_prior_std), else 0; "
      "eta's std = eta std(log eta); cond_W is that of J";
  d["nonlinear_fitted"] = L_ > 0;
  d["controller"] = loop_->describe();
  d["loop"] = open_ ? "open" : "closed";
  if (open_) {
    exid::Json w = exid::Json::object();
    w["window_s"] = window_s_;
    w["windows"] = static_cast<long long>(windows_.size());
    w["samples_fitted"] = static_cast<long long>(keep_t_.size());
    w["samples_not_fitted"] = dropped_;
    w["start"] =
        "each window from its first sample's recorded q and qd (not fitted), driven by the "
        "recorded torque read between samples by a cubic Hermite spline; the samples before "
        "the fourth and after the fifth-to-last are not simulated";
    d["windows"] = w;
  }
  d["memory"] = "the Jacobian (m x p doubles): not streamed";
}

exid::estimators::ClosedLoop::Tolerances Didim::withSensitivities(
    exid::estimators::ClosedLoop::Tolerances t, const std::string& how) {
  t.cvodes_sensitivities = how == "cvodes";
  return t;
}

}  // namespace exid::didim

EXID_REGISTER_PLUGIN(exid::didim::Didim)
