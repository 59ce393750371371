// Fusion of the user's recorded sensor logs (fusion/sensor_logs.h) into the flange pose
// T_base_flange in the robot base frame, at every tracked camera frame.
//
// Each sensor in the base frame:
//  camera        T_base_flange = T_base_rig * T_rig_target * T_flange_target^-1. Its
//                covariance is carried through the fixed transforms in the [dtheta; dp]
//                layout: with a = R_base_rig R_rig_target p_target_flange (the base-frame
//                lever from the target origin to the flange origin),
//                    dtheta_base = R_br dtheta_rig,   dp_base = R_br dp_rig - [a]x R_br dtheta_rig.
//                The registration's own uncertainty (setup T_base_rig sigmas) adds
//                J C_base_rig J^T with J = [I 0; -[p_base_flange - p_base_rig]x I]. It is a
//                fixed error shared by every frame; treating it as independent per frame is
//                right for one frame's uncertainty but optimistic for averages over frames.
//  robot         FK of the joint readings linearly interpolated at the frame time (absent
//                when the time lies outside the joint log), covariance J Q_enc J^T (encoder
//                noise, model/robot_model.h) plus the setup's absolute-accuracy covariance.
//  inclinometer  the readings within +-period/2 of the frame time, averaged; n readings
//                carry n times the information of one (independent noise). A rank-2
//                orientation constraint (no yaw), linearized at the fused orientation of the
//                other sensors and relinearized once at the result. Skipped when the
//                estimated orientation is outside the sensor's range.
//
// (1) MOIFA (fusion/moifa.h, FusePoses) of the sensors present at each frame, with the
//     chi-square consistency check (fusion/consistency.h) and the sensors it flags.
// (2) KF: one PoseKalmanFilter (fusion/kalman.h) over the time-merged stream of all
//     sensor samples (robot and inclinometer at their own time stamps, camera last among
//     equal stamps), started at the first camera or robot sample; its causal estimate is
//     reported after the update at each camera frame. The row's p-value tests the
//     innovations of all updates since the previous row (sum of NIS against the sum of
//     their dof), and a sensor is flagged when its own summed NIS fails at the setup's
//     significance.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "model/flange_pose.h"
#include "fusion/sensor_logs.h"

namespace mcms {

struct SensorLogs {
  TrackerLog tracker;
  std::optional<JointLog> robot;
  std::optional<InclinometerLog> inclinometer;
};

// InputError when neither robot nor inclinometer log is given, or when a given log's time
// range does not overlap the tracker's; the message names both files and their ranges.
void CheckTimeOverlap(const SensorLogs& logs);

// The camera's measurement of T_base_flange with its covariance: model/flange_pose.h with
// the setup's cell geometry.
PoseWithCovariance CameraFlangePose(const Pose& T_rig_target, const Mat6& covariance_rig, const FusionSetup& setup);
// FK at q with encoder and absolute-accuracy covariance. InputError when that covariance is
// singular (a robot file without encoder sigmas and no robot_accuracy in the setup).
PoseWithCovariance RobotFlangePose(const Eigen::VectorXd& q, const FusionSetup& setup);

enum class FusionMethod { kMoifa, kKalman };
const char* ToString(FusionMethod m);

struct FusedSample {
  int frame = 0;
  double time_s = 0.0;
  FusionMethod method = FusionMethod::kMoifa;
  Pose T_base_flange;
  Mat6 covariance = Mat6::Zero();     // [dtheta; dp], base frame
  std::vector<std::string> sensors;   // camera, robot, inclinometer: those that contributed
  int dof = 0;                        // of the consistency test
  double p_value = 1.0;               // 1 when nothing can be compared (dof 0)
  std::vector<std::string> flagged;   // sensors whose p-value is below the significance
};

// One row per tracked frame. CheckTimeOverlap first; InputError on inconsistent inputs.
std::vector<FusedSample> FuseLogsMoifa(const SensorLogs& logs, const FusionSetup& setup);
std::vector<FusedSample> FuseLogsKalman(const SensorLogs& logs, const FusionSetup& setup);

// frame,time_s,method,x_m,y_m,z_m,qw,qx,qy,qz,sensors,dof,p_value,flagged, then the 36
// covariance entries cov_<a>_<b>, a, b in rx,ry,rz,px,py,pz (as the tracker's CSV). The
// pose is T_base_flange; sensors and flagged are ';'-separated names (flagged may be
// empty). Written atomically.
void WriteFusedPoseCsv(const std::filesystem::path& path, const std::vector<FusedSample>& samples);

}  // namespace mcms
