// The tilt sensors of a robot's chain audited against their forward model (issue 52): an
// accelerometer (or inclinometer) fixed to a link above another one (the construction
// robot's column tip above its base) reads gravity in its own frame; the lower sensor
// fixes where up is, the chain's nominal frames carry it to the upper sensor, and what the
// upper one reads beyond that is what the chain between them does that the robot file does
// not say.
//
// Forward model, per row (model/extensions.h; one model of the inclinometer with `fuse`):
//   u       = R_base_ref u_ref            the lower sensor's measured up, base frame
//   R_wb    = the least rotation taking u to +z (the world is gravity-aligned)
//   beta    = sum of LinkBendingT          link_compliance c L M_h, segment_play p M_h/|M_h|
//             or, telescopic (variant 1), (p_x s_x, p_y s_y) / (o + t)^2
//             (M = CarriedMoment about the upper sensor's frame, L = the frames' distance,
//             s = M_h's direction in the link frame, t = the prismatic joint's travel left)
//   reading = InclinometerReadingOfT(R_wb Exp(beta) R_base_link, R_link_sensor,
//                                    misalignment, bias)      two tilts, rad
// and the upper sensor's measured tilts are asin of its measured up's x and y. Residual =
// predicted - measured; the noise covariance (2 x 2) is estimated with every model
// (profiled maximum likelihood): no sensor sigma is needed.
//
// Candidates (audit/model_selection.h, one rule for every mode): inclinometer_bias (2) and
// inclinometer_misalignment (variant 1: the sensor turned about its own vertical, 1) of
// the upper sensor, link_compliance (2), segment_play (1; telescopic: 3, its overlap o
// profiled over 0.01-3 m: where no station comes near full extension it ends at 0.01 and
// is held there, not named, the play competing with its two amplitudes; at 3 m the play
// hardly grows with the extension, the constant play's part, and is not tried) and
// axis_tilt (2) of the link carrying it (compliance and play >= 0: a link bends with its load, never against it). A
// mount tilted about the sensor's x or y reads as a bias to first order and is named as
// one. Two candidates tied in a step are named together when, fitted together, each adds
// to the other and the pair gains held-out. Folds for held-out gains: contiguous blocks of rows. Residual
// tests (lag-1 autocorrelation in row order, trends against the carried moment's two
// horizontal components, the bending length and time) at half the designed false-alarm
// rate, the selection at the other half.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "audit/audit_report.h"
#include "model/robot_measurements.h"
#include "model/extensions.h"
#include "model/robot_model.h"

namespace mcms {

struct TiltSensorAuditOptions {
  double false_alarm = 0.01;  // designed probability of calling a clean log not clean, per sensor
  int folds = 5;
  int max_effects = 4;
  bool IsValid(std::string* why) const;
};

struct TiltSensorAuditResult {
  std::string sensor, reference;  // URDF links: the audited sensor and the one below it
  int frame = 0, reference_frame = 0;  // their chain frames (model/urdf.h LinkMount)
  int bending_joint = -1;              // link_compliance / segment_play act at this joint's child link
  AuditReport report;                  // mode "tilt sensor"; effects' parameters in SI
  std::vector<Extension> extensions;   // the named effects, in order
  std::vector<std::vector<double>> parameters, sigmas;
  Eigen::Matrix2d noise_nominal = Eigen::Matrix2d::Identity(), noise = Eigen::Matrix2d::Identity();  // rad^2
  // Per row: the tilt residuals (predicted - measured, rad) of the nominal and the final
  // model, and the carried moment's horizontal components (N m).
  std::vector<Eigen::Vector2d> nominal_residuals, residuals;
  std::vector<Eigen::Vector2d> moment;
};

// Every sensor of `log` (RobotMeasurement::accel, m/s^2) on a higher chain frame than the
// lowest one, audited against the lowest. Empty when the log has fewer than two sensors on
// different frames or the robot is not a URDF. InputError (naming the link) for a sensor
// on no link of the chain, and for a robot without masses (the carried moment is not
// known); fewer than 20 rows are too few to audit (a note, nothing named).
std::vector<TiltSensorAuditResult> AuditTiltSensors(const RobotModel& robot, const RobotLog& log,
                                                    const TiltSensorAuditOptions& options = {});

// Text for reports: per sensor, the nominal and the final noise, the report's tests and
// effects (tilts in mrad), and whether the final residuals are in band.
std::string TiltSensorAuditText(const std::vector<TiltSensorAuditResult>& results, const RobotModel& robot);

// JSON: [{"sensor", "reference", "report": (audit_report.h), "noise_sigma_rad": [x, y],
//   "noise_sigma_nominal_rad": [x, y], "in_band": bool}].
nlohmann::json TiltSensorAuditJson(const std::vector<TiltSensorAuditResult>& results);

// CSV per row and sensor: row, sensor, the nominal and final tilt residuals (mrad), the
// carried moment's horizontal components (N m). Atomically.
void WriteTiltSensorResiduals(const std::filesystem::path& path, const std::vector<TiltSensorAuditResult>& results);

}  // namespace mcms
