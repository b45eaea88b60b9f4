// exid — estimator `didim`: Levenberg-Marquardt on x = (theta, log eta, d) (the secant term,
// Nielsen's damping, the first-order test), the gain prior's pseudo-observations, and the
// starts on both sides of the first (see didim.cpp).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "didim.hpp"
#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid::didim {

// The gain prior's columns (the model's dK, base order) and its std and mean per column.
void Didim::setPrior(const exid::ObservationModel& model) {
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
double Didim::priorRss(const VectorXd& x, double sigma) const {
  double out = 0.0;
  for (std::size_t i = 0; i < prior_col_.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const double r = sigma * (prior_mu_[k] - x[prior_col_[i]]) / prior_sd_[k];
    out += r * r;
  }
  return out;
}
void Didim::priorTerms(const VectorXd& x, double sigma, Sim* s) const {
  s->prior_rss = priorRss(x, sigma);
}

// A run at x: its simulation with the sensitivities; the prior's weight from it (sigma < 0)
// or sigma, settled (no further round).
Didim::Run Didim::startRun(const VectorXd& x, const exid::Dataset& data, double sigma) const {
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

double Didim::noiseStd(const Sim& s) const {
  return std::max(std::sqrt(s.rss / static_cast<double>(m_ - (p_ + L_ + D_))), floor_sigma_);
}

void Didim::record(Run* r, const Sim& s, double rho, double damping, int trials) const {
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
void Didim::prepare(Run* rp) const {
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
void Didim::iterate(Run* rp, int limit, const exid::Dataset& data,
                    const exid::RunContext& ctx) const {
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
      r.stop = fmt::format("the step moved theta by {:.2g} of itself, below step_tolerance = {:g}",
                           moved, xtol_);
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
void Didim::conclude(Run* rp) const {
  Run& r = *rp;
  if (!r.prepared) prepare(&r);
  if (!r.stopped && r.stop.empty()) r.stop = fmt::format("max_iterations = {} reached", max_iter_);
  if (!std::isfinite(r.undamped) && secant_) {
    // The secant term can leave H + S indefinite where the last steps were at the simulation's
    // precision (a change of the last bits of sin and cos decides it): the test then uses the
    // Gauss-Newton model H alone, positive semidefinite, instead of finding no prediction.
    const Eigen::LDLT<MatrixXd> ldlt(r.H);
    if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
      const double gd = r.g.dot(ldlt.solve(r.g));
      if (std::isfinite(gd) && gd >= 0) r.undamped = gd;
    }
  }
  const double s2_end = r.cur.rss / static_cast<double>(std::max(m_ - (p_ + L_ + D_), 1L));
  r.distance_std = std::isfinite(r.undamped) ? std::sqrt(r.undamped / std::max(s2_end, 1e-300))
                                             : std::numeric_limits<double>::infinity();
  r.undamped_relative = r.undamped / std::max(r.cur.total(), 1e-300);
  r.first_order = std::isfinite(r.undamped) &&
                  (r.undamped_relative < ftol_ || r.distance_std <= first_order_std_);
}

// The parameters the starts move (StartParam): dK and FcL in base order, log eta, the delay.
std::vector<Didim::StartParam> Didim::startParams(const exid::ObservationModel& model) const {
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
double Didim::startMultiple(int i) {
  static const double kMul[] = {0.0, -1.0, 1.0, -0.5, 0.5, -2.0, 2.0};
  return kMul[i];
}
// The sample period of the fitted samples (the delay's shift is counted in it).
double Didim::samplePeriod() const {
  return keep_t_.size() > 1
             ? (keep_t_.back() - keep_t_.front()) / static_cast<double>(keep_t_.size() - 1)
             : 0.0;
}
// Start i > 0 from the first start x0: eta times 2^(+-m), dK and FcL shifted by
// +-m start_spread, the delay by +-2 m sample periods (within 0.9 of its bound),
// m = |startMultiple(i)|, the sign its; theta's other entries by least squares on the rows at
// that eta and delay, dK and FcL held.
VectorXd Didim::startPoint(const exid::ObservationModel& model, const exid::Dataset& data,
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
  exid::Rows R = L_ > 0 ? model.rowsAt(data, x.segment(p_, L_).array().exp().matrix(), nullptr, ctx)
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
Didim::Run Didim::failedRun(const VectorXd& x, const std::string& error) const {
  Run r;
  r.x0 = x;
  r.x = x;
  r.error = error;
  r.sims = 0;
  r.jacobians = 0;
  return r;
}
std::string Didim::startName(int i) const {
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
// below the first's end; the lowest objective kept (a later start only below the earlier by
// more than the first-order test's region: lowest()). Returns the kept run's index.
int Didim::multiStart(const exid::ObservationModel& model, const exid::Dataset& data,
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
// only below the earlier by more than the first-order test's region: first_order_std^2 s^2
// (s^2 = rss / (m - p - L - D) of the earlier), the objective's rise at that many standard
// deviations from a minimum. Two runs ending in the same minimum, each passing the test, differ
// by up to about that much (with the simulation's error), which tells no start from another.
int Didim::lowest(const std::vector<Run>& runs, double sigma) const {
  const double floor = 1e-12 * y_.squaredNorm();
  int best = -1;  // (none: every start failed)
  auto objective = [&](const Run& r) { return r.cur.rss + priorRss(r.x, sigma); };
  const double dof = static_cast<double>(std::max(m_ - (p_ + L_ + D_), 1L));
  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (!runs[i].error.empty()) continue;
    if (best < 0) {
      best = static_cast<int>(i);
      continue;
    }
    const Run& kept = runs[static_cast<std::size_t>(best)];
    const double ob = objective(kept);
    const double region = first_order_std_ * first_order_std_ * kept.cur.rss / dof;
    if (objective(runs[i]) < ob - region - 1e-7 * ob - floor) best = static_cast<int>(i);
  }
  return best;
}

// details.starts: each start's nonlinear parameters where it began and ended, its objective,
// iterations, stop and first-order test; details.best_start.
void Didim::describeStarts(const std::vector<Run>& runs, int best, exid::Json* d) const {
  const std::vector<StartParam>& sp = sp_;
  std::vector<std::string> names;
  for (const StartParam& s : sp) names.push_back(s.name);
  auto values = [&](const VectorXd& x) {
    VectorXd v(static_cast<Eigen::Index>(sp.size()));
    for (std::size_t k = 0; k < sp.size(); ++k)
      v[static_cast<Eigen::Index>(k)] = sp[k].kind == 0 ? std::exp(x[sp[k].index]) : x[sp[k].index];
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

}  // namespace exid::didim
