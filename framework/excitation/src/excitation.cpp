#include "exid/excitation.hpp"

#include <fmt/format.h>

#include <cmath>

#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid {

namespace {

constexpr DriveColumns kAllDriveTerms{true, true, true, true};

class Problem final : public ExcitationProblem {
 public:
  Problem(std::shared_ptr<Trajectory> t, std::shared_ptr<ObservationModel> m,
          std::shared_ptr<Criterion> c, const ExcitationOptions& o)
      : traj_(std::move(t)), model_(std::move(m)), crit_(std::move(c)), opt_(o) {
    const int p = model_->numBase();
    scale_ = Eigen::VectorXd::Ones(p);
    if (opt_.scale_columns) {
      Eigen::VectorXd nom = model_->baseNominal().cwiseAbs();
      const double floor = std::max(1e-6, 1e-3 * nom.maxCoeff());
      for (int i = 0; i < p; ++i) scale_(i) = std::max(nom(i), floor);
    }
    if (opt_.prior_information.size() > 0) {
      check(opt_.prior_information.rows() == p && opt_.prior_information.cols() == p &&
                opt_.prior_information.allFinite(),
            fmt::format("excitation: the information already known must be a finite {} x {} "
                        "matrix (the model's base parameters), found {} x {}",
                        p, p, opt_.prior_information.rows(), opt_.prior_information.cols()));
      M0_ = scale_.asDiagonal() *
            (0.5 * (opt_.prior_information + opt_.prior_information.transpose())) *
            scale_.asDiagonal();
    }
    Samples s = traj_->evaluate(traj_->initial());
    K_ = s.size();
    n_ = s.dof();
    const RobotModel& r = model_->robot();
    r.requireFixedBase("excitation design (the fixed-contact floating-base case is not designed)");
    // Limits in measured coordinates equal joint limits when there is no transmission; with a
    // transmission, the joint-space limits are applied to q = T qm + q0 below.
    std::vector<JointLimits> limits = r.limits;
    limits.resize(static_cast<std::size_t>(n_));
    traj_->adjustLimits(&limits);
    for (int j = 0; j < n_; ++j) {
      const JointLimits L = limits[static_cast<std::size_t>(j)];
      if (L.q_max < 1e299) active_.push_back({0, j, +1, L.q_max - opt_.position_margin});
      if (L.q_min > -1e299) active_.push_back({0, j, -1, -(L.q_min + opt_.position_margin)});
      if (opt_.velocity_limits && L.qd_max < 1e299) {
        active_.push_back({1, j, +1, L.qd_max});
        active_.push_back({1, j, -1, L.qd_max});
      }
      if (opt_.acceleration_limits && L.qdd_max < 1e299) {
        active_.push_back({2, j, +1, L.qdd_max});
        active_.push_back({2, j, -1, L.qdd_max});
      }
    }
    if (opt_.torque_margin > 0) {
      check(std::isfinite(opt_.torque_margin),
            "excitation: torque_margin must be a finite fraction of the torque limits");
      tau_max_ = torqueLimits(r, opt_.torque_max, "excitation: torque limits").tau_max;
      dyn_ = makeDynamicsData(r);
      nl_ = 2 * n_ * K_;
    }
    if (opt_.collision) {
      collision_ = std::make_unique<CollisionModel>(r, *opt_.collision);
      nc_ = collision_->numPairs() * K_;
    }
    if (r.hasTransmission()) {
      T_ = r.transmission;
      q0_ = r.transmission_offset.size() ? r.transmission_offset : Eigen::VectorXd::Zero(n_);
    } else {
      T_ = Eigen::MatrixXd::Identity(n_, n_);
      q0_ = Eigen::VectorXd::Zero(n_);
    }
  }

  int numVariables() const override { return traj_->numVariables(); }
  Eigen::VectorXd initial() const override { return traj_->initial(); }
  void bounds(Eigen::VectorXd* lo, Eigen::VectorXd* hi) const override { traj_->bounds(lo, hi); }

