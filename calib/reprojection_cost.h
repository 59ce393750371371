// The rig calibration's reprojection residual as a Ceres cost function with analytic
// derivatives: libmrcal projects straight from the intrinsics parameter block (no
// camera model is built per evaluation), the pose derivatives are written in closed
// form. Exposed so that tests check it against numeric derivatives
// (ceres::GradientChecker).
#pragma once

#include <optional>
#include <string>

#include <ceres/cost_function.h>
#include <Eigen/Core>

#include "core/pose_math.h"
#include "vision/mrcal_c.h"

namespace mcms {

// residual = weight * (project(intrinsics, p_cam) - q_obs), with
//   p_cam = R(rc) (R(rb) P' + tb) + tc,
//   P'    = P + (wx a + wy b) e_z when the board warp is solved (a, b: the point's warp
//           shape factors 1 - u^2, 1 - v^2; see CameraCalibrationOptions::solve_board_warp).
// Parameter blocks, in order: intrinsics (mrcal's, NumIntrinsics of the lens model),
// rt_rig_board (6: rotation vector, translation), rt_cam_rig (6) unless the camera is
// the rig frame (has_extrinsics false), the warp (2) when warp_shape is given.
// Evaluate returns false (Ceres retries a shorter step) for a point behind a camera
// that cannot see behind itself or a projection that is not finite.
class ReprojectionCost final : public ceres::CostFunction {
 public:
  // InputError when the lens model is unknown, has no gradients or is splined (its
  // intrinsics gradient is sparse).
  ReprojectionCost(const std::string& lensmodel, const Vec3& P_board, const Vec2& q_observed, double weight,
                   bool has_extrinsics, std::optional<Eigen::Vector2d> warp_shape);

  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override;

  // Maximum intrinsics count supported (LENSMODEL_OPENCV12: 4 + 12).
  static constexpr int kMaxIntrinsics = 16;

 private:
  mrcal_lensmodel_t lens_;
  bool sees_behind_ = false;
  int num_intrinsics_ = 0;
  Vec3 P_;
  Vec2 q_;
  double w_;
  bool has_extrinsics_;
  std::optional<Eigen::Vector2d> warp_shape_;
};

}  // namespace mcms
