#include "calib/reprojection_cost.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace mcms {

ReprojectionCost::ReprojectionCost(const std::string& lensmodel, const Vec3& P_board, const Vec2& q_observed,
                                   double weight, bool has_extrinsics, std::optional<Eigen::Vector2d> warp_shape)
    : P_(P_board), q_(q_observed), w_(weight), has_extrinsics_(has_extrinsics), warp_shape_(warp_shape) {
  if (!mrcal_lensmodel_from_name(&lens_, lensmodel.c_str()) || !mrcal_lensmodel_type_is_valid(lens_.type))
    Throw("reprojection cost: unknown lens model '", lensmodel, "'");
  const mrcal_lensmodel_metadata_t meta = mrcal_lensmodel_metadata(&lens_);
  if (!meta.has_gradients || lens_.type == MRCAL_LENSMODEL_SPLINED_STEREOGRAPHIC)
    Throw("reprojection cost: lens model '", lensmodel, "' has no dense intrinsics gradient");
  sees_behind_ = meta.can_project_behind_camera;
  num_intrinsics_ = mrcal_lensmodel_num_params(&lens_);
  if (num_intrinsics_ > kMaxIntrinsics)
    Throw("reprojection cost: lens model '", lensmodel, "' has ", num_intrinsics_, " intrinsics, at most ",
          kMaxIntrinsics, " are supported");
  set_num_residuals(2);
  mutable_parameter_block_sizes()->push_back(num_intrinsics_);
  mutable_parameter_block_sizes()->push_back(6);
  if (has_extrinsics) mutable_parameter_block_sizes()->push_back(6);
  if (warp_shape) mutable_parameter_block_sizes()->push_back(2);
}

bool ReprojectionCost::Evaluate(double const* const* params, double* residuals, double** jacobians) const {
  const Vec3 rb(params[1][0], params[1][1], params[1][2]), tb(params[1][3], params[1][4], params[1][5]);
  const Mat3 Rb = ExpSO3(rb);
  const int warp_block = has_extrinsics_ ? 3 : 2;
  Vec3 P = P_;
  if (warp_shape_) P.z() += params[warp_block][0] * warp_shape_->x() + params[warp_block][1] * warp_shape_->y();
  const Vec3 RbP = Rb * P;
  const Vec3 p_rig = RbP + tb;
  Mat3 Rc = Mat3::Identity();
  Vec3 rc = Vec3::Zero(), tc = Vec3::Zero();
  if (has_extrinsics_) {
    rc = Vec3(params[2][0], params[2][1], params[2][2]);
    tc = Vec3(params[2][3], params[2][4], params[2][5]);
    Rc = ExpSO3(rc);
  }
  const Vec3 Rc_prig = Rc * p_rig;
  const Vec3 p_cam = Rc_prig + tc;
  if (!(p_cam.z() > 1e-9) && !sees_behind_) return false;

  // libmrcal straight on the intrinsics block; dq/dintrinsics is (2, n) row-major,
  // Ceres' layout of jacobians[0], so it is written there directly.
  const bool want = jacobians != nullptr;
  const mrcal_point3_t p{{p_cam.x(), p_cam.y(), p_cam.z()}};
  mrcal_point2_t q;
  mrcal_point3_t grad[2];
  double* dq_di = want ? jacobians[0] : nullptr;
  if (dq_di) std::fill(dq_di, dq_di + 2 * num_intrinsics_, 0.0);
  mrcal_project(&q, want ? grad : nullptr, dq_di, &p, 1, &lens_, params[0]);
  if (!std::isfinite(q.x) || !std::isfinite(q.y)) return false;
  residuals[0] = w_ * (q.x - q_.x());
  residuals[1] = w_ * (q.y - q_.y());
  if (!want) return true;
  if (dq_di)
    for (int k = 0; k < 2 * num_intrinsics_; ++k) dq_di[k] *= w_;
  Eigen::Matrix<double, 2, 3> dq_dp;
  dq_dp << grad[0].x, grad[0].y, grad[0].z, grad[1].x, grad[1].y, grad[1].z;
  dq_dp *= w_;
  if (jacobians[1]) {
    Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(jacobians[1]);
    const Eigen::Matrix<double, 2, 3> dq_dprig = dq_dp * Rc;
    J.leftCols<3>() = dq_dprig * (-Skew(RbP) * LeftJacobianSO3(rb));
    J.rightCols<3>() = dq_dprig;
  }
  if (has_extrinsics_ && jacobians[2]) {
    Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(jacobians[2]);
    J.leftCols<3>() = dq_dp * (-Skew(Rc_prig) * LeftJacobianSO3(rc));
    J.rightCols<3>() = dq_dp;
  }
  if (warp_shape_ && jacobians[warp_block]) {
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[warp_block]);
    J = (dq_dp * Rc * Rb.col(2)) * warp_shape_->transpose();
  }
  return true;
}

}  // namespace mcms
