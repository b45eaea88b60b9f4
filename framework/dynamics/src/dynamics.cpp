// exid — rigid-body algorithms: torque / energy / wrench / payload-torque regressors, their exact
// vector-Jacobian products (hand-written reverse mode), RNEA, CRBA, forward dynamics.
//
// Internal conventions (see docs/dynamics.md):
//  * every quantity of body j is expressed in body frame j;
//  * spatial motion vectors are {w, v} = {angular, linear velocity of the frame origin}
//    (Featherstone), spatial forces are {n, f} = {moment about the frame origin, force};
//  * each joint axis is folded into pre/post (pre' = pre*Q, post' = Q^T*post with Q z = axis), so
//    every joint rotates about / translates along the z axis of its joint frame; the motion
//    subspace S_j of joint j is then a constant 6-vector in body frame j;
//  * gravity enters as the base acceleration a_0 = {0, -g}.
#include "exid/dynamics.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "internal.hpp"

namespace exid {

namespace {

using V3 = Eigen::Vector3d;
using M3 = Eigen::Matrix3d;
using Vec10 = Eigen::Matrix<double, 10, 1>;

struct SV {  // spatial vector {angular, linear}
  V3 w = V3::Zero(), v = V3::Zero();
  SV() = default;
  SV(const V3& a, const V3& b) : w(a), v(b) {}
  void setZero() {
    w.setZero();
    v.setZero();
  }
};
inline SV operator+(const SV& a, const SV& b) { return {a.w + b.w, a.v + b.v}; }
inline SV operator*(const SV& a, double s) { return {a.w * s, a.v * s}; }
inline SV& operator+=(SV& a, const SV& b) {
  a.w += b.w;
  a.v += b.v;
  return a;
}
inline double dot(const SV& a, const SV& b) { return a.w.dot(b.w) + a.v.dot(b.v); }
// motion cross product a x b
inline SV crm(const SV& a, const SV& b) {
  return {a.w.cross(b.w), a.w.cross(b.v) + a.v.cross(b.w)};
}
// c . (a x b) for motion cross
inline double dotCrm(const SV& a, const SV& b, const SV& c) {
  return c.w.dot(a.w.cross(b.w)) + c.v.dot(a.w.cross(b.v) + a.v.cross(b.w));
}
// motion transform parent -> child, child pose (R, p) in parent
inline SV xMotion(const M3& R, const V3& p, const SV& m) {
  return {R.transpose() * m.w, R.transpose() * (m.v + m.w.cross(p))};
}
// its transpose: force transform child -> parent
inline SV xForceT(const M3& R, const V3& p, const SV& f) {
  const V3 fv = R * f.v;
  return {R * f.w + p.cross(fv), fv};
}

// Symmetric 3x3 stored as XX XY XZ YY YZ ZZ, times x.
template <class P>
inline V3 symMul(const P& g, const V3& x) {
  return {g[0] * x[0] + g[1] * x[1] + g[2] * x[2], g[1] * x[0] + g[3] * x[1] + g[4] * x[2],
          g[2] * x[0] + g[4] * x[1] + g[5] * x[2]};
}

struct Kin {
  V3 w, wd, ao;  // angular velocity, angular acceleration, classical acceleration of the origin
                 // (incl. -g)
};

// Newton-Euler wrench {n, f} of a body with parameters g (pi order) and kinematics k.
template <class P>
inline SV newtonEuler(const P& g, const Kin& k) {
  const V3 h(g[6], g[7], g[8]);
  const double m = g[9];
  const V3 wh = k.w.cross(h);
  return {symMul(g, k.wd) + k.w.cross(symMul(g, k.w)) + h.cross(k.ao),
          m * k.ao + k.wd.cross(h) + k.w.cross(wh)};
}

// Regressor row of one (subspace s, body kinematics k) pair: out[c] = s^T K(k) e_c, c in pi order.
template <class Out>
inline void pairRow(const SV& s, const Kin& k, Out&& out) {
  const V3& sw = s.w;
  const V3& sv = s.v;
  const V3 x = sw.cross(k.w);
  const V3& a = k.wd;
  const V3& w = k.w;
  out(0) = sw[0] * a[0] + x[0] * w[0];
  out(1) = sw[0] * a[1] + sw[1] * a[0] + x[0] * w[1] + x[1] * w[0];
  out(2) = sw[0] * a[2] + sw[2] * a[0] + x[0] * w[2] + x[2] * w[0];
  out(3) = sw[1] * a[1] + x[1] * w[1];
  out(4) = sw[1] * a[2] + sw[2] * a[1] + x[1] * w[2] + x[2] * w[1];
  out(5) = sw[2] * a[2] + x[2] * w[2];
  const V3 hc = k.ao.cross(sw) + sv.cross(a) + sv.cross(w).cross(w);
  out(6) = hc[0];
  out(7) = hc[1];
  out(8) = hc[2];
  out(9) = sv.dot(k.ao);
}

// Adds the gradient of s^T NE(g, k) with respect to (w, wd, ao).
template <class P>
inline void pairKinGrad(const SV& s, const P& g, const Kin& k, V3& wb, V3& wdb, V3& aob) {
  const V3 h(g[6], g[7], g[8]);
  const double m = g[9];
  const V3& sw = s.w;
  const V3& sv = s.v;
  wdb += symMul(g, sw) + h.cross(sv);
  aob += sw.cross(h) + m * sv;
  wb += symMul(g, k.w).cross(sw) + symMul(g, sw.cross(k.w)) + h.cross(sv.cross(k.w)) +
        k.w.cross(h).cross(sv);
}

struct JointC {
  M3 Rpre, Rpost, Rfix;  // Rfix = Rpre*Rpost (prismatic)
  V3 ppre, ppost, pfix;  // pfix = ppre + Rpre*ppost (prismatic)
  bool revolute = true, post_R_id = false, post_p_zero = false;
  int parent = -1;
  SV S;
};

constexpr int kPhiToPi[10] = {9, 6, 7, 8, 0, 1, 2, 3, 4, 5};

}  // namespace

struct DynamicsData {
  const RobotModel* key = nullptr;
  int n = 0;
  std::vector<JointC> J;
  std::vector<int> anc_off, anc_idx;  // ancestors of j (j itself first) at anc_off[j]..anc_off[j+1]
  std::vector<int> off_off, off_idx;  // the other bodies (not ancestors of j), likewise
  // forward quantities (body frames)
  std::vector<M3> R;
  std::vector<V3> p;
  std::vector<SV> v, a, xv, xa, s;
  std::vector<Kin> kin;
  // adjoints
  std::vector<SV> vb, ab, sb;
  std::vector<V3> wb, wdb, aob;
  // RNEA / CRBA
  std::vector<SV> f;
  // the composite rigid bodies of the CRBA: rotational inertia about the frame's origin, first
  // moment of mass, mass (a body's spatial inertia [I [h]x; [h]x^T m 1])
  std::vector<M3> cI;
  std::vector<V3> ch;
  std::vector<double> cm;
  std::vector<Pose> X0;
  // sensor frame
  M3 Rs;
  V3 ps;
  SV vs, as;
  Kin ks;
  std::vector<SV> ss, ssb;
  Eigen::VectorXd zero_n, tmp_n;
  // forward tangents of v, a and the body forces (3 x 3n each, columns dq_i dqd_i dqdd_i)
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> tvw, tvv, taw, tav, tfw, tfv;
  Eigen::Matrix<double, 3, Eigen::Dynamic> tao;  // tangent of the origin's acceleration
  Eigen::MatrixXd tdtau;                         // n x 3n
  Eigen::MatrixXd scratch_m[4];
  Eigen::VectorXd scratch_v[4];
};

namespace detail {
Eigen::MatrixXd& scratchMatrix(DynamicsData& d, int slot) { return d.scratch_m[slot & 3]; }
Eigen::VectorXd& scratchVector(DynamicsData& d, int slot) { return d.scratch_v[slot & 3]; }
}  // namespace detail

void DynamicsDataDeleter::operator()(DynamicsData* d) const { delete d; }

namespace {

// Per body j, the bodies that are not its ancestors (the rows of j's regressor columns that
// stay zero), in the layout of the ancestors' lists.
void nonAncestors(int n, const std::vector<int>& anc_off, const std::vector<int>& anc_idx,
                  std::vector<int>* off, std::vector<int>* idx) {
  off->assign(static_cast<size_t>(n + 1), 0);
  idx->clear();
  for (int j = 0; j < n; ++j) {
    (*off)[static_cast<size_t>(j)] = static_cast<int>(idx->size());
    for (int i = 0; i < n; ++i) {
      bool ancestor = false;
      for (int t = anc_off[static_cast<size_t>(j)]; t < anc_off[static_cast<size_t>(j) + 1]; ++t)
        ancestor = ancestor || anc_idx[static_cast<size_t>(t)] == i;
      if (!ancestor) idx->push_back(i);
    }
  }
  (*off)[static_cast<size_t>(n)] = static_cast<int>(idx->size());
}

void setup(const RobotModel& model, DynamicsData& d) {
  const int n = model.dof();
  d.key = &model;
  d.n = n;
  d.J.assign(static_cast<size_t>(n), JointC{});
  d.anc_off.assign(static_cast<size_t>(n + 1), 0);
  d.anc_idx.clear();
  for (int j = 0; j < n; ++j) {
    const Body& b = model.bodies[static_cast<size_t>(j)];
    check(b.parent >= -1 && b.parent < j, "dynamics: body " + std::to_string(j + 1) +
                                              " has parent " + std::to_string(b.parent) +
                                              " (expected -1 <= parent < own index)");
    JointC& c = d.J[static_cast<size_t>(j)];
    c.parent = b.parent;
    c.revolute = b.type == JointType::Revolute;
    const V3 u = b.axis.normalized();
    M3 Q = M3::Identity();
    if ((u - V3::UnitZ()).norm() > 1e-15) {
      if ((u + V3::UnitZ()).norm() < 1e-12)
        Q = Eigen::AngleAxisd(M_PI, V3::UnitX()).toRotationMatrix();
      else
        Q = Eigen::Quaterniond::FromTwoVectors(V3::UnitZ(), u).toRotationMatrix();
    }
    c.Rpre = b.pre.R * Q;
    c.ppre = b.pre.p;
    c.Rpost = Q.transpose() * b.post.R;
    c.ppost = Q.transpose() * b.post.p;
    c.post_R_id = (c.Rpost - M3::Identity()).cwiseAbs().maxCoeff() == 0.0;
    c.post_p_zero = c.ppost.cwiseAbs().maxCoeff() == 0.0;
    c.Rfix = c.Rpre * c.Rpost;
    c.pfix = c.ppre + c.Rpre * c.ppost;
    if (c.revolute)
      c.S = SV(c.Rpost.transpose() * V3::UnitZ(), c.Rpost.transpose() * V3::UnitZ().cross(c.ppost));
    else
      c.S = SV(V3::Zero(), c.Rpost.transpose() * V3::UnitZ());
    d.anc_off[static_cast<size_t>(j)] = static_cast<int>(d.anc_idx.size());
    for (int i = j; i >= 0; i = model.bodies[static_cast<size_t>(i)].parent) d.anc_idx.push_back(i);
  }
  d.anc_off[static_cast<size_t>(n)] = static_cast<int>(d.anc_idx.size());
  nonAncestors(n, d.anc_off, d.anc_idx, &d.off_off, &d.off_idx);
  const size_t N = static_cast<size_t>(n), P = d.anc_idx.size();
  d.R.assign(N, M3::Identity());
  d.p.assign(N, V3::Zero());
  d.v.assign(N, SV());
  d.a.assign(N, SV());
  d.xv.assign(N, SV());
  d.xa.assign(N, SV());
  d.kin.assign(N, Kin{});
  d.vb.assign(N, SV());
  d.ab.assign(N, SV());
  d.wb.assign(N, V3::Zero());
  d.wdb.assign(N, V3::Zero());
  d.aob.assign(N, V3::Zero());
  d.f.assign(N, SV());
  d.cI.assign(N, M3::Zero());
  d.ch.assign(N, V3::Zero());
  d.cm.assign(N, 0.0);
  d.X0.assign(N, Pose{});
  d.s.assign(P, SV());
  d.sb.assign(P, SV());
  d.ss.assign(N, SV());
  d.ssb.assign(N, SV());
  d.zero_n = Eigen::VectorXd::Zero(n);
  d.tmp_n = Eigen::VectorXd::Zero(n);
  for (int j = 0; j < n; ++j)
    d.s[static_cast<size_t>(d.anc_off[static_cast<size_t>(j)])] = d.J[static_cast<size_t>(j)].S;
}

inline void prepare(const RobotModel& model, DynamicsData& d) {
  if (d.key != &model || d.n != model.dof()) setup(model, d);
}

void checkSize(const Eigen::VectorXd& x, int n, const char* what, const char* fn) {
  if (x.size() != n)
    throw Error(std::string(fn) + ": " + what + " has " + std::to_string(x.size()) +
                " entries (expected " + std::to_string(n) + ")");
}

void checkState(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd* qd,
                const Eigen::VectorXd* qdd, const char* fn) {
  const int n = m.dof();
  checkSize(q, n, "q", fn);
  if (qd) checkSize(*qd, n, "qd", fn);
  if (qdd) checkSize(*qdd, n, "qdd", fn);
}

enum class Level { Position, Velocity, Acceleration };

// Forward pass: poses (R, p), velocities, accelerations (with gravity if `gravity`), body
// kinematics.
void forwardPass(const RobotModel& model, DynamicsData& d, const double* q, const double* qd,
                 const double* qdd, Level level, bool gravity) {
  const int n = d.n;
  const SV a0(V3::Zero(), gravity ? V3(-model.gravity) : V3::Zero());
  for (int j = 0; j < n; ++j) {
    const JointC& c = d.J[static_cast<size_t>(j)];
    M3& R = d.R[static_cast<size_t>(j)];
    V3& p = d.p[static_cast<size_t>(j)];
    if (c.revolute) {
      const double cq = std::cos(q[j]), sq = std::sin(q[j]);
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
void ancestorSubspaces(DynamicsData& d) {
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

// Sensor frame kinematics from the sensor body's (after forwardPass at Acceleration level).
void sensorKinematics(const RobotModel& model, DynamicsData& d, bool subspaces) {
  const int b = model.sensorBody();
  d.Rs = model.sensor_pose.R;
  d.ps = model.sensor_pose.p;
  d.vs = xMotion(d.Rs, d.ps, d.v[static_cast<size_t>(b)]);
  d.as = xMotion(d.Rs, d.ps, d.a[static_cast<size_t>(b)]);
  d.ks.w = d.vs.w;
  d.ks.wd = d.as.w;
  d.ks.ao = d.as.v + d.vs.w.cross(d.vs.v);
  if (subspaces) {
    const int ob = d.anc_off[static_cast<size_t>(b)],
              cnt = d.anc_off[static_cast<size_t>(b) + 1] - ob;
    for (int k = 0; k < cnt; ++k)
      d.ss[static_cast<size_t>(k)] = xMotion(d.Rs, d.ps, d.s[static_cast<size_t>(ob + k)]);
  }
}

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

void rneaBackward(const RobotModel& model, DynamicsData& d, const double* pi, double* tau) {
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

}  // namespace

DynamicsDataPtr makeDynamicsData(const RobotModel& model) {
  DynamicsDataPtr d(new DynamicsData);
  setup(model, *d);
  return d;
}

void torqueRegressor(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                     Eigen::Ref<Eigen::MatrixXd> Y) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, &qdd, "torqueRegressor");
  check(Y.rows() == n && Y.cols() == 10 * n, "torqueRegressor: Y must be n x 10n");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  ancestorSubspaces(d);
  for (int j = 0; j < n; ++j) {
    const int oj = d.anc_off[static_cast<size_t>(j)],
              cnt = d.anc_off[static_cast<size_t>(j) + 1] - oj;
    const Kin& k = d.kin[static_cast<size_t>(j)];
    // the rows of the bodies that are not ancestors of j are zero; the ancestors' are written
    for (int t = d.off_off[static_cast<size_t>(j)]; t < d.off_off[static_cast<size_t>(j) + 1]; ++t)
      for (int col = 0; col < 10; ++col) Y(d.off_idx[static_cast<size_t>(t)], 10 * j + col) = 0.0;
    for (int t = 0; t < cnt; ++t) {
      const int i = d.anc_idx[static_cast<size_t>(oj + t)];
      pairRow(d.s[static_cast<size_t>(oj + t)], k,
              [&](int col) -> double& { return Y(i, 10 * j + col); });
    }
  }
}

void energyRegressor(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& qd, Eigen::Ref<Eigen::RowVectorXd> kinetic,
                     Eigen::Ref<Eigen::RowVectorXd> potential) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, nullptr, "energyRegressor");
  check(kinetic.size() == 10 * n && potential.size() == 10 * n,
        "energyRegressor: outputs must have 10n entries");
  forwardPass(model, d, q.data(), qd.data(), nullptr, Level::Velocity, false);
  const V3& g = model.gravity;
  for (int j = 0; j < n; ++j) {
    const size_t J = static_cast<size_t>(j);
    const V3& w = d.v[J].w;
    const V3& vl = d.v[J].v;
    double* K = kinetic.data() + 10 * j;
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
    double* U = potential.data() + 10 * j;
    for (int c = 0; c < 6; ++c) U[c] = 0.0;
    const V3 gb = -(X.R.transpose() * g);
    U[6] = gb[0];
    U[7] = gb[1];
    U[8] = gb[2];
    U[9] = -g.dot(X.p);
  }
}

void wrenchRegressor(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                     Eigen::Ref<Eigen::Matrix<double, 6, 10>> A) {
  prepare(model, d);
  checkState(model, q, &qd, &qdd, "wrenchRegressor");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  sensorKinematics(model, d, false);
  const Kin& k = d.ks;
  A.setZero();
  A.block<3, 1>(0, 0) = k.ao;
  for (int e = 0; e < 3; ++e) {
    const V3 u = V3::Unit(e);
    A.block<3, 1>(0, 1 + e) = k.wd.cross(u) + k.w.cross(k.w.cross(u));
    A.block<3, 1>(3, 1 + e) = u.cross(k.ao);
  }
  for (int c = 0; c < 6; ++c) {
    double g[6] = {0, 0, 0, 0, 0, 0};
    g[c] = 1.0;
    A.block<3, 1>(3, 4 + c) = symMul(g, k.wd) + k.w.cross(symMul(g, k.w));
  }
}

void payloadTorqueRegressor(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                            const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                            Eigen::Ref<Eigen::MatrixXd> Yp) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, &qdd, "payloadTorqueRegressor");
  check(Yp.rows() == n && Yp.cols() == 10, "payloadTorqueRegressor: Yp must be n x 10");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  ancestorSubspaces(d);
  sensorKinematics(model, d, true);
  Yp.setZero();
  const int b = model.sensorBody();
  const int ob = d.anc_off[static_cast<size_t>(b)],
            cnt = d.anc_off[static_cast<size_t>(b) + 1] - ob;
  for (int t = 0; t < cnt; ++t) {
    const int i = d.anc_idx[static_cast<size_t>(ob + t)];
    Vec10 row;
    pairRow(d.ss[static_cast<size_t>(t)], d.ks, [&](int c) -> double& { return row[c]; });
    for (int c = 0; c < 10; ++c) Yp(i, c) = row[kPhiToPi[c]];
  }
}

