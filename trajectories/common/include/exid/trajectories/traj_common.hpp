// Shared by the trajectory plugins (pointwise, fourier, spline): the common parameters, the
// joint set that moves, effective limits (robot limits less the margin, optionally capped by
// the trajectory's own velocity/acceleration caps, which reach the excitation problem through
// Trajectory::adjustLimits), and a base class for trajectories that are a constant plus a
// per-joint linear basis (fourier, spline): q_j = c_j + Bq z_j, etc.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "exid/interfaces.hpp"

namespace exid::trajectories {

/// Parameters every trajectory declares: sample_period_s, samples, position_margin_rad,
/// velocity_limits, acceleration_limits, velocity_limit_rad_s, acceleration_limit_rad_s2,
/// joints, rest_position_rad.
std::vector<ParamDecl> commonParams();

struct CommonOptions {
  double sample_period = 0.1;
  int samples = 0;  // 0: from the period/duration and sample_period
  double margin = 0.0;
  bool velocity_limits = true, acceleration_limits = true;
  double velocity_cap = 0.0, acceleration_cap = 0.0;  // 0: none
  std::vector<std::int64_t> joints;                   // 1-based; empty: all
  std::vector<double> rest;                           // per joint or one value; empty: centre
};
CommonOptions readCommon(const ParamSet& p);

/// Resolved at bind(): measured coordinates, limits as the excitation problem applies them
/// (margin included) and the caps.
struct JointSpace {
  int n = 0;
  std::vector<int> moving;          // 0-based indices of the joints that move
  Eigen::VectorXd rest;             // n: positions of every joint when it does not move
  Eigen::VectorXd centre;           // n: centre of the (margined) range, or 0 if unlimited
  Eigen::VectorXd q_lo, q_hi;       // n: position range less the margin (+-inf if none)
  Eigen::VectorXd qd_max, qdd_max;  // n: effective limits (+inf if none or not imposed)
  Eigen::VectorXd qd_cap, qdd_cap;  // n: the trajectory's own caps (+inf if none)
  // n: the caps in joint coordinates (the excitation problem's limits): cap x |T_jj| with a
  // diagonal transmission, else the cap itself (then a joint-coordinate cap).
  Eigen::VectorXd qd_cap_joint, qdd_cap_joint;
  bool hasCaps() const;
  bool hasVelocityCap() const;
  bool hasAccelerationCap() const;
};
JointSpace resolveJoints(const RobotModel& robot, const CommonOptions& o, const std::string& who);

/// Trajectory::adjustLimits for every trajectory plugin: velocity/acceleration limits the
/// trajectory does not impose are dropped (+inf), and its caps tighten the rest (or stand alone).
void adjustLimitsCommon(const JointSpace& js, const CommonOptions& o,
                        std::vector<JointLimits>* limits);

/// What describe() says (for the report): "linear", the moving joints, the margin and the caps.
Json describeCommon(const JointSpace& js, const CommonOptions& o, bool linear);

/// The capabilities every trajectory plugin declares: its moving joints and linearity.
TrajectorySpecs specsCommon(const JointSpace& js, bool linear);

/// Parameters of the trajectories that can start and stop at rest: rest_to_rest,
/// start_position_rad.
std::vector<ParamDecl> restToRestParams();
/// start_position_rad resolved (n entries, every joint's; held joints: their rest position), or
/// empty when not given. Checked against the (margined) position range of the moving joints.
Eigen::VectorXd resolveStart(const JointSpace& js, const std::vector<double>& start,
                             const std::string& who);

/// Sample count for a window of length T [s]: `samples` if set, else round(T / dt) (+1 when the
/// end point is included).
/// Design samples at most (samples, or T / sample_period_s); checked before any allocation.
inline constexpr double kMaxDesignSamples = 1e6;
int sampleCount(const CommonOptions& o, double T, bool include_end, const std::string& who,
                const std::string& t_key = "duration_s");

/// Trajectory whose signals are a constant plus a basis shared by every moving joint:
/// q(:, j) = Bq z_j (+ a constant offset_j), qd(:, j) = Bqd z_j, qdd(:, j) = Bqdd z_j (z_j: m
/// variables per moving joint, stored joint after joint). Held joints stay at rest. Exact, cached
/// Jacobian. The basis is a function of time (basisAt), so the trajectory is also evaluated at
/// arbitrary times (evaluateAt, vjpAt); the sample grid's basis is the same function at the sample
/// times.
class BasisTrajectory : public Trajectory {
 public:
  int numVariables() const override { return m_ * static_cast<int>(js_.moving.size()); }
  Samples evaluate(const Eigen::VectorXd& z) const override;
  Eigen::VectorXd vjp(const Eigen::VectorXd& z, const Samples& adj) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& z) const override;
  /// Moving joints, linear, continuous; subclasses add the duration and whether it is periodic.
  TrajectorySpecs specs() const override { return basisSpecs(); }
  Samples evaluateAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t) const override;
  Eigen::VectorXd vjpAt(const Eigen::VectorXd& z, const Eigen::VectorXd& t,
                        const Samples& adj) const override;
  double positionMargin() const override { return opt_.margin; }
  // A cap is imposed even when the robot's own limits are not (adjustLimits drops those).
  bool velocityLimits() const override { return opt_.velocity_limits || js_.hasVelocityCap(); }
  bool accelerationLimits() const override {
    return opt_.acceleration_limits || js_.hasAccelerationCap();
  }
  void adjustLimits(std::vector<JointLimits>* limits) const override {
    adjustLimitsCommon(js_, opt_, limits);
  }
  Json describe() const override;
  const JointSpace& joints() const { return js_; }

 protected:
  /// The basis rows (m values each) of q, qd and qdd at time t. Valid after bind().
  virtual void basisAt(double t, Eigen::RowVectorXd* bq, Eigen::RowVectorXd* bqd,
                       Eigen::RowVectorXd* bqdd) const = 0;
  /// The sample grid t with its basis from basisAt; called by subclasses' bind() once the basis
  /// function is set up (m: variables per moving joint).
  void setGrid(Eigen::VectorXd t, int m);
  TrajectorySpecs basisSpecs() const;
  /// z <- zref + s_j (z - zref) per moving joint j, s_j chosen so that the deviation from the
  /// reference (whose signals are the constant centre_j) uses `fraction` of the tightest of the
  /// joint's half position range (about the centre), velocity and acceleration limits.
  void scaleIntoLimits(Eigen::VectorXd* z, const Eigen::VectorXd& zref, double fraction) const;

  /// Constant added to q of each moving joint (n entries; empty: none): the start position of a
  /// trajectory whose variables describe the motion relative to it.
  double offset(int j) const { return q_offset_.size() ? q_offset_(j) : 0.0; }
  Eigen::VectorXd q_offset_;

  CommonOptions opt_;
  JointSpace js_;
  Eigen::VectorXd t_;
  Eigen::MatrixXd Bq_, Bqd_, Bqdd_;
  int m_ = 0;
  mutable Eigen::MatrixXd J_;  // cached dense Jacobian
};

}  // namespace exid::trajectories
