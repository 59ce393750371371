#include "fusion/log_audit.h"

#include <vector>

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
  return AuditInclinometer(setup.inclinometer, reference, readings, options, shape);
}

}  // namespace mcms
