// exid — the derivatives of inverse dynamics (inverseDynamicsDerivatives): the RNEA with forward
// tangents in q, qd and qdd, body by body. Conventions and the shared recursions: rigid_body.hpp.
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "rigid_body.hpp"

namespace exid {

using namespace detail;

namespace {
// Tangents (inverseDynamicsDerivatives), column 3i: dq_i, 3i+1: dqd_i, 3i+2: dqdd_i.
// Forward, body j: its velocity and acceleration (d.tvw, d.tvv, d.taw, d.tav) from its
// parent's, and its origin's acceleration d.tao; they only involve its ancestors (indices <= j):
// columns < 3(j+1).
void bodyMotionTangents(DynamicsData& d, int j, double qd_j) {
  const int D = 3 * d.n;
  const size_t J = static_cast<size_t>(j);
  const JointC& c = d.J[J];
  const SV& S = c.S;
  const int par = c.parent;
  const int wj = 3 * (j + 1);
  auto Vw = d.tvw[J].leftCols(wj);
  auto Vv = d.tvv[J].leftCols(wj);
  auto Aw = d.taw[J].leftCols(wj);
  auto Av = d.tav[J].leftCols(wj);
  const M3 Rt = d.R[J].transpose();
  const M3 P = skew(d.p[J]);
  if (par >= 0) {
    const size_t Pp = static_cast<size_t>(par);
    const int wp = 3 * (par + 1);
    // motion transform {R^T w, R^T (v - p x w)}, linear in the parent's tangents
    Vw.leftCols(wp).noalias() = Rt * d.tvw[Pp].leftCols(wp);
    Vv.leftCols(wp).noalias() = Rt * (d.tvv[Pp].leftCols(wp) - P * d.tvw[Pp].leftCols(wp));
    Aw.leftCols(wp).noalias() = Rt * d.taw[Pp].leftCols(wp);
    Av.leftCols(wp).noalias() = Rt * (d.tav[Pp].leftCols(wp) - P * d.taw[Pp].leftCols(wp));
    Vw.rightCols(wj - wp).setZero();
    Vv.rightCols(wj - wp).setZero();
    Aw.rightCols(wj - wp).setZero();
    Av.rightCols(wj - wp).setZero();
  } else {
    Vw.setZero();
    Vv.setZero();
    Aw.setZero();
    Av.setZero();
  }
  const int cq = 3 * j, cqd = cq + 1, cqdd = cq + 2;
  // d(X m)/dq_j = (X m) x S
  const SV dxv = crm(d.xv[J], S), dxa = crm(d.xa[J], S);
  Vw.col(cq) += dxv.w;
  Vv.col(cq) += dxv.v;
  Aw.col(cq) += dxa.w;
  Av.col(cq) += dxa.v;
  Vw.col(cqd) += S.w;
  Vv.col(cqd) += S.v;
  // a = xa + S qdd + v x u, u = S qd: d(v x u) = dv x u + v x du
  const SV& v = d.v[J];
  const SV u = S * qd_j;
  const M3 Uw = skew(u.w), Uv = skew(u.v);
  Aw.noalias() -= Uw * Vw;
  Av.noalias() -= Uv * Vw;
  Av.noalias() -= Uw * Vv;
  const SV vS = crm(v, S);
  Aw.col(cqd) += vS.w;
  Av.col(cqd) += vS.v;
  Aw.col(cqdd) += S.w;
  Av.col(cqdd) += S.v;
  // body kinematics: w = v.w, wd = a.w, ao = a.v + v.w x v.v
  const M3 Wx = skew(v.w);
  d.tao.resize(3, D);
  auto Ao = d.tao.leftCols(wj);
  Ao = Av;
  Ao.noalias() -= skew(v.v) * Vw;
  Ao.noalias() += Wx * Vv;
}

// Forward, body j: the tangent of its Newton-Euler wrench (d.tfw, d.tfv), from its motion's.
void bodyWrenchTangents(const RobotModel& model, DynamicsData& d, int j,
                        const Eigen::VectorXd* pi) {
  const int D = 3 * d.n;
  const size_t J = static_cast<size_t>(j);
  const int wj = 3 * (j + 1);
  const auto Vw = d.tvw[J].leftCols(wj);
  const auto Aw = d.taw[J].leftCols(wj);
  const auto Ao = d.tao.leftCols(wj);
  const SV& v = d.v[J];
  const M3 Wx = skew(v.w);
  const double* g = pi ? pi->data() + 10 * j : model.bodies[J].inertia.data();
  M3 I;
  I << g[0], g[1], g[2], g[1], g[3], g[4], g[2], g[4], g[5];
  const V3 h(g[6], g[7], g[8]);
  const double m = g[9];
  const M3 H = skew(h);
  const M3 dfw_dw = Wx * I - skew(I * v.w);
  const M3 dfv_dw = -(skew(v.w.cross(h)) + Wx * H);
  auto Fw = d.tfw[J].leftCols(wj);
  auto Fv = d.tfv[J].leftCols(wj);
  Fw.noalias() = I * Aw;
  Fw.noalias() += dfw_dw * Vw;
  Fw.noalias() += H * Ao;
  Fv.noalias() = m * Ao;
  Fv.noalias() -= H * Aw;
  Fv.noalias() += dfv_dw * Vw;
  d.tfw[J].rightCols(D - wj).setZero();
  d.tfv[J].rightCols(D - wj).setZero();
}

// Backward: each joint's torque tangent (d.tdtau) from the force it transmits, which is then
// added to its parent's.
void torqueTangents(DynamicsData& d) {
  const int n = d.n;
  Eigen::MatrixXd& dtau = d.tdtau;
  dtau.resize(n, 3 * n);
  for (int j = n - 1; j >= 0; --j) {
    const size_t J = static_cast<size_t>(j);
    const SV& S = d.J[J].S;
    dtau.row(j).noalias() = S.w.transpose() * d.tfw[J];
    dtau.row(j).noalias() += S.v.transpose() * d.tfv[J];
    const int par = d.J[J].parent;
    if (par < 0) continue;
    const size_t Pp = static_cast<size_t>(par);
    const M3& R = d.R[J];
    const M3 PR = skew(d.p[J]) * R;
    // force transform {R f.w + p x R f.v, R f.v}; d(X^T F)/dq_j = X^T (S x* F)
    d.tfw[Pp].noalias() += R * d.tfw[J];
    d.tfw[Pp].noalias() += PR * d.tfv[J];
    d.tfv[Pp].noalias() += R * d.tfv[J];
    const SV& F = d.f[J];
    const SV crf(S.w.cross(F.w) + S.v.cross(F.v), S.w.cross(F.v));
    const SV x = xForceT(R, d.p[J], crf);
    d.tfw[Pp].col(3 * j) += x.w;
    d.tfv[Pp].col(3 * j) += x.v;
  }
}
}  // namespace

void inverseDynamicsDerivatives(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                                const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                const Eigen::VectorXd* pi, Eigen::VectorXd* tau,
                                Eigen::MatrixXd* dtau_dq, Eigen::MatrixXd* dtau_dqd,
                                Eigen::MatrixXd* dtau_dqdd) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, &qdd, "inverseDynamicsDerivatives");
  check(tau != nullptr, "inverseDynamicsDerivatives: tau must be given");
  if (pi) checkSize(*pi, 10 * n, "pi", "inverseDynamicsDerivatives");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  tau->resize(n);
  // d.f: the force each joint transmits (the body's own Newton-Euler wrench plus its subtree's)
  rneaBackward(model, d, pi ? pi->data() : nullptr, tau->data());
  const int D = 3 * n;  // tangent directions: column 3i dq_i, 3i+1 dqd_i, 3i+2 dqdd_i
  const size_t N = static_cast<size_t>(n);
  for (auto* t : {&d.tvw, &d.tvv, &d.taw, &d.tav, &d.tfw, &d.tfv})
    if (t->size() != N || (n > 0 && (*t)[0].cols() != D))
      t->assign(N, Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, D));
  for (int j = 0; j < n; ++j) {
    bodyMotionTangents(d, j, qd[j]);
    bodyWrenchTangents(model, d, j, pi);
  }
  torqueTangents(d);
  const Eigen::MatrixXd& dtau = d.tdtau;
  for (int r = 0; r < 3; ++r) {
    Eigen::MatrixXd* out = r == 0 ? dtau_dq : (r == 1 ? dtau_dqd : dtau_dqdd);
    if (!out) continue;
    out->resize(n, n);
    for (int i = 0; i < n; ++i) out->col(i) = dtau.col(3 * i + r);
  }
}

}  // namespace exid
