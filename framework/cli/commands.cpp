// exid — the stage commands' options and dispatch: robot info, eval, excite, simulate, identify,
// export, check-trajectory, matrix, inspect. The commands themselves: commands_robot.cpp,
// commands_study.cpp, commands_matrix.cpp.
#include "commands.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <iostream>
#include <memory>

#include "exid/context.hpp"

namespace exid::cli {

namespace {

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
  std::string format;           // export --format
};

// exid robot info ROBOT; returns the info subcommand.
CLI::App* addRobotCommand(CLI::App& app, CommandArgs* st) {
  auto* robot = app.add_subcommand("robot", "robot descriptions: exid robot info ROBOT");
  auto* info = robot->add_subcommand("info", "parameters, base parameters and their expressions");
  robot->require_subcommand(1);
  info->add_option("robot", st->robot, "robot plugin name, or a .urdf / DH .yaml file")->required();
  info->add_option("--model", st->model,
                   "observation model that defines the columns (default: differential, or "
                   "floating_base for a floating-base robot)");
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
  auto* exp = app.add_subcommand(
      "export",
      "write identified consistent parameters as a robot description (URDF, MJCF or SDF): "
      "exid export [ROBOT] --study DIR --out robot_identified.urdf|.mjcf|.sdf [--format F]");
  exp->add_option("robot", st->robot,
                  "robot plugin name or .urdf / DH .yaml file (default: the study's robot)");
  exp->add_option("--study", st->study, "output folder of a study identified with consistent_ls")
      ->required();
  exp->add_option("--out", st->out, "file to write")->required();
  exp->add_option("--format", st->format,
                  "urdf (default), mjcf (MuJoCo) or sdf (SDFormat 1.9); without it the "
                  "extension of --out chooses (.urdf, .mjcf, .sdf)");
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
    if (*info)
      return robotInfo(registry, st->robot, info->get_option("--model")->count() ? st->model : "",
                       st->model_params, st->json);
    if (*eval)
      return evalCommand(registry, st->robot, st->samples, st->what, st->out, st->rigid_body_only);
    if (*exp) return exportCommand(registry, st->robot, st->study, st->out, st->format);
    for (auto* s : stages)
      if (*s)
        return stageCommand(registry, s->get_name(), st->study, st->data, st->out,
                            ExportArgs{st->export_dir, st->rate_hz, st->periods});
    std::cerr << "exid: no command chosen (see exid --help)\n";
    return 2;
  };
  return c;
}

ProgressPrinter::ProgressPrinter() : tty_(::isatty(STDERR_FILENO) != 0) {}

std::function<void(const std::string&, double, const std::string&)> ProgressPrinter::callback() {
  return [this](const std::string& s, double f, const std::string& t) { (*this)(s, f, t); };
}

void ProgressPrinter::operator()(const std::string& stage, double f, const std::string& text) {
  if (logLevel() < LogLevel::Info) return;
  std::lock_guard<std::mutex> lock(m_);
  const auto now = std::chrono::steady_clock::now();
  const bool started = stage != stage_;
  if (started) {
    stage_ = stage;
    stage_start_ = now;
  }
  f = std::clamp(f, 0.0, 1.0);
  // the time left, once a little of the stage is done: elapsed (1 - f) / f
  const double elapsed = std::chrono::duration<double>(now - stage_start_).count();
  const std::string left = f >= 0.02 && f < 1.0 && elapsed >= 1.0
                               ? fmt::format(" ~{:.0f} s left", elapsed * (1.0 - f) / f)
                               : std::string();
  if (tty_) {
    const int width = 30;
    const int filled = std::clamp(static_cast<int>(f * width + 0.5), 0, width);
    std::cerr << fmt::format("\r[exid] {:<12} [{}{}] {:3.0f}%{:<14} {:<40}", stage,
                             std::string(static_cast<std::size_t>(filled), '#'),
                             std::string(static_cast<std::size_t>(width - filled), '.'), 100.0 * f,
                             left, text.substr(0, 40));
    if (f >= 1.0) std::cerr << '\n';
    std::cerr.flush();
  } else if (started || f >= 1.0 || now - last_ > std::chrono::seconds(2)) {
    std::cerr << fmt::format("[exid] {} {:3.0f}%{} {}\n", stage, 100.0 * f, left, text);
    last_ = now;
  }
}

}  // namespace exid::cli
