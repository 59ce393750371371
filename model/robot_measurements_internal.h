// What the robot log's files share (model/robot_measurements.h is the entry).
#pragma once

#include <string>

#include "model/robot_model.h"

namespace mcms::robot_log_internal {

// The joint's name in the robot description, or "joint <i+1>" when it has none.
std::string JointName(const RobotModel& robot, int i);

}  // namespace mcms::robot_log_internal
