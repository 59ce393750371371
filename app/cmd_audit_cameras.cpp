// mcms audit cameras: track a recording and test every camera against the rest of the rig;
// name an inconsistent camera and the cause, and optionally write the repaired rig.
#include <cstdio>

#include "app/audit_modes.h"
#include "app/tracking_options.h"
#include "core/error.h"
#include "core/io.h"
#include "tracking/audit.h"
#include "tracking/noise_estimate.h"
#include "tracking/sequence.h"

namespace mcms::app {
namespace {

struct AuditArgs {
  std::string dir, repaired;
  double rate = 10.0;
  bool quiet = false;
  TrackerCli tracker;
};

int RunAudit(const AuditArgs& a) {
  namespace fs = std::filesystem;
  const fs::path dir = a.dir;
  if (!a.repaired.empty()) RequireWritableFile(a.repaired, "audit --repaired-rig");
  const CameraRig rig = CameraRig::Read(dir / "rig.yaml");
  const Target target = Target::Read(dir / "target.yaml");
  const ImageSequence seq = ScanImageSequence({dir / "images", dir / "frames.csv", a.rate}, rig);
  std::vector<std::string> notes;
  Tracker tracker(rig, target, a.tracker.Options(seq, rig, &notes));
  for (const auto& line : notes) std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  Progress progress("track", seq.frames.size(), a.quiet);
  const auto results = TrackImageSequence(
      seq, tracker, [&](size_t d, size_t) { progress.Update(d); }, a.tracker.Threads());
  progress.Finish();
  std::printf("%s\n", CheckPoseResiduals(results).Describe().c_str());
  const SequenceAudit audit = AuditCameras(rig, target, results);
  std::printf("%s", audit.Report().c_str());
  if (audit.worst < 0) {
    std::printf("every camera is consistent with the rest of the rig\n");
  } else if (!a.repaired.empty()) {
    if (audit.cameras[audit.worst].cause == "noise model")
      Throw("camera ", audit.cameras[audit.worst].name,
            "'s residuals are larger than the pixel noise model predicts and neither a camera move nor lens distortion "
            "explains them: check --gain and --read-noise (or leave them out to measure the noise); no repaired rig "
            "written");
    if (audit.cameras[audit.worst].cause != "camera moved")
      Throw("camera ", audit.cameras[audit.worst].name, " is inconsistent (", audit.cameras[audit.worst].cause,
            "): re-calibrate its lens (mcms calib-rig); no repaired rig written");
    RepairRig(rig, audit).Write(a.repaired);
    std::printf("wrote the rig with %s's re-estimated pose to %s\n", audit.cameras[audit.worst].name.c_str(),
                a.repaired.c_str());
  }
  return 0;
}

}  // namespace

std::pair<CLI::App*, Runner> AddAuditCameras(CLI::App& audit) {
  auto args = std::make_shared<AuditArgs>();
  CLI::App* cmd = audit.add_subcommand(
      "cameras",
      "Track a recording (as `mcms track`) and test every camera against the rest of the rig: leave-one-camera-out "
      "residuals against chi-square. An inconsistent camera is named with the cause that explains its residuals "
      "(camera moved, lens distortion, or a pixel noise model that is too optimistic), and a moved camera's pose is "
      "re-estimated. The pixel noise model is measured from the images unless --gain is given (as in `mcms track`).");
  cmd->add_option("DIR", args->dir, "recording folder (images/, rig.yaml, target.yaml, optional frames.csv)")->required();
  cmd->add_option("--repaired-rig", args->repaired, "write the rig with the re-estimated camera pose here");
  cmd->add_option("--rate", args->rate, "frame rate in Hz when there is no frames.csv")->check(CLI::PositiveNumber);
  args->tracker.Add(cmd);
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunAudit(*args); }));
}

}  // namespace mcms::app
