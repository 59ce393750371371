// Robots as ROS describes them (model/urdf.h): a URDF chain parsed with urdfdom, its forward
// kinematics, Jacobian, masses and gravity torques against independent computations, the
// geometric error model, the calibrated URDF written back, DH tables written as URDF, and
// every bad input named.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>

#include <Eigen/Geometry>

#include "core/random.h"
#include "model/extensions.h"
#include "model/kinematics.h"
#include "model/robot_model.h"
#include "model/urdf.h"
#include "tests/gradient_check.h"
#include "tests/test_util.h"
#include "tests/urdf_robots.h"

namespace mcms {
namespace {

using test::ErrorOf;
using test::SevenJointUrdf;

RobotModel Seven() { return ParseUrdf(SevenJointUrdf(), "seven.urdf", {"world", "tool"}); }

Eigen::VectorXd SomeJoints(int n, uint64_t seed) {
  Rng rng(seed);
  Eigen::VectorXd q(n);
  for (int i = 0; i < n; ++i) q[i] = rng.Uniform(-1.0, 1.0);
  q[0] = rng.Uniform(0.05, 0.35);  // the lift (m)
  return q;
}

// The seven-joint robot's FK written out from the URDF's numbers with Eigen's own transforms:
// each joint Translation(xyz) Rz(y) Ry(p) Rx(r), then its motion.
Eigen::Isometry3d IndependentFk(const Eigen::VectorXd& q) {
  const auto Origin = [](double x, double y, double z, double r, double p, double yaw) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translate(Eigen::Vector3d(x, y, z));
    T.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(p, Eigen::Vector3d::UnitY()) *
             Eigen::AngleAxisd(r, Eigen::Vector3d::UnitX()));
    return T;
  };
  const auto Rot = [](const Eigen::Vector3d& axis, double a) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.rotate(Eigen::AngleAxisd(a, axis));
    return T;
  };
  const double h = 1.5707963267948966;
  Eigen::Isometry3d T = Origin(0.1, -0.05, 0.3, 0, 0, 0.2);                   // pedestal (fixed)
  T = T * Origin(0, 0, 0.2, 0, 0, 0);                                         // lift
  T.translate(Eigen::Vector3d(0, 0, q[0]));
  T = T * Origin(0.1, 0.02, 0.05, 0, 0, -0.3);                                // shoulder mount (fixed)
  T = T * Origin(0.05, 0, 0.05, 0, 0, -h) * Rot(Eigen::Vector3d::UnitZ(), q[1]);  // j1
  T = T * Origin(0.12, 0, 0.03, h, 0, 0) * Rot(Eigen::Vector3d::UnitZ(), q[2]);   // j2
  T = T * Origin(0.3, 0, 0, 0, 0.1, 0) * Rot(Eigen::Vector3d::UnitY(), q[3]);     // j3
  T = T * Origin(0.25, 0.01, 0, -h, 0, 0) * Rot(Eigen::Vector3d::UnitZ(), q[4]);  // j4
  T = T * Origin(0.05, 0, 0.12, 0, 0, 0.2) * Rot(Eigen::Vector3d::UnitX(), q[5]); // j5
  T = T * Origin(0.08, 0, 0, h, 0, h) * Rot(Eigen::Vector3d::UnitZ(), q[6]);      // j6
  return T * Origin(0, 0.01, 0.06, 0, 0, 0.5);                                // tool (fixed)
}

TEST(Urdf, ReadsTheChainBetweenBaseAndTip) {
  const RobotModel r = Seven();
  ASSERT_EQ(r.NumJoints(), 7);
  EXPECT_EQ(r.Convention(), ChainConvention::kUrdf);
  const char* names[7] = {"lift_joint", "j1", "j2", "j3", "j4", "j5", "j6"};
  for (int i = 0; i < 7; ++i) EXPECT_EQ(r.Joints()[i].name, names[i]);
  EXPECT_EQ(r.Joints()[0].type, JointType::kPrismatic);
  EXPECT_EQ(r.Joints()[3].type, JointType::kRevolute);
  EXPECT_DOUBLE_EQ(r.Joints()[0].upper, 0.4);
  EXPECT_DOUBLE_EQ(r.Joints()[2].lower, -1.6);
  EXPECT_TRUE(std::isinf(r.Joints()[6].upper));  // continuous
  ASSERT_NE(r.Urdf(), nullptr);
  EXPECT_EQ(r.Urdf()->base_link, "world");
  EXPECT_EQ(r.Urdf()->tip_link, "tool");
  // Without --tip-link the farthest leaf (the finger, 8 movable joints below the root) is the tip.
  const RobotModel whole = ParseUrdf(SevenJointUrdf(), "seven.urdf");
  EXPECT_EQ(whole.NumJoints(), 8);
  EXPECT_EQ(whole.Joints().back().name, "finger_joint");
}

