// The whole `mcms audit fusion` job on the jobs floor (audit/fusion_log_audit.h holds the
// audits it chains).
#pragma once

#include <functional>
#include <string>

#include "audit/fusion_log_audit.h"
#include "jobs/job.h"

namespace mcms {

// The whole `mcms audit fusion` job (the inputs of `mcms fuse`): the tracker's poses
// against the robot's joints through the setup's registration and target mount (the robot
// audit of audit/robot_audit.h, plus clock_offset between the two logs, joint velocities
// from the joint log), and with an inclinometer log its readings against the tracker's
// flange orientation (AuditInclinometerLogs); the designed false-alarm rate is split
// evenly between the two. Writes the JSON report and the output folder when asked.
struct FusionAuditJob {
  std::string tracker, robot, inclinometer, setup;  // inclinometer: optional
  std::string json, output;                         // empty: not written
  double false_alarm = 0.01;
};
// out.print receives the report text, out.progress (may be empty) the audits' progress lines.
void RunFusionAuditJob(const FusionAuditJob& job, const JobOutput& out);

}  // namespace mcms
