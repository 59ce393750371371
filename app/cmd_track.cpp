// mcms track: image sequence + rig + target -> one CSV row per frame with the pose
// and its 6x6 covariance.
#include <cmath>
#include <cstdio>
#include <map>
#include <thread>

#include "app/commands.h"
#include "app/tracking_options.h"
#include "core/error.h"
#include "core/io.h"
#include "synthetic/evaluation.h"
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

// The error summary against a truth file, as the lines printed and written at the top of
// poses.csv.
std::vector<std::string> DescribeTruthErrors(const PoseErrorSummary& s, const std::string& file) {
  std::vector<std::string> lines;
  char buf[400];
  if (s.evaluated == 0) {
    lines.push_back("truth " + file + ": no frame with a pose to compare");
    return lines;
  }
  std::snprintf(buf, sizeof(buf),
                "truth %s: position error RMS %.4f mm (the covariances predict %.4f), max %.4f mm; rotation error "
                "RMS %.5f deg (predicted %.5f), max %.5f deg; over %d frames with a pose",
                file.c_str(), 1e3 * s.position_rms_m, 1e3 * s.predicted_position_rms_m, 1e3 * s.position_max_m,
                s.rotation_rms_rad * 180 / M_PI, s.predicted_rotation_rms_rad * 180 / M_PI,
                s.rotation_max_rad * 180 / M_PI, s.evaluated);
  lines.push_back(buf);
  std::snprintf(buf, sizeof(buf),
                "truth: mean NEES %.3f over %d frames; an honest 6-dof covariance gives 6 on average, the mean "
                "within %.3f-%.3f (95 %% chi-square band with %d dof, /%d): %s",
                s.mean_nees, s.evaluated, s.nees_band_lo, s.nees_band_hi, 6 * s.evaluated, s.evaluated,
                s.NeesInBand()                    ? "consistent"
                : s.mean_nees > s.nees_band_hi    ? "ABOVE the band, the covariance is optimistic"
                                                  : "below the band, the covariance is conservative");
  lines.push_back(buf);
  return lines;
}

struct TrackArgs {
  std::string dir;
  std::string images, rig, target, frames_csv, output, truth;
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
  // The truth, checked against the recording's frames before the long work.
  std::map<size_t, TruthPose> truth;
  if (!a.truth.empty()) {
    truth = ReadTruthPoses(a.truth);
    for (size_t i = 0; i < seq.frames.size(); ++i) {
      const auto it = truth.find(seq.frames[i]);
      if (it == truth.end())
        Throw("truth file ", a.truth, " has no row for frame ", seq.frames[i], " of ", images.string(), " (it holds ",
              truth.size(), " frames, ", truth.begin()->first, " to ", truth.rbegin()->first,
              "); give the truth of this recording");
      if (!(std::abs(it->second.time_s - seq.times_s[i]) <= 1e-6 * std::max(1.0, std::abs(seq.times_s[i]))))
        Throw("truth file ", a.truth, ": frame ", seq.frames[i], " is at time_s ", it->second.time_s,
              " but the recording has it at ", seq.times_s[i], " s",
              frames.empty() || !std::filesystem::exists(frames) ? std::string(" (from --rate; give --frames)")
                                                                 : " (from " + frames.string() + ")",
              "; give the truth of this recording");
    }
  }
  std::vector<std::string> notes;
  Tracker tracker(rig, target, a.tracker.Options(seq, rig, &notes));
  for (const auto& line : notes) std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  Progress progress("track", seq.frames.size(), a.quiet);
  // Each frame's row is written (to a temporary file beside the output) as it finishes, and
  // the summaries are running sums: memory does not grow with the length of the recording.
  const bool with_truth = !truth.empty();
  PoseCsvWriter writer(out, with_truth ? std::vector<std::string>{"err_pos_mm", "err_rot_deg", "nees"}
                                       : std::vector<std::string>{});
  PoseResidualCheck check;
  PoseErrorAccumulator errors;
  size_t frames_done = 0;
  int ok = 0, degraded = 0, lost = 0;
  std::string first_reason;
  TrackImageSequenceStreaming(
      seq, tracker,
      [&](FrameResult&& r) {
        if (frames_done++ == 0) first_reason = r.reason;
        (r.status == FrameStatus::kOk ? ok : r.status == FrameStatus::kDegraded ? degraded : lost)++;
        check.Add(r);
        if (with_truth) {
          const FramePoseError e = errors.Add(r, truth.at(r.frame).T_rig_target);
          writer.Add(r, {1e3 * e.position_m, e.rotation_rad * 180 / M_PI, e.nees});
        } else {
          writer.Add(r);
        }
      },
      [&](size_t d, size_t) { progress.Update(d); }, a.tracker.Threads());
  progress.Finish();
  if (ok + degraded == 0)
    Throw("target never found in any of the ", frames_done, " frames of ", images.string(), " (first frame: ", first_reason,
          "); no output written");
  check.Finish();
  notes.push_back(check.Describe());
  std::printf("%s\n", check.Describe().c_str());
  if (with_truth) {
    for (const std::string& line : DescribeTruthErrors(errors.Summary(), a.truth)) {
      notes.push_back(line);
      std::printf("%s\n", line.c_str());
    }
  }
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
  cmd->add_option("--truth", args->truth,
                  "truth file of T_rig_target per frame with columns frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz (what "
                  "`mcms render` writes as DIR/truth/poses.csv); adds the columns err_pos_mm, err_rot_deg (norms of "
                  "the [rotation; position] error of the tracked pose against the truth) and nees (that error "
                  "squared, normalized by the frame's covariance) to the output, and prints the mean NEES against "
                  "its chi-square band; every frame of the recording needs a truth row at the same time");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  args->tracker.Add(cmd);
  return std::make_pair(cmd, Runner([args] { return RunTrack(*args); }));
});

}  // namespace
}  // namespace mcms::app
