// exid — closed kinematic chains: loop-closure constraint, position solve, tree map (see
// exid/closed_chain.hpp). Kinematics here are computed on their own (world-frame spatial
// vectors), independently of the dynamics kernels.
#include "exid/closed_chain.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>
#include <vector>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid {

namespace {

using V3 = Eigen::Vector3d;
using M3 = Eigen::Matrix3d;

std::string robotLabel(const RobotModel& m) {
  std::string s = "robot '" + m.name + "'";
  if (!m.source.empty()) s += " from " + m.source;
  return s;
}

std::string loopLabel(const RobotModel& m, std::size_t l) {
  const LoopJoint& L = m.closed.loops[l];
  std::string s = "loop-closure joint " + std::to_string(l + 1);
  if (!L.name.empty()) s += " '" + L.name + "'";
  if (!L.where.empty()) s += " (" + L.where + ")";
  return s;
}

std::string vecText(const Eigen::VectorXd& v) {
  std::ostringstream os;
  os.precision(10);
  os << "[";
  for (Eigen::Index i = 0; i < v.size(); ++i) os << (i ? ", " : "") << v[i];
  os << "]";
  return os.str();
}

// World-frame kinematics of the tree: body poses, joint screw axes S = (w; v) at the world
// origin, spatial velocities V = (omega; v_O) and accelerations A = (alpha; a_O) (without
// gravity), where v_O is the velocity of the body point at the world origin.
struct Kin {
  std::vector<M3> R;
  std::vector<V3> p;
  std::vector<V3> sw, sv;              // joint screws
  std::vector<V3> w, v, al, a;         // spatial velocity and acceleration
  std::vector<std::vector<char>> anc;  // anc[i][j]: joint j moves body i
};

void kinematics(const RobotModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd* qd,
                const Eigen::VectorXd* qdd, Kin& k) {
  const int n = m.numJoints();
  k.R.resize(n);
  k.p.resize(n);
  k.sw.resize(n);
  k.sv.resize(n);
  k.w.assign(n, V3::Zero());
  k.v.assign(n, V3::Zero());
  k.al.assign(n, V3::Zero());
  k.a.assign(n, V3::Zero());
  k.anc.assign(n, std::vector<char>(static_cast<size_t>(n), 0));
  for (int i = 0; i < n; ++i) {
    const Body& b = m.bodies[static_cast<size_t>(i)];
    const int pa = b.parent;
    const M3 Rp = pa < 0 ? M3::Identity() : k.R[pa];
    const V3 pp = pa < 0 ? V3::Zero() : k.p[pa];
    const M3 Rj = Rp * b.pre.R;  // joint frame
    const V3 oj = pp + Rp * b.pre.p;
    const V3 s = Rj * b.axis;
    M3 Rm = Rj;
    V3 om = oj;
    if (b.type == JointType::Revolute) {
      Rm = Rj * Eigen::AngleAxisd(q[i], b.axis).toRotationMatrix();
      k.sw[i] = s;
      k.sv[i] = oj.cross(s);
    } else {
      om = oj + s * q[i];
      k.sw[i] = V3::Zero();
      k.sv[i] = s;
    }
    k.R[i] = Rm * b.post.R;
    k.p[i] = om + Rm * b.post.p;
    if (pa >= 0) k.anc[i] = k.anc[pa];
    k.anc[i][i] = 1;
    if (qd) {
      const double u = (*qd)[i];
      const V3 w0 = pa < 0 ? V3::Zero() : k.w[pa], v0 = pa < 0 ? V3::Zero() : k.v[pa];
      k.w[i] = w0 + k.sw[i] * u;
      k.v[i] = v0 + k.sv[i] * u;
      const double ud = qdd ? (*qdd)[i] : 0.0;
      const V3 al0 = pa < 0 ? V3::Zero() : k.al[pa], a0 = pa < 0 ? V3::Zero() : k.a[pa];
      // A_i = A_parent + S qdd + V_i x (S qd)
      const V3 Sw = k.sw[i] * u, Sv = k.sv[i] * u;
      k.al[i] = al0 + k.sw[i] * ud + k.w[i].cross(Sw);
      k.a[i] = a0 + k.sv[i] * ud + k.w[i].cross(Sv) + k.v[i].cross(Sw);
    }
  }
}

// The two unit vectors across the cut joint's axis u (in the cut frame).
void across(const V3& u, V3* e1, V3* e2) {
  const V3 un = u.normalized();
  V3 t = std::abs(un.x()) < 0.9 ? V3::UnitX() : V3::UnitY();
  *e1 = (t - un * un.dot(t)).normalized();
  *e2 = un.cross(*e1);
}

struct Side {
  M3 R;
  V3 x;  // cut frame origin in the world
  int body;
};

Side side(const RobotModel&, const Kin& k, int body, const Pose& pose) {
  if (body < 0) return {pose.R, pose.p, -1};
  return {k.R[body] * pose.R, k.p[body] + k.R[body] * pose.p, body};
}

int rowsOf(const LoopJoint& L) { return L.kind == LoopJoint::Kind::Revolute ? 5 : 3; }

void constraintFromKin(const RobotModel& m, const Kin& k, Eigen::VectorXd* c, Eigen::MatrixXd* J) {
  const int n = m.numJoints(), nc = numLoopConstraints(m);
  if (c) c->resize(nc);
  if (J) J->setZero(nc, n);
  int r = 0;
  for (const LoopJoint& L : m.closed.loops) {
    const Side A = side(m, k, L.body_a, L.pose_a), B = side(m, k, L.body_b, L.pose_b);
    if (c) c->segment<3>(r) = B.x - A.x;
    if (J)
      for (int j = 0; j < n; ++j) {
        V3 col = V3::Zero();
        if (B.body >= 0 && k.anc[B.body][j]) col += k.sw[j].cross(B.x) + k.sv[j];
        if (A.body >= 0 && k.anc[A.body][j]) col -= k.sw[j].cross(A.x) + k.sv[j];
        J->block<3, 1>(r, j) = col;
      }
    if (L.kind == LoopJoint::Kind::Revolute) {
      V3 e1, e2;
      across(L.axis, &e1, &e2);
      const V3 Bu = B.R * L.axis.normalized();
      const V3 Ae[2] = {A.R * e1, A.R * e2};
      for (int t = 0; t < 2; ++t) {
        if (c) (*c)[r + 3 + t] = Ae[t].dot(Bu);
        if (J)
          for (int j = 0; j < n; ++j) {
            double d = 0.0;
            if (A.body >= 0 && k.anc[A.body][j]) d += k.sw[j].cross(Ae[t]).dot(Bu);
            if (B.body >= 0 && k.anc[B.body][j]) d += Ae[t].dot(k.sw[j].cross(Bu));
            (*J)(r + 3 + t, j) = d;
          }
      }
    }
    r += rowsOf(L);
  }
}

// Point velocity and acceleration of a world point x moving with body b (zero for the base).
void pointMotion(const Kin& k, int b, const V3& x, V3* vel, V3* acc) {
  if (b < 0) {
    *vel = V3::Zero();
    *acc = V3::Zero();
    return;
  }
  *vel = k.v[b] + k.w[b].cross(x);
  *acc = k.a[b] + k.al[b].cross(x) + k.w[b].cross(*vel);
}

void vectorMotion(const Kin& k, int b, const V3& e, V3* ed, V3* edd) {
  if (b < 0) {
    *ed = V3::Zero();
    *edd = V3::Zero();
    return;
  }
  *ed = k.w[b].cross(e);
  *edd = k.al[b].cross(e) + k.w[b].cross(*ed);
}

// Passive joints (tree indices not actuated).
std::vector<int> passiveJoints(const RobotModel& m) {
  std::vector<char> act(static_cast<size_t>(m.numJoints()), 0);
  for (int a : m.closed.actuated) act[static_cast<size_t>(a)] = 1;
  std::vector<int> p;
  for (int j = 0; j < m.numJoints(); ++j)
    if (!act[static_cast<size_t>(j)]) p.push_back(j);
  return p;
}

Eigen::MatrixXd columns(const Eigen::MatrixXd& J, const std::vector<int>& idx) {
  Eigen::MatrixXd out(J.rows(), static_cast<Eigen::Index>(idx.size()));
  for (std::size_t i = 0; i < idx.size(); ++i)
    out.col(static_cast<Eigen::Index>(i)) = J.col(idx[i]);
  return out;
}

double lengthScale(const RobotModel& m) {
  double L = 0.0;
  for (const Body& b : m.bodies) L += b.pre.p.norm() + b.post.p.norm();
  for (const LoopJoint& l : m.closed.loops) L += l.pose_a.p.norm() + l.pose_b.p.norm();
  return std::max(1.0, L);
}

constexpr double kTol = 1e-12;

// Rank-revealing decomposition of the passive columns with a threshold relative to their size.
struct PassiveSolver {
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
  explicit PassiveSolver(const Eigen::MatrixXd& Jp) {
    cod.setThreshold(1e-10);
    cod.compute(Jp);
  }
};

// Newton on the passive coordinates at fixed actuated ones; returns the final residual norm.
double newton(const RobotModel& m, const std::vector<int>& passive, Eigen::VectorXd& q, Kin& k,
              double tol) {
  Eigen::VectorXd c;
  Eigen::MatrixXd J;
  kinematics(m, q, nullptr, nullptr, k);
  constraintFromKin(m, k, &c, &J);
  double norm = c.lpNorm<Eigen::Infinity>();
  // iterate past `tol` to rounding (quadratic convergence: a step or two), stop without progress
  const double tight = 1e-3 * tol;
  for (int it = 0; it < 60 && norm > tight; ++it) {
    PassiveSolver S(columns(J, passive));
    const Eigen::VectorXd dx = S.cod.solve(-c);
    double step = 1.0;
    bool better = false;
    Eigen::VectorXd trial;
    for (int h = 0; h < 30; ++h, step *= 0.5) {
      trial = q;
      for (std::size_t i = 0; i < passive.size(); ++i)
        trial[passive[i]] += step * dx[static_cast<Eigen::Index>(i)];
      kinematics(m, trial, nullptr, nullptr, k);
      Eigen::VectorXd ct;
      constraintFromKin(m, k, &ct, nullptr);
      const double nt = ct.lpNorm<Eigen::Infinity>();
      if (nt < norm) {
        better = true;
        q = trial;
        norm = nt;
        break;
      }
    }
    if (!better) break;
    kinematics(m, q, nullptr, nullptr, k);
    constraintFromKin(m, k, &c, &J);
  }
  return norm;
}

// Newton over every tree joint (minimum-norm steps): the assembled configuration nearest the
// given one, whatever the actuated joints. Returns the final residual norm.
double assembleAll(const RobotModel& m, Eigen::VectorXd& q, double tol) {
  Kin k;
  Eigen::VectorXd c;
  Eigen::MatrixXd J;
  kinematics(m, q, nullptr, nullptr, k);
  constraintFromKin(m, k, &c, &J);
  double norm = c.lpNorm<Eigen::Infinity>();
  for (int it = 0; it < 60 && norm > 1e-3 * tol; ++it) {
    PassiveSolver S(J);
    const Eigen::VectorXd dx = S.cod.solve(-c);
    double step = 1.0;
    bool better = false;
    for (int h = 0; h < 30 && !better; ++h, step *= 0.5) {
      const Eigen::VectorXd trial = q + step * dx;
      kinematics(m, trial, nullptr, nullptr, k);
      Eigen::VectorXd ct;
      constraintFromKin(m, k, &ct, nullptr);
      if (ct.lpNorm<Eigen::Infinity>() < norm) {
        q = trial;
        norm = ct.lpNorm<Eigen::Infinity>();
        better = true;
      }
    }
    if (!better) break;
    kinematics(m, q, nullptr, nullptr, k);
    constraintFromKin(m, k, &c, &J);
  }
  return norm;
}

[[noreturn]] void noAssembly(const RobotModel& m, const Eigen::VectorXd& qa, const Kin& k,
                             double norm) {
  // name the loop with the largest gap
  Eigen::VectorXd c;
  constraintFromKin(m, k, &c, nullptr);
  std::size_t worst = 0;
  double wv = -1.0;
  int r = 0;
  for (std::size_t l = 0; l < m.closed.loops.size(); ++l) {
    const int nr = rowsOf(m.closed.loops[l]);
    const double v = c.segment(r, nr).lpNorm<Eigen::Infinity>();
    if (v > wv) {
      wv = v;
      worst = l;
    }
    r += nr;
  }
  std::ostringstream os;
  os << robotLabel(m) << ": the closed chain does not assemble at actuated coordinates "
     << vecText(qa) << ": " << loopLabel(m, worst) << " stays open (constraint residual " << norm
     << ", expected <= 1e-12 after Newton on the passive joints)";
  throw Error(os.str());
}

}  // namespace

