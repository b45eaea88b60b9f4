#include "exid/trajectory_export.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <stdio.h>
#include <unistd.h>

#include <cctype>
#include <cmath>
#include <sstream>
#include <variant>

#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/signal.hpp"
#include "figures.hpp"
#include "plot.hpp"

namespace exid {

namespace fs = std::filesystem;

namespace {

bool finiteLimit(double x) { return std::isfinite(x) && std::abs(x) < 1e299; }

// A YAML double-quoted scalar.
std::string quoted(const std::string& s) {
  std::string o = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\')
      o += '\\', o += c;
    else if (static_cast<unsigned char>(c) < 0x20)
      o += fmt::format("\\x{:02x}", static_cast<unsigned char>(c));
    else
      o += c;
  }
  return o + "\"";
}

std::string number(double x) {
  if (std::isnan(x)) return ".nan";
  if (std::isinf(x)) return x > 0 ? ".inf" : "-.inf";
  return fmt::format("{}", x);
}

std::string flowList(const double* v, Eigen::Index n) {
  std::string s = "[";
  for (Eigen::Index i = 0; i < n; ++i) s += (i ? ", " : "") + number(v[i]);
  return s + "]";
}

std::string paramYaml(const ParamValue& v) {
  return std::visit(
      [](const auto& x) -> std::string {
        using T = std::decay_t<decltype(x)>;
        if constexpr (std::is_same_v<T, bool>)
          return x ? "true" : "false";
        else if constexpr (std::is_same_v<T, std::int64_t>)
          return std::to_string(x);
        else if constexpr (std::is_same_v<T, double>)
          return number(x);
        else if constexpr (std::is_same_v<T, std::string>)
          return quoted(x);
        else if constexpr (std::is_same_v<T, std::vector<double>>)
          return flowList(x.data(), static_cast<Eigen::Index>(x.size()));
        else if constexpr (std::is_same_v<T, std::vector<std::int64_t>>) {
          std::string s = "[";
          for (std::size_t i = 0; i < x.size(); ++i) s += (i ? ", " : "") + std::to_string(x[i]);
          return s + "]";
        } else {
          std::string s = "[";
          for (std::size_t i = 0; i < x.size(); ++i) s += (i ? ", " : "") + quoted(x[i]);
          return s + "]";
        }
      },
      v);
}

bool scalarArray(const Json& j) {
  if (!j.isArray()) return false;
  for (const auto& kv : j.items())
    if (kv.second.isArray() || kv.second.isObject()) return false;
  return true;
}

std::string scalarYaml(const Json& j) {
  switch (j.type()) {
    case Json::Type::Null:
      return "null";
    case Json::Type::Bool:
      return j.asBool() ? "true" : "false";
    case Json::Type::Int:
      return std::to_string(j.asInt());
    case Json::Type::Double:
      return number(j.asDouble());
    case Json::Type::String:
      return quoted(j.asString());
    default:
      return "";
  }
}

// Json as block YAML (objects as mappings, arrays of scalars in flow style).
void jsonYaml(const Json& j, int indent, std::string& out) {
  const std::string pad(static_cast<std::size_t>(indent), ' ');
  if (j.isObject()) {
    for (const auto& [k, v] : j.items()) {
      out += pad + k + ":";
      if (v.isObject() && v.size() > 0) {
        out += "\n";
        jsonYaml(v, indent + 2, out);
      } else if (v.isArray() && !scalarArray(v)) {
        out += "\n";
        jsonYaml(v, indent + 2, out);
      } else if (v.isArray()) {
        out += " [";
        for (std::size_t i = 0; i < v.size(); ++i) out += (i ? ", " : "") + scalarYaml(v.at(i));
        out += "]\n";
      } else if (v.isObject()) {
        out += " {}\n";
      } else {
        out += " " + scalarYaml(v) + "\n";
      }
    }
  } else if (j.isArray()) {
    for (const auto& kv : j.items()) {
      const Json& v = kv.second;
      if (v.isObject()) {
        std::string inner;
        jsonYaml(v, indent + 2, inner);
        // "- " takes the place of the first line's indentation
        out += pad + "- " + inner.substr(static_cast<std::size_t>(indent) + 2);
      } else {
        out += pad + "- " + scalarYaml(v) + "\n";
      }
    }
  }
}

std::vector<std::string> names(const char* prefix, int n) {
  std::vector<std::string> v;
  for (int j = 1; j <= n; ++j) v.push_back(fmt::format("{}{}", prefix, j));
  return v;
}

// tau_max per measured coordinate when known (empty otherwise).
Eigen::VectorXd knownTorqueLimits(const RobotModel& robot, const std::vector<double>& torque_max) {
  const int n = robot.dof();
  if (!torque_max.empty()) {
    check(static_cast<int>(torque_max.size()) == n,
          fmt::format("torque_max_Nm has {} values; robot '{}' has {} joints", torque_max.size(),
                      robot.name, n));
    return Eigen::Map<const Eigen::VectorXd>(torque_max.data(), n);
  }
  if (robot.hasTransmission()) return {};
  Eigen::VectorXd t(n);
  for (int j = 0; j < n; ++j) {
    const double x = j < static_cast<int>(robot.limits.size())
                         ? robot.limits[static_cast<std::size_t>(j)].tau_max
                         : HUGE_VAL;
    if (!(x > 0) || !finiteLimit(x)) return {};
    t(j) = x;
  }
  return t;
}

}  // namespace

