#include "fusion/log_checks.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "core/format.h"
#include "core/error.h"
#include "core/pose_math.h"
#include "core/statistics.h"
#include "model/flange_pose.h"

namespace mcms {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

CellGeometry Cell(const FusionSetup& setup) {
  CellGeometry cell;
  cell.T_base_rig = setup.T_base_rig;
  cell.T_base_rig_covariance = setup.T_base_rig_covariance;
  cell.T_flange_target = setup.T_flange_target;
  return cell;
}

// Readings in radians under _deg headers (or degrees under _rad): the readings against the
// tilts the tracker measured (each reading paired with the tracked frame nearest in time,
// within 0.5 s) have a slope of 1/57.3 (or 57.3) instead of 1. Refused with the unit named
// before any fit: the audit of such a log would only find a misfit of hundreds of sigma.
void CheckTiltUnits(const Inclinometer& incl, const std::vector<Vec2>& p, const std::vector<Vec2>& r,
                    const InclinometerLog& log) {
  if (p.size() < 10) return;
  Vec2 pm = Vec2::Zero(), rm = Vec2::Zero();
  for (size_t i = 0; i < p.size(); ++i) pm += p[i] / p.size(), rm += r[i] / r.size();
  double sxx = 0, sxy = 0;
  for (size_t i = 0; i < p.size(); ++i) sxx += (p[i] - pm).squaredNorm(), sxy += (p[i] - pm).dot(r[i] - rm);
  if (!(sxx > 1e-6 * p.size())) return;  // the tilt varies by less than 1 mrad: nothing to compare
  const double slope = sxy / sxx, k = 180.0 / std::numbers::pi;
  char b[64];
  std::snprintf(b, sizeof b, "%.4g", slope);
  if (std::abs(slope * k - 1.0) < 0.1)
    Throw(log.source.string(), ": the inclinometer's readings are ", b,
          " times the tilts the tracker measured, "
          "1/57.3: readings in radians under _deg headers? (give tilt_x_deg, tilt_y_deg in degrees, or "
          "tilt_x_rad, tilt_y_rad in radians)");
  if (std::abs(slope / k - 1.0) < 0.1)
    Throw(log.source.string(), ": the inclinometer's readings are ", b,
          " times the tilts the tracker measured, "
          "57.3: readings in degrees under _rad headers? (give tilt_x_rad, tilt_y_rad in radians, or "
          "tilt_x_deg, tilt_y_deg in degrees)");
  // Another scale: the readings' spread against the tilts' (a ratio no mounting angle
  // changes), beyond what a sensor's scale error (a few %) could be: degrees/100, gon or
  // mrad under _rad headers. Judged only where the tilt varies by far more than the noise.
  double srr = 0;
  for (size_t i = 0; i < p.size(); ++i) srr += (r[i] - rm).squaredNorm();
  const double spread = std::sqrt(srr / sxx);
  if (std::sqrt(sxx / p.size()) > 20 * incl.sigma && std::abs(spread - 1.0) > 0.3) {
    std::snprintf(b, sizeof b, "%.4g", spread);
    Throw(log.source.string(), ": the inclinometer's readings vary ", b,
          " times as much as the tilts the tracker measured: not a sensor's scale error (a few %) but another unit "
          "(degrees/100, gon, mrad?); give tilt_x_rad, tilt_y_rad in radians or tilt_x_deg, tilt_y_deg in degrees");
  }
  // The two columns exchanged: the readings follow the tracker's tilts with x and y
  // swapped (a reflection, which no mounting of the sensor produces) far better than as
  // logged. Compared after removing each fit's mean (a bias).
  const auto rms = [&](bool swapped) {
    const auto d = [&](size_t i) -> Vec2 { return (swapped ? Vec2(r[i].y(), r[i].x()) : r[i]) - p[i]; };
    Vec2 mean = Vec2::Zero();
    for (size_t i = 0; i < p.size(); ++i) mean += d(i) / p.size();
    double ss = 0;
    for (size_t i = 0; i < p.size(); ++i) ss += (d(i) - mean).squaredNorm();
    return std::sqrt(ss / p.size());
  };
  const double as_logged = rms(false), exchanged = rms(true);
  if (as_logged > 10 * incl.sigma && exchanged < 0.3 * as_logged) {
    char m[160];
    std::snprintf(m, sizeof m, "%.3g mrad RMS as logged, %.3g mrad with the columns exchanged", 1e3 * as_logged,
                  1e3 * exchanged);
    Throw(log.source.string(), ": the inclinometer's readings follow the tilts the tracker measured with tilt_x and "
          "tilt_y exchanged (", m, "): are the two columns swapped? (tilt_x is the sensor's x axis)");
  }
}


// A mount in the setup that turns the sensor away from gravity: the tracked orientations
// tilt the sensor beyond its range (where it reads nothing) for most readings, while the
// readings themselves are within it.
void CheckMount(const FusionSetup& setup, const std::vector<Mat3>& R, const std::vector<Vec2>& r,
                const InclinometerLog& log) {
  const Inclinometer& incl = setup.inclinometer;
  int n = 0, out = 0;
  std::vector<double> predicted;
  for (size_t i = 0; i < R.size(); ++i) {
    if (!((r[i] - incl.bias).cwiseAbs().maxCoeff() <= incl.range)) continue;
    ++n;
    const Vec3 up = (R[i] * incl.R_flange_incl).transpose() * Vec3::UnitZ();  // gravity's up in the sensor
    predicted.push_back(std::acos(std::clamp(up.z(), -1.0, 1.0)));
    if (!incl.InRange(R[i])) ++out;
  }
  if (n < 10 || 2 * out <= n) return;
  Throw(setup.source.string(), ": the inclinometer's mount (inclinometer.quaternion_wxyz, the rotation from the "
        "flange to the sensor) tilts the sensor ", Num4(SelectedMedian(predicted) / kDeg),
        " deg (median) from level at the orientations the tracker measured, beyond its range of ",
        Num4(incl.range / kDeg), " deg on ", out, " of ", n, " readings, while ", log.source.string(),
        " reads within its range: is the mount right? (the sensor's z axis up when the flange is level)");
}

}  // namespace

