// exid — estimator `didim`: output-error refinement (DIDIM, Gautier, Janot and Vandanjon):
// starting from the inverse-model (least-squares) estimate, the base parameters are fitted so
// that the closed-loop simulation of the robot (the recording's reference through the robot's
// PD gains and feed-forward: exid::estimators::ClosedLoop) reproduces the measured torques
// (output: torque, the controller's output along the simulated motion) or positions (output:
// position). Levenberg-Marquardt on theta; the Jacobian from CVODES forward sensitivities of
// the closed loop, with the sensitivity equations' right-hand side exact:
//   x = (q, qd),  f = (qd, a),  a = M^-1 (tau_c(t, q, qd) - h(q, qd)),
//   df/dtheta = (0, -M^-1 w(q, qd, a))                  (w theta = M a + h),
//   da/dq = M^-1 (-Kp - d(w theta)/dq |a),  da/dqd = M^-1 (-Kd - d(w theta)/dqd |a),
// the derivatives of w theta from the model's exact design VJP (one per joint). Outputs:
// d tau_c / dtheta = -Kp S_q - Kd S_qd, or d q / dtheta = S_q. Covariance sigma^2 (J^T J)^-1,
// sigma^2 = rss / (m - p) (docs/estimators.md, "didim").
#include <fmt/format.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <chrono>
#include <cmath>
#include <random>

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
    for (auto& d : std::vector<exid::ParamDecl>{
             exid::param_string("output", std::string("torque"),
                                "torque: fit the controller's torque along the simulated motion "
                                "to the recorded one (DIDIM); position: fit the simulated "
                                "positions to the recorded ones",
                                {"torque", "position"}),
             exid::param_int("max_iterations", 30, "Levenberg-Marquardt steps at most", 1, 10000),
             exid::param_double("rss_tolerance", 1e-10, "",
                                "stop when an accepted step lowers the residual sum of squares "
                                "by less than this fraction of it",
                                0.0, 1.0),
             exid::param_double("step_tolerance", 1e-7, "",
                                "stop when an accepted step moves theta by less than this "
                                "relative to its norm (the simulation's precision is near)",
                                0.0, 1.0, true),
             exid::param_bool("fit_nonlinear", true,
                              "fit the model's nonlinear parameters (friction widths, Stribeck "
                              "velocities: ObservationModel::nonlinearParameters) with theta, "
                              "from the model's values, on log scale; false: keep them"),
             exid::param_int("gradient_check", 0,
                             "> 0: compare the Jacobian along this many random directions with "
                             "central differences of the simulation at the start "
                             "(details.gradient_check)",
                             0, 1000),
         })
      p.push_back(d);
    return p;
  }

  explicit Didim(const exid::ParamSet& p)
      : P_(p),
        position_(p.getString("output") == "position"),
        max_iter_(static_cast<int>(p.getInt("max_iterations"))),
        ftol_(p.getDouble("rss_tolerance")),
        xtol_(p.getDouble("step_tolerance")),
        tol_loop_(exid::estimators::ClosedLoop::Tolerances::from(p)),
        check_(static_cast<int>(p.getInt("gradient_check"))),
        fit_nl_(p.getBool("fit_nonlinear")) {
    exid::estimators::ClosedLoop::checkParams(p, kName);
  }

  exid::EstimatorSpecs specs() const override { return {}; }  // the Jacobian held in memory

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data_in,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    exid::check(prior == nullptr, "didim: a prior is not supported");
    const exid::Dataset data = exid::materialize(data_in);
    loop_ = std::make_unique<exid::estimators::ClosedLoop>(model, P_, data, ctx, kName);
    const int p = model.numBase(), n = loop_->dof(), K = data.size();
    // the measured output, sample-major
    y_.resize(static_cast<Eigen::Index>(K) * n);
    const MatrixXd& Y = position_ ? data.q : data.tau;
    exid::check(
        Y.rows() == K && Y.cols() == n,
        fmt::format("didim: the data has no {} of {} joints", position_ ? "q" : "torque", n));
    for (int k = 0; k < K; ++k) y_.segment(static_cast<Eigen::Index>(k) * n, n) = Y.row(k);
    const long m = y_.size();
    exid::check(m > p, fmt::format("didim: {} rows for {} parameters", m, p));
    // start: the inverse model's least squares
    const exid::Rows R = model.rows(data, ctx);
    exid::estimators::checkRows(R, p, kName, 0);
    // x = (theta, log eta): the model's nonlinear parameters fitted with theta (fit_nonlinear)
    L_ = fit_nl_ ? static_cast<int>(loop_->nonlinear().size()) : 0;
    VectorXd theta(p + L_);
    theta.head(p) = startFit(model, R);
    for (int k = 0; k < L_; ++k) {
      const double v = loop_->nonlinear()[k];
      exid::check(v > 0,
                  fmt::format("didim: nonlinear parameter {} = {} is not positive (fitted "
                              "on log scale)",
                              model.nonlinearParameters()[static_cast<std::size_t>(k)].name, v));
      theta[p + k] = std::log(v);
    }
    p_ = p;
    const VectorXd theta0 = theta;
    Sim cur = simulate(theta, data, true);
    exid::Json check_json;
    if (check_ > 0) check_json = gradientCheck(theta, data, cur);
    exid::Json trace = exid::Json::array();
    auto record = [&](const Sim& s) {
      exid::Json t = exid::Json::object();
      t["rss"] = s.rss;
      trace.push_back(t);
    };
    record(cur);
    double mu = 1e-3;
    int it = 0, sims = 1;
    std::string stop;
    for (it = 1; it <= max_iter_; ++it) {
      if (ctx.shouldStop()) throw exid::Error("didim: stopped");
      // J = d y_sim / d theta; r = y - y_sim: the step solves (J^T J + mu D) d = J^T r
      const MatrixXd H = cur.J.transpose() * cur.J;
      const VectorXd g = cur.J.transpose() * (y_ - cur.y);
      bool accepted = false, flat = false;
      double decrease = 0.0, moved = 0.0;
      for (int tries = 0; tries < 12 && !accepted; ++tries) {
        MatrixXd A = H;
        A.diagonal() += mu * H.diagonal().cwiseMax(1e-300);
        const VectorXd step = A.ldlt().solve(g);
        if (!step.allFinite()) {
          mu *= 10;
          continue;
        }
        // the decrease the linearisation predicts: below rss_tolerance, theta is at the
        // minimum to the simulation's precision (trials would only see its noise)
        const double predicted = 2 * g.dot(step) - step.dot(H * step);
        if (tries == 0 && predicted < ftol_ * cur.rss) {
          flat = true;
          break;
        }
        // trials without the sensitivities; the accepted point gets them
        Sim trial;
        bool ok = true;
        try {
          trial = simulate(theta + step, data, false);
        } catch (const exid::Error&) {
          ok = false;  // (a trial that cannot be simulated is a rejected step)
        }
        ++sims;
        if (ok && trial.rss <= cur.rss) {
          decrease = (cur.rss - trial.rss) / std::max(cur.rss, 1e-300);
          // theta relative to its norm; log eta as it is (a relative change of eta)
          moved = step.head(p).norm() / std::max(theta.head(p).norm(), 1e-300);
          if (L_ > 0) moved = std::max(moved, step.tail(L_).cwiseAbs().maxCoeff());
          theta += step;
          cur = simulate(theta, data, true);
          ++sims;
          record(cur);
          mu = std::max(mu / 3, 1e-12);
          accepted = true;
        } else {
          mu *= 4;
        }
      }
      if (flat) {
        stop = fmt::format("the predicted decrease is below rss_tolerance = {:g} of the residual",
                           ftol_);
        break;
      }
      if (!accepted) {
        stop = "no step lowers the residual (a minimum to the simulation's precision)";
        break;
      }
      if (moved < xtol_) {
        stop = fmt::format("the step moved theta by {:.2g} of itself, below step_tolerance = {:g}",
                           moved, xtol_);
        break;
      }
      if (decrease < ftol_) {
        stop = fmt::format("the residual fell by {:.2g} of itself, below rss_tolerance = {:g}",
                           decrease, ftol_);
        break;
      }
    }
    const bool converged = !stop.empty();
    if (!converged) stop = fmt::format("max_iterations = {} reached (not converged)", max_iter_);
    exid::Estimate e = finish(model, cur, theta, m);
    exid::Json& d = e.details;
    d["iterations"] = std::min(it, max_iter_);
    d["simulations"] = sims;
    d["stop"] = stop;
    d["converged"] = converged;
    d["trace"] = trace;
    d["start"] = "least squares on the recording's rows (the inverse model)";
    d["start_change"] =
        (theta.head(p) - theta0.head(p)).norm() / std::max(theta.head(p).norm(), 1e-300);
    if (!check_json.isNull()) d["gradient_check"] = check_json;
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!converged) {
      exid::Json w = exid::Json::array();
      w.push_back(exid::Json(fmt::format("didim: {}", stop)));
      d["warnings"] = w;
    }
    return e;
  }

 private:
  // The inverse model's least squares: batch_ls's rank-revealing solve (an unidentifiable
  // direction is refused by name).
  static VectorXd startFit(const exid::ObservationModel& model, const exid::Rows& R) {
    exid::estimators::RowAccumulator acc(model.numBase());
    acc.add(R.W, R.y);
    return exid::estimators::solveLeastSquares(acc, model.base().names,
                                               exid::estimators::SolveOptions(), kName)
        .theta;
  }
  struct Sim {
    VectorXd y;  // simulated output, sample-major
    MatrixXd J;  // d y / d theta (with sensitivities)
    double rss = 0.0;
  };

  // The loop at x = (theta, log eta); J = d y / d x (the eta columns times eta: d/d log eta).
  Sim simulate(const VectorXd& xv, const exid::Dataset& data, bool sens) const {
    const int n = loop_->dof(), K = data.size(), p = static_cast<int>(xv.size());
    const VectorXd theta = xv.head(p_);
    if (L_ > 0) loop_->setNonlinear(xv.tail(L_).array().exp().matrix(), sens);
    Sim out;
    out.y.resize(static_cast<Eigen::Index>(K) * n);
    if (sens) out.J.resize(static_cast<Eigen::Index>(K) * n, p);
    loop_->simulate(
        theta, data.t, tol_loop_, sens, [&](int k, const VectorXd& x, const MatrixXd* S) {
          const Eigen::Index r0 = static_cast<Eigen::Index>(k) * n;
          out.y.segment(r0, n) =
              position_ ? VectorXd(x.head(n)) : loop_->control(data.t[k], x.head(n), x.tail(n));
          if (S)  // d tau_c / d theta = -Kp S_q - Kd S_qd, or d q / d theta = S_q
            out.J.middleRows(r0, n) = position_
                                          ? MatrixXd(S->topRows(n))
                                          : MatrixXd(-(loop_->kp().asDiagonal() * S->topRows(n)) -
                                                     loop_->kd().asDiagonal() * S->bottomRows(n));
        });
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
    const int p = model.numBase(), q = p + L_;
    exid::estimators::LsSolution L;
    L.p = p;
    L.m = m;
    L.theta = x.head(p);
    L.rss = s.rss;
    L.sigma2 = s.rss / static_cast<double>(m - q);
    VectorXd sc = s.J.colwise().norm().transpose();
    for (Eigen::Index i = 0; i < sc.size(); ++i) sc[i] = sc[i] > 0 ? 1.0 / sc[i] : 0.0;
    Eigen::JacobiSVD<MatrixXd> svd(s.J * sc.asDiagonal(), Eigen::ComputeThinV);
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
    if (L_ > 0) {  // eta = exp(lambda): std eta * std(lambda)
      const std::vector<exid::NonlinearParameter> nl = model.nonlinearParameters();
      e.nonlinear.resize(L_);
      e.nonlinear_std.resize(L_);
      for (int k = 0; k < L_; ++k) {
        e.nonlinear_names.push_back(nl[static_cast<std::size_t>(k)].name);
        e.nonlinear[k] = std::exp(x[p + k]);
        e.nonlinear_std[k] = e.nonlinear[k] * std::sqrt(std::max(0.0, C(p + k, p + k)));
      }
    }
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["output"] = position_ ? "position" : "torque";
    d["method"] =
        "output error: Levenberg-Marquardt on theta, the closed-loop simulation (CVODES BDF) "
        "against the recorded output; Jacobian from forward sensitivities with an exact "
        "right-hand side";
    d["covariance_definition"] =
        "sigma^2 (J^T J)^-1, J = d y_sim / d (theta, log eta), sigma^2 = rss / (m - p - L); "
        "eta's std = eta std(log eta); cond_W is that of J";
    d["nonlinear_fitted"] = L_ > 0;
    d["controller"] = loop_->describe();
    d["memory"] = "the Jacobian (m x p doubles): not streamed";
    return e;
  }

  exid::ParamSet P_;
  bool position_;
  int max_iter_;
  double ftol_, xtol_;
  exid::estimators::ClosedLoop::Tolerances tol_loop_;
  int check_;
  bool fit_nl_;
  int L_ = 0, p_ = 0;  // nonlinear parameters fitted; base parameters
  std::unique_ptr<exid::estimators::ClosedLoop> loop_;
  VectorXd y_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Didim)
