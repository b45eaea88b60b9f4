// exid — stage commands: robot info, eval, excite, simulate, identify, export.
#include "commands.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <sstream>

#include "exid/config.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"
#include "exid/runner.hpp"
#include "exid/study_check.hpp"
#include "exid/trajectory_export.hpp"
#include "exid/urdf_writer.hpp"

namespace exid::cli {

namespace fs = std::filesystem;

namespace {

/// ROBOT is a robot plugin name or a path to a .urdf or DH .yaml file (a .xacro file goes to
/// the URDF loader, which says how to expand it; every command taking a robot comes here).
std::shared_ptr<const RobotModel> loadRobot(const Registry& reg, const std::string& robot) {
  std::string type = robot, params = "{}";
  const fs::path p(robot);
  const std::string ext = p.extension().string();
  if (ext == ".urdf" || ext == ".xacro" || ext == ".yaml" || ext == ".yml") {
    if (!fs::exists(p)) throw Error(fmt::format("{}: no such robot file", robot));
    checkInputFile(p, "robot", kMaxRobotFileBytes);  // a FIFO or a device: refused, not opened
    type = ext == ".yaml" || ext == ".yml" ? "dh" : "urdf";
    std::string esc;  // (a quote in the path doubled: a YAML single-quoted scalar)
    for (char ch : fs::absolute(p).string())
      esc += ch == '\'' ? std::string("''") : std::string(1, ch);
    params = fmt::format("{{file: '{}'}}", esc);
    try {
      const PluginInfo& info = reg.get(PluginKind::Robot, type);
      ParamSet ps = resolveParams(info, params, "robot " + type, fs::current_path());
      RunContext ctx;
      return reg.create<Robot>(type, ps)->build(ctx);
    } catch (const Error& e) {  // the loader names the absolute path: say it as given
      std::string m = e.what();
      const std::string abs = fs::absolute(p).string();
      for (auto at = m.find(abs); at != std::string::npos; at = m.find(abs, at + robot.size()))
        m.replace(at, abs.size(), robot);
      throw Error(m);
    }
  }
  if (!reg.find(PluginKind::Robot, type) && fs::exists(p))
    throw Error(
        fmt::format("{}: a file, but not a robot description exid reads (expected a .urdf "
                    "file, a DH .yaml table, or a .xacro file expanded by xacro first), "
                    "nor a robot plugin's name",
                    robot));
  const PluginInfo& info = reg.get(PluginKind::Robot, type);
  ParamSet ps = resolveParams(info, params, "robot " + type, fs::current_path());
  RunContext ctx;
  return reg.create<Robot>(type, ps)->build(ctx);
}

int robotInfo(const Registry& reg, const std::string& robot, const std::string& model_name,
              const std::string& model_params, bool json) {
  auto r = loadRobot(reg, robot);
  const PluginInfo& info = reg.get(PluginKind::Model, model_name);
  auto model = reg.create<ObservationModel>(
      model_name, resolveParams(info, model_params, "model " + model_name, fs::current_path()));
  RunContext ctx;
  model->bind(r, ctx);
  const BaseParameters& b = model->base();
  Eigen::VectorXd nominal = model->fullNominal();
  Eigen::VectorXd base = model->baseNominal();
  if (json) {
    Json j = Json::object();
    j["name"] = r->name;
    j["source"] = r->source;
    j["dof"] = r->dof();
    j["model"] = model_name;
    j["parameters"] = Json(b.full_names);
    j["values"] = Json(std::vector<double>(nominal.data(), nominal.data() + nominal.size()));
    Json bp = Json::array();
    for (int i = 0; i < b.rank(); ++i) {
      Json e = Json::object();
      e["name"] = b.names[static_cast<std::size_t>(i)];
      e["expression"] = b.expressions[static_cast<std::size_t>(i)];
      e["value"] = base(i);
      bp.push_back(e);
    }
    j["base_parameters"] = bp;
    j["tolerance"] = b.tolerance;
    j["notes"] = Json(r->notes);
    j["warnings"] = Json(r->warnings);
    std::cout << j.dump(2) << '\n';
    return 0;
  }
  std::cout << fmt::format("robot {} ({} joints) from {}\n", r->name, r->dof(), r->source);
  for (const auto& note : r->notes) std::cout << "  note: " << note << "\n";
  for (int i = 0; i < r->dof(); ++i) {
    const Body& body = r->bodies[static_cast<std::size_t>(i)];
    const JointLimits& L = r->limits[static_cast<std::size_t>(i)];
    std::cout << fmt::format(
        "  {} {:<12} {:<9} parent {:>2}  q in [{:.4g}, {:.4g}]  |qd| <= {:.4g}\n", i + 1,
        body.joint_name, body.type == JointType::Revolute ? "revolute" : "prismatic",
        body.parent + 1, L.q_min, L.q_max, L.qd_max);
  }
  std::cout << fmt::format(
      "\nmodel {}: {} standard parameters, {} base parameters (tolerance {:g})\n\n", model_name,
      b.numFull(), b.rank(), b.tolerance);
  std::cout << "standard parameters:\n";
  for (int i = 0; i < b.numFull(); ++i)
    std::cout << fmt::format("  {:<6} {:>14.6g}{}", b.full_names[static_cast<std::size_t>(i)],
                             nominal(i), (i + 1) % 4 == 0 ? "\n" : "");
  std::cout << "\n\nbase parameters:\n";
  for (int i = 0; i < b.rank(); ++i)
    std::cout << fmt::format("  {:<8} = {:<60} = {:.6g}\n", b.names[static_cast<std::size_t>(i)],
                             b.expressions[static_cast<std::size_t>(i)], base(i));
  return 0;
}

int evalCommand(const Registry& reg, const std::string& robot, const std::string& samples,
                const std::string& what, const std::string& out, bool rigid_body_only) {
  auto r = loadRobot(reg, robot);
  const int n = r->dof();
  CsvTable in = readCsv(samples);
  // A joint column beyond the robot's joints means the file is not for this robot.
  for (const char* pre : {"q", "qd", "qdd"})
    if (in.has(fmt::format("{}{}", pre, n + 1)))
      throw Error(fmt::format(
          "{}: column '{}{}' but robot '{}' has {} joints (expected q1..q{}, qd1..qd{}, "
          "qdd1..qdd{}); is this file for another robot?",
          samples, pre, n + 1, r->name, n, n, n, n));
  if (rigid_body_only && what != "torque")
    throw Error(fmt::format("--rigid-body-only applies to --what torque only (given: {})", what));
  auto column = [&](const std::string& name, bool required) -> Eigen::VectorXd {
    int c = in.col(name);
    if (c < 0) {
      if (required)
        throw Error(
            fmt::format("{}: missing column '{}' (expected q1..q{}, qd1..qd{}, qdd1..qdd{})",
                        samples, name, n, n, n));
      return Eigen::VectorXd::Zero(in.data.rows());
    }
    return in.data.col(c);
  };
  const Eigen::Index K = in.data.rows();
  Eigen::MatrixXd Q(K, n), QD(K, n), QDD(K, n);
  const bool needs_qdd = what != "energy" && what != "energy_regressor";
  for (int j = 0; j < n; ++j) {
    Q.col(j) = column(fmt::format("q{}", j + 1), true);
    QD.col(j) = column(fmt::format("qd{}", j + 1), true);
    QDD.col(j) = column(fmt::format("qdd{}", j + 1), needs_qdd);
  }
  auto data = makeDynamicsData(*r);
  DriveColumns drives;  // the robot's full torque: every drive term it describes
  drives.rotor_inertia = drives.coulomb = drives.viscous = drives.offset = !rigid_body_only;
  CsvTable t;
  std::vector<std::string> names = r->inertialParameterNames();
  if (what == "torque") {
    for (int j = 0; j < n; ++j) t.columns.push_back(fmt::format("tau{}", j + 1));
    t.data.resize(K, n);
  } else if (what == "regressor") {
    t.columns = names;
    t.data.resize(K * n, static_cast<Eigen::Index>(names.size()));
  } else if (what == "energy") {
    t.columns = {"kinetic", "potential", "total"};
    t.data.resize(K, 3);
  } else if (what == "energy_regressor") {
    for (const auto& nm : names) t.columns.push_back("T_" + nm);
    for (const auto& nm : names) t.columns.push_back("U_" + nm);
    t.data.resize(K, 2 * static_cast<Eigen::Index>(names.size()));
  } else if (what == "wrench_regressor") {
    t.columns = {"M", "MX", "MY", "MZ", "XX", "XY", "XZ", "YY", "YZ", "ZZ"};
    t.data.resize(K * 6, 10);
  } else {
    throw Error(
        fmt::format("--what {}: expected one of torque, regressor, energy, energy_regressor, "
                    "wrench_regressor",
                    what));
  }
  const Eigen::VectorXd pi = r->inertialParameters();
  const Eigen::Index p = static_cast<Eigen::Index>(names.size());
  Eigen::MatrixXd Y(n, p);
  Eigen::RowVectorXd kin(p), pot(p);
  Eigen::Matrix<double, 6, 10> A;
  for (Eigen::Index k = 0; k < K; ++k) {
    Eigen::VectorXd qm = Q.row(k).transpose(), qdm = QD.row(k).transpose(),
                    qddm = QDD.row(k).transpose();
    Eigen::VectorXd q, qd, qdd;
    measuredToJoint(*r, qm, qdm, qddm, &q, &qd, &qdd);
    if (what == "torque") {
      Eigen::VectorXd tau;
      if (rigid_body_only) {
        tau = inverseDynamics(*r, *data, q, qd, qdd);
        if (r->hasTransmission()) tau = r->transmission.transpose() * tau;
      } else {
        tau = actuatorTorque(*r, *data, drives, qm, qdm, qddm);
      }
      t.data.row(k) = tau.transpose();
    } else if (what == "regressor") {
      torqueRegressor(*r, *data, q, qd, qdd, Y);
      if (r->hasTransmission()) Y = r->transmission.transpose() * Y;
      t.data.middleRows(k * n, n) = Y;
    } else if (what == "energy" || what == "energy_regressor") {
      energyRegressor(*r, *data, q, qd, kin, pot);
      if (what == "energy") {
        t.data(k, 0) = kin.dot(pi);
        t.data(k, 1) = pot.dot(pi);
        t.data(k, 2) = t.data(k, 0) + t.data(k, 1);
      } else {
        t.data.block(k, 0, 1, p) = kin;
        t.data.block(k, p, 1, p) = pot;
      }
    } else {
      wrenchRegressor(*r, *data, q, qd, qdd, A);
      t.data.middleRows(k * 6, 6) = A;
    }
  }
  std::string what_text = what;
  if (what == "torque") {
    const bool has_drives = std::any_of(r->drives.begin(), r->drives.end(), [](const Drive& d) {
      return d.rotor_inertia != 0 || d.coulomb != 0 || d.viscous != 0 || d.offset != 0;
    });
    what_text = rigid_body_only ? "torque of the rigid bodies alone (--rigid-body-only: no rotor "
                                  "inertia, friction or offset)"
                                : fmt::format(
                                      "full torque: rigid bodies + drives (rotor inertia, "
                                      "Coulomb, viscous, offset: the robot's nominal "
                                      "values{})",
                                      has_drives ? "" : "; this robot describes none");
    what_text += r->hasTransmission() ? ", measured (motor) coordinates, N m" : ", N m";
  }
  writeFileAtomic(out,
                  fmt::format("# exid eval {} {}: {}\n{}", what, r->name, what_text, toCsv(t)));
  std::cout << fmt::format("{}: {} rows x {} columns ({} of {} on {} samples)\n", out,
                           t.data.rows(), t.data.cols(), what_text, r->name, K);
  return 0;
}

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

/// The experiment that reads a recording named on the command line: a ROS 2 bag folder (a folder
/// holding metadata.yaml) by `rosbag2` (its parameter `path`), anything else by `csv` (`file`).
struct DataReader {
  const char* type;
  const char* key;
};
DataReader dataReader(const fs::path& p) {
  if (fs::is_directory(p) && fs::exists(p / "metadata.yaml")) return {"rosbag2", "path"};
  return {"csv", "file"};
}

/// Single stages run through the study runner on a trimmed copy of the study.
struct ExportArgs {
  std::string dir;
  double rate_Hz = 1000.0;
  int periods = 1;
};

int stageCommand(const Registry& reg, const std::string& stage, const std::string& study,
                 const std::string& data_file, std::string out, const ExportArgs& ex = {}) {
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

/// exid check-trajectory: a trajectory CSV (t, q, qd, qdd[, tau]) against the robot's limits at
/// the file's own rate; exit 1 when a limit is exceeded.
/// With a study (--collision), the smallest distance of the pairs its excitation.collision
/// checks as well.
int checkTrajectoryCommand(const Registry& reg, const std::string& robot, const std::string& file,
                           const std::vector<double>& torque_max, const std::string& json_out,
                           const std::string& collision_study) {
  const auto model = loadRobot(reg, robot);
  // A limit that is not a finite positive torque would switch its check off (NaN compares
  // false): refused, naming the flag.
  if (!torque_max.empty() && static_cast<int>(torque_max.size()) != model->dof())
    throw Error(
        fmt::format("--torque-max-nm: {} values; robot '{}' has {} joints (one limit "
                    "per joint, N m or N)",
                    torque_max.size(), model->name, model->dof()));
  for (std::size_t j = 0; j < torque_max.size(); ++j)
    if (!std::isfinite(torque_max[j]) || !(torque_max[j] > 0))
      throw Error(
          fmt::format("--torque-max-nm: value {} (joint {}) is {}; each limit must be a "
                      "finite torque > 0 [N m or N]",
                      j + 1, j + 1, torque_max[j]));
  std::shared_ptr<const CollisionOptions> collision;
  if (!collision_study.empty()) {
    collision = loadStudy(collision_study, reg).excitation_collision;
    if (!collision)
      throw Error(
          fmt::format("--collision {}: the study has no excitation.collision section (the "
                      "margin, obstacles and allowed pairs to check the distances with)",
                      collision_study));
  }
  const TrajectoryCheck c = checkTrajectoryCsv(file, *model, torque_max, collision.get());
  std::cout << c.text();
  if (!json_out.empty()) writeFileAtomic(json_out, c.toJson().dump(2) + "\n");
  if (!c.ok) {
    std::cerr << fmt::format("exid check-trajectory: {} exceeds a limit of robot '{}'\n", file,
                             model->name);
    return 1;
  }
  std::cout << "every limit holds\n";
  return 0;
}

/// exid export: the identified consistent standard parameters (consistent_ls writes them into
/// summary.json identification.details.standard_parameters) written into a URDF with the
/// robot's kinematics, limits and drives (docs/consistent.md).
int exportCommand(const Registry& reg, const std::string& robot, const std::string& study_dir,
                  const std::string& out) {
  const fs::path dir(study_dir);
  if (!fs::exists(dir / "summary.json"))
    throw Error(fmt::format("{}: no summary.json (the output folder of `exid run`)", dir.string()));
  const std::string text = readInputFile(dir / "summary.json", "summary", kMaxStudyFileBytes);
  Json S;
  try {
    S = Json::parse(text);
  } catch (const Error& e) {  // (the file named: JSON's own message says only where)
    throw Error(fmt::format("{}/summary.json: {}", dir.string(), e.what()));
  }
  const Json* I = S.find("identification");
  const Json* d = I ? I->find("details") : nullptr;
  const Json* sp = d ? d->find("standard_parameters") : nullptr;
  if (!sp || !sp->find("names") || !sp->find("values"))
    throw Error(fmt::format(
        "{}/summary.json: no identification.details.standard_parameters; only an estimator "
        "that identifies physically consistent STANDARD parameters (consistent_ls) can be "
        "exported (base parameters alone do not define a robot)",
        dir.string()));
  std::shared_ptr<const RobotModel> base;
  if (!robot.empty()) {
    base = loadRobot(reg, robot);
  } else {
    // Only the robot section of the resolved study (its paths are absolute).
    std::error_code ec;
    if (!fs::exists(fs::symlink_status(dir / "study.resolved.yaml", ec)))
      throw Error(fmt::format("{}: no study.resolved.yaml; name the robot (exid export ROBOT ...)",
                              dir.string()));
    std::istringstream ry(
        readInputFile(dir / "study.resolved.yaml", "resolved study", kMaxStudyFileBytes));
    std::string line, section;
    bool in_robot = false;
    while (std::getline(ry, line)) {
      if (!line.empty() && line[0] != ' ' && line[0] != '#')
        in_robot = line.rfind("robot:", 0) == 0;
      if (in_robot) section += line + "\n";
    }
    StudyConfig cfg = parseStudy(section, (dir / "study.resolved.yaml").string(), dir, reg);
    RunContext ctx;
    ctx.study_dir = cfg.dir;
    base = reg.create<Robot>(cfg.robot->type, cfg.robot->params)->build(ctx);
  }
  RobotModel m = *base;
  const Json& names = *sp->find("names");
  const Json& values = *sp->find("values");
  check(names.size() == values.size(), "standard_parameters: names and values differ in length");
  const std::vector<std::string> inertial = m.inertialParameterNames();
  int set = 0;
  std::vector<std::string> ignored;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (!names.at(i).isString() || !values.at(i).isNumber() ||
        !std::isfinite(values.at(i).asDouble()))
      throw Error(
          fmt::format("{}/summary.json: identification.details.standard_parameters, "
                      "element {}: expected a name and a finite number",
                      dir.string(), i + 1));
    const std::string n = names.at(i).asString();
    const double v = values.at(i).asDouble();
    auto it = std::find(inertial.begin(), inertial.end(), n);
    if (it != inertial.end()) {
      const auto k = static_cast<std::size_t>(it - inertial.begin());
      m.bodies[k / 10].inertia(static_cast<Eigen::Index>(k % 10)) = v;
      ++set;
      continue;
    }
    bool done = false;
    for (const char* pre : {"Ia", "Fc", "Fv", "OFF"}) {
      const std::string p(pre);
      if (n.size() <= p.size() || n.compare(0, p.size(), p) != 0) continue;
      const std::string rest = n.substr(p.size());
      // (digits beyond a joint count: not an int, not a joint; std::stoi would throw)
      if (rest.size() > 6 || rest.find_first_not_of("0123456789") != std::string::npos) continue;
      const int j = std::stoi(rest) - 1;
      if (j < 0 || j >= static_cast<int>(m.drives.size())) continue;
      Drive& dr = m.drives[static_cast<std::size_t>(j)];
      (p == "Ia"   ? dr.rotor_inertia
       : p == "Fc" ? dr.coulomb
       : p == "Fv" ? dr.viscous
                   : dr.offset) = v;
      done = true;
      ++set;
    }
    if (!done) ignored.push_back(n);
  }
  for (int j = 0; j < m.dof(); ++j) {
    const InertiaCheck c = checkPhysical(m.bodies[static_cast<std::size_t>(j)].inertia);
    if (!c.ok)
      throw Error(
          fmt::format("body {} ('{}'): {}; the identified parameters are not physically consistent "
                      "and cannot be written as URDF",
                      j + 1, m.bodies[static_cast<std::size_t>(j)].name, c.rule));
  }
  UrdfWriteOptions wo;
  wo.comment = fmt::format(
      "  {}: identified by exid {} ({}), study {} ({}).\n  Inertial parameters and drives "
      "from identification.details.standard_parameters; kinematics, limits and transmission "
      "from {}.",
      m.name, EXID_VERSION_STRING, I->find("estimator") ? I->find("estimator")->asString() : "?",
      S.find("study") ? S.find("study")->asString() : "?", dir.string(), base->source);
  m.name = m.name + "_identified";
  writeFileAtomic(out, writeUrdf(m, wo));
  std::cout << fmt::format(
      "{}: {} ({} joints), {} identified parameters written{}\n", out, m.name, m.dof(), set,
      ignored.empty()
          ? std::string()
          : fmt::format("; not part of the robot, ignored: {}", fmt::join(ignored, ", ")));
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

std::vector<std::string> splitComma(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

/// --shard i/N: two decimal integers, 0 <= i < N <= 100000 (nothing else on the line).
void parseShard(const std::string& shard, int* index, int* count) {
  const auto slash = shard.find('/');
  auto number = [&](const std::string& t, const char* what) {
    if (t.empty() || t.size() > 6 || t.find_first_not_of("0123456789") != std::string::npos)
      throw Error(
          fmt::format("--shard {}: {} '{}' is not a non-negative integer; expected i/N "
                      "with 0 <= i < N (e.g. --shard 0/4)",
                      shard, what, t));
    return std::stoi(t);
  };
  if (slash == std::string::npos)
    throw Error(fmt::format("--shard {}: expected i/N with 0 <= i < N (e.g. --shard 0/4)", shard));
  *index = number(shard.substr(0, slash), "i");
  *count = number(shard.substr(slash + 1), "N");
  if (*count < 1 || *count > 100000 || *index >= *count)
    throw Error(fmt::format("--shard {}: expected 0 <= i < N and 1 <= N <= 100000", shard));
}

int matrixCommand(const Registry& reg, const std::vector<std::string>& args,
                  const std::string& out_arg, int jobs, const std::string& shard, bool retry,
                  bool force, const std::string& rows, const std::string& cols,
                  const std::string& metric, const std::function<bool()>& cancelled) {
  if (args.empty())
    throw Error(
        "usage: exid matrix MATRIX.yaml --out DIR [-j N] | exid matrix table DIR ... | exid matrix "
        "merge DEST SRC...");
  if (args[0] == "table") {
    if (args.size() != 2)
      throw Error("usage: exid matrix table DIR --rows A,B --cols C --metric NAME");
    const fs::path db = fs::path(args[1]) / "results.sqlite";
    if (metric.empty()) {
      std::cout << "metrics:\n";
      for (const auto& m : matrixMetrics(db)) std::cout << "  " << m << "\n";
      return 0;
    }
    MatrixTable t = matrixTable(db, splitComma(rows), splitComma(cols), metric);
    std::cout << t.markdown;
    std::string safe = metric;
    for (char& c : safe)
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') c = '_';
    const fs::path csv = fs::path(args[1]) / ("table_" + safe + ".csv");
    writeFileAtomic(csv, t.csv);
    std::cout << fmt::format("\n(CSV: {})\n", csv.string());
    return 0;
  }
  if (args[0] == "merge") {
    if (args.size() < 3) throw Error("usage: exid matrix merge DEST_DIR SRC_DIR...");
    std::vector<fs::path> srcs;
    for (std::size_t i = 2; i < args.size(); ++i)
      srcs.push_back(fs::path(args[i]) / "results.sqlite");
    int n = mergeMatrixDatabases(fs::path(args[1]) / "results.sqlite", srcs);
    std::cout << fmt::format("merged {} runs into {}/results.sqlite\n", n, args[1]);
    return 0;
  }
  if (args.size() != 1)
    throw Error("usage: exid matrix MATRIX.yaml --out DIR [-j N] [--shard i/N]");
  MatrixSpec spec = loadMatrix(args[0], reg);
  MatrixOptions opt;
  opt.out_dir = out_arg.empty() ? fs::path("out") / spec.name : fs::path(out_arg);
  if (underMpiLauncher()) {
    if (!mpiAvailable())
      throw Error(
          "exid runs under an MPI launcher but was built without MPI (install libopenmpi-dev and "
          "rebuild), "
          "or run shards with --shard i/N");
    if (!shard.empty()) throw Error("--shard and MPI both split the matrix; use one of them");
    MpiSession mpi;
    opt.jobs = std::max(1, jobs);
    opt.retry_failed = retry;
    opt.force = force;
    opt.cancelled = cancelled;
    opt.shard_index = mpi.rank;
    opt.shard_count = mpi.size;
    opt.database = fmt::format("shard-{}-of-{}.sqlite", mpi.rank, mpi.size);
    MatrixRunSummary s = runMatrix(spec, reg, opt);
    const int ok = mpi.sumInt(s.ok), failed = mpi.sumInt(s.failed), timeout = mpi.sumInt(s.timeout),
              skipped = mpi.sumInt(s.skipped), not_run = mpi.sumInt(s.not_run),
              total = mpi.sumInt(s.total);
    mpi.barrier();  // every shard database is complete
    if (mpi.rank == 0) {
      std::vector<fs::path> shards;
      for (int r = 0; r < mpi.size; ++r)
        shards.push_back(opt.out_dir / fmt::format("shard-{}-of-{}.sqlite", r, mpi.size));
      const int merged = mergeMatrixDatabases(opt.out_dir / "results.sqlite", shards);
      std::cout << fmt::format(
          "matrix {} on {} MPI ranks: {} cells: {} ok, {} failed, {} timeout, {} skipped, {} not "
          "run; "
          "{} new runs gathered into {}/results.sqlite\n",
          spec.name, mpi.size, total, ok, failed, timeout, skipped, not_run, merged,
          opt.out_dir.string());
    }
    return not_run > 0 ? signalExitCode() : 0;
  }
  opt.jobs = jobs;
  opt.retry_failed = retry;
  opt.force = force;
  opt.cancelled = cancelled;
  if (!shard.empty()) parseShard(shard, &opt.shard_index, &opt.shard_count);
  MatrixRunSummary s = runMatrix(spec, reg, opt);
  std::cout << fmt::format(
      "matrix {}: {} cells: {} ok, {} failed, {} timeout, {} skipped (finished before), {} not "
      "run; "
      "{:.2f} s\nresults: {}/results.sqlite\n",
      spec.name, s.total, s.ok, s.failed, s.timeout, s.skipped, s.not_run, s.wall_s,
      opt.out_dir.string());
  if (s.incomplete > 0)
    std::cout << fmt::format(
        "{} incomplete (no space left on device): they run again when the matrix is resumed\n",
        s.incomplete);
  return s.not_run > 0 ? signalExitCode() : 0;
}

// What the command line gives the commands (shared by the subcommands' options and the run).
struct CommandArgs {
  std::string robot, model = "differential", model_params = "{}", samples, what, out, study, data;
  bool json = false, rigid_body_only = false;
  std::vector<std::string> matrix_args, inspect_args, sets;
  std::string params, json_out;
  int jobs = 1;
  std::string shard, rows, cols, metric;
  bool retry = false, force = false;
  std::string export_dir;
  double rate_hz = 1000.0;
  int periods = 1;
  std::vector<double> torque_max;
  std::string collision_study;  // check-trajectory --collision
};

// exid robot info ROBOT; returns the info subcommand.
CLI::App* addRobotCommand(CLI::App& app, CommandArgs* st) {
  auto* robot = app.add_subcommand("robot", "robot descriptions: exid robot info ROBOT");
  auto* info = robot->add_subcommand("info", "parameters, base parameters and their expressions");
  robot->require_subcommand(1);
  info->add_option("robot", st->robot, "robot plugin name, or a .urdf / DH .yaml file")->required();
  info->add_option("--model", st->model,
                   "observation model that defines the columns (default differential)");
  info->add_option("--model-params", st->model_params,
                   "its parameters as YAML, e.g. '{rotor_inertia: true}'");
  info->add_flag("--json", st->json, "print JSON");
  return info;
}

CLI::App* addEvalCommand(CLI::App& app, CommandArgs* st) {
  auto* eval =
      app.add_subcommand("eval", "evaluate torque, regressors or energy on a CSV of samples");
  eval->add_option("robot", st->robot, "robot plugin name, or a .urdf / DH .yaml file")->required();
  eval->add_option("--samples", st->samples, "CSV with q1..qn qd1..qdn qdd1..qddn")->required();
  eval->add_option("--what", st->what, "torque|regressor|energy|energy_regressor|wrench_regressor")
      ->required();
  eval->add_option("--out", st->out, "output CSV")->required();
  eval->add_flag("--rigid-body-only", st->rigid_body_only,
                 "torque: the rigid bodies alone (default: the full torque, drives included)");
  return eval;
}

// excite, simulate, identify: one stage of a study each.
std::vector<CLI::App*> addStageCommands(CLI::App& app, CommandArgs* st) {
  std::vector<CLI::App*> stages;
  for (const char* name : {"excite", "simulate", "identify"}) {
    auto* s = app.add_subcommand(name, fmt::format("run only the {} stage of a study", name));
    s->add_option("study", st->study, "study YAML file")->required();
    s->add_option("--out", st->out, "output folder");
    if (std::string(name) == "identify")
      s->add_option("--data", st->data,
                    "recorded CSV or ROS 2 bag folder (replaces the experiment)");
    if (std::string(name) == "excite") {
      s->add_option("--export", st->export_dir,
                    "also write the optimal trajectory for execution into this folder: "
                    "trajectory.csv, trajectory.params.yaml, joint_trajectory.yaml (ROS 2), "
                    "trajectory_check.json");
      s->add_option("--rate-hz", st->rate_hz, "--export: the controller rate [Hz] (default 1000)")
          ->check(CLI::PositiveNumber);
      s->add_option("--periods", st->periods, "--export: repetitions of the motion (default 1)")
          ->check(CLI::Range(1, 100000));
    }
    stages.push_back(s);
  }
  return stages;
}

CLI::App* addExportCommand(CLI::App& app, CommandArgs* st) {
  auto* exp = app.add_subcommand("export",
                                 "write identified consistent parameters into a URDF: "
                                 "exid export [ROBOT] --study DIR --out robot_identified.urdf");
  exp->add_option("robot", st->robot,
                  "robot plugin name or .urdf / DH .yaml file (default: the study's robot)");
  exp->add_option("--study", st->study, "output folder of a study identified with consistent_ls")
      ->required();
  exp->add_option("--out", st->out, "URDF file to write")->required();
  return exp;
}

CLI::App* addCheckTrajectoryCommand(CLI::App& app, CommandArgs* st) {
  auto* chk = app.add_subcommand(
      "check-trajectory",
      "check a trajectory CSV against a robot's limits at the file's rate: exid check-trajectory "
      "ROBOT FILE.csv [--torque-max-nm T1,...,Tn] [--collision STUDY.yaml] [--json FILE]");
  chk->add_option("robot", st->robot, "robot plugin name, or a .urdf / DH .yaml file")->required();
  chk->add_option("file", st->samples, "CSV with t, q1..qn, qd1..qdn, qdd1..qddn [, tau1..taun]")
      ->required();
  chk->add_option("--torque-max-nm", st->torque_max,
                  "torque limits [N m or N] per joint when the robot description has none")
      ->delimiter(',');
  chk->add_option("--collision", st->collision_study,
                  "a study whose excitation.collision (obstacles, allowed pairs, margin) the "
                  "smallest distance between the checked pairs is measured with");
  chk->add_option("--json", st->json_out, "write the result as JSON to this file");
  return chk;
}

CLI::App* addMatrixCommand(CLI::App& app, CommandArgs* st) {
  auto* matrix = app.add_subcommand(
      "matrix",
      "comparison matrices: exid matrix MATRIX.yaml --out DIR [-j N] [--shard i/N] | "
      "exid matrix table DIR --rows A,B --cols C --metric M | exid matrix merge DEST SRC...");
  matrix->add_option("args", st->matrix_args,
                     "MATRIX.yaml, or 'table DIR', or 'merge DEST SRC...'");
  matrix->add_option("--out", st->out, "output folder (results.sqlite, cells/)");
  matrix->add_option("-j,--jobs", st->jobs, "cells run in parallel (1 to 1024)")
      ->check(CLI::Range(1, 1024));
  matrix->add_option("--shard", st->shard, "run every N-th cell: i/N with 0 <= i < N");
  matrix->add_flag("--retry-failed", st->retry, "re-run cells that failed or timed out");
  matrix->add_flag("--force", st->force, "re-run every cell, finished ones included");
  matrix->add_option("--rows", st->rows, "table: axes of the rows, comma-separated");
  matrix->add_option("--cols", st->cols, "table: axes of the columns, comma-separated");
  matrix->add_option("--metric", st->metric, "table: the metric (without: list the metrics)");
  return matrix;
}

CLI::App* addInspectCommand(CLI::App& app, CommandArgs* st) {
  auto* inspect = app.add_subcommand(
      "inspect",
      "look at a recording before trusting it: exid inspect ROBOT DATA.csv|BAG_FOLDER [--set "
      "key=value ...] [--json FILE] | exid inspect STUDY.yaml [--json FILE]");
  inspect->add_option("args", st->inspect_args,
                      "ROBOT (plugin name, .urdf or DH .yaml) and DATA.csv or a ROS 2 bag folder, "
                      "or STUDY.yaml");
  inspect
      ->add_option("--set", st->sets,
                   "a parameter of the csv (or rosbag2) experiment, key=value (repeatable), e.g. "
                   "sample_period_s=0.002 or q_columns=[a,b,c]")
      ->allow_extra_args(false);
  inspect->add_option("--params", st->params,
                      "the csv experiment's parameters as YAML, e.g. '{sample_period_s: 0.002}'");
  inspect->add_option("--model", st->model,
                      "observation model for the condition number (default differential)");
  inspect->add_option("--model-params", st->model_params,
                      "its parameters as YAML, e.g. '{offset: true}'");
  inspect->add_option("--json", st->json_out, "write the result as JSON to this file");
  return inspect;
}

}  // namespace

Commands addCommands(CLI::App& app, Registry& registry) {
  auto st = std::make_shared<CommandArgs>();
  auto* info = addRobotCommand(app, st.get());
  auto* eval = addEvalCommand(app, st.get());
  const std::vector<CLI::App*> stages = addStageCommands(app, st.get());
  auto* exp = addExportCommand(app, st.get());
  auto* chk = addCheckTrajectoryCommand(app, st.get());
  auto* matrix = addMatrixCommand(app, st.get());
  auto* inspect = addInspectCommand(app, st.get());

  Commands c;
  c.run = [st, info, eval, exp, chk, stages, matrix, inspect, &registry]() -> int {
    if (*chk)
      return checkTrajectoryCommand(registry, st->robot, st->samples, st->torque_max, st->json_out,
                                    st->collision_study);
    if (*inspect)
      return inspectCommand(registry, st->inspect_args, st->sets, st->params, st->model,
                            st->model_params, st->json_out);
    if (*matrix)
      return matrixCommand(registry, st->matrix_args, st->out, st->jobs, st->shard, st->retry,
                           st->force, st->rows, st->cols, st->metric, cancelled());
    if (*info) return robotInfo(registry, st->robot, st->model, st->model_params, st->json);
    if (*eval)
      return evalCommand(registry, st->robot, st->samples, st->what, st->out, st->rigid_body_only);
    if (*exp) return exportCommand(registry, st->robot, st->study, st->out);
    for (auto* s : stages)
      if (*s)
        return stageCommand(registry, s->get_name(), st->study, st->data, st->out,
                            ExportArgs{st->export_dir, st->rate_hz, st->periods});
    std::cerr << "exid: no command chosen (see exid --help)\n";
    return 2;
  };
  return c;
}

}  // namespace exid::cli
