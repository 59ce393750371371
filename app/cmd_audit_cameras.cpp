// mcms audit cameras: track a recording, test every camera against the rest of the rig and
// name what the camera model gets wrong from the catalog of model/extensions.h
// (audit/camera_audit.h); optionally write the report as JSON, the extended rig and the
// extended target.
#include <cmath>
#include <cstdio>

#include "app/audit_modes.h"
#include "app/commands.h"
#include "app/tracking_options.h"
#include "jobs/camera_audit_job.h"

namespace mcms::app {
namespace {

struct AuditArgs {
  std::string dir, repaired, repaired_target, json, output;
  CameraAuditOptions audit;
  double rate = 10.0;
  bool quiet = false;
  TrackerCli tracker;
};

int RunAudit(const AuditArgs& a) {
  CameraAuditJob job;
  job.recording = a.dir;
  job.repaired_rig = a.repaired;
  job.repaired_target = a.repaired_target;
  job.json = a.json;
  job.output = a.output;
  job.audit = a.audit;
  job.rate_hz = a.rate;
  job.quiet = a.quiet;
  job.tracker = a.tracker.Settings();
  RunCameraAuditJob(job, CommandOutput("audit cameras", a.quiet));
  return 0;
}

}  // namespace

std::pair<CLI::App*, Runner> AddAuditCameras(CLI::App& audit) {
  auto args = std::make_shared<AuditArgs>();
  CLI::App* cmd = audit.add_subcommand(
      "cameras",
      "Track a recording (as `mcms track`) and audit the camera model: every camera is tested against the rest of the "
      "rig (leave-one-camera-out residuals, chi-square), then the catalog of model extensions is fitted camera by "
      "camera and ball by ball (pixel_noise_scale first, camera_moved, also from a change time on, focal_length, "
      "principal_point, radial_distortion, camera_time_offset, target_geometry), scored on held-out blocks of time "
      "and by BIC; greedy forward selection names the effects that earn their place, with size, sigma and held-out "
      "gain, and says when two candidates explain the residuals equally. The pixel noise model is measured from the "
      "images unless --gain is given (as in `mcms track`).");
  cmd->add_option("DIR", args->dir, "recording folder (images/, rig.yaml, target.yaml, optional frames.csv)")->required();
  cmd->add_option("--repaired-rig", args->repaired,
                  "write the rig extended by the effects found here (moved poses, focal length, principal point, k1)");
  cmd->add_option("--repaired-target", args->repaired_target,
                  "write the target with the ball positions found (target_geometry) here");
  cmd->add_option("-o,--output", args->output,
                  "output folder: report.txt, report.json, residuals.csv (whitened residuals with their covariates), "
                  "plots/<camera>.svg (residuals against time, distance from the image centre, distance to the camera, "
                  "image u and v, and as vectors over the image)");
  cmd->add_option("--json", args->json, "write the audit report as JSON here (mode, nominal, clean, effects, undecided)");
  cmd->add_option("--false-alarm", args->audit.false_alarm,
                  "designed probability of naming an effect on a recording without one")
      ->check(CLI::Range(1e-6, 0.5))
      ->capture_default_str();
  cmd->add_option("--noise-tolerance", args->audit.noise_tolerance,
                  "relative error of the pixel noise sigma accepted before pixel_noise_scale is named")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  cmd->add_option("--folds", args->audit.folds, "k of the k-fold cross-validation (blocks of time)")
      ->check(CLI::Range(2, 50))
      ->capture_default_str();
  cmd->add_option("--rate", args->rate, "frame rate in Hz when there is no frames.csv")->check(PositiveNumber());
  args->tracker.Add(cmd);
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunAudit(*args); }));
}

}  // namespace mcms::app