int numLoopConstraints(const RobotModel& model) {
  int r = 0;
  for (const LoopJoint& L : model.closed.loops) r += rowsOf(L);
  return r;
}

void loopConstraint(const RobotModel& model, const Eigen::VectorXd& q, Eigen::VectorXd* c,
                    Eigen::MatrixXd* J) {
  check(q.size() == model.numJoints(),
        "loopConstraint: q has " + std::to_string(q.size()) + " entries (expected " +
            std::to_string(model.numJoints()) + ", the tree's joints)");
  Kin k;
  kinematics(model, q, nullptr, nullptr, k);
  constraintFromKin(model, k, c, J);
}

Eigen::VectorXd loopConstraintBias(const RobotModel& model, const Eigen::VectorXd& q,
                                   const Eigen::VectorXd& qd) {
  check(q.size() == model.numJoints() && qd.size() == model.numJoints(),
        "loopConstraintBias: q and qd must have numJoints entries");
  Kin k;
  kinematics(model, q, &qd, nullptr, k);
  Eigen::VectorXd b(numLoopConstraints(model));
  int r = 0;
  for (const LoopJoint& L : model.closed.loops) {
    const Side A = side(model, k, L.body_a, L.pose_a), B = side(model, k, L.body_b, L.pose_b);
    V3 va, aa, vb, ab;
    pointMotion(k, A.body, A.x, &va, &aa);
    pointMotion(k, B.body, B.x, &vb, &ab);
    b.segment<3>(r) = ab - aa;
    if (L.kind == LoopJoint::Kind::Revolute) {
      V3 e1, e2;
      across(L.axis, &e1, &e2);
      const V3 Bu = B.R * L.axis.normalized();
      V3 Bd, Bdd;
      vectorMotion(k, B.body, Bu, &Bd, &Bdd);
      const V3 Ae[2] = {A.R * e1, A.R * e2};
      for (int t = 0; t < 2; ++t) {
        V3 Ad, Add;
        vectorMotion(k, A.body, Ae[t], &Ad, &Add);
        b[r + 3 + t] = Add.dot(Bu) + 2.0 * Ad.dot(Bd) + Ae[t].dot(Bdd);
      }
    }
    r += rowsOf(L);
  }
  return b;
}

