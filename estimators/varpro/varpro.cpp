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
// See docs/estimators.md, "Variable projection".
#include <fmt/format.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "exid/delay.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"
#include "exid/signal.hpp"

namespace {

using exid::estimators::RowAccumulator;

class VarPro : public exid::Estimator {
 public:
  static constexpr const char* kName = "varpro";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "variable projection: the linear parameters by least squares for given nonlinear ones "
      "(Stribeck velocities, smoothing widths), those by Levenberg-Marquardt with exact "
      "derivatives; standard deviations of all parameters";

  static std::vector<exid::ParamDecl> params() {
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

  explicit VarPro(const exid::ParamSet& p)
      : max_evals_(static_cast<int>(p.getInt("max_evaluations"))),
        xtol_(p.getDouble("step_tolerance")),
        ftol_(p.getDouble("rss_tolerance")),
        starts_(static_cast<int>(p.getInt("starts"))),
        gtol_(p.getDouble("gradient_tolerance")),
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

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.streams = true;  // one pass per evaluation, in chunks
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    exid::check(prior == nullptr, "varpro: a prior is not supported (use batch_ls)");
    rejected_singular_ = rejected_bound_ = 0;
    setUp(model, data);
    const int q = static_cast<int>(nl_.size());
    Eigen::VectorXd lambda0(q);
    for (int k = 0; k < q_model_; ++k)
      lambda0[k] = std::log(nl_[static_cast<std::size_t>(k)].value);
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

 private:
  // The fit at one set of nonlinear parameters.
  struct Eval {
    Eigen::VectorXd eta, theta;
    double rss = 0.0;
    double yy = 0.0;        // ||y||^2
    Eigen::MatrixXd R;      // (p + L + 1)^2 triangular factor of [W D y]
    Eigen::MatrixXd JtJ;    // q x q (Kaufman), in lambda = log(eta)
    Eigen::VectorXd Jtr;    // q
    Eigen::MatrixXd Theta;  // L x q: V = D Theta = d(W theta)/d lambda
    exid::estimators::LsSolution ls;
    long m = 0;
  };

  // One Levenberg-Marquardt run and where it ended.
  struct Run {
    std::string origin;
    Eigen::VectorXd eta0, lambda;
    Eval cur;
    int evals = 0, iterations = 0;
    std::string stop;
    exid::Json trace = exid::Json::array();
    double gradient_norm = 0.0;  // ||d rss / d log(eta)||
    double gn_fraction = 0.0;    // the part of rss a Gauss-Newton step would remove
    bool exact = false;          // the fit is exact to rounding
    bool stationary = false;     // the first-order test holds
    bool singular = false;       // the joint problem [W V] is singular there
    // the column-scaled SVD of the joint problem (the covariance's)
    Eigen::MatrixXd M;
  };

  // The grid of the globalisation.
  struct Grid {
    Eigen::VectorXd best;  // lambda
    Eval best_eval;
    std::vector<std::vector<int>> groups;
    std::vector<double> multipliers;
    int evaluations = 0, singular = 0, sweeps = 0;
    int checks = 0;          // sweeps around the best end
    long sample_stride = 1;  // points compared on every sample_stride-th sample
  };

  // "vs1 = 0.05 rad/s, eps1 = ..." (the delay in s)
  std::string where(const Eigen::VectorXd& eta) const {
    std::string out;
    for (std::size_t k = 0; k < nl_.size(); ++k)
      out += fmt::format("{}{} = {:.6g} {}", k ? ", " : "", nl_[k].name,
                         eta[static_cast<Eigen::Index>(k)], nl_[k].unit);
    return out;
  }

  // The model's nonlinear parameters in groups that move common columns (union-find; for
  // `differential`: one joint's eps and vs); the delay is in none (it is not a scale).
  std::vector<std::vector<int>> groups() const {
    std::vector<int> parent(static_cast<std::size_t>(q_model_));
    for (int k = 0; k < q_model_; ++k) parent[static_cast<std::size_t>(k)] = k;
    auto find = [&](int k) {
      while (parent[static_cast<std::size_t>(k)] != k) k = parent[static_cast<std::size_t>(k)];
      return k;
    };
    for (int a = 0; a < q_model_; ++a)
      for (int b = a + 1; b < q_model_; ++b) {
        const auto& ca = nl_[static_cast<std::size_t>(a)].columns;
        const auto& cb = nl_[static_cast<std::size_t>(b)].columns;
        const bool shared = std::any_of(ca.begin(), ca.end(), [&](int c) {
          return std::find(cb.begin(), cb.end(), c) != cb.end();
        });
        if (shared) parent[static_cast<std::size_t>(find(b))] = find(a);
      }
    std::vector<std::vector<int>> out;
    std::vector<int> slot(static_cast<std::size_t>(q_model_), -1);
    for (int k = 0; k < q_model_; ++k) {
      const int r = find(k);
      if (slot[static_cast<std::size_t>(r)] < 0) {
        slot[static_cast<std::size_t>(r)] = static_cast<int>(out.size());
        out.emplace_back();
      }
      out[static_cast<std::size_t>(slot[static_cast<std::size_t>(r)])].push_back(k);
    }
    return out;
  }

  // Block-coordinate search over the grid: for each group in turn, every combination of the
  // multipliers on its parameters (one common multiplier when the combinations would exceed
  // 125), the other groups at the best point so far; the linear part solved exactly at each.
  Grid searchGrid(const exid::ObservationModel& model, const exid::Dataset& data,
                  const Eigen::VectorXd& lambda0, const Eval& at_study,
                  const exid::RunContext& ctx) {
    Grid g;
    g.best = lambda0;
    g.best_eval = at_study;
    g.groups = groups();
    for (int i = 0; i < starts_; ++i)
      g.multipliers.push_back(i == 0 ? 1.0 : std::pow(2.0, (i % 2 ? -1.0 : 1.0) * ((i + 1) / 2)));
    const int S = static_cast<int>(g.multipliers.size());
    if (S < 2) return g;
    // sweeps over the groups until one improves nothing (at most 3): a group scanned while the
    // others were far off can prefer a wrong point, which the next sweep corrects
    for (g.sweeps = 1; g.sweeps <= 3; ++g.sweeps) {
      const double before = g.best_eval.rss;
      sweep(model, data, lambda0, &g, ctx);
      if (!(g.best_eval.rss < before)) break;
    }
    g.sweeps = std::min(g.sweeps, 3);
    return g;
  }

  void sweep(const exid::ObservationModel& model, const exid::Dataset& data,
             const Eigen::VectorXd& lambda0, Grid* gp, const exid::RunContext& ctx) {
    Grid& g = *gp;
    const int S = static_cast<int>(g.multipliers.size());
    for (const auto& grp : g.groups) {
      const int n = static_cast<int>(grp.size());
      const bool common = std::pow(S, n) > 125;
      const long combos = common ? S : static_cast<long>(std::lround(std::pow(S, n)));
      const Eigen::VectorXd base = g.best;
      for (long c = 0; c < combos; ++c) {
        if (ctx.shouldStop()) throw exid::Error("varpro: stopped");
        Eigen::VectorXd lambda = base;
        long rest = c;
        for (int i = 0; i < n; ++i) {
          const int digit = common ? static_cast<int>(c) : static_cast<int>(rest % S);
          rest /= S;
          lambda[grp[static_cast<std::size_t>(i)]] =
              lambda0[grp[static_cast<std::size_t>(i)]] +
              std::log(g.multipliers[static_cast<std::size_t>(digit)]);
        }
        if (lambda == base) continue;  // (the point itself: known)
        ++g.evaluations;
        try {
          Eval e = evaluate(model, data, lambda, ctx);
          if (std::isfinite(e.rss) && e.rss < g.best_eval.rss) {
            g.best = lambda;
            g.best_eval = std::move(e);
          }
        } catch (const exid::Error&) {
          ++g.singular;
        }
      }
    }
  }

  // Each model parameter alone at kAxisMultipliers of the centre's value, the others at the best
  // point so far.
  void axisScan(const exid::ObservationModel& model, const exid::Dataset& data,
                const Eigen::VectorXd& centre, Grid* gp, const exid::RunContext& ctx) {
    Grid& g = *gp;
    for (int k = 0; k < q_model_; ++k)
      for (double mult : kAxisMultipliers) {
        if (ctx.shouldStop()) throw exid::Error("varpro: stopped");
        Eigen::VectorXd lambda = g.best;
        lambda[k] = centre[k] + std::log(mult);
        if (lambda == g.best) continue;
        ++g.evaluations;
        try {
          Eval e = evaluate(model, data, lambda, ctx);
          if (std::isfinite(e.rss) && e.rss < g.best_eval.rss) {
            g.best = lambda;
            g.best_eval = std::move(e);
          }
        } catch (const exid::Error&) {
          ++g.singular;
        }
      }
  }

  // Every stride-th sample of d (read in chunks: a stream is never held whole).
  static exid::Dataset strided(const exid::Dataset& d, long stride) {
    const int K = d.size();
    const int n = static_cast<int>((K + stride - 1) / stride);
    exid::Dataset out;
    out.source = d.source;
    out.meta = d.meta;
    exid::SampleWindow window(d);
    int row = 0;
    constexpr int kChunk = 8192;
    for (int b = 0; b < K; b += kChunk) {
      const exid::Dataset c = window.span(b, std::min(K, b + kChunk));
      auto take = [&](const Eigen::MatrixXd& src, Eigen::MatrixXd& dst) {
        if (src.cols() == 0) return;
        if (dst.rows() != n) dst.resize(n, src.cols());
        int r = row;
        for (int k = static_cast<int>((b + stride - 1) / stride * stride); k < b + c.size();
             k += static_cast<int>(stride))
          dst.row(r++) = src.row(k - b);
      };
      if (out.t.size() != n) out.t.resize(n);
      int r = row;
      for (int k = static_cast<int>((b + stride - 1) / stride * stride); k < b + c.size();
           k += static_cast<int>(stride))
        out.t(r++) = c.t(k - b);
      take(c.q, out.q);
      take(c.qd, out.qd);
      take(c.qdd, out.qdd);
      take(c.tau, out.tau);
      take(c.wrench, out.wrench);
      row = r;
    }
    return out;
  }

  // Levenberg-Marquardt on lambda = log(eta) from `lambda` (its fit `cur`).
  Run levenbergMarquardt(const exid::ObservationModel& model, const exid::Dataset& data,
                         Eigen::VectorXd lambda, Eval cur, const std::string& origin,
                         const exid::RunContext& ctx) {
    const int q = static_cast<int>(nl_.size());
    Run run;
    run.origin = origin;
    run.eta0 = cur.eta;
    int evals = 1, iterations = 0;
    double mu = 1e-3;
    std::string stop;
    auto record = [&](const Eval& e) {
      exid::Json t = exid::Json::object();
      t["rss"] = e.rss;
      // (eta: the nonlinear parameters in their units, the delay in s)
      t["eta"] = exid::Json(std::vector<double>(e.eta.data(), e.eta.data() + e.eta.size()));
      run.trace.push_back(t);
    };
    record(cur);
    bool cur_regular = regular(jointMatrix(model, cur));
    while (evals < max_evals_) {
      if (ctx.shouldStop()) throw exid::Error("varpro: stopped");
      const Eigen::MatrixXd H = cur.JtJ;
      if (cur.Jtr.norm() == 0.0) {
        stop = "zero gradient";
        break;
      }
      bool accepted = false;
      double decrease = 0.0;
      Eigen::VectorXd delta;
      while (evals < max_evals_) {
        Eigen::MatrixXd A = H;
        A.diagonal() += mu * H.diagonal().cwiseMax(1e-300);
        delta = A.ldlt().solve(-cur.Jtr);
        if (!delta.allFinite() && mu < 1e30) {
          mu *= 10;
          continue;
        }
        if (!delta.allFinite()) break;
        // A trial where the fit is singular (a width so large that s is constant, say) or not
        // finite is a rejected step, as one that raises the residual.
        Eval trial;
        bool ok = true;
        if (delay_ && std::abs(ts_ * (lambda[q - 1] + delta[q - 1])) > delay_max_) {
          ok = false;  // outside the delays the kept rows allow
          ++rejected_bound_;
        } else {
          try {
            trial = evaluate(model, data, lambda + delta, ctx);
            // a step from a regular point into one where the joint problem is singular (a
            // Stribeck velocity drifting so high that its term is a Coulomb term, or so low that
            // it vanishes) is rejected: there the nonlinear parameter is not determined, and
            // the run would wander where no start can bring it back
            if (cur_regular && !regular(jointMatrix(model, trial))) {
              ok = false;
              ++rejected_singular_;
            }
          } catch (const exid::Error&) {
            ok = false;
            ++rejected_singular_;
          }
        }
        ++evals;
        if (ok && std::isfinite(trial.rss) && trial.rss <= cur.rss) {
          lambda += delta;
          cur_regular = regular(jointMatrix(model, trial));
          decrease = (cur.rss - trial.rss) / std::max(cur.rss, 1e-300);
          cur = std::move(trial);
          record(cur);
          mu = std::max(mu / 3.0, 1e-12);
          accepted = true;
          break;
        }
        mu *= 4.0;
        if (delta.cwiseAbs().maxCoeff() < xtol_) break;
      }
      ++iterations;
      if (!accepted && evals >= max_evals_) break;  // (not converged)
      if (!accepted) {
        stop = "no step decreases the residual";
        break;
      }
      if (delta.cwiseAbs().maxCoeff() < xtol_) {
        stop = fmt::format("step in log(eta) below step_tolerance = {:g}", xtol_);
        break;
      }
      if (decrease < ftol_) {
        stop = fmt::format("the residual fell by {:.2g} of itself, below rss_tolerance = {:g}",
                           decrease, ftol_);
        break;
      }
    }
    if (stop.empty()) stop = fmt::format("max_evaluations = {} reached", max_evals_);
    run.lambda = lambda;
    run.cur = std::move(cur);
    run.evals = evals;
    run.iterations = iterations;
    run.stop = stop;
    return run;
  }

  // The first-order test at a run's end, and whether the joint problem is regular there.
  void firstOrder(const exid::ObservationModel& model, Run* r) const {
    const Eval& e = r->cur;
    r->gradient_norm = 2.0 * e.Jtr.norm();  // ||d rss / d lambda|| = 2 ||J^T r||
    // g^T (J^T J)^+ g: the decrease of rss the Gauss-Newton step predicts
    Eigen::JacobiSVD<Eigen::MatrixXd> s(e.JtJ, Eigen::ComputeThinU | Eigen::ComputeThinV);
    s.setThreshold(1e-14);
    const double pred = e.Jtr.dot(s.solve(e.Jtr));
    r->gn_fraction = e.rss > 0 ? pred / e.rss : 0.0;
    // exact to rounding: the residual below 1e-12 of the measurement, relatively
    r->exact = e.rss <= 1e-24 * e.yy;
    r->stationary = r->exact || (std::isfinite(r->gn_fraction) && r->gn_fraction <= gtol_);
    r->M = jointMatrix(model, e);
    r->singular = !regular(r->M);
  }

  // The whole problem's Gauss-Newton matrix [W V]^T [W V] = M^T M,
  // M = [R11, R12 Theta; 0, R22 Theta] (the rows of [W D] in the QR basis).
  Eigen::MatrixXd jointMatrix(const exid::ObservationModel& model, const Eval& cur) const {
    const int p = model.numBase(), L = static_cast<int>(keep_.size()),
              q = static_cast<int>(nl_.size());
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(p + L, p + q);
    M.topLeftCorner(p, p) = cur.R.topLeftCorner(p, p);
    M.topRightCorner(p, q) = cur.R.block(0, p, p, L) * cur.Theta;
    M.bottomRightCorner(L, q) = cur.R.block(p, p, L, L) * cur.Theta;
    return M;
  }

  static Eigen::VectorXd columnScale(const Eigen::MatrixXd& M) {
    Eigen::VectorXd sc = M.colwise().norm().transpose();
    for (Eigen::Index i = 0; i < sc.size(); ++i) sc[i] = sc[i] > 0 ? 1.0 / sc[i] : 0.0;
    return sc;
  }

  bool regular(const Eigen::MatrixXd& M) const {
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(M * columnScale(M).asDiagonal());
    const Eigen::VectorXd sv = svd.singularValues();
    return sv.size() > 0 && sv[sv.size() - 1] > opt_.rank_tolerance * sv[0];
  }

  void setUp(const exid::ObservationModel& model, const exid::Dataset& data) {
    nl_ = model.nonlinearParameters();
    q_model_ = static_cast<int>(nl_.size());
    exid::check(!nl_.empty() || delay_,
                fmt::format("varpro: model '{}' has no nonlinear parameter (e.g. differential "
                            "with stribeck or coulomb_smoothing_rad_s) and measurement_delay is "
                            "false; batch_ls gives its fit",
                            model.pluginName()));
    // the moved columns that are base columns (the others do not enter the rows)
    const std::vector<int> in_base = model.nonlinearColumnsInBase();
    keep_.clear();
    owner_.clear();
    base_col_.clear();
    std::size_t l = 0;
    for (std::size_t k = 0; k < nl_.size(); ++k) {
      bool any = false;
      for (std::size_t i = 0; i < nl_[k].columns.size(); ++i, ++l)
        if (in_base[l] >= 0) {
          keep_.push_back(static_cast<int>(l));
          owner_.push_back(static_cast<int>(k));
          base_col_.push_back(in_base[l]);
          any = true;
        }
      exid::check(any, fmt::format("varpro: nonlinear parameter '{}' moves no base column of "
                                   "model '{}' (its columns are not identifiable from this "
                                   "motion): it cannot be fitted",
                                   nl_[k].name, model.pluginName()));
    }
    margin_ = 0;
    ts_ = 1.0;
    if (!delay_) return;
    // The delay: one more parameter; its columns in D are dW/dd (every base column).
    exid::check(model.specs().per_sample,
                fmt::format("varpro: measurement_delay needs a model whose rows are per sample "
                            "(model '{}' builds rows from several samples)",
                            model.pluginName()));
    double jitter = 0.0;
    const double fs = exid::samplingRate(data, &jitter);
    exid::check(std::isfinite(fs) && fs > 0 && jitter < 0.5,
                fmt::format("varpro: measurement_delay needs time stamps of a steady rate "
                            "(found {:g} Hz with steps {:.0f} % off the median)",
                            fs, 100 * jitter));
    ts_ = 1.0 / fs;
    // samples within measurement_delay_max_s of an end (the shortest step: median (1 -
    // jitter)), plus the three the interpolation's stencil needs
    // (a hair below: a bound of exactly n samples is n, not n + 1 by a rounding)
    // (counted in double first: a bound of 1e300 s is no int; refused before it is converted)
    const double margin = std::ceil(delay_max_ * fs / (1.0 - jitter) * (1 - 1e-12)) + 3;
    exid::check(
        margin <= 0.5 * (data.size() - 8),
        fmt::format("varpro: measurement_delay_max_s = {:g} s leaves {} of {} samples at "
                    "{:g} Hz ({:g} without rows at each end; at least 8 are needed)",
                    delay_max_,
                    static_cast<long>(std::max(0.0, data.size() - 2 * std::min(margin, 1e15))),
                    data.size(), fs, margin));
    margin_ = static_cast<int>(margin);
    exid::NonlinearParameter d;
    d.name = "measurement_delay_s";
    d.unit = "s";
    d.value = delay0_;
    nl_.push_back(d);
    for (int c = 0; c < model.numBase(); ++c) {
      keep_.push_back(-1);
      owner_.push_back(static_cast<int>(nl_.size()) - 1);
      base_col_.push_back(c);
    }
  }

  // eta from lambda: exp for the model's parameters, d = ts lambda for the delay.
  Eigen::VectorXd etaOf(const Eigen::VectorXd& lambda) const {
    Eigen::VectorXd eta = lambda;
    for (int k = 0; k < q_model_; ++k) eta[k] = std::exp(lambda[k]);
    if (delay_) eta[eta.size() - 1] = ts_ * lambda[lambda.size() - 1];
    return eta;
  }

  // The rows of samples [b, end) at eta (model parameters and the delay): W, y and the
  // derivative columns [dW_kept, dW/dd] into *D.
  exid::Rows chunkRows(const exid::ObservationModel& model, exid::SampleWindow& window, int b,
                       int end, const Eigen::VectorXd& eta, Eigen::MatrixXd* D,
                       const exid::RunContext& ctx) const {
    const int L = static_cast<int>(keep_.size()), Lm = L - (delay_ ? model.numBase() : 0);
    const Eigen::VectorXd eta_m = eta.head(q_model_);
    Eigen::MatrixXd dW;
    if (!delay_) {
      exid::Rows r = model.rowsAt(window.span(b, end), eta_m, &dW, ctx);
      D->resize(r.W.rows(), L);
      for (int l = 0; l < L; ++l) D->col(l) = dW.col(keep_[static_cast<std::size_t>(l)]);
      return r;
    }
    // the rows of the chunk and its margins, W (and dW) read at t_k - d
    const double d = eta[eta.size() - 1];
    const exid::Dataset span = window.span(b - margin_, end + margin_);
    const int S = span.size(), first = margin_, last = margin_ + end - b;
    const exid::Rows rs = model.rowsAt(span, eta_m, q_model_ > 0 ? &dW : nullptr, ctx);
    const auto R = static_cast<int>(rs.y.size());
    exid::check(R % S == 0 && rs.W.rows() == R,
                fmt::format("varpro: measurement_delay: model '{}' gave {} rows for {} samples "
                            "(not the same number per sample)",
                            model.pluginName(), R, S));
    const int P = R / S;
    exid::Rows r;
    Eigen::MatrixXd dWd;
    exid::shiftedRows(span.t, rs.W, P, -d, first, last, &r.W, &dWd);  // dWd: d/d(-d)
    r.y = rs.y.segment(static_cast<Eigen::Index>(first) * P,
                       static_cast<Eigen::Index>(last - first) * P);
    if (rs.equation.size() == static_cast<std::size_t>(R))
      r.equation.assign(rs.equation.begin() + first * P, rs.equation.begin() + last * P);
    r.numEquations = rs.numEquations;
    D->resize(r.W.rows(), L);
    if (Lm > 0) {
      Eigen::MatrixXd kept(R, Lm), kept_d;
      for (int l = 0; l < Lm; ++l) kept.col(l) = dW.col(keep_[static_cast<std::size_t>(l)]);
      exid::shiftedRows(span.t, kept, P, -d, first, last, &kept_d, nullptr);
      D->leftCols(Lm) = kept_d;
    }
    D->rightCols(L - Lm) = -dWd;
    return r;
  }

  Eval evaluate(const exid::ObservationModel& model, const exid::Dataset& data,
                const Eigen::VectorXd& lambda, const exid::RunContext& ctx) const {
    const int p = model.numBase(), L = static_cast<int>(keep_.size()),
              q = static_cast<int>(nl_.size());
    Eval e;
    e.eta = etaOf(lambda);
    RowAccumulator acc(p + L, method_);
    const int first = margin_, last = data.size() - margin_;
    exid::SampleWindow window(data);
    Eigen::MatrixXd D, A;
    for (int b = first; b < last; b += chunk_) {
      const int end = std::min(last, b + chunk_);
      const exid::Rows r = chunkRows(model, window, b, end, e.eta, &D, ctx);
      exid::estimators::checkRows(r, p, kName, b);
      A.resize(r.W.rows(), p + L);
      A.leftCols(p) = r.W;
      A.rightCols(L) = D;
      if (!A.allFinite() || !r.y.allFinite())
        throw exid::Error(
            fmt::format("varpro: a row from samples {}..{} is not finite at eta = "
                        "[{}]",
                        b, end, fmt::join(e.eta.data(), e.eta.data() + q, ", ")));
      acc.add(A, r.y);
    }
    e.m = acc.rows();
    // R of [W D y] (any factor F with F^T F = [W D y]^T [W D y] gives the same R)
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(acc.factor());
    e.R = qr.matrixQR().triangularView<Eigen::Upper>();
    // theta: the rank-revealing solve of [W y] (its Gram matrix from R's columns)
    RowAccumulator aw(p);
    Eigen::MatrixXd Rw(e.R.rows(), p);
    Rw = e.R.leftCols(p);
    aw.add(Rw, e.R.col(p + L));
    aw.setRowCount(e.m);
    e.ls = exid::estimators::solveLeastSquares(aw, model.base().names, opt_, kName);
    e.theta = e.ls.theta;
    e.rss = e.R.col(p + L).tail(L + 1).squaredNorm();
    e.yy = e.R.col(p + L).head(p + L + 1).squaredNorm();
    // V = D Theta in lambda: dW/dlambda_k = eta_k dW/deta_k; the delay: d = ts lambda
    e.Theta = Eigen::MatrixXd::Zero(L, q);
    for (int l = 0; l < L; ++l) {
      const int k = owner_[static_cast<std::size_t>(l)];
      e.Theta(l, k) =
          e.theta[base_col_[static_cast<std::size_t>(l)]] * (k < q_model_ ? e.eta[k] : ts_);
    }
    const Eigen::MatrixXd R22T = e.R.block(p, p, L, L).triangularView<Eigen::Upper>() * e.Theta;
    e.JtJ = R22T.transpose() * R22T;
    e.Jtr = -R22T.transpose() * e.R.col(p + L).segment(p, L);
    return e;
  }

  exid::Estimate finish(const exid::ObservationModel& model, const std::vector<Run>& runs, int won,
                        const Grid& grid, std::chrono::steady_clock::time_point t0) const {
    const Run& run = runs[static_cast<std::size_t>(won)];
    const Eval& cur = run.cur;
    const Eigen::VectorXd& lambda = run.lambda;
    const int p = model.numBase(), q = static_cast<int>(nl_.size());
    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, cur.ls, cur.rss, cur.m);
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
    d["memory"] =
        "one chunk of rows and the (p + L + 1)^2 factor per pass, one pass per evaluation";
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
    return e;
  }

  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& p : nl_) out.push_back(p.name);
    return out;
  }

  int max_evals_;
  double xtol_, ftol_;
  int starts_;
  static constexpr int kGridSamples = 4000;
  static constexpr int kRounds = 6;  // checks around the best end, while one finds a lower point
  // x1/32 .. x32 in steps of sqrt(2), x1 left out (the centre)
  static constexpr double kAxisMultipliers[] = {0.03125,
                                                0.04419417382415922,
                                                0.0625,
                                                0.08838834764831845,
                                                0.125,
                                                0.1767766952966369,
                                                0.25,
                                                0.3535533905932738,
                                                0.5,
                                                0.7071067811865476,
                                                1.414213562373095,
                                                2.0,
                                                2.82842712474619,
                                                4.0,
                                                5.656854249492381,
                                                8.0,
                                                11.31370849898476,
                                                16.0,
                                                22.62741699796952,
                                                32.0};
  double gtol_;
  int chunk_;
  RowAccumulator::Method method_;
  exid::estimators::SolveOptions opt_;
  std::vector<exid::NonlinearParameter> nl_;
  std::vector<int> keep_, owner_, base_col_;  // per derivative column (the delay's: keep -1)
  int rejected_singular_ = 0;                 // trial steps where the fit was singular
  int rejected_bound_ = 0;                    // trial delays beyond measurement_delay_max_s
  int q_model_ = 0;                           // the model's nonlinear parameters (first in nl_)
  bool delay_ = false;
  double delay0_ = 0.0, delay_max_ = 0.0;
  double ts_ = 1.0;  // [s] the median sample period (the delay's lambda unit)
  int margin_ = 0;   // samples at each end without rows (measurement_delay)
};

}  // namespace

EXID_REGISTER_PLUGIN(VarPro)
