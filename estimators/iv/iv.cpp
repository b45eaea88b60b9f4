// exid — estimator `iv`: instrumental variables with the simulated model as the instrument
// (Janot, Vandanjon and Gautier's IDIM-IV, as in BIRDy; docs/estimators.md, "iv").
//
// The rows W of a recording are built from measured positions and their derivatives: noise in
// them (errors in variables) biases least squares. The instrument Z is the same model's rows
// built from a simulation instead: the closed loop of the robot with the current estimate,
// driven by the recording's reference (reference_file) through the robot's controller (PD
// gains and the feed-forward, given), integrated by CVODES. Z is noise-free and correlated with
// W, so
//   theta_{i+1} = (Z^T W)^-1 Z^T y
// is consistent. Start: ordinary least squares; iterate until theta settles. Covariance: the
// sandwich (Z^T W)^-1 (sum_k g_k g_k^T) (Z^T W)^-T, g_k = Z_k^T e_k over sample k's rows.
//
// Simulated dynamics from the model's own rows, in measured coordinates: with w(q, qd, qdd)
// the design rows (one per joint), tau = w(q, qd, qdd) theta is affine in qdd, so
// M e_i = w(q, qd, e_i) theta - w(q, qd, 0) theta and h = w(q, qd, 0) theta; qdd = M^-1 (tau_c
// - h), tau_c = tau_ff(qr, qdr, qddr) + Kp (qr - q) + Kd (qdr - qd).
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/closed_loop.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;
using exid::estimators::RowAccumulator;

class Iv : public exid::Estimator {
 public:
  static constexpr const char* kName = "iv";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "instrumental variables: the instrument is the model's rows from a closed-loop "
      "simulation with the current estimate (the recording's reference, the robot's PD gains "
      "and feed-forward; CVODES), iterated from least squares (IDIM-IV, BIRDy)";

  static std::vector<exid::ParamDecl> params() {
    std::vector<exid::ParamDecl> p = exid::estimators::ClosedLoop::params();
    for (auto& d : std::vector<exid::ParamDecl>{
             exid::param_int("max_iterations", 20, "IV iterations at most", 1, 1000),
             exid::param_double("tolerance", 1e-6, "",
                                "stop when theta changes by less than this relative to its norm",
                                0.0, 1.0, true),
         })
      p.push_back(d);
    return p;
  }

  explicit Iv(const exid::ParamSet& p)
      : P_(p),
        max_iter_(static_cast<int>(p.getInt("max_iterations"))),
        tol_(p.getDouble("tolerance")),
        tol_loop_(exid::estimators::ClosedLoop::Tolerances::from(p)) {
    exid::estimators::ClosedLoop::checkParams(p, kName);
  }

