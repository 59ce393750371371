// mcms audit fusion: the fusion-log mode of the model audit. The inputs of `mcms fuse`
// (tracker poses, the robot's joint log, the setup) give, at every tracked frame, two
// independent views of the flange: the camera rig's measured target pose and the robot's
// joints. They form a 6-D robot measurement log in the rig frame (meas = rig, tool = the
// setup's T_flange_target, registration starting at T_base_rig^-1), which the robot audit
// (audit/robot_audit.h) tests: the robot catalog plus clock_offset between the joint log
// and the tracker (joint velocities from the log). With --inclinometer, the inclinometer's
// readings are audited against the tracker's flange orientation (audit/inclinometer_audit.h:
// inclinometer_bias, inclinometer_misalignment, clock_offset / clock_drift of its log);
// the designed false-alarm rate is then split evenly between the two audits.
#include <cstdio>
#include <memory>

#include "app/audit_modes.h"
#include "jobs/fusion_audit_job.h"

namespace mcms::app {
namespace {

struct AuditFusionArgs {
  std::string tracker, robot, inclinometer, setup, json, output;
  double false_alarm = 0.01;
  bool quiet = false;
};

int RunAuditFusion(const AuditFusionArgs& a) {
  FusionAuditJob job;
  job.tracker = a.tracker;
  job.robot = a.robot;
  job.inclinometer = a.inclinometer;
  job.setup = a.setup;
  job.json = a.json;
  job.output = a.output;
  job.false_alarm = a.false_alarm;
  RunFusionAuditJob(job, CommandOutput("audit fusion", a.quiet));
  return 0;
}

}  // namespace

std::pair<CLI::App*, Runner> AddAuditFusion(CLI::App& audit) {
  auto args = std::make_shared<AuditFusionArgs>();
  CLI::App* cmd = audit.add_subcommand(
      "fusion",
      "Audit the inputs of `mcms fuse`: the tracker's poses against the robot's joints through the setup's registration "
      "and target mount (the robot catalog, and clock_offset between the joint log and the tracker); with "
      "--inclinometer, its readings against the tracker's flange orientation (inclinometer_bias, "
      "inclinometer_misalignment, clock_offset / clock_drift of its log).");
  cmd->add_option("--tracker", args->tracker, "tracker poses CSV (mcms track's poses.csv)")->required();
  cmd->add_option("--robot", args->robot, "robot joint log CSV (time_s,q1_rad..)")->required();
  cmd->add_option("--inclinometer", args->inclinometer, "inclinometer log CSV (time_s,tilt_x_<unit>,tilt_y_<unit>): audited against the tracker");
  cmd->add_option("--setup", args->setup, "setup YAML (as for mcms fuse)")->required();
  cmd->add_option("--json", args->json, "write the machine-readable report here");
  cmd->add_option("-o,--output", args->output,
                  "output folder: report.txt, report.json, inclinometer_residuals.csv, plots/*.svg");
  cmd->add_option("--false-alarm", args->false_alarm, "designed false-alarm rate on clean logs (default 0.01)");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunAuditFusion(*args); }));
}

}  // namespace mcms::app
