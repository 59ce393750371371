// Robot measurements: a robot's joint values and what an external instrument (a laser
// tracker, the camera rig, a motion-capture system) measured of its tool at each, read
// from one kind of file for `calib-robot` and the robot audit alike, with the checks that
// catch another unit, a mistyped row or a body that is not rigid before any fit.
//
// A measurement is one of
//  - a point: the position of one point fixed in the tool (the target), or
//  - K >= 3 points of one rigid body fixed in the tool (motion capture's markers): their
//    coordinates in the tool frame are unknown and fitted with the registration, or
//  - a pose: a point and the tool's orientation.
// Frames and units (docs/conventions.md): `meas` is the instrument's frame; metres,
// radians (metres for a prismatic joint), seconds.
#pragma once

#include <cmath>
#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/io.h"
#include "core/pose_math.h"
#include "model/robot_model.h"

namespace mcms {

// What a row is for where a log places the robot per station (issue 51): a row measured
// only to place its station in the instrument's frame (`stationing`), a row scored against
// the model (`evaluation`, the default), or one measured at the station that neither places
// it nor is scored in another session (`spare`: the stationing points a protocol does not
// use). In the fitted log every row is fitted alike.
enum class RowRole { kEvaluation, kStationing, kSpare };
const char* Name(RowRole r);

struct RobotMeasurement {
  Eigen::VectorXd q;  // the chain's joint values (a mimic joint's from its driver)
  Vec3 p_meas = Vec3::Zero();        // the measured point (point 1 of a rigid body)
  std::vector<Vec3> other_points;    // points 2..K of the same rigid body (empty: one point)
  std::optional<Mat3> R_meas_tool;   // measured orientation of the tool (a pose)
  double time_s = 0.0;
  std::optional<double> temperature_c;  // given when the log has the column (has_temperature)
  std::optional<double> payload_kg;     // given when the log has the column (has_payload)
  // Joint velocities at the measurement (empty = at rest): with them the audit tests a
  // clock offset between the joint log and the instrument (`audit fusion`).
  Eigen::VectorXd qdot;
  // The station: rows that share one placement of the robot in the instrument's frame (the
  // instrument or the robot set up anew); "" = the log's one placement.
  std::string station;
  RowRole role = RowRole::kEvaluation;
  // Accelerometers at rest fixed to links of the robot's URDF (issue 52): per sensor, its
  // link's name and its specific force in the sensor's frame (m/s^2; at rest, g upward).
  std::vector<std::pair<std::string, Vec3>> accel;
  int line = 0;        // 1-based line in the file (0: made in code)
  std::string source;  // where it came from, for messages ("file.yaml measurement 5 (line 23)")
  int NumPoints() const { return 1 + static_cast<int>(other_points.size()); }
  // Point k (0-based) of the body.
  const Vec3& Point(int k) const { return k == 0 ? p_meas : other_points[k - 1]; }
};

// Measurements in time order, from one file (one session).
struct RobotLog {
  std::filesystem::path source;
  std::vector<RobotMeasurement> rows;
  bool has_time = false, has_temperature = false, has_payload = false;
  bool has_stations = false, has_roles = false;
  std::vector<std::string> ignored_columns;  // CSV columns the reader does not use
  std::vector<std::string> notes;            // what the reader decided that a report should say
  // The stations in order of first appearance ({""} without a station column).
  std::vector<std::string> Stations() const;
  bool six_dof() const { return !rows.empty() && rows.front().R_meas_tool.has_value(); }
  int NumPoints() const { return rows.empty() ? 0 : rows.front().NumPoints(); }
  // "file line 12" (or "file row 3" for rows made in code).
  std::string Where(size_t row) const;
};

// Reads a measurement file:
//  - CSV, one row per measurement, columns (any order; unknown columns are ignored and
//    listed in `ignored_columns`):
//      time:    time_s, or t_start_robot and t_end_robot (the middle of the averaging window);
//      joints:  q1_rad .. qN_rad (q<i>_deg, q<i>_m for a prismatic joint), or the robot's
//               joint names (as its URDF names them), bare (rad, or m for a prismatic joint)
//               or with _rad, _deg, _m;
//      points:  x_m, y_m, z_m (one point), or x1, y1, z1, ..., xK, yK, zK (metres; also
//               x1_m ...) for K points of one rigid body;
//      pose:    qw, qx, qy, qz with one point (the tool's orientation);
//      temperature_c, payload_kg;
//      accelerometers: <link>_ax, <link>_ay, <link>_az (m/s^2, the sensor's frame) of a
//               sensor fixed to that URDF link of the chain (issue 52: tilt sensors);
//      station: rows that share one placement of the robot in the instrument's frame (any
//               label); role: stationing, evaluation (also an empty cell) or spare (RowRole);
//  - or YAML: calib-robot's `measurements:` list or ROS-Industrial industrial_calibration's
//    kinematic measurements (ReadRobotMeasurements), rows in order (the row index is the time);
//  - or YAML as Hilti publishes its construction-robot stationing datasets (`joint_names`,
//    `column_heights: {h: {solution_spaces: {s: {stationing_measurements, evaluation_
//    measurements}}}}`): one station per column height and solution space ("1.98 m / 0"),
//    the four stationing points that form the square the publisher's protocol uses as
//    `stationing`, its other stationing points `spare`, evaluation points `evaluation` (those
//    of a station without stationing points `spare`: nothing places them), rows in time
//    order, the joints by the file's names (a mimic joint's driver), the prism's position.
// InputError naming the file, the line and the column: missing or extra joint columns (a
// URDF joint that is not in the chain, a chain joint not in the log), a duplicated column,
// degrees under a radian header or millimetres under a metre header (CheckRobotLog), joint
// values outside the robot's limits, time going backwards, non-finite cells, a quaternion
// that is not unit, 2 points (give 1 or >= 3), points that are not one rigid body, a role
// not understood.
RobotLog ReadRobotLog(const std::filesystem::path& path, const RobotModel& robot);

// The joint columns of a CSV log, the one reader of them (robot logs here, `mcms fuse`'s
// joint log in fusion/sensor_logs.h): per actuated joint (a mimic joint's driver) its
// column and the factor to SI, found as q1_rad .. qN_rad (q<i>_deg; q<i>_m for a prismatic
// joint) or by the robot's joint names (bare, _rad, _deg, _m); the columns used are added
// to `used`. InputError naming the file: a joint missing (by number and name), more
// numbered columns than joints, a joint given twice, a unit for the other joint type, a
// URDF joint outside the chain.
struct JointColumns {
  std::vector<int> column;
  std::vector<double> scale;
};
JointColumns FindJointColumns(const CsvTable& t, const RobotModel& robot, std::set<int>* used);

// Checks a log made in code or read: joint counts, limits (a reading may pass one by
// RobotModel::kLimitSlack of the joint's range; beyond, the likely unit is named when a
// value would fit in another one), finite values, time order, all rows of one kind;
// `min_rows` rows at least (0: no minimum).
void CheckRobotLog(const RobotLog& log, const RobotModel& robot, int min_rows = 0);
// The robot with each joint's limits widened to cover the readings of `logs` that pass them
// (within the slack CheckRobotLog allows), so that its kinematics take every reading; what
// was widened is said in `notes` (may be null).
RobotModel CoverReadings(const RobotModel& robot, const std::vector<const RobotLog*>& logs,
                         std::vector<std::string>* notes = nullptr);

// The checks of a log's plausibility before any fit (each an InputError naming the file,
// the row and the likely cause): a row measured far from all others (a mistyped row, one
// row in millimetres), the same row twice, positions in another unit than metres or
// mirrored axes (the best similarity between the nominal tool positions and the measured
// ones has a scale far from 1 or needs a reflection), joints that do not move the tool,
// points of one rigid body whose mutual distances vary beyond their noise.
void CheckRobotLogPlausible(const RobotLog& log, const RobotModel& robot);

// A rigid body measured by K >= 3 points in every row: its points in its own frame (origin
// at their centroid, axes those of the meas frame at the first row, the mean shape over the
// rows) and the body's pose T_meas_body in every row (least squares, Kabsch), with the RMS
// distance of the row's points from the fitted shape.
struct RigidBody {
  std::vector<Vec3> points_body;
  std::vector<Pose> T_meas_body;
  std::vector<double> fit_rms_m;
};
RigidBody FitRigidBody(const RobotLog& log);
// The poses of a rigid body of known shape (points_body, its own frame) in every row.
RigidBody RigidBodyPoses(const RobotLog& log, const std::vector<Vec3>& points_body);

// Per posture, how it relates to the postures of a fitted log (validation groups): repeated
// (every joint within `tolerance` of some fitted row), new inside the fitted joint ranges,
// or outside them (some joint beyond the fitted range).
enum class PostureGroup { kRepeated, kNewInRange, kOutOfRange };
const char* Name(PostureGroup g);
std::vector<PostureGroup> PostureGroups(const RobotLog& fitted, const RobotLog& other, double tolerance = 0.01);

// The log with only the points `keep` (1-based, in that order; empty: every point) of every
// row. InputError naming `option` for a point the log does not have, or 2 points.
RobotLog KeepPoints(const RobotLog& log, const std::vector<int>& keep, const std::string& option);

// YAML measurement files alone (the two layouts above), without a robot to check against.
std::vector<RobotMeasurement> ReadRobotMeasurements(const std::filesystem::path& path);
// Writes calib-robot's layout, atomically, 17 significant digits (points 2..K not written).
void WriteRobotMeasurements(const std::filesystem::path& path, const std::vector<RobotMeasurement>& m);

// Every measurement usable by a fit of `robot`: one joint value per joint within its
// limits, finite positions, the same number of points and the same kind (3-D or 6-D) in
// each. InputError naming `who` and the measurement.
void CheckRobotMeasurements(const RobotModel& robot, const std::vector<RobotMeasurement>& ms, const char* who);

// A starting registration when none is known: the rigid transform (Umeyama/Kabsch) that
// best maps the nominal tool positions T_base_tool(q_i).t onto the measured positions.
// InputError when fewer than 3 measurements or the positions are collinear.
Pose InitialBaseGuess(const RobotModel& robot, const std::vector<RobotMeasurement>& measurements);

}  // namespace mcms
