// exid — floating-base dynamics (exid/floating_base.hpp): the floating regressor, a recursive
// Newton-Euler pass, the contact map and the base-motion helpers. Plain recursions in the base
// frame (not the ISA-compiled kernels; speed is not optimised).
#include "exid/floating_base.hpp"

#include <Eigen/Geometry>
#include <string>

#include "exid/error.hpp"
#include "rigid_body.hpp"

namespace exid {

namespace {

using detail::Kin;
using detail::M3;
using detail::SV;
using detail::V3;
using Mat6x10 = Eigen::Matrix<double, 6, 10>;

std::string label(const RobotModel& m) {
  std::string s = "robot '" + m.name + "'";
  if (!m.source.empty()) s += " from " + m.source;
  return s;
}

void checkVec(const RobotModel& m, const Eigen::VectorXd& x, int n, const char* what,
              const char* fn) {
  if (x.size() != n)
    throw Error(std::string(fn) + ": " + label(m) + ": " + what + " has " +
                std::to_string(x.size()) + " entries (expected " + std::to_string(n) + ")");
}

// Kinematics of every body at one instant: the pose of its frame in the base frame, its joint
// subspace in the base frame, and its body-frame kinematics (forward recursion from the base
// link's v0 = {omega, 0}, a0 = {alpha, f}: the base origin's linear velocity is taken as zero,
// which is exact for the forces at one instant, Galilean invariance).
struct FloatState {
  std::vector<M3> R0;    // body frame in the base frame
  std::vector<V3> p0;    // body origin in the base frame
  std::vector<SV> S0;    // joint subspace in the base frame (motion, about the base origin)
  std::vector<Kin> kin;  // body kinematics in the body frame
  std::vector<SV> S;     // joint subspace in the body frame
  std::vector<M3> R;     // body frame in the parent frame
  std::vector<V3> p;
  Kin kin0;  // the base link's
};

Pose jointPose(const Body& b, double q) {
  Pose J;
  if (b.type == JointType::Revolute)
    J.R = Eigen::AngleAxisd(q, b.axis).toRotationMatrix();
  else
    J.p = q * b.axis;
  return b.pre * J * b.post;
}

void forward(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd* qd,
             const Eigen::VectorXd* qdd, const BaseMotion* base, FloatState& st) {
  const int n = m.dof();
  st.R0.resize(n);
  st.p0.resize(n);
  st.S0.resize(n);
  st.kin.resize(n);
  st.S.resize(n);
  st.R.resize(n);
  st.p.resize(n);
  std::vector<SV> v(n), a(n);
  SV v0, a0;
  if (base) {
    v0 = SV((*base).segment<3>(0), V3::Zero());
    a0 = SV((*base).segment<3>(3), (*base).segment<3>(6));
    st.kin0 = Kin{v0.w, a0.w, a0.v};
  }
  for (int j = 0; j < n; ++j) {
    const Body& b = m.bodies[static_cast<size_t>(j)];
    const Pose X = jointPose(b, q[j]);
    st.R[j] = X.R;
    st.p[j] = X.p;
    // joint subspace: {axis, 0} (revolute) or {0, axis} (prismatic) in the moved joint frame,
    // carried to the body frame (post relative to the moved joint frame)
    const SV sj = b.type == JointType::Revolute ? SV(b.axis, V3::Zero()) : SV(V3::Zero(), b.axis);
    st.S[j] = detail::xMotion(b.post.R, b.post.p, sj);
    const int par = b.parent;
    if (par < 0) {
      st.R0[j] = X.R;
      st.p0[j] = X.p;
    } else {
      st.R0[j] = st.R0[par] * X.R;
      st.p0[j] = st.R0[par] * X.p + st.p0[par];
    }
    const V3 sw = st.R0[j] * st.S[j].w;
    st.S0[j] = SV(sw, st.R0[j] * st.S[j].v + st.p0[j].cross(sw));
    if (!qd) continue;
    const SV& vp = par < 0 ? v0 : v[par];
    const SV& ap = par < 0 ? a0 : a[par];
    const SV vj = st.S[j] * (*qd)[j];
    v[j] = detail::xMotion(X.R, X.p, vp) + vj;
    a[j] = detail::xMotion(X.R, X.p, ap) + st.S[j] * (*qdd)[j] + detail::crm(v[j], vj);
    st.kin[j] = Kin{v[j].w, a[j].w, a[j].v + v[j].w.cross(v[j].v)};
  }
}

// The body's Newton-Euler wrench {n, f} as a 6 x 10 matrix of its parameters (body frame):
// rows 0..2 the moment about the body origin, rows 3..5 the force.
Mat6x10 bodyMatrix(const Kin& k) {
  Mat6x10 K;
  for (int r = 0; r < 6; ++r) {
    SV s;
    if (r < 3)
      s.w[r] = 1.0;
    else
      s.v[r - 3] = 1.0;
    Eigen::Matrix<double, 10, 1> row;
    detail::pairRow(s, k, row);
    K.row(r) = row.transpose();
  }
  return K;
}

// {n, f} rows (body frame, about its origin) to the base frame, about the base origin.
Mat6x10 toBase(const M3& R, const V3& p, const Mat6x10& K) {
  Mat6x10 out;
  const Eigen::Matrix<double, 3, 10> F = R * K.bottomRows<3>();
  out.bottomRows<3>() = F;
  out.topRows<3>() = R * K.topRows<3>() + detail::skew(p) * F;
  return out;
}

}  // namespace

std::vector<std::string> floatingParameterNames(const RobotModel& model) {
  std::vector<std::string> names;
  for (int k = 0; k < 10; ++k) names.push_back(std::string(kInertialNames[k]) + "0");
  for (const auto& s : model.inertialParameterNames()) names.push_back(s);
  return names;
}

Eigen::VectorXd floatingParameters(const RobotModel& model) {
  Eigen::VectorXd pi(10 * (model.dof() + 1));
  pi.head<10>() = model.base.inertia;
  pi.tail(10 * model.dof()) = model.inertialParameters();
  return pi;
}

void requireFloatingBase(const RobotModel& model, const std::string& what) {
  if (model.floating_base) return;
  throw Error(label(model) + " has a fixed base: " + what +
              " needs a floating-base robot (a URDF 'floating' joint from the world to the base "
              "link, or a description's floating_base key; docs/robots.md)");
}

void floatingRegressor(const RobotModel& model, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                       const Eigen::VectorXd& qdd, const BaseMotion& base, Eigen::MatrixXd& Y) {
  requireFloatingBase(model, "floatingRegressor");
  const int n = model.dof();
  checkVec(model, q, n, "q", "floatingRegressor");
  checkVec(model, qd, n, "qd", "floatingRegressor");
  checkVec(model, qdd, n, "qdd", "floatingRegressor");
  FloatState st;
  forward(model, q, &qd, &qdd, &base, st);
  Y.setZero(6 + n, 10 * (n + 1));
  // the base link: its own frame is the base frame
  const Mat6x10 K0 = bodyMatrix(st.kin0);
  Y.block<3, 10>(0, 0) = K0.bottomRows<3>();
  Y.block<3, 10>(3, 0) = K0.topRows<3>();
  for (int j = 0; j < n; ++j) {
    const Mat6x10 Kb = toBase(st.R0[j], st.p0[j], bodyMatrix(st.kin[j]));
    const int c = 10 * (j + 1);
    Y.block<3, 10>(0, c) = Kb.bottomRows<3>();
    Y.block<3, 10>(3, c) = Kb.topRows<3>();
    // every joint between the base and body j (j included) carries its wrench
    for (int i = j; i >= 0; i = model.bodies[static_cast<size_t>(i)].parent) {
      const SV& s = st.S0[i];
      Y.block<1, 10>(6 + i, c) =
          s.w.transpose() * Kb.topRows<3>() + s.v.transpose() * Kb.bottomRows<3>();
    }
  }
}

Eigen::VectorXd floatingInverseDynamics(const RobotModel& model, const Eigen::VectorXd& q,
                                        const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                                        const BaseMotion& base, const Eigen::VectorXd* pi_f) {
  requireFloatingBase(model, "floatingInverseDynamics");
  const int n = model.dof();
  checkVec(model, q, n, "q", "floatingInverseDynamics");
  checkVec(model, qd, n, "qd", "floatingInverseDynamics");
  checkVec(model, qdd, n, "qdd", "floatingInverseDynamics");
  if (pi_f) checkVec(model, *pi_f, 10 * (n + 1), "pi_f", "floatingInverseDynamics");
  const Eigen::VectorXd pi = pi_f ? *pi_f : floatingParameters(model);
  FloatState st;
  forward(model, q, &qd, &qdd, &base, st);
  // backward: each body's transmitted wrench in its own frame, children first
  std::vector<SV> f(static_cast<size_t>(n));
  for (int j = 0; j < n; ++j) f[j] = detail::newtonEuler(pi.segment<10>(10 * (j + 1)), st.kin[j]);
  SV f0 = detail::newtonEuler(pi.head<10>(), st.kin0);
  Eigen::VectorXd out(6 + n);
  for (int j = n - 1; j >= 0; --j) {
    out[6 + j] = detail::dot(st.S[j], f[j]);
    const SV up = detail::xForceT(st.R[j], st.p[j], f[j]);
    const int par = model.bodies[static_cast<size_t>(j)].parent;
    if (par < 0)
      f0 += up;
    else
      f[par] += up;
  }
  out.head<3>() = f0.v;
  out.segment<3>(3) = f0.w;
  return out;
}

Eigen::MatrixXd contactMap(const RobotModel& model, const Eigen::VectorXd& q, int body,
                           const Pose& sensor) {
  requireFloatingBase(model, "contactMap");
  const int n = model.dof();
  checkVec(model, q, n, "q", "contactMap");
  if (body < -1 || body >= n)
    throw Error("contactMap: " + label(model) + ": body " + std::to_string(body) +
                " out of range (expected -1 for the base link or 0.." + std::to_string(n - 1) +
                ")");
  FloatState st;
  forward(model, q, nullptr, nullptr, nullptr, st);
  const Pose B = body < 0 ? Pose{} : Pose{st.R0[body], st.p0[body]};
  const Pose P = B * sensor;  // sensor frame in the base frame
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(6 + n, 6);
  // w = [f; m] (sensor frame, about the sensor origin) -> base: f0 = R f, n0 = R m + p x R f
  C.block<3, 3>(0, 0) = P.R;
  C.block<3, 3>(3, 0) = detail::skew(P.p) * P.R;
  C.block<3, 3>(3, 3) = P.R;
  for (int i = body; i >= 0; i = model.bodies[static_cast<size_t>(i)].parent) {
    const SV& s = st.S0[i];
    C.row(6 + i) = s.v.transpose() * C.block<3, 6>(0, 0) + s.w.transpose() * C.block<3, 6>(3, 0);
  }
  return C;
}

int floatingBodyIndex(const RobotModel& model, const std::string& link, const std::string& who) {
  if (model.floating_base && link == model.base.link) return -1;
  std::string names = model.floating_base ? "'" + model.base.link + "' (the base link)" : "";
  for (int i = 0; i < model.dof(); ++i) {
    const std::string& b = model.bodies[static_cast<size_t>(i)].name;
    if (b == link) return i;
    names += (names.empty() ? "'" : ", '") + b + "'";
  }
  throw Error(who + ": unknown link '" + link + "' of " + label(model) + " (expected one of " +
              names + "; a link fixed to another is merged into it: name that one)");
}

Pose poseFromXyzRpy(const double* v) {
  Pose P;
  P.p = V3(v[0], v[1], v[2]);
  P.R = (Eigen::AngleAxisd(v[5], V3::UnitZ()) * Eigen::AngleAxisd(v[4], V3::UnitY()) *
         Eigen::AngleAxisd(v[3], V3::UnitX()))
            .toRotationMatrix();
  return P;
}

Pose floatingBodyPose(const RobotModel& model, const Eigen::VectorXd& q, int body) {
  const int n = model.dof();
  checkVec(model, q, n, "q", "floatingBodyPose");
  if (body < -1 || body >= n)
    throw Error("floatingBodyPose: " + label(model) + ": body " + std::to_string(body) +
                " out of range");
  if (body < 0) return Pose{};
  FloatState st;
  forward(model, q, nullptr, nullptr, nullptr, st);
  return Pose{st.R0[body], st.p0[body]};
}

BaseMotion baseMotionFromWorld(const Eigen::Matrix3d& R_wb, const Eigen::Vector3d& omega_w,
                               const Eigen::Vector3d& alpha_w, const Eigen::Vector3d& a_w,
                               const Eigen::Vector3d& g_w) {
  BaseMotion b;
  b.segment<3>(0) = R_wb.transpose() * omega_w;
  b.segment<3>(3) = R_wb.transpose() * alpha_w;
  b.segment<3>(6) = R_wb.transpose() * (a_w - g_w);
  return b;
}

BaseMotion baseMotionFromImu(const Pose& imu, const Eigen::Vector3d& gyro,
                             const Eigen::Vector3d& alpha_imu, const Eigen::Vector3d& accel) {
  const V3 w = imu.R * gyro, al = imu.R * alpha_imu, fr = imu.R * accel;
  const V3& r = imu.p;
  BaseMotion b;
  b.segment<3>(0) = w;
  b.segment<3>(3) = al;
  b.segment<3>(6) = fr - al.cross(r) - w.cross(w.cross(r));
  return b;
}

}  // namespace exid
