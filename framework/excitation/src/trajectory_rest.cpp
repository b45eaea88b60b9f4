// Whether a trajectory for execution starts and ends at rest (TrajectoryCheck::start, end): a
// controller handed a first sample with a velocity must bring the robot to that state first.
#include <fmt/format.h>

#include <cmath>

#include "exid/trajectory_export.hpp"

namespace exid {

EndMotion endMotion(const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd, int k,
                    const RobotModel& robot) {
  EndMotion e;
  for (Eigen::Index j = 0; j < qd.cols(); ++j) {
    const auto J = static_cast<std::size_t>(j);
    const JointLimits L = J < robot.limits.size() ? robot.limits[J] : JointLimits{};
    auto tolerance = [](double limit) {
      return std::isfinite(limit) && limit > 0 && limit < 1e299 ? kRestTolerance * limit
                                                                : kRestTolerance;
    };
    const double v = qd(k, j), a = qdd(k, j);
    e.qd.push_back(v);
    e.qdd.push_back(a);
    if (!(std::abs(v) <= tolerance(L.qd_max)) || !(std::abs(a) <= tolerance(L.qdd_max)))
      e.moving.push_back(static_cast<int>(j) + 1);
  }
  e.at_rest = e.moving.empty();
  return e;
}

Json EndMotion::toJson() const {
  Json o = Json::object();
  o["at_rest"] = at_rest;
  o["qd"] = Json(qd);
  o["qdd"] = Json(qdd);
  Json m = Json::array();
  for (int j : moving) m.push_back(j);
  o["moving_joints"] = m;
  return o;
}

namespace {

std::string endText(const TrajectoryCheck& c, const EndMotion& e) {
  std::string s;
  for (int j : e.moving) {
    const auto J = static_cast<std::size_t>(j - 1);
    const bool lin = J < c.prismatic.size() && c.prismatic[J];
    const bool named = J < c.joint_names.size() && !c.joint_names[J].empty() &&
                       c.joint_names[J] != fmt::format("joint{}", j);
    const std::string name = named ? " (" + c.joint_names[J] + ")" : "";
    s += fmt::format("{}joint {}{} at qd = {:.4g} {}, qdd = {:.4g} {}", s.empty() ? "" : "; ", j,
                     name, e.qd[J], lin ? "m/s" : "rad/s", e.qdd[J], lin ? "m/s^2" : "rad/s^2");
  }
  return s;
}

}  // namespace

std::string TrajectoryCheck::restText() const {
  std::string s;
  if (!start.at_rest) s += fmt::format("NOT AT REST at the start: {}\n", endText(*this, start));
  if (!end.at_rest) s += fmt::format("NOT AT REST at the end: {}\n", endText(*this, end));
  if (!s.empty())
    s += fmt::format(
        "(at rest: |qd| <= {0:g} qd_max and |qdd| <= {0:g} qdd_max per joint.) A controller must "
        "bring the robot to the first sample's position, velocity and acceleration before "
        "playing the trajectory (and stop it after the last): ramp in and out, or design the "
        "trajectory with rest_to_rest: true.\n",
        kRestTolerance);
  return s;
}

}  // namespace exid
