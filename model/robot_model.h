// A serial robot described by Denavit-Hartenberg parameters: forward kinematics, link
// frames, the geometric Jacobian in the project's pose-covariance layout, and the pose
// covariance that joint-encoder noise produces at the flange (paper eq. 8, J Q J^T).
//
// Conventions (docs/conventions.md): SI units (m, rad); T_base_flange maps flange
// coordinates to base coordinates; pose errors are [dtheta; dp] with
// R = Exp(dtheta) * R_hat and p = p_hat + dp, both expressed in the BASE frame.
//
// A robot is data, not code: RobotModel::Read parses a YAML description (format in
// model/robots/kuka_kr5_arc.yaml, the default robot, whose text is embedded into the
// library at build time so RobotModel::Default() needs no source tree).
#pragma once

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose_math.h"
#include "model/joint.h"

namespace mcms {

// A mass carried at the flange (a tool, the target, a gripper): kg and its centre of mass
// in the flange frame (m).
struct ToolMass {
  double mass_kg = 0.0;
  Vec3 com_m = Vec3::Zero();
};

class RobotModel {
 public:
  // Which frame the Jacobian and the pose covariance refer to.
  enum class EndFrame { kFlange, kTool };

  RobotModel() = default;
  // InputError when there are no joints, a parameter is not finite, a limit range is
  // empty, an encoder sigma is negative, or the link masses are not all given (finite,
  // >= 0, with finite centres of mass) or all left out.
  RobotModel(std::string name, DhConvention convention, std::vector<Joint> joints,
             const Pose& T_flange_tool = Pose::Identity());

  // The KUKA KR 5 arc of the paper, from the embedded model/robots/kuka_kr5_arc.yaml.
  static RobotModel Default();
  // YAML description; InputError naming the file, the joint and the field on bad input.
  static RobotModel Read(const std::filesystem::path& path);
  // The same from text; `source` names the text in error messages.
  static RobotModel Parse(const std::string& yaml_text, const std::string& source);
  // Writes every number with 17 significant digits in radians and metres, so
  // Read(Write(m)) reproduces m exactly.
  void Write(const std::filesystem::path& path) const;
  std::string ToYaml() const;

  const std::string& Name() const { return name_; }
  DhConvention Convention() const { return convention_; }
  const std::vector<Joint>& Joints() const { return joints_; }
  int NumJoints() const { return static_cast<int>(joints_.size()); }
  const Pose& T_flange_tool() const { return T_flange_tool_; }
  void SetT_flange_tool(const Pose& T) { T_flange_tool_ = T; }
  // Whether the description gives the links' masses (every joint's mass_kg); then the
  // gravity torque of the arm on each joint is known up to the joints' compliances.
  bool HasMasses() const;
  // The same robot (name, convention, tool and its mass) with another joint table.
  RobotModel WithJoints(std::vector<Joint> joints) const;
  // The tool's mass (YAML `tool: {mass_kg, com_m}`; zero when not given). InputError when
  // not finite or negative.
  const ToolMass& Tool() const { return tool_mass_; }
  void SetToolMass(const ToolMass& m);

  // InputError when q has the wrong size, a value is not finite, or a joint is outside
  // its limits; the message names the joint and the limit (in degrees for revolute joints).
  void CheckJoints(const Eigen::VectorXd& q) const;
  // The same test without throwing; `why` receives the reason when not null.
  bool WithinLimits(const Eigen::VectorXd& q, std::string* why = nullptr) const;

  // Forward kinematics. Every function taking q calls CheckJoints(q) first.
  Pose T_base_flange(const Eigen::VectorXd& q) const;
  Pose T_base_tool(const Eigen::VectorXd& q) const { return T_base_flange(q) * T_flange_tool_; }
  // All link frames T_base_link_i, i = 0..n: element 0 is the base (identity), element n
  // the flange.
  std::vector<Pose> LinkFrames(const Eigen::VectorXd& q) const;

  // Geometric Jacobian (6 x n) of the end frame's pose in the [dtheta; dp] layout, base
  // frame: a joint change dq moves the pose to R = Exp(J_rot dq) R, p = p + J_pos dq to
  // first order. Column i of a revolute joint is [w_i; w_i x (p_end - o_i)] with w_i the
  // joint axis and o_i a point on it; of a prismatic joint [0; w_i]. A joint's error
  // motion enters through the link frames (the axis as displaced at q), not through its
  // rate dE/dq, which is of the error motion's own size (1e-4 and below) relative to the column.
  Eigen::Matrix<double, 6, Eigen::Dynamic> Jacobian(const Eigen::VectorXd& q,
                                                    EndFrame end = EndFrame::kTool) const;

  // Diagonal n x n covariance of the encoder readings, encoder_sigma^2.
  Eigen::MatrixXd EncoderCovariance() const;
  // Pose covariance J Q J^T (paper eq. 8), full 6x6 in [dtheta; dp], from a joint
  // covariance Q (n x n, symmetric positive semi-definite; InputError otherwise).
  Mat6 PoseCovariance(const Eigen::VectorXd& q, const Eigen::MatrixXd& Q, EndFrame end = EndFrame::kTool) const;
  // The same with Q = EncoderCovariance().
  Mat6 PoseCovariance(const Eigen::VectorXd& q, EndFrame end = EndFrame::kTool) const;

 private:
  // Link transform of joint i at joint value qi.
  Pose LinkTransform(int i, double qi) const;
  std::string name_;
  DhConvention convention_ = DhConvention::kStandard;
  std::vector<Joint> joints_;
  Pose T_flange_tool_;
  ToolMass tool_mass_;
};

}  // namespace mcms
