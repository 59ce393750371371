// The ROS-Industrial two-axis positioner data set (/work/shared/data/
// industrial-calibration-positioner) as the calib tests use it: its nominal chain and the
// upstream starting guesses. Shared by test_calib_positioner and test_audit_robot.
#pragma once

#include <numbers>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <vector>

#include "core/pose_math.h"
#include "model/robot_model.h"

namespace mcms::test {

// Upstream DH rows (d, theta, r, alpha), standard DH: j1 (0, 0, 0, -pi/2), j2 (-0.475, -pi/2, 0, 0).
inline RobotModel Positioner(const Pose& tool) {
  std::vector<Joint> j(2);
  j[0].name = "j1";
  j[0].alpha = -std::numbers::pi / 2;
  j[0].lower = -std::numbers::pi;
  j[0].upper = std::numbers::pi;
  j[1].name = "j2";
  j[1].d = -0.475;
  j[1].theta_offset = -std::numbers::pi / 2;
  j[1].lower = -2 * std::numbers::pi;
  j[1].upper = 2 * std::numbers::pi;
  return RobotModel("two-axis positioner", ChainConvention::kStandard, j, tool);
}

// A pose of pose_initial_guesses.yaml: {x, y, z, qw, qx, qy, qz}.
inline Pose ReadGuess(const YAML::Node& n) {
  return Pose::FromQuaternion(
      Eigen::Quaterniond(n["qw"].as<double>(), n["qx"].as<double>(), n["qy"].as<double>(), n["qz"].as<double>())
          .normalized(),
      Vec3(n["x"].as<double>(), n["y"].as<double>(), n["z"].as<double>()));
}

// The sensor in the positioner's base: T_camera_base = T_world_camera^-1 T_world_positionerbase,
// T_world_positionerbase = Trans(2.2, 0, 1.6) Rx(pi/2).
inline Pose PositionerBaseGuess(const YAML::Node& guesses) {
  const Pose T_world_base{Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()).toRotationMatrix(), Vec3(2.2, 0.0, 1.6)};
  return ReadGuess(guesses["camera_mount_to_camera_guess"]).Inverse() * T_world_base;
}

}  // namespace mcms::test
