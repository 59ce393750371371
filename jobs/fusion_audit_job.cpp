#include "jobs/fusion_audit_job.h"

#include <cstdio>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "fusion/log_checks.h"
#include "fusion/stream_fusion.h"

namespace mcms {

void RunFusionAuditJob(const FusionAuditJob& a, const JobOutput& out) {
  const std::function<void(const std::string&)>& progress = out.progress;
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
  CheckTrackerAgainstJoints(setup, tracker, joints);  // before any misfit is blamed on the robot
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
  out.Print(text);
  if (!a.output.empty()) {
    WriteFolderAtomically(a.output, {"report.json"}, "audit fusion", "audit fusion -o",
                          [&](const std::filesystem::path& dir) {
                            WriteFileAtomically(dir / "report.txt", [&](std::ostream& os) { os << text; });
                            if (with_incl) WriteInclinometerAuditFiles(ir, dir);
                            if (!r.next_poses.empty()) WriteNextPoses(dir / "next_poses.csv", r, robot);
                            r.report.WriteJson(dir / "report.json");
                          });
    out.Print("wrote " + a.output + "\n");
  }
  if (!a.json.empty()) {
    r.report.WriteJson(a.json);
    out.Print("wrote " + a.json + "\n");
  }
}

}  // namespace mcms
