// mcms: the command-line front end. A thin table of subcommands; each RunX parses its
// options and calls the library. No algorithm lives here.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>

#include "app/commands.h"
#include "core/error.h"

int main(int argc, char** argv) {
  CLI::App app{"mcms: multi-camera photogrammetry, robot and inclinometer fusion for robot metrology"};
  app.require_subcommand(1);
  mcms::app::RegisterCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    return mcms::app::RunSelected(app);
  } catch (const mcms::InputError& e) {
    std::fprintf(stderr, "mcms: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcms: internal error: %s\n", e.what());
    return 3;
  }
}
