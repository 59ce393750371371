// The whole `mcms audit robot` job on the jobs floor (audit/robot_audit.h holds the audit).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "audit/robot_audit.h"
#include "jobs/job.h"

namespace mcms {

// The whole `mcms audit robot` job: read, audit, write the output folder (report.txt,
// report.json, robot.yaml (and robot.urdf for a URDF robot), residuals.csv,
// plots/effect<k>.svg (each named effect on the fitted log), next_poses.csv when a pair is
// undecided; with --validate validation.csv and plots/validation<k>.svg (per other session:
// point 1's error per posture, and per named cause without and with it; atomically)
// and/or a JSON file.
struct RobotAuditJob {
  std::filesystem::path log, robot, output_dir, json;
  ChainSelection chain;                       // of a URDF robot
  std::vector<int> points;                    // points of a rigid body to use (1-based; empty: all)
  std::vector<std::filesystem::path> validate;  // other sessions, scored frozen
  RobotAuditOptions options;
};
// out.print receives the report text, out.progress (may be empty) the audit's progress
// lines (job.options.progress is used when out.progress is empty).
void RunRobotAuditJob(const RobotAuditJob& job, const JobOutput& out);

}  // namespace mcms