void CheckTrackerAgainstJoints(const FusionSetup& setup, const TrackerLog& tracker, const JointLog& joints) {
  const CellGeometry cell = Cell(setup);
  std::vector<double> as_read, scalar_last;
  Eigen::VectorXd q;
  for (const TrackerSample& s : tracker.samples) {
    if (!joints.Interpolate(s.time_s, &q)) continue;
    const Mat3 R_robot = setup.robot.T_base_tool(q).R;
    const Mat3 R_target = s.T_rig_target.R;
    const Mat3 R_alt = RotationReadScalarLast(Eigen::Quaterniond(R_target));
    as_read.push_back(RotationAngle(R_robot, CameraFlangePose(cell, s.T_rig_target, s.covariance).T.R));
    Pose T_alt = s.T_rig_target;
    T_alt.R = R_alt;
    scalar_last.push_back(RotationAngle(R_robot, CameraFlangePose(cell, T_alt, s.covariance).T.R));
  }
  if (as_read.size() < 3) return;
  const double median = SelectedMedian(as_read) / kDeg, median_alt = SelectedMedian(scalar_last) / kDeg;
  if (median > 10 && median_alt < 5 && median_alt < 0.25 * median)
    Throw(tracker.source.string(), ": the tracked flange orientations differ from the robot's (", joints.source.string(),
          " through the setup's T_base_rig and T_flange_target) by ", Num4(median), " deg (median), and by ",
          Num4(median_alt), " deg read scalar last: quaternions x, y, z, w under qw, qx, qy, qz? expected qw, qx, "
          "qy, qz (scalar first)");
}

void CheckInclinometerAgainstTracker(const FusionSetup& setup, const TrackerLog& tracker,
                                     const InclinometerLog& log) {
  const CellGeometry cell = Cell(setup);
  std::vector<Mat3> R;
  std::vector<Vec2> r;
  const auto& ref = tracker.samples;
  for (const InclinometerSample& s : log.samples) {
    const auto it = std::lower_bound(ref.begin(), ref.end(), s.time_s,
                                     [](const TrackerSample& o, double t) { return o.time_s < t; });
    const TrackerSample* best = nullptr;
    if (it != ref.end()) best = &*it;
    if (it != ref.begin() && (!best || s.time_s - std::prev(it)->time_s < best->time_s - s.time_s))
      best = &*std::prev(it);
    if (!best || std::abs(best->time_s - s.time_s) > 0.5) continue;
    R.push_back(CameraFlangePose(cell, best->T_rig_target, best->covariance).T.R);
    r.push_back(s.reading);
  }
  CheckMount(setup, R, r, log);
  // The unit checks compare readings with predictions where the sensor can read at all.
  std::vector<Vec2> p, rr;
  for (size_t i = 0; i < R.size(); ++i)
    if (setup.inclinometer.InRange(R[i])) p.push_back(setup.inclinometer.Tilt(R[i])), rr.push_back(r[i]);
  CheckTiltUnits(setup.inclinometer, p, rr, log);
}

}  // namespace mcms
