// exid — the full actuator-side regressor: rigid-body columns mapped through the transmission,
// plus drive columns (rotor inertia Ia, Coulomb Fc, viscous Fv, offset OFF) per measured
// coordinate.
//
// Measured coordinates qm (motor-side or absolute angles) and joint coordinates q:
//   q = T qm + q0,  qd = T qdm,  qdd = T qddm,  tau_m = T^T tau   (T = model.transmission)
// Full parameter vector: the 10n standard inertial parameters, then for each measured
// coordinate j the enabled drive parameters in the order Ia_j, Fc_j, Fv_j, OFF_j.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/export.hpp"

namespace exid {

/// The sign of a velocity in a Coulomb friction term (every model, regressor and simulation):
/// zero below kCoulombDeadband [rad/s or m/s], where a joint stands still. A standstill in a
/// recording differentiates to velocities of rounding size (1e-14 rad/s from a filtered constant
/// position) whose sign is noise; +-1 there would put the full Coulomb torque into every
/// standing sample's row, which the torque at rest does not hold (a 20 s standstill before 4 s
/// of motion made filtered_ls's defaults 17 times worse). No joint moves at 1e-9 rad/s in a
/// motion that identifies friction.
inline constexpr double kCoulombDeadband = 1e-9;
inline double coulombSign(double v) {
  return v > kCoulombDeadband ? 1.0 : (v < -kCoulombDeadband ? -1.0 : 0.0);
}

struct EXID_API DriveColumns {
  bool rotor_inertia = false;
  bool coulomb = false;
  bool viscous = false;
  bool offset = false;
  int count() const { return rotor_inertia + coulomb + viscous + offset; }
};

/// The enabled drive columns of one measured coordinate moving at qdm, qddm, in parameterNames'
/// order: Ia (qddm), Fc (coulombSign(qdm)), Fv (qdm), OFF (1); v[0 .. count). The one definition
/// of the drive columns (actuatorRegressor; the `floating_base` model's joint rows).
struct DriveColumnValues {
  double v[4] = {0.0, 0.0, 0.0, 0.0};
  int count = 0;
};
inline DriveColumnValues driveColumnValues(const DriveColumns& cols, double qdm, double qddm) {
  DriveColumnValues r;
  if (cols.rotor_inertia) r.v[r.count++] = qddm;
  if (cols.coulomb) r.v[r.count++] = coulombSign(qdm);
  if (cols.viscous) r.v[r.count++] = qdm;
  if (cols.offset) r.v[r.count++] = 1.0;
  return r;
}
/// Drive j of the robot (0-based), or a drive without terms where the description gives none.
inline Drive driveAt(const RobotModel& model, int j) {
  return j < static_cast<int>(model.drives.size()) ? model.drives[static_cast<std::size_t>(j)]
                                                   : Drive{};
}
/// A drive's own torque at qdm, qddm: Ia qddm + Fc coulombSign(qdm) + Fv qdm + OFF (every term
/// of the description, as actuatorTorque adds them).
inline double driveTorque(const Drive& d, double qdm, double qddm) {
  return d.rotor_inertia * qddm + d.coulomb * coulombSign(qdm) + d.viscous * qdm + d.offset;
}
/// The sign in a smoothed Coulomb column (the models' coulomb_smoothing_rad_s): tanh(v / eps)
/// for a width eps > 0, else coulombSign(v); *ds_deps (when given) its derivative with respect
/// to eps (0 for the sign).
inline double smoothCoulombSign(double v, double eps, double* ds_deps = nullptr) {
  const double sg = eps > 0 ? std::tanh(v / eps) : coulombSign(v);
  if (ds_deps) *ds_deps = eps > 0 ? -(v / (eps * eps)) * (1.0 - sg * sg) : 0.0;
  return sg;
}
/// The nonlinear friction columns of a drive (the `differential` and `floating_base` models'
/// coulomb_asymmetric, coulomb_smoothing_rad_s and stribeck), per joint in this order: with
/// `coulomb`, the Coulomb columns shaped by s = smoothCoulombSign(v, eps) (eps = 0: sign(v)):
/// one, s (Fc), or with `asymmetric` two, (1 + s)/2 and -(1 - s)/2 (FcP, FcN: the levels for
/// v > 0 and v < 0); then with `stribeck` one, s exp(-(|v| / vs)^delta) (Fs).
struct FrictionColumns {
  bool coulomb = false, asymmetric = false, stribeck = false;
  double delta = 2.0;  // the Stribeck exponent

