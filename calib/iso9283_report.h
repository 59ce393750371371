// ISO 9283 characteristics from files of measured poses, as `mcms iso9283` reads them:
// the table and its CSV (calib/iso9283.h computes the characteristics).
//
// POSES: a pose CSV with a header row and one row per attained pose:
//   pose,cycle,cmd_x_m,cmd_y_m,cmd_z_m,cmd_qw,cmd_qx,cmd_qy,cmd_qz,x_m,y_m,z_m,qw,qx,qy,qz
// `pose` names the commanded pose (P1..P5 in the standard), `cycle` the repetition; the
// commanded columns must be the same on every row of one pose; quaternions are w,x,y,z,
// unit norm; both poses in the base (or measuring) frame, metres.
// PATH (optional):  run,x_m,y_m,z_m   with run = "commanded" for the commanded path (its
// rows, in order, are the calculation points) and any other label for each attained run
// (rows in time order).
// Output: per pose AP, RP with their orientation parts; per consecutive pose pair (in order
// of first appearance) AD, RD over the cycles both poses have; AT, RT for the path. Lengths
// in mm, angles in degrees.
#pragma once

#include <filesystem>
#include <string>

namespace mcms {

struct Iso9283Report {
  std::string table;  // for people
  std::string csv;    // kind,name,n,AP_mm,...,AD_mm,RD_mm,AT_mm,RT_mm
};

// InputError naming the file and line on bad input (a quaternion not of unit norm, a pose
// whose commanded pose changes, a cycle given twice, fewer than 2 cycles, no commanded path).
// `path_file` empty: no path characteristics.
Iso9283Report EvaluateIso9283Files(const std::filesystem::path& poses_file, const std::filesystem::path& path_file);

}  // namespace mcms