Samples resampleTrajectory(const Trajectory& traj, const Eigen::VectorXd& z, double rate_Hz,
                           int periods) {
  const TrajectorySpecs sp = traj.specs();
  const std::string who = fmt::format("export of trajectory '{}'", traj.pluginName());
  check(sp.continuous,
        fmt::format("{}: it is defined on its sample grid only; a trajectory for a controller must "
                    "be defined at any time (fourier, spline)",
                    who));
  check(sp.duration_s > 0, fmt::format("{}: the trajectory declares no duration", who));
  check(std::isfinite(rate_Hz) && rate_Hz > 0,
        fmt::format("{}: rate_Hz = {}: must be a positive rate", who, rate_Hz));
  check(periods >= 1, fmt::format("{}: periods = {}: must be at least 1", who, periods));
  check(periods == 1 || sp.repeatable,
        fmt::format("{}: periods = {}, but the motion does not end in the state it starts in "
                    "(give a periodic trajectory, or rest_to_rest with start_position_rad)",
                    who, periods));
  const double T = sp.duration_s;
  const double steps = T * rate_Hz;
  const long per = std::lround(steps);
  check(per >= 1 && std::abs(steps - static_cast<double>(per)) <= 1e-9 * steps,
        fmt::format("{}: the duration {} s is not a whole number of controller periods at {} Hz "
                    "({} steps)",
                    who, T, rate_Hz, steps));
  const long N = per * periods;
  check(N < 100000000, fmt::format("{}: {} samples are too many", who, N + 1));
  Eigen::VectorXd local(N + 1), t(N + 1);
  for (long i = 0; i <= N; ++i) {
    t(i) = static_cast<double>(i) / rate_Hz;
    local(i) = i == N ? T : static_cast<double>(i % per) / rate_Hz;
  }
  Samples s = traj.evaluateAt(z, local);
  s.t = t;
  return s;
}

namespace {

// The smallest signed distance over the checked pairs at every sample, and the worst of all.
LimitWorst distanceWorst(const Samples& s, const RobotModel& robot, const CollisionOptions& o,
                         Eigen::VectorXd* min_distance, std::string* pair) {
  CollisionModel cm(robot, o);
  const int K = s.size();
  LimitWorst w;
  w.what = "distance";
  w.checked = true;
  w.value = HUGE_VAL;
  if (min_distance) min_distance->resize(K);
  Eigen::VectorXd d;
  for (int k = 0; k < K; ++k) {
    cm.distances(s.q.row(k).transpose(), &d);
    Eigen::Index p = 0;
    const double dk = d.minCoeff(&p);
    if (min_distance) (*min_distance)(k) = dk;
    if (dk < w.value) {
      w.value = dk;
      w.t_s = s.t(k);
      *pair = cm.pairNames()[static_cast<std::size_t>(p)];
    }
  }
  // The hard limit is contact (0), as the robot's own limits are for the joints; the design's
  // margin is reported beside it (ratio = margin_m / distance: above 1 inside the margin).
  w.limit = 0.0;
  w.margin = w.value;
  w.ratio = w.value > 0 ? o.margin_m / w.value : HUGE_VAL;
  return w;
}

}  // namespace

