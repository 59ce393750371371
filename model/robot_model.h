// A serial robot described by Denavit-Hartenberg parameters or, as ROS describes robots,
// by a URDF chain (model/urdf.h): forward kinematics, link frames, the geometric Jacobian
// in the project's pose-covariance layout, the pose covariance that joint-encoder noise
// produces at the flange (paper eq. 8, J Q J^T), and the geometric error model shared by
// calibration and the audit (model/joint.h).
//
// Conventions (docs/conventions.md): SI units (m, rad); T_base_flange maps flange
// coordinates to base coordinates; pose errors are [dtheta; dp] with
// R = Exp(dtheta) * R_hat and p = p_hat + dp, both expressed in the BASE frame.
//
// A robot is data, not code: RobotModel::Read parses a YAML description (format in
// model/robots/kuka_kr5_arc.yaml, the default robot, whose text is embedded into the
// library at build time so RobotModel::Default() needs no source tree) or a URDF.
#pragma once

#include <filesystem>
#include <limits>
#include <memory>
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

// Which part of a URDF tree is the robot: empty names mean the URDF's root link, and the tip
// that is unambiguous (the one leaf farthest from the base in movable joints).
inline constexpr double kStandardGravity = 9.80665;  // m/s^2

struct ChainSelection {
  std::string base_link, tip_link;
};

// What a robot read from a URDF keeps of it: the text (to write a calibrated URDF back with
// every other element unchanged), the chain's ends, every joint name of the file, and per
// movable joint the fixed placements folded in before its own <origin>.
struct UrdfSource {
  std::string text, source, base_link, tip_link;
  std::string tip_note;  // how the tip was chosen when not given (leaves on one chain), else empty
  std::vector<std::string> all_joints;
  std::vector<Pose> prefix;
};

// A joint's axis at a pose, in the base frame: unit direction w and a point o on it.
struct JointAxis {
  Vec3 w = Vec3::UnitZ(), o = Vec3::Zero();
};

class RobotModel {
 public:
  // How far (a share of the range) a measured joint reading may pass a limit of the robot
  // description (model/robot_measurements.h CoverReadings widens the limits to such
  // readings): real readings do, by an overshoot or a joint zero that is itself a little off
  // (a TIAGo's torso reads 5 mm, 1.5 % of its range, below its URDF limit); another unit or
  // another robot passes by far more. The model's own limits are strict.
  static constexpr double kLimitSlack = 0.02;
  // Which frame the Jacobian and the pose covariance refer to.
  enum class EndFrame { kFlange, kTool };
  // A joint a log records (issue 51): every chain joint that mimics none, and the driver of
  // mimic joints, in chain order (a driver outside the chain where its first mimic joint
  // is); its range is the one its mimic joints' limits imply. Without mimic joints, the
  // chain's joints.
  struct ActuatedJoint {
    std::string name;
    JointType type = JointType::kRevolute;
    double lower = -std::numeric_limits<double>::infinity(), upper = std::numeric_limits<double>::infinity();
  };

  RobotModel() = default;
  // InputError when there are no joints, a parameter is not finite, a limit range is
  // empty, an encoder sigma is negative, or the link masses are not all given (finite,
  // >= 0, with finite centres of mass) or all left out.
  RobotModel(std::string name, ChainConvention convention, std::vector<Joint> joints,
             const Pose& T_flange_tool = Pose::Identity());

  // The KUKA KR 5 arc of the paper, from the embedded model/robots/kuka_kr5_arc.yaml.
  static RobotModel Default();
  // A YAML description, or a URDF (model/urdf.h: by its extension .urdf, or an XML file with
  // a <robot> element) with the chain `chain` picks; InputError naming the file, the joint
  // and the field on bad input.
  static RobotModel Read(const std::filesystem::path& path, const ChainSelection& chain = {});
  // The same from text; `source` names the text in error messages.
  static RobotModel Parse(const std::string& yaml_text, const std::string& source);
  // Writes every number with 17 significant digits in radians and metres, so
  // Read(Write(m)) reproduces m exactly (a URDF chain as `convention: urdf`).
  void Write(const std::filesystem::path& path) const;
  std::string ToYaml() const;

