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

  /// Loads with these options, applies the gravity override. The loader's warnings are logged
  /// and kept in the model's `warnings`; with `known_defects` (a shipped description of
  /// published data whose defects are documented and kept on purpose) they are stated once as
  /// a note instead: `known_defects` followed by what the checks found.
  template <class Load>
  std::shared_ptr<const RobotModel> build(Load&& load,
                                          const std::string& known_defects = {}) const {
    std::vector<std::string> warnings;
    LoadOptions opt;
    opt.strict = strict;
    opt.warnings = &warnings;
    RobotModel m = load(opt);
    if (!known_defects.empty() && !warnings.empty()) {
      std::string found;
      for (const auto& w : warnings) found += (found.empty() ? "" : "; ") + w;
      m.notes.push_back(known_defects + " Found: " + found + ".");
      for (const auto& w : warnings) logDebug(w);
    } else {
      for (const auto& w : warnings) logWarn(w);
      m.warnings.insert(m.warnings.end(), warnings.begin(), warnings.end());
    }
    if (!gravity.empty()) m.gravity = Eigen::Vector3d(gravity[0], gravity[1], gravity[2]);
    return std::make_shared<const RobotModel>(std::move(m));
  }
};

}  // namespace exid::robots
