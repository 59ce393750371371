// One recording tracked end to end, as `mcms track` does it (and mcms.track_recording,
// `mcms batch`): the recording folder's images, rig and target in, the pose CSV out, with
// the error and NEES against a truth file when one is given.
#pragma once

#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "jobs/evaluation.h"
#include "tracking/noise_estimate.h"

namespace mcms {

struct TrackRecordingInput {
  // The recording folder (what `mcms render` writes): images/<camera>/<frame>.png, rig.yaml,
  // target.yaml, optional frames.csv. Each of the paths below, when empty, is taken from it.
  std::filesystem::path dir;
  std::filesystem::path images, rig, target, frames_csv;
  std::filesystem::path output;  // default DIR/poses.csv (poses.csv without DIR)
  std::string output_what = "output";  // how messages about the output name it (e.g. "track -o")
  // Truth of T_rig_target per frame (ReadTruthPoses); empty: none. "auto": DIR/truth/poses.csv
  // when that file exists, else none.
  std::string truth;
  // Frame rate (Hz) when there is no frames CSV; 0 = not given: frames are then 10 Hz
  // apart, an assumption the run states in its notes (and the output's '#' lines).
  double rate_hz = 0;
  RecordingTrackerSettings tracker;
};

struct TrackRecordingResult {
  std::filesystem::path output, images;
  std::string truth;  // the truth file used; empty: none
  size_t frames = 0;
  int ok = 0, degraded = 0, lost = 0;
  // The noise model, the check of the pose fits' residuals and, with a truth, the error
  // summary: the lines printed by `mcms track` and written as '#' lines at the top of the CSV.
  std::vector<std::string> notes;
  PoseResidualCheck residuals;
  std::optional<PoseErrorSummary> errors;  // with a truth file
  double seconds = 0;                      // wall time
};

// Checks that `truth` holds every frame of `seq` at the same time; InputError naming the
// truth file and the first frame that does not fit otherwise.
void CheckTruthCoversSequence(const std::map<size_t, TruthPose>& truth, const std::string& truth_file,
                              const ImageSequence& seq, const std::filesystem::path& images,
                              const std::filesystem::path& frames_csv);

// The error summary of tracked frames against a truth file, frames matched by number:
// every frame needs a truth row at the same time (InputError naming the truth file, the
// frame and `source`, the results' origin, otherwise).
PoseErrorSummary EvaluateAgainstTruth(const std::vector<FrameResult>& results,
                                      const std::map<size_t, TruthPose>& truth, const std::string& truth_file,
                                      const std::string& source);

// The two lines that describe an error summary against a truth file (position and rotation
// RMS against the covariances' prediction, mean NEES against its chi-square band).
std::vector<std::string> DescribeTruthErrors(const PoseErrorSummary& s, const std::string& file);

// Tracks the recording: checks the output and the truth before the long work, measures the
// noise model (unless given), streams every frame through the tracker into the pose CSV
// (written atomically, with err_pos_mm, err_rot_deg and nees columns when there is a truth).
// on_note(line) receives each note as soon as it is known (the noise model before the
// frames, the summaries after them); progress(done, total) after each frame. InputError
// naming the file on bad input, and when the target is found in no frame (then no output
// is written).
TrackRecordingResult TrackRecording(const TrackRecordingInput& in,
                                    const std::function<void(const std::string&)>& on_note = {},
                                    const std::function<void(size_t, size_t)>& progress = {});

}  // namespace mcms
