// exid — rigid-body algorithms: torque / energy / wrench / payload-torque regressors, RNEA, CRBA,
// forward dynamics; the hot kernels (compiled once per instruction set) are in kernels.hpp. Their
// exact vector-Jacobian products (hand-written reverse mode) are in
// dynamics_vjp.cpp, the derivatives of inverse dynamics in dynamics_derivatives.cpp; the spatial
// algebra, the workspace and the recursions they share (with the internal conventions) in
// rigid_body.hpp.
#include "exid/dynamics.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "internal.hpp"
#include "kernel_table.hpp"
#include "rigid_body.hpp"

namespace exid {

using namespace detail;

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
}  // namespace

namespace detail {

// Kin{} leaves its vectors unset (as it always did): forwardPass writes each body's kinematics
// before they are read. Since the split into dynamics*.cpp (Kin now in rigid_body.hpp) gcc 12
// warns that the copies may be uninitialized; silenced for setup alone.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
void setup(const RobotModel& model, DynamicsData& d) {
  model.requireFixedBase("the fixed-base rigid-body algorithms (exid/dynamics.hpp)");
  const int n = model.numJoints();
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
  d.cq.assign(N, 1.0);
  d.sq.assign(N, 0.0);
  for (int j = 0; j < n; ++j)
    d.s[static_cast<size_t>(d.anc_off[static_cast<size_t>(j)])] = d.J[static_cast<size_t>(j)].S;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

void checkSize(const Eigen::VectorXd& x, int n, const char* what, const char* fn) {
  if (x.size() != n)
    throw Error(std::string(fn) + ": " + what + " has " + std::to_string(x.size()) +
                " entries (expected " + std::to_string(n) + ")");
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

}  // namespace detail

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
  kernels().torqueRegressor(model, d, q.data(), qd.data(), qdd.data(), Y.data(), Y.outerStride());
}

namespace {
// The samples' states as the lane kernels read them: state j of sample k at x[k + ld j], one ld
// for the three (copies when the matrices' strides differ, which Eigen::Ref's blocks of one
// matrix never do).
struct SampleStates {
  const double *q, *qd, *qdd;
  long ld;
  Eigen::MatrixXd qc, qdc, qddc;
  SampleStates(const Eigen::Ref<const Eigen::MatrixXd>& Q,
               const Eigen::Ref<const Eigen::MatrixXd>& QD,
               const Eigen::Ref<const Eigen::MatrixXd>* QDD)
      : q(Q.data()),
        qd(QD.data()),
        qdd(QDD ? QDD->data() : nullptr),
        ld(static_cast<long>(Q.outerStride())) {
    const bool same =
        Q.outerStride() == QD.outerStride() && (!QDD || Q.outerStride() == QDD->outerStride());
    if (same) return;
    qc = Q;
    qdc = QD;
    q = qc.data();
    qd = qdc.data();
    if (QDD) {
      qddc = *QDD;
      qdd = qddc.data();
    }
    ld = static_cast<long>(Q.rows());
  }
  // sample k's states as vectors (the one-sample kernels of another copy)
  void sample(Eigen::Index k, int n, Eigen::VectorXd& a, Eigen::VectorXd& b,
              Eigen::VectorXd& c) const {
    a.resize(n);
    b.resize(n);
    c.resize(n);
    for (int j = 0; j < n; ++j) {
      a[j] = q[k + ld * j];
      b[j] = qd[k + ld * j];
      c[j] = qdd ? qdd[k + ld * j] : 0.0;
    }
  }
};
}  // namespace

void torqueRegressors(const RobotModel& model, DynamicsData& d,
                      const Eigen::Ref<const Eigen::MatrixXd>& Q,
                      const Eigen::Ref<const Eigen::MatrixXd>& QD,
                      const Eigen::Ref<const Eigen::MatrixXd>& QDD, Eigen::Ref<Eigen::MatrixXd> Y) {
  prepare(model, d);
  const int n = d.n;
  const Eigen::Index K = Q.rows();
  check(Q.cols() == n && QD.cols() == n && QDD.cols() == n && QD.rows() == K && QDD.rows() == K,
        "torqueRegressors: Q, QD, QDD must be K x n");
  check(Y.rows() == K * n && Y.cols() == 10 * n, "torqueRegressors: Y must be K n x 10n");
  const SampleStates x(Q, QD, &QDD);
  if (const detail::LaneKernels* lanes = detail::activeLanes()) {
    lanes->torqueRegressors(model, d, static_cast<int>(K), x.q, x.qd, x.qdd, x.ld, Y.data(),
                            Y.outerStride(), n);
    return;
  }
  // another copy of the kernels (EXID_ISA): its own torqueRegressor, sample by sample
  Eigen::VectorXd qk, qdk, qddk;
  for (Eigen::Index k = 0; k < K; ++k) {
    x.sample(k, n, qk, qdk, qddk);
    kernels().torqueRegressor(model, d, qk.data(), qdk.data(), qddk.data(), Y.data() + k * n,
                              Y.outerStride());
  }
}

void inverseDynamicsSamples(const RobotModel& model, DynamicsData& d,
                            const Eigen::Ref<const Eigen::MatrixXd>& Q,
                            const Eigen::Ref<const Eigen::MatrixXd>& QD,
                            const Eigen::Ref<const Eigen::MatrixXd>& QDD,
                            Eigen::Ref<Eigen::MatrixXd> Tau, const Eigen::VectorXd* pi) {
  prepare(model, d);
  const int n = d.n;
  const Eigen::Index K = Q.rows();
  check(Q.cols() == n && QD.cols() == n && QDD.cols() == n && QD.rows() == K && QDD.rows() == K,
        "inverseDynamicsSamples: Q, QD, QDD must be K x n");
  check(Tau.rows() == K && Tau.cols() == n, "inverseDynamicsSamples: Tau must be K x n");
  if (pi) checkSize(*pi, 10 * n, "pi", "inverseDynamicsSamples");
  const SampleStates x(Q, QD, &QDD);
  const double* p = pi ? pi->data() : nullptr;
  if (const detail::LaneKernels* lanes = detail::activeLanes()) {
    lanes->inverseDynamics(model, d, static_cast<int>(K), x.q, x.qd, x.qdd, x.ld, p, Tau.data(),
                           Tau.outerStride());
    return;
  }
  Eigen::VectorXd qk, qdk, qddk, tau(n);
  for (Eigen::Index k = 0; k < K; ++k) {
    x.sample(k, n, qk, qdk, qddk);
    kernels().inverseDynamics(model, d, qk.data(), qdk.data(), qddk.data(), p, tau.data());
    Tau.row(k) = tau.transpose();
  }
}

void energyRegressors(const RobotModel& model, DynamicsData& d,
                      const Eigen::Ref<const Eigen::MatrixXd>& Q,
                      const Eigen::Ref<const Eigen::MatrixXd>& QD,
                      Eigen::Ref<Eigen::MatrixXd> kinetic, Eigen::Ref<Eigen::MatrixXd> potential) {
  prepare(model, d);
  const int n = d.n;
  const Eigen::Index K = Q.rows();
  check(Q.cols() == n && QD.cols() == n && QD.rows() == K, "energyRegressors: Q, QD must be K x n");
  check(kinetic.rows() == K && kinetic.cols() == 10 * n && potential.rows() == K &&
            potential.cols() == 10 * n,
        "energyRegressors: kinetic and potential must be K x 10n");
  const SampleStates x(Q, QD, nullptr);
  if (const detail::LaneKernels* lanes = detail::activeLanes();
      lanes && kinetic.outerStride() == potential.outerStride()) {
    lanes->energyRegressors(model, d, static_cast<int>(K), x.q, x.qd, x.ld, kinetic.data(),
                            potential.data(), kinetic.outerStride());
    return;
  }
  Eigen::VectorXd qk, qdk, unused;
  Eigen::RowVectorXd kin(10 * n), pot(10 * n);
  for (Eigen::Index k = 0; k < K; ++k) {
    x.sample(k, n, qk, qdk, unused);
    kernels().energyRegressor(model, d, qk.data(), qdk.data(), kin.data(), pot.data());
    kinetic.row(k) = kin;
    potential.row(k) = pot;
  }
}

void torqueRegressorVjps(const RobotModel& model, DynamicsData& d,
                         const Eigen::Ref<const Eigen::MatrixXd>& Q,
                         const Eigen::Ref<const Eigen::MatrixXd>& QD,
                         const Eigen::Ref<const Eigen::MatrixXd>& QDD,
                         const Eigen::Ref<const Eigen::MatrixXd>& G, Eigen::MatrixXd* d_q,
                         Eigen::MatrixXd* d_qd, Eigen::MatrixXd* d_qdd) {
  prepare(model, d);
  const int n = d.n;
  const Eigen::Index K = Q.rows();
  check(Q.cols() == n && QD.cols() == n && QDD.cols() == n && QD.rows() == K && QDD.rows() == K,
        "torqueRegressorVjps: Q, QD, QDD must be K x n");
  check(G.rows() == K * n && G.cols() == 10 * n, "torqueRegressorVjps: G must be K n x 10n");
  for (Eigen::MatrixXd* x : {d_q, d_qd, d_qdd})
    if (x) x->resize(K, n);
  auto out = [](Eigen::MatrixXd* x) { return x ? x->data() : nullptr; };
  const SampleStates x(Q, QD, &QDD);
  if (const detail::LaneKernels* lanes = detail::activeLanes()) {
    lanes->torqueRegressorVjps(model, d, static_cast<int>(K), x.q, x.qd, x.qdd, x.ld, G.data(),
                               G.outerStride(), n, out(d_q), out(d_qd), out(d_qdd), K);
    return;
  }
  // another copy of the kernels (EXID_ISA): its own torqueRegressorVjp, sample by sample
  Eigen::VectorXd qk, qdk, qddk, gq(n), gqd(n), gqdd(n);
  for (Eigen::Index k = 0; k < K; ++k) {
    x.sample(k, n, qk, qdk, qddk);
    kernels().torqueRegressorVjp(model, d, qk.data(), qdk.data(), qddk.data(), G.data() + k * n,
                                 G.outerStride(), gq.data(), gqd.data(), gqdd.data());
    if (d_q) d_q->row(k) = gq.transpose();
    if (d_qd) d_qd->row(k) = gqd.transpose();
    if (d_qdd) d_qdd->row(k) = gqdd.transpose();
  }
}

void energyRegressorVjps(const RobotModel& model, DynamicsData& d,
                         const Eigen::Ref<const Eigen::MatrixXd>& Q,
                         const Eigen::Ref<const Eigen::MatrixXd>& QD,
                         const Eigen::Ref<const Eigen::MatrixXd>& Gk,
                         const Eigen::Ref<const Eigen::MatrixXd>& Gu, Eigen::MatrixXd* d_q,
                         Eigen::MatrixXd* d_qd) {
  prepare(model, d);
  const int n = d.n;
  const Eigen::Index K = Q.rows();
  check(Q.cols() == n && QD.cols() == n && QD.rows() == K,
        "energyRegressorVjps: Q, QD must be K x n");
  check(Gk.rows() == K && Gk.cols() == 10 * n && Gu.rows() == K && Gu.cols() == 10 * n,
        "energyRegressorVjps: Gk and Gu must be K x 10n");
  for (Eigen::MatrixXd* x : {d_q, d_qd})
    if (x) x->resize(K, n);
  auto out = [](Eigen::MatrixXd* x) { return x ? x->data() : nullptr; };
  const SampleStates x(Q, QD, nullptr);
  const detail::LaneKernels* lanes = detail::activeLanes();
  if (lanes && Gk.outerStride() == Gu.outerStride()) {
    lanes->energyRegressorVjps(model, d, static_cast<int>(K), x.q, x.qd, x.ld, Gk.data(), Gu.data(),
                               Gk.outerStride(), out(d_q), out(d_qd), K);
    return;
  }
  Eigen::VectorXd qk, qdk, unused, gq(n), gqd(n);
  Eigen::RowVectorXd gk(10 * n), gu(10 * n);
  for (Eigen::Index k = 0; k < K; ++k) {
    x.sample(k, n, qk, qdk, unused);
    gk = Gk.row(k);
    gu = Gu.row(k);
    kernels().energyRegressorVjp(model, d, qk.data(), qdk.data(), gk.data(), gu.data(),
                                 d_q ? gq.data() : nullptr, gqd.data());
    if (d_q) d_q->row(k) = gq.transpose();
    if (d_qd) d_qd->row(k) = gqd.transpose();
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
  kernels().energyRegressor(model, d, q.data(), qd.data(), kinetic.data(), potential.data());
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
  Eigen::VectorXd tau(d.n);
  kernels().inverseDynamics(model, d, q.data(), qd.data(), qdd.data(), pi ? pi->data() : nullptr,
                            tau.data());
  return tau;
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

}  // namespace exid
