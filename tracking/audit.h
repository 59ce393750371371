// Audit of a tracked sequence against its own camera model: which camera's observations
// the rest of the rig does not explain, what kind of error explains them, and a repaired
// model. Leave-one-camera-out: every frame's pose is re-fitted without camera c, camera
// c's ball images are predicted from it, and the whitened prediction residuals of c are
// tested against chi-square, each whitened with the blob's covariance plus the
// leave-one-out pose's covariance carried into the prediction, gross outliers (beyond a
// 1e-5 quantile scaled by the camera's median residual) left out. A camera whose residuals fail is then explained by the
// candidate causes below, each fitted by least squares over the whole sequence; the cause
// that removes the most chi-square is named, and a moved camera gets a re-estimated pose.
//
// Candidate causes (the simulation's camera model is exact; a real rig is not):
//   - "camera moved"  : a rigid change of T_cam_rig (bumped camera, drifting mount), 6 dof;
//   - "lens distortion": a radial term the lens model lacks, dq = k * r^2 * (q - c), 1 dof;
//   - "noise model"   : neither cause explains the residuals (neither fit brings chi-square
//                       under the threshold while removing at least half of its excess
//                       over 1): the pixel noise model is too optimistic
//                       (tracking/noise_estimate.h), not the camera;
//   - "none"          : noise; the camera is consistent with the rest.
#pragma once

#include <string>
#include <vector>

#include "tracking/target.h"
#include "tracking/tracker.h"
#include "vision/camera_model.h"

namespace mcms {

struct CameraAudit {
  std::string name;
  int observations = 0;
  int outliers = 0;             // gross outliers left out of chi2 (a pulled ball image)
  double chi2_per_dof = 0;      // leave-one-out prediction residuals, whitened
  double chi2_threshold = 0;    // the 99.9 % chi-square quantile per dof for this count
  bool consistent = true;
  Vec2 mean_residual_px = Vec2::Zero();
  // chi-square per dof left after fitting each cause (only for inconsistent cameras)
  double after_moved = 0, after_radial = 0;
  std::string cause;            // "none", "camera moved", "lens distortion" or "noise model"
  Pose corrected_T_cam_rig;     // for "camera moved": the re-estimated extrinsics
  Vec6 camera_move = Vec6::Zero();  // BoxMinus(corrected, model): [rad; m]
  double radial_k = 0;          // for "lens distortion": px per px^2 of radius squared
};

struct SequenceAudit {
  std::vector<CameraAudit> cameras;
  int worst = -1;  // index of the least consistent camera, -1 when all are consistent
  std::string Report() const;
};

SequenceAudit AuditCameras(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results);

// The rig with the audit's re-estimated extrinsics applied to every moved camera.
CameraRig RepairRig(const CameraRig& rig, const SequenceAudit& audit);

}  // namespace mcms
