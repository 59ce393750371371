// Audit of tracked poses against the forward model's ground truth: errors and their
// consistency with the covariance the tracker reported (NEES against chi-square).
#pragma once

#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "tracking/tracker.h"

namespace mcms {

struct PoseErrorSummary {
  int frames = 0, ok = 0, degraded = 0, lost = 0;
  int evaluated = 0;            // frames with a pose (ok or degraded)
  double position_rms_m = 0;    // RMS of |p - p_true|
  double position_max_m = 0;
  double rotation_rms_rad = 0;  // RMS of the rotation angle error
  double rotation_max_rad = 0;
  // Normalized estimation error squared of [dtheta; dp] with the reported 6x6 covariance:
  // its mean over the evaluated frames, and the two-sided 95 % band of that mean for an
  // honest covariance (chi-square with 6 * evaluated dof, divided by evaluated).
  double mean_nees = 0, nees_band_lo = 0, nees_band_hi = 0;
  // RMS of the errors predicted by the covariances (sqrt of mean trace of the blocks).
  double predicted_position_rms_m = 0, predicted_rotation_rms_rad = 0;
  // Mean distance of the true positions from the rig origin over that of the estimated
  // ones (the evaluated frames): about 1 for a truth of this recording in the same unit.
  double truth_to_estimate_distance = 1;
  // Frames whose rotation is more than 30 deg off the truth's, and of those, how many agree
  // within 2 deg when the truth's four quaternion numbers are read scalar-last (x, y, z, w
  // under qw..qz): a truth file in the other quaternion order.
  int rotation_far = 0, rotation_far_but_scalar_last_close = 0;
  bool NeesInBand() const { return evaluated > 0 && mean_nees >= nees_band_lo && mean_nees <= nees_band_hi; }
};

// One frame's error against the truth: BoxMinus(estimate, truth) = [dtheta; dp], its
// norms, and its NEES with the frame's reported covariance. All NaN for a frame without a
// pose.
struct FramePoseError {
  Vec6 e = Vec6::Constant(std::nan(""));
  double position_m = std::nan(""), rotation_rad = std::nan(""), nees = std::nan("");
};

// PoseErrorSummary as running sums, for sequences streamed frame by frame: Add() each frame
// with its truth, Summary() at any time.
class PoseErrorAccumulator {
 public:
  FramePoseError Add(const FrameResult& f, const Pose& truth);
  PoseErrorSummary Summary() const;

 private:
  PoseErrorSummary s_;
  double p2_ = 0, r2_ = 0, nees_ = 0, pp_ = 0, pr_ = 0, dt_ = 0, de_ = 0;
};

// InputError when a truth file's positions are not in the unit of the tracked ones or not
// of this recording: the true positions on average more than 5 times as far from the rig
// as the tracked ones, or less than a fifth (millimetres under metre headers give 1000).
void CheckTruthDistances(const PoseErrorSummary& s, const std::string& truth_file);
// InputError when most evaluated frames' rotations are far from the truth's but agree with
// its quaternions read scalar-last: the truth file's quaternions are in x, y, z, w order.
void CheckTruthRotations(const PoseErrorSummary& s, const std::string& truth_file);

// truth[i] is the true T_rig_target of results[i].
PoseErrorSummary EvaluatePoses(const std::vector<FrameResult>& results, const std::vector<Pose>& truth);

// A truth file of T_rig_target per frame: the columns frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz
// (what `mcms render` writes as truth/poses.csv; other columns are ignored). InputError
// naming the file, line and column on a missing column, a cell that is not a finite
// number, a frame that is not a non-negative integer, a repeated frame, or a quaternion
// whose norm is not 1 (within 1e-4).
struct TruthPose {
  double time_s = 0;
  Pose T_rig_target;
};
std::map<size_t, TruthPose> ReadTruthPoses(const std::filesystem::path& path);

// Two-sided band [lo, hi] holding a chi-square(dof) variable with probability `p`.
void Chi2Band(double dof, double p, double* lo, double* hi);

// A human-readable report (mm, degrees).
std::string FormatSummary(const PoseErrorSummary& s);

}  // namespace mcms