  double value(const Eigen::VectorXd& z, Eigen::VectorXd* grad) override {
    ++evaluations_;
    Samples s = traj_->evaluate(z);
    Eigen::MatrixXd W = model_->design(s) * scale_.asDiagonal();
    Eigen::MatrixXd M = W.transpose() * W;
    if (M0_.size() > 0) M += M0_;  // constant: the gradient through W is unchanged
    Eigen::MatrixXd dM;
    const double J = crit_->evaluate(M, grad ? &dM : nullptr);
    if (grad) {
      Eigen::MatrixXd Gs = 0.5 * (dM + dM.transpose());
      Eigen::MatrixXd dW = 2.0 * W * Gs;
      dW = dW * scale_.asDiagonal();  // back through the scaling
      Samples adj;
      model_->designVjp(s, dW, &adj);
      *grad = traj_->vjp(z, adj);
    }
    return J;
  }

  Eigen::MatrixXd information(const Eigen::VectorXd& z) override {
    ++evaluations_;
    const Eigen::MatrixXd W = model_->design(traj_->evaluate(z)) * scale_.asDiagonal();
    Eigen::MatrixXd M = W.transpose() * W;
    if (M0_.size() > 0) M += M0_;
    return M;
  }
  const Eigen::MatrixXd& priorInformation() const override { return M0_; }

  Eigen::MatrixXd informationGradients(const Eigen::VectorXd& z,
                                       const std::vector<Eigen::MatrixXd>& dM) override {
    const Samples s = traj_->evaluate(z);
    const Eigen::MatrixXd W = model_->design(s) * scale_.asDiagonal();
    Eigen::MatrixXd out(numVariables(), static_cast<Eigen::Index>(dM.size()));
    Samples adj;
    for (std::size_t i = 0; i < dM.size(); ++i) {
      check(dM[i].rows() == W.cols() && dM[i].cols() == W.cols(),
            "informationGradients: each dM must be p x p (p = number of base parameters)");
      const Eigen::MatrixXd dW = 2.0 * W * (0.5 * (dM[i] + dM[i].transpose())) *
                                 scale_.asDiagonal();  // back through the scaling
      model_->designVjp(s, dW, &adj);
      out.col(static_cast<Eigen::Index>(i)) = traj_->vjp(z, adj);
    }
    return out;
  }

  int numConstraints() const override { return static_cast<int>(active_.size()) * K_ + nl_ + nc_; }
  int numNonlinearConstraints() const override { return nl_ + nc_; }

  void nonlinearConstraints(const Eigen::VectorXd& z, Eigen::VectorXd* g,
                            Eigen::MatrixXd* jac) override {
    if (g) g->resize(nl_ + nc_);
    if (jac) jac->resize(nl_ + nc_, numVariables());
    if (nl_ + nc_ == 0) return;
    const Samples s = traj_->evaluate(z);
    if (nl_ > 0) torqueRows(z, s, g ? g->data() : nullptr, jac, 0);
    if (nc_ > 0) collisionRows(z, s, g ? g->data() + nl_ : nullptr, jac, nl_);
  }

  void constraints(const Eigen::VectorXd& z, Eigen::VectorXd* g, Eigen::MatrixXd* jac) override {
    Samples s = traj_->evaluate(z);
    const int m = numConstraints();
    if (g) g->resize(m);
    // joint-space signals
    Eigen::MatrixXd qj = (s.q * T_.transpose()).rowwise() + q0_.transpose();
    Eigen::MatrixXd qdj = s.qd * T_.transpose();
    Eigen::MatrixXd qddj = s.qdd * T_.transpose();
    Eigen::MatrixXd Jt_own;  // d[vec q; vec qd; vec qdd]/dz, column-major vec (index j*K + k)
    const Eigen::MatrixXd* Jtp = nullptr;
    if (jac) {
      jac->resize(m, numVariables());
      Jtp = &trajectoryJacobian(z, &Jt_own);
    }
    const Eigen::MatrixXd& Jt = jac ? *Jtp : Jt_own;
    const Eigen::Index Kn = static_cast<Eigen::Index>(K_) * n_;
    int row = 0;
    for (const auto& c : active_) {
      const Eigen::MatrixXd& sig = c.signal == 0 ? qj : (c.signal == 1 ? qdj : qddj);
      for (int k = 0; k < K_; ++k, ++row) {
        if (g) (*g)(row) = c.sign * sig(k, c.joint) - c.bound;
        if (jac) {
          // d(sign * (T x_k)_j)/dz = sign * sum_i T(j, i) dx_k,i/dz
          jac->row(row).setZero();
          for (int i = 0; i < n_; ++i) {
            const double t = T_(c.joint, i);
            if (t != 0.0)
              jac->row(row) +=
                  c.sign * t * Jt.row(c.signal * Kn + static_cast<Eigen::Index>(i) * K_ + k);
          }
        }
      }
    }
    if (nl_ > 0) torqueRows(z, s, g ? g->data() + row : nullptr, jac, row);
    if (nc_ > 0) collisionRows(z, s, g ? g->data() + row + nl_ : nullptr, jac, row + nl_);
  }

