// exid — rigid-body algorithms on a RobotModel: regressors (torque, energy, payload wrench,
// payload torque), their exact derivatives, inverse and forward dynamics, mass matrix.
//
// All functions are free functions f(model, data, ...) in the Pinocchio style: the RobotModel is
// immutable and shared between threads; each thread owns a DynamicsData workspace.
// Coordinates are JOINT coordinates of the tree (not the measured coordinates of a transmission;
// see drive.hpp for those). Gravity is model.gravity, in the base frame.
//
// Parameter order per body (docs/conventions.md §1): XX XY XZ YY YZ ZZ MX MY MZ M about the body
// frame origin, in the body frame. The identity  tau = Y(q, qd, qdd) * pi  holds with pi =
// model.inertialParameters(). Payload parameters phi (docs/conventions.md §1): M MX MY MZ XX XY XZ
// YY YZ ZZ about the sensor frame origin, in the sensor frame. Wrench order: fx fy fz mx my mz, in
// the sensor frame.
#pragma once

#include <Eigen/Core>
#include <memory>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

/// Mutable workspace of the algorithms below. Create one per thread with makeDynamicsData().
struct DynamicsData;
struct EXID_API DynamicsDataDeleter {
  void operator()(DynamicsData* d) const;
};
using DynamicsDataPtr = std::unique_ptr<DynamicsData, DynamicsDataDeleter>;
EXID_API DynamicsDataPtr makeDynamicsData(const RobotModel& model);

/// Joint-torque regressor: Y is n x 10n, tau = Y * pi. O(n^2).
EXID_API void torqueRegressor(const RobotModel& model, DynamicsData& data, const Eigen::VectorXd& q,
                              const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                              Eigen::Ref<Eigen::MatrixXd> Y);

/// The torque regressors of K samples: sample k's state is row k of Q, QD, QDD (K x n), its
/// n x 10n regressor rows k n .. k n + n - 1 of Y (K n x 10n). The same bits as torqueRegressor
/// called sample by sample; with the portable kernels (the default: exid/isa.hpp) several
/// samples are computed at once, one per vector lane.
EXID_API void torqueRegressors(const RobotModel& model, DynamicsData& data,
                               const Eigen::Ref<const Eigen::MatrixXd>& Q,
                               const Eigen::Ref<const Eigen::MatrixXd>& QD,
                               const Eigen::Ref<const Eigen::MatrixXd>& QDD,
                               Eigen::Ref<Eigen::MatrixXd> Y);

/// Energy regressors (1 x 10n each): kinetic energy T = kinetic * pi, potential energy
/// U = potential * pi with U = -sum_j M_j g^T c_j (c_j the centre of mass in the base frame).
EXID_API void energyRegressor(const RobotModel& model, DynamicsData& data, const Eigen::VectorXd& q,
                              const Eigen::VectorXd& qd, Eigen::Ref<Eigen::RowVectorXd> kinetic,
                              Eigen::Ref<Eigen::RowVectorXd> potential);

/// The energy regressors of K samples: sample k's state is row k of Q, QD (K x n), its kinetic
/// and potential rows are row k of `kinetic` and `potential` (K x 10n). The same bits as
/// energyRegressor called sample by sample (several samples per vector register, as
/// torqueRegressors).
EXID_API void energyRegressors(const RobotModel& model, DynamicsData& data,
                               const Eigen::Ref<const Eigen::MatrixXd>& Q,
                               const Eigen::Ref<const Eigen::MatrixXd>& QD,
                               Eigen::Ref<Eigen::MatrixXd> kinetic,
                               Eigen::Ref<Eigen::MatrixXd> potential);

/// Wrench (6 x 10) that the sensor measures from a payload rigidly attached to the sensor frame:
/// w = A(omega, alpha, a - g) * phi, all expressed in the sensor frame. w is the wrench the
/// robot exerts on the payload (force, then moment about the sensor origin).
EXID_API void wrenchRegressor(const RobotModel& model, DynamicsData& data, const Eigen::VectorXd& q,
                              const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                              Eigen::Ref<Eigen::Matrix<double, 6, 10>> A);