TrajectoryCheck checkTrajectory(const Samples& s, const RobotModel& robot,
                                const std::vector<double>& torque_max,
                                const Eigen::MatrixXd* tau_file, const CollisionOptions* collision,
                                Eigen::VectorXd* min_distance_m) {
  const int n = robot.dof(), K = s.size();
  check(s.dof() == n && K >= 2,
        fmt::format("trajectory check: {} joints and {} samples (robot '{}' has {} joints; at "
                    "least 2 samples are needed)",
                    s.dof(), K, robot.name, n));
  TrajectoryCheck c;
  c.samples = K;
  const double dur = s.t(K - 1) - s.t(0);
  c.rate_Hz = dur > 0 ? (K - 1) / dur : 0.0;
  if (c.rate_Hz > 0)
    for (int k = 0; k + 1 < K; ++k)
      c.max_rate_deviation =
          std::max(c.max_rate_deviation, std::abs((s.t(k + 1) - s.t(k)) * c.rate_Hz - 1.0));
  // joint coordinates for the joint limits
  Eigen::MatrixXd q(K, n), qd(K, n), qdd(K, n);
  for (int k = 0; k < K; ++k) {
    Eigen::VectorXd a, b, e;
    measuredToJoint(robot, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                    s.qdd.row(k).transpose(), &a, &b, &e);
    q.row(k) = a.transpose();
    qd.row(k) = b.transpose();
    qdd.row(k) = e.transpose();
  }
  auto limitOf = [&](int j) {
    return j < static_cast<int>(robot.limits.size()) ? robot.limits[static_cast<std::size_t>(j)]
                                                     : JointLimits{};
  };
  LimitWorst pos{"position"}, vel{"velocity"}, acc{"acceleration"}, trq{"torque"};
  pos.margin = HUGE_VAL;
  for (LimitWorst* w : {&vel, &acc, &trq}) w->ratio = -1.0;
  for (int j = 0; j < n; ++j) {
    const JointLimits L = limitOf(j);
    if (finiteLimit(L.q_min) && finiteLimit(L.q_max)) {
      const double centre = 0.5 * (L.q_min + L.q_max), half = 0.5 * (L.q_max - L.q_min);
      for (int k = 0; k < K; ++k) {
        const double x = q(k, j);
        const double m = std::min(x - L.q_min, L.q_max - x);
        if (m < pos.margin) {
          pos = {"position", true,
                 j + 1,      s.t(k),
                 x,          x - L.q_min < L.q_max - x ? L.q_min : L.q_max,
                 m,          half > 0 ? std::abs(x - centre) / half : 0.0};
        }
      }
    }
    auto rateCheck = [&](LimitWorst& w, const Eigen::MatrixXd& x, double lim) {
      if (!finiteLimit(lim) || !(lim > 0)) return;
      for (int k = 0; k < K; ++k) {
        const double r = std::abs(x(k, j)) / lim;
        if (r > w.ratio)
          w = {w.what, true, j + 1, s.t(k), std::abs(x(k, j)), lim, lim - std::abs(x(k, j)), r};
      }
    };
    rateCheck(vel, qd, L.qd_max);
    rateCheck(acc, qdd, L.qdd_max);
  }
  const Eigen::VectorXd tmax = knownTorqueLimits(robot, torque_max);
  const Eigen::MatrixXd tau = predictedTorques(robot, s);
  if (tmax.size() == n) {
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < K; ++k) {
        const double r = std::abs(tau(k, j)) / tmax(j);
        if (r > trq.ratio)
          trq = {"torque",
                 true,
                 j + 1,
                 s.t(k),
                 std::abs(tau(k, j)),
                 tmax(j),
                 tmax(j) - std::abs(tau(k, j)),
                 r};
      }
  }
  c.tau_file_deviation = tau_file && tau_file->rows() == K && tau_file->cols() == n
                             ? (*tau_file - tau).cwiseAbs().maxCoeff()
                             : std::nan("");
  for (LimitWorst* w : {&pos, &vel, &acc, &trq}) {
    if (!w->checked) {
      w->margin = 0.0;
      w->ratio = 0.0;
    }
    c.worst.push_back(*w);
    if (w->checked && w->margin < 0) c.ok = false;
  }
  c.start = endMotion(qd, qdd, 0, robot);
  c.end = endMotion(qd, qdd, K - 1, robot);
  for (int j = 0; j < robot.dof(); ++j) {  // measured coordinates (a closed chain's actuated)
    const Body& b = robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))];
    c.joint_names.push_back(b.joint_name);
    c.prismatic.push_back(b.type == JointType::Prismatic);
  }
  if (static_cast<int>(c.joint_names.size()) != n) c.joint_names.clear();
  if (collision) {
    c.worst.push_back(distanceWorst(s, robot, *collision, min_distance_m, &c.distance_pair));
    if (c.worst.back().margin < 0) c.ok = false;
  }
  return c;
}

