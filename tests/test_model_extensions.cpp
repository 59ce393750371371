// The model layer's templated units: each extension of the catalog against numeric
// derivatives (ceres::GradientChecker), what each one means (its effect on the pose),
// the templated forward kinematics against RobotModel, and inverse kinematics.
#include <gtest/gtest.h>


#include <functional>
#include <set>

#include "core/error.h"
#include "core/pose_math.h"
#include "model/extensions.h"
#include "model/flange_pose.h"
#include "model/inclinometer.h"
#include "model/inverse_kinematics.h"
#include "model/kinematics.h"
#include "model/robot_model.h"
#include "tests/gradient_check.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

const Eigen::VectorXd& TestJoints() {
  static const Eigen::VectorXd q = (Eigen::VectorXd(6) << 0.3, -1.2, 1.0, 0.4, 0.7, -0.5).finished();
  return q;
}

using test::ExpectGradientsMatch;

// Residuals: the flange position (m) and the 9 entries of its rotation matrix (smooth
// everywhere, unlike a rotation vector at the identity).
struct ExtendedFlangeUnit {
  const RobotModel* robot;
  std::vector<Extension> ext;
  MeasurementContext ctx;
  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    std::vector<const T*> blocks;
    const T* at = p[0];
    for (const Extension& e : ext) {
      blocks.push_back(at);
      at += e.NumParameters();
    }
    const PoseT<T> F = ExtendedFlangeT(*robot, ext, blocks.data(), TestJoints(), ctx);
    for (int k = 0; k < 3; ++k) r[k] = F.t[k];
    for (int k = 0; k < 9; ++k) r[3 + k] = F.R(k % 3, k / 3);
    return true;
  }
};

MeasurementContext TestContext(const RobotModel& robot) {
  MeasurementContext c;
  c.time_s = 900.0;
  c.temperature_c = 31.0;
  c.move_direction = (Eigen::VectorXd(6) << 1, -1, 1, 1, -1, 1).finished();
  c.gravity_torque = 3.0 * GravityTorquePerKg(robot, TestJoints());
  c.gravity_lever = GravityLever(robot, TestJoints());
  return c;
}

std::vector<Extension> RobotExtensions() {
  return {{Effect::kJointOffset, 1, 0},       {Effect::kLinkLength, 2, 0},    {Effect::kLinkLength, 3, 1},
          {Effect::kJointScale, 0, 0},        {Effect::kGravityCompliance, 2, 0}, {Effect::kThermalDrift, -1, 0},
          {Effect::kThermalDrift, -1, 1},     {Effect::kBacklash, 4, 0},      {Effect::kErrorMotion, 1, 2}};
}

TEST(ModelExtensions, EveryRobotUnitMatchesNumericDerivatives) {
  const RobotModel robot = RobotModel::Default();
  std::vector<Extension> units = RobotExtensions();
  // The geometric units of the audit and lumped-mass compliance.
  units.push_back({Effect::kLinkTwist, 2, 0});
  units.push_back({Effect::kGeometry, -1, 24});
  units.push_back({Effect::kGravityCompliance, 1, 13});
  for (const Extension& e : units) {
    SCOPED_TRACE(e.Label());
    e.Check(&robot);
    std::vector<double> x = e.InitialParameters();
    for (size_t k = 0; k < x.size(); ++k) x[k] += 1e-3 * (1.0 + 0.37 * k);  // away from the nominal point
    ExpectGradientsMatch(ExtendedFlangeUnit{&robot, {e}, TestContext(robot)}, e.NumParameters(), 12, x);
  }
}

TEST(ModelExtensions, AllRobotUnitsTogetherMatchNumericDerivatives) {
  const RobotModel robot = RobotModel::Default();
  std::vector<Extension> all = RobotExtensions();
  all.pop_back();               // error motion has its own test above
  all.erase(all.begin() + 5);   // thermal drift once (in temperature)
  int n = 0;
  std::vector<double> x;
  for (const Extension& e : all) {
    n += e.NumParameters();
    for (double v : e.InitialParameters()) x.push_back(v + 2e-4 * (x.size() + 1));
  }
  ASSERT_LE(n, 8);
  ExpectGradientsMatch(ExtendedFlangeUnit{&robot, all, TestContext(robot)}, n, 12, x);
}

