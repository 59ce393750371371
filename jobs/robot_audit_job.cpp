#include "jobs/robot_audit_job.h"

#include "audit/robot_audit.h"
#include "audit/tilt_sensor_audit.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"

namespace mcms {

void RunRobotAuditJob(const RobotAuditJob& job, const JobOutput& out) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  std::vector<std::filesystem::path> inputs{job.log, job.robot};
  inputs.insert(inputs.end(), job.validate.begin(), job.validate.end());
  RequireOutputsSpareInputs({{job.output_dir, "audit robot -o", true}, {job.json, "audit robot --json"}}, inputs);
  if (!job.output_dir.empty())
    RequireReplaceableFolder(job.output_dir, {"report.json"}, "audit robot", "audit robot -o");
  if (!job.json.empty()) RequireWritableFile(job.json, "audit robot --json");
  if (job.robot.empty() && (!job.chain.base_link.empty() || !job.chain.tip_link.empty()))
    Throw("audit robot: --base-link and --tip-link pick a chain of a URDF robot; give it with --robot");
  const RobotModel described = job.robot.empty() ? RobotModel::Default() : RobotModel::Read(job.robot, job.chain);
  const RobotLog log = KeepPoints(ReadRobotLog(job.log, described), job.points, "audit robot --points");
  std::vector<RobotLog> validate;
  for (const auto& v : job.validate)
    validate.push_back(KeepPoints(ReadRobotLog(v, described), job.points, "audit robot --points"));
  std::vector<const RobotLog*> logs{&log};
  for (const auto& v : validate) logs.push_back(&v);
  std::vector<std::string> reading_notes;
  const RobotModel robot = CoverReadings(described, logs, &reading_notes);
  RobotAuditOptions options = job.options;
  if (out.progress) options.progress = out.progress;
  RobotAuditResult r = AuditRobot(robot, log, options, validate);
  r.report.notes.insert(r.report.notes.begin(), reading_notes.begin(), reading_notes.end());
  // Tilt sensors on the chain (issue 52): their readings against their forward model.
  TiltSensorAuditOptions tilt_options;
  tilt_options.false_alarm = job.options.false_alarm;
  const std::vector<TiltSensorAuditResult> tilt = AuditTiltSensors(robot, log, tilt_options);
  const std::string report = RobotAuditText(r, log, robot, tilt);
  if (!job.output_dir.empty())
    WriteFolderAtomically(job.output_dir, {"report.json"}, "audit robot", "audit robot -o",
                          [&](const std::filesystem::path& dir) { WriteRobotAuditFolder(dir, r, log, robot, tilt, report); });
  if (!job.json.empty()) WriteRobotAuditJson(job.json, r, tilt);
  out.Print(report);
}

}  // namespace mcms