void closedChainState(const RobotModel& m, const Eigen::VectorXd& qa, const Eigen::VectorXd* qda,
                      const Eigen::VectorXd* qdda, Eigen::VectorXd* q_out, Eigen::VectorXd* qd_out,
                      Eigen::VectorXd* qdd_out, Eigen::MatrixXd* G_out, Eigen::VectorXd* g_out) {
  const int n = m.numJoints(), na = m.dof();
  check(m.hasLoops(), "closedChainState: " + robotLabel(m) + " has no loop-closure joint");
  if (qa.size() != na)
    throw Error("closedChainState: qa has " + std::to_string(qa.size()) + " entries (expected " +
                std::to_string(na) + ", the actuated joints of " + robotLabel(m) + ")");
  if (!qa.allFinite())
    throw Error(robotLabel(m) + ": non-finite actuated coordinates " + vecText(qa));
  const std::vector<int> passive = passiveJoints(m);
  const double tol = kTol * lengthScale(m);
  // continuation from the reference configuration along a straight path in qa
  Eigen::VectorXd q =
      m.closed.reference.size() == n ? m.closed.reference : Eigen::VectorXd::Zero(n);
  Eigen::VectorXd qa0(na);
  for (int i = 0; i < na; ++i) qa0[i] = q[m.closed.actuated[static_cast<size_t>(i)]];
  // A revolute actuated joint moves the mechanism 2 pi-periodically: the path starts from the
  // reference's angle nearest qa (the passive joints come out modulo 2 pi, as the dynamics read
  // them), so a crank that has turned many times costs no longer path.
  for (int i = 0; i < na; ++i) {
    const int j = m.closed.actuated[static_cast<size_t>(i)];
    if (m.bodies[static_cast<size_t>(j)].type == JointType::Revolute)
      qa0[i] = qa[i] - std::remainder(qa[i] - qa0[i], 2.0 * M_PI);
  }
  const double span = (qa - qa0).lpNorm<Eigen::Infinity>();
  if (!(span <= 1e4))
    throw Error(robotLabel(m) + ": actuated coordinates " + vecText(qa) +
                " are more than 1e4 m from the closed chain's reference configuration");
  const int steps = std::max(1, static_cast<int>(std::ceil(span / 0.25)));
  Kin k;
  double norm = 0.0;
  for (int s = 1; s <= steps; ++s) {
    const double t = static_cast<double>(s) / steps;
    for (int i = 0; i < na; ++i)
      q[m.closed.actuated[static_cast<size_t>(i)]] =
          s == steps ? qa[i] : qa0[i] + t * (qa[i] - qa0[i]);
    norm = newton(m, passive, q, k, s == steps ? tol : 1e-6);
    if (!(norm <= (s == steps ? tol : 1e-6))) noAssembly(m, qa, k, norm);
  }
  if (q_out) *q_out = q;
  if (!qd_out && !qdd_out && !G_out && !g_out) return;
  Eigen::MatrixXd J;
  constraintFromKin(m, k, nullptr, &J);  // k holds the final configuration
  const Eigen::MatrixXd Jp = columns(J, passive), Ja = columns(J, m.closed.actuated);
  PassiveSolver S(Jp);
  if (S.cod.rank() < static_cast<Eigen::Index>(passive.size())) {
    std::ostringstream os;
    os << robotLabel(m) << ": at actuated coordinates " << vecText(qa)
       << " the actuated joints do not determine the passive ones (the passive columns of the "
          "loop-closure Jacobian have rank "
       << S.cod.rank() << ", expected " << passive.size()
       << "): a singular configuration, or fewer actuated joints than the mechanism's mobility";
    throw Error(os.str());
  }
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, na);
  const Eigen::MatrixXd Gp = -S.cod.solve(Ja);
  for (int i = 0; i < na; ++i) G(m.closed.actuated[static_cast<size_t>(i)], i) = 1.0;
  for (std::size_t r = 0; r < passive.size(); ++r)
    G.row(passive[r]) = Gp.row(static_cast<Eigen::Index>(r));
  Eigen::VectorXd qd;
  if (qd_out || qdd_out || g_out) {
    const Eigen::VectorXd z = Eigen::VectorXd::Zero(na);
    qd = G * (qda ? *qda : z);
  }
  if (qd_out) *qd_out = qd;
  if (qdd_out || g_out) {
    const Eigen::VectorXd bias = loopConstraintBias(m, q, qd);
    const Eigen::VectorXd gp = -S.cod.solve(bias);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(n);
    for (std::size_t r = 0; r < passive.size(); ++r)
      g[passive[r]] = gp[static_cast<Eigen::Index>(r)];
    if (qdd_out) {
      const Eigen::VectorXd z = Eigen::VectorXd::Zero(na);
      *qdd_out = G * (qdda ? *qdda : z) + g;
    }
    if (g_out) *g_out = g;
  }
  if (G_out) *G_out = G;
}

