// ISO 9283 on the forward model (issue 4): pose accuracy and repeatability (AP, RP with
// their orientation parts), distance accuracy and repeatability (AD, RD) and path
// accuracy and repeatability (AT, RT) of the KR 5 arc, measured before and after
// calibration and before and after fusion. The formulas are calib/iso9283.h; this file
// produces the repeated measurements they need.
//
// Design decisions:
//  - Frames. The commanded poses are T_rig_target: the rig frame is the cell's world
//    frame (z up, gravity along -z), the five-ball target's origin is the TCP. The
//    controller maps a command into joints through what it believes: T_rig_base, its DH
//    table and T_flange_tool. The simulation's truth plays the ISO reference instrument:
//    attained poses are the TRUE robot's forward kinematics of the attained joints.
//  - The true robot: the nominal KR 5 arc (model/robots/kuka_kr5_arc.yaml) plus the DH
//    errors of an uncalibrated robot, each of magnitude uniform in [0.1, 0.3] mm (a, d)
//    or [0.01, 0.03] deg (alpha, theta offset) with a random sign, plus a base error
//    (T_rig_base, 0.5 mm and 0.02 deg) and a tool error (T_flange_target, 0.2 mm and
//    0.02 deg), all from the seed. The nominal model is what the controller believes.
//    Were that all, a calibration of the same model would remove the error entirely
//    (measured: AP 0.005 mm after calibration) and nothing would be left for fusion; a
//    real calibrated robot keeps 0.05-0.2 mm from what a DH table does not describe
//    (gear transmission error, compliance, heat). So the true robot also has a gear
//    transmission error on each joint, 8e-5 rad (0.0046 deg) amplitude with a 10 deg
//    period in joint angle and a random phase, which no DH parameter can absorb.
//  - Repeatability: a move to commanded joints q_c ends at q_a = q_c + eps, eps ~ N(0,
//    sigma_rep^2 I) per joint, drawn anew on every move (servo settling, backlash on the
//    joint side of the gears). sigma_rep = 1.4e-5 rad makes RP 0.035-0.038 mm on average over
//    P1..P5 and at most about 0.04 mm (n = 30, seeds 1-8), the +-0.04 mm of the KR 5 arc
//    data sheet. The encoders read q_e = q_a + nu with
//    the model's encoder_sigma (1e-5 rad).
//  - The ISO test cube: edge 0.25 m, centred in the rig's working volume (rig (0,0,0.5),
//    the centre of the lab experiment's sphere, which the robot reaches comfortably).
//    P1 is the centre; P2..P5 lie on the cube's diagonal plane through the corners
//    C(-,-,+), C(+,+,+), C(+,+,-), C(-,-,-) (in that order), each at 10 % of the cube's
//    diagonal from its corner. All five have the same orientation (flange z down). One
//    cycle visits P1 -> P5; n = cycles cycles. The path is the straight line from P2 to
//    P4 (across the cube, through P1) with `path_points` calculation points, each run
//    sampled densely a little beyond both ends, with fresh joint noise at every sample.
//  - Camera measurement: for each ball and camera, the area centroid of the sphere's image
//    (vision/sphere_projection.h, the forward model a centroiding detector measures) plus
//    Gaussian pixel noise of pixel_sigma per axis, kept when the ball is in front of the
//    camera and its image inside the frame (balls hiding each other and the robot hiding
//    balls are not modelled); then RefinePose (the tracker's bundle adjustment) gives
//    T_rig_target with covariance. 0.017 px is the centroid sigma the blob detector
//    reports on the default scenario's rendered images (8 bit, 200 DN balls, gain 4 e-/DN,
//    1.5 DN read noise; RMS over 58 blobs), with which the tracker's pose NEES is
//    consistent (tests/test_app_pipeline.cpp). No images are rendered: that keeps the demo
//    and the tests fast; what the images add (the detector) is represented by its noise.
//    The cameras are taken as perfectly calibrated: the camera measurement is unbiased.
//  - Robot measurement: the controller's model (calibrated) at the encoder readings, with
//    covariance
//    J Q_enc J^T + J_par C_par J_par^T + U: the second term the calibration's parameter
//    covariance propagated to the pose, U the fit's residual per axis (what the model
//    cannot explain; camera noise included, so on the safe side).
//    Inclinometer: model/inclinometer.h, the mean of inclinometer_readings readings taken
//    while the robot stands at the pose (pitch/roll only). It sits on the target plate:
//    its R_flange_incl is taken as the rotation from its frame to the TARGET's, known
//    (leveled against the camera beforehand). Referenced through the robot's calibrated
//    tool rotation instead, it inherits that rotation's calibration error, which the
//    correction then adds to every pose (measured: a 0.006 deg bias in AP_a). The rig's
//    z axis is taken as exactly vertical.
//  - Conditions: (1) before calibration, joints from IK of the nominal model; (2) after
//    calibration by CalibrateRobot from 6-D camera measurements (meas frame = rig) at
//    calibration_poses other configurations (random positions within 0.25 m of the cube's
//    centre, orientations within +-25 deg of the nominal), joints from IK of the
//    calibrated model; (3) as (2), then at each visit the pose is measured by the camera
//    alone and ONE correction move is made, q_c' = q_e + J^+ e with e = BoxMinus(commanded,
//    measured) (the new move draws new repeatability noise); (4) as (3) with the pose
//    measured by MOIFA over camera + robot + inclinometer (fusion/stream_fusion.h FuseEpoch,
//    the instant fusion `mcms fuse` runs per frame). The attained pose after the
//    correction is what ISO 9283 evaluates. The path is run with the model only (no
//    correction is possible along a moving path in this scheme), so conditions 3 and 4
//    report condition 2's path.
//  - Prediction for (3) and (4): the error after the correction is
//    -(estimation error) + J (eps' + nu), so its covariance is
//    C_after = P_est + J (sigma_rep^2 + encoder_sigma^2) J^T; the predicted RP per pose
//    (mean of l + 3 std of l for a Gaussian with C_after's position block) and the
//    predicted RMS position and orientation error are compared with the measured ones.
//    For (1) and (2) the predicted RP is that of the repeatability alone, J sigma_rep^2 J^T.
#pragma once

