// `mcms fuse` on files: the user's recorded sensor logs (formats in fusion/sensor_logs.h)
// read, checked and fused by the one fusion path (fusion/stream_fusion.h), and the fused
// poses written. Also the writers of the logs the fusion reads (robot joints, inclinometer,
// setup, windows), so that a simulation (the demo) can write the very files it fuses and
// `mcms fuse` on them reproduces its numbers.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "fusion/stream_fusion.h"

namespace mcms {

// Fusion windows (see fusion/stream_fusion.h), CSV: start_s,end_s, one window [start_s,
// end_s) per row, in time order, not overlapping. InputError naming the file and line.
std::vector<FusionWindow> ReadFusionWindows(const std::filesystem::path& path);
void WriteFusionWindows(const std::filesystem::path& path, const std::vector<FusionWindow>& windows);

// Writers of the formats fusion/sensor_logs.h reads, at full precision (%.17g), atomically.
// Joint log: time_s,q1_rad,...,qN_rad (every joint written in rad or m as `robot` says).
void WriteJointLog(const std::filesystem::path& path, const JointLog& log, const RobotModel& robot);
// Inclinometer log: time_s,tilt_x_rad,tilt_y_rad.
void WriteInclinometerLog(const std::filesystem::path& path, const InclinometerLog& log);
// The setup YAML. `robot_file` is written as the setup's robot (relative to the setup's
// folder, or absolute); empty writes none, which the reader takes as RobotModel::Default():
// the caller's setup.robot must then be that robot. The robot's accuracy is written as its
// full covariance.
void WriteFusionSetup(const std::filesystem::path& path, const FusionSetup& setup, const std::string& robot_file = "");

struct FuseFilesRequest {
  std::filesystem::path tracker, robot, inclinometer, setup;  // robot, inclinometer: empty when absent
  std::filesystem::path windows;                             // empty: one sample per camera frame
  bool moifa = true, kalman = true;
  std::filesystem::path output;                              // fused pose CSV; empty: not written
};

struct FuseFilesResult {
  SensorLogs logs;
  FusionSetup setup;
  std::vector<FusionWindow> windows;
  std::vector<FusedSample> rows;  // FuseStream's order
  // Input rows left out before fusion, one line each naming the file, line and value
  // (an inclinometer reading beyond the sensor's range plus 5 sigma, which a saturating
  // sensor cannot produce); the rest is fused.
  std::vector<std::string> dropped;
};

// Reads and checks every input before anything is written (InputError naming the file),
// fuses them (FuseStream) and writes `output` when given.
FuseFilesResult FuseLogFiles(const FuseFilesRequest& request);

// frame,time_s,method,x_m,y_m,z_m,qw,qx,qy,qz,sensors,dof,p_value,flagged,excluded,fault,
// then the 36 covariance entries cov_<a>_<b>, a, b in rx,ry,rz,px,py,pz (as the tracker's
// CSV). The pose is T_base_flange; sensors (those fused), flagged and excluded (left out as
// inconsistent, FusedSample) are ';'-separated names (may be empty); fault is a quoted text
// saying what was excluded and why (empty when nothing was). dof and p_value are the
// consistency test of every sensor before exclusion. With windows, frame is the window's index and time_s its end. Written atomically.
void WriteFusedPoseCsv(const std::filesystem::path& path, const std::vector<FusedSample>& samples);

}  // namespace mcms
