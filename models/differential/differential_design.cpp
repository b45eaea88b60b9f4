// exid — observation model `differential`: the rows (recorded torque less the known payload's,
// the load-dependent Coulomb and drive gain columns), the design and the torque at given
// nonlinear parameters, with their derivatives and vector-Jacobian products (see
// differential.cpp).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "differential.hpp"
#include "exid/closed_chain.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/payload.hpp"

namespace exid::differential {

exid::Rows DifferentialModel::fullRowsAt(const exid::Dataset& d, const Eigen::VectorXd& eta,
                                         Eigen::MatrixXd* dW, const exid::RunContext&) const {
  const int n = robot().dof();
  const std::string who = "model 'differential'";
  requireTorqueSignals(d, n, who);
  exid::Rows r;
  r.W = designAt(d.samples(), frictionAt(eta), dW, false);
  const int K = d.size(), m = static_cast<int>(sel_.size());
  exid::models::sizeRows(&r, K, m);
  // drive gains: the payload part's samples (t >= its first) carry the known payload
  double loaded_from = HUGE_VAL;
  if (gains_ && gains_prior_) {
    exid::check(!d.facts.payload_part_from_t_s,
                fmt::format("{}: the data have a payload part (facts.payload_part_from_t_s) "
                            "but drive_gains_scale is prior: give the payload "
                            "(payload_mass_kg, ...) and drive_gains_scale: payload ({})",
                            who, d.source));
  } else if (gains_) {
    if (!d.facts.payload_part_from_t_s)
      throw exid::Error(
          fmt::format("{}: drive_gains needs a part of the recording with the known payload (csv "
                      "payload_file; facts.payload_part_from_t_s): without it the gains and the "
                      "parameters' scale are not identifiable ({})",
                      who, d.source));
    loaded_from = *d.facts.payload_part_from_t_s;
  }
  const int Pg = static_cast<int>(r.W.cols()) - gainCount(), Pl = Pg - loadCount();
  auto data = gains_ ? exid::makeDynamicsData(robot()) : nullptr;  // (once per call)
  Eigen::VectorXd tp;
  for (int k = 0; k < K; ++k) {
    const bool loaded = gains_ && d.t[k] >= loaded_from;
    if (loaded) tp = payloadTorque(*data, phi_, d.q.row(k), d.qd.row(k), d.qdd.row(k));
    for (int i = 0; i < m; ++i) {
      const int j = sel_[static_cast<std::size_t>(i)];
      double y = d.tau(k, j);
      if (friction_ == "subtract") y -= frictionTorque(j, d.qd(k, j));
      if (gains_) r.W(k * m + i, Pg + j) = -d.tau(k, j);
      if (load_) r.W(k * m + i, Pl + j) = exid::loadCoulombColumn(d.tau(k, j), d.qd(k, j));
      if (loaded) y -= tp[j];
      r.y[k * m + i] = y;
      r.equation[static_cast<std::size_t>(k * m + i)] = i;
      r.t[static_cast<std::size_t>(k * m + i)] = d.t[k];
    }
  }
  r.equation_names = exid::models::torqueEquationNames(robot(), sel_);
  return r;
}

// The nonlinear friction columns alone (extraColumns' values and derivatives, the same bits:
// FrictionColumns's values do not depend on whether derivatives are asked for); any other
// column through fullRowsAt.
Eigen::MatrixXd DifferentialModel::fullColumnsAt(const exid::Dataset& d, const Eigen::VectorXd& eta,
                                                 const std::vector<int>& columns,
                                                 const exid::RunContext& ctx,
                                                 Eigen::MatrixXd* dW) const {
  const int n = robot().dof(), P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
  bool friction_only = E > 0 && !columns.empty();
  for (int c : columns) friction_only = friction_only && c >= P0 && c < P0 + E * n;
  if (!friction_only) return ObservationModel::fullColumnsAt(d, eta, columns, ctx, dW);
  const std::string who = "model 'differential'";
  requireTorqueSignals(d, n, who);
  exid::models::requireSamples(d.samples(), n, true, who);
  const Friction f = frictionAt(eta);
  const int K = d.size(), m = static_cast<int>(sel_.size());
  const auto C = static_cast<Eigen::Index>(columns.size());
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(K) * m, C);
  const exid::FrictionColumns fc = frictionColumns();
  // (extraColumns' derivative columns, in nonlinearParameters() order)
  std::vector<int> deps(static_cast<std::size_t>(n), -1), dvs(static_cast<std::size_t>(n), -1);
  if (dW) {
    int L = 0;
    for (const Slot& sl : slots()) {
      (sl.eps ? deps : dvs)[static_cast<std::size_t>(sl.joint)] = L;
      L += sl.eps ? E : 1;
    }
    dW->setZero(static_cast<Eigen::Index>(K) * m, L);
  }
  // each row's columns (and derivatives) from one evaluation of its joint's friction per sample
  double w[3], dw_eps[3], dw_vs = 0.0;
  std::vector<std::pair<Eigen::Index, int>> own;  // (output column, the joint's column e)
  for (int i = 0; i < m; ++i) {
    const int j = sel_[static_cast<std::size_t>(i)];
    const auto u = static_cast<std::size_t>(j);
    own.clear();
    for (Eigen::Index c = 0; c < C; ++c) {
      const int col = columns[static_cast<std::size_t>(c)] - P0;
      if (col / E == j) own.emplace_back(c, col % E);  // (a row has its own joint's only)
    }
    const bool derivatives = dW && (deps[u] >= 0 || dvs[u] >= 0);
    if (own.empty() && !derivatives) continue;
    for (int k = 0; k < K; ++k) {
      const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
      fc.values(d.qd(k, j), f.eps[u], f.vs[u], w, derivatives ? dw_eps : nullptr,
                derivatives ? &dw_vs : nullptr);
      for (const auto& [c, e] : own) out(row, c) = w[e];
      if (!derivatives) continue;
      if (deps[u] >= 0)
        for (int e = 0; e < E; ++e) (*dW)(row, deps[u] + e) = dw_eps[e];
      if (dvs[u] >= 0) (*dW)(row, dvs[u]) = dw_vs;
    }
  }
  return out;
}

