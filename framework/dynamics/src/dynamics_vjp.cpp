// exid — the exact vector-Jacobian products (hand-written reverse mode) of the torque, energy,
// wrench and payload-torque regressors: forward pass, then the adjoints of the body kinematics
// carried back through the recursion. Conventions and the shared recursions: rigid_body.hpp.
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "rigid_body.hpp"

namespace exid {

using namespace detail;

namespace {

void clearAdjoints(DynamicsData& d, bool subspaces) {
  for (int j = 0; j < d.n; ++j) {
    d.vb[static_cast<size_t>(j)].setZero();
    d.ab[static_cast<size_t>(j)].setZero();
    d.wb[static_cast<size_t>(j)].setZero();
    d.wdb[static_cast<size_t>(j)].setZero();
    d.aob[static_cast<size_t>(j)].setZero();
  }
  if (subspaces)
    for (auto& x : d.sb) x.setZero();
}

// Reverse pass: from adjoints of the body kinematics (wb, wdb, aob), of v / a (vb, ab) and of the
// ancestor subspaces (sb) to gradients in q, qd, qdd. Outputs are overwritten (may be null).
void reversePass(DynamicsData& d, const double* qd, Level level, bool subspaces, double* gq,
                 double* gqd, double* gqdd) {
  for (int j = d.n - 1; j >= 0; --j) {
    const size_t J = static_cast<size_t>(j);
    const JointC& c = d.J[J];
    const SV& S = c.S;
    const SV& v = d.v[J];
    SV& vb = d.vb[J];
    SV& ab = d.ab[J];
    double dq = 0.0, dqd = 0.0, dqdd = 0.0;
    if (level == Level::Acceleration) {
      ab.w += d.wdb[J];
      ab.v += d.aob[J];
      vb.w += d.wb[J] + v.v.cross(d.aob[J]);
      vb.v += d.aob[J].cross(v.w);
      dqdd = dot(S, ab);
      const SV u = S * qd[j];
      vb.w += u.w.cross(ab.w) + u.v.cross(ab.v);
      vb.v += u.w.cross(ab.v);
      const SV ub(ab.w.cross(v.w) + ab.v.cross(v.v), ab.v.cross(v.w));
      dqd += dot(S, ub);
      dq -= dotCrm(S, d.xa[J], ab);
    } else {
      vb.w += d.wb[J];
    }
    dqd += dot(S, vb);
    dq -= dotCrm(S, d.xv[J], vb);
    const int par = c.parent;
    const M3& R = d.R[J];
    const V3& p = d.p[J];
    const int oj = d.anc_off[J], cnt = d.anc_off[J + 1] - oj;
    if (subspaces)
      for (int k = 1; k < cnt; ++k)
        dq -= dotCrm(S, d.s[static_cast<size_t>(oj + k)], d.sb[static_cast<size_t>(oj + k)]);
    if (par >= 0) {
      const size_t Pp = static_cast<size_t>(par);
      d.vb[Pp] += xForceT(R, p, vb);
      if (level == Level::Acceleration) d.ab[Pp] += xForceT(R, p, ab);
      if (subspaces) {
        const int op = d.anc_off[Pp];
        for (int k = 1; k < cnt; ++k)
          d.sb[static_cast<size_t>(op + k - 1)] += xForceT(R, p, d.sb[static_cast<size_t>(oj + k)]);
      }
    }
    if (gq) gq[j] = dq;
    if (gqd) gqd[j] = dqd;
    if (gqdd) gqdd[j] = dqdd;
  }
}

// Adjoint of the sensor kinematics (given d.ks adjoints) into the sensor body's v / a adjoints.
void sensorReverse(const RobotModel& model, DynamicsData& d, const V3& wb, const V3& wdb,
                   const V3& aob) {
  const int b = model.sensorBody();
  const SV asb(wdb, aob);
  const SV vsb(wb + d.vs.v.cross(aob), aob.cross(d.vs.w));
  d.vb[static_cast<size_t>(b)] += xForceT(d.Rs, d.ps, vsb);
  d.ab[static_cast<size_t>(b)] += xForceT(d.Rs, d.ps, asb);
}

void outputs(Eigen::VectorXd* out, int n) {
  if (out && out->size() != n) out->resize(n);
}

}  // namespace

void torqueRegressorVjp(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                        const Eigen::MatrixXd& G, Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd,
                        Eigen::VectorXd* d_qdd) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, &qdd, "torqueRegressorVjp");
  check(G.rows() == n && G.cols() == 10 * n, "torqueRegressorVjp: G must be n x 10n");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  ancestorSubspaces(d);
  clearAdjoints(d, true);
  const Eigen::Index ld = G.outerStride();
  for (int j = 0; j < n; ++j) {
    const size_t J = static_cast<size_t>(j);
    const int oj = d.anc_off[J], cnt = d.anc_off[J + 1] - oj;
    const Kin& k = d.kin[J];
    for (int t = 0; t < cnt; ++t) {
      const int i = d.anc_idx[static_cast<size_t>(oj + t)];
      double g[10];
      const double* gp = G.data() + i + ld * 10 * j;
      for (int c = 0; c < 10; ++c) g[c] = gp[ld * c];
      const SV& s = d.s[static_cast<size_t>(oj + t)];
      pairKinGrad(s, g, k, d.wb[J], d.wdb[J], d.aob[J]);
      if (t > 0) d.sb[static_cast<size_t>(oj + t)] = newtonEuler(g, k);
    }
  }
  outputs(d_q, n);
  outputs(d_qd, n);
  outputs(d_qdd, n);
  reversePass(d, qd.data(), Level::Acceleration, true, d_q ? d_q->data() : nullptr,
              d_qd ? d_qd->data() : nullptr, d_qdd ? d_qdd->data() : nullptr);
}