Eigen::VectorXd loopConstraintJerk(const RobotModel& model, const Eigen::VectorXd& q,
                                   const Eigen::VectorXd& w) {
  check(q.size() == model.numJoints() && w.size() == model.numJoints(),
        "loopConstraintJerk: q and w must have numJoints entries");
  const int n = model.numJoints();
  Kin k;
  kinematics(model, q, &w, nullptr, k);
  // spatial jerk (d/dt of the spatial acceleration) at qdd = qddd = 0:
  // Jk_i = Jk_parent + Sdd_i qd_i, Sdd_i = A_parent x S_i + V_parent x (V_parent x S_i)
  // (motion cross product (w; v) x (sw; sv) = (w x sw; w x sv + v x sw))
  std::vector<V3> jw(static_cast<size_t>(n)), jv(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const int pa = model.bodies[static_cast<size_t>(i)].parent;
    const V3 w0 = pa < 0 ? V3::Zero() : k.w[pa], v0 = pa < 0 ? V3::Zero() : k.v[pa];
    const V3 al0 = pa < 0 ? V3::Zero() : k.al[pa], a0 = pa < 0 ? V3::Zero() : k.a[pa];
    const V3 sw = k.sw[i], sv = k.sv[i];
    const V3 cw = w0.cross(sw), cv = w0.cross(sv) + v0.cross(sw);  // V x S
    const V3 ddw = al0.cross(sw) + w0.cross(cw);                   // A x S + V x (V x S)
    const V3 ddv = al0.cross(sv) + a0.cross(sw) + w0.cross(cv) + v0.cross(cw);
    const double u = w[i];
    jw[static_cast<size_t>(i)] = (pa < 0 ? V3::Zero() : jw[static_cast<size_t>(pa)]) + ddw * u;
    jv[static_cast<size_t>(i)] = (pa < 0 ? V3::Zero() : jv[static_cast<size_t>(pa)]) + ddv * u;
  }
  // a point x and a vector e fixed in body b, their first three time derivatives:
  //   x3 = jv + jw x x + 2 al x x1 + w x x2,   e3 = jw x e + 2 al x e1 + w x e2
  auto point = [&](int b, const V3& x, V3 d[3]) {
    if (b < 0) {
      d[0] = d[1] = d[2] = V3::Zero();
      return;
    }
    const auto u = static_cast<size_t>(b);
    d[0] = k.v[b] + k.w[b].cross(x);
    d[1] = k.a[b] + k.al[b].cross(x) + k.w[b].cross(d[0]);
    d[2] = jv[u] + jw[u].cross(x) + 2.0 * k.al[b].cross(d[0]) + k.w[b].cross(d[1]);
  };
  auto vec = [&](int b, const V3& e, V3 d[3]) {
    if (b < 0) {
      d[0] = d[1] = d[2] = V3::Zero();
      return;
    }
    const auto u = static_cast<size_t>(b);
    d[0] = k.w[b].cross(e);
    d[1] = k.al[b].cross(e) + k.w[b].cross(d[0]);
    d[2] = jw[u].cross(e) + 2.0 * k.al[b].cross(d[0]) + k.w[b].cross(d[1]);
  };
  Eigen::VectorXd out(numLoopConstraints(model));
  int r = 0;
  for (const LoopJoint& L : model.closed.loops) {
    const Side A = side(model, k, L.body_a, L.pose_a), B = side(model, k, L.body_b, L.pose_b);
    V3 da[3], db[3];
    point(A.body, A.x, da);
    point(B.body, B.x, db);
    out.segment<3>(r) = db[2] - da[2];
    if (L.kind == LoopJoint::Kind::Revolute) {
      V3 e1, e2;
      across(L.axis, &e1, &e2);
      const V3 Bu = B.R * L.axis.normalized();
      V3 bu[3];
      vec(B.body, Bu, bu);
      const V3 Ae[2] = {A.R * e1, A.R * e2};
      for (int t = 0; t < 2; ++t) {
        V3 ae[3];
        vec(A.body, Ae[t], ae);
        out[r + 3 + t] =
            ae[2].dot(Bu) + 3.0 * ae[1].dot(bu[0]) + 3.0 * ae[0].dot(bu[1]) + Ae[t].dot(bu[2]);
      }
    }
    r += rowsOf(L);
  }
  return out;
}