/// The payload's contribution to the joint torques: n x 10, tau_payload = Yp * phi.
EXID_API void payloadTorqueRegressor(const RobotModel& model, DynamicsData& data,
                                     const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                     const Eigen::VectorXd& qdd, Eigen::Ref<Eigen::MatrixXd> Yp);

/// Inverse dynamics by recursive Newton-Euler with the model's own parameters (or pi if given,
/// 10n stacked standard parameters). Rigid body only, no drive terms.
EXID_API Eigen::VectorXd inverseDynamics(const RobotModel& model, DynamicsData& data,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                         const Eigen::VectorXd& qdd,
                                         const Eigen::VectorXd* pi = nullptr);

/// Inverse dynamics of K samples: sample k's state is row k of Q, QD, QDD (K x n), its torques
/// row k of Tau (K x n); parameters as inverseDynamics. The same bits as inverseDynamics called
/// sample by sample (several samples per vector register, as torqueRegressors).
EXID_API void inverseDynamicsSamples(const RobotModel& model, DynamicsData& data,
                                     const Eigen::Ref<const Eigen::MatrixXd>& Q,
                                     const Eigen::Ref<const Eigen::MatrixXd>& QD,
                                     const Eigen::Ref<const Eigen::MatrixXd>& QDD,
                                     Eigen::Ref<Eigen::MatrixXd> Tau,
                                     const Eigen::VectorXd* pi = nullptr);

/// Partial derivatives of the inverse dynamics tau(q, qd, qdd) (as inverseDynamics: the model's
/// own parameters, or pi): row i of each n x n matrix is the gradient of tau_i. Exact (forward
/// tangents of the recursive Newton-Euler algorithm, all 3n directions at once), O(n^2); also
/// returns tau. Outputs may be null except tau.
EXID_API void inverseDynamicsDerivatives(const RobotModel& model, DynamicsData& data,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                         const Eigen::VectorXd& qdd, const Eigen::VectorXd* pi,
                                         Eigen::VectorXd* tau, Eigen::MatrixXd* dtau_dq,
                                         Eigen::MatrixXd* dtau_dqd, Eigen::MatrixXd* dtau_dqdd);

/// Joint-space mass matrix (composite rigid body algorithm), n x n.
EXID_API Eigen::MatrixXd massMatrix(const RobotModel& model, DynamicsData& data,
                                    const Eigen::VectorXd& q, const Eigen::VectorXd* pi = nullptr);

/// Forward dynamics qdd = M(q)^-1 (tau - h(q, qd)), rigid body only.
EXID_API Eigen::VectorXd forwardDynamics(const RobotModel& model, DynamicsData& data,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                         const Eigen::VectorXd& tau,
                                         const Eigen::VectorXd* pi = nullptr);

/// Pose of body i's frame in the base frame.
EXID_API Pose bodyPose(const RobotModel& model, DynamicsData& data, const Eigen::VectorXd& q,
                       int body);

/// Vector-Jacobian products (exact; what the adjoint optimiser needs at every sample).
/// Given G with the shape of the regressor, these return the gradient of the scalar <G, Y>
/// (sum of elementwise products) with respect to q, qd and qdd. Outputs may be null.
EXID_API void torqueRegressorVjp(const RobotModel& model, DynamicsData& data,
                                 const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 const Eigen::VectorXd& qdd, const Eigen::MatrixXd& G,
                                 Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd,
                                 Eigen::VectorXd* d_qdd);
/// Gradient of <Gk, kinetic> + <Gu, potential> with respect to q and qd.
EXID_API void energyRegressorVjp(const RobotModel& model, DynamicsData& data,
                                 const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 const Eigen::RowVectorXd& Gk, const Eigen::RowVectorXd& Gu,
                                 Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd);