namespace {

// A trajectory file is checked at its own samples: its columns must be the robot's (a column of
// a joint the robot does not have is refused, never ignored), its time must strictly increase
// (swapped or repeated rows) at a uniform rate (a gap, or uneven stamps, would hide what
// happens between samples), as the csv experiment reads a recording.
void checkTrajectoryFile(const fs::path& csv, const CsvTable& T, const RobotModel& robot) {
  const int n = robot.dof();
  const std::string expected = fmt::format(
      "robot '{}' has {} joints; expected t, q1..q{}, qd1..qd{}, qdd1..qdd{} [, "
      "tau1..tau{}]",
      robot.name, n, n, n, n, n);
  check(T.has("t"), fmt::format("{}: no column 't' (the time [s]; {})", csv.string(), expected));
  for (const std::string& c : T.columns) {
    std::size_t i = 0;
    while (i < c.size() && std::isalpha(static_cast<unsigned char>(c[i]))) ++i;
    const std::string prefix = c.substr(0, i), digits = c.substr(i);
    if (digits.empty() || digits.size() > 9 ||
        digits.find_first_not_of("0123456789") != std::string::npos)
      continue;
    if (prefix != "q" && prefix != "qd" && prefix != "qdd" && prefix != "tau") continue;
    const long j = std::stol(digits);
    check(j >= 1 && j <= n,
          fmt::format("{}: column '{}': joint {} is not a joint of the robot ({}); a file for "
                      "another robot is refused, not read in part",
                      csv.string(), c, j, expected));
  }
  const Eigen::VectorXd t = T.column("t");
  const Eigen::Index K = t.size();
  check(K >= 2,
        fmt::format("{}: {} data row(s); the check needs at least 2 samples", csv.string(), K));
  auto lineOf = [&](Eigen::Index k) {
    return static_cast<std::size_t>(k) < T.line_of.size() ? T.line_of[static_cast<std::size_t>(k)]
                                                          : static_cast<int>(k) + 2;
  };
  for (Eigen::Index k = 1; k < K; ++k)
    check(t(k) > t(k - 1),
          fmt::format("{}: line {} (data row {}): column 't': time must strictly increase; t = "
                      "{} s after t = {} s at line {} (rows swapped or repeated?)",
                      csv.string(), lineOf(k), k + 1, t(k), t(k - 1), lineOf(k - 1)));
  // Uniform steps: within kMaxStepRatio of the median step (the csv experiment's default
  // max_gap_ratio), as exid::samplingStats counts gaps.
  constexpr double kMaxStepRatio = 1.5;
  const auto steps = static_cast<std::size_t>(K - 1);
  const double med = medianOfValues(steps, [&](std::size_t i) {
    return t(static_cast<Eigen::Index>(i) + 1) - t(static_cast<Eigen::Index>(i));
  });
  for (Eigen::Index k = 1; k < K; ++k) {
    const double step = t(k) - t(k - 1);
    check(step <= kMaxStepRatio * med && step >= med / kMaxStepRatio,
          fmt::format(
              "{}: line {} (data row {}): time step {:.6g} s against a median step of {:.6g} s: "
              "{} (the limits are checked at the file's samples, which must come at a "
              "uniform rate; steps may differ from the median by a factor of {} at most)",
              csv.string(), lineOf(k), k + 1, step, med,
              step > med ? "a gap" : "uneven time stamps", kMaxStepRatio));
  }
}

}  // namespace

