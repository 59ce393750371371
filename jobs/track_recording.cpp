#include "jobs/track_recording.h"

#include <numbers>
#include <chrono>
#include <sstream>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "tracking/sequence.h"

namespace mcms {

void CheckTruthCoversSequence(const std::map<size_t, TruthPose>& truth, const std::string& truth_file,
                              const ImageSequence& seq, const std::filesystem::path& images,
                              const std::filesystem::path& frames_csv) {
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    const auto it = truth.find(seq.frames[i]);
    if (it == truth.end())
      Throw("truth file ", truth_file, " has no row for frame ", seq.frames[i], " of ", images.string(), " (it holds ",
            truth.size(), " frames, ", truth.begin()->first, " to ", truth.rbegin()->first,
            "); give the truth of this recording");
    if (!(std::abs(it->second.time_s - seq.times_s[i]) <= 1e-6 * std::max(1.0, std::abs(seq.times_s[i]))))
      Throw("truth file ", truth_file, ": frame ", seq.frames[i], " is at time_s ", it->second.time_s,
            " but the recording has it at ", seq.times_s[i], " s",
            frames_csv.empty() || !std::filesystem::exists(frames_csv)
                ? std::string(" (from --rate; give --frames)")
                : std::string(" (from ").append(frames_csv.string()).append(")"),
            "; give the truth of this recording");
  }
}

PoseErrorSummary EvaluateAgainstTruth(const std::vector<FrameResult>& results,
                                      const std::map<size_t, TruthPose>& truth, const std::string& truth_file,
                                      const std::string& source) {
  if (truth.empty()) Throw("truth file ", truth_file, " holds no frame");
  PoseErrorAccumulator acc;
  for (const FrameResult& r : results) {
    if (!r.T_rig_target) {
      acc.Add(r, Pose());
      continue;
    }
    const auto it = truth.find(r.frame);
    if (it == truth.end())
      Throw("truth file ", truth_file, " has no row for frame ", r.frame, " of ", source, " (it holds ", truth.size(),
            " frames, ", truth.begin()->first, " to ", truth.rbegin()->first, "); give the truth of this recording");
    if (!(std::abs(it->second.time_s - r.time_s) <= 1e-6 * std::max(1.0, std::abs(r.time_s))))
      Throw("truth file ", truth_file, ": frame ", r.frame, " is at time_s ", it->second.time_s, " but ", source,
            " has it at ", r.time_s, " s; give the truth of this recording");
    acc.Add(r, it->second.T_rig_target);
  }
  const PoseErrorSummary s = acc.Summary();
  CheckTruthDistances(s, truth_file);
  return s;
}

std::vector<std::string> DescribeTruthErrors(const PoseErrorSummary& s, const std::string& file) {
  std::vector<std::string> lines;
  char buf[400];
  if (s.evaluated == 0) {
    lines.push_back(std::string("truth ").append(file).append(": no frame with a pose to compare"));
    return lines;
  }
  std::snprintf(buf, sizeof(buf),
                "truth %s: position error RMS %.4f mm (the covariances predict %.4f), max %.4f mm; rotation error "
                "RMS %.5f deg (predicted %.5f), max %.5f deg; over %d frames with a pose",
                file.c_str(), 1e3 * s.position_rms_m, 1e3 * s.predicted_position_rms_m, 1e3 * s.position_max_m,
                s.rotation_rms_rad * 180 / std::numbers::pi, s.predicted_rotation_rms_rad * 180 / std::numbers::pi,
                s.rotation_max_rad * 180 / std::numbers::pi, s.evaluated);
  lines.push_back(buf);
  std::snprintf(buf, sizeof(buf),
                "truth: mean NEES %.3f over %d frames; an honest 6-dof covariance gives 6 on average, the mean "
                "within %.3f-%.3f (95 %% chi-square band with %d dof, /%d): %s",
                s.mean_nees, s.evaluated, s.nees_band_lo, s.nees_band_hi, 6 * s.evaluated, s.evaluated,
                s.NeesInBand()                 ? "consistent"
                : s.mean_nees > s.nees_band_hi ? "ABOVE the band, the covariance is optimistic"
                                               : "below the band, the covariance is conservative");
  lines.push_back(buf);
  return lines;
}

