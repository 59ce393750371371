// The inclinometer audit (audit/inclinometer_audit.h) on the logs `mcms fuse` reads: the
// tracker's target poses become flange-orientation references through the setup's cell
// (T_base_rig with its covariance, T_flange_target), the inclinometer log's readings are
// the measurements, and the robot's joint log (when given) the shape of the motion between
// the tracker's frames (the whole `mcms audit fusion` job: jobs/fusion_audit_job.h).
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


// The robot-audit log of a tracker log against a joint log: every tracked frame inside the
// joint log's time span, with the joints interpolated at its time and their velocities
// (central differences over 20 ms). InputError naming both logs when fewer than
// kMinRobotMeasurements frames overlap.
RobotLog TrackerAgainstJoints(const TrackerLog& tracker, const JointLog& joints, const std::string& tracker_name,
                              const std::string& joints_name);

}  // namespace mcms