TrajectoryCheck checkTrajectoryCsv(const fs::path& csv, const RobotModel& robot,
                                   const std::vector<double>& torque_max,
                                   const CollisionOptions* collision,
                                   Eigen::VectorXd* min_distance_m) {
  const CsvTable T = readCsv(csv);
  checkTrajectoryFile(csv, T, robot);
  const int n = robot.dof();
  Samples s;
  s.t = T.column("t");
  const Eigen::Index K = s.t.size();
  s.q.resize(K, n);
  s.qd.resize(K, n);
  s.qdd.resize(K, n);
  Eigen::MatrixXd tau(K, n);
  bool has_tau = true;
  for (int j = 0; j < n; ++j) {
    for (const auto& [prefix, m] :
         {std::pair<const char*, Eigen::MatrixXd*>{"q", &s.q}, {"qd", &s.qd}, {"qdd", &s.qdd}}) {
      const std::string name = fmt::format("{}{}", prefix, j + 1);
      check(T.has(name), fmt::format("{}: no column '{}' (robot '{}' has {} joints; expected t, "
                                     "q1..q{}, qd1..qd{}, qdd1..qdd{})",
                                     csv.string(), name, robot.name, n, n, n, n));
      m->col(j) = T.column(name);
    }
    const std::string tn = fmt::format("tau{}", j + 1);
    if (T.has(tn))
      tau.col(j) = T.column(tn);
    else
      has_tau = false;
  }
  return checkTrajectory(s, robot, torque_max, has_tau ? &tau : nullptr, collision, min_distance_m);
}

Json TrajectoryCheck::toJson() const {
  Json j = Json::object();
  j["ok"] = ok;
  j["samples"] = samples;
  j["rate_Hz"] = rate_Hz;
  j["max_rate_deviation"] = max_rate_deviation;
  Json w = Json::object();
  for (const LimitWorst& x : worst) {
    Json e = Json::object();
    e["checked"] = x.checked;
    if (x.checked) {
      if (x.what == "distance")
        e["pair"] = distance_pair;
      else
        e["joint"] = x.joint;
      e["t_s"] = x.t_s;
      e["value"] = x.value;
      e["limit"] = x.limit;
      e["margin"] = x.margin;
      e["ratio"] = x.ratio;
    }
    w[x.what] = e;
  }
  j["worst"] = w;
  if (std::isfinite(tau_file_deviation)) j["tau_file_deviation"] = tau_file_deviation;
  j["start"] = start.toJson();
  j["end"] = end.toJson();
  return j;
}

std::string TrajectoryCheck::text() const {
  std::string s = fmt::format("{} samples at {:.6g} Hz\n", samples, rate_Hz);
  s +=
      "| limit | joint | t [s] | value | limit | margin | ratio |\n|---|---|---|---|---|---|---|\n";
  for (const LimitWorst& x : worst) {
    if (!x.checked) {
      s += fmt::format("| {} | - | - | - | none | - | - |\n", x.what);
      continue;
    }
    s += fmt::format("| {} | {} | {:.4f} | {:.6g} | {:.6g} | {:.6g}{} | {:.4f} |\n", x.what,
                     x.what == "distance" ? distance_pair : std::to_string(x.joint), x.t_s, x.value,
                     x.limit, x.margin, x.margin < 0 ? " VIOLATED" : "", x.ratio);
  }
  if (std::isfinite(tau_file_deviation))
    s += fmt::format("torque in the file vs the robot's model: max difference {:.3g}\n",
                     tau_file_deviation);
  return s + restText();
}

