// exid — the study commands: one stage of a study (excite, simulate, identify) and inspect.
#include <fmt/format.h>

#include <iostream>
#include <memory>

#include "commands.hpp"
#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/recording.hpp"
#include "exid/runner.hpp"
#include "exid/study_check.hpp"

namespace exid::cli {

namespace fs = std::filesystem;

namespace {

/// The params YAML of a plugin with `KEY: PATH` added (a flow mapping, a block mapping or "").
std::string withFile(const std::string& yaml, const std::string& file,
                     const std::string& key = "file") {
  std::string esc;
  for (char ch : file) esc += ch == '\'' ? std::string("''") : std::string(1, ch);
  const std::string f = key + ": '" + esc + "'";
  const auto a = yaml.find_first_not_of(" \t\r\n"), b = yaml.find_last_not_of(" \t\r\n");
  const std::string t = a == std::string::npos ? std::string() : yaml.substr(a, b - a + 1);
  if (t.empty()) return "{" + f + "}";
  if (t.front() == '{' && t.back() == '}') {
    const std::string inner = t.substr(1, t.size() - 2);
    return inner.find_first_not_of(" \t\r\n") == std::string::npos ? "{" + f + "}"
                                                                   : "{" + f + ", " + inner + "}";
  }
  return f + "\n" + yaml + "\n";
}

/// The experiment that reads a recording named on the command line: a ROS 2 bag (a folder, an
/// .mcap or .db3 storage file: exid::isBagPath) by `rosbag2` (its parameter `path`), anything
/// else by `csv` (`file`).
struct DataReader {
  const char* type;
  const char* key;
};
DataReader dataReader(const fs::path& p) {
  if (isBagPath(p)) return {"rosbag2", "path"};
  return {"csv", "file"};
}

}  // namespace

int stageCommand(const Registry& reg, const std::string& stage, const std::string& study,
                 const std::string& data_file, std::string out, const ExportArgs& ex) {
  StudyConfig cfg = stageStudy(loadStudy(study, reg), stage, reg, data_file);
  // What exid validate checks, before the stage runs (as exid run)
  std::shared_ptr<const RobotModel> robot = checkStudy(cfg, reg, study);
  if (out.empty()) out = "out/" + cfg.name + "_" + stage;
  RunOptions opt;
  opt.out_dir = out;
  opt.robot = std::move(robot);
  opt.cancelled = cancelled();
  opt.hard_stop_s = 0.5;  // SIGINT/SIGTERM end any stage within about 1 s
  opt.hard_stop_exit_code = signalExitCode;
  opt.export_dir = ex.dir;
  opt.export_rate_Hz = ex.rate_Hz;
  opt.export_periods = ex.periods;
  ProgressPrinter printer;  // the optimiser's and the export check's progress
  opt.progress = printer.callback();
  StudyResult r = runStudy(cfg, reg, opt);
  if (r.ok && r.headline.verdict == "suspect") {
    std::cout << "VERDICT: SUSPECT: the stage ran to the end, but its results fail checks of their "
                 "own:\n";
    for (const auto& reason : r.headline.verdict_reasons) std::cout << "  - " << reason << "\n";
    std::cout << "\n";
  }
  std::cout << briefTable(r.headline);
  if (!r.ok) {
    std::cerr << fmt::format(
        "exid {}: {}: {}{}\n", stage, r.cancelled ? "cancelled" : "failed", r.message,
        r.written_to.empty() ? std::string()
                             : fmt::format(" (details in {}/summary.json)", r.written_to.string()));
    return r.cancelled ? signalExitCode() : 1;
  }
  std::cout << fmt::format("\nResults in {}/ (summary.json, report.md)\n", out);
  if (!ex.dir.empty()) {
    const Json* X = r.summary.find("excitation");
    const Json* E = X ? X->find("export") : nullptr;
    const Json* C = E ? E->find("check") : nullptr;
    const Json* ok = C ? C->find("ok") : nullptr;
    std::cout << fmt::format(
        "Trajectory for execution in {}/ (trajectory.csv, trajectory.params.yaml, "
        "joint_trajectory.yaml, trajectory_check.json)\n",
        ex.dir);
    if (const Json* rest = E ? E->find("rest_note") : nullptr; rest && rest->isString())
      std::cout << rest->asString();
    if (!ok || !ok->asBool()) {
      std::cerr << fmt::format(
          "exid excite: the exported trajectory exceeds a limit of the robot at {} Hz (see {}/"
          "trajectory_check.json)\n",
          ex.rate_Hz, ex.dir);
      return 1;
    }
  }
  return 0;
}

/// exid inspect ROBOT DATA.csv|BAG [--set key=value ...] [--params YAML] [--json FILE], or
/// exid inspect STUDY.yaml [--json FILE]: the checks of exid/inspect.hpp, printed and as JSON.
int inspectCommand(const Registry& reg, const std::vector<std::string>& args,
                   const std::vector<std::string>& sets, const std::string& params,
                   const std::string& model_name, const std::string& model_params,
                   const std::string& json_out) {
  const char* usage =
      "usage: exid inspect ROBOT DATA.csv|BAG_FOLDER [--set key=value ...] [--params '{yaml}'] "
      "[--json FILE], or exid inspect STUDY.yaml [--json FILE]";
  if (args.empty() || args.size() > 2) throw Error(usage);
  RunContext ctx;
  ctx.study_dir = fs::current_path();
  auto bindModel = [&](const std::string& type, const ParamSet& ps,
                       std::shared_ptr<const RobotModel> r, const RunContext& c) {
    auto m = reg.create<ObservationModel>(type, ps);
    m->bind(std::move(r), c);
    return m;
  };
  std::string text;
  Json out;
  if (args.size() == 2) {
    auto robot = loadRobot(reg, args[0]);
    const fs::path data(args[1]);
    if (!fs::exists(data)) throw Error(fmt::format("{}: no such data file", args[1]));
    const DataReader dr = dataReader(data);
    const PluginInfo& reader = reg.get(PluginKind::Experiment, dr.type);
    const std::string file = fs::absolute(data).string();
    ParamSet ps =
        resolveParams(reader, withFile(params, file, dr.key),
                      fmt::format("experiment {} (--params)", dr.type), fs::current_path());
    for (const auto& kv : sets) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0)
        throw Error(
            fmt::format("--set {}: expected key=value (a parameter of the {} experiment, "
                        "see exid plugins info {})",
                        kv, dr.type, dr.type));
      const std::string key = kv.substr(0, eq);
      const ParamSet one =
          resolveParams(reader, withFile(key + ": " + kv.substr(eq + 1), file, dr.key),
                        fmt::format("experiment {} (--set {})", dr.type, kv), fs::current_path());
      ps.set(key, one.at(key));
    }
    const PluginInfo& mi = reg.get(PluginKind::Model, model_name);
    auto model = bindModel(
        model_name, resolveParams(mi, model_params, "model " + model_name, fs::current_path()),
        robot, ctx);
    const Dataset d = reg.create<Experiment>(dr.type, ps)->run(robot, nullptr, ctx);
    out = Json::object();
    out["robot"] = robot->name;
    const Json result = inspectExperimentData(*robot, model.get(), d, ctx, "experiment");
    for (const auto& [k, v] : result.items()) out[k] = v;
    text = fmt::format("exid inspect: robot {} ({} joints), model {}\n", robot->name, robot->dof(),
                       model_name) +
           inspectionText(out);
  } else {
    if (!sets.empty() || !params.empty())
      throw Error(
          "exid inspect STUDY.yaml: --set and --params apply to a CSV file (exid inspect ROBOT "
          "DATA.csv); the study gives its experiment's parameters");
    const StudyConfig cfg = loadStudy(args[0], reg);
    if (!cfg.experiment && !cfg.validation)
      throw Error(
          fmt::format("{}: no experiment or validation section: no data to inspect", args[0]));
    ctx.study_dir = cfg.dir;
    ctx.seed = cfg.seed;
    auto robot = reg.create<Robot>(cfg.robot->type, cfg.robot->params)->build(ctx);
    std::shared_ptr<ObservationModel> model;
    if (!cfg.models.empty())
      model = bindModel(cfg.models[0].type, cfg.models[0].params, robot, ctx);
    out = Json::object();
    text = fmt::format("exid inspect: study {} ({}), robot {} ({} joints), model {}{}\n", cfg.name,
                       args[0], robot->name, robot->dof(),
                       model ? model->pluginName() : std::string("none"),
                       cfg.models.size() > 1 ? " (the first of the study's models)" : "");
    for (const auto& [what, spec] : {std::make_pair("experiment", &cfg.experiment),
                                     std::make_pair("validation", &cfg.validation)}) {
      if (!*spec) continue;
      RunContext c = ctx;
      if (std::string(what) == "validation") c.seed = ctx.seed + 1000003;  // as exid run
      const Dataset d =
          reg.create<Experiment>((*spec)->type, (*spec)->params)->run(robot, nullptr, c);
      out[what] = inspectExperimentData(*robot, model.get(), d, c, what);
      text += fmt::format("\n== {} ({}) ==\n", what, (*spec)->type) + inspectionText(out[what]);
    }
  }
  std::cout << text;
  if (!json_out.empty()) {
    writeFileAtomic(json_out, out.dump(2) + "\n");
    std::cout << fmt::format("JSON: {}\n", json_out);
  }
  return 0;
}

}  // namespace exid::cli