TEST(ModelExtensions, RobotUnitsMeanWhatTheirNamesSay) {
  const RobotModel robot = RobotModel::Default();
  const Eigen::VectorXd& q = TestJoints();
  const MeasurementContext c = TestContext(robot);
  const auto flange = [&](const Extension& e, const std::vector<double>& p) {
    const double* blocks[1] = {p.data()};
    const PoseT<double> F = ExtendedFlangeT(robot, {e}, blocks, q, c);
    return Pose{F.R, F.t};
  };
  // The nominal parameters reproduce the nominal model exactly.
  for (const Extension& e : RobotExtensions()) {
    const Pose F = flange(e, e.InitialParameters());
    EXPECT_LT(BoxMinus(F, robot.T_base_flange(q)).norm(), 1e-12) << e.Label();
  }
  // A joint offset is the same as turning the joint.
  Eigen::VectorXd q2 = q;
  q2[1] += 1e-3;
  EXPECT_LT(BoxMinus(flange({Effect::kJointOffset, 1, 0}, {1e-3}), robot.T_base_flange(q2)).norm(), 1e-12);
  // A scale error s turns the joint by s q.
  q2 = q;
  q2[0] *= 1.01;
  EXPECT_LT(BoxMinus(flange({Effect::kJointScale, 0, 0}, {0.01}), robot.T_base_flange(q2)).norm(), 1e-12);
  // Backlash b: the link lags the encoder by half of it (joint 5 moved downwards here, so
  // the link stands half the backlash above the encoder's reading).
  q2 = q;
  q2[4] += 0.5 * 2e-3;
  EXPECT_LT(BoxMinus(flange({Effect::kBacklash, 4, 0}, {2e-3}), robot.T_base_flange(q2)).norm(), 1e-12);
  // A link length change equals the DH table changed.
  std::vector<Joint> joints = robot.Joints();
  joints[3].d += 1e-3;
  const RobotModel longer("longer", robot.Convention(), joints, robot.T_flange_tool());
  EXPECT_LT(BoxMinus(flange({Effect::kLinkLength, 3, 1}, {1e-3}), longer.T_base_flange(q)).norm(), 1e-12);
  EXPECT_EQ(Extension({Effect::kLinkLength, 3, 1}).Where(), "d4");
  // A link twist is alpha changed; the geometry block is every DH parameter.
  joints = robot.Joints();
  joints[2].alpha += 1e-3;
  const RobotModel twisted("twisted", robot.Convention(), joints, robot.T_flange_tool());
  EXPECT_LT(BoxMinus(flange({Effect::kLinkTwist, 2, 0}, {1e-3}), twisted.T_base_flange(q)).norm(), 1e-12);
  EXPECT_EQ(Extension({Effect::kLinkTwist, 2, 0}).Where(), "alpha3");
  Eigen::VectorXd dh(24);
  for (int k = 0; k < 24; ++k) dh[k] = 1e-4 * std::sin(1.0 + k);
  const std::vector<double> dhv(dh.data(), dh.data() + 24);
  joints = robot.Joints();
  for (int k = 0; k < 6; ++k) {
    joints[k].theta_offset += dh[4 * k];
    joints[k].d += dh[4 * k + 1];
    joints[k].a += dh[4 * k + 2];
    joints[k].alpha += dh[4 * k + 3];
  }
  EXPECT_LT(BoxMinus(flange({Effect::kGeometry, -1, 24}, dhv), robot.WithJoints(joints).T_base_flange(q)).norm(), 1e-12);
  // Thermal growth scales every length: the flange moves outwards, rotation unchanged.
  const Pose warm = flange({Effect::kThermalDrift, -1, 1}, {1e-4});  // 11 K above 20 C
  const Pose nominal = robot.T_base_flange(q);
  EXPECT_NEAR(warm.t.norm() / nominal.t.norm(), 1.0 + 11e-4, 2e-4);
  EXPECT_LT(RotationAngle(warm.R, nominal.R), 1e-12);
  // Compliance: a joint whose gravity torque is zero does not deflect.
  EXPECT_NEAR(GravityTorquePerKg(robot, q)[0], 0.0, 1e-12);  // joint 1's axis is vertical
  EXPECT_GT(std::abs(GravityTorquePerKg(robot, q)[1]), 1.0);
}

