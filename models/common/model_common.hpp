// exid — helpers shared by the observation-model plugins (models/*) and the `simulate`
// experiment: payload parameters, joint selections, coordinate maps, dataset checks.
// Header-only; installed (exid::models_common), so that out-of-tree models use it too.
#pragma once

#include <fmt/format.h>

#include <Eigen/Core>
#include <Eigen/LU>
#include <cstdint>
#include <string>
#include <vector>

#include "exid/data.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/robot_model.hpp"

namespace exid::models {

using Vec10 = Eigen::Matrix<double, 10, 1>;

/// Names of the 10 payload parameters, in the order of wrenchRegressor (docs/conventions.md §1).
inline std::vector<std::string> payloadNames() {
  return {"L_M", "L_MX", "L_MY", "L_MZ", "L_XX", "L_XY", "L_XZ", "L_YY", "L_YZ", "L_ZZ"};
}

/// pi order (XX XY XZ YY YZ ZZ MX MY MZ M) -> phi order (M MX MY MZ XX XY XZ YY YZ ZZ).
inline Vec10 piToPhi(const Vec10& pi) {
  Vec10 phi;
  phi << pi[9], pi[6], pi[7], pi[8], pi[0], pi[1], pi[2], pi[3], pi[4], pi[5];
  return phi;
}
inline Vec10 phiToPi(const Vec10& phi) {
  Vec10 pi;
  pi << phi[4], phi[5], phi[6], phi[7], phi[8], phi[9], phi[1], phi[2], phi[3], phi[0];
  return pi;
}

/// The parameters that describe a payload rigidly attached to the sensor frame.
inline std::vector<ParamDecl> payloadParams(const std::string& role) {
  return {
      param_double("payload_mass_kg", 0.0, "kg", "mass of the " + role, 0.0),
      param_doubles("payload_com_m", std::vector<double>{0.0, 0.0, 0.0}, "m",
                    "centre of mass of the " + role + " [x, y, z] in the sensor frame", 3, 3),
      param_doubles("payload_inertia_kg_m2", std::vector<double>{0, 0, 0, 0, 0, 0}, "kg m^2",
                    "inertia of the " + role +
                        " about its centre of mass, sensor axes: [xx, xy, xz, yy, yz, zz]",
                    6, 6),
  };
}

struct Payload {
  double mass = 0.0;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  Eigen::Matrix3d I_com = Eigen::Matrix3d::Zero();

  static Payload fromParams(const ParamSet& p) {
    Payload L;
    L.mass = p.getDouble("payload_mass_kg");
    const auto c = p.getDoubles("payload_com_m");
    const auto I = p.getDoubles("payload_inertia_kg_m2");
    check(c.size() == 3,
          fmt::format("{}: payload_com_m: expected 3 numbers, found {}", p.context, c.size()));
    check(I.size() == 6,
          fmt::format(
              "{}: payload_inertia_kg_m2: expected 6 numbers [xx, xy, xz, yy, yz, zz], found {}",
              p.context, I.size()));
    L.com = Eigen::Vector3d(c[0], c[1], c[2]);
    L.I_com << I[0], I[1], I[2], I[1], I[3], I[4], I[2], I[4], I[5];
    return L;
  }
  /// From the JSON json() writes (a simulated dataset's meta.payload).
  static Payload fromJson(const Json& j) {
    const Json* m = j.find("mass_kg");
    const Json* c = j.find("com_m");
    const Json* I = j.find("inertia_com_kg_m2");
    check(m && c && I && c->size() == 3 && I->size() == 6,
          "payload: expected {mass_kg, com_m[3], inertia_com_kg_m2[6]}");
    Payload L;
    L.mass = m->asDouble();
    L.com = Eigen::Vector3d(c->at(0).asDouble(), c->at(1).asDouble(), c->at(2).asDouble());
    auto e = [&](std::size_t i) { return I->at(i).asDouble(); };
    L.I_com << e(0), e(1), e(2), e(1), e(3), e(4), e(2), e(4), e(5);
    return L;
  }
  bool empty() const { return mass == 0.0 && I_com.isZero(0.0); }
  /// Standard parameters about the sensor origin, sensor axes, pi order.
  Vec10 pi() const { return inertialFromCom(mass, com, I_com); }
  /// The same in phi order (the wrench regressor's).
  Vec10 phi() const { return piToPhi(pi()); }
  Json json() const {
    Json j = Json::object();
    j["mass_kg"] = mass;
    j["com_m"] = Json(std::vector<double>{com[0], com[1], com[2]});
    j["inertia_com_kg_m2"] = Json(std::vector<double>{I_com(0, 0), I_com(0, 1), I_com(0, 2),
                                                      I_com(1, 1), I_com(1, 2), I_com(2, 2)});
    return j;
  }
};

/// Names of the torque equations of the selected (0-based) measured coordinates.
inline std::vector<std::string> torqueEquationNames(const RobotModel& R,
                                                    const std::vector<int>& sel) {
  std::vector<std::string> out;
  for (int j : sel) {
    const std::string& jn = !R.hasTransmission() && j < static_cast<int>(R.bodies.size())
                                ? R.bodies[static_cast<std::size_t>(j)].joint_name
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
inline void jointGradToMeasured(const RobotModel& r, Eigen::VectorXd* g) {
  if (g && r.hasTransmission()) *g = (r.transmission.transpose() * *g).eval();
}

/// Checks that a dataset carries a signal with the expected number of columns and rows.
inline void requireSignal(const Dataset& d, const Eigen::MatrixXd& m, const char* name, int cols,
                          const std::string& who) {
  check(m.cols() > 0,
        fmt::format("{}: the dataset ({}) has no '{}' signal (columns {}1..{}{}); "
                    "record it, or use an estimator that differentiates q",
                    who, d.source.empty() ? "unnamed" : d.source, name, name, name, cols));
  check(m.cols() == cols && m.rows() == d.size(),
        fmt::format("{}: the dataset ({}) signal '{}' is {} x {} (expected {} x {})", who,
                    d.source.empty() ? "unnamed" : d.source, name, m.rows(), m.cols(), d.size(),
                    cols));
}

inline void requireSamples(const Samples& s, int n, bool need_qdd, const std::string& who) {
  const int K = s.size();
  check(s.q.rows() == K && s.q.cols() == n && s.qd.rows() == K && s.qd.cols() == n,
        fmt::format("{}: samples must have q and qd of size {} x {} (found q {} x {}, qd {} x {})",
                    who, K, n, s.q.rows(), s.q.cols(), s.qd.rows(), s.qd.cols()));
  if (need_qdd)
    check(s.qdd.rows() == K && s.qdd.cols() == n,
          fmt::format("{}: samples must have qdd of size {} x {} (found {} x {})", who, K, n,
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
