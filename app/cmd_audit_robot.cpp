// mcms audit robot LOG.csv: the robot mode of the model audit (calib/robot_audit.h).
#include "app/audit_modes.h"
#include "core/error.h"

namespace mcms::app {

std::pair<CLI::App*, Runner> AddAuditRobot(CLI::App& audit) {
  CLI::App* cmd = audit.add_subcommand("robot", "Audit a robot model against a measurement log (in progress).");
  return std::make_pair(cmd, Runner([] {
                          Throw("audit robot: not built yet");
                          return 2;
                        }));
}

}  // namespace mcms::app