Eigen::VectorXd inverseDynamics(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                                const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                const Eigen::VectorXd* pi) {
  prepare(model, d);
  checkState(model, q, &qd, &qdd, "inverseDynamics");
  if (pi) checkSize(*pi, 10 * d.n, "pi", "inverseDynamics");
  forwardPass(model, d, q.data(), qd.data(), qdd.data(), Level::Acceleration, true);
  Eigen::VectorXd tau(d.n);
  rneaBackward(model, d, pi ? pi->data() : nullptr, tau.data());
  return tau;
}

namespace {
inline M3 skew(const V3& a) {
  M3 S;
  S << 0, -a[2], a[1], a[2], 0, -a[0], -a[1], a[0], 0;
  return S;
}

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

Eigen::MatrixXd massMatrix(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                           const Eigen::VectorXd* pi) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, nullptr, nullptr, "massMatrix");
  if (pi) checkSize(*pi, 10 * n, "pi", "massMatrix");
  forwardPass(model, d, q.data(), nullptr, nullptr, Level::Position, false);
  // Composite rigid bodies, leaves first, each as (I about its origin, h = m c, m) in its own
  // frame: moved to the parent's frame (R, p: the child's frame there) by
  //   m' = m,  h' = R h + m p,  I' = R I R^T - [R h]x [p]x - [p]x [R h]x - m [p]x^2,
  // which is X^T I6 X of the spatial inertia, in 3 x 3 blocks.
  for (int j = 0; j < n; ++j) {
    const double* g =
        pi ? pi->data() + 10 * j : model.bodies[static_cast<size_t>(j)].inertia.data();
    M3& I = d.cI[static_cast<size_t>(j)];
    I << g[0], g[1], g[2], g[1], g[3], g[4], g[2], g[4], g[5];
    d.ch[static_cast<size_t>(j)] = V3(g[6], g[7], g[8]);
    d.cm[static_cast<size_t>(j)] = g[9];
  }
  for (int j = n - 1; j >= 0; --j) {
    const int par = d.J[static_cast<size_t>(j)].parent;
    if (par < 0) continue;
    const auto u = static_cast<size_t>(j), w = static_cast<size_t>(par);
    const M3& R = d.R[u];
    const V3& p = d.p[u];
    const double m = d.cm[u];
    const V3 Rh = R * d.ch[u];
    const M3 P = skew(p), RH = skew(Rh);
    d.cI[w].noalias() += R * d.cI[u] * R.transpose();
    d.cI[w] -= RH * P + P * RH + m * (P * P);
    d.ch[w] += Rh + m * p;
    d.cm[w] += m;
  }
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    const auto u = static_cast<size_t>(i);
    const SV& S = d.J[u].S;
    // the force the composite body i needs for a unit qdd_i, carried to each ancestor:
    // n' = R n + p x (R f), f' = R f
    V3 fn = d.cI[u] * S.w + d.ch[u].cross(S.v);
    V3 ff = d.cm[u] * S.v - d.ch[u].cross(S.w);
    M(i, i) = S.w.dot(fn) + S.v.dot(ff);
    int j = i;
    while (d.J[static_cast<size_t>(j)].parent >= 0) {
      const auto v = static_cast<size_t>(j);
      const V3 Rf = d.R[v] * ff;
      fn = d.R[v] * fn + d.p[v].cross(Rf);
      ff = Rf;
      j = d.J[v].parent;
      const SV& Sj = d.J[static_cast<size_t>(j)].S;
      M(i, j) = M(j, i) = Sj.w.dot(fn) + Sj.v.dot(ff);
    }
  }
  return M;
}

