// Robot model: KR 5 arc forward kinematics at the zero pose, the geometric Jacobian against
// central differences of FK in the [dtheta; dp] layout, standard vs modified DH on an
// equivalent robot, J Q J^T against Monte Carlo, YAML round trips and bad files.
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "model/robot_model.h"
#include "core/error.h"
#include "core/random.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

Eigen::VectorXd Vec(std::initializer_list<double> v) {
  Eigen::VectorXd q(v.size());
  int i = 0;
  for (double x : v) q[i++] = x;
  return q;
}

// Random joint values well inside the limits (10 % margin of each range, capped at +-pi).
Eigen::VectorXd RandomInside(const RobotModel& robot, Rng& rng) {
  Eigen::VectorXd q(robot.NumJoints());
  for (int i = 0; i < robot.NumJoints(); ++i) {
    const Joint& j = robot.Joints()[i];
    const double lo = std::max(j.lower, -kPi), hi = std::min(j.upper, kPi);
    const double m = 0.1 * (hi - lo);
    q[i] = rng.Uniform(lo + m, hi - m);
  }
  return q;
}

using test::ErrorOf;

TEST(RobotModel, Kr5ArcAtZeroPose) {
  const RobotModel robot = RobotModel::Default();
  EXPECT_EQ(robot.NumJoints(), 6);
  EXPECT_EQ(robot.Convention(), ChainConvention::kStandard);
  const Pose T = robot.T_base_flange(Eigen::VectorXd::Zero(6));
  // Hand-derived from the table: shoulder at (0.18, 0, 0.4), upper arm 0.6 up, elbow offset
  // 0.12 up, forearm 0.62 forward, flange 0.115 further; flange z along base x.
  EXPECT_NEAR((T.t - Vec3(0.915, 0.0, 1.120)).norm(), 0.0, 1e-12);
  Mat3 R;
  R << 0, 0, 1, 0, -1, 0, 1, 0, 0;
  EXPECT_NEAR((T.R - R).norm(), 0.0, 1e-12);
  const auto frames = robot.LinkFrames(Eigen::VectorXd::Zero(6));
  ASSERT_EQ(frames.size(), 7u);
  EXPECT_NEAR(frames[0].t.norm() + (frames[0].R - Mat3::Identity()).norm(), 0.0, 0.0);
  EXPECT_NEAR((frames[1].t - Vec3(0.18, 0, 0.4)).norm(), 0.0, 1e-12);   // shoulder (A2 axis)
  EXPECT_NEAR((frames[2].t - Vec3(0.18, 0, 1.0)).norm(), 0.0, 1e-12);   // elbow (A3 axis)
  EXPECT_NEAR((frames[4].t - Vec3(0.80, 0, 1.12)).norm(), 0.0, 1e-12);  // wrist centre
  EXPECT_NEAR((frames[6].t - T.t).norm(), 0.0, 0.0);
}

void ExpectJacobianMatchesFk(const RobotModel& robot, const Eigen::VectorXd& q, RobotModel::EndFrame end) {
  const auto fk = [&](const Eigen::VectorXd& x) {
    return end == RobotModel::EndFrame::kTool ? robot.T_base_tool(x) : robot.T_base_flange(x);
  };
  const Pose T0 = fk(q);
  const Eigen::MatrixXd Jn = test::NumericJacobian(
      [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return BoxMinus(fk(x), T0); }, q, 1e-6);
  const Eigen::MatrixXd J = robot.Jacobian(q, end);
  EXPECT_LT((J - Jn).cwiseAbs().maxCoeff(), 1e-8) << "analytic\n" << J << "\nnumeric\n" << Jn;
}

TEST(RobotModel, JacobianMatchesCentralDifferencesOfFk) {
  RobotModel robot = RobotModel::Default();
  robot.SetT_flange_tool({ExpSO3(Vec3(0.2, -0.1, 0.3)), Vec3(0.01, -0.02, 0.15)});
  Rng rng(7);
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q = RandomInside(robot, rng);
    ExpectJacobianMatchesFk(robot, q, RobotModel::EndFrame::kTool);
    ExpectJacobianMatchesFk(robot, q, RobotModel::EndFrame::kFlange);
  }
}

// A SCARA-like arm with a prismatic joint, in both conventions.
std::vector<Joint> ScaraJoints() {
  std::vector<Joint> j(4);
  j[0] = {"J1", JointType::kRevolute, 0.35, 0.0, 0.4, 0.1, -2.5, 2.5, 1e-5};
  j[1] = {"J2", JointType::kRevolute, 0.30, kPi, 0.0, 0.0, -2.5, 2.5, 1e-5};
  j[2] = {"J3", JointType::kPrismatic, 0.0, 0.0, 0.05, 0.0, 0.0, 0.2, 1e-6};
  j[3] = {"J4", JointType::kRevolute, 0.0, 0.0, 0.02, 0.3, -3.0, 3.0, 1e-5};
  return j;
}