namespace {

// trajectory.csv: the dataset columns (docs/conventions.md §1), tau predicted
void writeTrajectoryCsv(const fs::path& file, const Samples& s, const Eigen::MatrixXd& tau) {
  const int n = s.dof();
  const Eigen::Index K = s.size();
  CsvTable table;
  table.columns = {"t"};
  for (const char* p : {"q", "qd", "qdd", "tau"})
    for (auto& c : names(p, n)) table.columns.push_back(c);
  table.data.resize(K, 1 + 4 * n);
  table.data.col(0) = s.t;
  table.data.middleCols(1, n) = s.q;
  table.data.middleCols(1 + n, n) = s.qd;
  table.data.middleCols(1 + 2 * n, n) = s.qdd;
  table.data.middleCols(1 + 3 * n, n) = tau;
  writeCsvAtomic(file, table);
}

std::vector<std::string> quotedJointNames(const RobotModel& robot) {
  std::vector<std::string> jn;
  for (int j = 0; j < robot.dof(); ++j)
    jn.push_back(quoted(robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name));
  return jn;
}

// trajectory.params.yaml: the trajectory's own parameters (the same trajectory again)
void writeParamsYaml(const fs::path& file, const Trajectory& traj, const std::string& type,
                     const ParamSet& params, const Eigen::VectorXd& z, const RobotModel& robot,
                     const TrajectoryExportOptions& o) {
  const TrajectorySpecs sp = traj.specs();
  std::string y;
  y += "# exid excitation trajectory: its own parameters. `variables` is z in the trajectory's\n"
       "# order: with init: coefficients (fourier) or init: knots (spline) and\n"
       "# init_coefficients / init_knots set to it, the same parameters give this trajectory.\n";
  y += "trajectory:\n  type: " + quoted(type) + "\n  params:\n";
  for (const auto& [k, v] : params.values()) y += "    " + k + ": " + paramYaml(v) + "\n";
  y += "variables: " + flowList(z.data(), z.size()) + "\n";
  y += fmt::format("duration_s: {}\nperiods: {}\nrate_Hz: {}\nrest_to_rest: {}\n",
                   number(sp.duration_s), o.periods, number(o.rate_Hz),
                   sp.rest_to_rest ? "true" : "false");
  const std::vector<std::string> jn = quotedJointNames(robot);
  y += "joint_names: [" + fmt::format("{}", fmt::join(jn, ", ")) + "]\n";
  const Json pj = traj.parametersAt(z);
  if (pj.isObject() && pj.size() > 0) {
    y += "parameters:\n";
    jsonYaml(pj, 2, y);
  }
  writeFileAtomic(file, y);
}

// joint_trajectory.yaml: trajectory_msgs/msg/JointTrajectory
void writeJointTrajectoryYaml(const fs::path& file, const Samples& s, const Eigen::MatrixXd& tau,
                              const RobotModel& robot, double rate_Hz) {
  const int n = s.dof();
  const Eigen::Index K = s.size();
  const std::vector<std::string> jn = quotedJointNames(robot);
  std::string r;
  r.reserve(static_cast<std::size_t>(K) * static_cast<std::size_t>(n) * 100 + 256);
  r += "# trajectory_msgs/msg/JointTrajectory (ROS 2), measured coordinates, SI units;\n"
       "# effort: the torque the robot's model predicts (rigid body + drives)\n";
  r += "header:\n  stamp: {sec: 0, nanosec: 0}\n  frame_id: \"\"\n";
  r += "joint_names: [" + fmt::format("{}", fmt::join(jn, ", ")) + "]\npoints:\n";
  const double ns_per_sample = 1e9 / rate_Hz;
  for (Eigen::Index k = 0; k < K; ++k) {
    const long long ns = std::llround(static_cast<double>(k) * ns_per_sample);
    const Eigen::RowVectorXd qr = s.q.row(k), vr = s.qd.row(k), ar = s.qdd.row(k), er = tau.row(k);
    r += "  - positions: " + flowList(qr.data(), n) + "\n";
    r += "    velocities: " + flowList(vr.data(), n) + "\n";
    r += "    accelerations: " + flowList(ar.data(), n) + "\n";
    r += "    effort: " + flowList(er.data(), n) + "\n";
    r += fmt::format("    time_from_start: {{sec: {}, nanosec: {}}}\n", ns / 1000000000LL,
                     ns % 1000000000LL);
  }
  writeFileAtomic(file, r);
}

// plots/trajectory_{q,qd,tau_ratio or tau,distance}
void drawExportPlots(const fs::path& stage, const Samples& s, const Eigen::MatrixXd& tau,
                     const RobotModel& robot, const TrajectoryExportOptions& o,
                     const Eigen::VectorXd& dmin) {
  const int n = s.dof();
  const Eigen::Index K = s.size();
  std::vector<std::string> jn;
  for (int j = 0; j < robot.dof(); ++j)
    jn.push_back(robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name);
  if (static_cast<int>(jn.size()) != n) jn.clear();
  auto series = [&](const Eigen::MatrixXd& m, const char* prefix) {
    std::vector<PlotSeries> v;
    for (int j = 0; j < n; ++j) {
      PlotSeries ps;
      ps.title = jointLabel(prefix, j, jn);
      ps.x.assign(s.t.data(), s.t.data() + K);
      ps.y.assign(m.col(j).data(), m.col(j).data() + K);
      v.push_back(std::move(ps));
    }
    return v;
  };
  auto spec = [&](const char* name, const char* title, const char* ylabel,
                  std::vector<PlotSeries> v) {
    PlotSpec p;
    p.name = name;
    p.title = title;
    p.xlabel = "t [s]";
    p.ylabel = ylabel;
    p.series = std::move(v);
    p.x_column = "t_s";
    return p;
  };
  drawPlot(
      spec("trajectory_q", "positions at the controller rate", "q [rad or m]", series(s.q, "q")),
      stage);
  drawPlot(spec("trajectory_qd", "velocities at the controller rate", "qd [rad/s or m/s]",
                series(s.qd, "qd")),
           stage);
  const Eigen::VectorXd tmax = knownTorqueLimits(robot, o.torque_max);
  if (tmax.size() == n) {
    drawPlot(torqueRatioPlot("trajectory_tau_ratio", "predicted torque / torque limit", s.t, tau,
                             tmax, o.torque_margin, jn),
             stage);
  } else {
    drawPlot(spec("trajectory_tau", "predicted torque (no torque limits known)", "tau [N m or N]",
                  series(tau, "tau")),
             stage);
  }
  if (o.collision && dmin.size() == K) {
    PlotSeries d;
    d.title = "minimum distance";
    d.x.assign(s.t.data(), s.t.data() + K);
    d.y.assign(dmin.data(), dmin.data() + K);
    PlotSpec p =
        spec("trajectory_distance", "minimum distance over the checked pairs", "distance [m]", {d});
    p.limits.push_back({o.collision->margin_m,
                        fmt::format("design margin {:g} m", o.collision->margin_m), "#e67e22"});
    p.limits.push_back({0.0, "contact", "#c0392b"});
    drawPlot(p, stage);
  }
}

// Publishes the staging folder as dir in one rename (renameat2 RENAME_EXCHANGE with an earlier
// export, which is then removed).
void publishStaging(const fs::path& stage, const fs::path& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) {
    fs::rename(stage, dir);
    return;
  }
  if (::renameat2(AT_FDCWD, stage.c_str(), AT_FDCWD, dir.c_str(), RENAME_EXCHANGE) == 0) {
    fs::remove_all(stage, ec);  // now the earlier export
    return;
  }
  // No RENAME_EXCHANGE on this file system: the earlier export moves aside first.
  const fs::path aside = dir.string() + fmt::format(".old.{}", static_cast<long>(::getpid()));
  fs::remove_all(aside, ec);
  fs::rename(dir, aside);
  fs::rename(stage, dir);
  fs::remove_all(aside, ec);
}

}  // namespace

