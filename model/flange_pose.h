// The flange pose in the robot base frame, with its covariance, as each sensor sees it:
// the camera rig through its registration and the target's mounting, the robot through
// its kinematics and encoder noise. Every fusion path and experiment converts through
// these two functions, so the model of how a sensor sees the flange lives here once.
//
// Covariances in the [dtheta; dp] layout of docs/conventions.md, base frame.
#pragma once

#include <Eigen/Core>

#include "core/pose_math.h"
#include "model/robot_model.h"

namespace mcms {

struct PoseWithCovariance {
  Pose T;
  Mat6 covariance = Mat6::Zero();
};

// Where the rig and the target sit: T_base_rig (with the covariance of the registration,
// [dtheta; dp] of T_base_rig in the base frame) and T_flange_target (taken as exact).
struct CellGeometry {
  Pose T_base_rig;
  Mat6 T_base_rig_covariance = Mat6::Zero();
  Pose T_flange_target;
};

// T_base_flange = T_base_rig T_rig_target T_target_flange from the rig's measurement of
// the target (covariance_rig: [dtheta; dp] of T_rig_target in the rig frame), the
// registration's uncertainty added to first order.
PoseWithCovariance CameraFlangePose(const CellGeometry& cell, const Pose& T_rig_target, const Mat6& covariance_rig);

// T_base_flange from joint readings q with joint covariance Q (n x n) through the robot's
// kinematics (J Q J^T, paper eq. 8), plus the robot's absolute-accuracy covariance. `end`:
// the frame the fusion calls the flange (kTool where the robot's tool frame is that flange,
// as a fusion setup's robot: a URDF's tip link).
PoseWithCovariance RobotFlangePose(const RobotModel& robot, const Eigen::VectorXd& q, const Eigen::MatrixXd& Q,
                                   const Mat6& accuracy_covariance,
                                   RobotModel::EndFrame end = RobotModel::EndFrame::kFlange);

}  // namespace mcms
