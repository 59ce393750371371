// Real data: kinematic calibration of a two-axis part positioner from 205 measurements of
// a static 6-DOF sensor (ROS-Industrial industrial_calibration's kinematic calibration
// example, /work/shared/data/industrial-calibration-positioner).
//
// Frames of the data set: the sensor ("camera") is static; each measurement is the pose
// T_camera_target and the two positioner joint values. The upstream model is
//   T_camera_target = T_world_camera^-1 * T_world_positionerbase * FK(q) * T_mount_target
// with T_world_positionerbase = Trans(2.2, 0, 1.6) Rx(pi/2) and T_world_camera and
// T_mount_target guessed in pose_initial_guesses.yaml. Here meas = camera, so the
// starting registration is T_camera_base = T_world_camera^-1 * T_world_positionerbase and
// the starting tool T_flange_tool = T_mount_target. The upstream DH rows (d, theta, r,
// alpha) are standard DH: Rz(theta) Tz(d) Tx(r) Rx(alpha).
#include <gtest/gtest.h>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <string>

#include "calib/robot_calibration.h"
#include "test_util.h"

namespace mcms {
namespace {

// Acceptance figures of the upstream test (on all measurements) and of the issue.
constexpr double kMaxMeanPositionM = 2e-3;
constexpr double kMaxMeanRotationRad = 0.2 * M_PI / 180.0;
// Improvement over the nominal DH table with the upstream starting guesses for the sensor
// and the target mount (the upstream "nominal model" before any fitting).
constexpr double kMinImprovement = 0.10;
// Improvement over the nominal DH table REGISTERED (sensor and target mount fitted, DH
// held): a two-axis positioner has only two geometric parameters beyond the two rigid
// transforms (distance and angle between the axes, j1.a and j1.alpha; the rest are
// absorbed by base and tool, as the fixed list says), so DH calibration can remove only
// that part. The remaining residual (about 0.38 mm, 0.046 deg mean) is a function of q2
// that no DH table represents: a fit of the residuals on sin/cos(q2), sin/cos(2 q2)
// halves their x and y RMS, i.e. turntable wobble/eccentricity-like, non-geometric.
// Measured: 9 % (position mean) and 2 % (rotation mean) better; asserted:
constexpr double kMinPositionImprovementOverRegistered = 0.05;

RobotModel Positioner(const Pose& tool) {
  std::vector<Joint> j(2);
  j[0].name = "j1";
  j[0].alpha = -M_PI / 2;
  j[0].lower = -M_PI;
  j[0].upper = M_PI;
  j[1].name = "j2";
  j[1].d = -0.475;
  j[1].theta_offset = -M_PI / 2;
  j[1].lower = -2 * M_PI;
  j[1].upper = 2 * M_PI;
  return RobotModel("two-axis positioner", DhConvention::kStandard, j, tool);
}

Pose ReadGuess(const YAML::Node& n) {
  return Pose::FromQuaternion(
      Eigen::Quaterniond(n["qw"].as<double>(), n["qx"].as<double>(), n["qy"].as<double>(), n["qz"].as<double>())
          .normalized(),
      Vec3(n["x"].as<double>(), n["y"].as<double>(), n["z"].as<double>()));
}

struct Stats {
  double pos_mean, pos_std, rot_mean, rot_std;
};
Stats Of(const std::vector<PoseError>& e) {
  double sp = 0, sp2 = 0, sr = 0, sr2 = 0;
  for (const auto& x : e) {
    sp += x.position();
    sp2 += x.position() * x.position();
    sr += *x.rotation_rad;
    sr2 += *x.rotation_rad * *x.rotation_rad;
  }
  const double n = static_cast<double>(e.size());
  return {sp / n, std::sqrt(std::max(0.0, sp2 / n - sp * sp / n / n)), sr / n,
          std::sqrt(std::max(0.0, sr2 / n - sr * sr / n / n))};
}

void Print(const char* what, const Stats& s) {
  std::printf("%-34s position mean %.3f mm (sd %.3f), rotation mean %.4f deg (sd %.4f)\n", what, s.pos_mean * 1e3,
              s.pos_std * 1e3, s.rot_mean * 180 / M_PI, s.rot_std * 180 / M_PI);
}

TEST(Positioner, RealDataCalibrationBeatsNominalModel) {
  MCMS_REQUIRE_DATA(dir, "industrial-calibration-positioner");
  const auto ms = ReadRobotMeasurements(dir / "measurements.yaml");
  ASSERT_EQ(ms.size(), 205u);
  const YAML::Node guesses = YAML::LoadFile((dir / "pose_initial_guesses.yaml").string());
  const Pose T_world_camera = ReadGuess(guesses["camera_mount_to_camera_guess"]);
  const Pose T_mount_target = ReadGuess(guesses["target_mount_to_target_guess"]);
  const Pose T_world_base{Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX()).toRotationMatrix(), Vec3(2.2, 0.0, 1.6)};
  const Pose guess = T_world_camera.Inverse() * T_world_base;
  const RobotModel nominal = Positioner(T_mount_target);