// The arm's own weight: the torque of the links' masses (at their centres of mass), the
// tool's and a payload equals the derivative of their potential energy; lumped masses at
// the frames' origins and the DH corners are the lever columns times the masses.
TEST(ModelExtensions, ArmGravityTorqueMatchesVirtualWork) {
  std::vector<Joint> j = RobotModel::Default().Joints();
  const double m[6] = {25.0, 18.0, 12.0, 4.0, 2.0, 0.5};
  const Vec3 c[6] = {{-0.09, 0.1, 0.0}, {-0.3, 0.0, 0.05}, {-0.05, 0.0, 0.2}, {0.0, -0.1, 0.0}, {0.0, 0.0, 0.02}, {0.0, 0.0, -0.02}};
  for (int k = 0; k < 6; ++k) {
    j[k].mass_kg = m[k];
    j[k].com_m = c[k];
  }
  RobotModel robot = RobotModel::Default().WithJoints(j);
  robot.SetT_flange_tool(Pose{Mat3::Identity(), Vec3(0.01, 0.02, 0.15)});
  robot.SetToolMass({1.5, Vec3(0.0, 0.03, 0.05)});
  ASSERT_TRUE(robot.HasMasses());
  const double payload = 4.0;
  const auto Energy = [&](const Eigen::VectorXd& q) {
    const std::vector<Pose> F = robot.LinkFrames(q);
    double z = 0;
    for (int k = 0; k < 6; ++k) z += m[k] * (F[k + 1] * c[k]).z();
    z += 1.5 * (F[6] * Vec3(0.0, 0.03, 0.05)).z() + payload * (F[6] * robot.T_flange_tool()).t.z();
    return 9.80665 * z;
  };
  const Eigen::VectorXd tau = GravityTorque(robot, TestJoints(), payload);
  for (int i = 0; i < 6; ++i) {
    Eigen::VectorXd a = TestJoints(), b = TestJoints();
    a[i] += 1e-6;
    b[i] -= 1e-6;
    EXPECT_NEAR(tau[i], -(Energy(a) - Energy(b)) / 2e-6, 1e-4) << "joint " << i + 1;
  }
  // Lumped: masses at the origins (centres of mass zero) are the lever columns times them.
  for (int k = 0; k < 6; ++k) j[k].com_m = Vec3::Zero();
  const RobotModel lumped = RobotModel::Default().WithJoints(j);
  const Eigen::MatrixXd L = GravityLever(lumped, TestJoints());
  ASSERT_EQ(L.cols(), 13);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(13);
  for (int k = 0; k < 6; ++k) w[k] = m[k];
  w[12] = payload;
  EXPECT_LT((L * w - GravityTorque(lumped, TestJoints(), payload)).norm(), 1e-9);
  // Link 4's DH corner (o3 + d4 z3 = o4 for the KR 5 arc, whose a4 = 0) is its origin.
  EXPECT_LT((L.col(6 + 3) - L.col(3)).norm(), 1e-9);
  // A robot without masses has no arm torque to give.
  EXPECT_THROW(GravityTorque(RobotModel::Default(), TestJoints(), 1.0), InputError);
}

TEST(ModelExtensions, GravityTorqueMatchesVirtualWork) {
  // tau_i = dU/dq_i with U the potential energy of 1 kg at the flange: m g z(q).
  const RobotModel robot = RobotModel::Default();
  const Eigen::VectorXd tau = GravityTorquePerKg(robot, TestJoints());
  for (int i = 0; i < 6; ++i) {
    Eigen::VectorXd a = TestJoints(), b = TestJoints();
    a[i] += 1e-6;
    b[i] -= 1e-6;
    const double dz = (robot.T_base_flange(a).t.z() - robot.T_base_flange(b).t.z()) / 2e-6;
    EXPECT_NEAR(tau[i], -9.80665 * dz, 1e-5) << "joint " << i + 1;
  }
}

