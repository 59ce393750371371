// The chi-square consistency check: false-alarm rate on consistent sensors, the
// leave-one-out identity, detection and attribution of an offset sensor (positions, and
// poses with a robot whose joint offset is wrong and a bumped camera).
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>

#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "core/error.h"
#include "core/random.h"
#include "core/statistics.h"
#include "fusion/consistency.h"

namespace mcms {
namespace {

constexpr double kPi = std::numbers::pi;

Vec3 SampleDiag(Rng& rng, const Vec3& sigma) {
  return Vec3(sigma.x() * rng.Normal(), sigma.y() * rng.Normal(), sigma.z() * rng.Normal());
}

const Vec3 kCamera(0.15e-3, 0.15e-3, 0.15e-3);     // the paper's sigmas
const Vec3 kRobot(0.157e-3, 0.087e-3, 0.043e-3);
const Vec3 kTracker(0.03e-3, 0.03e-3, 0.03e-3);    // a laser tracker as third sensor

std::vector<PositionMeasurement> ThreeSensors(Rng& rng, const Vec3& truth, const Vec3& robot_offset) {
  return {PositionMeasurement::FromCovariance("camera", truth + SampleDiag(rng, kCamera),
                                              kCamera.cwiseAbs2().asDiagonal()),
          PositionMeasurement::FromCovariance("robot", truth + robot_offset + SampleDiag(rng, kRobot),
                                              kRobot.cwiseAbs2().asDiagonal()),
          PositionMeasurement::FromCovariance("tracker", truth + SampleDiag(rng, kTracker),
                                              kTracker.cwiseAbs2().asDiagonal())};
}

// With full-rank sensors the per-sensor statistic is the leave-one-out NIS.
TEST(Consistency, PerSensorStatisticIsLeaveOneOutNis) {
  Rng rng(1);
  const auto m = ThreeSensors(rng, Vec3(0.1, 0.2, 0.3), Vec3(2e-4, 0, 0));
  const ConsistencyReport r = CheckConsistency(m);
  ASSERT_EQ(r.sensors.size(), 3u);
  EXPECT_EQ(r.dof, 6);
  for (int i = 0; i < 3; ++i) {
    std::vector<PositionMeasurement> others;
    for (int j = 0; j < 3; ++j)
      if (j != i) others.push_back(m[j]);
    const FusedPosition f = FusePositions(others);
    const Mat3 Pi = m[i].information.inverse();
    const Vec3 nu = Pi * m[i].information_vector - f.p;
    const double nis = nu.dot((Pi + f.covariance).inverse() * nu);
    EXPECT_NEAR(r.sensors[i].nis, nis, 1e-9 * (1 + nis)) << m[i].name;
    EXPECT_EQ(r.sensors[i].dof, 3);
    EXPECT_NEAR(r.sensors[i].p_value, ChiSquareSurvival(nis, 3), 1e-9);
  }
}

// 2000 consistent trials at significance 0.01: the total test's false alarms stay inside
// the binomial 99.9 % band [7, 37] around 20, and the mean per-sensor NIS is its dof
// (band: mean of 2000 chi2(3), 99.9 % two-sided).
TEST(Consistency, ConsistentSensorsPass) {
  Rng rng(2);
  const int n = 2000;
  int alarms = 0, excluded = 0;
  Vec3 nis_sum = Vec3::Zero();
  for (int k = 0; k < n; ++k) {
    const ConsistencyReport r = CheckConsistency(ThreeSensors(rng, Vec3(0.1, 0.2, 0.3), Vec3::Zero()));
    alarms += r.consistent ? 0 : 1;
    excluded += static_cast<int>(r.excluded.size());
    for (int i = 0; i < 3; ++i) nis_sum[i] += r.sensors[i].nis;
  }
  std::printf("consistent sensors: %d false alarms in %d trials at significance 0.01\n", alarms, n);
  EXPECT_GE(alarms, 7);
  EXPECT_LE(alarms, 37);
  EXPECT_LE(excluded, alarms);
  const double lo = ChiSquareQuantile(0.0005, 3 * n) / n, hi = ChiSquareQuantile(0.9995, 3 * n) / n;
  for (int i = 0; i < 3; ++i) {
    EXPECT_GT(nis_sum[i] / n, lo);
    EXPECT_LT(nis_sum[i] / n, hi);
  }
}

// A robot 1.2 mm off in x (7.6 of its sigmas; at 0.8 mm the test detects ~92 %): flagged
// and excluded, the others kept.
TEST(Consistency, OffsetSensorIsIsolated) {
  Rng rng(3);
  const int n = 500;
  int isolated = 0, detected = 0;
  for (int k = 0; k < n; ++k) {
    const ConsistencyReport r = CheckConsistency(ThreeSensors(rng, Vec3(0.1, 0.2, 0.3), Vec3(1.2e-3, 0, 0)));
    detected += r.consistent ? 0 : 1;
    if (r.excluded == std::vector<int>{1} && r.attributed) ++isolated;
  }
  std::printf("robot 1.2 mm off: detected %d / %d, isolated as the only bad sensor %d / %d\n", detected, n, isolated, n);
  EXPECT_GE(detected, n * 99 / 100);
  EXPECT_GE(isolated, n * 95 / 100);
}

// Two sensors that disagree: detected, but not attributable.
TEST(Consistency, TwoSensorsCannotBeAttributed) {
  Rng rng(4);
  const auto m3 = ThreeSensors(rng, Vec3::Zero(), Vec3(3e-3, 0, 0));
  const ConsistencyReport r = CheckConsistency(std::vector<PositionMeasurement>{m3[0], m3[1]});
  EXPECT_FALSE(r.consistent);
  EXPECT_FALSE(r.attributed);
  EXPECT_TRUE(r.excluded.empty());
  EXPECT_NEAR(r.sensors[0].nis, r.sensors[1].nis, 1e-9 * r.sensors[0].nis);
  EXPECT_TRUE(r.sensors[0].flagged && r.sensors[1].flagged);
  ConsistencyOptions bad;
  bad.significance = 1.5;
  EXPECT_THROW(CheckConsistency(m3, bad), InputError);
  EXPECT_THROW(CheckConsistency(std::vector<PositionMeasurement>{}), InputError);
}

// Poses: camera, robot (FK of the KR 5 arc) and inclinometer on the flange.
struct PoseScene {
  RobotModel robot = RobotModel::Default();
  Inclinometer incl;
  Eigen::VectorXd q;
  Mat6 C_camera, C_robot;
  PoseScene() {
    incl.R_flange_incl = Eigen::AngleAxisd(kPi / 2, Vec3::UnitY()).toRotationMatrix();
    q.resize(6);
    q << 0.2, -0.3, 0.4, 0.1, -0.15, 0.3;  // keeps the sensor within its 30 deg range
    C_camera = (Vec6() << 0.5e-3, 0.5e-3, 0.5e-3, 0.15e-3, 0.15e-3, 0.15e-3).finished().cwiseAbs2().asDiagonal();
    // Robot absolute accuracy (not encoder noise): 0.3 mrad and the paper's position sigmas.
    C_robot = (Vec6() << 0.3e-3, 0.3e-3, 0.3e-3, 0.157e-3, 0.087e-3, 0.043e-3).finished().cwiseAbs2().asDiagonal();
  }
  // robot_joint_error: the true joint offsets differ from the model's by this (rad);
  // camera_bump: the camera's frame is rotated by this (rad, base frame).
  std::vector<PoseMeasurement> Measure(Rng& rng, const Eigen::VectorXd& robot_joint_error, const Vec3& camera_bump) {
    const Pose truth = robot.T_base_flange(q + robot_joint_error);  // where the flange really is
    const Pose fk = robot.T_base_flange(q);                         // where the robot says it is
    Vec6 nc, nr;
    for (int i = 0; i < 6; ++i) nc[i] = std::sqrt(C_camera(i, i)) * rng.Normal();
    for (int i = 0; i < 6; ++i) nr[i] = std::sqrt(C_robot(i, i)) * rng.Normal();
    Pose cam = BoxPlus(truth, nc);
    cam = Pose{ExpSO3(camera_bump), Vec3::Zero()} * cam;  // a bumped rig rotates everything it sees
    const Vec2 reading = *incl.Simulate(truth.R, rng);
    return {PoseMeasurement::FromCovariance("camera", cam, C_camera),
            PoseMeasurement::FromCovariance("robot", BoxPlus(fk, nr), C_robot),
            PoseMeasurement::FromOrientation("inclinometer", incl.Constraint(reading, cam.R))};
  }
};

TEST(Consistency, RobotWithBadJointOffsetIsIsolated) {
  PoseScene s;
  Rng rng(5);
  Eigen::VectorXd err = Eigen::VectorXd::Zero(6);
  err[1] = 0.1 * kPi / 180;  // A2 zero off by 0.1 deg: 1.7 mrad tilt and ~1.5 mm at the flange
  const int n = 200;
  int isolated = 0, passed_clean = 0;
  for (int k = 0; k < n; ++k) {
    const ConsistencyReport bad = CheckConsistency(s.Measure(rng, err, Vec3::Zero()));
    if (!bad.consistent && bad.excluded == std::vector<int>{1} && bad.attributed) ++isolated;
    const ConsistencyReport good = CheckConsistency(s.Measure(rng, Eigen::VectorXd::Zero(6), Vec3::Zero()));
    if (good.consistent) ++passed_clean;
  }
  std::printf("robot A2 offset 0.1 deg: isolated %d / %d; clean scene passed %d / %d\n", isolated, n, passed_clean, n);
  EXPECT_GE(isolated, n * 95 / 100);
  EXPECT_GE(passed_clean, n * 96 / 100);  // 99 % expected; binomial 99.9 % lower bound ~96 %
}

TEST(Consistency, BumpedCameraIsIsolated) {
  PoseScene s;
  Rng rng(6);
  const int n = 200;
  int isolated = 0;
  for (int k = 0; k < n; ++k) {
    // 3 mrad about a horizontal axis: the robot and the inclinometer both disagree with it.
    const ConsistencyReport r = CheckConsistency(s.Measure(rng, Eigen::VectorXd::Zero(6), Vec3(0.0, 3e-3, 0.0)));
    if (r.excluded == std::vector<int>{0} && r.attributed) ++isolated;
  }
  std::printf("camera bumped 3 mrad: isolated %d / %d\n", isolated, n);
  EXPECT_GE(isolated, n * 95 / 100);
}

}  // namespace
}  // namespace mcms
