// mcms: the command-line front end. A thin table of subcommands; each RunX parses its
// options and calls the library. No algorithm lives here.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "app/commands.h"
#include "core/error.h"
#include "core/interrupt.h"
#include "core/io.h"

namespace {

// A word where a subcommand was expected but none has that name (`mcms audit imu`): named
// with the choices, instead of CLI11's "A subcommand is required". Returns 2 after saying
// so, or 0 when the command line names known subcommands throughout.
int RefuseUnknownSubcommand(CLI::App& app, int argc, char** argv) {
  CLI::App* level = &app;
  std::string path = "mcms";
  for (int i = 1; i < argc; ++i) {
    const std::string word = argv[i];
    const std::vector<CLI::App*> subs = level->get_subcommands([](CLI::App*) { return true; });
    if (word.empty() || word[0] == '-' || subs.empty()) return 0;
    CLI::App* next = nullptr;
    for (CLI::App* s : subs)
      if (s->check_name(word)) next = s;
    if (!next) {
      std::string names;
      for (const CLI::App* s : subs) names += (names.empty() ? "" : ", ") + s->get_name();
      std::fprintf(stderr, "mcms: error: unknown %s '%s' of `%s`; %s are: %s (`%s --help` shows them)\n",
                   level == &app ? "command" : "mode", word.c_str(), path.c_str(),
                   level == &app ? "the commands" : "its modes", names.c_str(), path.c_str());
      return 2;
    }
    level = next;
    path += " " + word;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Ctrl-C or a kill leaves no temporaries behind (core/interrupt.h).
  mcms::InstallInterruptCleanup();
  CLI::App app{"mcms: multi-camera photogrammetry, robot and inclinometer fusion for robot metrology"};
  app.require_subcommand(1);
  mcms::app::RegisterCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (const int code = RefuseUnknownSubcommand(app, argc, argv)) return code;
    return app.exit(e);
  }
  try {
    // One command per process: every file it reads is an input no output may replace.
    const mcms::RunInputsRecord run_inputs;
    return mcms::app::RunSelected(app);
  } catch (const mcms::InputError& e) {
    std::fprintf(stderr, "mcms: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcms: internal error: %s\n", e.what());
    return 3;
  }
}