  int coulombCount() const { return coulomb ? (asymmetric ? 2 : 1) : 0; }
  int perJoint() const { return coulombCount() + (stribeck ? 1 : 0); }
  /// The names of joint j's (0-based) columns.
  std::vector<std::string> names(int j) const {
    const std::string k = std::to_string(j + 1);
    std::vector<std::string> out;
    if (coulomb && !asymmetric) out.push_back("Fc" + k);
    if (coulomb && asymmetric) {
      out.push_back("FcP" + k);
      out.push_back("FcN" + k);
    }
    if (stribeck) out.push_back("Fs" + k);
    return out;
  }
  /// The columns at velocity v (w: perJoint() values); dw_eps (when given): their derivatives
  /// with respect to eps; *dw_vs (when given): the Stribeck column's with respect to vs.
  void values(double v, double eps, double vs, double* w, double* dw_eps = nullptr,
              double* dw_vs = nullptr) const {
    double ds_deps = 0.0;
    const double sg = smoothCoulombSign(v, eps, &ds_deps);
    int c = 0;
    if (coulomb && !asymmetric) {
      if (dw_eps) dw_eps[c] = ds_deps;
      w[c++] = sg;
    } else if (coulomb) {
      if (dw_eps) dw_eps[c] = dw_eps[c + 1] = 0.5 * ds_deps;
      w[c++] = 0.5 * (1.0 + sg);
      w[c++] = -0.5 * (1.0 - sg);
    }
    if (stribeck) {
      const double r = std::abs(v) / vs;
      const double rd = std::pow(r, delta), g = std::exp(-rd);
      w[c] = sg * g;
      if (dw_eps) dw_eps[c] = ds_deps * g;
      if (dw_vs) *dw_vs = sg * g * delta * rd / vs;
    }
  }
  /// d/dv of sum_c g[c] w_c(v): the columns' vector-Jacobian product in the velocity.
  double velocityVjp(double v, double eps, double vs, const double* g) const {
    const double sg = smoothCoulombSign(v, eps);
    const double ds = eps > 0 ? (1.0 - sg * sg) / eps : 0.0;
    double out = 0.0;
    int e = 0;
    if (coulomb && !asymmetric) out += g[e++] * ds;
    if (coulomb && asymmetric) {
      out += g[e++] * 0.5 * ds;
      out += g[e++] * 0.5 * ds;
    }
    if (stribeck) {
      const double r = std::abs(v) / vs, rd = std::pow(r, delta), gg = std::exp(-rd);
      // d/dv [s g] = ds g + s g (-delta r^(delta-1) sign(v) / vs)
      const double dr = v == 0.0 ? 0.0 : delta * std::pow(r, delta - 1.0) * (v > 0 ? 1 : -1) / vs;
      out += g[e] * (ds * gg - sg * gg * dr);
    }
    return out;
  }
};
/// The load-dependent Coulomb column (the models' coulomb_load, FcL): |tau| sign(qdm), tau the
/// torque the drive carries (recorded in rows; the nominal robot's in a design).
inline double loadCoulombColumn(double tau, double qdm) { return std::abs(tau) * coulombSign(qdm); }

EXID_API std::vector<std::string> parameterNames(const RobotModel& model, const DriveColumns& cols);
EXID_API Eigen::VectorXd parameterValues(const RobotModel& model, const DriveColumns& cols);
EXID_API int numParameters(const RobotModel& model, const DriveColumns& cols);
/// True for a drive column's name as parameterNames writes it (Ia3, Fc3, Fv3, OFF3), or a
/// nonlinear friction column of the `differential` model (FcP3, FcN3, Fs3).
EXID_API bool isDriveParameterName(const std::string& name);
/// Whether `name` is `prefix` followed by a joint number (1, 2, ...), e.g. "Fc3" for "Fc".
EXID_API bool isIndexedParameterName(const std::string& name, const char* prefix);
/// A column that holds the recorded torque itself: the `differential` model's drive gains
/// dK<j> (1) and load-dependent Coulomb FcL<j> (2); else 0.
EXID_API int torqueColumnKind(const std::string& name);

/// Joint coordinates from measured ones (identity when the model has no transmission).
EXID_API void measuredToJoint(const RobotModel& model, const Eigen::VectorXd& qm,
                              const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                              Eigen::VectorXd* q, Eigen::VectorXd* qd, Eigen::VectorXd* qdd);
/// Measured coordinates from joint ones (the transmission must be invertible). For a closed
/// chain: from the tree's coordinates (numJoints entries: the actuated joints' values) or from
/// the actuated joints' own (dof entries: returned as they are).
EXID_API void jointToMeasured(const RobotModel& model, const Eigen::VectorXd& q,
                              const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                              Eigen::VectorXd* qm, Eigen::VectorXd* qdm, Eigen::VectorXd* qddm);

/// A scalar's gradient with respect to the joint coordinates (gq, gqd, gqdd: numJoints entries,
/// of a function of q, qd, qdd) mapped in place to the measured coordinates at the sample (qm,
/// qdm, qddm): through the transmission (T^T g), or for a closed chain by the chain rule through
/// q = phi(qa), qd = G qda, qdd = G qdda + g(qa, qda) (closedChainStateDerivatives). gqdd null:
/// the function does not depend on qdd; gqd null: nor on qd.
EXID_API void jointGradientToMeasured(const RobotModel& model, const Eigen::VectorXd& qm,
                                      const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                                      Eigen::VectorXd* gq, Eigen::VectorXd* gqd,
                                      Eigen::VectorXd* gqdd);

/// Y (n x numParameters) in measured coordinates: tau_m = Y * parameterValues(model, cols).
EXID_API void actuatorRegressor(const RobotModel& model, DynamicsData& data,
                                const DriveColumns& cols, const Eigen::VectorXd& qm,
                                const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                                Eigen::Ref<Eigen::MatrixXd> Y);
/// actuatorRegressor of K samples: sample k's measured state is row k of Qm, QDm, QDDm (K x n),
/// its rows k n .. k n + n - 1 of Y (K n x numParameters). The same bits as actuatorRegressor
/// sample by sample (torqueRegressors).
EXID_API void actuatorRegressors(const RobotModel& model, DynamicsData& data,
                                 const DriveColumns& cols,
                                 const Eigen::Ref<const Eigen::MatrixXd>& Qm,
                                 const Eigen::Ref<const Eigen::MatrixXd>& QDm,
                                 const Eigen::Ref<const Eigen::MatrixXd>& QDDm,
                                 Eigen::Ref<Eigen::MatrixXd> Y);
/// Gradient of <G, Y> with respect to qm, qdm, qddm (sign(qd) has zero derivative); a closed
/// chain's through the loop constraints (Y = G_c^T Y_tree with G_c = dq/dqa depending on qa).
EXID_API void actuatorRegressorVjp(const RobotModel& model, DynamicsData& data,
                                   const DriveColumns& cols, const Eigen::VectorXd& qm,
                                   const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                                   const Eigen::MatrixXd& G, Eigen::VectorXd* d_qm,
                                   Eigen::VectorXd* d_qdm, Eigen::VectorXd* d_qddm);
/// actuatorRegressorVjp of K samples: sample k's state is row k of Qm, QDm, QDDm (K x n), its G
/// the rows k n .. k n + n - 1 of G (K n x numParameters, actuatorRegressors' layout); its
/// gradients row k of *d_qm, *d_qdm, *d_qddm (resized to K x n; null: not computed). The same
/// bits as actuatorRegressorVjp sample by sample (torqueRegressorVjps).
EXID_API void actuatorRegressorVjps(
    const RobotModel& model, DynamicsData& data, const DriveColumns& cols,
    const Eigen::Ref<const Eigen::MatrixXd>& Qm, const Eigen::Ref<const Eigen::MatrixXd>& QDm,
    const Eigen::Ref<const Eigen::MatrixXd>& QDDm, const Eigen::Ref<const Eigen::MatrixXd>& G,
    Eigen::MatrixXd* d_qm, Eigen::MatrixXd* d_qdm, Eigen::MatrixXd* d_qddm);
/// Full actuator torque with the model's own parameters (rigid body + drives).
EXID_API Eigen::VectorXd actuatorTorque(const RobotModel& model, DynamicsData& data,
                                        const DriveColumns& cols, const Eigen::VectorXd& qm,
                                        const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm);
/// actuatorTorque and its partial derivatives with respect to qm, qdm, qddm (n x n each, row i
/// the gradient of tau_m,i; sign(qd) has zero derivative). Exact (inverseDynamicsDerivatives
/// mapped through the transmission, or for a closed chain through the loop constraints:
/// closedChainStateDerivatives). The derivative outputs may be null.
EXID_API void actuatorTorqueDerivatives(const RobotModel& model, DynamicsData& data,
                                        const DriveColumns& cols, const Eigen::VectorXd& qm,
                                        const Eigen::VectorXd& qdm, const Eigen::VectorXd& qddm,
                                        Eigen::VectorXd* tau_m, Eigen::MatrixXd* dtau_dqm,
                                        Eigen::MatrixXd* dtau_dqdm, Eigen::MatrixXd* dtau_dqddm);

/// actuatorTorqueDerivatives with the full parameters `params` (numParameters(model, cols)
/// values in parameterValues()'s order: the 10n standard inertial parameters, then each measured
/// coordinate's enabled drive parameters) in place of the model's own: tau_m = Y params with
/// Y = actuatorRegressor(qm, qdm, qddm), and its exact partial derivatives (sign(qd) has zero
/// derivative). With dq and dqd null, dqdd (the mass matrix) comes from the composite rigid
/// body algorithm and tau_m from recursive Newton-Euler, without tangents. Outputs other than
/// tau_m may be null.
EXID_API void actuatorTorqueWith(const RobotModel& model, DynamicsData& data,
                                 const DriveColumns& cols, const Eigen::VectorXd& params,
                                 const Eigen::VectorXd& qm, const Eigen::VectorXd& qdm,
                                 const Eigen::VectorXd& qddm, Eigen::VectorXd* tau_m,
                                 Eigen::MatrixXd* dq, Eigen::MatrixXd* dqd, Eigen::MatrixXd* dqdd);
}  // namespace exid
