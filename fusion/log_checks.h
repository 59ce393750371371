// Cross-checks of one sensor log against another before anything is fused or audited:
// mistakes a user makes in writing a file (a quaternion order, a unit, two columns
// exchanged, a mount in the setup) that would otherwise surface as hundreds of sigma of
// misfit blamed on a sensor, or as a sensor silently left out. Each throws InputError
// naming the file (or the setup's key) and the likely mistake; each stays silent when the
// logs do not overlap enough to judge. Used by `mcms fuse` and `mcms audit fusion`.
#pragma once

#include "fusion/sensor_logs.h"

namespace mcms {

// The tracker's flange orientations (through the setup's T_base_rig and T_flange_target)
// against the robot's (its joints interpolated at the tracker's times): a median
// disagreement beyond 10 deg that the same four numbers read scalar last (x, y, z, w under
// qw..qz) bring within a quarter of it and under 5 deg is named as the quaternion order.
void CheckTrackerAgainstJoints(const FusionSetup& setup, const TrackerLog& tracker, const JointLog& joints);

// The inclinometer's readings against the tilts the tracker's flange orientations predict
// through the setup's inclinometer (each reading paired with the tracked frame nearest in
// time, within 0.5 s): radians under _deg headers or degrees under _rad (slope 1/57.3 or
// 57.3), another unit (spread ratio beyond 30 %), tilt_x and tilt_y exchanged, and a mount
// in the setup (inclinometer.quaternion_wxyz) that tilts the sensor beyond its range at
// most of the tracked orientations while its readings stay within it.
void CheckInclinometerAgainstTracker(const FusionSetup& setup, const TrackerLog& tracker,
                                     const InclinometerLog& inclinometer);

}  // namespace mcms
