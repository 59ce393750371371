// The modes of `mcms audit` (issue 11), one file each: each adds its subcommand to the
// `audit` command (app/cmd_audit.cpp) and returns it with its runner.
//   audit cameras DIR      app/cmd_audit_cameras.cpp
//   audit robot LOG.csv    app/cmd_audit_robot.cpp
//   audit fusion --tracker .. --robot .. --setup ..   app/cmd_audit_fusion.cpp
//   audit lens MODEL.cameramodel   app/cmd_audit_lens.cpp
#pragma once

#include "app/commands.h"

namespace mcms::app {

std::pair<CLI::App*, Runner> AddAuditCameras(CLI::App& audit);
std::pair<CLI::App*, Runner> AddAuditRobot(CLI::App& audit);
std::pair<CLI::App*, Runner> AddAuditFusion(CLI::App& audit);
std::pair<CLI::App*, Runner> AddAuditLens(CLI::App& audit);

}  // namespace mcms::app