Eigen::VectorXd forwardDynamics(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                                const Eigen::VectorXd& qd, const Eigen::VectorXd& tau,
                                const Eigen::VectorXd* pi) {
  prepare(model, d);
  checkState(model, q, &qd, nullptr, "forwardDynamics");
  checkSize(tau, d.n, "tau", "forwardDynamics");
  const Eigen::VectorXd h = inverseDynamics(model, d, q, qd, d.zero_n, pi);
  const Eigen::MatrixXd M = massMatrix(model, d, q, pi);
  Eigen::LLT<Eigen::MatrixXd> llt(M);
  check(llt.info() == Eigen::Success,
        "forwardDynamics: the mass matrix of robot '" + model.name +
            "' is not positive definite at this configuration (check masses and inertias)");
  return llt.solve(tau - h);
}

Pose bodyPose(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q, int body) {
  prepare(model, d);
  checkState(model, q, nullptr, nullptr, "bodyPose");
  check(body >= 0 && body < d.n, "bodyPose: body index " + std::to_string(body) + " out of range");
  forwardPass(model, d, q.data(), nullptr, nullptr, Level::Position, false);
  Pose X;
  for (int j = body; j >= 0; j = d.J[static_cast<size_t>(j)].parent)
    X = Pose{d.R[static_cast<size_t>(j)], d.p[static_cast<size_t>(j)]} * X;
  return X;
}

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