void closedChainStateDerivatives(const RobotModel& m, const Eigen::VectorXd& qa,
                                 const Eigen::VectorXd& qda, const Eigen::VectorXd& qdda,
                                 Eigen::VectorXd* q_out, Eigen::VectorXd* qd_out,
                                 Eigen::VectorXd* qdd_out, Eigen::MatrixXd* G_out,
                                 std::vector<Eigen::MatrixXd>* dG_out, Eigen::MatrixXd* dqd_dqa,
                                 Eigen::MatrixXd* dqdd_dqa, Eigen::MatrixXd* dqdd_dqda) {
  const int n = m.numJoints(), na = m.dof();
  if (qda.size() != na || qdda.size() != na)
    throw Error("closedChainStateDerivatives: qda and qdda must have " + std::to_string(na) +
                " entries (the actuated joints of " + robotLabel(m) + ")");
  Eigen::VectorXd q, qd, qdd;
  Eigen::MatrixXd G;
  closedChainState(m, qa, &qda, &qdda, &q, &qd, &qdd, &G, nullptr);
  if (q_out) *q_out = q;
  if (qd_out) *qd_out = qd;
  if (qdd_out) *qdd_out = qdd;
  if (G_out) *G_out = G;
  if (!dG_out && !dqd_dqa && !dqdd_dqa && !dqdd_dqda) return;
  const std::vector<int> passive = passiveJoints(m);
  Eigen::MatrixXd J;
  loopConstraint(m, q, nullptr, &J);
  PassiveSolver S(columns(J, passive));
  // y = -Jp^+ rhs, lifted to the tree (zero on the actuated joints)
  auto lift = [&](const Eigen::VectorXd& rhs) {
    const Eigen::VectorXd y = -S.cod.solve(rhs);
    Eigen::VectorXd out = Eigen::VectorXd::Zero(n);
    for (std::size_t r = 0; r < passive.size(); ++r)
      out[passive[r]] = y[static_cast<Eigen::Index>(r)];
    return out;
  };
  // the constraint's Hessian H(u, v) and third-derivative tensor T(u, v, v) by polarisation of
  // the exactly quadratic bias H(w, w) and the exactly cubic jerk T(w, w, w)
  auto H = [&](const Eigen::VectorXd& u, const Eigen::VectorXd& v) -> Eigen::VectorXd {
    return 0.25 * (loopConstraintBias(m, q, u + v) - loopConstraintBias(m, q, u - v));
  };
  auto T = [&](const Eigen::VectorXd& u, const Eigen::VectorXd& v) -> Eigen::VectorXd {
    return (loopConstraintJerk(m, q, v + u) - loopConstraintJerk(m, q, v - u) -
            2.0 * loopConstraintJerk(m, q, u)) /
           6.0;
  };
  // J G = 0  =>  J (dG/dqa_k) e_j = -H(G e_k, G e_j)
  std::vector<Eigen::MatrixXd> dG(static_cast<std::size_t>(na), Eigen::MatrixXd::Zero(n, na));
  for (int kk = 0; kk < na; ++kk)
    for (int j = kk; j < na; ++j) {
      const Eigen::VectorXd col = lift(H(G.col(kk), G.col(j)));
      dG[static_cast<std::size_t>(kk)].col(j) = col;
      dG[static_cast<std::size_t>(j)].col(kk) = col;  // symmetric: d2 q / dqa_k dqa_j
    }
  Eigen::MatrixXd Dqd(n, na);
  for (int kk = 0; kk < na; ++kk) Dqd.col(kk) = dG[static_cast<std::size_t>(kk)] * qda;
  if (dqd_dqa) *dqd_dqa = Dqd;
  if (dqdd_dqa) {
    // qdd = G qdda + g with J g + H(qd, qd) = 0, so along qa_k (u_k = G e_k):
    // J dg_k = -(H(u_k, g) + T(u_k, qd, qd) + 2 H(qd, dqd_k))
    const Eigen::VectorXd gb = qdd - G * qdda;
    dqdd_dqa->resize(n, na);
    for (int kk = 0; kk < na; ++kk) {
      const Eigen::VectorXd u = G.col(kk);
      dqdd_dqa->col(kk) = dG[static_cast<std::size_t>(kk)] * qdda +
                          lift(H(u, gb) + T(u, qd) + 2.0 * H(qd, Dqd.col(kk)));
    }
  }
  if (dqdd_dqda) {
    // J dg/dqda_j = -2 H(qd, G e_j)
    dqdd_dqda->resize(n, na);
    for (int j = 0; j < na; ++j) dqdd_dqda->col(j) = lift(2.0 * H(qd, G.col(j)));
  }
  if (dG_out) *dG_out = std::move(dG);
}

