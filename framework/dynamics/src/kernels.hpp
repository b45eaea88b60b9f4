// exid — the hot kernels of the rigid-body algorithms (forward pass, RNEA, torque and energy
// regressors and their vector-Jacobian products), written once and compiled once per instruction
// set: kernels_portable.cpp (the build's baseline, x86-64: SSE2) and kernels_avx2.cpp (AVX2 +
// FMA). isa.cpp chooses one table of entry points at run time (docs/dynamics.md §6).
//
// Each including source defines EXID_KERNEL_NS (the namespace of its copy) and EXID_KERNEL (the
// attributes of the entry points) first, and in that namespace
//   void sinCos(int n, const double* q, double* s, double* c)   // s_j = sin q_j, c_j = cos q_j
// (every joint's, before the forward pass's recursion). Everything here has internal linkage (an
// anonymous namespace inside EXID_KERNEL_NS): no two sources share a symbol of it. The AVX2 copy is
// compiled with EXID_KERNEL = flatten, so that the inline helpers it calls (rigid_body.hpp,
// Eigen) are inlined into it instead of being emitted as weak symbols that the linker could merge
// with the baseline copies of the other sources (ctest dynamics.isa_symbols checks the object
// with nm).
//
// Not a public header; included by the kernels_*.cpp alone.
#pragma once

#include <cmath>

#include "exid/dynamics.hpp"
#include "kernel_table.hpp"
#include "rigid_body.hpp"

#if !defined(EXID_KERNEL_NS) || !defined(EXID_KERNEL)
#error "define EXID_KERNEL_NS and EXID_KERNEL before including kernels.hpp"
#endif

