// The inclinometer audit (audit/inclinometer_audit.h) on the logs `mcms fuse` reads: the
// tracker's target poses become flange-orientation references through the setup's cell
// (T_base_rig with its covariance, T_flange_target), the inclinometer log's readings are
// the measurements, and the robot's joint log (when given) the shape of the motion between
// the tracker's frames. And the whole `mcms audit fusion` job.
#pragma once

#include <functional>
#include <string>

#include "audit/inclinometer_audit.h"
#include "audit/robot_audit.h"
#include "fusion/sensor_logs.h"

namespace mcms {

// InputError (from the audit) when the logs do not overlap in time or are unusable.
InclinometerAuditResult AuditInclinometerLogs(const FusionSetup& setup, const TrackerLog& tracker,
                                              const InclinometerLog& inclinometer, const JointLog* motion,
                                              const InclinometerAuditOptions& options = {});

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
// `print` receives the report text; `progress` (may be empty) the audits' progress lines.
void RunFusionAuditJob(const FusionAuditJob& job, const std::function<void(const std::string&)>& print,
                       const std::function<void(const std::string&)>& progress = {});

// The robot-audit log of a tracker log against a joint log: every tracked frame inside the
// joint log's time span, with the joints interpolated at its time and their velocities
// (central differences over 20 ms). InputError naming both logs when fewer than
// kMinRobotMeasurements frames overlap.
RobotLog TrackerAgainstJoints(const TrackerLog& tracker, const JointLog& joints, const std::string& tracker_name,
                              const std::string& joints_name);

}  // namespace mcms