TEST(Urdf, ForwardKinematicsEqualsTheUrdfWrittenOut) {
  const RobotModel r = Seven();
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const Eigen::VectorXd q = SomeJoints(7, seed);
    const Pose T = r.T_base_tool(q);
    const Eigen::Isometry3d E = IndependentFk(q);
    EXPECT_LT((T.t - E.translation()).norm(), 1e-12) << "seed " << seed;
    EXPECT_LT((T.R - E.rotation()).norm(), 1e-12) << "seed " << seed;
  }
}

TEST(Urdf, JacobianMatchesNumericDerivatives) {
  const RobotModel r = Seven();
  const Eigen::VectorXd q = SomeJoints(7, 3);
  const auto J = r.Jacobian(q);
  const Pose T0 = r.T_base_tool(q);
  const Eigen::MatrixXd N = test::NumericJacobian(
      [&](const Eigen::VectorXd& x) {
        const Pose T = r.T_base_tool(x);
        Eigen::VectorXd v(6);
        v << LogSO3(T.R * T0.R.transpose()), T.t;
        return v;
      },
      q, 1e-6);
  EXPECT_LT((J - N).cwiseAbs().maxCoeff(), 1e-7);
}

TEST(Urdf, LinksCarryTheWholeSubtreeBeyondThem) {
  const RobotModel r = Seven();
  ASSERT_TRUE(r.HasMasses());
  // The lift carries its own 6 kg and the head on it (1.2 kg); j6's link its own 0.3 kg and
  // the hand (0.8) and finger (0.1) beyond the tip.
  EXPECT_NEAR(*r.Joints()[0].mass_kg, 7.2, 1e-12);
  EXPECT_NEAR(*r.Joints()[6].mass_kg, 1.2, 1e-12);
  EXPECT_NEAR(*r.Joints()[1].mass_kg, 2.5, 1e-12);
  EXPECT_EQ(r.Tool().mass_kg, 0.0);
}

// The gravity torque on each joint is minus the derivative of the potential energy of every
// link's mass (off-chain ones included) with respect to the joint.
TEST(Urdf, GravityTorqueIsMinusTheDerivativeOfThePotentialEnergy) {
  const RobotModel r = Seven();
  const auto V = [&](const Eigen::VectorXd& q) {
    const std::vector<Pose> F = r.LinkFrames(q);
    double v = 0;
    for (int i = 0; i < r.NumJoints(); ++i) v += *r.Joints()[i].mass_kg * 9.80665 * (F[i + 1] * r.Joints()[i].com_m).z();
    Eigen::VectorXd out(1);
    out << v;
    return out;
  };
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    const Eigen::VectorXd q = SomeJoints(7, seed);
    const Eigen::VectorXd tau = GravityTorque(r, q, 0.0);
    const Eigen::VectorXd dV = test::NumericJacobian(V, q, 1e-6).row(0).transpose();
    EXPECT_LT((tau + dV).cwiseAbs().maxCoeff(), 1e-6) << "seed " << seed << ": " << tau.transpose() << " vs "
                                                      << -dV.transpose();
    // The prismatic lift carries every link above it: its torque is their weight.
    double above = 0;
    for (const Joint& j : r.Joints()) above += j.mass_kg.value_or(0.0);
    EXPECT_NEAR(tau[0], -above * 9.80665, 1e-9);
  }
}