/// The torque regressor's VJPs of K samples: sample k's state is row k of Q, QD, QDD (K x n),
/// its G the rows k n .. k n + n - 1 of G (K n x 10n, torqueRegressors' layout); its gradients
/// row k of *d_q, *d_qd, *d_qdd (resized to K x n; null: not computed). The same bits as
/// torqueRegressorVjp called sample by sample (several samples per vector register).
EXID_API void torqueRegressorVjps(const RobotModel& model, DynamicsData& data,
                                  const Eigen::Ref<const Eigen::MatrixXd>& Q,
                                  const Eigen::Ref<const Eigen::MatrixXd>& QD,
                                  const Eigen::Ref<const Eigen::MatrixXd>& QDD,
                                  const Eigen::Ref<const Eigen::MatrixXd>& G, Eigen::MatrixXd* d_q,
                                  Eigen::MatrixXd* d_qd, Eigen::MatrixXd* d_qdd);
/// The energy regressors' VJPs of K samples: sample k's state is row k of Q, QD (K x n), its Gk
/// and Gu row k of Gk, Gu (K x 10n); its gradients row k of *d_q, *d_qd (resized to K x n; null:
/// not computed). The same bits as energyRegressorVjp called sample by sample.
EXID_API void energyRegressorVjps(const RobotModel& model, DynamicsData& data,
                                  const Eigen::Ref<const Eigen::MatrixXd>& Q,
                                  const Eigen::Ref<const Eigen::MatrixXd>& QD,
                                  const Eigen::Ref<const Eigen::MatrixXd>& Gk,
                                  const Eigen::Ref<const Eigen::MatrixXd>& Gu, Eigen::MatrixXd* d_q,
                                  Eigen::MatrixXd* d_qd);
/// Gradient of <G, A> (G 6 x 10) with respect to q, qd, qdd.
EXID_API void wrenchRegressorVjp(const RobotModel& model, DynamicsData& data,
                                 const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 const Eigen::VectorXd& qdd, const Eigen::Matrix<double, 6, 10>& G,
                                 Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd,
                                 Eigen::VectorXd* d_qdd);
/// Gradient of <G, Yp> (G n x 10) with respect to q, qd, qdd.
EXID_API void payloadTorqueRegressorVjp(const RobotModel& model, DynamicsData& data,
                                        const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                        const Eigen::VectorXd& qdd, const Eigen::MatrixXd& G,
                                        Eigen::VectorXd* d_q, Eigen::VectorXd* d_qd,
                                        Eigen::VectorXd* d_qdd);

/// G += B^T B, lower triangle: G row-major (m x m, leading dimension ldg >= m rounded up to a
/// multiple of 4), B row-major (k x m, leading dimension ldb >= m rounded up to a multiple of 4,
/// the padding zeros; G's padding may be written). Each G(i, j), j <= i, adds
/// the rows' products four rows at a time in row order, the same sequence of IEEE operations
/// whatever the vector width (no FMA): with the portable kernels (exid/isa.hpp) the same bits
/// on every CPU, in AVX registers where the CPU has them (otherwise SSE2); with EXID_ISA=avx2,
/// that copy's FMA kernel. The entries above the diagonal are not touched.
EXID_API void gramUpdate(double* G, int ldg, const double* B, int ldb, int k, int m);

/// Information-matrix accumulation M = sum_k W_k^T W_k over many small row blocks W_k (e.g. one
/// regressor per sample), much faster than a rank update per block: rows are grouped by their
/// first non-zero column (the torque regressor of a chain is block upper triangular), buffered,
/// and added in batches by a cache-friendly kernel (AVX2/FMA when the CPU has it, chosen at run
/// time). Not thread-safe; use one accumulator per thread and add the matrices.
class EXID_API GramAccumulator {
 public:
  explicit GramAccumulator(int cols = 0);
  ~GramAccumulator();
  GramAccumulator(GramAccumulator&&) noexcept;
  GramAccumulator& operator=(GramAccumulator&&) noexcept;
  /// Clears the sum; a non-negative `cols` also changes the number of columns.
  void reset(int cols = -1);
  /// Adds rows^T rows (rows.cols() must equal cols()).
  void add(const Eigen::Ref<const Eigen::MatrixXd>& rows);
  /// Adds w * rows^T rows (w >= 0, e.g. weights of weighted least squares).
  void addWeighted(const Eigen::Ref<const Eigen::MatrixXd>& rows, double w);
  /// The full symmetric sum so far (flushes the buffers).
  const Eigen::MatrixXd& matrix();
  int cols() const;
  long rowsAdded() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace exid