TrackRecordingResult TrackRecording(const TrackRecordingInput& in,
                                    const std::function<void(const std::string&)>& on_note,
                                    const std::function<void(size_t, size_t)>& progress) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  namespace fs = std::filesystem;
  const auto start = std::chrono::steady_clock::now();
  const fs::path& dir = in.dir;
  auto pick = [&](const fs::path& given, const char* inside, const char* option) -> fs::path {
    if (!given.empty()) return given;
    if (dir.empty()) Throw("give a recording folder DIR or ", option);
    return dir / inside;
  };
  if (!dir.empty() && !fs::is_directory(dir))
    Throw("recording folder ", dir.string(), ": ", fs::exists(dir) ? "not a folder" : "does not exist");
  in.tracker.Check();
  // A camera's frame rate: from a frame every 1000 s to a million a second.
  if (!(in.rate_hz == 0 || (in.rate_hz >= 1e-3 && in.rate_hz <= 1e6)))
    Throw("frame rate (--rate): expected 0.001 to 1e6 Hz, got ", in.rate_hz);
  TrackRecordingResult res;
  res.images = pick(in.images, "images", "--images");
  const fs::path rig_file = pick(in.rig, "rig.yaml", "--rig");
  const fs::path target_file = pick(in.target, "target.yaml", "--target");
  const fs::path frames = !in.frames_csv.empty() ? in.frames_csv : (dir.empty() ? fs::path() : dir / "frames.csv");
  res.output = !in.output.empty() ? in.output : (dir.empty() ? fs::path("poses.csv") : dir / "poses.csv");
  res.truth = in.truth;
  if (res.truth == "auto") {
    if (dir.empty()) Throw("truth 'auto' needs a recording folder DIR (it means DIR/truth/poses.csv)");
    const fs::path t = dir / "truth" / "poses.csv";
    res.truth = fs::exists(t) ? t.string() : std::string();
  }
  const CameraRig rig = CameraRig::Read(rig_file);  // (and its camera model files: inputs too)
  const Target target = Target::Read(target_file);
  RequireOutputsSpareInputs({{res.output, in.output_what}},
                            {res.images, rig_file, target_file, frames, fs::path(res.truth)});
  RequireWritableFile(res.output, in.output_what);  // before the sequence, not after it
  // The default DIR/poses.csv sits among the user's files: replaced only when an earlier
  // track wrote it (its column header), never the user's own poses.csv. An explicit -o is
  // the user's choice of file.
  if (in.output.empty())
    RequireOwnEarlierOutput(
        res.output,
        [](const std::string& head) {
          std::istringstream lines(head);
          for (std::string line; std::getline(lines, line);)
            if (line.empty() || line[0] != '#') return line.rfind("frame,time_s,status,reason,", 0) == 0;
          return false;
        },
        "track", "poses an earlier mcms track wrote", "give the output file with -o, or move it");

  const bool assumed_rate = in.rate_hz == 0 && (frames.empty() || !fs::exists(frames));
  const ImageSequence seq = ScanImageSequence({res.images, frames, in.rate_hz > 0 ? in.rate_hz : 10.0}, rig);
  // The truth, checked against the recording's frames before the long work.
  std::map<size_t, TruthPose> truth;
  if (!res.truth.empty()) {
    truth = ReadTruthPoses(res.truth);
    CheckTruthCoversSequence(truth, res.truth, seq, res.images, frames);
  }
  auto note = [&](const std::string& line) {
    res.notes.push_back(line);
    if (on_note) on_note(line);
  };
  if (assumed_rate)
    note("frame times: no frames CSV (" + (frames.empty() ? std::string("none given") : frames.string() + " is absent") +
         ") and no frame rate given: frame k is at k / 10 s, an assumed 10 Hz; give --rate (or a frames CSV "
         "frame,time_s) for the recording's real times");
  std::vector<std::string> noise_notes;
  Tracker tracker(rig, target, in.tracker.Options(seq, rig, &noise_notes));
  for (const auto& line : noise_notes) note(line);
  // Each frame's row is written (to a temporary file beside the output) as it finishes, and
  // the summaries are running sums: memory does not grow with the length of the recording.
  const bool with_truth = !truth.empty();
  PoseCsvWriter writer(res.output, with_truth ? std::vector<std::string>{"err_pos_mm", "err_rot_deg", "nees"}
                                              : std::vector<std::string>{});
  PoseErrorAccumulator errors;
  std::string first_reason;
  TrackImageSequenceStreaming(
      seq, tracker,
      [&](FrameResult&& r) {
        if (res.frames++ == 0) first_reason = r.reason;
        (r.status == FrameStatus::kOk ? res.ok : r.status == FrameStatus::kDegraded ? res.degraded : res.lost)++;
        res.residuals.Add(r);
        if (with_truth) {
          const FramePoseError e = errors.Add(r, truth.at(r.frame).T_rig_target);
          writer.Add(r, {1e3 * e.position_m, e.rotation_rad * 180 / std::numbers::pi, e.nees});
        } else {
          writer.Add(r);
        }
      },
      progress, in.tracker.threads);
  if (res.ok + res.degraded == 0)
    Throw("target never found in any of the ", res.frames, " frames of ", res.images.string(), " (first frame: ",
          first_reason, "); no output written");
  res.residuals.Finish();
  note(res.residuals.Describe());
  if (in.tracker.predicted_windows) {
    std::ostringstream s;
    s << "predicted windows: " << tracker.window_detections() << " camera images detected in windows, "
      << tracker.whole_image_detections() << " whole (no prediction, every 25th frame, or a ball the windows missed)";
    note(s.str());
  }
  if (with_truth) {
    res.errors = errors.Summary();
    CheckTruthDistances(*res.errors, res.truth);  // before the output is committed
    CheckTruthRotations(*res.errors, res.truth);
    for (const std::string& line : DescribeTruthErrors(*res.errors, res.truth)) note(line);
  }
  writer.Finish(res.notes);
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

}  // namespace mcms
