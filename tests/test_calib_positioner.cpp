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
#include <numbers>
#include <gtest/gtest.h>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <string>
#include <tuple>

#include "calib/robot_calibration.h"
#include "core/random.h"
#include "positioner.h"
#include "test_util.h"

namespace mcms {
namespace {

// Acceptance figures of the upstream test (on all measurements) and of the issue.
constexpr double kMaxMeanPositionM = 2e-3;
constexpr double kMaxMeanRotationRad = 0.2 * std::numbers::pi / 180.0;
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

using test::Positioner;
using test::ReadGuess;

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
              s.pos_std * 1e3, s.rot_mean * 180 / std::numbers::pi, s.rot_std * 180 / std::numbers::pi);
}

TEST(Positioner, RealDataCalibrationBeatsNominalModel) {
  MCMS_REQUIRE_DATA(dir, "industrial-calibration-positioner");
  const auto ms = ReadRobotMeasurements(dir / "measurements.yaml");
  ASSERT_EQ(ms.size(), 205u);
  const YAML::Node guesses = YAML::LoadFile((dir / "pose_initial_guesses.yaml").string());
  const Pose T_world_camera = ReadGuess(guesses["camera_mount_to_camera_guess"]);
  const Pose T_mount_target = ReadGuess(guesses["target_mount_to_target_guess"]);
  const Pose T_world_base{Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()).toRotationMatrix(), Vec3(2.2, 0.0, 1.6)};
  const Pose guess = T_world_camera.Inverse() * T_world_base;
  const RobotModel nominal = Positioner(T_mount_target);

  RobotCalibrationOptions opt;
  // About the per-axis scatter of the final residuals (variance factor ~ 1); the results
  // change by < 0.01 mm for ratios of the two sigmas from 1e-2 to 1e2 m/rad.
  opt.position_sigma_m = 0.25e-3;
  opt.rotation_sigma_rad = 0.03 * std::numbers::pi / 180;
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


// The model extension. The DH calibration above leaves a residual that depends on the
// turntable angle q2, which no DH table can represent; a rotary axis that is not a
// perfect rotation has "error motion" (ISO 230-7: tilt, radial, axial and angular
// positioning error as functions of the angle), modelled in model/robot_model.h as a
// harmonic series of q2 and estimated with the rest. The number of harmonics is chosen
// by held-out (5-fold) error, and the gain is measured held out, never on the fitting set.
// Measured (position mean / rotation mean, held out):
//   DH only 0.378 mm / 0.0465 deg; H=1 0.272 / 0.0418; H=2 0.247 / 0.0408; H=3 0.228 / 0.0400.
// The largest terms are once-per-revolution tilt (0.64 +- 0.06 mrad about the fixed y
// axis) and radial motion (0.57 +- 0.03 mm along y). These data cannot tell a turntable
// error motion from a bias of the sensor that depends on how the target faces it (the
// target turns with q2): what is established is that the effect is a smooth, repeatable
// function of q2 that predicts held-out poses.
constexpr double kMinHeldOutGainH1 = 0.20;  // position mean, H=1 vs DH only (measured 28 %)
constexpr int kMaxHarmonics = 3;

TEST(Positioner, TurntableErrorMotionExplainsTheResidual) {
  MCMS_REQUIRE_DATA(dir, "industrial-calibration-positioner");
  const auto ms = ReadRobotMeasurements(dir / "measurements.yaml");
  const YAML::Node guesses = YAML::LoadFile((dir / "pose_initial_guesses.yaml").string());
  const Pose T_world_base{Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()).toRotationMatrix(), Vec3(2.2, 0.0, 1.6)};
  const Pose guess = ReadGuess(guesses["camera_mount_to_camera_guess"]).Inverse() * T_world_base;
  const RobotModel nominal = Positioner(ReadGuess(guesses["target_mount_to_target_guess"]));
  RobotCalibrationOptions opt;
  opt.position_sigma_m = 0.25e-3;
  opt.rotation_sigma_rad = 0.03 * std::numbers::pi / 180;
  std::vector<Stats> held;
  int best = 0;
  for (int H = 0; H <= kMaxHarmonics; ++H) {
    RobotCalibrationOptions o = opt;
    o.error_motion_harmonics = {0, H};
    const CrossValidation cv = CrossValidateRobot(nominal, guess, ms, o, 5);
    held.push_back(Of(cv.calibrated));
    std::printf("turntable error motion, %d harmonics: 5-fold held out %.3f mm / %.4f deg\n", H,
                held.back().pos_mean * 1e3, held.back().rot_mean * 180 / std::numbers::pi);
    if (held.back().pos_mean < held[best].pos_mean) best = H;
  }
  // Each harmonic added up to kMaxHarmonics predicts held-out poses better.
  for (int H = 1; H <= kMaxHarmonics; ++H) EXPECT_LT(held[H].pos_mean, held[H - 1].pos_mean) << H;
  EXPECT_GT((held[0].pos_mean - held[1].pos_mean) / held[0].pos_mean, kMinHeldOutGainH1);
  EXPECT_LT(held[1].rot_mean, held[0].rot_mean);

  // The chosen model against the nominal DH table registered, by the criteria
  // (mean position and rotation error > 10 % better) and the upstream test's position
  // spread, on all measurements as upstream does and held out. The spread of the rotation
  // error improves by only 4 % (all) and 1 % (held out), so it is reported, not asserted:
  // the rotation residual left (0.039 deg mean) is near the sensor's own orientation noise.
  RobotCalibrationOptions o = opt;
  o.error_motion_harmonics = {0, best};
  const RobotCalibrationResult cal = CalibrateRobot(nominal, guess, ms, o);
  RobotCalibrationOptions reg_opt = opt;
  reg_opt.estimate_dh = false;
  const RobotCalibrationResult reg = CalibrateRobot(nominal, guess, ms, reg_opt);
  const CrossValidation cv = CrossValidateRobot(nominal, guess, ms, o, 5);
  int kept = 0, held_terms = 0;
  for (const auto& p : cal.parameters)
    if (p.name.find(".em") != std::string::npos) (p.fixed ? held_terms : kept)++;
  std::printf("chosen: %d harmonics, %d error-motion terms estimated, %d held (they duplicate the tool)\n", best, kept,
              held_terms);
  for (const auto& [what, c, n] : {std::tuple{"all 205", Of(cal.errors_after), Of(reg.errors_after)},
                                   std::tuple{"held out", Of(cv.calibrated), Of(cv.nominal)}}) {
    Print((std::string("registered nominal, ") + what + ":").c_str(), n);
    Print((std::string("DH + error motion, ") + what + ":").c_str(), c);
    EXPECT_LT(c.pos_mean, kMaxMeanPositionM) << what;
    EXPECT_LT(c.rot_mean, kMaxMeanRotationRad) << what;
    EXPECT_GT((n.pos_mean - c.pos_mean) / n.pos_mean, kMinImprovement) << what;
    EXPECT_GT((n.pos_std - c.pos_std) / n.pos_std, kMinImprovement) << what;
    EXPECT_GT((n.rot_mean - c.rot_mean) / n.rot_mean, kMinImprovement) << what;
  }
}

