// Robots as ROS describes them: a serial chain read from a URDF (Unified Robot Description
// Format) with Debian's urdfdom, the ROS parser, and written back with the calibration's
// corrections folded into the joints' <origin> elements.
//
// The chain runs from a base link to a tip link. Its movable joints (revolute, continuous,
// prismatic) become the model's joints (ChainConvention::kUrdf, model/joint.h): joint i's
// frame is its child link's frame, placed in joint i-1's frame by `origin` (the fixed
// joints between the two folded in) and moved about or along `axis`. The fixed joints
// after the last movable one make the tool transform T_flange_tool (flange = the last
// movable joint's child link, tool = the tip link). A mimic joint inside the chain follows
// its driving joint (model/joint.h: the log records the driver, RobotModel::ActuatedJoints),
// with placement errors of its own; floating and planar joints inside the chain are refused
// by name. Without --tip-link, the tip is the leaf farthest from the base in movable
// joints; leaves after the same last joint (a tool frame beside a sensor frame) are one
// chain, and the tool-like one (tool0, tool, tcp, ...) is taken, said in
// UrdfSource::tip_note. A link mass of 0 is a massless (virtual) link. Trees are walked
// without recursion; a file beyond kMaxRobotLinks links or a chain beyond kMaxRobotJoints
// movable joints (core/limits.h) is refused.
//
// The arm's weight comes from the links' <inertial> elements: each joint's link carries
// every link rigidly attached to it, including the branches off the chain (a head on the
// torso, the hand and fingers beyond the tip) with their own joints at zero, so that each
// joint feels the whole subtree beyond it. A chain whose moving links have no inertial at
// all has no masses (RobotModel::HasMasses false).
#pragma once

#include <filesystem>
#include <map>
#include <string>

#include "model/robot_model.h"

namespace mcms {

// Whether a robot file is a URDF (by its extension .urdf, or .xml / no known extension
// with a <robot> root element).
bool IsUrdfFile(const std::filesystem::path& path);

// InputError naming the file and the element: a URDF urdfdom rejects (its own message
// kept), an unknown base or tip link (the links listed), no chain between them (the
// links on the tip's path listed), an ambiguous tip (the leaves listed with their depths),
// a floating or planar joint in the chain, a mimic joint whose driver is missing, a zero
// axis, a negative or non-finite inertial mass, a xacro file (with the command that
// expands it).
RobotModel ReadUrdf(const std::filesystem::path& path, const ChainSelection& chain = {});
RobotModel ParseUrdf(const std::string& xml, const std::string& source, const ChainSelection& chain = {});

// Where a sensor fixed to URDF link `link` rides on the robot's chain (issue 52: tilt
// sensors named by their links): the index into RobotModel::LinkFrames of the moving link it
// is fixed to (0: the chain's base) and its rotation in that frame (the fixed joints'
// origins between). InputError naming the link: not a link of the URDF (the links listed),
// on a branch off the chain (a moving joint between it and the chain), or the robot not
// read from a URDF.
struct LinkMount {
  std::string link;
  int frame = 0;
  Mat3 R_frame_link = Mat3::Identity();
};
LinkMount MountOnChain(const RobotModel& robot, const std::string& link);

// The robot's URDF with every chain joint's <origin> set to the model's placement (for a
// calibrated model: the corrections folded in, exactly: FK of the written file equals the
// model's T_base_flange), every other element as it was. `comments` (joint name -> text)
// are written as an XML comment before that joint's <origin>: the parameters with sigma.
// For a robot not read from a URDF (a DH table, or a URDF chain read back from its YAML
// form), a new URDF of the chain (mimic joints with their drivers on branches): links
// <joint>_link, the masses as inertials, the tool as a fixed joint to the link `tool`.
// InputError for a robot with error motion (URDF cannot hold it).
std::string UrdfText(const RobotModel& robot, const std::map<std::string, std::string>& comments = {});
void WriteUrdf(const std::filesystem::path& path, const RobotModel& robot,
               const std::map<std::string, std::string>& comments = {});

}  // namespace mcms
