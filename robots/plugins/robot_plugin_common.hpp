// exid — helpers shared by the robot plugins in this folder (not installed).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/params.hpp"
#include "exid/robot_loaders.hpp"

namespace exid::robots {

/// Parameters every robot plugin has.
inline std::vector<ParamDecl> commonParams() {
  return {
      param_bool("strict", false,
                 "physically impossible inertial data is an error instead of a warning"),
      param_doubles("gravity", std::vector<double>{}, "m/s^2",
                    "gravity [gx, gy, gz] in the base frame, overriding the description's; "
                    "empty: from the description",
                    0, 3),
  };
}

struct CommonOptions {
  bool strict = false;
  std::vector<double> gravity;

  explicit CommonOptions(const ParamSet& p) : strict(p.getBool("strict")) {
    gravity = p.getDoubles("gravity");
    if (!gravity.empty() && gravity.size() != 3) {
      throw Error(p.context + ": gravity: expected 3 numbers [gx, gy, gz] or none, found " +
                  std::to_string(gravity.size()));
    }
  }

  /// Loads with these options, logs the warnings, applies the gravity override.
  template <class Load>
  std::shared_ptr<const RobotModel> build(Load&& load) const {
    std::vector<std::string> warnings;
    LoadOptions opt;
    opt.strict = strict;
    opt.warnings = &warnings;
    RobotModel m = load(opt);
    for (const auto& w : warnings) logWarn(w);
    if (!gravity.empty()) m.gravity = Eigen::Vector3d(gravity[0], gravity[1], gravity[2]);
    return std::make_shared<const RobotModel>(std::move(m));
  }
};

}  // namespace exid::robots