bool DifferentialModel::fullTorqueAt(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                     const Eigen::VectorXd& qdd, const Eigen::VectorXd& eta,
                                     const Eigen::VectorXd& phi, Eigen::VectorXd* tau,
                                     Eigen::MatrixXd* d_q, Eigen::MatrixXd* d_qd,
                                     Eigen::MatrixXd* d_qdd) const {
  const exid::RobotModel& R = robot();
  const int n = R.dof(), P0 = exid::numParameters(R, cols_), E = extraPerJoint();
  const int T = loadCount() + gainCount();
  if (phi.size() != P0 + E * n + T || tau == nullptr)  // (a simulation's every step)
    throw exid::Error(
        fmt::format("model 'differential': fullTorqueAt: {} parameters, expected {}{}", phi.size(),
                    P0 + E * n + T, tau ? "" : "; tau must be given"));
  if (static_cast<int>(sel_.size()) != n) return false;
  for (int i = 0; i < n; ++i)
    if (sel_[static_cast<std::size_t>(i)] != i) return false;
  if (T > 0 && !phi.tail(T).isZero(0.0)) return false;      // (the torque columns: the design's)
  const Friction f = E > 0 ? frictionAt(eta) : Friction{};  // (only the extra columns read it)
  {
    const Workspace data(*this);
    exid::actuatorTorqueWith(R, *data, cols_, phi.head(P0), q, qd, qdd, tau, d_q, d_qd, d_qdd);
  }
  const exid::FrictionColumns fc = frictionColumns();
  for (int j = 0; j < n && E > 0; ++j) {  // the nonlinear friction columns (extraColumns)
    const auto u = static_cast<std::size_t>(j);
    const auto g = phi.segment(P0 + E * j, E);
    const double v = qd[j];
    double w[3];
    fc.values(v, f.eps[u], f.vs[u], w);
    double t = 0.0;
    for (int e = 0; e < E; ++e) t += g[e] * w[e];
    (*tau)[j] += t;
    if (d_qd) (*d_qd)(j, j) += extraColumnsVjp(v, f, j, g.transpose());
  }
  return true;
}