  const Trajectory& trajectory() const override { return *traj_; }
  const ObservationModel& model() const override { return *model_; }
  const Criterion& criterion() const override { return *crit_; }
  long evaluations() const override { return evaluations_; }

 private:
  struct Limit {
    int signal;  // 0 q, 1 qd, 2 qdd
    int joint;
    double sign;
    double bound;
  };
  // d[vec q; vec qd; vec qdd]/dz: the trajectory's, kept once when it is constant (linear).
  const Eigen::MatrixXd& trajectoryJacobian(const Eigen::VectorXd& z, Eigen::MatrixXd* own) {
    if (traj_->specs().linear) {
      if (jt_.size() == 0) jt_ = traj_->jacobian(z);
      return jt_;
    }
    *own = traj_->jacobian(z);
    return *own;
  }

  // Torque rows: group (j, +) then (j, -) for each measured coordinate j, K samples each:
  // +-tau_j(t_k) / tau_max,j - margin <= 0. Their Jacobian is exact: per sample, the partial
  // derivatives of the full model's torque (actuatorTorqueDerivatives) times the trajectory's
  // Jacobian rows of that sample (sampleRows).
  void torqueRows(const Eigen::VectorXd& z, const Samples& s, double* g, Eigen::MatrixXd* jac,
                  int row0) {
    const RobotModel& r = model_->robot();
    const int n = n_, K = K_;
    SampleRows rows_own;
    const SampleRows* R = jac ? &sampleRows(z, &rows_own) : nullptr;
    const Eigen::Index nv = numVariables();
    Eigen::VectorXd qm(n), qdm(n), qddm(n), tau(n);
    Eigen::MatrixXd Dk(n, 3 * n), Dq, Dqd, Dqdd;
    RowMatrix Tk(n, nv);
    for (int k = 0; k < K; ++k) {
      qm = s.q.row(k).transpose();
      qdm = s.qd.row(k).transpose();
      qddm = s.qdd.row(k).transpose();
      if (jac)
        actuatorTorqueDerivatives(r, *dyn_, kAllDriveTerms, qm, qdm, qddm, &tau, &Dq, &Dqd, &Dqdd);
      else
        tau = actuatorTorque(r, *dyn_, kAllDriveTerms, qm, qdm, qddm);
      if (g)
        for (int j = 0; j < n; ++j) {
          const double x = tau(j) / tau_max_(j);
          g[(2 * j) * K + k] = x - opt_.torque_margin;
          g[(2 * j + 1) * K + k] = -x - opt_.torque_margin;
        }
      if (!jac) continue;
      Dk.leftCols(n) = Dq;
      Dk.middleCols(n, n) = Dqd;
      Dk.rightCols(n) = Dqdd;
      // Tk = Dk * (the trajectory's Jacobian rows of sample k), over each row's non-zero span
      Tk.setZero();
      for (int c = 0; c < 3 * n; ++c) {
        const Eigen::Index src = static_cast<Eigen::Index>(3 * n) * k + c;
        const auto [c0, c1] = R->span[static_cast<std::size_t>(src)];
        if (c1 <= c0) continue;
        const auto Jrow = R->J.row(src).segment(c0, c1 - c0);
        for (int j = 0; j < n; ++j)
          if (Dk(j, c) != 0.0) Tk.row(j).segment(c0, c1 - c0) += Dk(j, c) * Jrow;
      }
      for (int j = 0; j < n; ++j) {
        const double sc = 1.0 / tau_max_(j);
        jac->row(row0 + (2 * j) * K + k) = sc * Tk.row(j);
        jac->row(row0 + (2 * j + 1) * K + k) = -sc * Tk.row(j);
      }
    }
  }

