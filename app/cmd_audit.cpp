// mcms audit: the model audit (issue 11), one mode per kind of measured data
// (app/audit_modes.h): show where the measurements and the nominal forward model disagree
// beyond chance, name the catalog effects (model/extensions.h) that explain it, and
// measure what each gains on held-out data.
#include <memory>
#include <vector>

#include "app/audit_modes.h"

namespace mcms::app {
namespace {

McmsCommand audit_command([](CLI::App& app) {
  CLI::App* cmd = app.add_subcommand(
      "audit",
      "Audit a model against measured data: `audit cameras DIR` (a recording: images, rig, target), `audit robot "
      "LOG.csv` (a robot's joint values and externally measured positions) or `audit fusion` (the logs of `mcms "
      "fuse`: tracker, robot, inclinometer) or `audit lens MODEL.cameramodel` (a lens model against its chessboard observations). Shows where the nominal model and the measurements disagree, names the "
      "effects that explain it and their held-out gain.");
  cmd->require_subcommand(1);
  auto modes = std::make_shared<std::vector<std::pair<CLI::App*, Runner>>>();
  modes->push_back(AddAuditCameras(*cmd));
  modes->push_back(AddAuditRobot(*cmd));
  modes->push_back(AddAuditFusion(*cmd));
  modes->push_back(AddAuditLens(*cmd));
  return std::make_pair(cmd, Runner([modes] {
                          for (auto& [sub, run] : *modes)
                            if (sub->parsed()) return run();
                          return 2;
                        }));
});

}  // namespace
}  // namespace mcms::app
