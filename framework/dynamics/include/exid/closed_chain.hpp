// exid — closed kinematic chains: the loop-closure constraint of a RobotModel with cut joints
// (RobotModel::closed), the position solve of the passive joints, and the map from the measured
// (actuated) coordinates to the coordinates of the spanning tree.
//
// With qa the actuated coordinates and q the tree's, the loops define q = phi(qa) (one assembly
// branch: the one reached from the description's reference configuration by a straight path in
// qa). Differentiating the constraint c(q) = 0:
//   qd = G qd_a,   qdd = G qdd_a + g,   G = dq/dqa = P [I; -Jp^+ Ja],   g = P [0; -Jp^+ (Jdot qd)]
// (Ja, Jp: the constraint Jacobian's actuated and passive columns; Jp^+ a rank-revealing
// least-squares solve, since planar loops give redundant spatial constraints). The actuated
// torques are the tree's inverse dynamics projected by the virtual work of the actuated joints
// (Khalil and Dombre): tau_a = G^T tau_tree(q, qd, qdd), linear in the tree's standard
// parameters, so tau_a = G^T Y_tree(q, qd, qdd) pi.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

/// Number of scalar loop-closure constraints (5 per revolute, 3 per spherical cut joint).
EXID_API int numLoopConstraints(const RobotModel& model);

/// The loop-closure residual c(q) (zero when assembled) and its exact Jacobian dc/dq
/// (rows: per cut joint, the origin gap x_b - x_a in the base frame [m], then for a revolute
/// one the two components of b's axis across a's axis [1]). Either output may be null.
EXID_API void loopConstraint(const RobotModel& model, const Eigen::VectorXd& q, Eigen::VectorXd* c,
                             Eigen::MatrixXd* J);

/// The constraint's acceleration bias Jdot(q, qd) qd (c's second time derivative at qdd = 0).
EXID_API Eigen::VectorXd loopConstraintBias(const RobotModel& model, const Eigen::VectorXd& q,
                                            const Eigen::VectorXd& qd);

/// Tree coordinates from measured (actuated) ones: positions by damped Newton on the constraint
/// (tolerance 1e-12, continued from the reference configuration along a straight path in qa),
/// velocities and accelerations from the constraint Jacobian. G (numJoints x dof) and g as above.
/// Any output may be null. Throws exid::Error naming the robot, the loop and qa when the
/// mechanism does not assemble there or the actuated joints do not determine the passive ones.
EXID_API void closedChainState(const RobotModel& model, const Eigen::VectorXd& qa,
                               const Eigen::VectorXd* qda, const Eigen::VectorXd* qdda,
                               Eigen::VectorXd* q, Eigen::VectorXd* qd, Eigen::VectorXd* qdd,
                               Eigen::MatrixXd* G, Eigen::VectorXd* g);

/// The closed-chain state's derivatives with respect to the actuated coordinates, from the
/// loop constraint's second and third derivatives (implicit differentiation of J G = 0 and
/// J qdd + Jdot qd = 0; the constraint's Hessian and third-derivative tensor come from its exact
/// time derivatives by polarisation, so the result is analytic, not a finite difference):
///   dG[k] = dG/dqa_k (numJoints x dof; the actuated rows are zero),
///   dqd_dqa = d qd/d qa (column k: dG[k] qda), and d qd/d qda = G,
///   dqdd_dqa = d qdd/d qa, dqdd_dqda = d qdd/d qda, and d qdd/d qdda = G.
/// q, qd, qdd, G as closedChainState. Any output may be null; the same errors.
EXID_API void closedChainStateDerivatives(const RobotModel& model, const Eigen::VectorXd& qa,
                                          const Eigen::VectorXd& qda, const Eigen::VectorXd& qdda,
                                          Eigen::VectorXd* q, Eigen::VectorXd* qd,
                                          Eigen::VectorXd* qdd, Eigen::MatrixXd* G,
                                          std::vector<Eigen::MatrixXd>* dG,
                                          Eigen::MatrixXd* dqd_dqa, Eigen::MatrixXd* dqdd_dqa,
                                          Eigen::MatrixXd* dqdd_dqda);

/// The constraint's third time derivative along q(t) with qd(t0) = w and qdd = qddd = 0: the
/// third-derivative tensor of c(q) contracted three times with w (cubic in w).
EXID_API Eigen::VectorXd loopConstraintJerk(const RobotModel& model, const Eigen::VectorXd& q,
                                            const Eigen::VectorXd& w);

/// The structural checks of a closed-chain description (called by validateStructure): indices,
/// poses, the actuated joints, assembly at the reference configuration, and the rank test (the
/// actuated joints determine the passive ones, and are independent).
EXID_API void validateClosedChain(const RobotModel& model);

}  // namespace exid
