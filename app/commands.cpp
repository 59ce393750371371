#include "app/commands.h"

#include <memory>

namespace mcms::app {

namespace {
std::vector<Registrar>& Registrars() {
  static std::vector<Registrar> r;
  return r;
}
std::vector<std::pair<CLI::App*, Runner>>& Registered() {
  static std::vector<std::pair<CLI::App*, Runner>> r;
  return r;
}
}  // namespace

McmsCommand::McmsCommand(Registrar r) { Registrars().push_back(std::move(r)); }

void RegisterCommands(CLI::App& app) {
  for (auto& r : Registrars()) Registered().push_back(r(app));
}

int RunSelected(CLI::App& app) {
  for (auto& [sub, run] : Registered())
    if (sub->parsed()) return run();
  (void)app;
  return 1;
}

}  // namespace mcms::app
