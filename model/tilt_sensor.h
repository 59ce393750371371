// Accelerometers at rest read as tilt sensors on a robot's links (issue 52): the Hilti
// construction robot's two ADXL355, one on the rigid base, one at the tip of its telescopic
// column. At rest an accelerometer reads the specific force, g upward, in its own frame; a
// change of that reading is its link's change of tilt (a turn about gravity is not seen).
// The rig's inclinometer on a flange (model/inclinometer.h) is the same sensor read as two
// angles.
//
// The measured tilt as a correction of the chain's forward kinematics: a link that bends
// (a column under its arm's moment) or a base that settles is measured, not modelled. Each
// sensor's link (model/urdf.h MountOnChain) is turned by its measured tilt since a
// reference (a station's stationing rows, where the instrument placed the robot) about its
// frame's origin, relative to the tilt measured below it; what rides on it follows.
#pragma once

#include <string>
#include <vector>

#include "core/pose_math.h"
#include "model/urdf.h"

namespace mcms {

// InputError naming `where` when a reading's norm is not g within 10 %: not m/s^2 (in g,
// in mg?) or not at rest.
void CheckAccelerometerReading(const Vec3& a, const std::string& where);

// The sensor frame's rotation D since reference reading a0: the least rotation with
// D a = a0 (both specific forces in the sensor's frame, m/s^2).
Mat3 TiltSince(const Vec3& a0, const Vec3& a);

struct MeasuredTilt {
  LinkMount mount;
  Mat3 D = Mat3::Identity();  // TiltSince, in the sensor's frame
};

// The rigid motion C (base frame) the measured tilts give everything above every sensor:
// with the chain's link frames `frames` (RobotModel::LinkFrames), each sensor's rotation
// taken to the base frame, A_j; applied from the farthest sensor in, p <- o_j + A_j
// A_{j-1}^T (p - o_j), o_j its frame's origin (A_{-1} = I). A point p of the tool moves to
// C p, the tool's pose X to C X.
Pose TiltCorrection(const std::vector<Pose>& frames, std::vector<MeasuredTilt> tilts);

}  // namespace mcms
