// exid — helpers shared by the observation-model plugins (models/*) and the `simulate`
// experiment: joint selections, coordinate maps, dataset checks (the payload: exid/payload.hpp).
// Header-only; installed (exid::models_common), so that out-of-tree models use it too.
#pragma once

#include <fmt/format.h>

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "exid/data.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/payload.hpp"
#include "exid/robot_model.hpp"

namespace exid::models {

// The payload description lives in the core (exid/payload.hpp, shared with the `simulate`
// experiment); its names are used here as models:: names too.
using exid::Payload;
using exid::payloadNames;
using exid::payloadParams;
using exid::phiToPi;
using exid::piToPhi;
using exid::Vec10;

/// Names of the torque equations of the selected (0-based) measured coordinates.
inline std::vector<std::string> torqueEquationNames(const RobotModel& R,
                                                    const std::vector<int>& sel) {
  std::vector<std::string> out;
  for (int j : sel) {
    const std::string& jn = !R.hasTransmission() && j < R.dof()
                                ? R.bodies[static_cast<std::size_t>(R.actuatedJoint(j))].joint_name
                                : std::string();
    out.push_back(jn.empty() ? fmt::format("tau{} [N m or N]", j + 1)
                             : fmt::format("tau{} {} [N m or N]", j + 1, jn));
  }
  return out;
}

/// 1-based joint numbers from a parameter -> 0-based indices; empty selects all joints.
inline std::vector<int> selectJoints(const std::vector<std::int64_t>& joints, int dof,
                                     const std::string& where) {
  std::vector<int> out;
  if (joints.empty()) {
    for (int j = 0; j < dof; ++j) out.push_back(j);
    return out;
  }
  for (std::int64_t j : joints) {
    check(
        j >= 1 && j <= dof,
        fmt::format("{}: joints: {} is out of range (the robot has joints 1..{})", where, j, dof));
    for (int o : out)
      check(o != j - 1, fmt::format("{}: joints: joint {} is listed twice", where, j));
    out.push_back(static_cast<int>(j - 1));
  }
  return out;
}

/// A gradient with respect to joint coordinates mapped to measured coordinates (q = T qm + q0).
/// A closed chain needs the sample (exid::jointGradientToMeasured); the callers left here (the
/// load models) project torques through G, whose derivative their design gradients do not
/// carry: refused.
inline void jointGradToMeasured(const RobotModel& r, Eigen::VectorXd* g) {
  if (r.hasLoops())
    throw Error("robot '" + r.name +
                "' is a closed chain: this model (a load model) has no design gradient through "
                "the loop constraints, so gradient-based excitation design refuses it (the "
                "differential and integral models have theirs)");
  if (g && r.hasTransmission()) *g = (r.transmission.transpose() * *g).eval();
}

/// Checks that a dataset carries a signal with the expected number of columns and rows.
inline void requireSignal(const Dataset& d, const Eigen::MatrixXd& m, const char* name, int cols,
                          const std::string& who) {
  // (messages built only when a check fails: this runs once per chunk)
  if (m.cols() == 0)
    throw Error(
        fmt::format("{}: the dataset ({}) has no '{}' signal (columns {}1..{}{}); "
                    "record it, or use an estimator that differentiates q",
                    who, d.source.empty() ? "unnamed" : d.source, name, name, name, cols));
  if (!(m.cols() == cols && m.rows() == d.size()))
    throw Error(fmt::format("{}: the dataset ({}) signal '{}' is {} x {} (expected {} x {})", who,
                            d.source.empty() ? "unnamed" : d.source, name, m.rows(), m.cols(),
                            d.size(), cols));
}

/// A model's nonlinear parameters for its describe(): [{name, value, unit}, ...].
inline Json nonlinearParametersJson(const std::vector<NonlinearParameter>& params) {
  Json nl = Json::array();
  for (const auto& p : params) {
    Json e = Json::object();
    e["name"] = p.name;
    e["value"] = p.value;
    e["unit"] = p.unit;
    nl.push_back(e);
  }
  return nl;
}

/// The four signals of a torque model (q, qd, qdd, tau), each K x n.
inline void requireTorqueSignals(const Dataset& d, int n, const std::string& who) {
  requireSignal(d, d.q, "q", n, who);
  requireSignal(d, d.qd, "qd", n, who);
  requireSignal(d, d.qdd, "qdd", n, who);
  requireSignal(d, d.tau, "tau", n, who);
}

/// Rows of K samples with m equations each: y, equation labels and times sized (the model
/// fills W, y and the labels).
inline void sizeRows(Rows* r, int K, int m) {
  r->y.resize(static_cast<Eigen::Index>(K) * m);
  r->equation.resize(static_cast<std::size_t>(K) * m);
  r->numEquations = m;
  r->t.resize(static_cast<std::size_t>(K) * m);
}

/// Row k of a design gradient from the joint-coordinate gradients of sample k (mapped to
/// measured coordinates first).
inline void storeSampleGrad(const RobotModel& r, int k, Eigen::VectorXd* gq, Eigen::VectorXd* gqd,
                            Eigen::VectorXd* gqdd, Samples* grad) {
  jointGradToMeasured(r, gq);
  jointGradToMeasured(r, gqd);
  jointGradToMeasured(r, gqdd);
  grad->q.row(k) = gq->transpose();
  grad->qd.row(k) = gqd->transpose();
  grad->qdd.row(k) = gqdd->transpose();
}

inline void requireSamples(const Samples& s, int n, bool need_qdd, const std::string& who) {
  const int K = s.size();
  // (messages built only when a check fails: this runs once per chunk)
  if (!(s.q.rows() == K && s.q.cols() == n && s.qd.rows() == K && s.qd.cols() == n))
    throw Error(
        fmt::format("{}: samples must have q and qd of size {} x {} (found q {} x {}, qd {} x {})",
                    who, K, n, s.q.rows(), s.q.cols(), s.qd.rows(), s.qd.cols()));
  if (need_qdd && !(s.qdd.rows() == K && s.qdd.cols() == n))
    throw Error(fmt::format("{}: samples must have qdd of size {} x {} (found {} x {})", who, K, n,
                            s.qdd.rows(), s.qdd.cols()));
}

/// Zero-filled gradient with the shapes of s.
inline void zeroGrad(const Samples& s, Samples* g) {
  g->t = s.t;
  g->q = Eigen::MatrixXd::Zero(s.q.rows(), s.q.cols());
  g->qd = Eigen::MatrixXd::Zero(s.q.rows(), s.q.cols());
  g->qdd = Eigen::MatrixXd::Zero(s.q.rows(), s.q.cols());
}

inline Json intsJson(const std::vector<int>& v, int add = 0) {
  Json a = Json::array();
  for (int x : v) a.push_back(Json(x + add));
  return a;
}

}  // namespace exid::models