TEST(RobotModel, PrismaticJointJacobian) {
  for (ChainConvention c : {ChainConvention::kStandard, ChainConvention::kModified}) {
    const RobotModel robot("scara", c, ScaraJoints(), Pose{ExpSO3(Vec3(0.1, 0.2, 0)), Vec3(0, 0, 0.1)});
    Rng rng(3);
    for (int k = 0; k < 10; ++k) ExpectJacobianMatchesFk(robot, RandomInside(robot, rng), RobotModel::EndFrame::kTool);
  }
}

// Standard DH  Prod_i Rz(th_i) Tz(d_i) Tx(a_i) Rx(al_i)  regroups as
//   Rz(th_1)Tz(d_1) [Rx(al_1)Tx(a_1) Rz(th_2)Tz(d_2)] ... [Rx(al_n)Tx(a_n)]
// (Tx and Rx commute), i.e. a modified-DH robot whose joint i carries (al, a) of
// standard joint i-1, with the last Rx(al_n)Tx(a_n) moved into the tool.
TEST(RobotModel, ModifiedDhMatchesEquivalentStandardDh) {
  const RobotModel standard = RobotModel::Default();
  std::vector<Joint> mj = standard.Joints();
  for (int i = standard.NumJoints() - 1; i >= 0; --i) {
    mj[i].alpha = i > 0 ? standard.Joints()[i - 1].alpha : 0.0;
    mj[i].a = i > 0 ? standard.Joints()[i - 1].a : 0.0;
  }
  const Joint& last = standard.Joints().back();
  const Pose T_last{Eigen::AngleAxisd(last.alpha, Vec3::UnitX()).toRotationMatrix(), Vec3(last.a, 0, 0)};
  const Pose tool{ExpSO3(Vec3(-0.3, 0.1, 0.2)), Vec3(0.02, 0.0, 0.12)};
  RobotModel s = standard;
  s.SetT_flange_tool(tool);
  const RobotModel modified("kr5 modified", ChainConvention::kModified, mj, T_last * tool);
  Rng rng(11);
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q = RandomInside(standard, rng);
    const Pose a = s.T_base_tool(q), b = modified.T_base_tool(q);
    EXPECT_LT(BoxMinus(a, b).norm(), 1e-12);
    EXPECT_LT((s.Jacobian(q) - modified.Jacobian(q)).cwiseAbs().maxCoeff(), 1e-12);
    ExpectJacobianMatchesFk(modified, q, RobotModel::EndFrame::kTool);
  }
}

// J Q J^T against the scatter of FK under sampled encoder noise (10x the default sigma,
// still linear to 1e-4 relative). Tolerance: 5 % on each variance for 4000 samples
// (the relative standard error of a variance is sqrt(2/4000) = 2.2 %).
TEST(RobotModel, PoseCovarianceMatchesEncoderNoiseMonteCarlo) {
  const RobotModel robot = RobotModel::Default();
  const Eigen::VectorXd q = Vec({0.3, -0.4, 0.5, 0.2, 0.6, -0.3});
  Eigen::MatrixXd Q = 100.0 * robot.EncoderCovariance();
  const Mat6 C = robot.PoseCovariance(q, Q);
  const Pose T0 = robot.T_base_flange(q);
  Rng rng(5);
  const int n = 4000;
  Mat6 S = Mat6::Zero();
  for (int k = 0; k < n; ++k) {
    Eigen::VectorXd dq(6);
    for (int i = 0; i < 6; ++i) dq[i] = std::sqrt(Q(i, i)) * rng.Normal();
    const Vec6 e = BoxMinus(robot.T_base_flange(q + dq), T0);
    S += e * e.transpose() / n;
  }
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(S(i, i) / C(i, i), 1.0, 0.05) << "component " << i;
  // Full 6x6 including correlations, in the metric of C.
  const Eigen::LLT<Mat6> llt(C);
  const Mat6 L = llt.matrixL();
  const Mat6 W = L.inverse() * S * L.inverse().transpose();
  EXPECT_LT((W - Mat6::Identity()).cwiseAbs().maxCoeff(), 0.08);

  // The default encoder sigma, for the YAML comment: flange position scatter at q = 0.
  const Mat6 C0 = robot.PoseCovariance(Eigen::VectorXd::Zero(6));
  const double rms_mm = std::sqrt(C0.bottomRightCorner<3, 3>().trace()) * 1e3;
  std::printf("default encoder noise at q = 0: flange position scatter %.4f mm RMS (3-D)\n", rms_mm);
  EXPECT_GT(rms_mm, 0.005);
  EXPECT_LT(rms_mm, 0.03);
}

