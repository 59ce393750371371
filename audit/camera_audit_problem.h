// The camera audit's problem (audit/camera_audit.h is the entry): the observations of a
// tracked recording (each frame's ball images associated with the balls, the leave-one-out
// poses), their prediction through the catalog's terms, the unit fits and the joint fit (a
// bundle adjustment of the rig's model), and what a selection round compares. Internal to
// the camera audit: camera_audit_selection.h runs the rounds over it.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numeric>
#include <set>

#include "audit/camera_audit_types.h"
#include "audit/model_selection.h"
#include "core/error.h"
#include "core/statistics.h"
#include "tracking/pose_refinement.h"
#include "vision/blob_detector.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms::camera_audit {

// An OpenCV camera with k1 (a radial term to fit).
bool HasK1(const CameraModel& cam);
// The rig with the named terms applied; at time `t`, a camera moved from a change time on
// has its old pose before it.
CameraRig ExtendRig(const CameraRig& rig, const std::vector<CameraModelTerm>& terms,
                    double t = std::numeric_limits<double>::infinity());
// The target with its named ball moves applied.
Target ExtendTarget(const Target& target, const std::vector<CameraModelTerm>& terms);

struct Obs {
  int camera, ball;
  Vec2 q;  // a late camera's blob moved back by its time offset's shift (see Associate)
  Mat2 cov;
  Vec2 raw;  // the blob as detected
};

struct Frame {
  size_t result;
  double t;
  Pose T;  // the tracker's pose
  // The move to the pose dt later (TimeShiftedPoseT): twist dt + accel dt^2; twist is
  // [omega; v] in the rig frame with v = pdot - omega x p.
  Vec6 twist, accel;
  int block;
  std::vector<double> lag;  // per camera: its exposure time - t (FrameResult::camera_time_s), or 0
};

struct Sample {
  int camera, ball, block;
  double t;
  Pose T;  // leave-one-out pose
  Vec6 twist, accel;
  Vec2 q, bias;
  double lag;  // the camera's exposure time - t (known), before any camera_time_offset
};

// The samples of one unit in one frame, whitened together: they share the error of the
// leave-one-out pose. W = L^-1 for S = L L^T, S = blockdiag(blob covariances) + J C_pose J^T
// (camera units: with the pose part / s_c^2, the whitened residual then divided by s_c;
// ball units: the cameras' s_c^2 built in).
struct Group {
  int begin = 0, n = 0, block = 0;
  int camera = -1;  // camera units: the camera whose s divides the residual; -1: built in
  Eigen::MatrixXd W;
};

struct UnitData {
  std::vector<Sample> s;
  std::vector<Group> g;
  bool empty() const { return s.empty(); }
  size_t size() const { return s.size(); }
};

struct Eval {
  double ll = 0, sq = 0, chi2 = 0;
  long n = 0;  // samples (2 residuals each)
};

// A fitted model of one unit (a camera or a ball): its terms and, for a camera, s.
struct UnitFit {
  std::vector<CameraModelTerm> terms;
  double scale = 1;
};

enum class ScaleMode { kBand, kFree, kFixed };

class Auditor {
 public:
  Auditor(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results,
          const CameraAuditOptions& o);

  size_t NumFrames() const { return frames_.size(); }
  const UnitData& CameraSamples(int c) const { return cam_samples_[c]; }
  const UnitData& BallSamples(int b) const { return ball_samples_[b]; }

  // The pose at which camera c saw frame f's target: moved along the frame's motion by the
  // camera's known exposure lag and its fitted time offset (camera_time_offset).
  static Pose ViewPose(const Frame& f, int c, const std::vector<CameraModelTerm>& terms);

  // Every camera's blobs of one frame associated with the balls under the model (rig_x,
  // target_x: extended by `terms` at the frame's time).
  std::vector<Obs> Associate(const Frame& f, const CameraRig& rig_x, const Target& target_x,
                             const std::vector<CameraModelTerm>& terms) const;