  const std::string& Name() const { return name_; }
  ChainConvention Convention() const { return convention_; }
  const std::vector<Joint>& Joints() const { return joints_; }
  int NumJoints() const { return static_cast<int>(joints_.size()); }
  // The joints a log records and the chain's values from theirs (ChainValues; the identity
  // without mimic joints), and back (each driver from its first mimic joint).
  const std::vector<ActuatedJoint>& ActuatedJoints() const { return actuated_; }
  int NumActuated() const { return static_cast<int>(actuated_.size()); }
  bool HasMimicJoints() const { return mimic_; }
  // The actuated joint that drives chain joint i, and d(q_i)/d(q_actuated).
  int ActuatedOf(int i) const { return actuated_of_[i]; }
  Eigen::VectorXd ChainValues(const Eigen::VectorXd& q_actuated) const;
  Eigen::VectorXd ActuatedValues(const Eigen::VectorXd& q_chain) const;
  const Pose& T_flange_tool() const { return T_flange_tool_; }
  // The geometric error model (model/joint.h): parameters per joint and in all.
  int GeometryParamsPerJoint() const { return mcms::GeometryParamsPerJoint(convention_); }
  int NumGeometryParameters() const { return GeometryParamsPerJoint() * NumJoints(); }
  // Joint i's offset among its geometric parameters (theta for a revolute joint, d for a
  // prismatic one in a DH table; the placement's term along the axis in a URDF chain).
  int OffsetParameter(int i) const { return mcms::OffsetParameter(convention_, joints_[i].type); }
  // Whether the chain's geometric terms are a DH table's (offset, link lengths, twist, each
  // a catalog term of its own, and error motion in the robot file) rather than a URDF
  // placement's six, which are fitted and written back only all at once.
  bool HasDhTerms() const { return convention_ != ChainConvention::kUrdf; }
  // The URDF the robot was read from (null for a DH table).
  const UrdfSource* Urdf() const { return urdf_.get(); }
  void SetUrdf(std::shared_ptr<const UrdfSource> urdf) { urdf_ = std::move(urdf); }
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
  // The same test without throwing; `why` receives the reason when not null. With `slack`,
  // each limit is widened by that share of its joint's range.
  bool WithinLimits(const Eigen::VectorXd& q, std::string* why = nullptr, double slack = 0.0) const;

  // Forward kinematics. Every function taking q calls CheckJoints(q) first.
  Pose T_base_flange(const Eigen::VectorXd& q) const;
  Pose T_base_tool(const Eigen::VectorXd& q) const { return T_base_flange(q) * T_flange_tool_; }
  // All link frames T_base_link_i, i = 0..n: element 0 is the base (identity), element n
  // the flange.
  std::vector<Pose> LinkFrames(const Eigen::VectorXd& q) const;
  // Joint i's axis given the link frames of LinkFrames (standard DH: z of frame i-1;
  // modified DH: z of frame i; URDF: frame i's axis through its origin).
  JointAxis AxisOf(const std::vector<Pose>& frames, int i) const;

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
  ChainConvention convention_ = ChainConvention::kStandard;
  std::vector<Joint> joints_;
  Pose T_flange_tool_;
  ToolMass tool_mass_;
  std::shared_ptr<const UrdfSource> urdf_;
  std::vector<ActuatedJoint> actuated_;
  std::vector<int> actuated_of_;  // per chain joint
  bool mimic_ = false;
};

// Names of the geometric error parameters in the layout of model/joint.h, joint by joint:
// "<joint>.theta_offset", ".d", ".a", ".alpha" (DH) or "<joint>.offset", ".x", ".y", ".z",
// ".rx", ".ry", ".rz" (URDF); a joint without a name is J<i>.
std::vector<std::string> GeometryParameterNames(const RobotModel& robot);
// Whether geometric parameter k (of the layout) is an angle (rad) rather than a length (m).
bool GeometryParameterIsAngle(const RobotModel& robot, int k);
// The largest standard deviation with which a geometric parameter is worth estimating: a
// robot's placements are not off by more than a few degrees or centimetres, so a parameter
// the poses determine only to worse than this (kWeakGeometryAngleRad, kWeakGeometryLengthM)
// is weakly identifiable: held at its nominal value, never written into a calibrated robot
// (issue 51: a wrist offset of -17.6 +- 26.6 deg was). Angle or length by
// GeometryParameterIsAngle.
inline constexpr double kWeakGeometryAngleRad = 0.035;  // 2 deg
inline constexpr double kWeakGeometryLengthM = 0.02;
double WeakGeometrySigma(const RobotModel& robot, int k);
// The largest geometric error a calibration may find (a bound of its fit): a placement off
// by more is another robot's description, not this one's error.
inline constexpr double kMaxGeometryErrorRad = 0.2, kMaxGeometryErrorM = 0.2;
// The robot with geometric errors `delta` (NumGeometryParameters values) folded into its
// description: added to the DH table, or into each URDF joint's origin (origin G M(offset)),
// so that its forward kinematics equals the error model's exactly.
RobotModel WithGeometryErrors(const RobotModel& robot, const Eigen::VectorXd& delta);
// The geometric errors (NumGeometryParameters values) by which every link length grows by
// the same relative amount 1 (thermal growth): each DH a and d, or each URDF origin's
// translation, times 1.
Eigen::VectorXd UniformGrowth(const RobotModel& robot);

}  // namespace mcms
