// The one fusion path: time-stamped sensor samples with covariance in, fused flange poses
// T_base_flange with consistency flags out, by MOIFA and by the multi-sensor Kalman filter.
// `mcms fuse` (fusion/log_fusion.h), the demo's lab experiment (jobs/lab_experiment.h)
// and the ISO 9283 experiment (jobs/iso9283_experiment.h, FuseEpoch) all run it.
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
//  robot         FK of the joint readings, covariance J Q_enc J^T (encoder noise,
//                model/robot_model.h) plus the setup's absolute-accuracy covariance.
//  inclinometer  readings averaged; n readings carry n times the information of one
//                (independent noise). A rank-2 orientation constraint (no yaw), linearized at
//                the fused orientation of the other sensors and relinearized once at the
//                result (FuseEpoch). Skipped when the estimated orientation is outside the
//                sensor's range.
//
// Two ways to cut the streams into fused samples:
//  per camera frame (no windows): MOIFA of the frame's camera pose, the joints linearly
//     interpolated at its time (absent outside the joint log) and the inclinometer readings
//     within +-period/2; one Kalman filter over the time-merged stream of all samples
//     (robot and inclinometer at their own stamps, camera last among equal stamps), started
//     at the first camera or robot sample, reported after the update at each camera frame.
//     The KF row's p-value tests the innovations of all updates since the previous row (sum
//     of NIS against the sum of their dof); a sensor is flagged when its own summed NIS
//     fails at the setup's significance.
//  per window [start_s, end_s) (the robot stands still in each, e.g. the demo's dwells):
//     one row per window, `frame` = the window's index, time_s = its end. MOIFA of the
//     window's camera frames fused (a minimum-variance average), the mean joint reading (its
//     encoder covariance divided by the number of readings; the accuracy covariance is not:
//     it is one systematic error) and the mean inclinometer reading; the row exists when a
//     camera frame or a joint reading lies in the window. The KF restarts in every window
//     at its first camera frame (samples before it are dropped, those at its time stamp
//     follow it; no row without a camera frame) and is reported at the window's end. As
//     the robot's kinematic error is the same at every reading of a window, the accuracy
//     covariance of each joint reading is inflated by the number of readings in the window
//     so that the window's readings together carry it once. With PoseKalmanOptions' process noise and velocity prior near zero
//     (setup `kalman`) the KF then is the static filter of a standing robot.
//
// Faults (issue 14). MOIFA: leave-one-out exclusion when an epoch's test fails (FuseEpoch).
// KF: every update is gated on its innovation (NIS against the chi-square quantile); a
// rejected update is skipped and recorded in the row (`excluded`, `fault`). The gate is the
// setup's kalman.nis_gate_probability when given (> 0), else 1 - significance / n with n the
// mean number of updates per row (all sensors), so that a clean row loses an update with
// probability about the significance (Bonferroni). When two sensors are each rejected at least
// twice in a row with no update accepted in between, the filter's state is the outlier (e.g.
// it started on a faulty sample): it restarts at the current measurement. Inclinometer
// readings beyond the sensor's range (BeyondRange) are rejected by both methods.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "fusion/consistency.h"
#include "fusion/kalman.h"
#include "fusion/moifa.h"
#include "fusion/sensor_logs.h"
#include "model/flange_pose.h"

