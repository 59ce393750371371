// mcms track: image sequence + rig + target -> one CSV row per frame with the pose
// and its 6x6 covariance.
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>

#include "core/limits.h"
#include "app/commands.h"
#include "app/tracking_options.h"
#include "core/error.h"
#include "core/io.h"
#include "jobs/track_recording.h"

namespace mcms::app {

void TrackerCli::Add(CLI::App* cmd) {
  cmd->add_option("--gain", gain_e_per_dn,
                  "camera gain in electrons per DN, for the photon-noise part of the centre covariance (0 = leave "
                  "it out); default: measured per camera from the balls' images in the recording")
      ->check(NonNegativeNumber());
  cmd->add_option("--read-noise", read_noise_dn,
                  "noise std of a background pixel in DN (0 = measure it around each blob)")
      ->check(NonNegativeNumber() & CLI::Range(0.0, kMaxImageDn));
  cmd->add_option("--polarity", polarity, "blobs brighter (bright) or darker (dark) than the background")
      ->check(CLI::IsMember({"bright", "dark"}));
  cmd->add_option("--threshold", threshold_dn, "detection threshold in DN beyond the background (0 = automatic)")
      ->check(NonNegativeNumber() & CLI::Range(0.0, kMaxImageDn));
  cmd->add_option("--noise-frames", noise_frames,
                  "frames (spread over the recording) from which the gain is measured when --gain is not given")
      ->check(PositiveNumber());
  cmd->add_option("--threads", threads, "threads for reading images and detecting blobs (0 = all cores)")
      ->check(CLI::Range(0, kMaxThreads));
  cmd->add_flag("--predicted-windows", predicted_windows,
                "detect balls only in windows around the images the track predicts (about 1.4x the frame rate "
                "of images in memory; the same poses where the windows hold every ball); the whole image every "
                "25th frame, when a camera's windows miss a ball it saw in the last frame, and when there is no "
                "prediction. Blobs outside the windows (spurious reflections) are then not reported");
}

int TrackerCli::Threads() const {
  return ThreadsToUse(threads);
}

RecordingTrackerSettings TrackerCli::Settings() const {
  RecordingTrackerSettings s;
  s.gain_e_per_dn = gain_e_per_dn;
  s.read_noise_dn = read_noise_dn;
  s.polarity = polarity == "dark" ? Polarity::kDark : Polarity::kBright;
  s.threshold_dn = threshold_dn;
  s.noise_frames = noise_frames;
  s.threads = Threads();
  s.predicted_windows = predicted_windows;
  return s;
}

namespace {

struct TrackArgs {
  std::string dir;
  std::string images, rig, target, frames_csv, output, truth;
  double rate = 0;  // not given
  bool quiet = false;
  TrackerCli tracker;
};

int RunTrack(const TrackArgs& a) {
  TrackRecordingInput in;
  in.dir = a.dir;
  in.images = a.images;
  in.rig = a.rig;
  in.target = a.target;
  in.frames_csv = a.frames_csv;
  in.output = a.output;
  in.output_what = "track -o";
  in.truth = a.truth;
  in.rate_hz = a.rate;
  in.tracker = a.tracker.Settings();
  std::unique_ptr<Progress> progress;
  const TrackRecordingResult r = TrackRecording(
      in,
      [&](const std::string& line) {
        std::printf("%s\n", line.c_str());
        std::fflush(stdout);
      },
      [&](size_t done, size_t total) {
        if (!progress) progress = std::make_unique<Progress>("track", total, a.quiet);
        progress->Update(done);
      });
  if (progress) progress->Finish();
  std::printf("tracked %zu frames: %d ok, %d degraded, %d lost -> %s\n", r.frames, r.ok, r.degraded, r.lost,
              r.output.string().c_str());
  return 0;
}

McmsCommand track_command([](CLI::App& app) {
  auto args = std::make_shared<TrackArgs>();
  CLI::App* cmd = app.add_subcommand(
      "track",
      "Track the five-ball target through a multi-camera image sequence: detect, match, triangulate, identify, "
      "bundle-adjust. Writes one CSV row per frame: frame, time_s, status (ok/degraded/lost) and reason, position "
      "x_m,y_m,z_m and orientation qw,qx,qy,qz of T_rig_target, diagnostics, and the 6x6 pose covariance "
      "cov_<a>_<b> in the [rotation rx,ry,rz (rad); position px,py,pz (m)] layout of docs/conventions.md. The "
      "pixel-noise model the covariances assume is measured from the images unless --gain is given, printed, and "
      "written as '#' lines at the top of the CSV with the check of the pose fits' residuals.");
  cmd->add_option("DIR", args->dir,
                  "recording folder holding images/<camera>/<frame>.png, rig.yaml, target.yaml and optionally "
                  "frames.csv (what `mcms render` writes)");
  cmd->add_option("--images", args->images, "image folder (default DIR/images)");
  cmd->add_option("--rig", args->rig, "rig file (default DIR/rig.yaml)");
  cmd->add_option("--target", args->target, "target file (default DIR/target.yaml)");
  cmd->add_option("--frames", args->frames_csv, "frame times CSV with columns frame,time_s (default DIR/frames.csv)");
  cmd->add_option("--rate", args->rate,
                  "frame rate in Hz when there is no frames CSV (0.001 to 1e6); without either, frames are taken "
                  "10 Hz apart and the run says so")
      ->check(PositiveNumber());
  cmd->add_option("-o,--output", args->output, "output CSV (default DIR/poses.csv)");
  cmd->add_option("--truth", args->truth,
                  "truth file of T_rig_target per frame with columns frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz (what "
                  "`mcms render` writes as DIR/truth/poses.csv); adds the columns err_pos_mm, err_rot_deg (norms of "
                  "the [rotation; position] error of the tracked pose against the truth) and nees (that error "
                  "squared, normalized by the frame's covariance) to the output, and prints the mean NEES against "
                  "its chi-square band; every frame of the recording needs a truth row at the same time; 'auto' = "
                  "DIR/truth/poses.csv when it exists");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  args->tracker.Add(cmd);
  return std::make_pair(cmd, Runner([args] { return RunTrack(*args); }));
});

}  // namespace
}  // namespace mcms::app
