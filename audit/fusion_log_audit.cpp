#include "audit/fusion_log_audit.h"

#include "fusion/stream_fusion.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"

namespace mcms {

namespace {

// Readings in radians under _deg headers (or degrees under _rad): the readings against the
// tilts the tracker measured (each reading paired with the tracked frame nearest in time,
// within 0.5 s) have a slope of 1/57.3 (or 57.3) instead of 1. Refused with the unit named
// before any fit: the audit of such a log would only find a misfit of hundreds of sigma.
void CheckTiltUnits(const Inclinometer& incl, const std::vector<OrientationReference>& reference,
                    const InclinometerLog& log) {
  std::vector<Vec2> p, r;
  for (const InclinometerSample& s : log.samples) {
    const auto it = std::lower_bound(reference.begin(), reference.end(), s.time_s,
                                     [](const OrientationReference& o, double t) { return o.time_s < t; });
    const OrientationReference* best = nullptr;
    if (it != reference.end()) best = &*it;
    if (it != reference.begin() && (!best || s.time_s - std::prev(it)->time_s < best->time_s - s.time_s))
      best = &*std::prev(it);
    if (!best || std::abs(best->time_s - s.time_s) > 0.5) continue;
    p.push_back(incl.Tilt(best->R_base_flange));
    r.push_back(s.reading);
  }
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

}  // namespace

InclinometerAuditResult AuditInclinometerLogs(const FusionSetup& setup, const TrackerLog& tracker,
                                              const InclinometerLog& inclinometer, const JointLog* motion,
                                              const InclinometerAuditOptions& options) {
  CellGeometry cell;
  cell.T_base_rig = setup.T_base_rig;
  cell.T_base_rig_covariance = setup.T_base_rig_covariance;
  cell.T_flange_target = setup.T_flange_target;
  std::vector<OrientationReference> reference;
  reference.reserve(tracker.samples.size());
  for (const TrackerSample& s : tracker.samples)
    reference.push_back(CameraOrientationReference(cell, s.time_s, s.T_rig_target, s.covariance, s.line));
  std::vector<InclinometerReadingSample> readings;
  readings.reserve(inclinometer.samples.size());
  for (const InclinometerSample& s : inclinometer.samples) readings.push_back({s.time_s, s.reading, s.line});
  std::vector<OrientationSample> shape;
  if (motion)
    for (const JointSample& s : motion->samples) shape.push_back({s.time_s, setup.robot.T_base_flange(s.q).R});
  CheckTiltUnits(setup.inclinometer, reference, inclinometer);
  return AuditInclinometer(setup.inclinometer, reference, readings, options, shape);
}

RobotLog TrackerAgainstJoints(const TrackerLog& tracker, const JointLog& joints, const std::string& tracker_name,
                              const std::string& joints_name) {
  RobotLog log;
  log.source = tracker_name;
  log.has_time = true;
  for (const TrackerSample& s : tracker.samples) {
    Eigen::VectorXd q, qa, qb;
    if (!joints.Interpolate(s.time_s, &q)) continue;
    RobotMeasurement r;
    r.time_s = s.time_s;
    r.q = q;
    r.p_meas = s.T_rig_target.t;
    r.R_meas_tool = s.T_rig_target.R;
    r.line = s.line;
    const double h = 0.01;
    if (joints.Interpolate(s.time_s - h, &qa) && joints.Interpolate(s.time_s + h, &qb)) r.qdot = (qb - qa) / (2 * h);
    log.rows.push_back(r);
  }
  if (static_cast<int>(log.rows.size()) < kMinRobotMeasurements)
    Throw("audit fusion: only ", log.rows.size(), " tracked frames of ", tracker_name, " fall within the joint log ",
          joints_name, "'s time span; the audit needs at least ", kMinRobotMeasurements,
          " (are the two logs on the same clock?)");
  return log;
}

void RunFusionAuditJob(const FusionAuditJob& a, const std::function<void(const std::string&)>& print,
                       const std::function<void(const std::string&)>& progress) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  const FusionSetup setup = ReadFusionSetup(a.setup);  // (and the robot file it names: an input too)
  RequireOutputsSpareInputs({{a.output, "audit fusion -o", true}, {a.json, "audit fusion --json"}},
                            {a.tracker, a.robot, a.inclinometer, a.setup});
  if (!a.json.empty()) RequireWritableFile(a.json, "audit fusion --json");
  if (!a.output.empty()) RequireReplaceableFolder(a.output, {"report.json"}, "audit fusion", "audit fusion -o");
  const TrackerLog tracker = ReadTrackerLog(a.tracker);
  const JointLog joints = ReadJointLog(a.robot, setup.robot);
  const bool with_incl = !a.inclinometer.empty();
  InclinometerLog incl_log;
  if (with_incl) incl_log = ReadInclinometerLog(a.inclinometer);
  {
    SensorLogs logs{tracker, joints, std::nullopt};
    if (with_incl) logs.inclinometer = incl_log;
    CheckTimeOverlap(logs);  // one clock, one unit of time (fusion/stream_fusion.h)
  }
  RobotModel robot = setup.robot;
  robot.SetT_flange_tool(setup.T_flange_target);
  const RobotLog log = TrackerAgainstJoints(tracker, joints, a.tracker, a.robot);
  RobotAuditOptions options;
  options.false_alarm = with_incl ? a.false_alarm / 2 : a.false_alarm;
  options.base_guess = setup.T_base_rig.Inverse();
  options.progress = progress;
  RobotAuditResult r = AuditRobot(robot, log, options);
  r.report.mode = "fusion";
  for (auto& e : r.report.effects)
    if (e.name == "clock_offset") e.where = "robot";
  InclinometerAuditResult ir;
  if (with_incl) {
    InclinometerAuditOptions io;
    io.false_alarm = a.false_alarm / 2;
    io.progress = progress;
    try {
      // The robot's joint log gives the motion's shape between the tracker's frames.
      ir = AuditInclinometerLogs(setup, tracker, incl_log, &joints, io);
    } catch (const InputError& e) {
      Throw(a.inclinometer, " against ", a.tracker, ": ", e.what());
    }
    r.report.Merge(ir.report);
  }
  std::string text;
  {
    char b[512];
    std::snprintf(b, sizeof b, "fusion logs: %zu tracked frames with joint values (tracker %s, robot %s)\n",
                  log.rows.size(), a.tracker.c_str(), a.robot.c_str());
    text += b;
    if (with_incl) {
      std::snprintf(b, sizeof b,
                    "inclinometer %s: %zu readings, %zu of them between two tracked frames used (every other "
                    "pair of frames)\n",
                    a.inclinometer.c_str(), incl_log.samples.size(), ir.rows.size());
      text += b;
    }
  }
  text += r.report.Text();
  print(text);
  if (!a.output.empty()) {
    WriteFolderAtomically(a.output, {"report.json"}, "audit fusion", "audit fusion -o",
                          [&](const std::filesystem::path& dir) {
                            WriteFileAtomically(dir / "report.txt", [&](std::ostream& os) { os << text; });
                            if (with_incl) WriteInclinometerAuditFiles(ir, dir);
                            if (!r.next_poses.empty()) WriteNextPoses(dir / "next_poses.csv", r, robot);
                            r.report.WriteJson(dir / "report.json");
                          });
    print("wrote " + a.output + "\n");
  }
  if (!a.json.empty()) {
    r.report.WriteJson(a.json);
    print("wrote " + a.json + "\n");
  }
}

}  // namespace mcms
