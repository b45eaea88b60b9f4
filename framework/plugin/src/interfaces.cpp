#include "exid/interfaces.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <ostream>
#include <random>

#include "exid/drive.hpp"
#include "exid/error.hpp"

namespace exid {

void ObservationModel::bind(std::shared_ptr<const RobotModel> robot, const RunContext& ctx) {
  check(robot != nullptr, "ObservationModel::bind: no robot");
  if (robot->floating_base && !specs().floating_base)
    robot->requireFixedBase("the observation model '" + pluginName() + "'");
  robot_ = std::move(robot);
  onBind(ctx);
  int samples = baseSamples();
  // Large robots: no more rows than computeBaseParameters uses (max(4 p, 2000)); a 50-link
  // chain needs 52 of the 200 samples. Sized from the rows of one probe sample.
  try {
    const Samples probe = randomSamples(1, ctx.seed);
    const Eigen::Index per = fullDesign(probe).rows();
    const double needed =
        std::max(4.0 * static_cast<double>(fullNames().size()), 2000.0) / std::max<double>(per, 1);
    if (per > 0 && static_cast<double>(samples) > std::ceil(needed))
      samples = std::max(1, static_cast<int>(std::ceil(needed)));
  } catch (const Error&) {  // a model that needs more than one sample: all of them
  }
  Samples s = randomSamples(samples, ctx.seed ^ 0x9e3779b97f4a7c15ull);
  if (!moving_.empty()) {
    check(held_.size() == s.dof(),
          fmt::format("model '{}': restrictMotion: {} held positions for a "
                      "{}-dof robot",
                      pluginName(), held_.size(), s.dof()));
    for (int j = 0; j < s.dof(); ++j) {
      if (std::find(moving_.begin(), moving_.end(), j) != moving_.end()) continue;
      s.q.col(j).setConstant(held_(j));
      s.qd.col(j).setZero();
      s.qdd.col(j).setZero();
    }
  }
  Eigen::MatrixXd W = fullDesign(s);
  base_ = computeBaseParameters(W, fullNames(), base_options_);
  check(base_.rank() > 0, fmt::format("model '{}' on robot '{}': no identifiable parameter",
                                      pluginName(), robot_->name));
}

void ObservationModel::restrictMotion(std::vector<int> moving, Eigen::VectorXd held) {
  moving_ = std::move(moving);
  held_ = std::move(held);
}

Samples ObservationModel::randomSamples(int count, std::uint64_t seed) const {
  const RobotModel& r = *robot_;
  const int n = r.dof();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Samples s;
  s.t = Eigen::VectorXd::LinSpaced(count, 0.0, count - 1.0);
  s.q.resize(count, n);
  s.qd.resize(count, n);
  s.qdd.resize(count, n);
  for (int k = 0; k < count; ++k) {
    Eigen::VectorXd q(n), qd(n), qdd(n);
    for (int j = 0; j < n; ++j) {
      const JointLimits& L =
          r.limits.size() > static_cast<std::size_t>(j) ? r.limits[j] : JointLimits{};
      double lo = L.q_min, hi = L.q_max;
      if (!(std::isfinite(lo) && std::abs(lo) < 1e3)) lo = -M_PI;
      if (!(std::isfinite(hi) && std::abs(hi) < 1e3)) hi = M_PI;
      q(j) = 0.5 * (lo + hi) + 0.5 * (hi - lo) * u(rng);
      double vmax = (std::isfinite(L.qd_max) && L.qd_max < 1e3) ? L.qd_max : 2.0;
      double amax = (std::isfinite(L.qdd_max) && L.qdd_max < 1e4) ? L.qdd_max : 10.0;
      qd(j) = vmax * u(rng);
      qdd(j) = amax * u(rng);
    }
    Eigen::VectorXd qm, qdm, qddm;
    jointToMeasured(r, q, qd, qdd, &qm, &qdm, &qddm);
    s.q.row(k) = qm.transpose();
    s.qd.row(k) = qdm.transpose();
    s.qdd.row(k) = qddm.transpose();
  }
  return s;
}

namespace {

// Samples per block when a per-sample model's full rows are built a block at a time (rows(),
// design()): a block's full W about 1 MB (cache resident, its memory reused) for max(dof, 6)
// rows per sample.
int fullBlockSamples(int full_columns, int dof) {
  constexpr double kBlockBytes = 1 << 20;
  const double sample_bytes =
      8.0 * static_cast<double>(std::max(1, full_columns)) * static_cast<double>(std::max(6, dof));
  return static_cast<int>(std::clamp(kBlockBytes / sample_bytes, 16.0, 65536.0));
}

// Full-column rows reduced to the base columns (the rest moved over as they are).
Rows baseRowsOf(const BaseParameters& base, Rows&& full) {
  Rows out;
  out.W = base.columns(full.W);
  out.y = std::move(full.y);
  out.equation = std::move(full.equation);
  out.numEquations = full.numEquations;
  out.t = std::move(full.t);
  out.equation_names = std::move(full.equation_names);
  out.torque = std::move(full.torque);
  return out;
}

// A per-sample model's full rows are built a block of samples at a time (a block's full W
// about 1 MB, cache resident and reused) and only the base columns are kept: the full W of a
// long chunk (84 columns for a 6-joint arm with drives, twice the base ones) is never held.
// full_of(d): the full rows of the samples d.
Rows baseRowsByBlocks(const ObservationModel& model, const Dataset& data,
                      const std::function<Rows(const Dataset&)>& full_of) {
  const BaseParameters& base = model.base();
  const int K = data.size();
  const int block = fullBlockSamples(base.numFull(), data.dof());
  if (!data.streamed() && K > block && model.specs().per_sample) {
    const int p = base.rank();
    Rows out;
    Eigen::Index m = 0;  // rows per sample
    for (int b = 0; b < K; b += block) {
      const int e = std::min(K, b + block);
      Rows full = full_of(sliceDataset(data, b, e));
      if (b == 0) {
        m = full.W.rows() / std::max(1, e - b);
        out.W.resize(static_cast<Eigen::Index>(K) * m, p);
        out.y.resize(out.W.rows());
        out.numEquations = full.numEquations;
        out.equation_names = full.equation_names;
      }
      const Eigen::Index r0 = static_cast<Eigen::Index>(b) * m, nr = full.W.rows();
      check(nr == static_cast<Eigen::Index>(e - b) * m && full.y.size() == nr &&
                full.W.cols() == base.numFull(),
            fmt::format("model '{}': {} rows of {} columns for samples [{}, {}) (expected {} "
                        "per sample, as for the first samples, of {} columns)",
                        model.pluginName(), nr, full.W.cols(), b, e, m, base.numFull()));
      for (int k = 0; k < p; ++k)
        out.W.col(k).segment(r0, nr) = full.W.col(base.independent[static_cast<size_t>(k)]);
      out.y.segment(r0, nr) = full.y;
      out.equation.insert(out.equation.end(), full.equation.begin(), full.equation.end());
      out.t.insert(out.t.end(), full.t.begin(), full.t.end());
      out.torque.insert(out.torque.end(), full.torque.begin(), full.torque.end());
    }
    return out;
  }
  Rows full = full_of(data);
  if (full.W.cols() != base.numFull())  // (the message only when it fails: once per chunk)
    throw Error(fmt::format("model '{}': {} full columns, expected {}", model.pluginName(),
                            full.W.cols(), base.numFull()));
  return baseRowsOf(base, std::move(full));
}

}  // namespace

Rows ObservationModel::rows(const Dataset& data, const RunContext& ctx) const {
  return baseRowsByBlocks(*this, data, [&](const Dataset& d) { return fullRows(d, ctx); });
}

Rows ObservationModel::fullRowsAt(const Dataset& data, const Eigen::VectorXd& eta,
                                  Eigen::MatrixXd* dW, const RunContext& ctx) const {
  if (eta.size() != 0)
    throw Error(fmt::format("model '{}': it has no nonlinear parameter, {} given", pluginName(),
                            eta.size()));
  Rows r = fullRows(data, ctx);
  if (dW) dW->resize(r.W.rows(), 0);
  return r;
}

Eigen::MatrixXd ObservationModel::fullColumnsAt(const Dataset& data, const Eigen::VectorXd& eta,
                                                const std::vector<int>& columns,
                                                const RunContext& ctx, Eigen::MatrixXd* dW) const {
  const Rows full = fullRowsAt(data, eta, dW, ctx);
  Eigen::MatrixXd out(full.W.rows(), static_cast<Eigen::Index>(columns.size()));
  for (std::size_t i = 0; i < columns.size(); ++i) {
    const int c = columns[i];
    if (c < 0 || c >= full.W.cols())
      throw Error(fmt::format("model '{}': fullColumnsAt: column {} of {} full columns",
                              pluginName(), c, full.W.cols()));
    out.col(static_cast<Eigen::Index>(i)) = full.W.col(c);
  }
  return out;
}

namespace {

// dJ/dW of the base columns as dJ/dW of the full ones (zero on the dependent columns).
Eigen::MatrixXd fullOfBase(const BaseParameters& base, const Eigen::MatrixXd& dW_base) {
  Eigen::MatrixXd dW = Eigen::MatrixXd::Zero(dW_base.rows(), base.numFull());
  for (int i = 0; i < base.rank(); ++i) dW.col(base.independent[i]) = dW_base.col(i);
  return dW;
}

}  // namespace

Eigen::MatrixXd ObservationModel::fullDesignAt(const Samples& s, const Eigen::VectorXd& eta,
                                               Eigen::MatrixXd* dW) const {
  if (eta.size() != 0)
    throw Error(fmt::format("model '{}': it has no nonlinear parameter, {} given", pluginName(),
                            eta.size()));
  Eigen::MatrixXd W = fullDesign(s);
  if (dW) dW->resize(W.rows(), 0);
  return W;
}

void ObservationModel::fullDesignVjpAt(const Samples& s, const Eigen::VectorXd& eta,
                                       const Eigen::MatrixXd& dW, Samples* grad) const {
  if (eta.size() != 0)
    throw Error(fmt::format("model '{}': it has no nonlinear parameter, {} given", pluginName(),
                            eta.size()));
  fullDesignVjp(s, dW, grad);
}

Eigen::MatrixXd ObservationModel::designAt(const Samples& s, const Eigen::VectorXd& eta,
                                           Eigen::MatrixXd* dW) const {
  // (fullDesignAt checks eta's size against its own nonlinear parameters: a hot path)
  return base_.columns(fullDesignAt(s, eta, dW));
}

void ObservationModel::designVjpAt(const Samples& s, const Eigen::VectorXd& eta,
                                   const Eigen::MatrixXd& dW_base, Samples* grad) const {
  fullDesignVjpAt(s, eta, fullOfBase(base_, dW_base), grad);
}

Rows ObservationModel::rowsAt(const Dataset& data, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW,
                              const RunContext& ctx) const {
  const std::vector<NonlinearParameter> nl = nonlinearParameters();
  if (eta.size() != static_cast<Eigen::Index>(nl.size()))
    throw Error(fmt::format("model '{}': {} nonlinear parameter values given, expected {}",
                            pluginName(), eta.size(), nl.size()));
  if (!dW)  // (block by block, as rows())
    return baseRowsByBlocks(*this, data,
                            [&](const Dataset& d) { return fullRowsAt(d, eta, nullptr, ctx); });
  Rows full = fullRowsAt(data, eta, dW, ctx);
  if (full.W.cols() != base_.numFull())
    throw Error(fmt::format("model '{}': fullRowsAt gave {} columns, expected {}", pluginName(),
                            full.W.cols(), base_.numFull()));
  return baseRowsOf(base_, std::move(full));
}

std::vector<int> ObservationModel::nonlinearColumnsInBase() const {
  std::vector<int> out;
  for (const NonlinearParameter& p : nonlinearParameters())
    for (int c : p.columns) {
      const auto it = std::find(base_.independent.begin(), base_.independent.end(), c);
      out.push_back(
          it == base_.independent.end() ? -1 : static_cast<int>(it - base_.independent.begin()));
    }
  return out;
}

Eigen::MatrixXd ObservationModel::design(const Samples& s) const {
  const int K = s.size();
  const int block = fullBlockSamples(base_.numFull(), s.dof());
  if (K <= block || !specs().per_sample) return base_.columns(fullDesign(s));
  // As rows(): the full design a block of samples at a time, only the base columns kept.
  const int p = base_.rank();
  Eigen::MatrixXd W;
  Eigen::Index m = 0;
  Samples sub;
  for (int b = 0; b < K; b += block) {
    const int e = std::min(K, b + block);
    sub.t = s.t.segment(b, e - b);
    sub.q = s.q.middleRows(b, e - b);
    sub.qd = s.qd.middleRows(b, e - b);
    sub.qdd = s.qdd.middleRows(b, e - b);
    if (s.base.size() > 0) sub.base = s.base.middleRows(b, e - b);  // a floating base
    const Eigen::MatrixXd full = fullDesign(sub);
    if (b == 0) {
      m = full.rows() / (e - b);
      W.resize(static_cast<Eigen::Index>(K) * m, p);
    }
    check(full.rows() == static_cast<Eigen::Index>(e - b) * m && full.cols() == base_.numFull(),
          fmt::format("model '{}': design of {} rows, {} columns for samples [{}, {}) (expected {} "
                      "per sample, as for the first samples, of {} columns)",
                      pluginName(), full.rows(), full.cols(), b, e, m, base_.numFull()));
    for (int k = 0; k < p; ++k)
      W.col(k).segment(static_cast<Eigen::Index>(b) * m, full.rows()) =
          full.col(base_.independent[static_cast<size_t>(k)]);
  }
  return W;
}

void ObservationModel::designVjp(const Samples& s, const Eigen::MatrixXd& dW_base,
                                 Samples* grad) const {
  fullDesignVjp(s, fullOfBase(base_, dW_base), grad);
}

void ExcitationProblem::nonlinearConstraints(const Eigen::VectorXd& z, Eigen::VectorXd* g,
                                             Eigen::MatrixXd* jac) {
  const int nl = numNonlinearConstraints();
  if (nl == 0) {
    if (g) g->resize(0);
    if (jac) jac->resize(0, z.size());
    return;
  }
  Eigen::VectorXd ga;
  Eigen::MatrixXd ja;
  constraints(z, g ? &ga : nullptr, jac ? &ja : nullptr);
  if (g) *g = ga.tail(nl);
  if (jac) *jac = ja.bottomRows(nl);
}

void Trajectory::bounds(Eigen::VectorXd* lower, Eigen::VectorXd* upper) const {
  const int m = numVariables();
  if (lower) *lower = Eigen::VectorXd::Constant(m, -HUGE_VAL);
  if (upper) *upper = Eigen::VectorXd::Constant(m, HUGE_VAL);
}

Eigen::MatrixXd Trajectory::jacobian(const Eigen::VectorXd& z) const {
  Samples s = evaluate(z);
  const Eigen::Index K = s.q.rows(), n = s.q.cols();
  const Eigen::Index rows = 3 * K * n;
  Eigen::MatrixXd J(rows, numVariables());
  Samples adj;
  adj.t = s.t;
  adj.q = Eigen::MatrixXd::Zero(K, n);
  adj.qd = adj.q;
  adj.qdd = adj.q;
  for (Eigen::Index r = 0; r < rows; ++r) {
    const Eigen::Index block = r / (K * n), idx = r % (K * n);
    Eigen::MatrixXd& m = block == 0 ? adj.q : (block == 1 ? adj.qd : adj.qdd);
    m(idx % K, idx / K) = 1.0;
    J.row(r) = vjp(z, adj).transpose();
    m(idx % K, idx / K) = 0.0;
  }
  return J;
}

Samples Trajectory::evaluateAt(const Eigen::VectorXd&, const Eigen::VectorXd&) const {
  throw Error(fmt::format(
      "trajectory '{}' is defined on its sample grid only (no evaluation at arbitrary times)",
      pluginName()));
}

Eigen::VectorXd Trajectory::vjpAt(const Eigen::VectorXd&, const Eigen::VectorXd&,
                                  const Samples&) const {
  throw Error(fmt::format(
      "trajectory '{}' is defined on its sample grid only (no evaluation at arbitrary times)",
      pluginName()));
}

std::string toString(StopReason r) {
  switch (r) {
    case StopReason::None:
      return "";
    case StopReason::Converged:
      return "converged";
    case StopReason::ConvergedFtol:
      return "converged (ftol_rel)";
    case StopReason::ConvergedGtol:
      return "converged (gtol)";
    case StopReason::MaxIterations:
      return "max_iterations";
    case StopReason::StartOnly:
      return "max_iterations (0: start evaluated only)";
    case StopReason::OuterPasses:
      return "outer passes";
    case StopReason::MaxEvaluations:
      return "max_evaluations";
    case StopReason::MaxTime:
      return "max_time_s";
    case StopReason::MaxCpu:
      return "max_cpu_s";
    case StopReason::Deadline:
      return "deadline";
    case StopReason::Cancelled:
      return "cancelled";
    case StopReason::ConvergedXtol:
      return "converged (xtol_rel)";
    case StopReason::Stalled:
      return "stalled (no convergence test passed)";
    case StopReason::NoProgress:
      return "no progress (stopped at the start: its first search direction did not descend)";
  }
  return "";
}

std::ostream& operator<<(std::ostream& os, StopReason r) { return os << toString(r); }

bool stoppedByTime(StopReason r) {
  return r == StopReason::MaxTime || r == StopReason::MaxCpu || r == StopReason::Deadline;
}

std::string stopReasonText(const OptimizerResult& r) {
  std::string s = toString(r.stop_reason);
  if (!r.feasible) s += " (no feasible point found; least violation returned)";
  return s;
}

}  // namespace exid