namespace mcms {

struct SensorLogs {
  TrackerLog tracker;
  std::optional<JointLog> robot;
  std::optional<InclinometerLog> inclinometer;
};

// InputError when neither robot nor inclinometer log is given, or when a given log's time
// range does not overlap the tracker's; the message names both files and their ranges.
void CheckTimeOverlap(const SensorLogs& logs);

// The sensors, in the order of the KF's tie-break at equal time stamps.
enum class StreamSensor { kRobot = 0, kInclinometer = 1, kCamera = 2 };
const char* ToString(StreamSensor k);

// The camera's measurement of T_base_flange with its covariance: model/flange_pose.h with
// the setup's cell geometry (see the header comment).
PoseWithCovariance CameraFlangePose(const Pose& T_rig_target, const Mat6& covariance_rig, const FusionSetup& setup);
// FK at q with encoder covariance times encoder_scale plus the absolute-accuracy
// covariance times accuracy_scale. InputError when the result is singular (a robot file
// without encoder sigmas and no robot_accuracy in the setup).
PoseWithCovariance RobotFlangePose(const Eigen::VectorXd& q, const FusionSetup& setup, double encoder_scale = 1.0,
                                   double accuracy_scale = 1.0);

// A mean inclinometer reading and the model with the noise of that mean.
struct TiltReading {
  Vec2 reading = Vec2::Zero();  // rad, bias included
  Inclinometer model;
};

// MOIFA at one instant: the full-pose measurements (at least one; all in one frame whose
// -z is gravity) fused, the inclinometer's constraint added when the fused orientation is in
// its range (linearized there, then once more at the result), and the chi-square test of all
// that were used. InputError when `poses` is empty.
//
// Faults. When that test fails (p < significance), each sensor is left out in turn
// (leave-one-out) and the rest fused and tested again. The suspects are the sensors whose
// removal makes the rest consistent; among them, those flagged by their own statistic (their
// residual against the others, SensorConsistency) when there are any.
//  - one suspect: it is excluded, the row is the fusion of the rest with its covariance;
//  - several (the disagreement lies along directions only they observe, e.g. a position
//    jump between camera and robot that the inclinometer cannot see): the fault cannot be
//    attributed. The pose stays the fusion of all, its covariance is widened to the union
//    of the hypotheses "suspect i is wrong" (each: the rest's covariance plus the outer
//    product of the rest's offset from the pose), so it covers whichever suspect is wrong;
//  - none (no single removal explains it, e.g. two faulty sensors): the covariance is
//    scaled by chi2 / dof of the failed test.
// `excluded` and `fault` say what was done. Without a failed test nothing changes, so clean
// data is affected only in the rows whose test fails by chance, at the significance level.
struct EpochFusion {
  FusedPose fused;                            // weights in the order of `measurements`
  std::vector<PoseMeasurement> measurements;  // the sensors fused: poses, then the inclinometer if used
  ConsistencyReport consistency;              // of every sensor, before any exclusion
  std::vector<std::string> excluded;          // sensors left out of `fused`
  std::string fault;                          // why, or how the covariance was widened; empty if consistent
};
// exclude_faults false: no leave-one-out, the fusion of all as given.
EpochFusion FuseEpoch(const std::vector<PoseMeasurement>& poses, const std::optional<TiltReading>& tilt,
                      const ConsistencyOptions& options, bool exclude_faults = true);

// A covariance no smaller than either (A and B symmetric positive definite): both made
// diagonal by one basis, the larger variance kept along each of its directions.
Mat6 CovarianceUnion(const Mat6& A, const Mat6& B);

// Whether an inclinometer reading (bias included) is one the sensor cannot give: beyond its
// range on either axis by more than 5 sigma. Such readings are rejected before fusion.
bool BeyondRange(const Vec2& reading, const Inclinometer& model);

enum class FusionMethod { kMoifa, kKalman };
const char* ToString(FusionMethod m);

struct SensorStatistic {
  std::string name;
  double chi2 = 0.0;  // MOIFA: the sensor's share of the residual; KF: its summed NIS
  int dof = 0;
};

struct FusedSample {
  int frame = 0;                      // camera frame, or window index
  double time_s = 0.0;
  FusionMethod method = FusionMethod::kMoifa;
  Pose T_base_flange;
  Mat6 covariance = Mat6::Zero();     // [dtheta; dp], base frame
  std::vector<std::string> sensors;   // camera, robot, inclinometer: those that contributed
  int dof = 0;                        // of the consistency test
  double p_value = 1.0;               // 1 when nothing can be compared (dof 0)
  std::vector<std::string> flagged;   // sensors whose p-value is below the significance
  std::vector<SensorStatistic> statistics;  // per sensor in `sensors`
  // Sensors (or some of their samples) left out of this row as inconsistent: MOIFA's
  // leave-one-out exclusion (EpochFusion), the KF's gated updates, inclinometer readings
  // beyond the sensor's range. `fault` says which, why, and what was done.
  std::vector<std::string> excluded;
  std::string fault;
};

// A time interval [start_s, end_s) over which the robot stands still.
struct FusionWindow {
  double start_s = 0.0, end_s = 0.0;
};

// What each sensor says over one window (see the header comment); absent when it has no
// sample there.
struct WindowMeasurements {
  std::optional<PoseWithCovariance> camera;  // the window's camera frames fused
  int camera_frames = 0;
  std::optional<PoseWithCovariance> robot;   // FK of the mean joint reading
  int robot_readings = 0;
  std::optional<TiltReading> inclinometer;   // the mean reading
  int inclinometer_readings = 0;             // used in the mean
  int inclinometer_beyond_range = 0;         // rejected (BeyondRange)
  double inclinometer_worst_rad = 0.0;       // largest |reading - bias| among them
};
WindowMeasurements MeasureWindow(const SensorLogs& logs, const FusionSetup& setup, const FusionWindow& window);

// InputError naming the window when it is empty or not finite, or when windows overlap or
// are out of time order.
void CheckWindows(const std::vector<FusionWindow>& windows);

struct StreamFusionOptions {
  bool moifa = true, kalman = true;
  std::vector<FusionWindow> windows;  // empty: one sample per camera frame
  // At least one method; the windows' own check is CheckWindows (against the logs).
  bool IsValid(std::string* why) const;
};

// CheckTimeOverlap and CheckWindows first; InputError on inconsistent inputs.
std::vector<FusedSample> FuseMoifa(const SensorLogs& logs, const FusionSetup& setup,
                                   const std::vector<FusionWindow>& windows = {});
std::vector<FusedSample> FuseKalman(const SensorLogs& logs, const FusionSetup& setup,
                                    const std::vector<FusionWindow>& windows = {});
// The methods asked for, in time order, MOIFA before KF at equal times.
std::vector<FusedSample> FuseStream(const SensorLogs& logs, const FusionSetup& setup,
                                    const StreamFusionOptions& options);

}  // namespace mcms