DifferentialModel::Friction DifferentialModel::frictionAt(const Eigen::VectorXd& eta) const {
  const int n = robot().dof();
  Friction f;
  f.eps.assign(static_cast<std::size_t>(n), 0.0);
  f.vs.assign(static_cast<std::size_t>(n), 1.0);
  for (int j = 0; j < n; ++j) {
    if (!eps_param_.empty()) f.eps[static_cast<std::size_t>(j)] = perJoint(eps_param_, j);
    if (stribeck_) f.vs[static_cast<std::size_t>(j)] = perJoint(vs_param_, j);
  }
  const std::vector<Slot> sl = slots();
  exid::check(eta.size() == static_cast<Eigen::Index>(sl.size()),
              "model 'differential': wrong number of nonlinear parameter values");
  for (std::size_t k = 0; k < sl.size(); ++k) {
    const double v = eta[static_cast<Eigen::Index>(k)];
    if (!(v > 0 && std::isfinite(v)))
      throw exid::Error(fmt::format("model 'differential': {}{} = {} (must be positive)",
                                    sl[k].eps ? "eps" : "vs", sl[k].joint + 1, v));
    (sl[k].eps ? f.eps : f.vs)[static_cast<std::size_t>(sl[k].joint)] = v;
  }
  return f;
}

// Full design rows at the friction f; dW (optional): the derivatives of the columns the
// nonlinear parameters move, in nonlinearParameters() order.
// With drive gains and gain_design, the dK columns are those of a design (no measurement):
// minus the nominal robot's torque, with the known payload on every other sample (the
// identifiable space of a recording with and without it); else zero (fullRowsAt fills them).
Eigen::MatrixXd DifferentialModel::designAt(const exid::Samples& s, const Friction& f,
                                            Eigen::MatrixXd* dW, bool gain_design) const {
  const exid::RobotModel& R = robot();
  const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
  exid::models::requireSamples(s, n, true, "model 'differential'");
  const int P0 = exid::numParameters(R, cols_), E = extraPerJoint();
  const int P = P0 + E * n + loadCount() + gainCount();
  // One sample's rows are a block of m consecutive rows of W: each column receives m
  // contiguous numbers (cache friendly), and nothing is allocated per sample.
  Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m, P);
  bool all = m == n;
  for (int i = 0; all && i < m; ++i) all = sel_[static_cast<std::size_t>(i)] == i;
  const Workspace data(*this);
  if (all) {
    // Written in place, several samples per kernel call (actuatorRegressors: the same bits as
    // one sample at a time).
    exid::actuatorRegressors(R, *data, cols_, s.q, s.qd, s.qdd, W.leftCols(P0));
  } else {
    // a block of samples at a time, then the selected joints' rows
    constexpr int kBlock = 64;
    Eigen::MatrixXd Y(static_cast<Eigen::Index>(kBlock) * n, P0);
    for (int k0 = 0; k0 < K; k0 += kBlock) {
      const int b = std::min(kBlock, K - k0);
      auto Yb = Y.topRows(static_cast<Eigen::Index>(b) * n);
      exid::actuatorRegressors(R, *data, cols_, s.q.middleRows(k0, b), s.qd.middleRows(k0, b),
                               s.qdd.middleRows(k0, b), Yb);
      for (int k = 0; k < b; ++k)
        for (int i = 0; i < m; ++i)
          W.row(static_cast<Eigen::Index>(k0 + k) * m + i).head(P0) =
              Yb.row(static_cast<Eigen::Index>(k) * n + sel_[static_cast<std::size_t>(i)]);
    }
  }
  if (E > 0) extraColumns(s, f, &W, dW);
  if (load_) loadColumns(s, &W);
  if (gains_) gainColumns(s, gain_design, &W);
  return W;
}

// The FcL columns of a design: |nominal torque| sign(qdm) (rows() puts the recorded torque).
void DifferentialModel::loadColumns(const exid::Samples& s, Eigen::MatrixXd* W) const {
  const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
  const int Pl = static_cast<int>(W->cols()) - n;
  const Eigen::VectorXd nominal = fullNominal().head(Pl);
  W->rightCols(n).setZero();  // (a row has its own joint's column only)
  for (int k = 0; k < K; ++k)
    for (int i = 0; i < m; ++i) {
      const int j = sel_[static_cast<std::size_t>(i)];
      const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
      (*W)(row, Pl + j) = exid::loadCoulombColumn(W->row(row).head(Pl).dot(nominal), s.qd(k, j));
    }
}