namespace exid::detail::EXID_KERNEL_NS {
namespace {

// Forward pass: poses (R, p), velocities, accelerations (with gravity if `gravity`), body
// kinematics.
inline void forwardPassImpl(const RobotModel& model, DynamicsData& d, const double* q,
                            const double* qd, const double* qdd, Level level, bool gravity) {
  const int n = d.n;
  const SV a0(V3::Zero(), gravity ? V3(-model.gravity) : V3::Zero());
  sinCos(n, q, d.sq.data(), d.cq.data());
  for (int j = 0; j < n; ++j) {
    const JointC& c = d.J[static_cast<size_t>(j)];
    M3& R = d.R[static_cast<size_t>(j)];
    V3& p = d.p[static_cast<size_t>(j)];
    if (c.revolute) {
      const double cq = d.cq[static_cast<size_t>(j)], sq = d.sq[static_cast<size_t>(j)];
      M3 M;
      M.col(0) = c.Rpre.col(0) * cq + c.Rpre.col(1) * sq;
      M.col(1) = c.Rpre.col(1) * cq - c.Rpre.col(0) * sq;
      M.col(2) = c.Rpre.col(2);
      if (c.post_R_id)
        R = M;
      else
        R.noalias() = M * c.Rpost;
      if (c.post_p_zero)
        p = c.ppre;
      else
        p = c.ppre + M * c.ppost;
    } else {
      R = c.Rfix;
      p = c.pfix + c.Rpre.col(2) * q[j];
    }
    if (level == Level::Position) continue;
    const int par = c.parent;
    SV& v = d.v[static_cast<size_t>(j)];
    SV& xv = d.xv[static_cast<size_t>(j)];
    if (par >= 0)
      xv = xMotion(R, p, d.v[static_cast<size_t>(par)]);
    else
      xv.setZero();
    const SV u = c.S * qd[j];
    v = xv + u;
    Kin& k = d.kin[static_cast<size_t>(j)];
    k.w = v.w;
    if (level == Level::Velocity) continue;
    SV& xa = d.xa[static_cast<size_t>(j)];
    xa = xMotion(R, p, par >= 0 ? d.a[static_cast<size_t>(par)] : a0);
    SV& a = d.a[static_cast<size_t>(j)];
    a = xa + c.S * qdd[j] + crm(v, u);
    k.wd = a.w;
    k.ao = a.v + v.w.cross(v.v);
  }
}

// Subspaces of all ancestors expressed in every body frame: s[anc_off[j] + k].
inline void ancestorSubspacesImpl(DynamicsData& d) {
  for (int j = 0; j < d.n; ++j) {
    const int par = d.J[static_cast<size_t>(j)].parent;
    if (par < 0) continue;
    const int oj = d.anc_off[static_cast<size_t>(j)], op = d.anc_off[static_cast<size_t>(par)];
    const int cnt = d.anc_off[static_cast<size_t>(j) + 1] - oj;
    const M3& R = d.R[static_cast<size_t>(j)];
    const V3& p = d.p[static_cast<size_t>(j)];
    for (int k = 1; k < cnt; ++k)
      d.s[static_cast<size_t>(oj + k)] = xMotion(R, p, d.s[static_cast<size_t>(op + k - 1)]);
  }
}

// Backward RNEA after forwardPass: the body forces d.f and tau; parameters pi (10 per body, pi
// order) or, when null, the model's.
inline void rneaBackwardImpl(const RobotModel& model, DynamicsData& d, const double* pi,
                             double* tau) {
  for (int j = 0; j < d.n; ++j) {
    const size_t J = static_cast<size_t>(j);
    if (pi)
      d.f[J] = newtonEuler(pi + 10 * j, d.kin[J]);
    else
      d.f[J] = newtonEuler(model.bodies[J].inertia.data(), d.kin[J]);
  }
  for (int j = d.n - 1; j >= 0; --j) {
    const size_t J = static_cast<size_t>(j);
    tau[j] = dot(d.J[J].S, d.f[J]);
    const int par = d.J[J].parent;
    if (par >= 0) d.f[static_cast<size_t>(par)] += xForceT(d.R[J], d.p[J], d.f[J]);
  }
}

inline void clearAdjointsImpl(DynamicsData& d, bool subspaces) {
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
inline void reversePassImpl(DynamicsData& d, const double* qd, Level level, bool subspaces,
                            double* gq, double* gqd, double* gqdd) {
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

// ---- entry points (Kernels in isa.hpp; the arguments are checked by the callers) ----

// (the portable table runs kernels_lanes.hpp's copies of these kernels instead, on one lane: the
// same bits as their lanes; these are the AVX2 + FMA table's)
[[maybe_unused]] EXID_KERNEL void torqueRegressor(const RobotModel& model, DynamicsData& d,
                                                  const double* q, const double* qd,
                                                  const double* qdd, double* Y, long ld) {
  const int n = d.n;
  forwardPassImpl(model, d, q, qd, qdd, Level::Acceleration, true);
  ancestorSubspacesImpl(d);
  for (int j = 0; j < n; ++j) {
    const int oj = d.anc_off[static_cast<size_t>(j)],
              cnt = d.anc_off[static_cast<size_t>(j) + 1] - oj;
    const Kin& k = d.kin[static_cast<size_t>(j)];
    double* Yj = Y + ld * 10 * j;  // column 10 j
    // the rows of the bodies that are not ancestors of j are zero; the ancestors' are written
    for (int t = d.off_off[static_cast<size_t>(j)]; t < d.off_off[static_cast<size_t>(j) + 1]; ++t)
      for (int col = 0; col < 10; ++col) Yj[d.off_idx[static_cast<size_t>(t)] + ld * col] = 0.0;
    for (int t = 0; t < cnt; ++t) {
      const int i = d.anc_idx[static_cast<size_t>(oj + t)];
      pairRow(d.s[static_cast<size_t>(oj + t)], k,
              [&](int col) -> double& { return Yj[i + ld * col]; });
    }
  }
}

[[maybe_unused]] EXID_KERNEL void inverseDynamics(const RobotModel& model, DynamicsData& d,
                                                  const double* q, const double* qd,
                                                  const double* qdd, const double* pi,
                                                  double* tau) {
  forwardPassImpl(model, d, q, qd, qdd, Level::Acceleration, true);
  rneaBackwardImpl(model, d, pi, tau);
}

[[maybe_unused]] EXID_KERNEL void energyRegressor(const RobotModel& model, DynamicsData& d,
                                                  const double* q, const double* qd,
                                                  double* kinetic, double* potential) {
  const int n = d.n;
  forwardPassImpl(model, d, q, qd, nullptr, Level::Velocity, false);
  const V3& g = model.gravity;
  for (int j = 0; j < n; ++j) {
    const size_t J = static_cast<size_t>(j);
    const V3& w = d.v[J].w;
    const V3& vl = d.v[J].v;
    double* K = kinetic + 10 * j;
    K[0] = 0.5 * w[0] * w[0];
    K[1] = w[0] * w[1];
    K[2] = w[0] * w[2];
    K[3] = 0.5 * w[1] * w[1];
    K[4] = w[1] * w[2];
    K[5] = 0.5 * w[2] * w[2];
    const V3 hc = vl.cross(w);
    K[6] = hc[0];
    K[7] = hc[1];
    K[8] = hc[2];
    K[9] = 0.5 * vl.squaredNorm();
    // base pose of body j
    const int par = d.J[J].parent;
    Pose& X = d.X0[J];
    if (par >= 0) {
      const Pose& Xp = d.X0[static_cast<size_t>(par)];
      X.R.noalias() = Xp.R * d.R[J];
      X.p = Xp.p + Xp.R * d.p[J];
    } else {
      X.R = d.R[J];
      X.p = d.p[J];
    }
    double* U = potential + 10 * j;
    for (int c = 0; c < 6; ++c) U[c] = 0.0;
    const V3 gb = -(X.R.transpose() * g);
    U[6] = gb[0];
    U[7] = gb[1];
    U[8] = gb[2];
    U[9] = -g.dot(X.p);
  }
}

[[maybe_unused]] EXID_KERNEL void torqueRegressorVjp(const RobotModel& model, DynamicsData& d,
                                                     const double* q, const double* qd,
                                                     const double* qdd, const double* G, long ld,
                                                     double* gq, double* gqd, double* gqdd) {
  const int n = d.n;
  forwardPassImpl(model, d, q, qd, qdd, Level::Acceleration, true);
  ancestorSubspacesImpl(d);
  clearAdjointsImpl(d, true);
  for (int j = 0; j < n; ++j) {
    const size_t J = static_cast<size_t>(j);
    const int oj = d.anc_off[J], cnt = d.anc_off[J + 1] - oj;
    const Kin& k = d.kin[J];
    for (int t = 0; t < cnt; ++t) {
      const int i = d.anc_idx[static_cast<size_t>(oj + t)];
      double g[10];
      const double* gp = G + i + ld * 10 * j;
      for (int c = 0; c < 10; ++c) g[c] = gp[ld * c];
      const SV& s = d.s[static_cast<size_t>(oj + t)];
      pairKinGrad(s, g, k, d.wb[J], d.wdb[J], d.aob[J]);
      if (t > 0) d.sb[static_cast<size_t>(oj + t)] = newtonEuler(g, k);
    }
  }
  reversePassImpl(d, qd, Level::Acceleration, true, gq, gqd, gqdd);
}

[[maybe_unused]] EXID_KERNEL void energyRegressorVjp(const RobotModel& model, DynamicsData& d,
                                                     const double* q, const double* qd,
                                                     const double* Gk, const double* Gu, double* gq,
                                                     double* gqd) {
  const int n = d.n;
  // Kinetic part: reverse mode through the velocity recursion.
  forwardPassImpl(model, d, q, qd, nullptr, Level::Velocity, false);
  clearAdjointsImpl(d, false);
  for (int j = 0; j < n; ++j) {
    const size_t J = static_cast<size_t>(j);
    const double* g = Gk + 10 * j;
    const V3 h(g[6], g[7], g[8]);
    const V3& w = d.v[J].w;
    const V3& vl = d.v[J].v;
    d.vb[J].w = symMul(g, w) + h.cross(vl);
    d.vb[J].v = w.cross(h) + g[9] * vl;
  }
  double* tq = d.tmp_n.data();
  reversePassImpl(d, qd, Level::Velocity, false, tq, gqd, nullptr);
  if (gq) {
    // Potential part: <Gu, potential> = U(q; pi = Gu), whose gradient is the gravity torque
    // (RNEA at rest with parameters Gu).
    forwardPassImpl(model, d, q, d.zero_n.data(), d.zero_n.data(), Level::Acceleration, true);
    rneaBackwardImpl(model, d, Gu, gq);
    for (int j = 0; j < n; ++j) gq[j] += tq[j];
  }
}

}  // namespace
}  // namespace exid::detail::EXID_KERNEL_NS
