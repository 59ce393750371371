#include "model/flange_pose.h"

namespace mcms {

PoseWithCovariance CameraFlangePose(const CellGeometry& cell, const Pose& T_rig_target, const Mat6& covariance_rig) {
  const Pose T_target_flange = cell.T_flange_target.Inverse();
  PoseWithCovariance out;
  out.T = cell.T_base_rig * T_rig_target * T_target_flange;
  out.covariance = TransformPoseCovariance(covariance_rig, cell.T_base_rig, T_rig_target, T_target_flange);
  // A registration error [dtheta_b; dp_b] moves the flange by dtheta_b and
  // dp_b + dtheta_b x (p_flange - p_rig).
  Mat6 K = Mat6::Identity();
  K.bottomLeftCorner<3, 3>() = -Skew(out.T.t - cell.T_base_rig.t);
  out.covariance += K * cell.T_base_rig_covariance * K.transpose();
  out.covariance = 0.5 * (out.covariance + out.covariance.transpose()).eval();
  return out;
}

PoseWithCovariance RobotFlangePose(const RobotModel& robot, const Eigen::VectorXd& q, const Eigen::MatrixXd& Q,
                                   const Mat6& accuracy_covariance, RobotModel::EndFrame end) {
  PoseWithCovariance out;
  out.T = end == RobotModel::EndFrame::kTool ? robot.T_base_tool(q) : robot.T_base_flange(q);
  out.covariance = robot.PoseCovariance(q, Q, end) + accuracy_covariance;
  out.covariance = 0.5 * (out.covariance + out.covariance.transpose()).eval();
  return out;
}

}  // namespace mcms