// The dK columns of a design (see designAt), or zeros.
void DifferentialModel::gainColumns(const exid::Samples& s, bool gain_design,
                                    Eigen::MatrixXd* W) const {
  const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
  const int Pg = static_cast<int>(W->cols()) - n;
  W->rightCols(n).setZero();
  if (!gain_design) return;
  const Eigen::VectorXd nominal = fullNominal().head(Pg);
  auto data = exid::makeDynamicsData(robot());
  Eigen::VectorXd tp = Eigen::VectorXd::Zero(n);
  for (int k = 0; k < K; ++k) {
    if (k % 2 == 1)
      tp = payloadTorque(*data, design_phi_, s.q.row(k), s.qd.row(k), s.qdd.row(k));
    else
      tp.setZero();
    for (int i = 0; i < m; ++i) {
      const int j = sel_[static_cast<std::size_t>(i)];
      const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
      (*W)(row, Pg + j) = -(W->row(row).head(Pg).dot(nominal) + tp[j]);
    }
  }
}

// The known payload's torque at a sample, in the measured coordinates: T^T Yp phi.
Eigen::VectorXd DifferentialModel::payloadTorque(
    exid::DynamicsData& data, const Eigen::Matrix<double, 10, 1>& phi,
    const Eigen::Ref<const Eigen::RowVectorXd>& qm, const Eigen::Ref<const Eigen::RowVectorXd>& qdm,
    const Eigen::Ref<const Eigen::RowVectorXd>& qddm) const {
  const exid::RobotModel& R = robot();
  Eigen::VectorXd q, qd, qdd;
  Eigen::MatrixXd Yp(R.numJoints(), 10);
  if (R.hasLoops()) {  // tau_a = G^T tau_tree
    Eigen::MatrixXd G;
    const Eigen::VectorXd a = qm.transpose(), ad = qdm.transpose(), add = qddm.transpose();
    exid::closedChainState(R, a, &ad, &add, &q, &qd, &qdd, &G, nullptr);
    exid::payloadTorqueRegressor(R, data, q, qd, qdd, Yp);
    return G.transpose() * (Yp * phi);
  }
  exid::measuredToJoint(R, qm.transpose(), qdm.transpose(), qddm.transpose(), &q, &qd, &qdd);
  exid::payloadTorqueRegressor(R, data, q, qd, qdd, Yp);
  const Eigen::VectorXd t = Yp * phi;
  if (R.hasTransmission()) return R.transmission.transpose() * t;
  return t;
}

// The nonlinear friction columns (after the P0 drive columns) of W, and their derivatives
// with respect to the nonlinear parameters into dW (see designAt).
void DifferentialModel::extraColumns(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* W,
                                     Eigen::MatrixXd* dW) const {
  const int n = robot().dof(), K = s.size(), m = static_cast<int>(sel_.size());
  const int P0 = exid::numParameters(robot(), cols_), E = extraPerJoint();
  W->middleCols(P0, E * n).setZero();
  // where each drive's derivative columns start in dW (nonlinearParameters() order)
  std::vector<int> deps(static_cast<std::size_t>(n), -1), dvs(static_cast<std::size_t>(n), -1);
  int L = 0;
  for (const Slot& sl : slots()) {  // (a width moves every column of its joint; vs one)
    (sl.eps ? deps : dvs)[static_cast<std::size_t>(sl.joint)] = L;
    L += sl.eps ? E : 1;
  }
  if (dW) dW->setZero(W->rows(), L);
  const exid::FrictionColumns fc = frictionColumns();
  double w[3], dw_eps[3], dw_vs = 0.0;
  for (int k = 0; k < K; ++k)
    for (int i = 0; i < m; ++i) {
      const int j = sel_[static_cast<std::size_t>(i)];
      const auto u = static_cast<std::size_t>(j);
      const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
      fc.values(s.qd(k, j), f.eps[u], f.vs[u], w, dw_eps, &dw_vs);
      for (int e = 0; e < E; ++e) (*W)(row, P0 + E * j + e) = w[e];
      if (dW && deps[u] >= 0)
        for (int e = 0; e < E; ++e) (*dW)(row, deps[u] + e) = dw_eps[e];
      if (dW && dvs[u] >= 0) (*dW)(row, dvs[u]) = dw_vs;
    }
}

