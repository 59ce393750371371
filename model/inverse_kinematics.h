// Inverse kinematics of a serial robot's flange (model/robot_model.h): damped least
// squares on the geometric Jacobian, each step projected onto the joint limits, so every
// iterate is a valid configuration and an unreachable goal ends as a reason, not an
// exception.
#pragma once

#include <optional>
#include <string>

#include <Eigen/Core>

#include "core/pose_math.h"
#include "model/robot_model.h"

namespace mcms {

struct IkOptions {
  int max_iterations = 200;
  double damping = 1e-3;        // lambda of (J J^T + lambda^2 I)
  double tolerance = 1e-9;      // |BoxMinus(goal, reached)| accepted as a solution (rad, m)
  bool IsValid(std::string* why) const;
};

// Joint values q with T_base_flange(q) = T_base_flange_goal, starting from `seed` (clamped
// into the limits first). nullopt when it does not converge within the limits; `why` (when
// not null) then says how far the closest configuration found stays from the goal, and
// which joints sit on a limit.
std::optional<Eigen::VectorXd> SolveIk(const RobotModel& robot, const Pose& T_base_flange_goal,
                                       const Eigen::VectorXd& seed, std::string* why = nullptr,
                                       const IkOptions& options = {});

}  // namespace mcms