TEST(RobotModel, JointLimitsAreEnforcedAndNamed) {
  const RobotModel robot = RobotModel::Default();
  const std::string msg = ErrorOf([&] { robot.T_base_flange(Vec({0, 70 * kDeg, 0, 0, 0, 0})); });
  EXPECT_NE(msg.find("A2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("= 70.000 deg is above its upper limit 65.000 deg"), std::string::npos) << msg;
  const std::string low = ErrorOf([&] { robot.Jacobian(Vec({0, 0, -20 * kDeg, 0, 0, 0})); });
  EXPECT_NE(low.find("A3"), std::string::npos) << low;
  EXPECT_NE(low.find("lower limit -15"), std::string::npos) << low;
  EXPECT_NE(ErrorOf([&] { robot.T_base_flange(Vec({0, 0, 0})); }).find("6 joints"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { robot.T_base_flange(Vec({0, NAN, 0, 0, 0, 0})); }).find("not finite"), std::string::npos);
  std::string why;
  EXPECT_TRUE(robot.WithinLimits(Vec({155 * kDeg, -180 * kDeg, 158 * kDeg, 0, 130 * kDeg, -350 * kDeg}), &why));
  EXPECT_FALSE(robot.WithinLimits(Vec({156 * kDeg, 0, 0, 0, 0, 0}), &why));
  EXPECT_NE(why.find("A1"), std::string::npos);
}

void ExpectSameRobot(const RobotModel& a, const RobotModel& b) {
  EXPECT_EQ(a.Name(), b.Name());
  EXPECT_EQ(a.Convention(), b.Convention());
  ASSERT_EQ(a.NumJoints(), b.NumJoints());
  for (int i = 0; i < a.NumJoints(); ++i) {
    const Joint &x = a.Joints()[i], &y = b.Joints()[i];
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.type, y.type);
    EXPECT_EQ(x.a, y.a);
    EXPECT_EQ(x.alpha, y.alpha);
    EXPECT_EQ(x.d, y.d);
    EXPECT_EQ(x.theta_offset, y.theta_offset);
    EXPECT_EQ(x.lower, y.lower);
    EXPECT_EQ(x.upper, y.upper);
    EXPECT_EQ(x.encoder_sigma, y.encoder_sigma);
  }
  EXPECT_LT((a.T_flange_tool().R - b.T_flange_tool().R).norm(), 1e-15);
  EXPECT_EQ(a.T_flange_tool().t, b.T_flange_tool().t);
}

TEST(RobotModel, WriteReadRoundTrip) {
  const auto dir = test::ScratchDir("calib_robot_round_trip");
  const RobotModel kr5 = RobotModel::Default();
  kr5.Write(dir / "kr5.yaml");
  ExpectSameRobot(kr5, RobotModel::Read(dir / "kr5.yaml"));

  std::vector<Joint> joints = ScaraJoints();
  joints[3].lower = -std::numeric_limits<double>::infinity();  // an open limit survives as -.inf
  const RobotModel scara("scara with tool", ChainConvention::kModified, joints,
                         Pose{ExpSO3(Vec3(0.3, -0.2, 0.1)), Vec3(0.01, 0.02, 0.3)});
  scara.Write(dir / "scara.yaml");
  ExpectSameRobot(scara, RobotModel::Read(dir / "scara.yaml"));

  // The shipped file and the embedded copy are the same robot.
  ExpectSameRobot(kr5, RobotModel::Read(std::filesystem::path(MCMS_SOURCE_DIR) / "model/robots/kuka_kr5_arc.yaml"));
}

TEST(RobotModel, DegreesAndRadiansAgree) {
  const RobotModel a = RobotModel::Parse(R"(convention: standard_dh
encoder_sigma_deg: 0.001
joints:
  - {name: J1, a_m: 0.1, d_m: 0.2, alpha_deg: 90, theta_offset_deg: -45, limits_deg: [-170, 170]}
)",
                                         "text");
  EXPECT_NEAR(a.Joints()[0].alpha, kPi / 2, 1e-15);
  EXPECT_NEAR(a.Joints()[0].theta_offset, -kPi / 4, 1e-15);
  EXPECT_NEAR(a.Joints()[0].upper, 170 * kDeg, 1e-15);
  EXPECT_NEAR(a.Joints()[0].encoder_sigma, 0.001 * kDeg, 1e-18);
}