// Functors of the camera, inclinometer and clock units (residuals: what the unit returns).
struct Moved {
  Pose pose;
  Vec3 p;
  template <typename T>
  bool operator()(T const* const* x, T* r) const {
    const PoseT<T> C = MovedCameraT<T>(pose, x[0]);
    const Eigen::Matrix<T, 3, 1> y = C.R * p.cast<T>() + C.t;
    for (int k = 0; k < 3; ++k) r[k] = y[k];
    return true;
  }
};

struct Shifted {
  Pose pose;
  Vec6 twist;
  template <typename T>
  bool operator()(T const* const* x, T* r) const {
    const PoseT<T> C = TimeShiftedPoseT<T>(pose, twist, Vec6(0.3 * twist), x[0]);
    for (int k = 0; k < 3; ++k) r[k] = C.t[k] + C.R(k, 0);
    return true;
  }
};

struct Intrinsics {
  Extension e;
  template <typename T>
  bool operator()(T const* const* x, T* r) const {
    T in[6] = {T(1100), T(1090), T(640), T(480), T(-0.1), T(0.02)};
    ExtendIntrinsicsT(e, x[0], in, 6);
    for (int k = 0; k < 6; ++k) r[k] = in[k];
    return true;
  }
};

struct Ball {
  template <typename T>
  bool operator()(T const* const* x, T* r) const {
    const auto b = MovedBallT<T>(Vec3(0.1, 0.0, 0.05), x[0]);
    r[0] = b.squaredNorm();
    r[1] = b[2] * PixelVarianceScaleT<T>(x[0]);
    return true;
  }
};

struct Reading {
  Mat3 R, M;
  template <typename T>
  bool operator()(T const* const* x, T* r) const {
    const auto t = InclinometerReadingT<T>(R, M, x[0], x[0] + 3);
    r[0] = t[0];
    r[1] = t[1];
    return true;
  }
};

struct Clock {
  Extension e;
  template <typename T>
  bool operator()(T const* const* x, T* r) const {
    r[0] = ReferenceTimeT(e, x[0], 125.0, 5.0);
    return true;
  }
};

TEST(ModelExtensions, CameraUnitsMatchNumericDerivatives) {
  const Pose T_rig_cam{ExpSO3(Vec3(0.1, -0.2, 0.3)), Vec3(0.4, 0.1, -0.2)};
  const Vec6 twist = (Vec6() << 0.2, -0.1, 0.3, 0.05, 0.02, -0.04).finished();
  const Vec3 p_rig(0.1, 0.2, 1.5);
  ExpectGradientsMatch(Moved{T_rig_cam, p_rig}, 6, 3, {1e-3, -2e-3, 3e-3, 1e-3, 2e-3, -1e-3});
  ExpectGradientsMatch(Shifted{T_rig_cam, twist}, 1, 3, {0.03});
  ExpectGradientsMatch(Intrinsics{{Effect::kFocalLength, 0, 0}}, 1, 6, {0.01});
  ExpectGradientsMatch(Intrinsics{{Effect::kPrincipalPoint, 0, 0}}, 2, 6, {3.0, -2.0});
  ExpectGradientsMatch(Intrinsics{{Effect::kRadialDistortion, 0, 0}}, 1, 6, {0.01});
  ExpectGradientsMatch(Ball{}, 3, 2, {1e-3, 2e-3, 0.9});
}

TEST(ModelExtensions, InclinometerUnitAgreesWithTheInclinometerModel) {
  Inclinometer incl;
  incl.R_flange_incl = ExpSO3(Vec3(0.02, -0.01, 0.3));
  const Mat3 R_base_flange = ExpSO3(Vec3(0.2, -0.3, 1.1));
  const Vec2 model = incl.Tilt(R_base_flange);
  const Vec2 unit = InclinometerReadingT<double>(R_base_flange, incl.R_flange_incl, nullptr, nullptr);
  EXPECT_LT((model - unit).norm(), 1e-14);
  const double bias[2] = {1e-3, -2e-3};
  EXPECT_LT((InclinometerReadingT<double>(R_base_flange, incl.R_flange_incl, nullptr, bias) - model -
             Vec2(1e-3, -2e-3)).norm(), 1e-15);
  ExpectGradientsMatch(Reading{R_base_flange, incl.R_flange_incl}, 5, 2, {1e-3, -2e-3, 5e-3, 1e-4, -1e-4});
}

