// exid — the checks of a study that need its plugins (exid/study_check.hpp).
#include "exid/study_check.hpp"

#include <fmt/format.h>

#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"
#include "exid/robot_model.hpp"

namespace exid {

std::shared_ptr<const RobotModel> checkStudy(const StudyConfig& cfg, const Registry& reg,
                                             const std::string& source) {
  const std::string file = !source.empty()     ? source
                           : !cfg.file.empty() ? cfg.file.string()
                                               : std::string("study");
  auto where = [&](const PluginSpec& spec) {
    return spec.line > 0 ? fmt::format("{}:{}: {}", file, spec.line, spec.key_path)
                         : fmt::format("{}: {}", file, spec.key_path);
  };
  // Made, not run: the constructors check their parameters together.
  auto make = [&](const PluginSpec& spec) {
    try {
      reg.createObject(reg.get(spec.kind, spec.type), spec.params);
    } catch (const Error& e) {
      throw Error(fmt::format("{}: {}", where(spec), e.what()));
    }
  };
  std::shared_ptr<const RobotModel> robot;
  if (cfg.robot) {
    RunContext ctx;  // as the run's robot stage: relative paths to the study's folder
    ctx.study_dir = cfg.dir;
    ctx.seed = cfg.seed;
    try {
      robot = reg.create<Robot>(cfg.robot->type, cfg.robot->params)->build(ctx);
    } catch (const Error& e) {
      throw Error(fmt::format("{}: {}", where(*cfg.robot), e.what()));
    }
    if (!robot || robot->dof() <= 0)
      throw Error(fmt::format("{}: robot '{}' has no joints", where(*cfg.robot), cfg.robot->type));
  }
  for (const PluginSpec& m : cfg.models) make(m);
  for (const auto* s : {&cfg.trajectory, &cfg.criterion, &cfg.optimizer, &cfg.experiment,
                        &cfg.estimator, &cfg.validation})
    if (*s) make(**s);
  if (cfg.prior && cfg.prior->from == "study") {
    try {
      checkPriorFile(*cfg.prior);
    } catch (const Error& e) {
      throw Error(cfg.prior->line > 0
                      ? fmt::format("{}:{}: prior: {}", file, cfg.prior->line, e.what())
                      : fmt::format("{}: prior: {}", file, e.what()));
    }
  }
  return robot;
}

}  // namespace exid
