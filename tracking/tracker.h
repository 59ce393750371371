// Sequence tracking of the five-ball target: per frame, detect balls in every camera,
// match and triangulate them, identify the target, fit it in closed form, then bundle-
// adjust its pose on the 2-D observations of all cameras. A constant-velocity
// prediction from earlier frames gates the association when identification is
// impossible or ambiguous (occluded balls, a camera missing). Every frame gets a status
// and, unless ok, the reason.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "tracking/identify.h"
#include "tracking/pose_refinement.h"
#include "tracking/target.h"
#include "vision/blob_detector.h"
#include "vision/camera_model.h"
#include "vision/triangulation.h"

namespace mcms {

enum class FrameStatus { kOk, kDegraded, kLost };
const char* ToString(FrameStatus s);

struct TrackerOptions {
  BlobDetectorOptions detector;
  MatchingOptions matching;
  IdentificationOptions identification;
  PoseRefinementOptions refinement;
  double min_margin = 9.0;            // identification margin (chi-square) below this is ambiguous
  double max_fit_rms_m = 0.005;       // closed-form fit worse than this: not the target
  double association_gate_px = 6.0;   // 2-D association of predicted ball images to blobs
  double max_chi2_per_dof = 6.0;      // a refined pose worse than this is rejected
  double max_prediction_age_s = 0.5;  // predictions older than this are not used
  // Per rig camera: the gain (e-/DN) of its detector's photon-noise term, overriding
  // detector.gain_e_per_dn (tracking/noise_estimate.h measures it). Empty = the same
  // detector for every camera; otherwise one entry per camera.
  std::vector<double> camera_gain_e_per_dn;
  // Detect in windows around the ball images predicted by the constant-velocity track
  // (DetectBlobsInWindows), not in the whole image: a camera whose windows do not yield a
  // usable blob for every ball predicted in its view, a frame without a prediction, and
  // every full_scan_every-th frame are detected in the whole image. Blobs the windows hold
  // are measured as in the whole image; blobs outside them (spurious reflections) are then
  // neither seen nor reported. Off by default (`mcms track --predicted-windows`).
  bool predicted_windows = false;
  int full_scan_every = 25;  // frames; with predicted_windows
  bool IsValid(std::string* why) const;
};

struct FrameResult {
  size_t frame = 0;
  double time_s = 0;
  // Per camera, when its image was exposed (s, the clock of time_s), for cameras that are
  // not triggered together; empty, or NaN for a camera, when it is time_s. The tracker
  // leaves it empty; the camera audit predicts each camera's images at its own time.
  std::vector<double> camera_time_s;
  FrameStatus status = FrameStatus::kLost;
  std::string reason;                // empty when ok
  std::optional<Pose> T_rig_target;  // absent when lost
  Mat6 cov = Mat6::Zero();           // [dtheta; dp], rig frame, SI units
  int points_triangulated = 0;
  int balls_identified = 0;
  int cameras_used = 0;
  int observations = 0;
  double identification_margin = 0;
  double rms_px = 0;
  double chi2_per_dof = 0;
  std::vector<TriangulatedPoint> points;              // all triangulated points of the frame
  std::vector<int> point_of_ball;                     // identification (-1 = not found)
  std::vector<BallObservation> ball_observations;     // the 2-D observations the pose was fitted to
  std::vector<std::vector<ImagePoint>> image_points;  // every detected blob, per camera
};

class Tracker {
 public:
  // InputError when the options are not valid or the target is degenerate.
  Tracker(CameraRig rig, Target target, TrackerOptions options);

  // images[c] is camera c's image, or an empty Mat when it is missing for this frame;
  // problems[c] (may be empty) says why it is missing ("file missing", "cannot decode").
  FrameResult ProcessFrame(size_t frame, double time_s, const std::vector<cv::Mat>& images,
                           const std::vector<std::string>& problems = {});

  // Makes rows of camera `camera`'s image readable before the detector reads them, for
  // images read in part (vision/image_file.h ImageFileRows, whose rows are unfiltered on
  // demand): `rows` the row ranges it reads (RowsReadInWindows), nullptr for every row.
  using PrepareRows = std::function<void(size_t camera, const std::vector<cv::Range>* rows)>;
  // ProcessFrame on images whose rows are made readable by `prepare` just before they are
  // read: with predicted_windows, only the rows of the windows and of the detector's
  // sample, unless the camera is detected whole; otherwise every row. The results are
  // those of ProcessFrame on the whole images.
  FrameResult ProcessFrame(size_t frame, double time_s, const std::vector<cv::Mat>& images,
                           const std::vector<std::string>& problems, const PrepareRows& prepare);

  // The detection step of ProcessFrame alone: the usable blobs of every camera (empty
  // optional = no usable image, with the reason in problems[c]). Const and thread-safe,
  // so that frames can be detected in parallel and processed in order.
  std::vector<std::optional<std::vector<ImagePoint>>> DetectPoints(const std::vector<cv::Mat>& images,
                                                                   std::vector<std::string>* problems) const;
  // DetectPoints in windows around the ball images predicted for time_s (see
  // TrackerOptions::predicted_windows); the whole image where that cannot be trusted.
  // Uses the track, so frames must come in order.
  // With `prepare`, the rows are made readable as ProcessFrame's overload says.
  std::vector<std::optional<std::vector<ImagePoint>>> DetectPointsPredicted(double time_s,
                                                                            const std::vector<cv::Mat>& images,
                                                                            std::vector<std::string>* problems,
                                                                            const PrepareRows& prepare = {});
  // Frames detected whole and in windows by DetectPointsPredicted so far, per camera.
  size_t whole_image_detections() const { return whole_detections_; }
  size_t window_detections() const { return window_detections_; }
  const TrackerOptions& options() const { return options_; }
  // The detector options used for camera c.
  BlobDetectorOptions DetectorFor(size_t camera) const;

  // Same, from already detected image points per camera (an empty optional = no image).
  FrameResult ProcessPoints(size_t frame, double time_s,
                            const std::vector<std::optional<std::vector<ImagePoint>>>& points,
                            const std::vector<std::string>& problems = {});

  const CameraRig& rig() const { return rig_; }
  const Target& target() const { return target_; }

 private:
  std::optional<Pose> Predict(double time_s) const;
  void DescribeRejections(const std::vector<std::vector<ImagePoint>>& pts,
                          const std::vector<std::optional<std::vector<ImagePoint>>>& in, const PoseRefinement& ref,
                          const std::vector<int>& views, std::vector<std::string>* notes) const;

  CameraRig rig_;
  Target target_;
  TrackerOptions options_;
  // Last two good poses for the constant-velocity prediction.
  std::vector<std::pair<double, Pose>> history_;
  // The previous frame's time: frames come in time order (InputError otherwise).
  std::optional<double> last_time_s_;
  void CheckTime(size_t frame, double time_s);
  FrameResult Track(size_t frame, double time_s, const std::vector<std::optional<std::vector<ImagePoint>>>& points,
                    const std::vector<std::string>& problems);
  size_t whole_detections_ = 0, window_detections_ = 0, frames_since_full_scan_ = 0;
  std::vector<std::vector<char>> last_observed_;  // [camera][ball]: kept by the last accepted pose
  // An image of camera c that can be detected; otherwise the reason in problems[c].
  bool Usable(size_t c, const std::vector<cv::Mat>& images, std::vector<std::string>* problems) const;
  std::vector<ImagePoint> Usable(const std::vector<Blob>& blobs) const;
};

}  // namespace mcms
