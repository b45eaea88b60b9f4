// exid — robot loaders: shared helpers (physical checks, warnings, dispatch).
#include <algorithm>
#include <cctype>
#include <iostream>
#include <sstream>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "read_text.hpp"
#include "xml_text.hpp"

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
      const std::string msg =
          model.source + ": floating base link '" + model.base.link +
          "': physically impossible inertia: " +
          (c.ok ? std::string("no mass (a floating base link needs one)") : c.rule);
      if (options.strict)
        throw Error(msg + " (strict mode; load without strict to accept it with a warning)");
      reportWarning(options, msg);
    }
  }
  for (int i = 0; i < model.numJoints(); ++i) {
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
  if (ext == ".urdf") return loadUrdf(file, options);
  if (ext == ".sdf") return loadSdf(file, options);
  if (ext == ".mjcf") return loadMjcf(file, options);
  if (ext == ".xml") {
    const std::string text = detail::readTextFile(file, "robot description (XML)");
    const std::string root = detail::xmlRootName(text);
    if (root == "mujoco") return loadMjcfString(text, file.string(), options);
    if (root == "sdf") return loadSdfString(text, file.string(), options);
    return loadUrdfString(text, file.string(), options);
  }
  if (ext == ".yaml" || ext == ".yml") return loadDhYaml(file, options);
  throw Error(file.string() + ": unknown robot description type '" + ext +
              "' (expected .urdf, .sdf, .mjcf, .xml, .yaml or .yml)");
}

namespace detail {

void makeClosedChain(RobotModel* m, std::vector<LoopJoint> loops, std::vector<int> actuated,
                     Eigen::VectorXd reference, const std::string& src) {
  const int n = m->numJoints();
  check(!actuated.empty(), src +
                               ": loop-closure joints but no actuated joint (the joints that "
                               "drive the mechanism must be declared)");
  for (int i = 0; i < n; ++i) {
    const Drive& d = m->drives[static_cast<std::size_t>(i)];
    const bool driven =
        d.rotor_inertia != 0.0 || d.coulomb != 0.0 || d.viscous != 0.0 || d.offset != 0.0;
    if (driven && std::find(actuated.begin(), actuated.end(), i) == actuated.end())
      throw Error(src + ": joint '" + m->bodies[static_cast<std::size_t>(i)].joint_name +
                  "' is passive (not actuated) but has drive terms");
  }
  m->closed.loops = std::move(loops);
  m->closed.reference = std::move(reference);
  m->closed.tree_limits = m->limits;
  std::vector<JointLimits> lim;
  std::vector<Drive> drv;
  for (int a : actuated) {
    lim.push_back(m->limits[static_cast<std::size_t>(a)]);
    drv.push_back(m->drives[static_cast<std::size_t>(a)]);
  }
  m->closed.actuated = std::move(actuated);
  m->limits = std::move(lim);
  m->drives = std::move(drv);
}

}  // namespace detail
}  // namespace exid