TEST(Urdf, GeometricErrorModelIsFoldedIntoTheOriginsExactly) {
  const RobotModel r = Seven();
  ASSERT_EQ(r.GeometryParamsPerJoint(), 7);
  Rng rng(7);
  Eigen::VectorXd delta(r.NumGeometryParameters());
  for (int k = 0; k < delta.size(); ++k) delta[k] = rng.Normal(0.0, 2e-3);
  const RobotModel cal = WithGeometryErrors(r, delta);
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    const Eigen::VectorXd q = SomeJoints(7, seed);
    ChainCorrections<double> c;
    c.geometry = delta.data();
    const PoseT<double> M = ForwardKinematicsT(r, q, c);
    const Pose F = cal.T_base_flange(q);
    EXPECT_LT((M.t - F.t).norm(), 1e-12);
    EXPECT_LT((M.R - F.R).norm(), 1e-12);
  }
  // The names of the error model.
  const auto names = GeometryParameterNames(r);
  ASSERT_EQ(static_cast<int>(names.size()), 49);
  EXPECT_EQ(names[7], "j1.offset");
  EXPECT_EQ(names[9], "j1.y");
  EXPECT_EQ(names[12], "j1.ry");
  EXPECT_TRUE(GeometryParameterIsAngle(r, 7));    // j1's offset
  EXPECT_FALSE(GeometryParameterIsAngle(r, 9));   // j1.y
  EXPECT_TRUE(GeometryParameterIsAngle(r, 12));   // j1.ry
  EXPECT_FALSE(GeometryParameterIsAngle(r, 0));   // the lift's offset is a length
}

TEST(Urdf, CalibratedUrdfParsesAndReproducesTheCalibratedModel) {
  const RobotModel r = Seven();
  Rng rng(11);
  Eigen::VectorXd delta(r.NumGeometryParameters());
  for (int k = 0; k < delta.size(); ++k) delta[k] = rng.Normal(0.0, 3e-3);
  const RobotModel cal = WithGeometryErrors(r, delta);
  const std::string text = UrdfText(cal, {{"j2", "j2: corrections folded in -- with sigma"}});
  // Everything else is kept: the head, the finger, the hand's mass.
  EXPECT_NE(text.find("head_joint"), std::string::npos);
  EXPECT_NE(text.find("finger_joint"), std::string::npos);
  EXPECT_NE(text.find("corrections folded in - - with sigma"), std::string::npos);
  const RobotModel back = ParseUrdf(text, "calibrated.urdf", {"world", "tool"});
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    const Eigen::VectorXd q = SomeJoints(7, seed);
    EXPECT_LT((back.T_base_tool(q).t - cal.T_base_tool(q).t).norm(), 1e-9);
    EXPECT_LT((back.T_base_tool(q).R - cal.T_base_tool(q).R).norm(), 1e-9);
  }
  EXPECT_NEAR(*back.Joints()[0].mass_kg, 7.2, 1e-12);
}

TEST(Urdf, DhRobotsWrittenAsUrdfHaveTheSameKinematicsAndWeight) {
  const RobotModel kr5 = RobotModel::Default();
  const RobotModel ur10 = RobotModel::Read(std::filesystem::path(MCMS_SOURCE_DIR) / "examples/robots/ur10_like.yaml");
  for (const RobotModel* dh : {&kr5, &ur10}) {
    SCOPED_TRACE(dh->Name());
    const RobotModel u = ParseUrdf(UrdfText(*dh), "converted.urdf");
    ASSERT_EQ(u.NumJoints(), dh->NumJoints());
    EXPECT_EQ(u.HasMasses(), dh->HasMasses());
    Rng rng(5);
    for (int k = 0; k < 20; ++k) {
      Eigen::VectorXd q(dh->NumJoints());
      for (int i = 0; i < q.size(); ++i) q[i] = rng.Uniform(std::max(-3.0, dh->Joints()[i].lower), std::min(3.0, dh->Joints()[i].upper));
      EXPECT_LT((u.T_base_tool(q).t - dh->T_base_tool(q).t).norm(), 1e-12);
      EXPECT_LT((u.T_base_tool(q).R - dh->T_base_tool(q).R).norm(), 1e-12);
      EXPECT_LT((u.Jacobian(q) - dh->Jacobian(q)).cwiseAbs().maxCoeff(), 1e-12);
      if (dh->HasMasses()) {
        EXPECT_LT((GravityTorque(u, q, 2.0) - GravityTorque(*dh, q, 2.0)).cwiseAbs().maxCoeff(), 1e-9);
      }
    }
  }
}

TEST(Urdf, YamlHoldsAUrdfChainToo) {
  const RobotModel r = Seven();
  const RobotModel back = RobotModel::Parse(r.ToYaml(), "seven.yaml");
  EXPECT_EQ(back.Convention(), ChainConvention::kUrdf);
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    const Eigen::VectorXd q = SomeJoints(7, seed);
    EXPECT_LT((back.T_base_tool(q).t - r.T_base_tool(q).t).norm(), 1e-12);
  }
}

