// mcms audit robot LOG: the robot mode of the model audit (audit/robot_audit.h): fits the
// nominal robot model (with the registration and the tool) to a log of joint values and
// externally measured tool positions, tests its residuals, names the catalog effects that
// explain them with their sizes, and measures each one's held-out gain.
#include <cstdio>
#include <filesystem>
#include <memory>

#include "app/audit_modes.h"
#include "app/commands.h"
#include "jobs/robot_audit_job.h"
#include "core/error.h"

namespace mcms::app {
namespace {

struct AuditRobotArgs {
  std::string log, robot, output, json, base_link, tip_link;
  std::vector<std::string> validate;
  std::vector<int> points;
  std::vector<std::string> only;
  std::vector<double> base_guess;
  double false_alarm = 0.01;
  int folds = 5, max_effects = 6;
  bool quiet = false;
};

int RunAuditRobot(const AuditRobotArgs& a) {
  RobotAuditJob job;
  job.log = a.log;
  job.robot = a.robot;
  job.output_dir = a.output;
  job.json = a.json;
  job.chain = {a.base_link, a.tip_link};
  job.points = a.points;
  for (const auto& v : a.validate) job.validate.push_back(v);
  job.options.only = a.only;
  job.options.false_alarm = a.false_alarm;
  job.options.folds = a.folds;
  job.options.max_effects = a.max_effects;
  if (!a.base_guess.empty()) job.options.base_guess = PoseFromArgs(a.base_guess, "audit robot", "--base-guess");
  std::string why;
  if (!job.options.IsValid(&why)) Throw("audit robot: ", why);
  RunRobotAuditJob(job, CommandOutput("audit robot", a.quiet));
  if (!a.output.empty())
    std::printf("wrote %s (report.txt, report.json, robot.yaml%s, residuals.csv, plots/%s%s)\n", a.output.c_str(),
                std::filesystem::exists(std::filesystem::path(a.output) / "robot.urdf") ? ", robot.urdf" : "",
                std::filesystem::exists(std::filesystem::path(a.output) / "next_poses.csv") ? ", next_poses.csv" : "",
                std::filesystem::exists(std::filesystem::path(a.output) / "validation.csv") ? ", validation.csv" : "");
  if (!a.json.empty()) std::printf("wrote %s\n", a.json.c_str());
  return 0;
}

}  // namespace

std::pair<CLI::App*, Runner> AddAuditRobot(CLI::App& audit) {
  auto args = std::make_shared<AuditRobotArgs>();
  CLI::App* cmd = audit.add_subcommand(
      "robot",
      "Audit a robot model against a measurement log: CSV time_s,q1_rad..qN_rad,x_m,y_m,z_m [,qw,qx,qy,qz] "
      "[,temperature_c] [,payload_kg] (or a calib-robot YAML file). The registration to the robot base and the tool "
      "are fitted; the noise (anisotropic, unknown) is estimated, from repeated poses where there are any. Geometry "
      "first: the DH parameters the poses identify, one by one (joint_offset, link_length, link_twist) or all at once "
      "(geometry); then the effects of the catalog on top of the whole geometry (gravity_compliance: the arm's own "
      "weight and the payload, from the robot file's link masses or lumped masses when it has none; joint_scale, "
      "thermal_drift, backlash, error_motion) that earn their parameters on held-out data, with size +- sigma. "
      "Candidates the data cannot tell apart are reported undecided with both sizes, and -o writes the poses that "
      "would separate them (next_poses.csv).");
  cmd->add_option("LOG", args->log,
                  "measurement log: CSV (time, joint columns q1_rad.. or the robot's joint names, x_m,y_m,z_m or "
                  "x1,y1,z1..xK,yK,zK of K points of one rigid body) or calib-robot YAML")
      ->required();
  cmd->add_option("--robot", args->robot,
                  "robot description: YAML (model/robots format, optionally with link masses: "
                  "examples/robots/ur10_like.yaml) or URDF (masses from its inertials); default: the built-in KUKA "
                  "KR 5 arc");
  cmd->add_option("--base-link", args->base_link, "URDF: the chain's base link (default: the URDF's root)");
  cmd->add_option("--tip-link", args->tip_link,
                  "URDF: the chain's tip link, where the measured points are fixed (default: the unambiguous leaf)");
  cmd->add_option("--points", args->points,
                  "use only these points of a rigid body (1-based, e.g. 1 for FIGAROH's point-1 protocol; default: "
                  "all, whose pose is then audited)")
      ->delimiter(',');
  cmd->add_option("--validate", args->validate,
                  "other sessions (one or more files): scored with the fitted models (registration, geometry, "
                  "final) frozen, the instrument placed anew per station or where it moved; mean, median, RMS, "
                  "95 % and max per point and posture group")
      ->expected(1, -1);
  cmd->add_option("-o,--output", args->output,
                  "output folder: report.txt, report.json, robot.yaml, residuals.csv, plots/, next_poses.csv (when a "
                  "pair is undecided)");
  cmd->add_option("--json", args->json, "write the machine-readable report here");
  cmd->add_option("--only", args->only, "test only these catalog effects (names)");
  cmd->add_option("--base-guess", args->base_guess, "starting T_meas_base: x y z qw qx qy qz (m)")->expected(7);
  cmd->add_option("--false-alarm", args->false_alarm,
                  "designed probability that a clean log is called not clean (default 0.01)");
  cmd->add_option("--folds", args->folds, "time-blocked cross-validation folds (default 5)");
  cmd->add_option("--max-effects", args->max_effects, "at most this many non-geometric effects (default 6)");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunAuditRobot(*args); }));
}

}  // namespace mcms::app
