#include "audit/fusion_log_audit.h"

#include "fusion/log_checks.h"
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
  CheckInclinometerAgainstTracker(setup, tracker, inclinometer);
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

}  // namespace mcms