void validateClosedChain(const RobotModel& m) {
  const int n = m.numJoints();
  const std::string who = robotLabel(m);
  for (std::size_t l = 0; l < m.closed.loops.size(); ++l) {
    const LoopJoint& L = m.closed.loops[l];
    const std::string lab = who + ": " + loopLabel(m, l);
    if (L.body_a < -1 || L.body_a >= n || L.body_b < -1 || L.body_b >= n)
      throw Error(lab + ": body index out of range (expected -1 for the base or 0.." +
                  std::to_string(n - 1) + ")");
    if (L.body_a == L.body_b)
      throw Error(lab + ": joins a body to itself (expected two different bodies)");
    for (const Pose* P : {&L.pose_a, &L.pose_b}) {
      if (!P->R.allFinite() || !P->p.allFinite()) throw Error(lab + ": non-finite pose");
      const double orth = (P->R.transpose() * P->R - M3::Identity()).cwiseAbs().maxCoeff();
      if (!(orth <= 1e-9) || !(P->R.determinant() > 0.0))
        throw Error(lab + ": pose rotation is not a proper orthonormal matrix");
    }
    if (!(std::abs(L.axis.norm() - 1.0) <= 1e-9)) throw Error(lab + ": axis is not a unit vector");
  }
  const int na = static_cast<int>(m.closed.actuated.size());
  if (na == 0) throw Error(who + ": a closed chain must name its actuated joints (found none)");
  std::vector<char> seen(static_cast<size_t>(n), 0);
  for (int a : m.closed.actuated) {
    if (a < 0 || a >= n)
      throw Error(who + ": actuated joint index " + std::to_string(a) +
                  " out of range (expected 0.." + std::to_string(n - 1) + ")");
    if (seen[static_cast<size_t>(a)]++)
      throw Error(who + ": actuated joint '" + m.bodies[static_cast<size_t>(a)].joint_name +
                  "' named twice");
  }
  if (m.closed.reference.size() != 0 &&
      (m.closed.reference.size() != n || !m.closed.reference.allFinite()))
    throw Error(who + ": the closed chain's reference configuration has " +
                std::to_string(m.closed.reference.size()) + " entries (expected " +
                std::to_string(n) + " finite tree coordinates)");
  if (!m.closed.tree_limits.empty() && static_cast<int>(m.closed.tree_limits.size()) != n)
    throw Error(who + ": tree_limits has " + std::to_string(m.closed.tree_limits.size()) +
                " entries (expected one per tree joint, " + std::to_string(n) + ")");
  // assembly at the reference, and the rank test there
  const Eigen::VectorXd q0 =
      m.closed.reference.size() == n ? m.closed.reference : Eigen::VectorXd::Zero(n);
  // the assembled configuration nearest the reference (every joint free), the rank tests there,
  // then the position solve from the reference at its actuated values
  Eigen::VectorXd q = q0;
  const double tol = kTol * lengthScale(m);
  if (!(assembleAll(m, q, tol) <= tol)) {
    Kin k;
    kinematics(m, q, nullptr, nullptr, k);
    Eigen::VectorXd qa0(na);
    for (int i = 0; i < na; ++i) qa0[i] = q0[m.closed.actuated[static_cast<size_t>(i)]];
    Eigen::VectorXd c;
    constraintFromKin(m, k, &c, nullptr);
    noAssembly(m, qa0, k, c.lpNorm<Eigen::Infinity>());
  }
  Eigen::MatrixXd J;
  loopConstraint(m, q, nullptr, &J);
  const std::vector<int> passive = passiveJoints(m);
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> full, pas;
  full.setThreshold(1e-10);
  pas.setThreshold(1e-10);
  full.compute(J);
  const Eigen::MatrixXd Jp = columns(J, passive);
  pas.compute(Jp);
  const Eigen::Index mobility = n - full.rank();
  if (pas.rank() < static_cast<Eigen::Index>(passive.size())) {
    std::ostringstream os;
    os << who << ": " << na << " actuated joint(s) do not determine the passive ones at the "
       << "reference configuration (the mechanism's mobility is " << mobility
       << "; expected as many actuated joints, chosen so that the passive ones follow)";
    throw Error(os.str());
  }
  if (pas.rank() < full.rank() || na != mobility) {
    std::ostringstream os;
    os << who << ": the " << na << " actuated joints are not independent (the mechanism's mobility "
       << "is " << mobility << "; expected that many actuated joints, free to move together)";
    throw Error(os.str());
  }
  Eigen::VectorXd qa0(na);
  for (int i = 0; i < na; ++i) qa0[i] = q0[m.closed.actuated[static_cast<size_t>(i)]];
  closedChainState(m, qa0, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr);
}

}  // namespace exid
