// The inclinometer audit (calib/inclinometer_audit.h) on the logs `mcms fuse` reads: the
// tracker's target poses become flange-orientation references through the setup's cell
// (T_base_rig with its covariance, T_flange_target), the inclinometer log's readings are
// the measurements, and the robot's joint log (when given) the shape of the motion between
// the tracker's frames. Used by `mcms audit fusion`; one place for the conversion.
#pragma once

#include "calib/inclinometer_audit.h"
#include "fusion/sensor_logs.h"

namespace mcms {

// InputError (from the audit) when the logs do not overlap in time or are unusable.
InclinometerAuditResult AuditInclinometerLogs(const FusionSetup& setup, const TrackerLog& tracker,
                                              const InclinometerLog& inclinometer, const JointLog* motion,
                                              const InclinometerAuditOptions& options = {});

}  // namespace mcms