TEST(RobotModel, BadFilesAreNamed) {
  const auto dir = test::ScratchDir("calib_robot_bad");
  const auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return dir / name;
  };
  const std::string joint = "  - {name: J1, a_m: 0.1, d_m: 0.2, alpha_rad: 0, theta_offset_rad: 0";
  struct Case {
    std::string file, text, expect;
  };
  const std::vector<Case> cases = {
      {"empty.yaml", "", "must be a map"},
      {"no_joints.yaml", "convention: standard_dh\n", "joints"},
      {"empty_joints.yaml", "convention: standard_dh\njoints: []\n", "joints"},
      {"no_convention.yaml", "joints:\n" + joint + "}\n", "convention"},
      {"bad_convention.yaml", "convention: hayati\njoints:\n" + joint + "}\n", "hayati"},
      {"unknown_key.yaml", "convention: standard_dh\njoints:\n" + joint + ", alpha: 1}\n", "unknown key 'alpha'"},
      {"both_units.yaml", "convention: standard_dh\njoints:\n" + joint + ", alpha_deg: 3}\n", "only one of"},
      {"missing_a.yaml", "convention: standard_dh\njoints:\n  - {d_m: 0, alpha_rad: 0, theta_offset_rad: 0}\n",
       "a_m"},
      {"not_number.yaml", "convention: standard_dh\njoints:\n  - {a_m: abc, d_m: 0, alpha_rad: 0, theta_offset_rad: 0}\n",
       "a_m must be a number"},
      {"bad_limits.yaml", "convention: standard_dh\njoints:\n" + joint + ", limits_deg: [10, -10]}\n", "lower < upper"},
      {"short_limits.yaml", "convention: standard_dh\njoints:\n" + joint + ", limits_deg: [10]}\n", "list of 2"},
      {"prismatic_deg.yaml",
       "convention: standard_dh\njoints:\n" + joint + ", type: prismatic, limits_deg: [0, 1]}\n", "limits_m"},
      {"negative_sigma.yaml", "convention: standard_dh\nencoder_sigma_rad: -1\njoints:\n" + joint + "}\n", ">= 0"},
      {"bad_quaternion.yaml",
       "convention: standard_dh\ntool: {quaternion_wxyz: [1, 1, 0, 0]}\njoints:\n" + joint + "}\n", "unit norm"},
      {"not_yaml.yaml", "convention: [standard_dh\n", "not valid YAML"},
  };
  for (const Case& c : cases) {
    const auto path = write(c.file, c.text);
    const std::string msg = ErrorOf([&] { RobotModel::Read(path); });
    EXPECT_NE(msg.find(c.file), std::string::npos) << c.file << ": " << msg;
    EXPECT_NE(msg.find(c.expect), std::string::npos) << c.file << ": " << msg;
  }
  EXPECT_NE(ErrorOf([&] { RobotModel::Read(dir / "missing.yaml"); }).find("missing.yaml"), std::string::npos);
  // A line number points at the offending joint.
  const auto path = write("line.yaml", "convention: standard_dh\njoints:\n" + joint + "}\n" + joint + ", limits_rad: [1, 0]}\n");
  EXPECT_NE(ErrorOf([&] { RobotModel::Read(path); }).find("line 4"), std::string::npos);
}

TEST(RobotModel, ConstructorRejectsBadParameters) {
  std::vector<Joint> j = ScaraJoints();
  j[1].a = NAN;
  EXPECT_THROW(RobotModel("x", ChainConvention::kStandard, j), InputError);
  EXPECT_THROW(RobotModel("x", ChainConvention::kStandard, {}), InputError);
  j = ScaraJoints();
  j[0].encoder_sigma = -1;
  EXPECT_THROW(RobotModel("x", ChainConvention::kStandard, j), InputError);
  Pose bad;
  bad.R(0, 0) = 2.0;
  EXPECT_THROW(RobotModel("x", ChainConvention::kStandard, ScaraJoints(), bad), InputError);
  const RobotModel r = RobotModel::Default();
  EXPECT_THROW(r.PoseCovariance(Eigen::VectorXd::Zero(6), Eigen::MatrixXd::Identity(5, 5)), InputError);
  EXPECT_THROW(r.PoseCovariance(Eigen::VectorXd::Zero(6), -Eigen::MatrixXd::Identity(6, 6)), InputError);
}

}  // namespace
}  // namespace mcms
