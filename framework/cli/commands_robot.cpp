// exid — the robot commands: robot info, eval, check-trajectory, export (and loadRobot, which
// every command taking a robot uses).
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iostream>
#include <memory>
#include <set>
#include <sstream>

#include "commands.hpp"
#include "exid/config.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/mjcf_writer.hpp"
#include "exid/sdf_writer.hpp"
#include "exid/study_check.hpp"
#include "exid/trajectory_export.hpp"
#include "exid/urdf_writer.hpp"

namespace exid::cli {

namespace fs = std::filesystem;

namespace {

/// The name of the first element of XML text (after the declaration, comments and a DOCTYPE),
/// "" when there is none: which loader an .xml robot file goes to.
std::string xmlRootElement(const std::string& text) {
  std::size_t i = 0;
  while ((i = text.find('<', i)) != std::string::npos) {
    if (text.compare(i, 4, "<!--") == 0) {
      i = text.find("-->", i);
    } else if (text.compare(i, 2, "<?") == 0 || text.compare(i, 2, "<!") == 0) {
      i = text.find('>', i);
    } else {
      std::size_t e = i + 1;
      while (e < text.size() &&
             (std::isalnum(static_cast<unsigned char>(text[e])) || text[e] == '_' ||
              text[e] == ':' || text[e] == '-' || text[e] == '.'))
        ++e;
      return text.substr(i + 1, e - i - 1);
    }
    if (i == std::string::npos) break;
  }
  return "";
}

/// The robot plugin that reads a description file, by its extension (an .xml file by its root
/// element: <mujoco> MJCF, <sdf> SDF, else URDF); "" for none.
std::string robotPluginOfFile(const fs::path& p) {
  const std::string ext = p.extension().string();
  if (ext == ".urdf" || ext == ".xacro") return "urdf";
  if (ext == ".yaml" || ext == ".yml") return "dh";
  if (ext == ".sdf") return "sdf";
  if (ext == ".mjcf") return "mjcf";
  if (ext != ".xml") return "";
  const std::string root = xmlRootElement(readInputFile(p, "robot", kMaxRobotFileBytes));
  return root == "mujoco" ? "mjcf" : root == "sdf" ? "sdf" : "urdf";
}

}  // namespace

/// ROBOT is a robot plugin name or a path to a robot description file (.urdf, .sdf, .mjcf, .xml,
/// DH .yaml; a .xacro file goes to the URDF loader, which says how to expand it; every command
/// taking a robot comes here).
std::shared_ptr<const RobotModel> loadRobot(const Registry& reg, const std::string& robot) {
  std::string type = robot, params = "{}";
  const fs::path p(robot);
  const std::string ext = p.extension().string();
  static const std::set<std::string> kFiles = {".urdf", ".xacro", ".yaml", ".yml",
                                               ".sdf",  ".mjcf",  ".xml"};
  if (kFiles.count(ext)) {
    if (!fs::exists(p)) throw Error(fmt::format("{}: no such robot file", robot));
    checkInputFile(p, "robot", kMaxRobotFileBytes);  // a FIFO or a device: refused, not opened
    type = robotPluginOfFile(p);
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
        fmt::format("{}: a file, but not a robot description exid reads (expected a .urdf, "
                    ".sdf, .mjcf or .xml file, a DH .yaml table, or a .xacro file expanded by "
                    "xacro first), nor a robot plugin's name",
                    robot));
  const PluginInfo& info = reg.get(PluginKind::Robot, type);
  ParamSet ps = resolveParams(info, params, "robot " + type, fs::current_path());
  RunContext ctx;
  return reg.create<Robot>(type, ps)->build(ctx);
}

int robotInfo(const Registry& reg, const std::string& robot, const std::string& model_given,
              const std::string& model_params, bool json) {
  auto r = loadRobot(reg, robot);
  // (the fixed-base models refuse a floating base: its own model by default, and said so)
  const std::string model_name = !model_given.empty() ? model_given
                                 : r->floating_base   ? "floating_base"
                                                      : "differential";
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
    if (model_given.empty())
      j["model_rule"] = r->floating_base ? "floating_base: the robot has a floating base (--model "
                                           "to choose another)"
                                         : "differential: the default (--model to choose another)";
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
  if (r->hasLoops())
    std::cout << fmt::format(
        "  closed chain: {} tree joints, {} loop-closure joint(s); the "
        "joints below are the actuated ones\n",
        r->numJoints(), r->closed.loops.size());
  if (r->floating_base)
    std::cout << fmt::format(
        "  floating base: link '{}' (parameters XX0 ... M0; parent 0 below means this link)\n",
        r->base.link);
  for (const auto& note : r->notes) std::cout << "  note: " << note << "\n";
  for (int i = 0; i < r->dof(); ++i) {
    const Body& body = r->bodies[static_cast<std::size_t>(r->actuatedJoint(i))];
    const JointLimits& L = r->limits[static_cast<std::size_t>(i)];
    std::cout << fmt::format(
        "  {} {:<12} {:<9} parent {:>2}  q in [{:.4g}, {:.4g}]  |qd| <= {:.4g}\n", i + 1,
        body.joint_name, body.type == JointType::Revolute ? "revolute" : "prismatic",
        body.parent + 1, L.q_min, L.q_max, L.qd_max);
  }
  std::cout << fmt::format(
      "\nmodel {}{}: {} standard parameters, {} base parameters (tolerance {:g})\n\n", model_name,
      model_given.empty() && r->floating_base ? " (the robot has a floating base; --model to "
                                                "choose another)"
                                              : "",
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
  r->requireFixedBase("exid robot eval");
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
      if (rigid_body_only && r->hasLoops()) {
        tau = actuatorTorque(*r, *data, DriveColumns{}, qm, qdm, qddm);
      } else if (rigid_body_only) {
        tau = inverseDynamics(*r, *data, q, qd, qdd);
        if (r->hasTransmission()) tau = r->transmission.transpose() * tau;
      } else {
        tau = actuatorTorque(*r, *data, drives, qm, qdm, qddm);
      }
      t.data.row(k) = tau.transpose();
    } else if (what == "regressor") {
      if (r->hasLoops())
        actuatorRegressor(*r, *data, DriveColumns{}, qm, qdm, qddm, Y);
      else
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

/// exid check-trajectory: a trajectory CSV (t, q, qd, qdd[, tau]) against the robot's limits at
/// the file's own rate; exit 1 when a limit is exceeded.
/// With a study (--collision), the smallest distance of the pairs its excitation.collision
/// checks as well.
int checkTrajectoryCommand(const Registry& reg, const std::string& robot, const std::string& file,
                           const std::vector<double>& torque_max, const std::string& json_out,
                           const std::string& collision_study) {
  const auto model = loadRobot(reg, robot);
  model->requireFixedBase("exid robot check-trajectory");
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

namespace {

/// The description format of `exid export`: --format, else the extension of --out, else URDF;
/// both given and contradicting: refused.
std::string exportFormat(const std::string& format, const std::string& out) {
  static const char* const kFormats[] = {"urdf", "mjcf", "sdf"};
  if (!format.empty() &&
      std::find(std::begin(kFormats), std::end(kFormats), format) == std::end(kFormats))
    throw Error(fmt::format("--format {}: expected urdf, mjcf (MuJoCo) or sdf (SDFormat)", format));
  std::string ext = fs::path(out).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  const std::string by_ext = ext == ".urdf"   ? "urdf"
                             : ext == ".mjcf" ? "mjcf"
                             : ext == ".sdf"  ? "sdf"
                                              : "";
  if (!format.empty() && !by_ext.empty() && format != by_ext)
    throw Error(
        fmt::format("--out {}: the extension {} says {}, but --format says {}; give a matching "
                    "extension or leave --format out",
                    out, ext, by_ext, format));
  return !format.empty() ? format : !by_ext.empty() ? by_ext : "urdf";
}

std::string upper(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  return s;
}

}  // namespace

/// exid export: the identified consistent standard parameters (consistent_ls writes them into
/// summary.json identification.details.standard_parameters) written as URDF, MJCF or SDF with
/// the robot's kinematics, limits and drives (docs/consistent.md).
int exportCommand(const Registry& reg, const std::string& robot, const std::string& study_dir,
                  const std::string& out, const std::string& format_arg) {
  const std::string format = exportFormat(format_arg, out);
  const std::string format_name = upper(format);
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
  // (a floating-base robot: its base link's parameters are XX0 ... M0, the bodies' XX1 ...; the
  // writers put a floating joint, a free joint, a free model)
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
    if (m.floating_base && n.size() > 1 && n.back() == '0' &&
        n.find_first_of("0123456789") == n.size() - 1) {
      const std::string pre = n.substr(0, n.size() - 1);
      int k = -1;
      for (int c = 0; c < 10; ++c)
        if (pre == kInertialNames[c]) k = c;
      if (k >= 0) {
        m.base.inertia(k) = v;
        ++set;
        continue;
      }
    }
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
  if (m.floating_base) {
    const InertiaCheck c = checkPhysical(m.base.inertia);
    if (!c.ok)
      throw Error(fmt::format(
          "floating base link '{}': {}; the identified parameters are not physically consistent "
          "and cannot be written as {}",
          m.base.link, c.rule, format_name));
  }
  for (int j = 0; j < m.numJoints(); ++j) {
    const InertiaCheck c = checkPhysical(m.bodies[static_cast<std::size_t>(j)].inertia);
    if (!c.ok)
      throw Error(
          fmt::format("body {} ('{}'): {}; the identified parameters are not physically consistent "
                      "and cannot be written as {}",
                      j + 1, m.bodies[static_cast<std::size_t>(j)].name, c.rule, format_name));
  }
  const std::string comment = fmt::format(
      "  {}: identified by exid {} ({}), study {} ({}).\n  Inertial parameters and drives "
      "from identification.details.standard_parameters; kinematics, limits and transmission "
      "from {}.",
      m.name, EXID_VERSION_STRING, I->find("estimator") ? I->find("estimator")->asString() : "?",
      S.find("study") ? S.find("study")->asString() : "?", dir.string(), base->source);
  m.name = m.name + "_identified";
  std::vector<std::string> left_out;
  std::string written;
  if (format == "mjcf") {
    MjcfWriteOptions wo;
    wo.comment = comment;
    written = writeMjcf(m, wo, &left_out);
  } else if (format == "sdf") {
    SdfWriteOptions wo;
    wo.comment = comment;
    written = writeSdf(m, wo, &left_out);
  } else {
    UrdfWriteOptions wo;
    wo.comment = comment;
    written = writeUrdf(m, wo);
  }
  writeFileAtomic(out, written);
  std::cout << fmt::format("{}: {} ({}, {} joints), {} identified parameters written{}\n", out,
                           m.name, format_name, m.dof(), set,
                           ignored.empty() ? std::string()
                                           : fmt::format("; not part of the robot, ignored: {}",
                                                         fmt::join(ignored, ", ")));
  for (const std::string& s : left_out)
    std::cout << fmt::format("note: not carried by {}: {}\n", format_name, s);
  return 0;
}

}  // namespace exid::cli