  RobotCalibrationOptions opt;
  // About the per-axis scatter of the final residuals (variance factor ~ 1); the results
  // change by < 0.01 mm for ratios of the two sigmas from 1e-2 to 1e2 m/rad.
  opt.position_sigma_m = 0.25e-3;
  opt.rotation_sigma_rad = 0.03 * M_PI / 180;
  const RobotCalibrationResult cal = CalibrateRobot(nominal, guess, ms, opt);
  RobotCalibrationOptions reg_opt = opt;
  reg_opt.estimate_dh = false;
  const RobotCalibrationResult reg = CalibrateRobot(nominal, guess, ms, reg_opt);
  EXPECT_TRUE(cal.converged);
  for (const auto* p : cal.Fixed()) std::printf("fixed %-16s %s\n", p->name.c_str(), p->reason.c_str());
  for (const auto& p : cal.parameters)
    if (!p.fixed && p.name.rfind("j", 0) == 0)
      std::printf("%-16s %+.6f +- %.6f\n", p.name.c_str(), p.estimate, p.sigma);
  for (const auto& c : cal.correlated) std::printf("correlated %s %s %.3f\n", c.a.c_str(), c.b.c_str(), c.rho);

  const Stats s_cal = Of(cal.errors_after), s_nom = Of(reg.errors_after), s_start = Of(cal.errors_before);
  Print("starting guess (all 205):", s_start);
  Print("nominal DH, registered (all 205):", s_nom);
  Print("calibrated (all 205):", s_cal);
  EXPECT_LT(s_cal.pos_mean, kMaxMeanPositionM);
  EXPECT_LT(s_cal.rot_mean, kMaxMeanRotationRad);
  EXPECT_GT((s_start.pos_mean - s_cal.pos_mean) / s_start.pos_mean, kMinImprovement);
  EXPECT_GT((s_start.rot_mean - s_cal.rot_mean) / s_start.rot_mean, kMinImprovement);
  EXPECT_GT((s_nom.pos_mean - s_cal.pos_mean) / s_nom.pos_mean, kMinPositionImprovementOverRegistered);
  EXPECT_LE(s_cal.rot_mean, s_nom.rot_mean);
  // The identifiability analysis finds exactly the redundancies of this chain.
  std::set<std::string> fixed;
  for (const auto* p : cal.Fixed()) fixed.insert(p->name);
  EXPECT_EQ(fixed, (std::set<std::string>{"j1.theta_offset", "j1.d", "j2.theta_offset", "j2.d", "j2.a", "j2.alpha"}));

  // Held out: 5-fold cross-validation, each measurement predicted without its fold.
  const CrossValidation cv = CrossValidateRobot(nominal, guess, ms, opt, 5);
  const Stats h_cal = Of(cv.calibrated), h_nom = Of(cv.nominal);
  Print("nominal DH, 5-fold held out:", h_nom);
  Print("calibrated, 5-fold held out:", h_cal);
  EXPECT_LT(h_cal.pos_mean, kMaxMeanPositionM);
  EXPECT_LT(h_cal.rot_mean, kMaxMeanRotationRad);
  EXPECT_GT((h_nom.pos_mean - h_cal.pos_mean) / h_nom.pos_mean, kMinPositionImprovementOverRegistered);
  EXPECT_LE(h_cal.rot_mean, h_nom.rot_mean);
}

}  // namespace
}  // namespace mcms
