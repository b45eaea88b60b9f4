// exid — actuator-side regressor: rigid-body columns through the transmission plus drive columns.
#include "exid/drive.hpp"

#include <algorithm>
#include <string>
#include <vector>

#include "exid/closed_chain.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "internal.hpp"

namespace exid {

namespace {

inline double sgn(double x) { return coulombSign(x); }

void checkMeasured(const RobotModel& m, const Eigen::VectorXd& x, const char* what,
                   const char* fn) {
  if (x.size() != m.dof())  // the message is built only on failure (hot path)
    throw Error(std::string(fn) + ": " + what + " has " + std::to_string(x.size()) +
                " entries (expected " + std::to_string(m.dof()) + ")");
}

// A closed chain's actuated torque tau_a = G^T tau_tree (pi null: the model's parameters), its
// mass matrix G^T M G, and (dq, dqd) its derivatives in qa and qda through the loop constraints:
//   d tau_a/d qa_k = dG_k^T tau + G^T (Tq G e_k + Tqd dqd_k + Tqdd dqdd_k)
//   d tau_a/d qda  = G^T (Tqd G + Tqdd dqdd/dqda)
// with Tq, Tqd, Tqdd the tree's inverse-dynamics derivatives.
void closedTorque(const RobotModel& model, DynamicsData& data, const Eigen::VectorXd* pi,
                  const Eigen::VectorXd& qm, const Eigen::VectorXd& qdm,
                  const Eigen::VectorXd& qddm, Eigen::VectorXd* tau_m, Eigen::MatrixXd* dq,
                  Eigen::MatrixXd* dqd, Eigen::MatrixXd* dqdd, const char* fn) {
  checkMeasured(model, qm, "qm", fn);
  checkMeasured(model, qdm, "qdm", fn);
  checkMeasured(model, qddm, "qddm", fn);
  Eigen::VectorXd q, qd, qdd;
  Eigen::MatrixXd Gm;
  if (!dq && !dqd) {
    closedChainState(model, qm, &qdm, &qddm, &q, &qd, &qdd, &Gm, nullptr);
    *tau_m = Gm.transpose() * inverseDynamics(model, data, q, qd, qdd, pi);
    if (dqdd) *dqdd = Gm.transpose() * massMatrix(model, data, q, pi) * Gm;
    return;
  }
  std::vector<Eigen::MatrixXd> dG;
  Eigen::MatrixXd Dqd, Dqdd_a, Dqdd_ad;
  closedChainStateDerivatives(model, qm, qdm, qddm, &q, &qd, &qdd, &Gm, dq ? &dG : nullptr,
                              dq ? &Dqd : nullptr, dq ? &Dqdd_a : nullptr,
                              dqd ? &Dqdd_ad : nullptr);
  Eigen::VectorXd tau;
  Eigen::MatrixXd Tq, Tqd, Tqdd;
  inverseDynamicsDerivatives(model, data, q, qd, qdd, pi, &tau, dq ? &Tq : nullptr, &Tqd, &Tqdd);
  *tau_m = Gm.transpose() * tau;
  if (dq) {
    const int na = model.dof();
    dq->resize(na, na);
    const Eigen::MatrixXd inner = Tq * Gm + Tqd * Dqd + Tqdd * Dqdd_a;
    dq->noalias() = Gm.transpose() * inner;
    for (int k = 0; k < na; ++k) dq->col(k) += dG[static_cast<std::size_t>(k)].transpose() * tau;
  }
  if (dqd) *dqd = Gm.transpose() * (Tqd * Gm + Tqdd * Dqdd_ad);
  if (dqdd) *dqdd = Gm.transpose() * Tqdd * Gm;
}

// actuatorRegressorVjp of a closed chain: Y = [Gm^T Yt(q, qd, qdd) | drive columns], so
// <W, Y_rb> = <Gm W, Yt>; with vq, vqd, vqdd the tree VJP of Wt = Gm W_rb:
//   d/dqa   = [<dG_k W_rb, Yt>]_k + Gm^T vq + (dqd/dqa)^T vqd + (dqdd/dqa)^T vqdd
//   d/dqda  = Gm^T vqd + (dqdd/dqda)^T vqdd,   d/dqdda = Gm^T vqdd
void closedRegressorVjp(const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
                        const Eigen::VectorXd& qm, const Eigen::VectorXd& qdm,
                        const Eigen::VectorXd& qddm, const Eigen::MatrixXd& W,
                        Eigen::VectorXd* d_qm, Eigen::VectorXd* d_qdm, Eigen::VectorXd* d_qddm) {
  const int n = model.dof(), nt = model.numJoints();
  checkMeasured(model, qm, "qm", "actuatorRegressorVjp");
  checkMeasured(model, qdm, "qdm", "actuatorRegressorVjp");
  checkMeasured(model, qddm, "qddm", "actuatorRegressorVjp");
  Eigen::VectorXd q, qd, qdd;
  Eigen::MatrixXd Gm, Dqd, Dqdd_a, Dqdd_ad;
  std::vector<Eigen::MatrixXd> dG;
  closedChainStateDerivatives(model, qm, qdm, qddm, &q, &qd, &qdd, &Gm, d_qm ? &dG : nullptr,
                              d_qm ? &Dqd : nullptr, d_qm ? &Dqdd_a : nullptr,
                              d_qdm ? &Dqdd_ad : nullptr);
  const Eigen::MatrixXd Wt = Gm * W.leftCols(10 * nt);
  Eigen::VectorXd vq, vqd, vqdd;
  torqueRegressorVjp(model, data, q, qd, qdd, Wt, &vq, &vqd, &vqdd);
  if (d_qm) {
    Eigen::MatrixXd Yt(nt, 10 * nt);
    torqueRegressor(model, data, q, qd, qdd, Yt);
    *d_qm = Gm.transpose() * vq + Dqd.transpose() * vqd + Dqdd_a.transpose() * vqdd;
    for (int k = 0; k < n; ++k)
      (*d_qm)[k] += (dG[static_cast<std::size_t>(k)] * W.leftCols(10 * nt)).cwiseProduct(Yt).sum();
  }
  if (d_qdm) *d_qdm = Gm.transpose() * vqd + Dqdd_ad.transpose() * vqdd;
  if (d_qddm) *d_qddm = Gm.transpose() * vqdd;
  const int k = cols.count();
  for (int j = 0; j < n && k > 0; ++j) {
    int c = 10 * nt + k * j;
    if (cols.rotor_inertia) {
      if (d_qddm) (*d_qddm)[j] += W(j, c);
      ++c;
    }
    if (cols.coulomb) ++c;
    if (cols.viscous && d_qdm) (*d_qdm)[j] += W(j, c);
  }
}

}  // namespace

std::vector<std::string> parameterNames(const RobotModel& model, const DriveColumns& cols) {
  std::vector<std::string> names = model.inertialParameterNames();
  for (int j = 0; j < model.dof(); ++j) {
    const std::string k = std::to_string(j + 1);
    if (cols.rotor_inertia) names.push_back("Ia" + k);
    if (cols.coulomb) names.push_back("Fc" + k);
    if (cols.viscous) names.push_back("Fv" + k);
    if (cols.offset) names.push_back("OFF" + k);
  }
  return names;
}

bool isDriveParameterName(const std::string& name) {
  // (FcP, FcN, Fs, FcL: the `differential` model's asymmetric Coulomb, Stribeck and
  // load-dependent Coulomb columns)
  for (const char* pre : {"Ia", "Fc", "Fv", "OFF", "FcP", "FcN", "Fs", "FcL"})
    if (isIndexedParameterName(name, pre)) return true;
  return false;
}

bool isIndexedParameterName(const std::string& name, const char* prefix) {
  const std::size_t n = std::char_traits<char>::length(prefix);
  return name.size() > n && name.compare(0, n, prefix) == 0 && name[n] != '0' &&
         name.find_first_not_of("0123456789", n) == std::string::npos;
}

int torqueColumnKind(const std::string& name) {
  return isIndexedParameterName(name, "dK") ? 1 : (isIndexedParameterName(name, "FcL") ? 2 : 0);
}

int numParameters(const RobotModel& model, const DriveColumns& cols) {
  return model.numInertialParameters() + cols.count() * model.dof();
}

Eigen::VectorXd parameterValues(const RobotModel& model, const DriveColumns& cols) {
  const int n = model.dof();
  Eigen::VectorXd v(numParameters(model, cols));
  v.head(model.numInertialParameters()) = model.inertialParameters();
  int c = model.numInertialParameters();
  for (int j = 0; j < n; ++j) {
    const Drive dr =
        j < static_cast<int>(model.drives.size()) ? model.drives[static_cast<size_t>(j)] : Drive{};
    if (cols.rotor_inertia) v[c++] = dr.rotor_inertia;
    if (cols.coulomb) v[c++] = dr.coulomb;
    if (cols.viscous) v[c++] = dr.viscous;
    if (cols.offset) v[c++] = dr.offset;
  }
  return v;
}

void measuredToJoint(const RobotModel& model, const Eigen::VectorXd& qm, const Eigen::VectorXd& qdm,
                     const Eigen::VectorXd& qddm, Eigen::VectorXd* q, Eigen::VectorXd* qd,
                     Eigen::VectorXd* qdd) {
  if (model.hasLoops()) {
    checkMeasured(model, qm, "qm", "measuredToJoint");
    if (qd) checkMeasured(model, qdm, "qdm", "measuredToJoint");
    if (qdd) checkMeasured(model, qddm, "qddm", "measuredToJoint");
    closedChainState(model, qm, qd || qdd ? &qdm : nullptr, qdd ? &qddm : nullptr, q, qd, qdd,
                     nullptr, nullptr);
    return;
  }
  const bool T = model.hasTransmission();
  if (q) {
    checkMeasured(model, qm, "qm", "measuredToJoint");
    if (T)
      q->noalias() = model.transmission * qm;
    else
      *q = qm;
    if (model.transmission_offset.size() == qm.size()) *q += model.transmission_offset;
  }
  if (qd) {
    checkMeasured(model, qdm, "qdm", "measuredToJoint");
    if (T)
      qd->noalias() = model.transmission * qdm;
    else
      *qd = qdm;
  }
  if (qdd) {
    checkMeasured(model, qddm, "qddm", "measuredToJoint");
    if (T)
      qdd->noalias() = model.transmission * qddm;
    else
      *qdd = qddm;
  }
}

void jointToMeasured(const RobotModel& model, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                     const Eigen::VectorXd& qdd, Eigen::VectorXd* qm, Eigen::VectorXd* qdm,
                     Eigen::VectorXd* qddm) {
  if (model.hasLoops()) {
    const int nt = model.numJoints(), n = model.dof();
    const Eigen::VectorXd* in[3] = {&q, &qd, &qdd};
    Eigen::VectorXd* out[3] = {qm, qdm, qddm};
    // tree coordinates (numJoints) -> the actuated ones; the actuated joints' own coordinates
    // (dof: what `limits` bound, e.g. a trajectory drawn inside them) are the measured ones
    for (int w = 0; w < 3; ++w) {
      if (!out[w]) continue;
      const Eigen::Index sz = in[w]->size();
      if (sz == n) {
        *out[w] = *in[w];
        continue;
      }
      check(sz == nt, "jointToMeasured: robot '" + model.name + "' (a closed chain) takes " +
                          std::to_string(nt) + " tree coordinates or " + std::to_string(n) +
                          " actuated ones (found " + std::to_string(sz) + ")");
      out[w]->resize(n);
      for (int k = 0; k < n; ++k) (*out[w])[k] = (*in[w])[model.actuatedJoint(k)];
    }
    return;
  }
  if (!model.hasTransmission()) {
    if (qm)
      *qm = model.transmission_offset.size() == q.size()
                ? Eigen::VectorXd(q - model.transmission_offset)
                : q;
    if (qdm) *qdm = qd;
    if (qddm) *qddm = qdd;
    return;
  }
  Eigen::FullPivLU<Eigen::MatrixXd> lu(model.transmission);
  check(lu.isInvertible(), "jointToMeasured: the transmission matrix of robot '" + model.name +
                               "' is singular (expected an invertible n x n matrix)");
  if (qm) {
    checkMeasured(model, q, "q", "jointToMeasured");
    *qm = lu.solve(model.transmission_offset.size() == q.size()
                       ? Eigen::VectorXd(q - model.transmission_offset)
                       : q);
  }
  if (qdm) {
    checkMeasured(model, qd, "qd", "jointToMeasured");
    *qdm = lu.solve(qd);
  }
  if (qddm) {
    checkMeasured(model, qdd, "qdd", "jointToMeasured");
    *qddm = lu.solve(qdd);
  }
}

void jointGradientToMeasured(const RobotModel& model, const Eigen::VectorXd& qm,
                             const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                             Eigen::VectorXd* gq, Eigen::VectorXd* gqd, Eigen::VectorXd* gqdd) {
  check(gq != nullptr, "jointGradientToMeasured: gq must be given");
  if (!model.hasLoops()) {
    if (!model.hasTransmission()) return;
    for (Eigen::VectorXd* g : {gq, gqd, gqdd})
      if (g) *g = (model.transmission.transpose() * *g).eval();
    return;
  }
  const int nt = model.numJoints();
  for (Eigen::VectorXd* g : {gq, gqd, gqdd})
    check(!g || g->size() == nt, "jointGradientToMeasured: robot '" + model.name +
                                     "' (a closed chain): a gradient has " +
                                     std::to_string(g ? g->size() : 0) + " entries (expected " +
                                     std::to_string(nt) + ", the tree's joints)");
  checkMeasured(model, qm, "qm", "jointGradientToMeasured");
  checkMeasured(model, qdm, "qdm", "jointGradientToMeasured");
  checkMeasured(model, qddm, "qddm", "jointGradientToMeasured");
  Eigen::MatrixXd Gm, Dqd, Dqdd_a, Dqdd_ad;
  closedChainStateDerivatives(model, qm, qdm, qddm, nullptr, nullptr, nullptr, &Gm, nullptr,
                              gqd ? &Dqd : nullptr, gqdd ? &Dqdd_a : nullptr,
                              gqdd ? &Dqdd_ad : nullptr);
  // d/dqa = G^T gq + (dqd/dqa)^T gqd + (dqdd/dqa)^T gqdd, d/dqda = G^T gqd + (dqdd/dqda)^T gqdd,
  // d/dqdda = G^T gqdd
  Eigen::VectorXd a = Gm.transpose() * *gq;
  if (gqd) a += Dqd.transpose() * *gqd;
  if (gqdd) a += Dqdd_a.transpose() * *gqdd;
  if (gqd) {
    Eigen::VectorXd ad = Gm.transpose() * *gqd;
    if (gqdd) ad += Dqdd_ad.transpose() * *gqdd;
    *gqd = ad;
  }
  if (gqdd) *gqdd = (Gm.transpose() * *gqdd).eval();
  *gq = a;
}

namespace {
// out = T^T Yj for one sample's joint regressor Yj (n x 10n, leading dimension ldj) into out
// (leading dimension ldo): each coefficient summed over k = 0 .. n - 1 in order, the zeros of
// the transmission skipped (a transmission is mostly zeros). `count` consecutive samples (sample
// s's n rows start at row s n of Yj and of out). One definition for actuatorRegressor and
// actuatorRegressors, so that both give the same bits.
void transmissionTransposeTimes(const Eigen::MatrixXd& T, const double* Yj, long ldj, double* out,
                                long ldo, int count = 1) {
  const int n = static_cast<int>(T.rows());
  for (int i = 0; i < n; ++i) {
    int nz[64];
    double t[64];
    int m = 0;
    for (int k = 0; k < n; ++k)
      if (T(k, i) != 0.0 && m < 64) {
        nz[m] = k;
        t[m++] = T(k, i);
      }
    if (m == 64 && n > 64) {  // (a dense transmission of more than 64 joints: every term)
      for (int c = 0; c < 10 * n; ++c)
        for (int s = 0; s < count; ++s) {
          double acc = 0.0;
          for (int k = 0; k < n; ++k) acc += T(k, i) * Yj[s * n + k + ldj * c];
          out[s * n + i + ldo * c] = acc;
        }
      continue;
    }
    // column by column, the samples within (each column's outputs are written together: its
    // cache lines once, whatever the stride between columns)
    for (int c = 0; c < 10 * n; ++c) {
      const double* y = Yj + ldj * c;
      double* o = out + i + ldo * c;
      for (int s = 0; s < count; ++s, y += n, o += n) {
        double acc = 0.0;
        for (int e = 0; e < m; ++e) acc += t[e] * y[nz[e]];
        *o = acc;
      }
    }
  }
}
}  // namespace

namespace {
// The joint states of the samples k0 .. k0 + b - 1 (rows of Qm, QDm, QDDm), as measuredToJoint
// gives each, into the first b rows of *Qj, *QDj, *QDDj (a tree's: one joint per coordinate).
void jointStates(const RobotModel& model, const Eigen::Ref<const Eigen::MatrixXd>& Qm,
                 const Eigen::Ref<const Eigen::MatrixXd>& QDm,
                 const Eigen::Ref<const Eigen::MatrixXd>& QDDm, Eigen::Index k0, Eigen::Index b,
                 Eigen::MatrixXd* Qj, Eigen::MatrixXd* QDj, Eigen::MatrixXd* QDDj) {
  Eigen::VectorXd qm, qdm, qddm, q, qd, qdd;
  for (Eigen::Index k = 0; k < b; ++k) {
    qm = Qm.row(k0 + k).transpose();
    qdm = QDm.row(k0 + k).transpose();
    qddm = QDDm.row(k0 + k).transpose();
    measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
    Qj->row(k) = q.transpose();
    QDj->row(k) = qd.transpose();
    QDDj->row(k) = qdd.transpose();
  }
}
}  // namespace

void actuatorRegressors(const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
                        const Eigen::Ref<const Eigen::MatrixXd>& Qm,
                        const Eigen::Ref<const Eigen::MatrixXd>& QDm,
                        const Eigen::Ref<const Eigen::MatrixXd>& QDDm,
                        Eigen::Ref<Eigen::MatrixXd> Y) {
  const int n = model.dof();
  const Eigen::Index K = Qm.rows();
  check(
      Qm.cols() == n && QDm.cols() == n && QDDm.cols() == n && QDm.rows() == K && QDDm.rows() == K,
      "actuatorRegressors: Qm, QDm, QDDm must be K x n");
  check(Y.rows() == K * n && Y.cols() == numParameters(model, cols),
        "actuatorRegressors: Y must be K n x numParameters(model, cols)");
  Eigen::VectorXd qm(n), qdm(n), qddm(n);
  if (model.hasLoops()) {
    for (Eigen::Index k = 0; k < K; ++k) {
      qm = Qm.row(k).transpose();
      qdm = QDm.row(k).transpose();
      qddm = QDDm.row(k).transpose();
      actuatorRegressor(model, data, cols, qm, qdm, qddm, Y.middleRows(k * n, n));
    }
    return;
  }
  if (model.hasTransmission() || model.transmission_offset.size() == n) {
    // A block of samples at a time: each one's joint state as actuatorRegressor computes it, the
    // block's joint regressors at once, then each sample's through the transmission with the
    // same function as there: the same bits.
    constexpr Eigen::Index kBlock = 64;
    const bool T = model.hasTransmission();
    Eigen::MatrixXd Qj(kBlock, n), QDj(kBlock, n), QDDj(kBlock, n), Yb(kBlock * n, 10 * n);
    for (Eigen::Index k0 = 0; k0 < K; k0 += kBlock) {
      const Eigen::Index b = std::min(kBlock, K - k0);
      jointStates(model, Qm, QDm, QDDm, k0, b, &Qj, &QDj, &QDDj);
      torqueRegressors(model, data, Qj.topRows(b), QDj.topRows(b), QDDj.topRows(b),
                       Yb.topRows(b * n));
      if (T)
        transmissionTransposeTimes(model.transmission, Yb.data(), Yb.outerStride(),
                                   Y.data() + k0 * n, Y.outerStride(), static_cast<int>(b));
      else
        Y.middleRows(k0 * n, b * n).leftCols(10 * n) = Yb.topRows(b * n);
    }
  } else {
    torqueRegressors(model, data, Qm, QDm, QDDm, Y.leftCols(10 * n));
  }
  const int c = cols.count();
  if (c == 0) return;
  Y.rightCols(c * n).setZero();
  for (Eigen::Index k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j) {
      const DriveColumnValues dv = driveColumnValues(cols, QDm(k, j), QDDm(k, j));
      for (int e = 0; e < dv.count; ++e) Y(k * n + j, 10 * n + c * j + e) = dv.v[e];
    }
}

void actuatorRegressor(const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
                       const Eigen::VectorXd& qm, const Eigen::VectorXd& qdm,
                       const Eigen::VectorXd& qddm, Eigen::Ref<Eigen::MatrixXd> Y) {
  const int n = model.dof();
  check(Y.rows() == n && Y.cols() == numParameters(model, cols),
        "actuatorRegressor: Y must be n x numParameters(model, cols)");
  checkMeasured(model, qm, "qm", "actuatorRegressor");
  checkMeasured(model, qdm, "qdm", "actuatorRegressor");
  checkMeasured(model, qddm, "qddm", "actuatorRegressor");
  const int nt = model.numJoints();
  if (model.hasLoops()) {
    Eigen::VectorXd& q = detail::scratchVector(data, 0);
    Eigen::VectorXd& qd = detail::scratchVector(data, 1);
    Eigen::VectorXd& qdd = detail::scratchVector(data, 2);
    Eigen::MatrixXd& Gm = detail::scratchMatrix(data, 1);
    closedChainState(model, qm, &qdm, &qddm, &q, &qd, &qdd, &Gm, nullptr);
    Eigen::MatrixXd& Yj = detail::scratchMatrix(data, 0);
    Yj.resize(nt, 10 * nt);
    torqueRegressor(model, data, q, qd, qdd, Yj);
    Y.leftCols(10 * nt).noalias() = Gm.transpose() * Yj;  // tau_a = G^T tau_tree
  } else if (model.hasTransmission() || model.transmission_offset.size() == n) {
    Eigen::VectorXd& q = detail::scratchVector(data, 0);
    Eigen::VectorXd& qd = detail::scratchVector(data, 1);
    Eigen::VectorXd& qdd = detail::scratchVector(data, 2);
    measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
    if (model.hasTransmission()) {
      Eigen::MatrixXd& Yj = detail::scratchMatrix(data, 0);
      Yj.resize(n, 10 * n);
      torqueRegressor(model, data, q, qd, qdd, Yj);
      // (a product of depth n, coefficient by coefficient over the transmission's non-zeros;
      // the blocked product packs its operands first, which costs more than it saves here)
      transmissionTransposeTimes(model.transmission, Yj.data(), Yj.outerStride(), Y.data(),
                                 Y.outerStride());
    } else {
      torqueRegressor(model, data, q, qd, qdd, Y.leftCols(10 * n));
    }
  } else {
    torqueRegressor(model, data, qm, qdm, qddm, Y.leftCols(10 * n));
  }
  const int k = cols.count();
  if (k == 0) return;
  Y.rightCols(k * n).setZero();
  for (int j = 0; j < n; ++j) {
    const DriveColumnValues dv = driveColumnValues(cols, qdm[j], qddm[j]);
    for (int e = 0; e < dv.count; ++e) Y(j, 10 * nt + k * j + e) = dv.v[e];
  }
}

void actuatorRegressorVjp(const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
                          const Eigen::VectorXd& qm, const Eigen::VectorXd& qdm,
                          const Eigen::VectorXd& qddm, const Eigen::MatrixXd& G,
                          Eigen::VectorXd* d_qm, Eigen::VectorXd* d_qdm, Eigen::VectorXd* d_qddm) {
  const int n = model.dof();
  check(G.rows() == n && G.cols() == numParameters(model, cols),
        "actuatorRegressorVjp: G must be n x numParameters(model, cols)");
  if (model.hasLoops()) {
    closedRegressorVjp(model, data, cols, qm, qdm, qddm, G, d_qm, d_qdm, d_qddm);
    return;
  }
  Eigen::VectorXd& q = detail::scratchVector(data, 0);
  Eigen::VectorXd& qd = detail::scratchVector(data, 1);
  Eigen::VectorXd& qdd = detail::scratchVector(data, 2);
  measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
  const bool T = model.hasTransmission();
  Eigen::MatrixXd& Gj = detail::scratchMatrix(data, 1);
  if (T)
    Gj.noalias() = model.transmission.lazyProduct(G.leftCols(10 * n));  // <G, T^T Y> = <T G, Y>
  else
    Gj = G.leftCols(10 * n);
  torqueRegressorVjp(model, data, q, qd, qdd, Gj, d_qm, d_qdm, d_qddm);
  if (T) {
    Eigen::VectorXd& tmp = detail::scratchVector(data, 3);
    for (Eigen::VectorXd* x : {d_qm, d_qdm, d_qddm})
      if (x) {
        tmp.noalias() = model.transmission.transpose() * *x;
        *x = tmp;
      }
  }
  const int k = cols.count();
  for (int j = 0; j < n && k > 0; ++j) {
    int c = 10 * n + k * j;
    if (cols.rotor_inertia) {
      if (d_qddm) (*d_qddm)[j] += G(j, c);
      ++c;
    }
    if (cols.coulomb) ++c;
    if (cols.viscous && d_qdm) (*d_qdm)[j] += G(j, c);
  }
}

void actuatorRegressorVjps(const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
                           const Eigen::Ref<const Eigen::MatrixXd>& Qm,
                           const Eigen::Ref<const Eigen::MatrixXd>& QDm,
                           const Eigen::Ref<const Eigen::MatrixXd>& QDDm,
                           const Eigen::Ref<const Eigen::MatrixXd>& G, Eigen::MatrixXd* d_qm,
                           Eigen::MatrixXd* d_qdm, Eigen::MatrixXd* d_qddm) {
  const int n = model.dof();
  const Eigen::Index K = Qm.rows();
  check(
      Qm.cols() == n && QDm.cols() == n && QDDm.cols() == n && QDm.rows() == K && QDDm.rows() == K,
      "actuatorRegressorVjps: Qm, QDm, QDDm must be K x n");
  check(G.rows() == K * n && G.cols() == numParameters(model, cols),
        "actuatorRegressorVjps: G must be K n x numParameters(model, cols)");
  Eigen::MatrixXd* outs[3] = {d_qm, d_qdm, d_qddm};
  for (Eigen::MatrixXd* x : outs)
    if (x) x->resize(K, n);
  Eigen::VectorXd qm(n), qdm(n), qddm(n), g[3];
  if (model.hasLoops()) {  // (sample by sample: the loop constraints)
    Eigen::MatrixXd Gk;
    for (Eigen::Index k = 0; k < K; ++k) {
      qm = Qm.row(k).transpose();
      qdm = QDm.row(k).transpose();
      qddm = QDDm.row(k).transpose();
      Gk = G.middleRows(k * n, n);
      actuatorRegressorVjp(model, data, cols, qm, qdm, qddm, Gk, d_qm ? &g[0] : nullptr,
                           d_qdm ? &g[1] : nullptr, d_qddm ? &g[2] : nullptr);
      for (int r = 0; r < 3; ++r)
        if (outs[r]) outs[r]->row(k) = g[r].transpose();
    }
    return;
  }
  // A block of samples at a time: each one's joint state and joint-space G as
  // actuatorRegressorVjp computes them, the block's VJPs at once, then each sample's gradients
  // through the transmission and the drive columns as there: the same bits. (16 samples: the
  // buffers stay small, reused memory rather than new pages at every call.)
  constexpr Eigen::Index kBlock = 16;
  const bool T = model.hasTransmission();
  const int nt = n;  // (a tree: one joint per coordinate)
  Eigen::MatrixXd Qj(kBlock, nt), QDj(kBlock, nt), QDDj(kBlock, nt), Gj(kBlock * nt, 10 * nt);
  Eigen::MatrixXd B[3];
  Eigen::VectorXd tmp(n);
  for (Eigen::Index k0 = 0; k0 < K; k0 += kBlock) {
    const Eigen::Index b = std::min(kBlock, K - k0);
    jointStates(model, Qm, QDm, QDDm, k0, b, &Qj, &QDj, &QDDj);
    for (Eigen::Index k = 0; k < b; ++k) {
      const auto Gs = G.block((k0 + k) * n, 0, n, 10 * nt);
      if (T)  // <G, T^T Y> = <T G, Y>
        Gj.middleRows(k * nt, nt).noalias() = model.transmission.lazyProduct(Gs);
      else
        Gj.middleRows(k * nt, nt) = Gs;
    }
    torqueRegressorVjps(model, data, Qj.topRows(b), QDj.topRows(b), QDDj.topRows(b),
                        Gj.topRows(b * nt), d_qm ? &B[0] : nullptr, d_qdm ? &B[1] : nullptr,
                        d_qddm ? &B[2] : nullptr);
    for (int r = 0; r < 3; ++r) {
      if (!outs[r]) continue;
      for (Eigen::Index k = 0; k < b; ++k) {
        g[r] = B[r].row(k).transpose();
        if (T) {
          tmp.noalias() = model.transmission.transpose() * g[r];
          g[r] = tmp;
        }
        outs[r]->row(k0 + k) = g[r].transpose();
      }
    }
  }
  const int k = cols.count();
  for (Eigen::Index s = 0; s < K && k > 0; ++s)
    for (int j = 0; j < n; ++j) {
      int c = 10 * n + k * j;
      if (cols.rotor_inertia) {
        if (d_qddm) (*d_qddm)(s, j) += G(s * n + j, c);
        ++c;
      }
      if (cols.coulomb) ++c;
      if (cols.viscous && d_qdm) (*d_qdm)(s, j) += G(s * n + j, c);
    }
}

Eigen::VectorXd actuatorTorque(const RobotModel& model, DynamicsData& data,
                               const DriveColumns& cols, const Eigen::VectorXd& qm,
                               const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm) {
  const int n = model.dof();
  Eigen::VectorXd q, qd, qdd;
  Eigen::VectorXd tm;
  if (model.hasLoops()) {
    checkMeasured(model, qm, "qm", "actuatorTorque");
    checkMeasured(model, qdm, "qdm", "actuatorTorque");
    checkMeasured(model, qddm, "qddm", "actuatorTorque");
    Eigen::MatrixXd Gm;
    closedChainState(model, qm, &qdm, &qddm, &q, &qd, &qdd, &Gm, nullptr);
    tm = Gm.transpose() * inverseDynamics(model, data, q, qd, qdd);
  } else {
    measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
    const Eigen::VectorXd tau = inverseDynamics(model, data, q, qd, qdd);
    tm = model.hasTransmission() ? Eigen::VectorXd(model.transmission.transpose() * tau) : tau;
  }
  for (int j = 0; j < n; ++j) {
    const Drive dr =
        j < static_cast<int>(model.drives.size()) ? model.drives[static_cast<size_t>(j)] : Drive{};
    if (cols.rotor_inertia) tm[j] += dr.rotor_inertia * qddm[j];
    if (cols.coulomb) tm[j] += dr.coulomb * sgn(qdm[j]);
    if (cols.viscous) tm[j] += dr.viscous * qdm[j];
    if (cols.offset) tm[j] += dr.offset;
  }
  return tm;
}

void actuatorTorqueDerivatives(const RobotModel& model, DynamicsData& data,
                               const DriveColumns& cols, const Eigen::VectorXd& qm,
                               const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                               Eigen::VectorXd* tau_m, Eigen::MatrixXd* dq, Eigen::MatrixXd* dqd,
                               Eigen::MatrixXd* dqdd) {
  const int n = model.dof();
  check(tau_m != nullptr, "actuatorTorqueDerivatives: tau_m must be given");
  Eigen::VectorXd& q = detail::scratchVector(data, 0);
  Eigen::VectorXd& qd = detail::scratchVector(data, 1);
  Eigen::VectorXd& qdd = detail::scratchVector(data, 2);
  Eigen::VectorXd& tau = detail::scratchVector(data, 3);
  if (model.hasLoops()) {
    closedTorque(model, data, nullptr, qm, qdm, qddm, tau_m, dq, dqd, dqdd,
                 "actuatorTorqueDerivatives");
  } else {
    measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
    inverseDynamicsDerivatives(model, data, q, qd, qdd, nullptr, &tau, dq, dqd, dqdd);
  }
  if (model.hasLoops()) {
  } else if (model.hasTransmission()) {
    const Eigen::MatrixXd& T = model.transmission;
    *tau_m = T.transpose() * tau;
    for (Eigen::MatrixXd* x : {dq, dqd, dqdd})
      if (x) *x = T.transpose() * *x * T;  // q = T qm + q0, tau_m = T^T tau
  } else {
    *tau_m = tau;
  }
  for (int j = 0; j < n; ++j) {
    const Drive dr =
        j < static_cast<int>(model.drives.size()) ? model.drives[static_cast<size_t>(j)] : Drive{};
    if (cols.rotor_inertia) {
      (*tau_m)[j] += dr.rotor_inertia * qddm[j];
      if (dqdd) (*dqdd)(j, j) += dr.rotor_inertia;
    }
    if (cols.coulomb) (*tau_m)[j] += dr.coulomb * sgn(qdm[j]);
    if (cols.viscous) {
      (*tau_m)[j] += dr.viscous * qdm[j];
      if (dqd) (*dqd)(j, j) += dr.viscous;
    }
    if (cols.offset) (*tau_m)[j] += dr.offset;
  }
}

void actuatorTorqueWith(const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
                        const Eigen::VectorXd& params, const Eigen::VectorXd& qm,
                        const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                        Eigen::VectorXd* tau_m, Eigen::MatrixXd* dq, Eigen::MatrixXd* dqd,
                        Eigen::MatrixXd* dqdd) {
  const int n = model.dof();
  check(tau_m != nullptr, "actuatorTorqueWith: tau_m must be given");
  if (params.size() != numParameters(model, cols))
    throw Error("actuatorTorqueWith: params has " + std::to_string(params.size()) +
                " entries (expected " + std::to_string(numParameters(model, cols)) + ")");
  Eigen::VectorXd& q = detail::scratchVector(data, 0);
  Eigen::VectorXd& qd = detail::scratchVector(data, 1);
  Eigen::VectorXd& qdd = detail::scratchVector(data, 2);
  Eigen::VectorXd& tau = detail::scratchVector(data, 3);
  const int nt = model.numJoints();
  const Eigen::VectorXd pi = params.head(10 * nt);
  if (model.hasLoops()) {
    closedTorque(model, data, &pi, qm, qdm, qddm, tau_m, dq, dqd, dqdd, "actuatorTorqueWith");
  } else if (dq || dqd) {
    measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
    inverseDynamicsDerivatives(model, data, q, qd, qdd, &pi, &tau, dq, dqd, dqdd);
  } else {
    measuredToJoint(model, qm, qdm, qddm, &q, &qd, &qdd);
    tau = inverseDynamics(model, data, q, qd, qdd, &pi);
    if (dqdd) *dqdd = massMatrix(model, data, q, &pi);
  }
  if (model.hasLoops()) {
  } else if (model.hasTransmission()) {
    const Eigen::MatrixXd& T = model.transmission;
    *tau_m = T.transpose() * tau;
    for (Eigen::MatrixXd* x : {dq, dqd, dqdd})
      if (x) *x = T.transpose() * *x * T;  // q = T qm + q0, tau_m = T^T tau
  } else {
    *tau_m = tau;
  }
  const int k = cols.count();
  for (int j = 0; j < n && k > 0; ++j) {
    int c = 10 * nt + k * j;
    if (cols.rotor_inertia) {
      (*tau_m)[j] += params[c] * qddm[j];
      if (dqdd) (*dqdd)(j, j) += params[c];
      ++c;
    }
    if (cols.coulomb) (*tau_m)[j] += params[c++] * sgn(qdm[j]);
    if (cols.viscous) {
      (*tau_m)[j] += params[c] * qdm[j];
      if (dqd) (*dqd)(j, j) += params[c];
      ++c;
    }
    if (cols.offset) (*tau_m)[j] += params[c];
  }
}

}  // namespace exid
