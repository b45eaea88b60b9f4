// exid — an excitation trajectory written for execution on a robot: sampled at a controller's
// rate (trajectory.csv: t, q, qd, qdd and the torque the robot's full model predicts), the
// trajectory's own parameters (trajectory.params.yaml) and a ROS 2 trajectory_msgs/JointTrajectory
// (joint_trajectory.yaml); and the check of such a file against the robot's limits at its own
// rate (the worst margin of each limit).
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "exid/collision.hpp"
#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/robot_model.hpp"

namespace exid {

class Trajectory;

struct EXID_API TrajectoryExportOptions {
  double rate_Hz = 1000.0;  // controller rate
  int periods = 1;          // repetitions (periodic, or rest to rest back to the start)
  /// tau_max per measured coordinate [N m or N]; empty: the robot's limits (URDF effort). The
  /// check reports the torque margin only when they are known.
  std::vector<double> torque_max;
  /// The fraction of tau_max the design was held to (0: none); reported beside the check.
  double torque_margin = 0.0;
  /// Collision avoidance the design was held to (null: none): the check reports the minimum
  /// distance over every sample and checked pair, and the plots draw it over time.
  std::shared_ptr<const CollisionOptions> collision;
  bool plots = true;
};

/// The trajectory at z sampled at rate_Hz over `periods` repetitions, both ends included:
/// t_i = i / rate_Hz. Throws exid::Error for a trajectory defined on its sample grid only, for
/// periods > 1 of one that does not end in its start state, and for a rate that does not divide
/// the duration.
EXID_API Samples resampleTrajectory(const Trajectory& trajectory, const Eigen::VectorXd& z,
                                    double rate_Hz, int periods);

/// The worst case of one limit over a trajectory.
struct EXID_API LimitWorst {
  std::string what;      // "position", "velocity", "acceleration", "torque", "distance"
  bool checked = false;  // false: the robot has no such limit
  int joint = 0;         // 1-based
  double t_s = 0.0;      // when
  double value = 0.0;    // the signal there (position: q; others: |x|)
  double limit = 0.0;    // the limit it is held to (position: the nearer of q_min, q_max)
  double margin = 0.0;   // limit - value (position: distance to the nearer limit); < 0: violated
  double ratio = 0.0;    // |x| / x_max (position: 0 at the centre, 1 at a limit)
};

/// The motion at one end of a trajectory (its first or last sample), in joint coordinates. At
/// rest when |qd_j| <= kRestTolerance qd_max,j and |qdd_j| <= kRestTolerance qdd_max,j for every
/// joint (kRestTolerance rad/s or m/s, rad/s^2 or m/s^2 where the robot has no such limit): a
/// trajectory that does not start at rest needs the robot brought to its first state first.
struct EXID_API EndMotion {
  bool at_rest = true;
  std::vector<double> qd, qdd;  // per joint
  std::vector<int> moving;      // 1-based joints not at rest
  Json toJson() const;          // {at_rest, qd, qdd, moving_joints}
};
inline constexpr double kRestTolerance = 1e-3;

/// The motion at sample k of joint-coordinate velocities and accelerations (K x n).
EXID_API EndMotion endMotion(const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd, int k,
                             const RobotModel& robot);

struct EXID_API TrajectoryCheck {
  int samples = 0;
  double rate_Hz = 0.0;             // measured: (samples - 1) / duration
  double max_rate_deviation = 0.0;  // max |t_i+1 - t_i - 1/rate| / (1/rate)
  /// position, velocity, acceleration, torque[, distance: value = the smallest signed distance
  /// [m], limit 0 (contact: a violation only when the bodies overlap), ratio = the design's
  /// margin_m / distance (above 1: inside the design margin), joint 0, distance_pair the pair]
  std::vector<LimitWorst> worst;
  std::string distance_pair;  // "link3 ~ table"
  /// max |tau in the file - tau the robot's model predicts| (NaN when the file has no tau).
  double tau_file_deviation = 0.0;
  bool ok = true;  // every checked limit holds
  /// The first and the last sample: at rest or not (not a limit: `ok` does not depend on it).
  EndMotion start, end;
  std::vector<std::string> joint_names;  // the robot's, per joint ("" unknown)
  std::vector<bool> prismatic;           // per joint: m/s instead of rad/s
  Json toJson() const;
  std::string text() const;  // a small table for the terminal, then restText()
  /// "" when the trajectory starts and ends at rest; otherwise which joints start (end) at what
  /// velocity and acceleration, and what that asks of whoever runs it.
  std::string restText() const;
};

/// Checks samples (measured coordinates) against the robot's limits: q within [q_min, q_max],
/// |qd| <= qd_max, |qdd| <= qdd_max, |tau| <= tau_max with tau the torque of the robot's full
/// model (rigid body + drives, nominal parameters), at every sample; with collision options, the
/// signed distance of every checked pair >= margin_m at every sample (min_distance_m gets the
/// per-sample minimum over the pairs).
EXID_API TrajectoryCheck checkTrajectory(const Samples& s, const RobotModel& robot,
                                         const std::vector<double>& torque_max,
                                         const Eigen::MatrixXd* tau_file = nullptr,
                                         const CollisionOptions* collision = nullptr,
                                         Eigen::VectorXd* min_distance_m = nullptr);
/// Reads a trajectory CSV (t, q1..qn, qd1..qdn, qdd1..qddn, optional tau1..taun) and checks it.
EXID_API TrajectoryCheck checkTrajectoryCsv(const std::filesystem::path& csv,
                                            const RobotModel& robot,
                                            const std::vector<double>& torque_max,
                                            const CollisionOptions* collision = nullptr,
                                            Eigen::VectorXd* min_distance_m = nullptr);

/// The folder an export is published as: dir made absolute (a symbolic link: its target). It
/// must be absent, empty or an earlier export (it holds trajectory_check.json), which the
/// export replaces whole; anything else throws exid::Error naming what the folder holds.
EXID_API std::filesystem::path exportFolder(const std::filesystem::path& dir);

/// Writes dir/trajectory.csv, dir/trajectory.params.yaml, dir/joint_trajectory.yaml,
/// dir/trajectory_check.json and the plots (dir/plots/trajectory_*): everything is written into
/// a staging folder beside dir first, which then replaces dir whole in one rename (see
/// exportFolder), so a failure leaves no partial set and dir holds this export only.
/// The check re-reads the written CSV. Returns the check (and what was written) as JSON.
EXID_API Json exportTrajectory(const Trajectory& trajectory, const std::string& trajectory_type,
                               const ParamSet& trajectory_params, const Eigen::VectorXd& z,
                               const RobotModel& robot, const TrajectoryExportOptions& options,
                               const std::filesystem::path& dir, TrajectoryCheck* check = nullptr);

}  // namespace exid