TEST(ModelExtensions, ClockUnitsMatchNumericDerivatives) {
  ExpectGradientsMatch(Clock{{Effect::kClockOffset, 0, 0}}, 1, 1, {0.02});
  ExpectGradientsMatch(Clock{{Effect::kClockDrift, 0, 0}}, 2, 1, {0.02, 1e-5});
  const double p[2] = {0.02, 1e-4};
  EXPECT_DOUBLE_EQ(ReferenceTimeT<double>({Effect::kClockDrift, 0, 0}, p, 105.0, 5.0), 105.0 + 0.02 + 0.01);
}

TEST(ModelExtensions, CatalogNamesAreUniqueAndRoundTrip) {
  std::set<std::string> names;
  for (const EffectInfo& i : EffectCatalog()) {
    EXPECT_TRUE(names.insert(i.name).second) << i.name;
    EXPECT_EQ(EffectFromName(i.name), i.effect);
    Extension e{i.effect, 0, i.effect == Effect::kErrorMotion ? 1 : 0};
    EXPECT_EQ(static_cast<int>(e.ParameterNames().size()), e.NumParameters()) << i.name;
    EXPECT_EQ(static_cast<int>(e.InitialParameters().size()), e.NumParameters()) << i.name;
  }
  for (const char* required :
       {"camera_moved", "focal_length", "principal_point", "radial_distortion", "camera_time_offset",
        "pixel_noise_scale", "target_geometry", "joint_offset", "link_length", "gravity_compliance", "thermal_drift",
        "backlash", "joint_scale", "error_motion", "inclinometer_bias", "inclinometer_misalignment", "clock_offset",
        "clock_drift"})
    EXPECT_TRUE(names.count(required)) << required;
  EXPECT_FALSE(EffectFromName("camera_bumped"));
  const RobotModel robot = RobotModel::Default();
  EXPECT_THROW(Extension({Effect::kJointOffset, 6, 0}).Check(&robot), InputError);
  EXPECT_THROW(Extension({Effect::kLinkLength, 0, 2}).Check(&robot), InputError);
  EXPECT_THROW(Extension({Effect::kCameraMoved, 4, 0}).Check(nullptr, 4), InputError);
  EXPECT_EQ(Extension({Effect::kCameraMoved, 1, 0}).Label({"cam0", "cam1"}), "camera_moved at cam1");
}

TEST(ModelKinematics, TemplatedChainEqualsTheRobotModel) {
  for (ChainConvention conv : {ChainConvention::kStandard, ChainConvention::kModified}) {
    RobotModel robot = RobotModel::Default();
    std::vector<Joint> joints = robot.Joints();
    joints[2].error_motion_sin = {(Vec6() << 1e-4, -2e-4, 3e-5, 1e-5, 2e-5, -3e-5).finished()};
    joints[2].error_motion_cos = {(Vec6() << -1e-4, 1e-4, 2e-5, -1e-5, 1e-5, 3e-5).finished()};
    robot = RobotModel("em", conv, joints);
    const std::vector<Pose> frames = robot.LinkFrames(TestJoints());
    const PoseT<double> F = ForwardKinematicsT<double>(robot, TestJoints(), {});
    EXPECT_LT(BoxMinus(Pose{F.R, F.t}, frames.back()).norm(), 1e-12);
    // Corrections through the DH table equal the same change made to the table.
    std::vector<double> dh(24, 0.0);
    dh[4 * 1 + 2] = 2e-3;  // a2
    dh[4 * 4 + 3] = 1e-3;  // alpha5
    ChainCorrections<double> c;
    c.geometry = dh.data();
    std::vector<Joint> changed = joints;
    changed[1].a += 2e-3;
    changed[4].alpha += 1e-3;
    const PoseT<double> G = ForwardKinematicsT<double>(robot, TestJoints(), c);
    EXPECT_LT(BoxMinus(Pose{G.R, G.t}, RobotModel("c", conv, changed).T_base_flange(TestJoints())).norm(), 1e-12);
  }
}