// An export replaces its folder whole (an earlier export's plots/ stayed beside the new files);
// a folder holding anything else is refused, untouched.
fs::path exportFolder(const fs::path& dir) {
  std::error_code ec;
  fs::path d = fs::absolute(dir).lexically_normal();
  if (d.filename().empty()) d = d.parent_path();
  if (fs::is_symlink(d, ec)) {
    const fs::path t = fs::canonical(d, ec);
    if (ec)
      throw Error(fmt::format("--export {}: a symbolic link to nothing ({}); export to a folder",
                              dir.string(), fs::read_symlink(d, ec).string()));
    d = t;
  }
  if (!fs::exists(d, ec)) return d;
  if (!fs::is_directory(d, ec))
    throw Error(fmt::format("--export {}: not a folder; export to a new folder", dir.string()));
  if (fs::equivalent(d, fs::current_path(), ec))
    throw Error(fmt::format(
        "--export {}: the current folder; an export replaces its folder whole: export to a "
        "folder of its own",
        dir.string()));
  if (fs::exists(d / "trajectory_check.json", ec)) return d;  // an earlier export
  for (const auto& e : fs::directory_iterator(d)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(".export.staging.", 0) == 0) continue;  // a killed export's leftover
    throw Error(fmt::format(
        "--export {}: the folder holds '{}', and is not an earlier export (no "
        "trajectory_check.json); an export replaces its folder whole: export to a new or empty "
        "folder",
        dir.string(), name));
  }
  return d;
}

