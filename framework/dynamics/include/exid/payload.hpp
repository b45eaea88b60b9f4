#pragma once

#include "exid/export.hpp"
// A payload rigidly attached to a robot's sensor frame (a wrist force/torque sensor's tool): its
// 10 inertial parameters in the two orders exid uses, the study parameters that describe it, and
// their JSON. Used by the load models and the `simulate` experiment. Header-only.
#include <fmt/format.h>

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/robot_model.hpp"

namespace exid {

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

struct EXID_API Payload {
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

}  // namespace exid