TEST(ModelInverseKinematics, SolvesReachablePosesAndExplainsUnreachableOnes) {
  const RobotModel robot = RobotModel::Default();
  const Pose goal = robot.T_base_flange(TestJoints());
  Eigen::VectorXd seed = TestJoints();
  seed.array() += 0.1;
  std::string why;
  const auto q = SolveIk(robot, goal, seed, &why);
  ASSERT_TRUE(q) << why;
  EXPECT_LT(BoxMinus(goal, robot.T_base_flange(*q)).norm(), 1e-9);
  const Pose far{goal.R, Vec3(5.0, 0.0, 0.5)};  // 5 m away: beyond a 1.4 m reach
  EXPECT_FALSE(SolveIk(robot, far, seed, &why));
  EXPECT_NE(why.find("mm"), std::string::npos) << why;
  EXPECT_FALSE(SolveIk(robot, goal, Eigen::VectorXd::Zero(3), &why));
  EXPECT_NE(why.find("seed"), std::string::npos) << why;
  // Options that no solve can use are named (the Python binding passes them through).
  IkOptions o;
  o.tolerance = 0.0;
  EXPECT_NE(test::ErrorOf([&] { SolveIk(robot, goal, seed, &why, o); }).find("tolerance must be positive"),
            std::string::npos);
  o = IkOptions{};
  o.max_iterations = 0;
  EXPECT_NE(test::ErrorOf([&] { SolveIk(robot, goal, seed, &why, o); }).find("max_iterations must be 1 to"),
            std::string::npos);
}

TEST(ModelFlangePose, CameraAndRobotConversionsPropagateCovariance) {
  CellGeometry cell;
  cell.T_base_rig = Pose{ExpSO3(Vec3(0.1, 0.2, -0.3)), Vec3(1.0, 0.5, 1.2)};
  cell.T_flange_target = Pose{ExpSO3(Vec3(0.0, 0.1, 0.0)), Vec3(0.0, 0.0, 0.05)};
  const Pose T_rig_target{ExpSO3(Vec3(0.3, 0.0, 0.1)), Vec3(0.1, -0.1, 1.5)};
  Mat6 C = Mat6::Identity() * 1e-8;
  C(0, 4) = C(4, 0) = 2e-9;
  const PoseWithCovariance f = CameraFlangePose(cell, T_rig_target, C);
  EXPECT_LT(BoxMinus(f.T, cell.T_base_rig * T_rig_target * cell.T_flange_target.Inverse()).norm(), 1e-14);
  // Numeric Jacobian of the conversion with respect to the rig measurement.
  Mat6 J;
  for (int k = 0; k < 6; ++k) {
    Vec6 d = Vec6::Zero();
    d[k] = 1e-7;
    const Pose a = cell.T_base_rig * BoxPlus(T_rig_target, d) * cell.T_flange_target.Inverse();
    const Pose b = cell.T_base_rig * BoxPlus(T_rig_target, -d) * cell.T_flange_target.Inverse();
    J.col(k) = (BoxMinus(a, f.T) - BoxMinus(b, f.T)) / 2e-7;
  }
  EXPECT_LT((J * C * J.transpose() - f.covariance).norm(), 1e-14);
  const RobotModel robot = RobotModel::Default();
  const Eigen::MatrixXd Q = Eigen::MatrixXd::Identity(6, 6) * 1e-8;
  const PoseWithCovariance r = RobotFlangePose(robot, TestJoints(), Q, Mat6::Identity() * 1e-10);
  const auto Jr = robot.Jacobian(TestJoints(), RobotModel::EndFrame::kFlange);
  EXPECT_LT((r.covariance - Jr * Q * Jr.transpose() - Mat6::Identity() * 1e-10).norm(), 1e-18);
}

}  // namespace
}  // namespace mcms
