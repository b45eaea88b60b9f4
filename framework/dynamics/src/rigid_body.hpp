// exid — internals shared by the rigid-body algorithms (dynamics.cpp: regressors, RNEA, CRBA,
// forward dynamics; dynamics_derivatives.cpp: inverseDynamicsDerivatives; dynamics_vjp.cpp: the
// regressors' vector-Jacobian products): spatial algebra, the workspace DynamicsData and the
// recursions they share (not installed). The small kernels are inline here, so that every source
// can still inline them.
//
// Internal conventions (see docs/dynamics.md):
//  * every quantity of body j is expressed in body frame j;
//  * spatial motion vectors are {w, v} = {angular, linear velocity of the frame origin}
//    (Featherstone), spatial forces are {n, f} = {moment about the frame origin, force};
//  * each joint axis is folded into pre/post (pre' = pre*Q, post' = Q^T*post with Q z = axis), so
//    every joint rotates about / translates along the z axis of its joint frame; the motion
//    subspace S_j of joint j is then a constant 6-vector in body frame j;
//  * gravity enters as the base acceleration a_0 = {0, -g}.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "exid/dynamics.hpp"

namespace exid {

namespace detail {

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

inline M3 skew(const V3& a) {
  M3 S;
  S << 0, -a[2], a[1], a[2], 0, -a[0], -a[1], a[0], 0;
  return S;
}

}  // namespace detail

struct DynamicsData {
  const RobotModel* key = nullptr;
  int n = 0;
  std::vector<detail::JointC> J;
  std::vector<int> anc_off, anc_idx;  // ancestors of j (j itself first) at anc_off[j]..anc_off[j+1]
  std::vector<int> off_off, off_idx;  // the other bodies (not ancestors of j), likewise
  // forward quantities (body frames)
  std::vector<detail::M3> R;
  std::vector<detail::V3> p;
  std::vector<detail::SV> v, a, xv, xa, s;
  std::vector<detail::Kin> kin;
  // adjoints
  std::vector<detail::SV> vb, ab, sb;
  std::vector<detail::V3> wb, wdb, aob;
  // RNEA / CRBA
  std::vector<detail::SV> f;
  // the composite rigid bodies of the CRBA: rotational inertia about the frame's origin, first
  // moment of mass, mass (a body's spatial inertia [I [h]x; [h]x^T m 1])
  std::vector<detail::M3> cI;
  std::vector<detail::V3> ch;
  std::vector<double> cm;
  std::vector<Pose> X0;
  // sensor frame
  detail::M3 Rs;
  detail::V3 ps;
  detail::SV vs, as;
  detail::Kin ks;
  std::vector<detail::SV> ss, ssb;
  Eigen::VectorXd zero_n, tmp_n;
  std::vector<double> cq, sq;   // cos q_j, sin q_j (revolute joints; forward pass)
  std::vector<double> lane_ws;  // the lane kernels' workspace (kernels_lanes.hpp)
  // forward tangents of v, a and the body forces (3 x 3n each, columns dq_i dqd_i dqdd_i)
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> tvw, tvv, taw, tav, tfw, tfv;
  Eigen::Matrix<double, 3, Eigen::Dynamic> tao;  // tangent of the origin's acceleration
  Eigen::MatrixXd tdtau;                         // n x 3n
  Eigen::MatrixXd scratch_m[4];
  Eigen::VectorXd scratch_v[4];
};

namespace detail {

/// (Re)builds the workspace for `model`: joint constants, ancestor lists, buffers.
void setup(const RobotModel& model, DynamicsData& d);

inline void prepare(const RobotModel& model, DynamicsData& d) {
  if (d.key != &model || d.n != model.numJoints()) setup(model, d);
}

void checkSize(const Eigen::VectorXd& x, int n, const char* what, const char* fn);

inline void checkState(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd* qd,
                       const Eigen::VectorXd* qdd, const char* fn) {
  const int n = m.numJoints();
  checkSize(q, n, "q", fn);
  if (qd) checkSize(*qd, n, "qd", fn);
  if (qdd) checkSize(*qdd, n, "qdd", fn);
}

enum class Level { Position, Velocity, Acceleration };

// Forward pass: poses (R, p), velocities, accelerations (with gravity if `gravity`), body
// kinematics.
void forwardPass(const RobotModel& model, DynamicsData& d, const double* q, const double* qd,
                 const double* qdd, Level level, bool gravity);

// Subspaces of all ancestors expressed in every body frame: s[anc_off[j] + k].
void ancestorSubspaces(DynamicsData& d);

// Sensor frame kinematics from the sensor body's (after forwardPass at Acceleration level).
void sensorKinematics(const RobotModel& model, DynamicsData& d, bool subspaces);

// Backward RNEA after forwardPass: the body forces d.f (each joint's transmitted force) and tau;
// parameters pi (10 per body, pi order) or, when null, the model's.
void rneaBackward(const RobotModel& model, DynamicsData& d, const double* pi, double* tau);

// Zeroes the adjoints (vb, ab, wb, wdb, aob; sb too if `subspaces`).
void clearAdjoints(DynamicsData& d, bool subspaces);

// Reverse pass: from adjoints of the body kinematics (wb, wdb, aob), of v / a (vb, ab) and of the
// ancestor subspaces (sb) to gradients in q, qd, qdd. Outputs are overwritten (may be null).
void reversePass(DynamicsData& d, const double* qd, Level level, bool subspaces, double* gq,
                 double* gqd, double* gqdd);

// (forwardPass, ancestorSubspaces, rneaBackward, clearAdjoints and reversePass are defined in
// kernels.hpp, compiled once per instruction set; these are the portable copies.)

}  // namespace detail

}  // namespace exid