struct UrdfUnit {
  const RobotModel* robot;
  Extension e;
  MeasurementContext ctx;
  Eigen::VectorXd q;
  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    const T* blocks[1] = {p[0]};
    const PoseT<T> F = ExtendedFlangeT(*robot, {e}, blocks, q, ctx);
    for (int k = 0; k < 3; ++k) r[k] = F.t[k];
    for (int k = 0; k < 9; ++k) r[3 + k] = F.R(k % 3, k / 3);
    return true;
  }
};


TEST(Urdf, EveryExtensionMatchesNumericDerivativesOnAUrdfChain) {
  const RobotModel robot = Seven();
  const Eigen::VectorXd q = SomeJoints(7, 2);
  MeasurementContext c;
  c.time_s = 900.0;
  c.temperature_c = 31.0;
  c.move_direction = Eigen::VectorXd::Ones(7);
  c.gravity_torque = GravityTorque(robot, q, 0.5);
  c.gravity_lever = GravityLever(robot, q);
  for (const Extension& e : std::vector<Extension>{{Effect::kGeometry, -1, robot.NumGeometryParameters()},
                                                   {Effect::kJointOffset, 0, 0},
                                                   {Effect::kGravityCompliance, 3, 0},
                                                   {Effect::kThermalDrift, -1, 1},
                                                   {Effect::kErrorMotion, 4, 1}}) {
    SCOPED_TRACE(e.Label());
    e.Check(&robot);
    std::vector<double> x = e.InitialParameters();
    for (size_t k = 0; k < x.size(); ++k) x[k] += 1e-3 * (1.0 + 0.37 * k);
    test::ExpectGradientsMatch(UrdfUnit{&robot, e, c, q}, e.NumParameters(), 12, x);
  }
  // DH terms are refused on a URDF chain, by name.
  EXPECT_NE(ErrorOf([&] { Extension{Effect::kLinkTwist, 2, 0}.Check(&robot); }).find("placement"), std::string::npos);
}

std::string Edit(std::string text, const std::string& from, const std::string& to) {
  const size_t p = text.find(from);
  EXPECT_NE(p, std::string::npos) << from;
  if (p != std::string::npos) text.replace(p, from.size(), to);
  return text;
}