void DifferentialModel::fullDesignVjpAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                                        const Eigen::MatrixXd& dW, exid::Samples* grad) const {
  const Friction f = frictionAt(eta);
  const exid::RobotModel& R = robot();
  const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
  const int P0 = exid::numParameters(R, cols_), P = P0 + extraPerJoint() * n;
  const int T = loadCount() + gainCount();  // the torque columns
  exid::check(dW.rows() == static_cast<Eigen::Index>(K) * m && dW.cols() == P + T,
              fmt::format("model 'differential': fullDesignVjp: dW is {} x {} (expected {} x {})",
                          dW.rows(), dW.cols(), K * m, P + T));
  if (load_) {
    // the FcL columns |W_row nominal| sign(qdm_j): their part of the gradient goes through the
    // other columns, times sign(nominal torque) sign(qdm_j) the nominal values (sign(qdm)'s
    // derivative is 0)
    const Eigen::MatrixXd Wd = designAt(s, f, nullptr);
    Eigen::MatrixXd dWe = dW.leftCols(P);
    const Eigen::VectorXd nominal = fullNominal().head(P);
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) {
        const int j = sel_[static_cast<std::size_t>(i)];
        const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
        const double c =
            dW(row, P + j) * signum(Wd.row(row).head(P).dot(nominal)) * signum(s.qd(k, j));
        if (c != 0.0) dWe.row(row) += c * nominal.transpose();
      }
    designVjpNoGains(s, f, dWe, grad);
    return;
  }
  if (gains_) {
    // the dK columns -(W_row nominal + [odd k] T^T Yp phi): their part of the gradient goes
    // through the other columns (times the nominal values) and the payload's torque
    Eigen::MatrixXd dWe = dW.leftCols(P);
    const Eigen::VectorXd nominal = fullNominal().head(P);
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < m; ++i) {
        const Eigen::Index row = static_cast<Eigen::Index>(k) * m + i;
        dWe.row(row) -= dW(row, P + sel_[static_cast<std::size_t>(i)]) * nominal.transpose();
      }
    designVjpNoGains(s, f, dWe, grad);
    payloadTorqueVjp(s, dW, P, grad);
    return;
  }
  designVjpNoGains(s, f, dW, grad);
}

// The gradient of sum_k,j c_kj [T^T Yp phi]_j over the odd samples, c = -dW's dK columns,
// added to grad.
void DifferentialModel::payloadTorqueVjp(const exid::Samples& s, const Eigen::MatrixXd& dW, int P,
                                         exid::Samples* grad) const {
  const exid::RobotModel& R = robot();
  const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
  auto data = exid::makeDynamicsData(R);
  Eigen::MatrixXd Gm(n, 10), G(n, 10);
  Eigen::VectorXd q, qd, qdd, gq, gqd, gqdd;
  for (int k = 1; k < K; k += 2) {
    Gm.setZero();
    for (int i = 0; i < m; ++i) {
      const int j = sel_[static_cast<std::size_t>(i)];
      Gm.row(j) -= dW(static_cast<Eigen::Index>(k) * m + i, P + j) * design_phi_.transpose();
    }
    if (R.hasLoops()) {
      // <Gm, Gc^T Yp(q, qd, qdd)> with Gc = dq/dqa: the tree VJP of Gc Gm, mapped by the chain
      // rule, plus <dGc/dqa_l Gm, Yp> (the projection depends on qa too)
      const Eigen::VectorXd a = s.q.row(k).transpose(), ad = s.qd.row(k).transpose(),
                            add = s.qdd.row(k).transpose();
      Eigen::MatrixXd Gc;
      std::vector<Eigen::MatrixXd> dGc;
      exid::closedChainStateDerivatives(R, a, ad, add, &q, &qd, &qdd, &Gc, &dGc, nullptr, nullptr,
                                        nullptr);
      const Eigen::MatrixXd Gt = Gc * Gm;
      exid::payloadTorqueRegressorVjp(R, *data, q, qd, qdd, Gt, &gq, &gqd, &gqdd);
      exid::jointGradientToMeasured(R, a, ad, add, &gq, &gqd, &gqdd);
      Eigen::MatrixXd Yp(R.numJoints(), 10);
      exid::payloadTorqueRegressor(R, *data, q, qd, qdd, Yp);
      for (int l = 0; l < n; ++l)
        gq[l] += (dGc[static_cast<std::size_t>(l)] * Gm).cwiseProduct(Yp).sum();
      grad->q.row(k) += gq.transpose();
      grad->qd.row(k) += gqd.transpose();
      grad->qdd.row(k) += gqdd.transpose();
      continue;
    }
    exid::measuredToJoint(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                          s.qdd.row(k).transpose(), &q, &qd, &qdd);
    if (R.hasTransmission())
      G.noalias() = R.transmission * Gm;
    else
      G = Gm;
    exid::payloadTorqueRegressorVjp(R, *data, q, qd, qdd, G, &gq, &gqd, &gqdd);
    exid::models::jointGradToMeasured(R, &gq);
    exid::models::jointGradToMeasured(R, &gqd);
    exid::models::jointGradToMeasured(R, &gqdd);
    grad->q.row(k) += gq.transpose();
    grad->qd.row(k) += gqd.transpose();
    grad->qdd.row(k) += gqdd.transpose();
  }
}

