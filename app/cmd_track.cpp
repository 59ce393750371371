// mcms track: image sequence + rig + target -> one CSV row per frame with the pose
// and its 6x6 covariance.
#include <cstdio>
#include <thread>

#include "app/commands.h"
#include "app/tracking_options.h"
#include "core/error.h"
#include "core/io.h"
#include "tracking/sequence.h"

namespace mcms::app {

void TrackerCli::Add(CLI::App* cmd) {
  cmd->add_option("--gain", gain_e_per_dn,
                  "camera gain in electrons per DN, for the photon-noise part of the centre covariance (0 = leave "
                  "it out); default: measured per camera from the balls' images in the recording")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--read-noise", read_noise_dn,
                  "noise std of a background pixel in DN (0 = measure it around each blob)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--polarity", polarity, "blobs brighter (bright) or darker (dark) than the background")
      ->check(CLI::IsMember({"bright", "dark"}));
  cmd->add_option("--threshold", threshold_dn, "detection threshold in DN beyond the background (0 = automatic)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--noise-frames", noise_frames,
                  "frames (spread over the recording) from which the gain is measured when --gain is not given")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--threads", threads, "threads for reading images and detecting blobs (0 = all cores)")
      ->check(CLI::NonNegativeNumber);
}

int TrackerCli::Threads() const {
  return threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

TrackerOptions TrackerCli::Options(const ImageSequence& seq, const CameraRig& rig,
                                   std::vector<std::string>* notes) const {
  TrackerOptions o;
  o.detector.read_noise_dn = read_noise_dn;
  o.detector.polarity = polarity == "dark" ? Polarity::kDark : Polarity::kBright;
  o.detector.threshold_dn = threshold_dn;
  char buf[160];
  if (gain_e_per_dn) {
    o.detector.gain_e_per_dn = *gain_e_per_dn;
    std::snprintf(buf, sizeof(buf), "noise model: gain %.4g e-/DN for every camera (--gain)%s", *gain_e_per_dn,
                  *gain_e_per_dn > 0 ? "" : ": photon noise left out");
    notes->push_back(buf);
  } else {
    NoiseEstimateOptions no;
    no.frames = noise_frames;
    const SequenceNoiseModel m = EstimateSequenceNoise(seq, rig, o.detector, no, Threads());
    o.camera_gain_e_per_dn = m.gain_e_per_dn;
    for (const auto& line : m.Describe()) notes->push_back(line);
  }
  if (read_noise_dn > 0) {
    std::snprintf(buf, sizeof(buf), "noise model: background pixel noise %.4g DN (--read-noise)", read_noise_dn);
    notes->push_back(buf);
  }
  return o;
}

namespace {

struct TrackArgs {
  std::string dir;
  std::string images, rig, target, frames_csv, output;
  double rate = 10.0;
  bool quiet = false;
  TrackerCli tracker;
};

int RunTrack(const TrackArgs& a) {
  namespace fs = std::filesystem;
  const fs::path dir = a.dir;
  auto pick = [&](const std::string& given, const char* inside) -> fs::path {
    if (!given.empty()) return given;
    if (a.dir.empty()) Throw("give a recording folder DIR or --", inside, "");
    return dir / inside;
  };
  const fs::path images = pick(a.images, "images");
  const fs::path rig_file = !a.rig.empty() ? fs::path(a.rig) : pick("", "rig.yaml");
  const fs::path target_file = !a.target.empty() ? fs::path(a.target) : pick("", "target.yaml");
  const fs::path frames = !a.frames_csv.empty() ? fs::path(a.frames_csv) : (a.dir.empty() ? fs::path() : dir / "frames.csv");
  const fs::path out = !a.output.empty() ? fs::path(a.output) : (a.dir.empty() ? fs::path("poses.csv") : dir / "poses.csv");
  RequireWritableFile(out, "track -o");  // before the sequence, not after it

  CameraRig rig = CameraRig::Read(rig_file);
  Target target = Target::Read(target_file);
  const ImageSequence seq = ScanImageSequence({images, frames, a.rate}, rig);
  std::vector<std::string> notes;
  Tracker tracker(rig, target, a.tracker.Options(seq, rig, &notes));
  for (const auto& line : notes) std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  Progress progress("track", seq.frames.size(), a.quiet);
  // Each frame's row is written (to a temporary file beside the output) as it finishes, and
  // the summaries are running sums: memory does not grow with the length of the recording.
  PoseCsvWriter writer(out);
  PoseResidualCheck check;
  size_t frames_done = 0;
  int ok = 0, degraded = 0, lost = 0;
  std::string first_reason;
  TrackImageSequenceStreaming(
      seq, tracker,
      [&](FrameResult&& r) {
        if (frames_done++ == 0) first_reason = r.reason;
        (r.status == FrameStatus::kOk ? ok : r.status == FrameStatus::kDegraded ? degraded : lost)++;
        check.Add(r);
        writer.Add(r);
      },
      [&](size_t d, size_t) { progress.Update(d); }, a.tracker.Threads());
  progress.Finish();
  if (ok + degraded == 0)
    Throw("target never found in any of the ", frames_done, " frames of ", images.string(), " (first frame: ", first_reason,
          "); no output written");
  check.Finish();
  notes.push_back(check.Describe());
  std::printf("%s\n", check.Describe().c_str());
  writer.Finish(notes);
  std::printf("tracked %zu frames: %d ok, %d degraded, %d lost -> %s\n", frames_done, ok, degraded, lost,
              out.string().c_str());
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
  cmd->add_option("--rate", args->rate, "frame rate in Hz when there is no frames CSV")->check(CLI::PositiveNumber);
  cmd->add_option("-o,--output", args->output, "output CSV (default DIR/poses.csv)");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  args->tracker.Add(cmd);
  return std::make_pair(cmd, Runner([args] { return RunTrack(*args); }));
});

}  // namespace
}  // namespace mcms::app
