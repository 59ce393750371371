// A synthetic URDF robot for the tests: a pedestal, a prismatic lift and six revolute joints
// (axes along z, y and x of their frames, one continuous), fixed joints inside the chain and
// after it, and branches off the chain that carry mass (a head on the lift, a finger on the
// hand beyond the tip). Its numbers are made up but of a service arm's size (link lengths
// 0.05-0.3 m, masses 0.1-6 kg).
#pragma once

#include <string>

namespace mcms::test {

inline std::string SevenJointUrdf() {
  return R"(<?xml version="1.0"?>
<robot name="seven">
  <link name="world"/>
  <joint name="pedestal_joint" type="fixed">
    <parent link="world"/><child link="pedestal"/>
    <origin xyz="0.1 -0.05 0.3" rpy="0 0 0.2"/>
  </joint>
  <link name="pedestal">
    <inertial><origin xyz="0 0 -0.15"/><mass value="20"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
  </link>
  <joint name="lift_joint" type="prismatic">
    <parent link="pedestal"/><child link="lift"/>
    <origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.4" effort="1000" velocity="0.1"/>
  </joint>
  <link name="lift">
    <inertial><origin xyz="0.05 0 -0.1"/><mass value="6"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <joint name="head_joint" type="revolute">
    <parent link="lift"/><child link="head"/>
    <origin xyz="0 0 0.25"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/>
  </joint>
  <link name="head">
    <inertial><origin xyz="0.02 0 0.05"/><mass value="1.2"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="shoulder_mount_joint" type="fixed">
    <parent link="lift"/><child link="shoulder_mount"/>
    <origin xyz="0.1 0.02 0.05" rpy="0 0 -0.3"/>
  </joint>
  <link name="shoulder_mount"/>
  <joint name="j1" type="revolute">
    <parent link="shoulder_mount"/><child link="l1"/>
    <origin xyz="0.05 0 0.05" rpy="0 0 -1.5707963267948966"/><axis xyz="0 0 1"/>
    <limit lower="-2.8" upper="2.8" effort="40" velocity="2"/>
  </joint>
  <link name="l1">
    <inertial><origin xyz="0.05 0 0"/><mass value="2.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.12 0 0.03" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1.6" upper="1.6" effort="40" velocity="2"/>
  </joint>
  <link name="l2">
    <inertial><origin xyz="0.1 0 0.01"/><mass value="2"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j3" type="revolute">
    <parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0" rpy="0 0.1 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="30" velocity="2"/>
  </joint>
  <link name="l3">
    <inertial><origin xyz="0.1 0.01 0"/><mass value="1.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j4" type="revolute">
    <parent link="l3"/><child link="l4"/>
    <origin xyz="0.25 0.01 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.2" upper="2.2" effort="20" velocity="2"/>
  </joint>
  <link name="l4">
    <inertial><origin xyz="0 0 0.05"/><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j5" type="revolute">
    <parent link="l4"/><child link="l5"/>
    <origin xyz="0.05 0 0.12" rpy="0 0 0.2"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="2"/>
  </joint>
  <link name="l5">
    <inertial><origin xyz="0.03 0 0"/><mass value="0.6"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="j6" type="continuous">
    <parent link="l5"/><child link="l6"/>
    <origin xyz="0.08 0 0" rpy="1.5707963267948966 0 1.5707963267948966"/><axis xyz="0 0 1"/>
  </joint>
  <link name="l6">
    <inertial><origin xyz="0 0 0.02"/><mass value="0.3"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="tool_joint" type="fixed">
    <parent link="l6"/><child link="tool"/>
    <origin xyz="0 0.01 0.06" rpy="0 0 0.5"/>
  </joint>
  <link name="tool"/>
  <joint name="hand_joint" type="fixed">
    <parent link="tool"/><child link="hand"/>
    <origin xyz="0 0 0.02"/>
  </joint>
  <link name="hand">
    <inertial><origin xyz="0 0 0.05"/><mass value="0.8"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="finger_joint" type="revolute">
    <parent link="hand"/><child link="finger"/>
    <origin xyz="0.03 0 0.08"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <link name="finger">
    <inertial><origin xyz="0 0 0.03"/><mass value="0.1"/><inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial>
  </link>
</robot>
)";
}

}  // namespace mcms::test
