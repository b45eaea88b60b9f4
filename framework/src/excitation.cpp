#include "exid/excitation.hpp"

#include <Eigen/SVD>
#include <cmath>

#include "exid/error.hpp"

namespace exid {

namespace {

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
    Samples s = traj_->evaluate(traj_->initial());
    K_ = s.size();
    n_ = s.dof();
    const RobotModel& r = model_->robot();
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
    return W.transpose() * W;
  }

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

  int numConstraints() const override { return static_cast<int>(active_.size()) * K_; }

  void constraints(const Eigen::VectorXd& z, Eigen::VectorXd* g, Eigen::MatrixXd* jac) override {
    Samples s = traj_->evaluate(z);
    const int m = numConstraints();
    if (g) g->resize(m);
    // joint-space signals
    Eigen::MatrixXd qj = (s.q * T_.transpose()).rowwise() + q0_.transpose();
    Eigen::MatrixXd qdj = s.qd * T_.transpose();
    Eigen::MatrixXd qddj = s.qdd * T_.transpose();
    Eigen::MatrixXd Jt;  // d[vec q; vec qd; vec qdd]/dz, column-major vec (index j*K + k)
    if (jac) {
      jac->resize(m, numVariables());
      Jt = traj_->jacobian(z);
    }
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
  std::shared_ptr<Trajectory> traj_;
  std::shared_ptr<ObservationModel> model_;
  std::shared_ptr<Criterion> crit_;
  ExcitationOptions opt_;
  Eigen::VectorXd scale_;
  std::vector<Limit> active_;
  Eigen::MatrixXd T_;
  Eigen::VectorXd q0_;
  int K_ = 0, n_ = 0;
  long evaluations_ = 0;
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

double conditionNumber(const Eigen::MatrixXd& W) {
  if (W.size() == 0) return HUGE_VAL;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(W);
  const auto& s = svd.singularValues();
  const double smin = s(s.size() - 1);
  return smin > 0 ? s(0) / smin : HUGE_VAL;
}

}  // namespace exid
