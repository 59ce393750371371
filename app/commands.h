// Subcommand registry of the mcms CLI. Each app/cmd_*.cpp registers its subcommands
// with a static McmsCommand object: a function that adds a CLI11 subcommand and
// returns the function that runs it. Commands parse options and call the library;
// no algorithm lives here. Errors: throw mcms::InputError (main prints it, exit 2).
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <vector>

namespace mcms::app {

using Runner = std::function<int()>;
// Adds a subcommand to `app` and returns (the subcommand, its runner).
using Registrar = std::function<std::pair<CLI::App*, Runner>(CLI::App& app)>;

struct McmsCommand {
  explicit McmsCommand(Registrar r);
};

void RegisterCommands(CLI::App& app);
int RunSelected(CLI::App& app);

}  // namespace mcms::app