void energyRegressorVjp(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& qd, const Eigen::RowVectorXd& Gk,
                        const Eigen::RowVectorXd& Gu, Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, nullptr, "energyRegressorVjp");
  check(Gk.size() == 10 * n && Gu.size() == 10 * n,
        "energyRegressorVjp: Gk and Gu must have 10n entries");
  // Kinetic part: reverse mode through the velocity recursion.
  forwardPass(model, d, q.data(), qd.data(), nullptr, Level::Velocity, false);
  clearAdjoints(d, false);
  for (int j = 0; j < n; ++j) {
    const size_t J = static_cast<size_t>(j);
    const double* g = Gk.data() + 10 * j;
    const V3 h(g[6], g[7], g[8]);
    const V3& w = d.v[J].w;
    const V3& vl = d.v[J].v;
    d.vb[J].w = symMul(g, w) + h.cross(vl);
    d.vb[J].v = w.cross(h) + g[9] * vl;
  }
  outputs(d_q, n);
  outputs(d_qd, n);
  double* gq = d.tmp_n.data();
  reversePass(d, qd.data(), Level::Velocity, false, gq, d_qd ? d_qd->data() : nullptr, nullptr);
  if (d_q) {
    // Potential part: <Gu, potential> = U(q; pi = Gu), whose gradient is the gravity torque
    // (RNEA at rest with parameters Gu).
    forwardPass(model, d, q.data(), d.zero_n.data(), d.zero_n.data(), Level::Acceleration, true);
    rneaBackward(model, d, Gu.data(), d_q->data());
    *d_q += d.tmp_n;
  }
}

void wrenchRegressorVjp(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                        const Eigen::Matrix<double, 6, 10>& G, Eigen::VectorXd* d_q,
                        Eigen::VectorXd* d_qd, Eigen::VectorXd* d_qdd) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, &qdd, "wrenchRegressorVjp");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  sensorKinematics(model, d, false);
  clearAdjoints(d, false);
  V3 wb = V3::Zero(), wdb = V3::Zero(), aob = V3::Zero();
  for (int c = 0; c < 10; ++c) {
    double g[10] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    g[kPhiToPi[c]] = 1.0;
    const SV s(G.block<3, 1>(3, c), G.block<3, 1>(0, c));
    pairKinGrad(s, g, d.ks, wb, wdb, aob);
  }
  sensorReverse(model, d, wb, wdb, aob);
  outputs(d_q, n);
  outputs(d_qd, n);
  outputs(d_qdd, n);
  reversePass(d, qd.data(), Level::Acceleration, false, d_q ? d_q->data() : nullptr,
              d_qd ? d_qd->data() : nullptr, d_qdd ? d_qdd->data() : nullptr);
}

void payloadTorqueRegressorVjp(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                               const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                               const Eigen::MatrixXd& G, Eigen::VectorXd* d_q,
                               Eigen::VectorXd* d_qd, Eigen::VectorXd* d_qdd) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, &qdd, "payloadTorqueRegressorVjp");
  check(G.rows() == n && G.cols() == 10, "payloadTorqueRegressorVjp: G must be n x 10");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  ancestorSubspaces(d);
  sensorKinematics(model, d, true);
  clearAdjoints(d, true);
  const int b = model.sensorBody();
  const int ob = d.anc_off[static_cast<size_t>(b)],
            cnt = d.anc_off[static_cast<size_t>(b) + 1] - ob;
  V3 wb = V3::Zero(), wdb = V3::Zero(), aob = V3::Zero();
  for (int t = 0; t < cnt; ++t) {
    const int i = d.anc_idx[static_cast<size_t>(ob + t)];
    double g[10];
    for (int c = 0; c < 10; ++c) g[kPhiToPi[c]] = G(i, c);
    const SV& s = d.ss[static_cast<size_t>(t)];
    pairKinGrad(s, g, d.ks, wb, wdb, aob);
    if (t > 0) d.sb[static_cast<size_t>(ob + t)] += xForceT(d.Rs, d.ps, newtonEuler(g, d.ks));
  }
  sensorReverse(model, d, wb, wdb, aob);
  outputs(d_q, n);
  outputs(d_qd, n);
  outputs(d_qdd, n);
  reversePass(d, qd.data(), Level::Acceleration, true, d_q ? d_q->data() : nullptr,
              d_qd ? d_qd->data() : nullptr, d_qdd ? d_qdd->data() : nullptr);
}

}  // namespace exid