  // Collision rows: K samples per checked pair p: margin - d_p(q(t_k)) <= 0, the Jacobian
  // -(d d_p / d q at t_k) times the trajectory's position rows of sample k.
  void collisionRows(const Eigen::VectorXd& z, const Samples& s, double* g, Eigen::MatrixXd* jac,
                     int row0) {
    const int n = n_, K = K_, P = collision_->numPairs();
    const double margin = collision_->margin();
    SampleRows rows_own;
    const SampleRows* R = jac ? &sampleRows(z, &rows_own) : nullptr;
    Eigen::VectorXd d;
    Eigen::MatrixXd D;
    for (int k = 0; k < K; ++k) {
      collision_->distances(s.q.row(k).transpose(), &d, jac ? &D : nullptr);
      for (int p = 0; p < P; ++p) {
        const Eigen::Index row = row0 + static_cast<Eigen::Index>(p) * K + k;
        if (g) g[row - row0] = margin - d(p);
        if (!jac) continue;
        jac->row(row).setZero();
        for (int i = 0; i < n; ++i) {
          if (D(p, i) == 0.0) continue;
          const Eigen::Index src = static_cast<Eigen::Index>(3 * n) * k + i;  // q_i at sample k
          const auto [c0, c1] = R->span[static_cast<std::size_t>(src)];
          if (c1 > c0)
            jac->row(row).segment(c0, c1 - c0) -= D(p, i) * R->J.row(src).segment(c0, c1 - c0);
        }
      }
    }
  }

  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  // The trajectory's Jacobian rows sample by sample (row 3n k + sig n + i: signal sig of joint i
  // at sample k), row-major, with the span of each row's non-zero columns (a basis trajectory's
  // row of one joint touches that joint's variables only). Kept once for a linear trajectory.
  struct SampleRows {
    RowMatrix J;
    std::vector<std::pair<Eigen::Index, Eigen::Index>> span;
  };
  const SampleRows& sampleRows(const Eigen::VectorXd& z, SampleRows* own) {
    const bool linear = traj_->specs().linear;
    if (linear && rows_.J.size() > 0) return rows_;
    SampleRows& R = linear ? rows_ : *own;
    Eigen::MatrixXd Jt_own;
    const Eigen::MatrixXd& Jt = trajectoryJacobian(z, &Jt_own);
    const Eigen::Index n = n_, K = K_, Kn = K * n, nv = numVariables();
    R.J.resize(3 * Kn, nv);
    R.span.assign(static_cast<std::size_t>(3 * Kn), {0, 0});
    for (Eigen::Index k = 0; k < K; ++k)
      for (Eigen::Index sig = 0; sig < 3; ++sig)
        for (Eigen::Index i = 0; i < n; ++i) {
          const Eigen::Index dst = 3 * n * k + sig * n + i;
          R.J.row(dst) = Jt.row(sig * Kn + i * K + k);
          Eigen::Index c0 = 0, c1 = nv;
          while (c0 < nv && R.J(dst, c0) == 0.0) ++c0;
          while (c1 > c0 && R.J(dst, c1 - 1) == 0.0) --c1;
          R.span[static_cast<std::size_t>(dst)] = {c0, c1};
        }
    return R;
  }

