// The pixel-noise model of a recording, measured from its own images (a real rig's
// recording has no scenario file beside it), and the check of that model by the pose
// fits' residuals.
//
// EstimateSequenceNoise detects the blobs of a few frames spread over the sequence and
// measures, per camera, the photon-transfer slope 1/gain from the balls' plateaus and
// their background rings (vision/pixel_noise.h). When the cameras' slopes agree within
// their errors (chi-square at 99.9 %) they share the pooled estimate, which is the more
// precise; otherwise each camera gets its own. The background noise itself needs no
// estimate here: the detector measures it around every blob.
//
// CheckPoseResiduals then compares the whitened residuals of every frame's pose fit with
// chi-square: a noise model that leaves photon noise out (or a camera model that is off)
// shows as chi2/dof above its band.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "tracking/sequence.h"
#include "tracking/tracker.h"
#include "vision/pixel_noise.h"

namespace mcms {

struct NoiseEstimateOptions {
  size_t frames = 12;          // frames used, evenly spread over the sequence (all when fewer)
  double homogeneity_p = 1e-3; // cameras differ when their slopes' chi-square is beyond 1 - p
  PixelNoiseOptions pixel;
  bool IsValid(std::string* why) const;
};

struct SequenceNoiseModel {
  std::vector<std::string> cameras;
  std::vector<PixelNoiseEstimate> per_camera;
  PixelNoiseEstimate pooled;                // all cameras' samples together
  double homogeneity_chi2 = 0;              // of the cameras' slopes about the pooled one
  int homogeneity_dof = 0;
  bool cameras_differ = false;
  std::vector<double> gain_e_per_dn;        // what the tracker is to use, per camera (0 = no photon term)
  size_t frames_used = 0;
  // Human-readable lines: one per camera and one for the choice (also the '#' header of
  // poses.csv).
  std::vector<std::string> Describe() const;
};

// InputError when the options are invalid; images that cannot be read are skipped (the
// tracker reports them per frame). With no usable blob anywhere the gains are 0 and
// Describe() says that photon noise is left out and why.
SequenceNoiseModel EstimateSequenceNoise(const ImageSequence& seq,
                                         const CameraRig& rig,
                                         const BlobDetectorOptions& detector,
                                         const NoiseEstimateOptions& options = {},
                                         int threads = 1);

// The tracker's settings as `mcms track` and `mcms audit cameras` take them (and
// mcms.track_recording): what is given, and what is measured from the recording when it is
// not (the gain).
// A camera's gain (e-/DN): from high-gain 16-bit sensors to wells of 1e5 e- in 8 bits.
inline constexpr double kMinGainEPerDn = 1e-3, kMaxGainEPerDn = 1e4;

struct RecordingTrackerSettings {
  std::optional<double> gain_e_per_dn;  // absent: measured per camera from the recording's images
  double read_noise_dn = 0;             // 0: measured around each blob
  Polarity polarity = Polarity::kBright;
  double threshold_dn = 0;              // 0: automatic
  size_t noise_frames = 12;             // frames the gain is measured from
  int threads = 1;                      // reading images and detecting blobs
  bool predicted_windows = false;       // TrackerOptions::predicted_windows

  // InputError naming the setting when one is out of range.
  void Check() const;
  // The tracker options for the recording `seq`: the settings given, and, unless
  // gain_e_per_dn is given, the per-camera gain measured from the images
  // (EstimateSequenceNoise). Appends the noise model's description to `notes` (printed by
  // the CLI, and written as the '#' header of poses.csv).
  TrackerOptions Options(const ImageSequence& seq, const CameraRig& rig, std::vector<std::string>* notes) const;
};

struct PoseResidualCheck {
  int frames = 0;           // frames with a pose
  double chi2 = 0;          // sum of the pose fits' whitened residual sums of squares
  int dof = 0;              // sum of 2 * observations - 6
  double band_lo = 0, band_hi = 0;  // two-sided 95 % band of chi2 / dof for an honest model
  double Chi2PerDof() const { return dof > 0 ? chi2 / dof : 0.0; }
  bool InBand() const { return dof > 0 && Chi2PerDof() >= band_lo && Chi2PerDof() <= band_hi; }
  // Above the band by at most kModelTolerance (chi2, so about half of it in sigma): what
  // the first-order centre covariance and the sphere-bias model leave out on rendered
  // images with an exact noise model (chi2/dof 1.03-1.07 over 2500 dof). Beyond it the
  // covariance is optimistic; leaving photon noise out gives 1.6-2.1.
  static constexpr double kModelTolerance = 1.15;
  bool Optimistic() const { return dof > 0 && Chi2PerDof() > kModelTolerance * band_hi; }
  std::string Describe() const;

  // Running sums, so a long sequence is checked as its frames stream past: Add() every
  // frame (frames without a pose or without redundant observations are skipped), then
  // Finish() once for the band.
  void Add(const FrameResult& f);
  void Finish();
};

// Add() of every result, then Finish().
PoseResidualCheck CheckPoseResiduals(const std::vector<FrameResult>& results);

}  // namespace mcms