// fullDesignVjp of every column but the dK ones (dW: K m x P).
void DifferentialModel::designVjpNoGains(const exid::Samples& s, const Friction& f,
                                         const Eigen::MatrixXd& dW, exid::Samples* grad) const {
  const exid::RobotModel& R = robot();
  const int n = R.dof(), K = s.size(), m = static_cast<int>(sel_.size());
  const int P0 = exid::numParameters(R, cols_), P = P0 + extraPerJoint() * n;
  exid::models::zeroGrad(s, grad);
  // a block of samples at a time (actuatorRegressorVjps: several samples per vector register,
  // the bits of one at a time); small blocks keep the buffers small (a buffer of a whole
  // trajectory's G is new memory, page faults and all, at every gradient)
  constexpr int kBlock = 16;
  Eigen::MatrixXd G(static_cast<Eigen::Index>(kBlock) * n, P0), gq, gqd, gqdd;
  const Workspace data(*this);
  for (int k0 = 0; k0 < K; k0 += kBlock) {
    const int b = std::min(kBlock, K - k0);
    auto Gb = G.topRows(static_cast<Eigen::Index>(b) * n);
    Gb.setZero();
    for (int k = 0; k < b; ++k)
      for (int i = 0; i < m; ++i)
        Gb.row(static_cast<Eigen::Index>(k) * n + sel_[static_cast<std::size_t>(i)]) =
            dW.row(static_cast<Eigen::Index>(k0 + k) * m + i).head(P0);
    exid::actuatorRegressorVjps(R, *data, cols_, s.q.middleRows(k0, b), s.qd.middleRows(k0, b),
                                s.qdd.middleRows(k0, b), Gb, &gq, &gqd, &gqdd);
    for (int k = 0; k < b; ++k)
      for (int i = 0; i < m && P > P0; ++i) {  // the extra columns' derivatives in qdm_j
        const int j = sel_[static_cast<std::size_t>(i)];
        gqd(k, j) += extraColumnsVjp(s.qd(k0 + k, j), f, j,
                                     dW.row(static_cast<Eigen::Index>(k0 + k) * m + i)
                                         .segment(P0 + extraPerJoint() * j, extraPerJoint()));
      }
    grad->q.middleRows(k0, b) = gq;
    grad->qd.middleRows(k0, b) = gqd;
    grad->qdd.middleRows(k0, b) = gqdd;
  }
}

// sum_e g_e d(column e of drive j)/d qdm_j (sign has derivative 0; tanh and Stribeck not).
double DifferentialModel::extraColumnsVjp(double v, const Friction& f, int j,
                                          const Eigen::Ref<const Eigen::RowVectorXd>& g) const {
  const auto u = static_cast<std::size_t>(j);
  return frictionColumns().velocityVjp(v, f.eps[u], f.vs[u], g.data());
}

}  // namespace exid::differential
