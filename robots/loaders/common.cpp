// exid — robot loaders: shared helpers (physical checks, warnings, dispatch).
#include <algorithm>
#include <cctype>
#include <iostream>
#include <sstream>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

namespace exid {

void reportWarning(const LoadOptions& options, const std::string& message) {
  if (options.warnings) {
    options.warnings->push_back(message);
  } else {
    std::cerr << "exid: warning: " << message << "\n";
  }
}

void checkModelPhysical(const RobotModel& model, const LoadOptions& options) {
  if (model.floating_base) {
    const InertiaCheck c = checkPhysical(model.base.inertia);
    if (!c.ok || !(model.base.inertia(9) > 0.0)) {
      const std::string msg = model.source + ": floating base link '" + model.base.link +
                              "': physically impossible inertia: " +
                              (c.ok ? std::string("no mass (a floating base link needs one)")
                                    : c.rule);
      if (options.strict)
        throw Error(msg + " (strict mode; load without strict to accept it with a warning)");
      reportWarning(options, msg);
    }
  }
  for (int i = 0; i < model.dof(); ++i) {
    const Body& b = model.bodies[static_cast<size_t>(i)];
    std::vector<std::string> rules;
    const InertiaCheck c = checkPhysical(b.inertia);
    if (!c.ok) rules.push_back(c.rule);
    // A massless body cannot have rotational inertia (the first moments then also vanish).
    if (b.inertia(9) == 0.0 && b.inertia.head<6>().cwiseAbs().maxCoeff() > 0.0) {
      rules.push_back("zero mass with non-zero rotational inertia");
    }
    for (const auto& rule : rules) {
      const std::string msg = model.source + ": link '" + b.name + "' (body " +
                              std::to_string(i + 1) + "): physically impossible inertia: " + rule;
      if (options.strict) {
        throw Error(msg + " (strict mode; load without strict to accept it with a warning)");
      }
      reportWarning(options, msg);
    }
  }
}

RobotModel loadRobotFile(const std::filesystem::path& file, const LoadOptions& options) {
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  if (ext == ".urdf" || ext == ".xml") return loadUrdf(file, options);
  if (ext == ".yaml" || ext == ".yml") return loadDhYaml(file, options);
  throw Error(file.string() + ": unknown robot description type '" + ext +
              "' (expected .urdf, .xml, .yaml or .yml)");
}

}  // namespace exid