// The hidden effect found: a synthetic positioner whose turntable has error motion (and
// DH errors) is measured with noise. DH-only calibration leaves a variance factor far
// above 1 (the model is wrong and the fit says so); with the error motion estimated the
// variance factor returns to 1 and every estimated term is within 3 sigma of the truth.
TEST(Positioner, FindsInjectedErrorMotion) {
  constexpr double kSigmaP = 5e-5, kSigmaR = 1e-4;  // measurement noise, m and rad per axis
  const RobotModel nominal = Positioner(Pose{Mat3::Identity(), Vec3(0.2, -0.1, 0.3)});
  Eigen::VectorXd dh = Eigen::VectorXd::Zero(8);
  dh[2] = 4e-4;   // j1.a
  dh[3] = -3e-4;  // j1.alpha
  // Terms the identifiability analysis keeps (a first-harmonic sine/cosine pair of tilt or
  // radial motion is half a rotating-frame constant, i.e. tool); others zero.
  Eigen::VectorXd em = Eigen::VectorXd::Zero(24);
  em[1] = -6e-4;        // em1.sin.ry: tilt once per revolution
  em[4] = 3e-4;         // em1.sin.y: radial once per revolution
  em[12 + 2] = 1.5e-4;  // em2.sin.rz: angular positioning error twice per revolution
  em[12 + 5] = 2e-4;    // em2.sin.z: axial error motion twice per revolution
  const RobotModel truth = WithErrorMotionErrors(WithGeometryErrors(nominal, dh), {0, 2}, em);
  const Pose T_meas_base{ExpSO3(Vec3(0.3, -0.2, 0.1)), Vec3(0.5, -0.3, 1.4)};
  Rng rng(11);
  std::vector<RobotMeasurement> ms;
  for (int a = 0; a < 13; ++a)
    for (int b = 0; b < 16; ++b) {
      RobotMeasurement m;
      m.q = Eigen::Vector2d((a - 6) * 5.0 * std::numbers::pi / 180, b * 22.5 * std::numbers::pi / 180);
      const Pose T = T_meas_base * truth.T_base_tool(m.q);
      m.p_meas = T.t + Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * kSigmaP;
      m.R_meas_tool = ExpSO3(Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * kSigmaR) * T.R;
      ms.push_back(m);
    }
  RobotCalibrationOptions o;
  o.position_sigma_m = kSigmaP;
  o.rotation_sigma_rad = kSigmaR;
  const RobotCalibrationResult dh_only = CalibrateRobot(nominal, T_meas_base, ms, o);
  o.error_motion_harmonics = {0, 2};
  const RobotCalibrationResult full = CalibrateRobot(nominal, T_meas_base, ms, o);
  std::printf("variance factor: DH only %.1f, DH + error motion %.3f\n", dh_only.variance_factor,
              full.variance_factor);
  // With ~1240 degrees of freedom a correct model gives 1 +- 0.04; measured 5.6.
  EXPECT_GT(dh_only.variance_factor, 2.0);
  EXPECT_LT(full.variance_factor, 1.15);
  EXPECT_GT(full.variance_factor, 0.85);
  const auto names = CalibrationParameterNames(nominal, o);
  int checked = 0;
  for (size_t k = 0; k < full.parameters.size(); ++k) {
    const auto& p = full.parameters[k];
    if (p.fixed || p.name.find(".em") == std::string::npos) continue;
    const double t = em[static_cast<int>(k) - 20];  // 8 DH + 12 base/tool before the error motion
    EXPECT_LT(std::abs(p.estimate - t), 3 * p.sigma) << p.name << " " << p.estimate << " truth " << t;
    ++checked;
  }
  EXPECT_EQ(checked, 20);  // 24 terms, 4 held as the tool's
  // The calibrated model's YAML keeps the error motion.
  const RobotModel back = RobotModel::Parse(full.robot.ToYaml(), "calibrated positioner");
  const Eigen::VectorXd q = Eigen::Vector2d(0.2, 1.3);
  EXPECT_LT((back.T_base_tool(q).t - full.robot.T_base_tool(q).t).norm(), 1e-12);
}

}  // namespace
}  // namespace mcms
