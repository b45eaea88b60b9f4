// exid — the stage commands of the command line (DESIGN.md §5) beyond run/validate/plugins.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>

#include "exid/registry.hpp"

namespace exid::cli {

struct Commands {
  std::function<int()> run;  // runs whichever of them was chosen
};

Commands addCommands(CLI::App& app, Registry& registry);

/// True once SIGINT or SIGTERM was received (set up by main).
std::function<bool()> cancelled();

}  // namespace exid::cli
