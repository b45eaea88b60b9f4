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
#include <fmt/format.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/estimators/closed_loop.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

class Didim : public exid::Estimator {
 public:
  static constexpr const char* kName = "didim";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "output error (DIDIM): the closed-loop simulation (reference file, PD gains, CVODES) "
      "fitted to the measured torques or positions from the least-squares start; Jacobian from "
      "forward sensitivities, sigma from the Gauss-Newton matrix";

  static std::vector<exid::ParamDecl> params() {
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

  explicit Didim(const exid::ParamSet& p)
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

  exid::EstimatorSpecs specs() const override { return {}; }  // the Jacobian held in memory

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data_in,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    exid::check(prior == nullptr, "didim: a prior is not supported");
    const exid::Dataset data = exid::materialize(data_in);
    loop_ = open_ ? std::make_unique<exid::estimators::ClosedLoop>(model, data, kName)
                  : std::make_unique<exid::estimators::ClosedLoop>(model, P_, data, ctx, kName);
    // (copies: the loop outlives this call and its context)
    loop_->setStop([stop = ctx.cancelled, deadline = ctx.deadline] {
      return deadline.expired() || (stop && stop());
    });
    const int p = model.numBase(), n = loop_->dof(), K = data.size();
    setPrior(model);
    chooseSamples(data, n, K);
    const long m = y_.size();
    exid::check(m > p, fmt::format("didim: {} rows for {} parameters", m, p));
    L_ = fit_nl_ ? static_cast<int>(loop_->nonlinear().size()) : 0;
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
    // "converged" only where the first-order test holds at the start of lowest objective (no
    // other start ended lower: multiStart), whatever stopped its iterations
    const bool converged = r.stopped && r.first_order;
    sigma_ = r.sigma;
    exid::Estimate e = finish(model, r.cur, r.x, m);
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
          exid::estimators::describePoint(names, values), r.cur.rss, 2.0 * r.g.norm(),
          r.distance_std, first_order_std_, r.stop)));
      d["warnings"] = w;
    }
    return e;
  }

 private:
  // The samples fitted (keep_t_, windows_, dropped_) and the measured output y_.
  void chooseSamples(const exid::Dataset& data, int n, int K) {
    // the samples fitted: all, or those whose t -+ measurement_delay_max_s lie in the
    // reference; with loop: open, the windows' samples after their starts
    keep_t_.clear();
    windows_.clear();
    std::vector<int> keep;
    if (open_) {
      exid::check(data.qd.rows() == K && data.qd.cols() == n,
                  "didim: loop: open starts each window from the recorded q and qd: the data "
                  "has no qd (the csv experiment's differentiate_cutoff_hz gives it)");
      int a = 0;
      while (a < K && data.t[a] < loop_->firstTime()) ++a;
      int last = K - 1;
      while (last > a && data.t[last] > loop_->lastTime()) --last;
      while (a < last) {
        int b = a + 1;
        while (b < last && data.t[b + 1] - data.t[a] <= window_s_ * (1 + 1e-12)) ++b;
        windows_.push_back({a, static_cast<int>(keep.size()), b - a});
        for (int k = a + 1; k <= b; ++k) {
          keep.push_back(k);
          keep_t_.push_back(data.t[k]);
        }
        a = b;
      }
      exid::check(!windows_.empty(), "didim: loop: open: no window fits in the recording");
    } else {
      for (int k = 0; k < K; ++k)
        if (!delay_ || (data.t[k] - delay_max_ >= loop_->reference().t0() &&
                        data.t[k] + delay_max_ <= loop_->reference().t1())) {
          keep.push_back(k);
          keep_t_.push_back(data.t[k]);
        }
    }
    dropped_ = K - static_cast<int>(keep.size());
    // the measured output, sample-major
    y_.resize(static_cast<Eigen::Index>(keep.size()) * n);
    const MatrixXd& Y = position_ ? data.q : data.tau;
    exid::check(
        Y.rows() == K && Y.cols() == n,
        fmt::format("didim: the data has no {} of {} joints", position_ ? "q" : "torque", n));
    for (std::size_t i = 0; i < keep.size(); ++i)
      y_.segment(static_cast<Eigen::Index>(i) * n, n) = Y.row(keep[i]);
  }

  // The first start x = (theta, log eta, d): the inverse model's least squares (drive gains at
  // their prior mean; the rows compensated for the initial delay), the model's nonlinear
  // parameters (fit_nonlinear), the initial delay (measurement_delay).
  VectorXd firstStart(const exid::ObservationModel& model, const exid::Dataset& data,
                      const exid::RunContext& ctx) const {
    const int p = model.numBase();
    // start: the inverse model's least squares (drive gains at their prior mean; the rows
    // compensated for the initial delay)
    exid::Rows R = model.rows(data, ctx);
    exid::estimators::checkRows(R, p, kName, 0);
    if (delay_ && delay0_ != 0.0) {
      exid::check(model.specs().per_sample,
                  "didim: measurement_delay_initial_s needs a model whose rows are per sample");
      int front = 0, back = 0;
      R = exid::delayedRows(R, data.t, delay0_, kName, &front, &back);
    }
    // x = (theta, log eta, d): the model's nonlinear parameters fitted with theta
    // (fit_nonlinear), the delay (measurement_delay)
    VectorXd theta(p + L_ + D_);
    theta.head(p) = startFit(model, R, prior_col_, prior_mu_);
    if (D_) theta[p + L_] = delay0_;
    for (int k = 0; k < L_; ++k) {
      const double v = loop_->nonlinear()[k];
      exid::check(v > 0,
                  fmt::format("didim: nonlinear parameter {} = {} is not positive (fitted "
                              "on log scale)",
                              model.nonlinearParameters()[static_cast<std::size_t>(k)].name, v));
      theta[p + k] = std::log(v);
    }
    return theta;
  }

  struct Sim {
    VectorXd y;  // simulated output, sample-major
    MatrixXd J;  // d y / d theta (with sensitivities)
    double rss = 0.0;
    double prior_rss = 0.0;  // the gain prior's pseudo-observations
    double total() const { return rss + prior_rss; }
    // the simulation's paths (one per window; without sensitivities): an accepted trial's
    // sensitivities are taken along them (ClosedLoop::sensitivitiesAlong)
    std::vector<exid::estimators::ClosedLoop::Path> paths;
  };

  // One Levenberg-Marquardt run (one start): where it started, where it is with its last
  // simulation (with the sensitivities), and its state.
  struct Run {
    VectorXd x0, x;  // (theta, log eta, d): the start; the current point
    Sim cur;
    double sigma = 0.0;  // the noise std the gain prior's weight uses
    int round = 1;       // the prior's noise rounds
    // The second-order term sum r_i d2 y_i / dtheta2 of the residual's Hessian, by secant
    // updates (Dennis, Gay and Welsch, NL2SOL), and the last accepted step's pair
    MatrixXd Ssec;
    VectorXd g_prev, s_prev, Jr_prev_at_new;
    // At the current point: H = J^T J (+ the prior's), g = J^T r (+ the prior's), Hm = H + S
    // (or H), and the decrease the undamped model predicts, g^T Hm^-1 g (infinite where Hm is
    // not positive definite: no minimum claimed)
    MatrixXd H, Hm;
    VectorXd g;
    double undamped = 0.0;
    bool prepared = false;  // (H, Hm, g, undamped are those of x)
    // Levenberg-Marquardt's damping (relative to diag(J^T J)) and its growth after rejections
    double mu = 1e-3, nu = 2.0;
    // simulations: integrations of the state; jacobians: sensitivity passes (the first with its
    // own simulation, the others along an accepted trial's)
    int iterations = 0, sims = 1, jacobians = 1;
    std::string stop;      // why it stopped (empty: the iterations ran out)
    bool stopped = false;  // a stop test held
    exid::Json trace = exid::Json::array();
    // at its end (conclude): the first-order test
    bool first_order = false;
    double distance_std = std::numeric_limits<double>::infinity();
    double undamped_relative = std::numeric_limits<double>::infinity();
    std::string error;  // a start that could not be simulated
  };

  // A run at x: its simulation with the sensitivities; the prior's weight from it (sigma < 0)
  // or sigma, settled (no further round).
  Run startRun(const VectorXd& x, const exid::Dataset& data, double sigma) const {
    Run r;
    r.x0 = x;
    r.x = x;
    r.cur = simulate(x, data, true);
    r.Ssec = MatrixXd::Zero(x.size(), x.size());
    if (!prior_col_.empty()) {
      r.sigma = sigma < 0 ? noiseStd(r.cur) : sigma;
      if (sigma >= 0) r.round = 2;
      priorTerms(x, r.sigma, &r.cur);
    }
    record(&r, r.cur);
    return r;
  }

  double noiseStd(const Sim& s) const {
    return std::max(std::sqrt(s.rss / static_cast<double>(m_ - (p_ + L_ + D_))), floor_sigma_);
  }

  void record(Run* r, const Sim& s, double rho = 0.0, double damping = 0.0, int trials = 0) const {
    exid::Json t = exid::Json::object();
    t["rss"] = s.rss;
    if (!prior_col_.empty()) t["prior_rss"] = s.prior_rss;
    if (trials > 0) {
      t["gain_ratio"] = rho;  // actual / predicted decrease
      t["damping"] = damping;
      t["trials"] = trials;
    }
    r->trace.push_back(t);
  }

  // H, Hm, g and the undamped model's predicted decrease at r's point (the secant term updated
  // with the last accepted step). Below rss_tolerance, x is at the minimum to the simulation's
  // precision (trials would only see its noise). The damped step's prediction is no test: a
  // large damping shrinks it wherever the model is poor (Gauss-Newton on the TX40 stopped
  // there 7.5 % above the minimum).
  void prepare(Run* rp) const {
    Run& r = *rp;
    r.H = r.cur.J.transpose() * r.cur.J;
    r.g = r.cur.J.transpose() * (y_ - r.cur.y);
    if (secant_ && r.s_prev.size() > 0) {
      // secant pair: s, yv = grad f(new) - grad f(old) of f = rss / 2 (without the prior's
      // pseudo-observations, linear in theta), y# = (J_new - J_old)^T r_new
      exid::estimators::secantSecondOrderUpdate(&r.Ssec, r.s_prev, -(r.g - r.g_prev),
                                                -r.g + r.Jr_prev_at_new);
      r.s_prev.resize(0);
    }
    r.g_prev = r.g;
    for (std::size_t i = 0; i < prior_col_.size(); ++i) {  // pseudo-observations
      const int c = prior_col_[i];
      const double w = r.sigma / prior_sd_[static_cast<Eigen::Index>(i)];
      r.H(c, c) += w * w;
      r.g[c] += w * w * (prior_mu_[static_cast<Eigen::Index>(i)] - r.x[c]);
    }
    r.undamped = std::numeric_limits<double>::infinity();
    r.Hm = r.H;
    if (secant_) r.Hm += r.Ssec;
    const Eigen::LDLT<MatrixXd> ldlt(r.Hm);
    if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
      const double gd = r.g.dot(ldlt.solve(r.g));
      if (std::isfinite(gd) && gd >= 0) r.undamped = gd;
    }
    r.prepared = true;
  }

  // Levenberg-Marquardt from r's state until a stop test holds or r has run `limit` iterations
  // (a run stopped by its limit can be continued with a larger one). The damping by Nielsen's
  // rule: after an accepted step mu *= max(1/3, 1 - (2 rho - 1)^3), rho the actual over the
  // predicted decrease; after a rejected one mu *= nu, nu doubling (a fixed up/down factor
  // makes the damping oscillate: a rejected trial, a whole simulation, every other iteration).
  void iterate(Run* rp, int limit, const exid::Dataset& data, const exid::RunContext& ctx) const {
    Run& r = *rp;
    const int p = p_;
    while (!r.stopped && r.iterations < limit) {
      ++r.iterations;
      if (ctx.shouldStop()) throw exid::Error("didim: stopped");
      // J = d y_sim / d theta; r = y - y_sim: the step solves (J^T J + S + mu D) d = J^T r,
      // D = diag(J^T J), S the secant term (hessian: secant) or 0 (a damped matrix that is not
      // positive definite is a rejected try)
      if (!r.prepared) prepare(&r);
      const double undamped_relative = r.undamped / std::max(r.cur.total(), 1e-300);
      bool accepted = false, flat = undamped_relative < ftol_;
      double moved = 0.0;
      for (int tries = 0; tries < 12 && !accepted && !flat; ++tries) {
        MatrixXd A = r.Hm;
        A.diagonal() += r.mu * r.H.diagonal().cwiseMax(1e-300);
        const Eigen::LDLT<MatrixXd> ldlt(A);
        const VectorXd step = ldlt.solve(r.g);
        if (!step.allFinite() || !ldlt.isPositive() || ldlt.info() != Eigen::Success) {
          r.mu *= 10;
          continue;
        }
        // the decrease the damped model predicts for this step (the gain ratio's denominator)
        const double predicted = 2 * r.g.dot(step) - step.dot(r.Hm * step);
        // trials without the sensitivities; the accepted point gets them
        if (D_ && std::abs(r.x[p + L_] + step[p + L_]) > delay_max_) {
          ++rejected_bound_;  // (a delay beyond measurement_delay_max_s is a rejected step)
          r.mu *= r.nu;
          r.nu *= 2;
          continue;
        }
        Sim trial;
        bool ok = true;
        try {
          trial = simulate(r.x + step, data, false);
          priorTerms(r.x + step, r.sigma, &trial);
        } catch (const exid::Error&) {
          ok = false;  // (a trial that cannot be simulated is a rejected step)
        }
        ++r.sims;
        if (ok && trial.total() <= r.cur.total()) {
          const double rho = (r.cur.total() - trial.total()) / std::max(predicted, 1e-300);
          // theta relative to its norm; log eta as it is (a relative change of eta); the
          // delay relative to its bound
          moved = step.head(p).norm() / std::max(r.x.head(p).norm(), 1e-300);
          if (L_ > 0) moved = std::max(moved, step.segment(p, L_).cwiseAbs().maxCoeff());
          if (D_) moved = std::max(moved, std::abs(step[p + L_]) / delay_max_);
          if (secant_) {
            r.s_prev = step;
            r.Jr_prev_at_new = r.cur.J.transpose() * (y_ - trial.y);
          }
          r.x += step;
          r.prepared = false;
          r.cur = simulate(r.x, data, true, &trial);  // (along the trial's paths)
          priorTerms(r.x, r.sigma, &r.cur);
          ++r.jacobians;
          record(&r, r.cur, rho, r.mu, tries + 1);
          r.mu = std::max(r.mu * std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3)), 1e-12);
          r.nu = 2.0;
          accepted = true;
        } else {
          r.mu *= r.nu;
          r.nu *= 2;
        }
      }
      if (flat) {
        r.stop = fmt::format(
            "the undamped model predicts a decrease of {:.2g} of the residual, below "
            "rss_tolerance = {:g}",
            undamped_relative, ftol_);
      } else if (!accepted) {
        r.stop = "no step lowers the residual (a minimum to the simulation's precision)";
      } else if (moved < xtol_) {
        r.stop = fmt::format(
            "the step moved theta by {:.2g} of itself, below step_tolerance = {:g}", moved, xtol_);
      }
      if (r.stop.empty()) continue;
      // with a prior: its weight from the noise std at this minimum, once more (the fixed point
      // of sqrt(rss / (m - q)): a second round settles it)
      if (!prior_col_.empty() && r.round == 1) {
        const double s2 = noiseStd(r.cur);
        ++r.round;
        if (std::abs(s2 - r.sigma) > 1e-3 * r.sigma) {
          r.sigma = s2;
          priorTerms(r.x, r.sigma, &r.cur);
          r.prepared = false;
          r.stop.clear();
          r.mu = 1e-3;
          r.nu = 2.0;
          continue;
        }
      }
      r.stopped = true;
    }
  }

  // The first-order test at r's end: the minimum the undamped model predicts lies within
  // first_order_std standard deviations (or its decrease is below rss_tolerance).
  void conclude(Run* rp) const {
    Run& r = *rp;
    if (!r.prepared) prepare(&r);
    if (!r.stopped && r.stop.empty())
      r.stop = fmt::format("max_iterations = {} reached", max_iter_);
    const double s2_end = r.cur.rss / static_cast<double>(std::max(m_ - (p_ + L_ + D_), 1L));
    r.distance_std = std::isfinite(r.undamped) ? std::sqrt(r.undamped / std::max(s2_end, 1e-300))
                                               : std::numeric_limits<double>::infinity();
    r.undamped_relative = r.undamped / std::max(r.cur.total(), 1e-300);
    r.first_order = std::isfinite(r.undamped) &&
                    (r.undamped_relative < ftol_ || r.distance_std <= first_order_std_);
  }

  // The parameters the starts move, other than theta: the drive gains (dK) and load-dependent
  // Coulomb (FcL) columns, the model's nonlinear parameters (log eta), the delay.
  struct StartParam {
    int index = 0;  // in x
    int kind = 0;   // 0: log eta, 1: dK, 2: FcL, 3: delay
    std::string name;
  };
  std::vector<StartParam> startParams(const exid::ObservationModel& model) const {
    std::vector<StartParam> out;
    for (int c = 0; c < p_; ++c) {
      const std::string& nm = model.base().names[static_cast<std::size_t>(c)];
      const int kind = exid::torqueColumnKind(nm);
      if (kind == 1 || kind == 2) out.push_back({c, kind, nm});
    }
    const std::vector<exid::NonlinearParameter> nl = model.nonlinearParameters();
    for (int k = 0; k < L_; ++k) out.push_back({p_ + k, 0, nl[static_cast<std::size_t>(k)].name});
    if (D_) out.push_back({p_ + L_, 3, "measurement_delay_s"});
    return out;
  }
  // Start i's side and size: 0, -1, +1, -1/2, +1/2, -2, +2 (as gains_ls).
  static double startMultiple(int i) {
    static const double kMul[] = {0.0, -1.0, 1.0, -0.5, 0.5, -2.0, 2.0};
    return kMul[i];
  }
  // The sample period of the fitted samples (the delay's shift is counted in it).
  double samplePeriod() const {
    return keep_t_.size() > 1
               ? (keep_t_.back() - keep_t_.front()) / static_cast<double>(keep_t_.size() - 1)
               : 0.0;
  }
  // Start i > 0 from the first start x0: eta times 2^(+-m), dK and FcL shifted by
  // +-m start_spread, the delay by +-2 m sample periods (within 0.9 of its bound),
  // m = |startMultiple(i)|, the sign its; theta's other entries by least squares on the rows at
  // that eta and delay, dK and FcL held.
  VectorXd startPoint(const exid::ObservationModel& model, const exid::Dataset& data,
                      const exid::RunContext& ctx, const VectorXd& x0, int i) const {
    const double mul = startMultiple(i);
    VectorXd x = x0;
    std::vector<int> held;
    std::vector<double> held_at;
    for (const StartParam& sp : sp_) {
      if (sp.kind == 1 || sp.kind == 2) {
        held.push_back(sp.index);
        held_at.push_back(x0[sp.index] + mul * spread_);
      } else if (sp.kind == 0) {
        x[sp.index] = x0[sp.index] + mul * std::log(2.0);
      } else {
        x[sp.index] = std::clamp(x0[sp.index] + 2.0 * mul * samplePeriod(), -0.9 * delay_max_,
                                 0.9 * delay_max_);
      }
    }
    exid::Rows R = L_ > 0
                       ? model.rowsAt(data, x.segment(p_, L_).array().exp().matrix(), nullptr, ctx)
                       : model.rows(data, ctx);
    exid::estimators::checkRows(R, p_, kName, 0);
    if (D_ && x[p_ + L_] != 0.0) {
      int front = 0, back = 0;
      R = exid::delayedRows(R, data.t, x[p_ + L_], kName, &front, &back);
    }
    x.head(p_) = startFit(
        model, R, held,
        Eigen::Map<const VectorXd>(held_at.data(), static_cast<Eigen::Index>(held_at.size())));
    return x;
  }
  Run failedRun(const VectorXd& x, const std::string& error) const {
    Run r;
    r.x0 = x;
    r.x = x;
    r.error = error;
    r.sims = 0;
    r.jacobians = 0;
    return r;
  }
  std::string startName(int i) const {
    const std::string first =
        prior_col_.empty() ? "least squares on the recording's rows (the inverse model)"
                           : "least squares on the recording's rows (the inverse model) with the "
                             "drive gains at their prior mean";
    if (i == 0) return first;
    const double mul = startMultiple(i);
    bool eta = false, torque = false, delay = false;
    for (const StartParam& sp : sp_) {
      eta = eta || sp.kind == 0;
      torque = torque || sp.kind == 1 || sp.kind == 2;
      delay = delay || sp.kind == 3;
    }
    std::string moved;
    auto add = [&](const std::string& what) { moved += (moved.empty() ? "" : ", ") + what; };
    if (eta) add(fmt::format("the model's nonlinear parameters x{:g}", std::pow(2.0, mul)));
    if (torque) add(fmt::format("dK and FcL {:+g}", mul * spread_));
    if (delay) add(fmt::format("the delay {:+g} samples", 2.0 * mul));
    return fmt::format("start 1 with {}, theta by least squares on the rows there", moved);
  }

  // The starts after the first (whose run is done): each run for start_iterations at most at
  // the first's final prior weight; the lowest of them continued to max_iterations when it is
  // below the first's end; the lowest objective kept (a later start only beyond the
  // simulation's rounding). Returns the kept run's index.
  int multiStart(const exid::ObservationModel& model, const exid::Dataset& data,
                 const exid::RunContext& ctx, std::vector<Run>* runs) const {
    if (starts_ <= 1 || sp_.empty()) return 0;
    const VectorXd x0 = (*runs)[0].x0;
    // (the first's final weight; its own where the first could not be simulated)
    const double sigma0 = (*runs)[0].error.empty() ? (*runs)[0].sigma : -1.0;
    for (int i = 1; i < starts_; ++i) {
      Run r;
      VectorXd xs = x0;
      try {
        xs = startPoint(model, data, ctx, x0, i);
        r = startRun(xs, data, sigma0);
        iterate(&r, std::min(start_iter_, max_iter_), data, ctx);
        if (!r.stopped)
          r.stop = fmt::format("start_iterations = {} reached", std::min(start_iter_, max_iter_));
      } catch (const exid::Error& err) {
        if (ctx.shouldStop()) throw;
        r = failedRun(xs, err.what());  // (a start that cannot be simulated is left out)
      }
      runs->push_back(std::move(r));
    }
    int best = lowest(*runs, sigma0 < 0 ? 0.0 : sigma0);
    if (best < 0) {
      std::string all;
      for (std::size_t i = 0; i < runs->size(); ++i)
        all += fmt::format("{}start {}: {}", i ? "; " : "", i + 1, (*runs)[i].error);
      throw exid::Error(
          fmt::format("didim: none of the {} starts could be simulated ({})", runs->size(), all));
    }
    Run& b = (*runs)[static_cast<std::size_t>(best)];
    if (best > 0 && !b.stopped) {  // on to convergence, its own prior weight settled
      if (!prior_col_.empty()) b.round = 1;
      b.stop.clear();
      iterate(&b, max_iter_, data, ctx);
      best = lowest(*runs, b.sigma);
    }
    return best;
  }
  // The run of lowest objective (rss plus the prior's terms at the weight sigma); a later one
  // only below the earlier by more than the simulation's rounding.
  int lowest(const std::vector<Run>& runs, double sigma) const {
    const double floor = 1e-12 * y_.squaredNorm();
    int best = -1;  // (none: every start failed)
    auto objective = [&](const Run& r) { return r.cur.rss + priorRss(r.x, sigma); };
    for (std::size_t i = 0; i < runs.size(); ++i) {
      if (!runs[i].error.empty()) continue;
      const double ob = best < 0 ? 0.0 : objective(runs[static_cast<std::size_t>(best)]);
      if (best < 0 || objective(runs[i]) < ob - 1e-7 * ob - floor) best = static_cast<int>(i);
    }
    return best;
  }

  // details.starts: each start's nonlinear parameters where it began and ended, its objective,
  // iterations, stop and first-order test; details.best_start.
  void describeStarts(const std::vector<Run>& runs, int best, exid::Json* d) const {
    const std::vector<StartParam>& sp = sp_;
    std::vector<std::string> names;
    for (const StartParam& s : sp) names.push_back(s.name);
    auto values = [&](const VectorXd& x) {
      VectorXd v(static_cast<Eigen::Index>(sp.size()));
      for (std::size_t k = 0; k < sp.size(); ++k)
        v[static_cast<Eigen::Index>(k)] =
            sp[k].kind == 0 ? std::exp(x[sp[k].index]) : x[sp[k].index];
      return v;
    };
    const double sigma = runs[static_cast<std::size_t>(best)].sigma;
    exid::Json starts = exid::Json::array();
    for (std::size_t i = 0; i < runs.size(); ++i) {
      const Run& r = runs[i];
      exid::Json o = exid::Json::object();
      o["start"] = startName(static_cast<int>(i));
      if (!sp.empty()) o["from"] = exid::estimators::describePoint(names, values(r.x0));
      if (!r.error.empty()) {
        o["error"] = r.error;
        starts.push_back(o);
        continue;
      }
      if (!sp.empty()) o["to"] = exid::estimators::describePoint(names, values(r.x));
      o["objective"] = r.cur.rss + priorRss(r.x, sigma);
      o["rss"] = r.cur.rss;
      o["iterations"] = r.iterations;
      o["simulations"] = r.sims;
      o["stop"] = r.stop;
      o["stopped"] = r.stopped;
      o["first_order"] = r.first_order;
      o["distance_std"] = std::isfinite(r.distance_std) ? exid::Json(r.distance_std) : exid::Json();
      starts.push_back(o);
    }
    (*d)["starts"] = starts;
    (*d)["best_start"] = best + 1;
    (*d)["starts_definition"] = fmt::format(
        "{}; objective: rss plus the gain prior's terms at the kept start's weight",
        sp.empty() ? std::string("one start: no nonlinear parameter beyond theta (drive gains, "
                                 "load Coulomb, the model's nonlinear parameters, a delay)")
                   : fmt::format("Levenberg-Marquardt from each of starts = {} (start_spread = "
                                 "{:g}), the later ones for start_iterations = {} at most and "
                                 "the lowest of them on to max_iterations when below the "
                                 "first's end; the lowest objective kept (a later start only "
                                 "beyond the simulation's rounding, 1e-7 of it)",
                                 starts_, spread_, start_iter_));
  }
  // The inverse model's least squares: batch_ls's rank-revealing solve (an unidentifiable
  // direction is refused by name), the columns `cols` held at `at`. The first start holds the
  // gains at the prior's mean (their scale with theta is not in the rows); the later starts
  // hold the gains and FcL at their shifted values.
  VectorXd startFit(const exid::ObservationModel& model, const exid::Rows& R,
                    const std::vector<int>& cols, const VectorXd& at) const {
    const int p = model.numBase();
    std::vector<int> free;
    std::vector<std::string> names;
    VectorXd fixed = VectorXd::Zero(p);
    std::vector<bool> held(static_cast<std::size_t>(p), false);
    for (std::size_t i = 0; i < cols.size(); ++i) {
      held[static_cast<std::size_t>(cols[i])] = true;
      fixed[cols[i]] = at[static_cast<Eigen::Index>(i)];
    }
    for (int c = 0; c < p; ++c)
      if (!held[static_cast<std::size_t>(c)]) {
        free.push_back(c);
        names.push_back(model.base().names[static_cast<std::size_t>(c)]);
      }
    MatrixXd W(R.W.rows(), static_cast<Eigen::Index>(free.size()));
    for (std::size_t i = 0; i < free.size(); ++i)
      W.col(static_cast<Eigen::Index>(i)) = R.W.col(free[i]);
    exid::estimators::RowAccumulator acc(static_cast<int>(free.size()));
    acc.add(W, R.y - R.W * fixed);
    const VectorXd th =
        exid::estimators::solveLeastSquares(acc, names, exid::estimators::SolveOptions(), kName)
            .theta;
    VectorXd out = fixed;
    for (std::size_t i = 0; i < free.size(); ++i) out[free[i]] = th[static_cast<Eigen::Index>(i)];
    return out;
  }
  static exid::estimators::ClosedLoop::Tolerances withSensitivities(
      exid::estimators::ClosedLoop::Tolerances t, const std::string& how) {
    t.cvodes_sensitivities = how == "cvodes";
    return t;
  }

  // The gain prior's columns (the model's dK, base order) and its std and mean per column.
  void setPrior(const exid::ObservationModel& model) {
    prior_col_ = loop_->driveGainColumns();
    const std::size_t ng = prior_col_.size();
    if (ng == 0) {
      exid::check(prior_std_.empty(),
                  "didim: gain_prior_std is given but the model has no drive "
                  "gain (differential's drive_gains)");
      prior_col_.clear();
      prior_sd_.resize(0);
      prior_mu_.resize(0);
      return;
    }
    exid::check(!prior_std_.empty(),
                fmt::format("didim: model '{}' has drive gains (dK): their scale with theta is "
                            "not in the closed loop (a common factor of theta and 1 + dK "
                            "gives the same motion and command); give gain_prior_std",
                            model.pluginName()));
    prior_sd_ = exid::estimators::perGain(prior_std_, ng, "gain_prior_std", 0.0, kName);
    prior_mu_ = exid::estimators::perGain(prior_mean_, ng, "gain_prior_dK", 0.0, kName);
  }
  // The prior's pseudo-observations' sum of squares at x (weight sigma / s).
  double priorRss(const VectorXd& x, double sigma) const {
    double out = 0.0;
    for (std::size_t i = 0; i < prior_col_.size(); ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      const double r = sigma * (prior_mu_[k] - x[prior_col_[i]]) / prior_sd_[k];
      out += r * r;
    }
    return out;
  }
  void priorTerms(const VectorXd& x, double sigma, Sim* s) const {
    s->prior_rss = priorRss(x, sigma);
  }

  // The loop at x = (theta, log eta, d) at the kept samples' times less d; J = d y / d x (the
  // eta columns times eta: d/d log eta; the delay's: -d tau_c / dt).
  // With `along` (the same xv's simulation without them), the sensitivities along its paths.
  Sim simulate(const VectorXd& xv, const exid::Dataset& data, bool sens,
               const Sim* along = nullptr) const {
    const int n = loop_->dof(), K = static_cast<int>(keep_t_.size()),
              p = static_cast<int>(xv.size());
    const VectorXd theta = xv.head(p_);
    if (L_ > 0) loop_->setNonlinear(xv.segment(p_, L_).array().exp().matrix(), sens);
    const double d = D_ ? xv[p_ + L_] : 0.0;
    VectorXd times(K);
    for (int k = 0; k < K; ++k) times[k] = keep_t_[static_cast<std::size_t>(k)] - d;
    Sim out;
    out.y.resize(static_cast<Eigen::Index>(K) * n);
    if (sens) out.J.resize(static_cast<Eigen::Index>(K) * n, p);
    auto at = [&](int k, const VectorXd& x, const MatrixXd* S) {
      const Eigen::Index r0 = static_cast<Eigen::Index>(k) * n;
      out.y.segment(r0, n) =
          position_ ? VectorXd(x.head(n)) : loop_->control(times[k], x.head(n), x.tail(n));
      if (S) {  // d tau_c / d theta = -Kp S_q - Kd S_qd, or d q / d theta = S_q
        out.J.block(r0, 0, n, S->cols()) =
            position_ ? MatrixXd(S->topRows(n))
                      : MatrixXd(-(loop_->kp().asDiagonal() * S->topRows(n)) -
                                 loop_->kd().asDiagonal() * S->bottomRows(n));
        if (D_) {
          const VectorXd a = loop_->acceleration(theta, times[k], x.head(n), x.tail(n));
          out.J.block(r0, p_ + L_, n, 1) = -loop_->controlRate(times[k], x.head(n), x.tail(n), a);
        }
      }
    };
    const bool replay = sens && along && !tol_loop_.cvodes_sensitivities &&
                        along->paths.size() == (open_ ? windows_.size() : 1);
    if (!sens) out.paths.resize(open_ ? windows_.size() : 1);
    if (!open_) {
      if (replay)
        loop_->sensitivitiesAlong(theta, along->paths[0], at);
      else
        loop_->simulate(theta, times, tol_loop_, sens, at, sens ? nullptr : &out.paths[0]);
    } else {  // each window from its recorded start (which does not depend on theta)
      for (std::size_t i = 0; i < windows_.size(); ++i) {
        const Window& w = windows_[i];
        auto at_w = [&](int k, const VectorXd& x, const MatrixXd* S) { at(w.first + k, x, S); };
        if (replay) {
          loop_->sensitivitiesAlong(theta, along->paths[i], at_w);
          continue;
        }
        VectorXd x0(2 * n);
        x0 << data.q.row(w.start).transpose(), data.qd.row(w.start).transpose();
        loop_->simulateFrom(theta, data.t[w.start], x0, times.segment(w.first, w.count), tol_loop_,
                            sens, at_w, sens ? nullptr : &out.paths[i]);
      }
    }
    if (sens && L_ > 0)
      for (int k = 0; k < L_; ++k) out.J.col(p_ + k) *= std::exp(xv[p_ + k]);
    out.rss = (y_ - out.y).squaredNorm();
    return out;
  }

  // The sensitivities' Jacobian along check_ random directions (each parameter moved by 1e-4
  // of its size) against central differences of the simulation.
  exid::Json gradientCheck(const VectorXd& theta, const exid::Dataset& data, const Sim& s) const {
    std::mt19937_64 rng(5);
    std::normal_distribution<double> nd(0.0, 1.0);
    double worst = 0.0;
    for (int c = 0; c < check_; ++c) {
      VectorXd dir(theta.size());
      for (Eigen::Index j = 0; j < dir.size(); ++j)
        dir[j] = 1e-4 * std::max(std::abs(theta[j]), 1e-3) * nd(rng);
      const VectorXd fd =
          (simulate(theta + dir, data, false).y - simulate(theta - dir, data, false).y) / 2.0;
      const VectorXd an = s.J * dir;
      worst = std::max(worst, (fd - an).norm() / std::max(fd.norm(), 1e-300));
    }
    exid::Json c = exid::Json::object();
    c["directions"] = check_;
    c["step"] = "each parameter moved by 1e-4 of max(|theta_j|, 1e-3), random signs and sizes";
    c["max_relative_difference"] = worst;
    return c;
  }

  exid::Estimate finish(const exid::ObservationModel& model, const Sim& s, const VectorXd& x,
                        long m) const {
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
    L.covariance = C.topLeftCorner(p, p);
    L.std = L.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    L.rel_std_percent = exid::estimators::relativeStdPercent(L.theta, L.std);
    Eigen::JacobiSVD<MatrixXd> raw(s.J);
    L.singular_values = raw.singularValues();
    L.cond_W = L.singular_values[0] / L.singular_values[q - 1];
    L.singular_values_scaled = sv;
    L.cond_W_scaled = sv[0] / sv[q - 1];
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
    return e;
  }

  exid::ParamSet P_;
  bool position_;
  int max_iter_;
  double ftol_, xtol_, first_order_std_;
  exid::estimators::ClosedLoop::Tolerances tol_loop_;
  int check_;
  bool secant_;
  bool fit_nl_;
  std::vector<double> prior_std_, prior_mean_;
  bool delay_ = false;
  double delay0_ = 0.0, delay_max_ = 0.0;
  int L_ = 0, p_ = 0, D_ = 0;   // nonlinear parameters fitted; base parameters; the delay (0, 1)
  std::vector<int> prior_col_;  // the drive gains' base columns
  VectorXd prior_sd_, prior_mu_;
  double sigma_ = 0.0;        // the noise std the prior's weight used at the kept start
  long m_ = 0;                // outputs fitted
  double floor_sigma_ = 0.0;  // the floor of the prior weight's noise std
  int starts_ = 1, start_iter_ = 5;
  double spread_ = 0.25;
  std::vector<double> keep_t_;  // the times of the samples fitted
  bool open_ = false;           // loop: open
  double window_s_ = 0.0;
  struct Window {
    int start = 0;  // the recorded sample it starts from
    int first = 0;  // its first fitted sample's index in keep_t_
    int count = 0;  // fitted samples (start + 1 .. start + count)
  };
  std::vector<Window> windows_;
  int dropped_ = 0;  // samples left out (measurement_delay_max_s)
  mutable int rejected_bound_ = 0;
  std::unique_ptr<exid::estimators::ClosedLoop> loop_;
  std::vector<StartParam> sp_;  // the parameters the starts move (startParams)
  VectorXd y_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Didim)
