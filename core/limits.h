// Limits on the numbers an option or a file gives, checked before any work starts: a
// number past its limit is an InputError that names the option or key, the value and the
// limit (never a crash, an allocation failure or hours of work later).
#pragma once

#include <cstddef>

#include <string>

namespace mcms {

// Worker threads: 0 means the machine's cores where an option allows it.
constexpr int kMaxThreads = 256;
// InputError unless 0 <= n <= kMaxThreads (1 <= n when `zero_means_all_cores` is false).
void CheckThreads(int n, const std::string& what, bool zero_means_all_cores = true);
// n, or the machine's cores (at least 1) for 0.
int ThreadsToUse(int n);

// The largest level of a stored image (16 bits, DN): a noise or threshold beyond it is no
// level an image can hold.
constexpr double kMaxImageDn = 65535.0;

// Pixels of one rendered image (a 200 MP camera; each costs 4 bytes or more in memory).
constexpr double kMaxRenderPixels = 2e8;

// Lengths of a robot (DH a and d, URDF origins, the tool, registration guesses): no robot
// or measuring volume is larger (m).
constexpr double kMaxRobotLengthM = 1000.0;
// A tool's offset from the flange (m): an end effector, a measuring bar or a marker cluster
// reaches a few metres; beyond this the number is in another unit (mm?) or not a tool.
constexpr double kMaxToolOffsetM = 10.0;
// An encoder's noise (rad or m): beyond it a reading says nothing about the joint.
constexpr double kMaxEncoderSigma = 0.1;
// A link, a tool or a payload (kg).
constexpr double kMaxMassKg = 1e5;
// Temperatures a robot or a camera works at (deg C).
constexpr double kMinTemperatureC = -100.0, kMaxTemperatureC = 300.0;
// How far a camera rig measures, and how far from a robot it stands (m): a tracker pose or
// a rig registration farther is a length in mm read as metres, not a measurement.
constexpr double kMaxRigRangeM = 100.0;
// What a compressed input may inflate to, in all (a zip inside a .cameramodel's
// optimization_inputs): a large real calibration's arrays are some 50 MB; a deflate bomb
// states gigabytes in a few MB.
constexpr size_t kMaxInflatedBytes = size_t{1} << 30;
// What an HTML report embeds in all (figures and text files): beyond it the rest are
// listed, not embedded, so the page stays one a browser opens.
constexpr size_t kMaxEmbeddedBytes = size_t{64} << 20;
// What the robot audit's linearised problem may take (its Jacobian and every fold's normal
// matrices): a 7-joint arm with 1000 poses needs some 300 MB; a 50-joint chain's catalog
// would need 15 GB.
constexpr size_t kMaxAuditBytes = size_t{2} << 30;
// Measurements the robot audit takes from one log: 50,000 rows of a 6-joint arm take some
// 2 minutes; a continuously logged trajectory of 400,000 rows is thinned first.
constexpr int kMaxAuditRows = 50000;
// Links in a robot's URDF tree below its base, and movable joints in its chain (issue 53):
// the largest real robots have some hundreds of links (a humanoid with hands) and tens of
// joints; a file beyond is refused by name before any walk of the tree or fit is built.
constexpr int kMaxRobotLinks = 10000;
constexpr int kMaxRobotJoints = 64;
// InputError unless value is finite and |value| <= limit: "<what> = <value> <unit>: ...".
// The likely unit of lengths that came out `ratio` times as large as expected, where they
// should be metres: " (millimetres under metre headers?)", " (centimetres?)",
// " (inches?)", " (kilometres?)"; "" when none fits (within 5 %, 0.05 decades).
std::string LengthUnitHint(double ratio);

void CheckMagnitude(double value, double limit, const std::string& what, const std::string& unit);

// A camera's name names its image folder (and a part of output file names): at most this
// many characters (file systems allow 255 bytes per name).
constexpr size_t kMaxCameraNameLength = 100;
// A calibration board's square (or tag): beyond this many metres it is a unit mistake.
constexpr double kMaxBoardSquareM = 2.0;

}  // namespace mcms
