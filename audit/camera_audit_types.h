// The types of the camera audit (audit/camera_audit.h): its options, a named term of the
// catalog with its parameters, the whitened residuals and the result. Shared by the
// audit's problem, selection and entry.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "audit/audit_report.h"
#include "model/extensions.h"
#include "tracking/target.h"
#include "tracking/tracker.h"
#include "vision/camera_model.h"

namespace mcms {

struct CameraAuditOptions {
  int folds = 5;                  // k of the k-fold, blocks of time
  double false_alarm = 0.01;      // designed probability of naming anything on a clean recording
  double noise_tolerance = 0.15;  // |s - 1| accepted in the pixel noise model (relative, on sigma)
  double undecided_nats = 3.0;    // held-out log-likelihood margin within which two candidates tie
  int max_effects = 4;
  int change_points = 9;          // candidate change times of a part-way camera move (0 = none)
  double gate_px = 12.0;          // association gate of a blob around its predicted ball image
  bool IsValid(std::string* why) const;
};

// One named effect of the extended model.
struct CameraModelTerm {
  Extension extension;
  std::vector<double> parameters, sigma;  // in Extension::ParameterNames() order
  // camera_moved only: the move applies from this time on (a camera bumped part-way);
  // -infinity: the whole recording.
  double from_time_s = -std::numeric_limits<double>::infinity();
  bool undecided = false;  // in an undecided group: kept in the audit's model, not named
};

// One leave-one-out ball image of the nominal model, whitened (under the model: two
// i.i.d. N(0, 1) numbers), with its covariates.
struct WhitenedResidual {
  int camera = 0, ball = 0;
  double time_s = 0.0;
  Vec2 q = Vec2::Zero();  // predicted ball image (px)
  Vec2 w = Vec2::Zero();  // whitened residual, observed - predicted (u, v)
  double radius_px = 0.0; // distance of q from the image centre
  double range_m = 0.0;   // distance of the ball from the camera
};

struct CameraAuditResult {
  AuditReport report;
  // Per camera, the nominal model's whitened residuals (what the residual tests and
  // the plots of `mcms audit cameras -o DIR` use).
  std::vector<std::vector<WhitenedResidual>> residuals;
  std::vector<CameraModelTerm> terms;  // the named effects, in the order found
  std::vector<double> noise_scale;     // estimated factor on each camera's pixel sigma
  // The rig with the named geometric effects applied: camera_moved (the pose after a
  // part-way move), focal_length, principal_point, radial_distortion (OpenCV models).
  CameraRig ExtendedRig(const CameraRig& rig) const;
  // The target with the named target_geometry effects applied.
  Target ExtendedTarget(const Target& target) const;
  // True when the extended rig differs from the nominal one.
  bool ChangesRig() const;
};

}  // namespace mcms