  // The joint fit (a bundle adjustment of the rig's model): every frame's pose and the
  // terms' parameters (all but the noise scales, which stay as given) fitted together to
  // every ball image, each whitened by its blob covariance times its camera's s^2; the
  // ball images associated under the terms as given. Returns the log-likelihood (up to a
  // constant) and leaves the fitted parameters in *terms. It is what a change to one
  // camera is judged by: unlike the leave-one-out residuals, where a camera's fault pulls
  // the poses its neighbours are tested against (and a neighbour made to agree with the
  // pulled poses also lowers the faulty camera's residuals), a fault here costs what it
  // costs once, and only its own correction removes all of it; and unlike the units' fits
  // on leave-one-out poses, whose optimum is not the joint one, every term is refitted
  // beside every other.
  // *sigma (optional) receives each term's parameter sigmas (the noise scales' empty), the
  // poses marginalised (the covariance of the whole fit, inverted).
  // *state (optional): the frames' poses to start from (when it holds one per frame) and,
  // on return, the poses reached with each camera's chi-square at unit noise scale and its
  // number of ball images (what the camera's scale is refitted from).
  struct JointState {
    std::vector<std::array<double, 6>> pose;
    std::vector<double> chi2;  // per camera, whitened by the blob covariances alone
    std::vector<long> n;       // ball images per camera
  };
  double JointFit(std::vector<CameraModelTerm>* terms_io, const std::vector<double>& scale,
                  std::vector<std::vector<double>>* sigma = nullptr, JointState* state = nullptr) const;

  // The joint fit with camera `camera`'s noise scale refitted too (mode: free, within the
  // band, or fixed), alternating the least squares and the scale's closed form
  // s^2 = chi2 / (2 n), from *state's poses: every step raises the likelihood, so a model
  // started at the solution of the one it contains never ends below it. *scale_io holds
  // the scale used on return.
  double JointFitWithScale(std::vector<CameraModelTerm>* terms_io, std::vector<double>* scale_io, int camera,
                           ScaleMode mode, JointState* state) const;

  // Associates every camera's blobs with the balls and re-fits the leave-one-out poses
  // under the model (terms, per-camera noise scales).
  void Rebuild(const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale);

  // Log-likelihood (up to a constant) of the samples outside (fold < 0: all) or inside
  // block `fold` (inside = true), and the raw squared residuals (px^2).
  Eval Evaluate(const UnitData& u, const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
                int fold, bool inside) const;

  // The whitened residuals of a unit's samples (under the model: i.i.d. N(0, 1), in time
  // order), each with the covariates it may depend on.
  std::vector<WhitenedResidual> Whitened(const UnitData& u, const std::vector<CameraModelTerm>& terms,
                                         const std::vector<double>& scale) const;

  // Fits the terms `free` (indices into terms) of a unit on its samples outside block
  // `fold` (-1: all): Ceres least squares, then the camera's noise scale (camera units) by
  // maximum likelihood, free or within the tolerance band. *sigma (optional) receives the
  // free parameters' sigmas, in order (MarginalSigmas: infinite where unconstrained).
  UnitFit Fit(const UnitData& s, int camera, std::vector<CameraModelTerm> terms, const std::vector<int>& free,
              std::vector<double> scale, ScaleMode mode, int fold, Eigen::VectorXd* sigma = nullptr) const;

  const CameraRig& rig_;
  const Target& target_;
  const std::vector<FrameResult>& results_;
  const CameraAuditOptions& o_;
  std::vector<Frame> frames_;
  std::vector<UnitData> cam_samples_, ball_samples_;
};

struct Candidate {
  CameraModelTerm term;
  bool camera_unit = true;
  int unit = 0;
  int k = 0;          // parameters it adds (a change time counts as one)
  bool step = false;  // camera_moved from a change time on
  bool pair = false;  // two intrinsic effects of one camera at once: term and term2
  CameraModelTerm term2;
  double lr = 0, bic_gain = 0, heldout_gain = 0, rms_before = 0, rms_after = 0, p_value = 1;
  double base_ll = 0;  // the log-likelihood of the model it extends (issue 51: lr >= 0)
  bool eligible = false;
  std::vector<CameraModelTerm> fitted;  // the unit's terms fitted on all data
  double scale = 1;
  std::vector<double> sigma;  // of the candidate's parameters
  std::string label;
};

}  // namespace mcms::camera_audit
