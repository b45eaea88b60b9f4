#include "commands.hpp"

#include <fmt/format.h>

#include <iostream>
#include <memory>

namespace exid::cli {

Commands addCommands(CLI::App& app, Registry& registry) {
  (void)app;
  (void)registry;
  Commands c;
  c.run = [] {
    std::cerr << "exid: no command chosen (see exid --help)\n";
    return 2;
  };
  return c;
}

}  // namespace exid::cli
