// The user's own sensor logs for `mcms fuse`: the tracker's pose CSV, the robot's joint
// log, the inclinometer's log, and the setup file that ties their frames together.
// Every reader validates strictly and throws mcms::InputError naming the file and the line
// (and the column, joint or key) of the first problem: missing columns, empty files, values
// that are not finite numbers, time stamps that do not strictly increase, joints outside
// the robot's limits, covariances that are not symmetric positive definite.
//
// Formats (CSV: one header row; blank lines and lines starting with '#' are ignored).
//
//  Tracker poses (tracking/sequence.h WritePoseCsv, what `mcms track` writes):
//    frame,time_s,status,...,x_m,y_m,z_m,qw,qx,qy,qz,...,cov_<a>_<b> (a, b in rx,ry,rz,px,py,pz)
//    The pose is T_rig_target; the 6x6 covariance is in the [dtheta; dp] layout of
//    docs/conventions.md, rig frame, rad^2 / rad*m / m^2. Other columns are ignored. Rows with
//    status `lost` are skipped; `ok` and `degraded` rows are used; time_s strictly increases
//    over all rows. The quaternion must have unit norm (to 1e-6) and the covariance must be
//    symmetric (to 1e-9 relative) and positive definite.
//
//  Robot joints:  time_s,q1_<unit>,...,qN_<unit>, or the robot's joint names
//    N is the robot's actuated joint count (a mimic joint follows its driver); the unit per
//    column is rad or deg for revolute joints and m for prismatic ones, read by the one
//    joint-column reader of every robot log (model/robot_measurements.h FindJointColumns).
//    Every reading must lie within the joint limits.
//
//  Inclinometer:  time_s,tilt_x_<unit>,tilt_y_<unit>   (unit rad or deg)
//    The two readings of model/inclinometer.h: the angle of the sensor's x (y) axis above
//    the horizontal plane, bias included (the setup's bias is subtracted by the model).
//
//  Setup (YAML; every key carries its unit; unknown keys are errors):
//    robot: kr5.yaml                  # optional; relative to the setup file; default
//                                     # RobotModel::Default() (KUKA KR 5 arc). The fusion
//                                     # estimates the flange: a DH table's last frame (its
//                                     # tool ignored), a URDF's tip link (the tool-like leaf
//                                     # through the fixed joints after the last moving one).
//    tip_link: tool0                  # optional, a URDF robot's chain (as --tip-link and
//    base_link: base_link             # --base-link of the robot commands)
//    T_base_rig:                      # the rig (camera) frame registered in the robot base
//      translation_m: [x, y, z]
//      quaternion_wxyz: [w, x, y, z]
//      sigma_rotation_rad: 1e-5       # optional (or _deg): uncertainty of this registration,
//      sigma_translation_m: 2e-5      # optional  per axis, base frame; default 0 (exact)
//    T_flange_target:                 # the five-ball target on the flange
//      translation_m: [x, y, z]
//      quaternion_wxyz: [w, x, y, z]
//    inclinometer:                    # optional block; defaults of model/inclinometer.h
//      quaternion_wxyz: [w, x, y, z]  # R_flange_incl, sensor frame to flange frame
//      bias_rad: [bx, by]             # or bias_deg
//      sigma_rad: 1.7e-4              # or sigma_deg: per-axis reading noise
//      period_s: 0.02                 # time between readings
//      range_deg: 30                  # or range_rad: saturation
//    robot_accuracy:                  # optional; absolute accuracy added to encoder noise
//      position_sigma_m: [sx, sy, sz] # base frame
//      orientation_sigma_rad: 1e-4    # or orientation_sigma_deg; per axis
//      covariance: [36 numbers]       # instead of the sigmas: the full 6x6 [dtheta; dp]
//                                     # covariance, row-major, rad^2 / rad m / m^2, base frame
//    kalman:                          # optional: PoseKalmanOptions (fusion/kalman.h)
//      angular_acceleration_psd: 1e-2 # rad^2/s^3
//      linear_acceleration_psd: 1e-2  # m^2/s^3
//      initial_angular_velocity_sigma_rad_s: 0.5  # prior sigma of the velocities at the start
//      initial_linear_velocity_sigma_m_s: 0.5
//      nis_gate_probability: 0        # per-update gate; 0 (default): 1 - significance / (updates
//                                     # per row), fusion/stream_fusion.h "Faults"
//    consistency_significance: 0.01   # optional: flag a sensor when its p-value is below; a
//                                     # MOIFA row whose test fails leaves the odd sensor out
//    Inclinometer readings beyond range_deg (+5 sigma) are rejected before fusion.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "core/pose_math.h"
#include "fusion/kalman.h"

namespace mcms {

struct TrackerSample {
  int frame = 0;
  double time_s = 0.0;
  int line = 0;                     // line in the file, for messages
  Pose T_rig_target;
  Mat6 covariance = Mat6::Zero();   // [dtheta; dp], rig frame
};

struct TrackerLog {
  std::filesystem::path source;
  std::vector<TrackerSample> samples;  // tracked rows only (lost rows skipped), time order
  double first_time_s = 0.0, last_time_s = 0.0;  // over all rows, lost ones included
  int lost_rows = 0;
};

struct JointSample {
  double time_s = 0.0;
  int line = 0;
  Eigen::VectorXd q;  // SI (rad, m)
};

struct JointLog {
  std::filesystem::path source;
  std::vector<JointSample> samples;  // strictly increasing time

  // Joint values linearly interpolated at t, or false when t lies outside
  // [first, last] sample time (the robot is then absent at t).
  bool Interpolate(double t, Eigen::VectorXd* q) const;
};

struct InclinometerSample {
  double time_s = 0.0;
  int line = 0;
  Vec2 reading = Vec2::Zero();  // rad, bias included
};

struct InclinometerLog {
  std::filesystem::path source;
  std::vector<InclinometerSample> samples;  // strictly increasing time
};

struct FusionSetup {
  std::filesystem::path source;
  RobotModel robot;  // ends at the flange: a DH table's last frame (its tool reset), a URDF's tip link
  Pose T_base_rig;
  Mat6 T_base_rig_covariance = Mat6::Zero();  // [dtheta; dp], base frame
  Pose T_flange_target;
  Inclinometer inclinometer;
  Mat6 robot_accuracy_covariance = Mat6::Zero();  // [dtheta; dp], base frame, diagonal
  PoseKalmanOptions kalman;
  double consistency_significance = 0.01;
  // Leave inconsistent sensors and samples out (fusion/stream_fusion.h, "Faults"). false
  // fuses every sample as given and only flags (the behaviour before issue 14), for
  // comparisons; not in the setup file.
  bool exclude_faults = true;
};

// The readers. InputError naming the file and line on any problem listed above.
TrackerLog ReadTrackerLog(const std::filesystem::path& path);
JointLog ReadJointLog(const std::filesystem::path& path, const RobotModel& robot);
InclinometerLog ReadInclinometerLog(const std::filesystem::path& path);
FusionSetup ReadFusionSetup(const std::filesystem::path& path);
// The same from text; `source` names it in messages and relative robot paths resolve
// against `base_dir`.
FusionSetup ParseFusionSetup(const std::string& yaml_text, const std::filesystem::path& source,
                             const std::filesystem::path& base_dir);

}  // namespace mcms
