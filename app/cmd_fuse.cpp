// mcms fuse: the user's tracker poses, robot joint log and inclinometer log fused into
// T_base_flange per camera frame or per window (fusion/log_fusion.h, fusion/stream_fusion.h;
// formats in fusion/sensor_logs.h).
#include <cstdio>
#include <memory>
#include <string>

#include "app/commands.h"
#include "core/error.h"
#include "core/io.h"
#include "fusion/log_fusion.h"

namespace mcms::app {
namespace {

struct FuseArgs {
  std::string tracker, robot, inclinometer, setup, windows, output, method = "both";
  bool quiet = false;
};

int RunFuse(const FuseArgs& a) {
  RequireWritableFile(a.output, "fuse -o");  // every input is then read and checked before anything is written
  FuseFilesRequest r;
  r.tracker = a.tracker;
  r.robot = a.robot;
  r.inclinometer = a.inclinometer;
  r.setup = a.setup;
  r.windows = a.windows;
  r.moifa = a.method != "kf";
  r.kalman = a.method != "moifa";
  r.output = a.output;
  const FuseFilesResult res = FuseLogFiles(r);
  for (const std::string& line : res.dropped) std::fprintf(stderr, "mcms fuse: warning: %s\n", line.c_str());
  if (!a.quiet) {
    int flagged = 0, excluded = 0;
    for (const auto& row : res.rows) {
      flagged += row.flagged.empty() ? 0 : 1;
      excluded += row.excluded.empty() && row.fault.empty() ? 0 : 1;
    }
    const std::string windows =
        res.windows.empty() ? std::string() : " over " + std::to_string(res.windows.size()) + " windows";
    std::printf(
        "fused %zu tracked frames (%d lost rows skipped)%s by %s: %zu rows, %d with a flagged sensor, %d with a sensor "
        "or samples left out as inconsistent (columns excluded, fault) -> %s\n",
        res.logs.tracker.samples.size(), res.logs.tracker.lost_rows, windows.c_str(), a.method.c_str(), res.rows.size(),
        flagged, excluded, a.output.c_str());
  }
  return 0;
}

McmsCommand fuse_command([](CLI::App& app) {
  auto args = std::make_shared<FuseArgs>();
  CLI::App* cmd = app.add_subcommand(
      "fuse",
      "Fuse recorded tracker poses, robot joints and inclinometer readings into the flange pose T_base_flange "
      "at every tracked camera frame, by MOIFA per frame and/or one Kalman filter over all samples; with "
      "--windows, once per window in which the robot stands still (fusion/stream_fusion.h).");
  cmd->add_option("--tracker", args->tracker,
                  "tracker pose CSV as written by `mcms track`: frame,time_s,status,...,x_m,y_m,z_m,qw,qx,qy,qz,...,"
                  "cov_<a>_<b> (a,b in rx,ry,rz,px,py,pz; T_rig_target, [dtheta; dp] covariance in the rig frame); "
                  "lost rows are skipped")
      ->required();
  cmd->add_option("--robot", args->robot,
                  "robot joint log CSV: time_s,q1_rad,...,qN_rad (N = joints of the setup's robot; q<i>_deg "
                  "accepted, q<i>_m for prismatic joints; or the robot's joint names); readings within the joint limits");
  cmd->add_option("--inclinometer", args->inclinometer,
                  "inclinometer log CSV: time_s,tilt_x_rad,tilt_y_rad (or _deg): angle of each sensor axis above "
                  "the horizontal, bias included");
  cmd->add_option("--setup", args->setup,
                  "setup YAML: robot (file, default KUKA KR 5 arc), T_base_rig and T_flange_target "
                  "(translation_m, quaternion_wxyz; T_base_rig may add sigma_rotation_rad, sigma_translation_m), "
                  "inclinometer (quaternion_wxyz = R_flange_incl, bias_rad, sigma_rad, period_s, range_deg), "
                  "robot_accuracy (position_sigma_m [x,y,z], orientation_sigma_rad), kalman "
                  "(angular_acceleration_psd, linear_acceleration_psd, nis_gate_probability), "
                  "consistency_significance. Full format: fusion/sensor_logs.h")
      ->required();
  cmd->add_option("-o,--output", args->output,
                  "fused pose CSV, written atomically: frame,time_s,method (moifa|kf),x_m,y_m,z_m,qw,qx,qy,qz "
                  "(T_base_flange),sensors,dof,p_value,flagged (';'-separated sensor names),excluded (sensors or "
                  "samples left out as inconsistent: leave-one-out when a MOIFA row's test fails, gated KF "
                  "updates, inclinometer readings beyond range),fault (why; quoted text),cov_<a>_<b> (36, "
                  "[dtheta; dp] in the base frame)")
      ->required();
  cmd->add_option("--windows", args->windows,
                  "windows CSV start_s,end_s (time order, not overlapping) over which the robot stands still: one "
                  "fused row per window instead of per camera frame (frame = window index, time_s = its end); the "
                  "KF restarts in each window (fusion/stream_fusion.h). `mcms demo` writes its dwells so.");
  cmd->add_option("--method", args->method, "moifa, kf or both (default both)")
      ->check(CLI::IsMember({"moifa", "kf", "both"}));
  cmd->add_flag("-q,--quiet", args->quiet, "no summary on stdout");
  return std::make_pair(cmd, Runner([args] {
                          if (args->robot.empty() && args->inclinometer.empty())
                            Throw("mcms fuse: give --robot and/or --inclinometer besides --tracker");
                          return RunFuse(*args);
                        }));
});

}  // namespace
}  // namespace mcms::app
