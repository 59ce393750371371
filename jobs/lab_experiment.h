// The paper's lab experiment (section 3.4) run on the forward model: each sensor alone,
// MOIFA over the three sensors at every point, and the multi-sensor Kalman filter over
// the asynchronous streams, all against the truth, reported by the paper's three-sigma
// rule and as RMS, with the errors split into tilt (roll/pitch, what an inclinometer
// sees) and yaw (what it cannot see).
#pragma once

#include <string>
#include <vector>

#include "fusion/stream_fusion.h"
#include "synthetic/lab_scenario.h"
#include "tracking/tracker.h"

namespace mcms {

// One estimate of T_base_flange at one point and its error against the truth.
struct PointEstimate {
  bool valid = false;
  Pose T;
  Mat6 cov = Mat6::Zero();
  Vec6 error = Vec6::Zero();  // BoxMinus(estimate, truth): [dtheta; dp]
  double nees = 0;
};

struct LabMethodSummary {
  std::string name;
  int points = 0;
  double position_rms_m = 0, position_3sigma_m = 0;  // 3-sigma rule: mean + 3 std of |dp|
  double tilt_rms_rad = 0, yaw_rms_rad = 0;
  double mean_nees = 0;  // against the method's own covariance (6 dof; inclinometer-only excluded)
  double nees_band_lo = 0, nees_band_hi = 0;
};

struct LabResult {
  // Per point, per method: camera, robot, moifa (camera + robot + inclinometer), kf.
  std::vector<std::string> methods;
  std::vector<std::vector<PointEstimate>> estimates;  // [method][point]
  std::vector<Pose> truth;                            // T_base_flange per point
  std::vector<LabMethodSummary> summary;
  std::vector<double> incl_tilt_error_rad;            // inclinometer alone: |tilt error| per point
  std::vector<double> kf_nis_mean;                    // mean NIS per dof: camera, robot, inclinometer
};

struct LabExperimentOptions {
  // The KF's process noise while the robot dwells (see fusion/kalman.h). Over a 7 s dwell
  // a white acceleration of density q moves the pose by sqrt(q t^3 / 3): 1e-16 m^2/s^3 is
  // 0.1 um, a robot standing still; 1e-12 would already be 10 um, as large as the camera's
  // error, and the filter would discount its own past measurements accordingly.
  double kf_angular_psd = 1e-16, kf_linear_psd = 1e-16;
  // False with the reason (a process noise that is negative or not finite).
  bool IsValid(std::string* why) const;
};

// The experiment runs the one fusion path (fusion/stream_fusion.h) that `mcms fuse` runs:
// the lab's streams as sensor logs, its frames and robot as a fusion setup, and its dwells as
// the fusion windows (the robot stands still in each; the KF restarts in each, in its static
// mode: process noise from the options, velocity prior 1e-10).
SensorLogs LabSensorLogs(const LabScenario& lab, const std::vector<FrameResult>& tracked);
FusionSetup LabFusionSetup(const LabScenario& lab, const LabExperimentOptions& options = {});
std::vector<FusionWindow> LabWindows(const LabScenario& lab);

// Scores against the truth: each sensor alone over each dwell (MeasureWindow), the fused rows
// (FuseStream over LabWindows: MOIFA and KF, `frame` = point) and the inclinometer's tilt.
LabResult EvaluateLabExperiment(const LabScenario& lab, const SensorLogs& logs, const FusionSetup& setup,
                                const std::vector<FusedSample>& fused);

// `tracked[k]` is the tracker's result for camera frame k of lab.vision: the logs, setup and
// windows above fused in memory and evaluated.
LabResult RunLabExperiment(const LabScenario& lab, const std::vector<FrameResult>& tracked,
                           const LabExperimentOptions& options = {});

// The sampling standard deviation of each method's reduction relative to the camera
// (1 - method's / camera's three-sigma position error), by a bootstrap over the points (the
// same resampled points for every method), in the order of r.summary (the camera's is 0).
std::vector<double> BootstrapReductionSd(const LabResult& r, int draws = 400, uint64_t seed = 1);

// The table, in mm and degrees.
std::string FormatLabTable(const LabResult& r);

}  // namespace mcms
