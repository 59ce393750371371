// The robot audit's options and results (audit/robot_audit.h runs it; the procedure is
// described there).
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "audit/audit_report.h"
#include "model/robot_measurements.h"
#include "core/pose_math.h"
#include "model/extensions.h"
#include "model/robot_model.h"

namespace mcms {

// The audit needs at least this many measurements (the registration alone has 9
// parameters; repeated poses over time show the noise). Logs are read by
// model/robot_measurements.h ReadRobotLog: one point, K >= 3 points of a rigid body (then
// each row's measured pose of the body), or a pose per row.
constexpr int kMinRobotMeasurements = 12;
// The largest deflection a joint's gravity compliance may give the robot audit (at the
// largest lever the log holds; each lumped mass alone): a revolute joint that sags by more
// than 0.1 rad (5.7 deg) under the arm's weight is broken, not compliant, as a joint with
// more play is (industrial arms sag 0.1-5 mrad; the real TIAGo's wrist about 30 mrad,
// docs/tiago.md); a prismatic one by more than 5 mm.
constexpr double kMaxGravityDeflectionRad = 0.1;
constexpr double kMaxGravityDeflectionM = 0.005;

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
  // For plots of the other sessions (--validate), frozen: per session, point 1's error per
  // posture for the registration, the geometry and the final model; and per named
  // non-geometric cause, against the covariate that exposes it, the error of the final
  // model refitted without it ("before") and of the final model ("after"), both along the
  // direction the cause moves the point, signed by the covariate (a proportional cause
  // reads as a line through 0, a step as two levels); with what the cause predicts. mm.
  struct ValidationPlot {
    std::string session, title, covariate;
    std::vector<double> x;
    std::vector<std::pair<std::string, std::vector<double>>> series;
  };
  std::vector<ValidationPlot> validation_plots;
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
    // What the poses decide once measured, with everything the audit refits refitted (the
    // registration, the tool and every other parameter of each model, on the logged rows and
    // the new ones): the noncentrality of the likelihood ratio between the two models (the
    // whitened misfit left when either model is fitted to the other's predictions; the
    // smaller of the two ways) per reading of each pose, after `readings` readings of each,
    // and the one the selection needs to decide at its tie band with 90 % power. readings
    // = 0: not within 1000 readings of each pose.
    double noncentrality_logged = 0.0;  // on the logged rows alone
    double noncentrality = 0.0;         // with `readings` readings of each pose
    double noncentrality_needed = 0.0;
    int readings = 0;
  };
  std::vector<NextPoses> next_poses;
  // (report.validation: every other session of `validate`, scored with the fitted models
  // frozen: the registration only ("registration"), with the whole identifiable geometry
  // ("geometry"), and the audit's final model ("final").)
};

}  // namespace mcms
