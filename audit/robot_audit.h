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

#include "core/pose_math.h"
#include "audit/audit_report.h"
#include "calib/robot_measurements.h"
#include "calib/robot_validation.h"
#include "model/extensions.h"
#include "model/robot_model.h"

namespace mcms {

// The audit needs at least this many measurements (the registration alone has 9
// parameters; repeated poses over time show the noise). Logs are read by
// calib/robot_measurements.h ReadRobotLog: one point, K >= 3 points of a rigid body (then
// each row's measured pose of the body), or a pose per row.
constexpr int kMinRobotMeasurements = 12;

struct RobotAuditOptions {
  // Designed probability that the audit calls a clean log not clean (any test failed or
  // any effect named): split evenly between the residual tests and the selection.
  double false_alarm = 0.01;
  int folds = 5;          // k of the time-blocked cross-validation (>= 2)
  int max_effects = 6;    // greedy steps at most for the non-geometric effects
  int max_geometric_terms = 3;  // single geometric terms named before `geometry` says "all"
  int max_full_fits = 8;  // candidates fitted in full per step (best by screening)
  // Relative distance of a scaled Jacobian column from the span of those before it below
  // which a parameter is not identifiable (as calib-robot's identifiability_tolerance).
  double identifiability_tolerance = 1e-5;
  // Poses proposed per undecided pair (next_poses).
  int next_poses = 10;
  // Restrict the catalog to these names (empty = every robot effect; "geometry" covers
  // the single geometric terms too).
  std::vector<std::string> only;
  std::optional<Pose> base_guess;  // T_meas_base start; default: rigid fit (3-D) / mean (6-D)
  double reference_temperature_c = 20.0;
  // Joint values closer than this (rad or m, every joint), or than six times the jitter
  // of two readings of the robot file's encoder_sigma, are the same pose (repeats), and a
  // change no larger is not a move (backlash).
  double repeat_tolerance = 1e-6;
  std::function<void(const std::string&)> progress;
  bool IsValid(std::string* why) const;
};

// One fitted model: the registration, the tool, the extensions with their parameters,
// the noise covariance, and per-row residuals (predicted - measured; m, and rad).
struct RobotAuditFit {
  std::vector<Extension> extensions;
  std::vector<std::vector<double>> parameters;  // one block per extension
  std::vector<std::vector<double>> sigmas;      // standard deviations (0 = held)
  Pose T_meas_base;
  Pose T_flange_tool;
  Eigen::MatrixXd noise;      // m x m, m = 3 or 6
  Eigen::MatrixXd residuals;  // rows x m
  double loglik = 0.0;
};

struct RobotAuditResult {
  AuditReport report;
  RobotAuditFit nominal, extended;
  // The robot with what its description can hold applied (joint offsets, link lengths,
  // error motion, registration-free); effects it cannot hold are listed in the report.
  RobotModel extended_robot;
  // For plots: per named effect, the covariate that exposed it, its values per row, and
  // the residual before the effect along the effect's direction with the effect itself.
  struct EffectPlot {
    std::string effect, covariate;
    std::vector<double> x, residual_before, effect_size;
  };
  std::vector<EffectPlot> plots;
  // For each undecided pair: the poses that best separate the two candidates, from the
  // difference of their predicted tool positions against the noise.
  struct SeparatingPose {
    Eigen::VectorXd q;
    Vec3 p_meas_a = Vec3::Zero(), p_meas_b = Vec3::Zero();  // predicted tool position (m)
    double separation_sigma = 0.0;  // sqrt of the predicted difference's chi-square
  };
  struct NextPoses {
    std::string a, b;  // the two candidates' labels
    std::vector<SeparatingPose> poses;
  };
  std::vector<NextPoses> next_poses;
  // (report.validation: every other session of `validate`, scored with the fitted models
  // frozen: the registration only ("registration"), with the whole identifiable geometry
  // ("geometry"), and the audit's final model ("final").)
};

// Writes next_poses as CSV: pair,q1_rad..qN_rad,x_a_m,y_a_m,z_a_m,x_b_m,y_b_m,z_b_m,
// difference_mm,separation_sigma (atomically).
void WriteNextPoses(const std::filesystem::path& path, const RobotAuditResult& result, int num_joints);

// `validate`: other sessions measured in the same frame, scored frozen (RobotAuditResult::
// validation; also in the report's JSON and text).
RobotAuditResult AuditRobot(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& options = {},
                            const std::vector<RobotLog>& validate = {});

// The whole `mcms audit robot` job: read, audit, write the output folder (report.txt,
// report.json, robot.yaml (and robot.urdf for a URDF robot), residuals.csv, plots/*.svg,
// next_poses.csv when a pair is undecided, validation.csv with --validate; atomically)
// and/or a JSON file.
struct RobotAuditJob {
  std::filesystem::path log, robot, output_dir, json;
  ChainSelection chain;                       // of a URDF robot
  std::vector<std::filesystem::path> validate;  // other sessions, scored frozen
  RobotAuditOptions options;
};
// Returns the report text.
std::string RunRobotAuditJob(const RobotAuditJob& job);

}  // namespace mcms