#include <numbers>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "model/inclinometer.h"
#include "calib/iso9283.h"
#include "core/pose_math.h"

namespace mcms {

struct Iso9283ExperimentOptions {
  int cycles = 30;                              // ISO 9283: n = 30 for AP/RP
  int path_runs = 10;                           // ISO 9283: n = 10 for AT/RT
  int path_points = 11;                         // calculation points on the path
  double cube_edge_m = 0.25;
  Vec3 cube_centre_rig = Vec3(0.0, 0.0, 0.5);
  int calibration_poses = 50;
  // Errors of the true robot against the nominal (magnitudes uniform in [min, max]).
  double dh_length_error_min_m = 1e-4, dh_length_error_max_m = 3e-4;
  double dh_angle_error_min_rad = 0.01 * std::numbers::pi / 180.0;
  double dh_angle_error_max_rad = 0.03 * std::numbers::pi / 180.0;
  double base_error_m = 5e-4, base_error_rad = 0.02 * std::numbers::pi / 180.0;
  double tool_error_m = 2e-4, tool_error_rad = 0.02 * std::numbers::pi / 180.0;
  // The true robot's joint-angle error that no DH table describes (a gear's transmission
  // error): amplitude per joint and period in joint angle, random phase per joint.
  double unmodelled_joint_error_rad = 8e-5;
  double unmodelled_joint_error_period_rad = 10.0 * std::numbers::pi / 180.0;
  double repeatability_joint_sigma_rad = 1.4e-5;  // per joint, per move
  double pixel_sigma = 0.017;                    // px per axis, ball centroid noise
  int inclinometer_readings = 50;                // averaged at each visit (1 s at 50 Hz)
  Inclinometer inclinometer;                     // paper: 0.01 deg
  uint64_t seed = 9283;
  bool IsValid(std::string* why) const;
};

// One condition's ISO 9283 characteristics. Lengths in m, angles in rad.
struct Iso9283Condition {
  std::string name;
  std::vector<PoseCharacteristics> poses;          // P1..P5
  std::vector<DistanceCharacteristics> distances;  // P1-P2, P2-P3, P3-P4, P4-P5
  PathCharacteristics path;
  std::string path_note;                           // empty, or where the path comes from
  std::vector<std::vector<Vec3>> path_attained;    // [run][sample], rig frame
  std::vector<std::vector<Pose>> attained;         // [pose][cycle], T_rig_target
  // Errors of every attained pose against its command, all visits: RMS of |dp| and of
  // the rotation angle.
  double rms_position_m = 0, rms_rotation_rad = 0;
  // Predictions from the covariances (see the header comment).
  std::vector<double> predicted_RP_m;               // per pose
  std::optional<double> predicted_rms_position_m, predicted_rms_rotation_rad;
};

struct Iso9283Experiment {
  Iso9283ExperimentOptions options;
  std::vector<Pose> commanded;             // P1..P5, T_rig_target
  std::vector<Vec3> path_commanded;        // calculation points, rig frame
  std::vector<Iso9283Condition> conditions;  // before calib, after calib, camera corr., MOIFA corr.
  // The calibration: RMS position error of the fitting set with the nominal and the
  // calibrated model, and the number of parameters held fixed.
  double calibration_rms_before_m = 0, calibration_rms_after_m = 0;
  int calibration_fixed = 0, calibration_parameters = 0;
};

// Runs the four conditions. InputError when the options are invalid (naming the option)
// or a commanded pose, a path point or a calibration pose is out of the robot's reach or
// not seen by the rig (naming cube_edge_m / cube_centre_rig).
Iso9283Experiment RunIso9283Experiment(const Iso9283ExperimentOptions& options = {});

// Human-readable tables (mm, deg): per condition AP/RP per pose, AD/RD, AT/RT, the
// predictions, and a summary across conditions.
std::string FormatIso9283Experiment(const Iso9283Experiment& e);

// condition,pose,AP_mm,AP_x_mm,AP_y_mm,AP_z_mm,RP_mm,RP_pred_mm,AP_a_deg,AP_b_deg,AP_c_deg,
// RP_a_deg,RP_b_deg,RP_c_deg   (atomically written)
void WriteIso9283ExperimentCsv(const std::filesystem::path& path, const Iso9283Experiment& e);
// The attained poses of one condition in `mcms iso9283`'s input layout (app/cmd_iso9283.cpp).
void WriteIso9283AttainedCsv(const std::filesystem::path& path, const Iso9283Experiment& e, int condition);
// The commanded path's calculation points and the attained runs of one condition in
// `mcms iso9283 --path`'s input layout (run,x_m,y_m,z_m; run = commanded or run1..).
void WriteIso9283PathCsv(const std::filesystem::path& path, const Iso9283Experiment& e, int condition);
// Both of the above for every condition k = 1..4: dir/<prefix>attained_<k>.csv and
// dir/<prefix>path_<k>.csv (the folder is created).
void WriteIso9283Measurements(const std::filesystem::path& dir, const std::string& prefix, const Iso9283Experiment& e);
// AP (log10 of mm) and RP (mm, with the prediction) per pose for the four conditions.
void WriteIso9283ExperimentSvg(const std::filesystem::path& ap_path, const std::filesystem::path& rp_path,
                               const Iso9283Experiment& e);

}  // namespace mcms
