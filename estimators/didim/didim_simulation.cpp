// exid — estimator `didim`: the samples fitted, the closed-loop simulation with its
// sensitivities, and the inverse model's least-squares starts (see didim.cpp).
#include <fmt/format.h>

#include <random>

#include "didim.hpp"
#include "exid/delay.hpp"
#include "exid/error.hpp"

namespace exid::didim {

// The samples fitted (keep_t_, windows_, dropped_) and the measured output y_.
void Didim::chooseSamples(const exid::ObservationModel& model, const exid::Dataset& data, int n,
                          int K, const exid::RunContext& ctx) {
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
  // the measured output, sample-major (n, or n + nb_: the base rows' measured side, the
  // contact wrenches at the recorded positions, as the model's rows give it)
  const int per = n + nb_;
  y_.resize(static_cast<Eigen::Index>(keep.size()) * per);
  const MatrixXd& Y = position_ ? data.q : data.tau;
  exid::check(Y.rows() == K && Y.cols() == n,
              fmt::format("didim: the data has no {} of {} joints", position_ ? "q" : "torque", n));
  VectorXd yb;
  if (nb_ > 0) {
    const exid::Rows R = model.rows(data, ctx);
    exid::check(R.y.size() == static_cast<Eigen::Index>(K) * per,
                fmt::format("didim: the model gives {} rows for {} samples (expected {} per "
                            "sample)",
                            R.y.size(), K, per));
    yb = R.y;
  }
  for (std::size_t i = 0; i < keep.size(); ++i) {
    const Eigen::Index r0 = static_cast<Eigen::Index>(i) * per;
    y_.segment(r0, n) = Y.row(keep[i]);
    if (nb_ > 0)
      y_.segment(r0 + n, nb_) = yb.segment(static_cast<Eigen::Index>(keep[i]) * per, nb_);
  }
}

// The first start x = (theta, log eta, d): the inverse model's least squares (drive gains at
// their prior mean; the rows compensated for the initial delay), the model's nonlinear
// parameters (fit_nonlinear), the initial delay (measurement_delay).
VectorXd Didim::firstStart(const exid::ObservationModel& model, const exid::Dataset& data,
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

// The inverse model's least squares: batch_ls's rank-revealing solve (an unidentifiable
// direction is refused by name), the columns `cols` held at `at`. The first start holds the
// gains at the prior's mean (their scale with theta is not in the rows); the later starts
// hold the gains and FcL at their shifted values.
VectorXd Didim::startFit(const exid::ObservationModel& model, const exid::Rows& R,
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

// The loop at x = (theta, log eta, d) at the kept samples' times less d; J = d y / d x (the
// eta columns times eta: d/d log eta; the delay's: -d tau_c / dt).
// With `along` (the same xv's simulation without them), the sensitivities along its paths.
Didim::Sim Didim::simulate(const VectorXd& xv, const exid::Dataset& data, bool sens,
                           const Sim* along) const {
  const int n = loop_->dof(), K = static_cast<int>(keep_t_.size()), p = static_cast<int>(xv.size());
  const VectorXd theta = xv.head(p_);
  if (L_ > 0) loop_->setNonlinear(xv.segment(p_, L_).array().exp().matrix(), sens);
  const double d = D_ ? xv[p_ + L_] : 0.0;
  VectorXd times(K);
  for (int k = 0; k < K; ++k) times[k] = keep_t_[static_cast<std::size_t>(k)] - d;
  Sim out;
  const int per = n + nb_;
  out.y.resize(static_cast<Eigen::Index>(K) * per);
  if (sens) out.J.resize(static_cast<Eigen::Index>(K) * per, p);
  auto at = [&](int k, const VectorXd& x, const MatrixXd* S) {
    const Eigen::Index r0 = static_cast<Eigen::Index>(k) * per;
    if (nb_ > 0) {  // a floating base's base rows at the simulated motion
      MatrixXd Jb;
      out.y.segment(r0 + n, nb_) = loop_->baseRows(theta, times[k], x, S, S ? &Jb : nullptr);
      if (S) out.J.block(r0 + n, 0, nb_, S->cols()) = Jb;
    }
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
exid::Json Didim::gradientCheck(const VectorXd& theta, const exid::Dataset& data,
                                const Sim& s) const {
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

}  // namespace exid::didim
