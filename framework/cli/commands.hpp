// exid — the stage commands of the command line (docs/conventions.md §3) beyond
// run/validate/plugins.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>

#include "exid/registry.hpp"

namespace exid::cli {

struct Commands {
  std::function<int()> run;  // runs whichever of them was chosen
};

Commands addCommands(CLI::App& app, Registry& registry);

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

/// True once SIGINT or SIGTERM was received (set up by main).
std::function<bool()> cancelled();
/// The exit code of a run stopped by a signal: 128 + the signal (130 SIGINT, 143 SIGTERM); 130
/// when no signal was received.
int signalExitCode();

}  // namespace exid::cli
