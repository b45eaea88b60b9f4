// exid — the stage commands of the command line (docs/conventions.md §3) beyond
// run/validate/plugins.
#pragma once

#include <CLI/CLI.hpp>
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "exid/registry.hpp"
#include "exid/robot_model.hpp"

namespace exid::cli {

struct Commands {
  std::function<int()> run;  // runs whichever of them was chosen
};

Commands addCommands(CLI::App& app, Registry& registry);

// The commands addCommands runs, each returning the exit code.
// commands_robot.cpp: robot info, eval, check-trajectory, export.
std::shared_ptr<const RobotModel> loadRobot(const Registry& reg, const std::string& robot);
/// model_name empty: differential, or floating_base for a floating-base robot (said so).
int robotInfo(const Registry& reg, const std::string& robot, const std::string& model_name,
              const std::string& model_params, bool json);
int evalCommand(const Registry& reg, const std::string& robot, const std::string& samples,
                const std::string& what, const std::string& out, bool rigid_body_only);
int checkTrajectoryCommand(const Registry& reg, const std::string& robot, const std::string& file,
                           const std::vector<double>& torque_max, const std::string& json_out,
                           const std::string& collision_study);
/// `format`: urdf, mjcf, sdf or "" (the extension of `out` chooses; URDF when it does not).
int exportCommand(const Registry& reg, const std::string& robot, const std::string& study_dir,
                  const std::string& out, const std::string& format);
// commands_study.cpp: excite, simulate, identify, inspect.
/// Single stages run through the study runner on a trimmed copy of the study.
struct ExportArgs {
  std::string dir;
  double rate_Hz = 1000.0;
  int periods = 1;
};
int stageCommand(const Registry& reg, const std::string& stage, const std::string& study,
                 const std::string& data_file, std::string out, const ExportArgs& ex = {});
int inspectCommand(const Registry& reg, const std::vector<std::string>& args,
                   const std::vector<std::string>& sets, const std::string& params,
                   const std::string& model_name, const std::string& model_params,
                   const std::string& json_out);
// commands_matrix.cpp: matrix (run, table, merge).
int matrixCommand(const Registry& reg, const std::vector<std::string>& args,
                  const std::string& out_arg, int jobs, const std::string& shard, bool retry,
                  bool force, const std::string& rows, const std::string& cols,
                  const std::string& metric, const std::function<bool()>& cancelled);

/// MPI (optional at build time): a session is active when the program was started by an MPI
/// launcher and exid was built with MPI.
bool underMpiLauncher();
bool mpiAvailable();
struct MpiSession {
  MpiSession();
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  void barrier();
  int sumInt(int v);
  int rank = 0, size = 1;
  bool active = false;
};

/// The progress of a run's stages on stderr (RunOptions::progress): on a terminal a bar with the
/// percentage and an estimate of the time left; otherwise a line when a stage starts, when it
/// ends, and at most every 2 s between. Silent below log level info (-q).
class ProgressPrinter {
 public:
  ProgressPrinter();
  void operator()(const std::string& stage, double fraction, const std::string& text);
  /// As a RunOptions::progress callback (the printer must outlive the run).
  std::function<void(const std::string&, double, const std::string&)> callback();

 private:
  bool tty_;
  std::mutex m_;
  std::string stage_;
  std::chrono::steady_clock::time_point stage_start_{}, last_{};
};

/// True once SIGINT or SIGTERM was received (set up by main).
std::function<bool()> cancelled();
/// The exit code of a run stopped by a signal: 128 + the signal (130 SIGINT, 143 SIGTERM); 130
/// when no signal was received.
int signalExitCode();

}  // namespace exid::cli