TEST(Urdf, BadInputIsNamed) {
  const std::string good = SevenJointUrdf();
  const auto Error = [](const std::string& xml, const ChainSelection& sel) {
    return ErrorOf([&] { ParseUrdf(xml, "r.urdf", sel); });
  };
  // urdfdom's own reason is kept.
  std::string e = Error(Edit(good, "<link name=\"l3\">", "<link>"), {"world", "tool"});
  EXPECT_NE(e.find("r.urdf: not a URDF that urdfdom can read"), std::string::npos) << e;
  EXPECT_GT(e.size(), std::string("r.urdf: not a URDF that urdfdom can read: ").size() + 5) << e;
  e = Error("<robot name=\"x\"><link name=\"a\"/>", {});
  EXPECT_NE(e.find("urdfdom"), std::string::npos) << e;
  // Unknown links: the links listed.
  e = Error(good, {"world", "gripper"});
  EXPECT_NE(e.find("--tip-link 'gripper' is not a link"), std::string::npos) << e;
  EXPECT_NE(e.find("finger"), std::string::npos) << e;
  e = Error(good, {"base", "tool"});
  EXPECT_NE(e.find("--base-link 'base'"), std::string::npos) << e;
  // No chain between them (the head is not above the tool).
  e = Error(good, {"head", "tool"});
  EXPECT_NE(e.find("no chain from base link 'head' to tip link 'tool'"), std::string::npos) << e;
  EXPECT_NE(e.find("shoulder_mount"), std::string::npos) << e;
  // Ambiguous tip: two leaves as far from the base.
  e = Error(Edit(good, "</robot>",
                 "<joint name=\"finger2_joint\" type=\"revolute\"><parent link=\"hand\"/><child link=\"finger2\"/>"
                 "<axis xyz=\"0 1 0\"/><limit lower=\"0\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>"
                 "<link name=\"finger2\"/></robot>"),
            {});
  EXPECT_NE(e.find("the tip of the chain is ambiguous"), std::string::npos) << e;
  EXPECT_NE(e.find("finger (8), finger2 (8), head (2)"), std::string::npos) << e;
  // A mimic joint whose driver is missing or fixed; a floating joint inside the chain.
  e = Error(Edit(good, "<joint name=\"j4\" type=\"revolute\">",
                 "<joint name=\"j4\" type=\"revolute\"><mimic joint=\"nowhere\" multiplier=\"1\"/>"),
            {"world", "tool"});
  EXPECT_NE(e.find("joint 'j4' mimics joint 'nowhere', which is not in the URDF"), std::string::npos) << e;
  e = Error(Edit(good, "<joint name=\"j5\" type=\"revolute\">", "<joint name=\"j5\" type=\"floating\">"),
            {"world", "tool"});
  EXPECT_NE(e.find("joint 'j5'"), std::string::npos) << e;
  EXPECT_NE(e.find("floating"), std::string::npos) << e;
  e = Error(Edit(good, "<joint name=\"j5\" type=\"revolute\">", "<joint name=\"j5\" type=\"planar\">"),
            {"world", "tool"});
  EXPECT_NE(e.find("planar"), std::string::npos) << e;
  // A negative or non-finite mass (0 is a massless link, as ROS's virtual frames are).
  e = Error(Edit(good, "<mass value=\"1.5\"/>", "<mass value=\"-1.5\"/>"), {"world", "tool"});
  EXPECT_NE(e.find("link 'l3'"), std::string::npos) << e;
  EXPECT_NE(e.find("mass"), std::string::npos) << e;
  e = Error(Edit(good, "<mass value=\"1.5\"/>", "<mass value=\"inf\"/>"), {"world", "tool"});
  EXPECT_NE(e.find("link 'l3'"), std::string::npos) << e;
  EXPECT_EQ(Error(Edit(good, "<mass value=\"1.5\"/>", "<mass value=\"0\"/>"), {"world", "tool"}), "(no InputError)");
  // A xacro file: named, with the command that expands it.
  e = Error(Edit(good, "<robot name=", "<robot xmlns:xacro=\"http://www.ros.org/wiki/xacro\" name="), {});
  EXPECT_NE(e.find("a xacro file"), std::string::npos) << e;
  EXPECT_NE(e.find("xacro r.urdf > robot.urdf"), std::string::npos) << e;
  // A zero axis.
  e = Error(Edit(good, "<axis xyz=\"0 1 0\"/>\n    <limit lower=\"-2.5\"", "<axis xyz=\"0 0 0\"/>\n    <limit lower=\"-2.5\""),
            {"world", "tool"});
  EXPECT_NE(e.find("j3"), std::string::npos) << e;
  EXPECT_NE(e.find("axis"), std::string::npos) << e;
  // --base-link/--tip-link on a YAML robot.
  e = ErrorOf([] {
    RobotModel::Read(std::filesystem::path(MCMS_SOURCE_DIR) / "examples/robots/ur10_like.yaml", {"", "tool"});
  });
  EXPECT_NE(e.find("--base-link and --tip-link pick a chain of a URDF"), std::string::npos) << e;
}