  exid::EstimatorSpecs specs() const override { return {}; }  // the rows held in memory

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data_in,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    exid::check(prior == nullptr, "iv: a prior is not supported");
    exid::requireOnePart(data_in, kName,
                         "iv simulates the closed loop along one continuous recording for its "
                         "instrument; identify from each recording in its own study, or use an "
                         "estimator that takes the rows sample by sample (batch_ls, wls, "
                         "consistent_ls, rls, filtered_ls, gains_ls)");
    const exid::Dataset data = exid::materialize(data_in);
    loop_ = std::make_unique<exid::estimators::ClosedLoop>(model, P_, data, ctx, kName);
    // (copies: the loop outlives this call and its context)
    loop_->setStop([stop = ctx.cancelled, deadline = ctx.deadline] {
      return deadline.expired() || (stop && stop());
    });
    exid::check(!loop_->hasDriveGains(),
                "iv: the model has drive gains (dK): their scale needs a known payload part or a "
                "prior, and the simulated closed loop has neither (use gains_ls, or didim with "
                "gain_prior_std)");
    const int p = model.numBase();
    const exid::Rows R = model.rows(data, ctx);
    exid::estimators::checkRows(R, p, kName, 0);
    const long m = R.y.size();
    exid::check(m > p, fmt::format("iv: {} rows for {} parameters", m, p));
    // the rows of one sample (a floating base's model may add the base's six to the joints')
    per_ = loop_->floatingBase() ? static_cast<int>(m / data.size()) : loop_->dof();
    // start: least squares
    VectorXd theta = startFit(model, R);
    exid::Json trace = exid::Json::array();
    MatrixXd ZtWinv, Zlast;
    int it = 0;
    double change = HUGE_VAL;
    std::string stop;
    for (it = 1; it <= max_iter_; ++it) {
      if (ctx.shouldStop()) throw exid::Error("iv: stopped");
      const exid::Dataset sim = simulate(theta, data);
      const exid::Rows Z = model.rows(sim, ctx);
      exid::check(Z.y.size() == m, "iv: the simulated rows differ in number from the recording's");
      Zlast = Z.W;
      const VectorXd next = solveIv(Z.W, R.W, R.y, &ZtWinv);
      change = (next - theta).norm() / std::max(next.norm(), 1e-300);
      theta = next;
      exid::Json t = exid::Json::object();
      t["change"] = change;
      t["tracking_rms_rad"] = std::sqrt((sim.q - data.q).squaredNorm() / sim.q.size());
      trace.push_back(t);
      if (change < tol_) {
        stop =
            fmt::format("theta changed by {:.2g} of itself, below tolerance = {:g}", change, tol_);
        break;
      }
    }
    // converged: theta a fixed point of the iteration (the instrument from theta gives theta
    // back to tolerance), the IV equations' first-order condition
    const bool converged = !stop.empty();
    if (!converged)
      stop = fmt::format(
          "max_iterations = {} reached, theta still changing by {:.2g} of itself "
          "(tolerance = {:g})",
          max_iter_, change, tol_);
    return finish(model, R, Zlast, theta, ZtWinv, std::min(it, max_iter_), stop, converged, trace,
                  t0);
  }

 private:
  // The inverse model's least squares: batch_ls's rank-revealing solve (an unidentifiable
  // direction is refused by name).
  static VectorXd startFit(const exid::ObservationModel& model, const exid::Rows& R) {
    RowAccumulator acc(model.numBase());
    acc.add(R.W, R.y);
    return exid::estimators::solveLeastSquares(acc, model.base().names,
                                               exid::estimators::SolveOptions(), kName)
        .theta;
  }
  // theta = (Z^T W)^-1 Z^T y without forming Z^T W (its condition number is about W's squared):
  // with column scalings E, D and Z E = Q Rz (thin QR), Z^T W = E^-1 Rz^T (Q^T W D) D^-1, so
  // theta = D (Q^T W D)^-1 Q^T y, a p x p system as well conditioned as W D. *inv: (Z^T W)^-1.
  static VectorXd solveIv(const MatrixXd& Z, const MatrixXd& W, const VectorXd& y, MatrixXd* inv) {
    const Eigen::Index p = W.cols();
    const VectorXd D = W.colwise().norm().transpose().cwiseMax(1e-300).cwiseInverse();
    const VectorXd E = Z.colwise().norm().transpose().cwiseMax(1e-300).cwiseInverse();
    Eigen::HouseholderQR<MatrixXd> qr(Z * E.asDiagonal());
    const MatrixXd Q = qr.householderQ() * MatrixXd::Identity(Z.rows(), p);
    const MatrixXd Rz = qr.matrixQR().topRows(p).triangularView<Eigen::Upper>();
    const MatrixXd A = Q.transpose() * (W * D.asDiagonal());
    Eigen::JacobiSVD<MatrixXd> svd(A);
    const VectorXd sv = svd.singularValues();
    Eigen::JacobiSVD<MatrixXd> svr(Rz);
    const VectorXd svz = svr.singularValues();
    exid::check(sv[p - 1] > 1e-13 * sv[0] && svz[p - 1] > 1e-13 * svz[0],
                fmt::format("iv: Z^T W is singular (the simulated motion does not excite every "
                            "base parameter: condition numbers {:.3g} of the scaled Q^T W, {:.3g} "
                            "of the scaled instrument)",
                            sv[0] / sv[p - 1], svz[0] / svz[p - 1]));
    const Eigen::PartialPivLU<MatrixXd> lu(A);
    // (Z^T W)^-1 = D A^-1 Rz^-T E
    const MatrixXd RzinvT =
        Rz.transpose().triangularView<Eigen::Lower>().solve(MatrixXd::Identity(p, p));
    *inv = D.asDiagonal() * lu.solve(RzinvT) * E.asDiagonal();
    return D.asDiagonal() * lu.solve(VectorXd(Q.transpose() * y));
  }

  // The loop at theta sampled at the recording's times: q, qd, qdd and the controller's torque
  // (the command the drives record: a column holding the recorded torque, e.g. coulomb_load's,
  // gets its noise-free simulated value).
  exid::Dataset simulate(const VectorXd& theta, const exid::Dataset& data) const {
    const int n = loop_->dof(), K = data.size();
    exid::Dataset out;
    out.t = data.t;
    out.q.resize(K, n);
    out.qd.resize(K, n);
    out.qdd.resize(K, n);
    out.tau = data.tau;
    out.source = "iv simulation";
    // a floating base: the simulated joints on the recorded base motion, with the recorded
    // contact wrenches (the rows' measured side)
    if (loop_->floatingBase()) {
      out.base = data.base;
      out.contact = data.contact;
    }
    loop_->simulate(
        theta, data.t, tol_loop_, false, [&](int k, const VectorXd& x, const MatrixXd*) {
          out.q.row(k) = x.head(n).transpose();
          out.qd.row(k) = x.tail(n).transpose();
          out.qdd.row(k) = loop_->acceleration(theta, data.t[k], x.head(n), x.tail(n)).transpose();
          out.tau.row(k) = loop_->control(data.t[k], x.head(n), x.tail(n)).transpose();
        });
    return out;
  }

  exid::Estimate finish(const exid::ObservationModel& model, const exid::Rows& R, const MatrixXd& Z,
                        const VectorXd& theta, const MatrixXd& ZtWinv, int iterations,
                        const std::string& stop, bool converged, const exid::Json& trace,
                        std::chrono::steady_clock::time_point t0) const {
    const int p = model.numBase();
    const long m = R.y.size();
    exid::estimators::LsSolution s;
    s.p = p;
    s.m = m;
    s.theta = theta;
    s.rss = (R.y - R.W * theta).squaredNorm();
    s.sigma2 = s.rss / static_cast<double>(m - p);
    // The sandwich A^-1 (sum_k g_k g_k^T) A^-T, g_k = Z_k^T e_k over the rows of sample k:
    // the residual e = y - W theta holds the noise of W's inputs (q, qd, qdd), shared by the
    // rows of one sample and larger on some joints, so neither is assumed away.
    const MatrixXd& A = ZtWinv;
    const VectorXd res = R.y - R.W * theta;
    const int per = per_;
    MatrixXd S = MatrixXd::Zero(p, p);
    for (long b = 0; b < m; b += per) {
      const VectorXd g = Z.middleRows(b, per).transpose() * res.segment(b, per);
      S.noalias() += g * g.transpose();
    }
    const double small = static_cast<double>(m) / static_cast<double>(m - p);
    s.covariance = small * A * S * A.transpose();
    s.std = s.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    s.rel_std_percent = exid::estimators::relativeStdPercent(s.theta, s.std);
    Eigen::JacobiSVD<MatrixXd> svd(R.W);
    s.singular_values = svd.singularValues();
    s.cond_W = s.singular_values[0] / s.singular_values[p - 1];
    const VectorXd norms = R.W.colwise().norm().transpose().cwiseMax(1e-300);
    Eigen::JacobiSVD<MatrixXd> svds(R.W * norms.cwiseInverse().asDiagonal());
    s.singular_values_scaled = svds.singularValues();
    s.cond_W_scaled = s.singular_values_scaled[0] / s.singular_values_scaled[p - 1];
    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, s, s.rss, m);
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["method"] =
        "theta_{i+1} = (Z^T W)^-1 Z^T y, Z the model's rows from the closed-loop simulation "
        "with theta_i (CVODES BDF), W and y the recording's; theta_0 least squares";
    d["covariance_definition"] =
        "(Z^T W)^-1 (sum_k g_k g_k^T) (Z^T W)^-T m / (m - p), g_k = Z_k^T (y_k - W_k theta) over "
        "the rows of sample k (robust to noise shared by a sample's rows and unequal per "
        "joint)";
    d["controller"] = loop_->describe();
    d["iterations"] = iterations;
    d["trace"] = trace;
    d["stop"] = stop;
    d["converged"] = converged;
    d["memory"] = "the recording's rows and the simulated rows (2 m p doubles): not streamed";
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!converged) {
      exid::Json w = exid::Json::array();
      const exid::Json& last = trace.at(trace.size() - 1);
      w.push_back(exid::Json(fmt::format(
          "iv: not converged: from least squares, stopped after {} iterations at {} with rss "
          "{:.6g}, the simulation tracking the recording to {:.3g} rad rms: {}",
          iterations, exid::estimators::describePoint(e.names, e.value), s.rss,
          last.find("tracking_rms_rad")->asDouble(), stop)));
      d["warnings"] = w;
    }
    return e;
  }

  exid::ParamSet P_;
  int max_iter_;
  double tol_;
  exid::estimators::ClosedLoop::Tolerances tol_loop_;
  std::unique_ptr<exid::estimators::ClosedLoop> loop_;
  int per_ = 0;  // rows per sample
};

}  // namespace

EXID_REGISTER_PLUGIN(Iv)
