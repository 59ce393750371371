// mcms audit fusion: the fusion-log mode of the model audit. The inputs of `mcms fuse`
// (tracker poses, the robot's joint log, the setup) give, at every tracked frame, two
// independent views of the flange: the camera rig's measured target pose and the robot's
// joints. They form a 6-D robot measurement log in the rig frame (meas = rig, tool = the
// setup's T_flange_target, registration starting at T_base_rig^-1), which the robot audit
// (calib/robot_audit.h) tests: the robot catalog plus clock_offset between the joint log
// and the tracker (joint velocities from the log). With --inclinometer, the inclinometer's
// readings are audited against the tracker's flange orientation (calib/inclinometer_audit.h:
// inclinometer_bias, inclinometer_misalignment, clock_offset / clock_drift of its log);
// the designed false-alarm rate is then split evenly between the two audits.
#include <cstdio>
#include <memory>

#include "app/audit_modes.h"
#include "calib/robot_audit.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "fusion/log_audit.h"
#include "fusion/sensor_logs.h"

namespace mcms::app {
namespace {

struct AuditFusionArgs {
  std::string tracker, robot, inclinometer, setup, json, output;
  double false_alarm = 0.01;
  bool quiet = false;
};

int RunAuditFusion(const AuditFusionArgs& a) {
  if (!a.json.empty()) RequireWritableFile(a.json, "audit fusion --json");
  if (!a.output.empty()) RequireReplaceableFolder(a.output, {"report.json"}, "audit fusion", "audit fusion -o");
  const FusionSetup setup = ReadFusionSetup(a.setup);
  const TrackerLog tracker = ReadTrackerLog(a.tracker);
  const JointLog joints = ReadJointLog(a.robot, setup.robot);
  const bool with_incl = !a.inclinometer.empty();
  InclinometerLog incl_log;
  if (with_incl) incl_log = ReadInclinometerLog(a.inclinometer);
  RobotModel robot = setup.robot;
  robot.SetT_flange_tool(setup.T_flange_target);
  RobotLog log;
  log.source = a.tracker;
  log.has_time = true;
  for (const TrackerSample& s : tracker.samples) {
    Eigen::VectorXd q, qa, qb;
    if (!joints.Interpolate(s.time_s, &q)) continue;
    RobotLogRow r;
    r.time_s = s.time_s;
    r.q = q;
    r.p_meas = s.T_rig_target.t;
    r.R_meas_tool = s.T_rig_target.R;
    r.line = s.line;
    const double h = 0.01;
    if (joints.Interpolate(s.time_s - h, &qa) && joints.Interpolate(s.time_s + h, &qb)) r.qdot = (qb - qa) / (2 * h);
    log.rows.push_back(r);
  }
  if (static_cast<int>(log.rows.size()) < kMinRobotLogRows)
    Throw("audit fusion: only ", log.rows.size(), " tracked frames of ", a.tracker, " fall within the joint log ", a.robot,
          "'s time span; the audit needs at least ", kMinRobotLogRows, " (are the two logs on the same clock?)");
  RobotAuditJob job;
  job.options.false_alarm = with_incl ? a.false_alarm / 2 : a.false_alarm;
  job.options.base_guess = setup.T_base_rig.Inverse();
  if (!a.quiet) job.options.progress = [](const std::string& s) { std::fprintf(stderr, "audit fusion: %s\n", s.c_str()); };
  RobotAuditResult r = AuditRobot(robot, log, job.options);
  r.report.mode = "fusion";
  for (auto& e : r.report.effects)
    if (e.name == "clock_offset") e.where = "robot";
  InclinometerAuditResult ir;
  if (with_incl) {
    InclinometerAuditOptions io;
    io.false_alarm = a.false_alarm / 2;
    io.progress = job.options.progress;
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
  std::printf("%s", text.c_str());
  if (!a.output.empty()) {
    WriteFolderAtomically(a.output, {"report.json"}, "audit fusion", "audit fusion -o",
                          [&](const std::filesystem::path& dir) {
                            WriteFileAtomically(dir / "report.txt", [&](std::ostream& os) { os << text; });
                            if (with_incl) WriteInclinometerAuditFiles(ir, dir);
                            r.report.WriteJson(dir / "report.json");
                          });
    std::printf("wrote %s\n", a.output.c_str());
  }
  if (!a.json.empty()) {
    r.report.WriteJson(a.json);
    std::printf("wrote %s\n", a.json.c_str());
  }
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