TEST(Urdf, RealTiagoUrdfLoads) {
  MCMS_REQUIRE_DATA(dir, "tiago-mocap");
  const auto path = dir / "tiago_48_hey5.urdf";
  ASSERT_TRUE(IsUrdfFile(path));
  // The tip is not unique in a robot with a head and a five-finger hand: the candidates listed.
  const std::string e = ErrorOf([&] { RobotModel::Read(path); });
  EXPECT_NE(e.find("the tip of the chain is ambiguous"), std::string::npos) << e;
  EXPECT_NE(e.find("--tip-link"), std::string::npos) << e;
  const auto t0 = std::chrono::steady_clock::now();
  const RobotModel r = RobotModel::Read(path, {"", "wrist_ft_tool_link"});
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  RecordProperty("load_ms", std::to_string(ms));
  ASSERT_EQ(r.NumJoints(), 8);
  EXPECT_EQ(r.Joints()[0].name, "torso_lift_joint");
  EXPECT_EQ(r.Joints()[0].type, JointType::kPrismatic);
  EXPECT_EQ(r.Joints()[7].name, "arm_7_joint");
  EXPECT_EQ(r.Urdf()->base_link, "base_footprint");
  ASSERT_TRUE(r.HasMasses());
  // The hand and its fingers hang beyond wrist_ft_tool_link: arm_7's link carries them.
  EXPECT_GT(r.Joints()[7].mass_kg.value_or(0.0), 0.5);
  double total = 0;
  for (const Joint& j : r.Joints()) total += j.mass_kg.value_or(0.0);
  EXPECT_GT(total, 15.0);  // torso, head and arm
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// A telescopic column as ROS describes one (issue 51): the motor's joint drives two segments
// that mimic it (multiplier 0.5 each), on a branch of its own; an arm on the top segment.
std::string ColumnUrdf() {
  return R"(<robot name="column">
  <link name="base"/>
  <joint name="motor" type="prismatic"><parent link="base"/><child link="motor_link"/>
    <axis xyz="0 0 1"/><limit lower="1.0" upper="3.0" effort="1" velocity="1"/></joint>
  <link name="motor_link"/>
  <joint name="mid" type="prismatic"><parent link="base"/><child link="mid_link"/><origin xyz="0.1 0 0.2"/>
    <axis xyz="0 0 1"/><limit lower="0.0" upper="1.0" effort="1" velocity="1"/>
    <mimic joint="motor" multiplier="0.5" offset="-0.5"/></joint>
  <link name="mid_link"><inertial><mass value="10"/><origin xyz="0 0 -0.5"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="top" type="prismatic"><parent link="mid_link"/><child link="top_link"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 0 1"/><limit lower="0.0" upper="1.0" effort="1" velocity="1"/>
    <mimic joint="motor" multiplier="0.5" offset="-0.5"/></joint>
  <link name="top_link"><inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="top_link"/><child link="arm"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="arm"><inertial><mass value="2"/><origin xyz="0.2 0 0"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="elbow" type="revolute"><parent link="arm"/><child link="forearm"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <link name="forearm"/>
  <joint name="to_tool" type="fixed"><parent link="forearm"/><child link="tool0"/><origin xyz="0.3 0 0"/></joint>
  <link name="tool0"/>
  <joint name="to_sensor" type="fixed"><parent link="forearm"/><child link="sensor"/><origin xyz="0.1 0.05 0"/></joint>
  <link name="sensor"/>
</robot>)";
}

TEST(Urdf, MimicJointsFollowTheirDriver) {
  const RobotModel r = ParseUrdf(ColumnUrdf(), "column.urdf");
  // The tip: leaves after the same last joint (elbow) are one chain; the tool-like one.
  EXPECT_EQ(r.Urdf()->tip_link, "tool0");
  EXPECT_NE(r.Urdf()->tip_note.find("tip link 'tool0' taken as the tool"), std::string::npos) << r.Urdf()->tip_note;
  ASSERT_EQ(r.NumJoints(), 4);
  ASSERT_EQ(r.NumActuated(), 3);
  EXPECT_TRUE(r.HasMimicJoints());
  EXPECT_EQ(r.ActuatedJoints()[0].name, "motor");
  EXPECT_NEAR(r.ActuatedJoints()[0].lower, 1.0, 1e-12);  // from the segments' limits
  EXPECT_NEAR(r.ActuatedJoints()[0].upper, 3.0, 1e-12);
  EXPECT_EQ(r.ActuatedJoints()[1].name, "shoulder");
  const Eigen::Vector3d qa(2.2, 0.4, -0.7);
  const Eigen::VectorXd q = r.ChainValues(qa);
  ASSERT_EQ(q.size(), 4);
  EXPECT_NEAR(q[0], 0.6, 1e-15);
  EXPECT_NEAR(q[1], 0.6, 1e-15);
  EXPECT_NEAR((r.ActuatedValues(q) - qa).norm(), 0.0, 1e-15);
  // The forward kinematics by hand: the two segments each rise by 0.5 q - 0.5.
  const double h = 0.2 + 0.05 + 0.3 + 2 * (0.5 * 2.2 - 0.5);
  const Eigen::Vector3d arm = Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) *
                              (Eigen::Vector3d(0.4, 0, 0) + Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitY()) *
                                                                Eigen::Vector3d(0.3, 0, 0));
  EXPECT_NEAR((r.T_base_tool(q).t - (Eigen::Vector3d(0.1, 0, h) + arm)).norm(), 0.0, 1e-12);
  // Each segment keeps placement errors of its own; YAML keeps the mimic.
  EXPECT_EQ(r.NumGeometryParameters(), 4 * kUrdfParamsPerJoint);
  const RobotModel y = RobotModel::Parse(r.ToYaml(), "column.yaml");
  EXPECT_EQ(y.NumActuated(), 3);
  EXPECT_NEAR((y.T_base_tool(y.ChainValues(qa)).t - r.T_base_tool(q).t).norm(), 0.0, 1e-12);
  // A massless top segment (mass 0, as ROS's virtual links) adds nothing.
  EXPECT_TRUE(r.HasMasses());
}

