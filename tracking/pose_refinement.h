// Bundle adjustment of the target's 6-DOF pose directly on the 2-D ball observations
// of all cameras (the cameras held fixed), with the covariance of the result in the
// project's layout: 6x6, [dtheta; dp], R = Exp(dtheta) * R_hat, p = p_hat + dp, rig frame
// (docs/conventions.md).
#pragma once

#include <vector>

#include "core/pose_math.h"
#include "tracking/target.h"
#include "vision/camera_model.h"

namespace ceres {
class CostFunction;
}

namespace mcms {

struct BallObservation {
  int camera = -1;
  int ball = -1;
  Vec2 q;    // px, the measured centroid of the ball's image
  Mat2 cov;  // px^2
};

struct PoseRefinementOptions {
  bool correct_sphere_bias = true;  // measurement model = the sphere image's centroid
  int bias_outline_points = 32;
  int max_outer_iterations = 4;     // Ceres solves, re-linearizing the sphere bias between them
  double huber_sigma = 4.0;         // robust loss scale in whitened units; <= 0: plain least squares
  double outlier_sigma = 5.0;       // observations beyond this whitened residual are dropped once
  bool IsValid(std::string* why) const;
};

struct PoseRefinement {
  Pose T_rig_target;
  Mat6 cov = Mat6::Zero();  // inverse of the Gauss-Newton information at the solution
  double chi2 = 0;          // whitened residual sum of squares of the kept observations
  int dof = 0;              // 2 * kept observations - 6
  double rms_px = 0;
  std::vector<BallObservation> kept;     // the observations used in the end
  std::vector<BallObservation> dropped;  // outliers
  bool converged = false;
};

// Requires at least 3 observations of 3 distinct balls (nothing else constrains a
// rigid pose); otherwise throws std::invalid_argument (a caller error, not input).
PoseRefinement RefinePose(const CameraRig& rig, const Target& target, const Pose& initial,
                          const std::vector<BallObservation>& observations,
                          const PoseRefinementOptions& options = {});

// The residual RefinePose minimizes for one observation, as a function of the pose
// increment delta = [dtheta; dp] about T0 (its one 6-parameter block):
//   r = W (q_minus_bias - Project(T_cam_rig (Exp(dtheta) R0 b + p0 + dp))),
// with analytic derivatives. Exposed for tests (Ceres' GradientChecker); the caller owns
// the result and `cam` must outlive it.
ceres::CostFunction* NewBallReprojectionCost(const CameraModel& cam, const Pose& T0, const Vec3& ball_target,
                                             const Vec2& q_minus_bias, const Mat2& W);

}  // namespace mcms