  std::shared_ptr<Trajectory> traj_;
  std::shared_ptr<ObservationModel> model_;
  std::shared_ptr<Criterion> crit_;
  ExcitationOptions opt_;
  Eigen::VectorXd scale_;
  Eigen::MatrixXd M0_;  // information already known, scaled like W's columns (empty: none)
  std::vector<Limit> active_;
  Eigen::MatrixXd T_;
  Eigen::VectorXd q0_;
  int K_ = 0, n_ = 0;
  long evaluations_ = 0;
  int nl_ = 0;  // torque rows (2 n K when the torque limits are on)
  int nc_ = 0;  // collision rows (pairs x K when collision avoidance is on)
  std::unique_ptr<CollisionModel> collision_;
  Eigen::VectorXd tau_max_;
  DynamicsDataPtr dyn_;
  Eigen::MatrixXd jt_;
  SampleRows rows_;
};

}  // namespace

std::unique_ptr<ExcitationProblem> makeExcitationProblem(std::shared_ptr<Trajectory> trajectory,
                                                         std::shared_ptr<ObservationModel> model,
                                                         std::shared_ptr<Criterion> criterion,
                                                         const ExcitationOptions& options) {
  check(trajectory && model && criterion, "makeExcitationProblem: missing part");
  return std::make_unique<Problem>(std::move(trajectory), std::move(model), std::move(criterion),
                                   options);
}

TorqueLimits torqueLimits(const RobotModel& robot, const std::vector<double>& torque_max,
                          const std::string& who) {
  const int n = robot.dof();
  check(robot.inertialParameters().cwiseAbs().maxCoeff() > 0,
        fmt::format("{}: robot '{}' carries no inertial parameters (every mass, first and second "
                    "moment is zero), so its torques cannot be predicted; give a robot description "
                    "with its dynamic parameters, or drop the torque limits",
                    who, robot.name));
  TorqueLimits tl;
  tl.tau_max.resize(n);
  if (!torque_max.empty()) {
    check(static_cast<int>(torque_max.size()) == n,
          fmt::format("{}: torque_max_Nm has {} values; robot '{}' has {} joints", who,
                      torque_max.size(), robot.name, n));
    for (int j = 0; j < n; ++j) {
      const double t = torque_max[static_cast<std::size_t>(j)];
      check(std::isfinite(t) && t > 0,
            fmt::format("{}: torque_max_Nm[{}] = {}: must be a positive finite torque", who, j, t));
      tl.tau_max(j) = t;
    }
    return tl;
  }
  check(!robot.hasTransmission(),
        fmt::format("{}: robot '{}' has a transmission, so its actuator (measured-coordinate) "
                    "torques are not limited by the joints' effort limits; give torque_max_Nm, "
                    "one limit per measured coordinate",
                    who, robot.name));
  std::vector<std::string> missing;
  for (int j = 0; j < n; ++j) {
    const double t = j < static_cast<int>(robot.limits.size())
                         ? robot.limits[static_cast<std::size_t>(j)].tau_max
                         : HUGE_VAL;
    if (!(t > 0) || !(t < 1e299))
      missing.push_back(
          fmt::format("{} ({})", j + 1,
                      robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name));
    else
      tl.tau_max(j) = t;
  }
  check(missing.empty(),
        fmt::format("{}: robot '{}' has no torque limit (URDF effort) for joint(s) {}; give "
                    "torque_max_Nm, one limit per joint",
                    who, robot.name, fmt::join(missing, ", ")));
  return tl;
}

Eigen::MatrixXd predictedTorques(const RobotModel& robot, const Samples& s) {
  auto dyn = makeDynamicsData(robot);
  const int n = robot.dof();
  Eigen::MatrixXd tau(s.size(), n);
  for (int k = 0; k < s.size(); ++k)
    tau.row(k) = actuatorTorque(robot, *dyn, kAllDriveTerms, s.q.row(k).transpose(),
                                s.qd.row(k).transpose(), s.qdd.row(k).transpose())
                     .transpose();
  return tau;
}

double conditionNumber(const Eigen::MatrixXd& W) {
  if (W.size() == 0) return HUGE_VAL;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(W);
  const auto& s = svd.singularValues();
  const double smin = s(s.size() - 1);
  return smin > 0 ? s(0) / smin : HUGE_VAL;
}

}  // namespace exid