TEST(Urdf, DeepChainsAreRefusedByNameNotByTheStack) {
  // 60,000 fixed links in one chain (issue 53: the recursive walks overflowed the stack).
  std::string xml = "<robot name=\"deep\"><link name=\"l0\"/>";
  xml += "<joint name=\"j\" type=\"revolute\"><parent link=\"l0\"/><child link=\"l1\"/><axis xyz=\"0 0 1\"/>"
         "<limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>";
  for (int i = 1; i < 60000; ++i)
    xml += "<link name=\"l" + std::to_string(i) + "\"/><joint name=\"f" + std::to_string(i) +
           "\" type=\"fixed\"><parent link=\"l" + std::to_string(i) + "\"/><child link=\"l" +
           std::to_string(i + 1) + "\"/></joint>";
  xml += "<link name=\"l60000\"/></robot>";
  const std::string e = ErrorOf([&] { ParseUrdf(xml, "deep.urdf"); });
  EXPECT_NE(e.find("deep.urdf: 60001 <link> elements; a robot has at most 10000"), std::string::npos) << e;
  // Under the bound, a long fixed tail and a tip given walk without recursion.
  std::string ok = "<robot name=\"long\"><link name=\"l0\"/>";
  ok += "<joint name=\"j\" type=\"revolute\"><parent link=\"l0\"/><child link=\"l1\"/><axis xyz=\"0 0 1\"/>"
        "<limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>";
  for (int i = 1; i < 9000; ++i)
    ok += "<link name=\"l" + std::to_string(i) + "\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" "
          "ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link><joint name=\"f" + std::to_string(i) +
          "\" type=\"fixed\"><parent link=\"l" + std::to_string(i) + "\"/><child link=\"l" + std::to_string(i + 1) +
          "\"/><origin xyz=\"0.0001 0 0\"/></joint>";
  ok += "<link name=\"l9000\"/></robot>";
  const RobotModel r = ParseUrdf(ok, "long.urdf", {"", "l9000"});
  EXPECT_EQ(r.NumJoints(), 1);
  EXPECT_NEAR(*r.Joints()[0].mass_kg, 8999.0, 1e-9);
  const RobotModel t = ParseUrdf(ok, "long.urdf");
  EXPECT_EQ(t.Urdf()->tip_link, "l9000");
}

TEST(Urdf, RealConstructionRobotAsPublished) {
  MCMS_REQUIRE_DATA(dir, "hilti-trailblazer");
  const RobotModel r = ReadUrdf(dir / "trailblazer.urdf", {"", "prism"});
  // The column's two segments mimic the motor's joint, which the logs record.
  ASSERT_EQ(r.NumJoints(), 8);
  ASSERT_EQ(r.NumActuated(), 7);
  EXPECT_EQ(r.ActuatedJoints()[0].name, "column_prismatic_joint");
  EXPECT_NEAR(r.ActuatedJoints()[0].lower, 1.48, 1e-9);
  EXPECT_NEAR(r.ActuatedJoints()[0].upper, 3.972, 1e-9);
  EXPECT_EQ(r.Joints()[0].mimics, "column_prismatic_joint");
  EXPECT_EQ(r.Joints()[2].name, "dsr_joint1");
  EXPECT_TRUE(r.HasMasses());
  // Without --tip-link: the prism and the drill tip hang from the same joint; the tool-like one.
  const RobotModel d = ReadUrdf(dir / "trailblazer.urdf");
  EXPECT_EQ(d.Urdf()->tip_link, "drill_tip");
  EXPECT_NE(d.Urdf()->tip_note.find("prism"), std::string::npos) << d.Urdf()->tip_note;
}

}  // namespace
}  // namespace mcms
