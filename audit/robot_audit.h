// The robot mode of the model audit (issues 11 and 24): given a robot's joint values and
// the positions (and optionally orientations) of its tool measured by an external
// instrument (the camera rig, a laser tracker), show where the nominal forward model
// disagrees with the measurements beyond chance, name the catalog effects
// (model/extensions.h) that explain it, with their sizes and standard deviations, and
// measure what each gains on held-out data.
//
// Model: p_meas = T_meas_base * T_base_flange(q; extensions) * t_flange_tool + e,
//        e ~ N(0, Sigma) (anisotropic, full 3x3; 6x6 with the orientation residual
//        Log(R_pred R_meas^T) for 6-D measurements), Sigma unknown.
// The registration T_meas_base (6) and the tool (3; 6 for 6-D) are always free, as in
// `calib-robot`; a term that the registration absorbs (the first joint's offset, its d,
// the last joint's terms that duplicate the tool) is reported as not identifiable.
//
// Noise: Sigma is estimated with the model by maximum likelihood (profiled), so every
// comparison between models is a likelihood ratio with Sigma free. When poses are repeated
// (rows with the same joint values), their scatter gives an estimate of the noise alone
// (pure error), and the nominal fit is tested against it (lack-of-fit F test).
//
// Procedure:
//  1. nominal fit; tests of its residuals: lack of fit (when there are repeats), lag-1
//     autocorrelation in time, and the correlation of each residual component with every
//     covariate (time, each joint, each joint's gravity torque, direction of the last
//     move, temperature);
//  2. greedy forward selection over the catalog, each step decided by the audit's
//     selection rule (audit/model_selection.h DecideStep): likelihood ratio past
//     chi-square at the selection's share of the false-alarm rate / candidates
//     (Bonferroni), BIC gain > 0, held-out log-likelihood gain > 0 in k-fold cross-
//     validation whose folds are contiguous blocks of time, ties judged statistically from
//     per-measurement log-likelihoods (Vuong's paired z on all data, one standard error
//     held out) and reported as undecided with both sizes. Geometry first: every real
//     robot has all its DH parameters a little off, so the DH parameters the poses
//     identify (theta offset, d, a, alpha of every joint; calib-robot's identifiability
//     analysis, base and tool first) are candidates one by one (joint_offset, link_length,
//     link_twist; a few at most) and all at once (`geometry`, with every identifiable
//     parameter's size +- sigma and the held ones with the reason). A non-geometric effect
//     (joint_scale, gravity_compliance, backlash, thermal_drift, error_motion,
//     clock_offset) must also pass on top of the whole identifiable geometry, so that it
//     cannot soak up a geometric error. In a tie, a single physical cause is preferred to
//     the whole geometry, and both to error_motion (a flexible harmonic family), which is
//     named only where no physical term does as well;
//  3. the geometric terms that the named effects make unnecessary are dropped (backward
//     pruning), the final model is refitted, and each finding is reported with its size
//     +- sigma, held-out RMS before and after, held-out log-likelihood gain and BIC gain.
//     For each undecided pair, the poses that would best separate the two (their
//     predicted difference against the noise) are returned (`next_poses`).
//
// Physical bounds: a compliance (and a lumped mass) and a backlash cannot be negative;
// they are fitted with the bound, and when the data ask for the other sign the report
// says so in a note instead of naming a negative stiffness.
//
// The fits are Gauss-Newton steps on one Jacobian of every candidate parameter taken at
// the nominal fit, with the exact nonlinear residuals re-evaluated until they agree
// (effects are small: a few steps converge), so the whole catalog costs little more than
// the nominal fit.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "audit/robot_audit_types.h"
#include "audit/tilt_sensor_audit.h"
#include "model/robot_validation.h"

namespace mcms {

// Writes next_poses as CSV: pair,q1_rad..qN_rad (q<i>_m for a prismatic joint; a robot with
// mimic joints: its actuated joints by name, as its logs record them),x_a_m,y_a_m,z_a_m,
// x_b_m,y_b_m,z_b_m,difference_mm,separation_sigma (atomically).
void WriteNextPoses(const std::filesystem::path& path, const RobotAuditResult& result, const RobotModel& robot);

// The audit's report text: the log and the robot, the nominal fit, the report
// (AuditReport::Text), the extended model, the tilt sensors' audits and the poses that
// would separate an undecided pair.
std::string RobotAuditText(const RobotAuditResult& result, const RobotLog& log, const RobotModel& robot,
                           const std::vector<TiltSensorAuditResult>& tilt);
// report.json: the audit (AuditReport::ToJson), with "tilt_sensors" when the log has them.
void WriteRobotAuditJson(const std::filesystem::path& path, const RobotAuditResult& result,
                         const std::vector<TiltSensorAuditResult>& tilt);
// The audit's output folder's contents into `dir` (an empty folder; the job writes it as a
// whole, core/output_folder.h): report.txt (`report`), robot.yaml (and robot.urdf for a URDF
// robot), residuals.csv, validation.csv, plots/effect<k>.svg and validation<k>.svg,
// next_poses.csv, tilt_residuals.csv and report.json.
void WriteRobotAuditFolder(const std::filesystem::path& dir, const RobotAuditResult& result, const RobotLog& log,
                           const RobotModel& robot, const std::vector<TiltSensorAuditResult>& tilt,
                           const std::string& report);

// `validate`: other sessions measured in the same frame, scored frozen (RobotAuditResult::
// validation; also in the report's JSON and text).
RobotAuditResult AuditRobot(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& options = {},
                            const std::vector<RobotLog>& validate = {});


}  // namespace mcms
