// Another session, frozen: a robot model fitted on one log (the geometry, each effect, the
// tool's points) scored unchanged on another log, as metrologists judge a model: by what it
// predicts on data it was not fitted to. Used by `calib-robot --validate` and
// `audit robot --validate`.
//
// Where the instrument stood (issue 51): a laser tracker, total station or motion-capture
// system is set up anew for each session, or for each station of one. The robot stays
// frozen; only its placement in the instrument's frame is found again:
//  - a log with stations (model/robot_measurements.h: a `station` column, or a dataset read
//    as published) places each station from its stationing rows (every row of the station
//    where the log gives no roles) by the rigid transform that best maps the model's
//    predictions onto the measurements (RigidFit), and scores its evaluation rows;
//  - a log without stations is scored with the fit's placement, unless that placement
//    misses far beyond the noise: re-placed from every row (its stationing rows where it
//    has roles) when the re-placement's likelihood ratio under the fit's noise passes
//    chi-square(6) at the false-alarm rate and halves the RMS error; the score says so, with
//    how far the placement moved (mm at the rows' centroid, mrad). A fit with stations of its
//    own has no placement to keep: every other session is placed anew.
// Too few or degenerate stationing rows (fewer than 3 points, or on one line) are an
// InputError naming the log and the station.
//
// Scores are per point of the measured body over the scored rows: 3-D error mean, median,
// RMS, 95th percentile and max, and the 95th percentiles of the horizontal (the
// instrument's xy) and vertical (|z|) errors, which is what a gravity-aligned instrument's
// users quote; point 1 per posture group (model/robot_measurements.h PostureGroups) and per
// station.
// JSON: {"log", "rows", "scored_rows", "models": [{"model", "points": [{"point", "rows",
//   "mean_mm", "median_mm", "rms_mm", "p95_mm", "max_mm", "p95_xy_mm", "p95_z_mm"}],
//   "groups": {"repeated": {"rows", "points": [..]}, ..}, "stations": [{"station", ..point..}],
//   "placements": [{"station", "stationing_rows", "scored_rows", "placed_anew", "moved_mm",
//   "moved_mrad"}]}]}
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "model/robot_measurements.h"
#include "core/pose_math.h"

namespace mcms {

struct PointScore {
  int point = 1;  // 1-based
  int rows = 0;
  double mean_m = 0.0, median_m = 0.0, rms_m = 0.0, p95_m = 0.0, max_m = 0.0;
  double p95_xy_m = 0.0, p95_z_m = 0.0;
};

// Where a session's station was placed for a model.
struct StationPlacement {
  std::string station;  // "" for a log without stations
  int stationing_rows = 0, scored_rows = 0;
  bool placed_anew = false;             // false: the fit's placement, frozen
  double moved_mm = 0.0, moved_mrad = 0.0;  // from the fit's placement
  double frozen_rms_mm = 0.0;          // a log without stations: the frozen placement's RMS error
};

struct ModelScore {
  std::string model;  // "registration", "geometry", "final", "final without X"
  std::vector<PointScore> points;
  std::vector<std::pair<PostureGroup, std::vector<PointScore>>> groups;  // the groups with rows
  std::vector<std::pair<std::string, PointScore>> stations;              // point 1, logs with stations
  std::vector<StationPlacement> placements;
  // Per row, each point's error (predicted - measured, m) with the placement used; empty for
  // rows not scored (stationing, spare).
  std::vector<std::vector<Vec3>> errors;
  // Per row, the change of placement applied to the predictions (identity where frozen).
  std::vector<Pose> correction;
};

struct SessionScore {
  std::string log;
  int rows = 0, scored_rows = 0;
  std::vector<PostureGroup> group_of_row;
  std::vector<ModelScore> models;
};

struct PlacementOptions {
  Mat3 noise = Mat3::Identity() * 1e-8;  // the fit's position noise covariance (m^2)
  double false_alarm = 0.01;
  bool fit_per_station = false;  // the fit placed the robot per station of its own
  // False with the reason (a noise covariance that is not finite and positive definite, a
  // false-alarm rate outside (0, 0.5)).
  bool IsValid(std::string* why) const;
};

// The score of one model on `log` from its predictions (per row, each point, in the
// instrument's frame with the fit's placement), placed as the header says.
ModelScore ScoreModel(const std::string& model, const RobotLog& log, const std::vector<std::vector<Vec3>>& predicted,
                      const std::vector<PostureGroup>& groups, const PlacementOptions& options);

// Per row of `log`, the rigid motion (robot base frame) its accelerometers' measured tilts
// give the tool (model/tilt_sensor.h TiltCorrection; issue 52): each sensor's tilt since
// the mean reading of its station's stationing rows (where the station was placed), on
// the chain's nominal frames at the row's joint values. Empty when the log has no stations
// or no accelerometer readings, a sensor is missing from a row, or the robot is not a URDF
// (nothing names its links). InputError naming the link when a sensor is on no link of the
// chain (model/urdf.h MountOnChain).
std::vector<Pose> MeasuredTiltCorrections(const RobotModel& robot, const RobotLog& log);

// Text for reports: per session, a table of the models (point 1: mean, 95 %, max, RMS mm;
// with stations, 95 % horizontal and |z|), where the instrument was placed, what each cause
// moved there, and per station the final model's figures.
std::string ValidationText(const std::vector<SessionScore>& sessions);
// The JSON array of the header.
nlohmann::json ValidationJson(const std::vector<SessionScore>& sessions);

}  // namespace mcms
