// exid — the exact vector-Jacobian products (hand-written reverse mode) of the torque, energy,
// wrench and payload-torque regressors: forward pass, then the adjoints of the body kinematics
// carried back through the recursion. Conventions and the shared recursions: rigid_body.hpp.
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "kernel_table.hpp"
#include "rigid_body.hpp"

namespace exid {

using namespace detail;

namespace {

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
  outputs(d_q, n);
  outputs(d_qd, n);
  outputs(d_qdd, n);
  kernels().torqueRegressorVjp(model, d, q.data(), qd.data(), qdd.data(), G.data(), G.outerStride(),
                               d_q ? d_q->data() : nullptr, d_qd ? d_qd->data() : nullptr,
                               d_qdd ? d_qdd->data() : nullptr);
}

void energyRegressorVjp(const RobotModel& model, DynamicsData& d, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& qd, const Eigen::RowVectorXd& Gk,
                        const Eigen::RowVectorXd& Gu, Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd) {
  prepare(model, d);
  const int n = d.n;
  checkState(model, q, &qd, nullptr, "energyRegressorVjp");
  check(Gk.size() == 10 * n && Gu.size() == 10 * n,
        "energyRegressorVjp: Gk and Gu must have 10n entries");
  outputs(d_q, n);
  outputs(d_qd, n);
  kernels().energyRegressorVjp(model, d, q.data(), qd.data(), Gk.data(), Gu.data(),
                               d_q ? d_q->data() : nullptr, d_qd ? d_qd->data() : nullptr);
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
