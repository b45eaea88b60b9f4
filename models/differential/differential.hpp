// exid — observation model `differential` (differential.cpp): the model class, shared by its
// sources (not installed). differential.cpp: its parameters, names, values and description;
// differential_design.cpp: the rows, the design, the torque and their derivatives.
#pragma once

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"
#include "exid/payload.hpp"

namespace exid::differential {

using exid::models::requireTorqueSignals;

class DifferentialModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "differential";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "equations of motion tau_m - tau_f = Y(qm, qdm, qddm) pi, one row per sample and selected "
      "joint (paper eqns 1, 3); drive columns Ia, Fc, Fv, OFF optional";

  static std::vector<exid::ParamDecl> params();

  explicit DifferentialModel(const exid::ParamSet& p);

  std::vector<std::string> fullNames() const override;
  Eigen::VectorXd fullNominal() const override;

  Eigen::VectorXd fullTruth(const exid::PlantTruth& plant) const override;

  std::vector<exid::NonlinearParameter> nonlinearParameters() const override;

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;  // the rows of sample k are the equations of motion at sample k
    sp.required_signals = {"q", "qd", "qdd", "tau"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext& ctx) const override {
    return fullRowsAt(d, studyEta(), nullptr, ctx);
  }

  exid::Rows fullRowsAt(const exid::Dataset& d, const Eigen::VectorXd& eta, Eigen::MatrixXd* dW,
                        const exid::RunContext&) const override;

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    return designAt(s, frictionAt(studyEta()), nullptr);
  }
  Eigen::MatrixXd fullColumnsAt(const exid::Dataset& d, const Eigen::VectorXd& eta,
                                const std::vector<int>& columns, const exid::RunContext& ctx,
                                Eigen::MatrixXd* dW = nullptr) const override;
  Eigen::MatrixXd fullDesignAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                               Eigen::MatrixXd* dW) const override {
    return designAt(s, frictionAt(eta), dW);
  }

  bool fullTorqueAt(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                    const Eigen::VectorXd& eta, const Eigen::VectorXd& phi, Eigen::VectorXd* tau,
                    Eigen::MatrixXd* d_q, Eigen::MatrixXd* d_qd,
                    Eigen::MatrixXd* d_qdd) const override;

  // The per-drive widths and Stribeck velocities at eta (nonlinearParameters() order).
  struct Friction {
    std::vector<double> eps, vs;  // per drive (eps 0: sign)
  };
  Friction frictionAt(const Eigen::VectorXd& eta) const;

  Eigen::MatrixXd designAt(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* dW,
                           bool gain_design = true) const;

  static double signum(double v) { return exid::coulombSign(v); }

  void loadColumns(const exid::Samples& s, Eigen::MatrixXd* W) const;

  void gainColumns(const exid::Samples& s, bool gain_design, Eigen::MatrixXd* W) const;

  Eigen::VectorXd payloadTorque(exid::DynamicsData& data, const Eigen::Matrix<double, 10, 1>& phi,
                                const Eigen::Ref<const Eigen::RowVectorXd>& qm,
                                const Eigen::Ref<const Eigen::RowVectorXd>& qdm,
                                const Eigen::Ref<const Eigen::RowVectorXd>& qddm) const;

  void extraColumns(const exid::Samples& s, const Friction& f, Eigen::MatrixXd* W,
                    Eigen::MatrixXd* dW) const;

  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    fullDesignVjpAt(s, studyEta(), dW, grad);
  }

  void fullDesignVjpAt(const exid::Samples& s, const Eigen::VectorXd& eta,
                       const Eigen::MatrixXd& dW, exid::Samples* grad) const override;

  void payloadTorqueVjp(const exid::Samples& s, const Eigen::MatrixXd& dW, int P,
                        exid::Samples* grad) const;

  void designVjpNoGains(const exid::Samples& s, const Friction& f, const Eigen::MatrixXd& dW,
                        exid::Samples* grad) const;

  double extraColumnsVjp(double v, const Friction& f, int j,
                         const Eigen::Ref<const Eigen::RowVectorXd>& g) const;

  exid::Json describe() const override;

 protected:
  void onBind(const exid::RunContext&) override {
    sel_ = exid::models::selectJoints(joints_param_, robot().dof(),
                                      "model 'differential' on robot '" + robot().name + "'");
  }

 private:
  // The dynamics algorithms' workspaces, reused from call to call (a simulation asks for the
  // design of one state thousands of times; a workspace costs more to make than to use). A call
  // on any thread takes one for its duration.
  class Workspace {
   public:
    explicit Workspace(const DifferentialModel& m) : m_(m), r_(&m.robot()), d_(m.takeData()) {}
    ~Workspace() { m_.giveData(std::move(d_), r_); }
    Workspace(const Workspace&) = delete;
    Workspace& operator=(const Workspace&) = delete;
    exid::DynamicsData& operator*() const { return *d_; }

   private:
    const DifferentialModel& m_;
    const exid::RobotModel* r_;  // the robot it was made for
    exid::DynamicsDataPtr d_;
  };
  exid::DynamicsDataPtr takeData() const {
    {
      std::lock_guard<std::mutex> lock(pool_mutex_);
      if (pool_robot_.get() == &robot() && !pool_.empty()) {
        exid::DynamicsDataPtr d = std::move(pool_.back());
        pool_.pop_back();
        return d;
      }
    }
    return exid::makeDynamicsData(robot());
  }
  void giveData(exid::DynamicsDataPtr d, const exid::RobotModel* made_for) const {
    if (made_for != &robot()) return;  // (bound to another robot during the call: dropped)
    std::lock_guard<std::mutex> lock(pool_mutex_);
    if (pool_robot_.get() != &robot()) {  // (bound to another robot since: of no use)
      pool_.clear();
      pool_robot_ = robotPtr();  // (held: no other robot can take its address while pooled)
    }
    if (pool_.size() < 64) pool_.push_back(std::move(d));
  }
  mutable std::mutex pool_mutex_;
  mutable std::vector<exid::DynamicsDataPtr> pool_;
  mutable std::shared_ptr<const exid::RobotModel> pool_robot_;

  double frictionTorque(int j, double qdm) const {
    const exid::Drive D = drive(j);
    const double sg = exid::coulombSign(qdm);
    return D.coulomb * sg + D.viscous * qdm + (cols_.offset ? 0.0 : D.offset);
  }

  exid::Drive drive(int j) const {
    const auto& dr = robot().drives;
    return j < static_cast<int>(dr.size()) ? dr[static_cast<std::size_t>(j)] : exid::Drive{};
  }
  // The nonlinear parameters in order: per selected joint (ascending), its width then its
  // Stribeck velocity.
  struct Slot {
    bool eps = false;
    int joint = 0;
  };
  std::vector<Slot> slots() const {
    std::vector<int> joints = sel_;
    std::sort(joints.begin(), joints.end());
    std::vector<Slot> out;
    for (int j : joints) {
      if (!eps_param_.empty()) out.push_back({true, j});
      if (stribeck_) out.push_back({false, j});
    }
    return out;
  }
  exid::FrictionColumns frictionColumns() const {
    exid::FrictionColumns fc;
    fc.coulomb = coulomb_extra_;
    fc.asymmetric = asym_;
    fc.stribeck = stribeck_;
    fc.delta = delta_;
    return fc;
  }
  int extraPerJoint() const { return frictionColumns().perJoint(); }
  double perJoint(const std::vector<double>& v, int j) const {
    if (v.size() != 1 && static_cast<int>(v.size()) != robot().dof())  // (a hot path)
      throw exid::Error(
          fmt::format("model 'differential': {} values given for robot '{}' of {} drives "
                      "(expected one, or one per drive)",
                      v.size(), robot().name, robot().dof()));
    return v.size() == 1 ? v[0] : v[static_cast<std::size_t>(j)];
  }
  Eigen::VectorXd studyEta() const {
    const std::vector<exid::NonlinearParameter> nl = nonlinearParameters();
    Eigen::VectorXd eta(static_cast<Eigen::Index>(nl.size()));
    for (std::size_t k = 0; k < nl.size(); ++k) eta[static_cast<Eigen::Index>(k)] = nl[k].value;
    return eta;
  }

  std::vector<std::int64_t> joints_param_;
  std::string friction_;
  exid::DriveColumns cols_;
  std::vector<int> sel_;
  bool asym_ = false, stribeck_ = false, coulomb_extra_ = false, gains_ = false;
  bool gains_prior_ = false;  // drive_gains_scale: prior
  Eigen::Matrix<double, 10, 1> phi_ = Eigen::Matrix<double, 10, 1>::Zero();  // drive_gains' payload
  Eigen::Matrix<double, 10, 1> design_phi_ = Eigen::Matrix<double, 10, 1>::Zero();  // the design's
  int gainCount() const { return gains_ ? robot().dof() : 0; }
  bool load_ = false;  // coulomb_load
  int loadCount() const { return load_ ? robot().dof() : 0; }
  std::vector<double> eps_param_, vs_param_;
  double delta_ = 2.0;
};

}  // namespace exid::differential