Json exportTrajectory(const Trajectory& traj, const std::string& type, const ParamSet& params,
                      const Eigen::VectorXd& z, const RobotModel& robot,
                      const TrajectoryExportOptions& o, const fs::path& dir,
                      TrajectoryCheck* check_out) {
  const Samples s = resampleTrajectory(traj, z, o.rate_Hz, o.periods);
  const Eigen::MatrixXd tau = predictedTorques(robot, s);
  const Eigen::Index K = s.size();
  const TrajectorySpecs sp = traj.specs();

  const fs::path target = exportFolder(dir);
  fs::create_directories(target.parent_path());
  // staged beside the target (the same file system), published in one rename
  const fs::path stage =
      target.parent_path() / fmt::format(".{}.export.staging.{}", target.filename().string(),
                                         static_cast<long>(::getpid()));
  fs::remove_all(stage);
  fs::create_directories(stage);
  try {
    writeTrajectoryCsv(stage / "trajectory.csv", s, tau);
    writeParamsYaml(stage / "trajectory.params.yaml", traj, type, params, z, robot, o);
    writeJointTrajectoryYaml(stage / "joint_trajectory.yaml", s, tau, robot, o.rate_Hz);
    // the check, on the file as written
    Eigen::VectorXd dmin;
    const TrajectoryCheck c =
        checkTrajectoryCsv(stage / "trajectory.csv", robot, o.torque_max, o.collision.get(), &dmin);
    Json out = Json::object();
    out["files"] = Json(std::vector<std::string>{"trajectory.csv", "trajectory.params.yaml",
                                                 "joint_trajectory.yaml", "trajectory_check.json"});
    out["rate_Hz"] = o.rate_Hz;
    out["periods"] = o.periods;
    out["duration_s"] = s.t(K - 1) - s.t(0);
    out["rest_to_rest"] = sp.rest_to_rest;
    if (o.torque_margin > 0) out["torque_margin"] = o.torque_margin;
    if (o.collision) out["distance_margin_m"] = o.collision->margin_m;
    out["check"] = c.toJson();
    out["starts_at_rest"] = c.start.at_rest;
    out["ends_at_rest"] = c.end.at_rest;
    if (const std::string rest = c.restText(); !rest.empty()) out["rest_note"] = rest;
    writeFileAtomic(stage / "trajectory_check.json", out.dump(2) + "\n");

    if (o.plots) drawExportPlots(stage, s, tau, robot, o, dmin);
    publishStaging(stage, target);
    if (check_out) *check_out = c;
    return out;
  } catch (...) {
    std::error_code ec;
    fs::remove_all(stage, ec);
    throw;
  }
}

}  // namespace exid
