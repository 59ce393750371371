// Kinematic calibration and base registration on a synthetic KUKA KR 5 arc with injected
// DH, base and tool errors and noisy measurements (calib/robot_calibration.h,
// calib/registration.h).
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <set>
#include <string>

#include <Eigen/Dense>

#include "calib/registration.h"
#include "calib/robot_calibration.h"
#include "core/error.h"
#include "core/random.h"
#include "model/urdf.h"
#include "test_util.h"

namespace mcms {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kNoise = 0.05e-3;  // m per axis
// Held-out 3-D RMS error may exceed the noise's 3-D RMS by this factor (model error from
// the finite fitting set adds about sqrt(1 + p / (3 N)) ~ 1.04 for p ~ 26, N = 120).
constexpr double kHeldOutFactor = 1.2;

struct Truth {
  RobotModel nominal;   // DH table as designed, tool as drawn
  RobotModel actual;    // with the injected errors
  Pose T_meas_base;     // true registration
  Eigen::VectorXd dh_errors;
};

Truth MakeTruth(uint64_t seed) {
  Rng rng(seed);
  Truth t;
  RobotModel nominal = RobotModel::Default();
  nominal.SetT_flange_tool(Pose{Mat3::Identity(), Vec3(0.02, -0.01, 0.15)});
  t.nominal = nominal;
  const int n = nominal.NumJoints();
  t.dh_errors.resize(4 * n);
  for (int i = 0; i < n; ++i) {
    auto sign = [&] { return rng.Uniform() < 0.5 ? -1.0 : 1.0; };
    t.dh_errors[4 * i + 0] = sign() * 0.05 * kDeg;
    t.dh_errors[4 * i + 1] = sign() * 0.5e-3;
    t.dh_errors[4 * i + 2] = sign() * 0.5e-3;
    t.dh_errors[4 * i + 3] = sign() * 0.05 * kDeg;
  }
  t.actual = WithGeometryErrors(nominal, t.dh_errors);
  // Tool error: 1 mm and 0.5 deg.
  t.actual.SetT_flange_tool(
      Pose{ExpSO3(Vec3(0.3, -0.2, 0.3) * kDeg) * nominal.T_flange_tool().R, nominal.T_flange_tool().t + Vec3(1e-3, -0.7e-3, 0.8e-3)});
  // The rig 2.5 m in front of the robot, looking back at it.
  t.T_meas_base = Pose{ExpSO3(Vec3(0.2, -0.1, 2.8)), Vec3(2.5, 0.3, -0.4)};
  return t;
}

std::vector<Eigen::VectorXd> RandomPoses(const RobotModel& robot, int count, Rng& rng) {
  // Within 80 % of the limits (and |q| < 150 deg on the wrist rolls) to stay in a plausible
  // measuring volume.
  std::vector<Eigen::VectorXd> poses;
  for (int k = 0; k < count; ++k) {
    Eigen::VectorXd q(robot.NumJoints());
    for (int i = 0; i < robot.NumJoints(); ++i) {
      const Joint& j = robot.Joints()[i];
      const double lo = std::max(j.lower, -150 * kDeg), hi = std::min(j.upper, 150 * kDeg);
      const double mid = 0.5 * (lo + hi), half = 0.4 * (hi - lo);
      q[i] = rng.Uniform(mid - half, mid + half);
    }
    poses.push_back(q);
  }
  return poses;
}

std::vector<RobotMeasurement> Measure(const Truth& t, const std::vector<Eigen::VectorXd>& poses, bool six_dof,
                                      double noise, double rot_noise, Rng& rng) {
  std::vector<RobotMeasurement> out;
  for (const auto& q : poses) {
    const Pose T = t.T_meas_base * t.actual.T_base_tool(q);
    RobotMeasurement m;
    m.q = q;
    m.p_meas = T.t + noise * Vec3(rng.Normal(), rng.Normal(), rng.Normal());
    if (six_dof) m.R_meas_tool = ExpSO3(rot_noise * Vec3(rng.Normal(), rng.Normal(), rng.Normal())) * T.R;
    out.push_back(m);
  }
  return out;
}

double Rms3d(const std::vector<PoseError>& e) { return Summarize(e).rms_position_m; }

const CalibrationParameter& Param(const RobotCalibrationResult& r, const std::string& name) {
  for (const auto& p : r.parameters)
    if (p.name == name) return p;
  throw std::runtime_error("no parameter " + name);
}

TEST(RobotCalibration, IdentifiesInjectedErrorsFromNoisyPositions) {
  const Truth truth = MakeTruth(11);
  Rng rng(12);
  const auto fit_poses = RandomPoses(truth.nominal, 120, rng);
  const auto test_poses = RandomPoses(truth.nominal, 200, rng);
  const auto fit = Measure(truth, fit_poses, false, kNoise, 0, rng);
  const auto held_out = Measure(truth, test_poses, false, kNoise, 0, rng);

  RobotCalibrationOptions opt;
  opt.position_sigma_m = kNoise;
  const Pose guess = InitialBaseGuess(truth.nominal, fit);
  const RobotCalibrationResult r = CalibrateRobot(truth.nominal, guess, fit, opt);
  EXPECT_TRUE(r.converged);

  // The dependencies the analysis must find on this robot with 3-D measurements.
  std::set<std::string> fixed;
  for (const auto* p : r.Fixed()) fixed.insert(p->name);
  for (const auto* p : r.Fixed()) std::printf("  fixed %-16s %s\n", p->name.c_str(), p->reason.c_str());
  for (const auto& c : r.correlated) std::printf("  correlated %s ~ %s: %.3f\n", c.a.c_str(), c.b.c_str(), c.rho);
  for (const char* f : {"A1.theta_offset", "A1.d", "tool.rx", "tool.ry", "tool.rz"})
    EXPECT_TRUE(fixed.count(f)) << f << " should be fixed";
  // A2 and A3 are parallel (alpha2 = 0): d2 and d3 shift along the same axis.
  EXPECT_TRUE(fixed.count("A3.d") || fixed.count("A2.d"));
  EXPECT_NE(Param(r, "A1.theta_offset").reason.find("base.r"), std::string::npos) << Param(r, "A1.theta_offset").reason;

  // The truth in the reduced parameterization: the same fit on noise-free measurements.
  Rng rng0(13);
  const auto exact = Measure(truth, fit_poses, false, 0.0, 0, rng0);
  RobotCalibrationOptions exact_opt = opt;
  exact_opt.fixed.clear();
  for (const auto& f : fixed) exact_opt.fixed.push_back(f);
  const RobotCalibrationResult r0 = CalibrateRobot(truth.nominal, guess, exact, exact_opt);
  EXPECT_LT(Rms3d(r0.errors_after), 1e-9);
  // Parameters that enter no dependency keep their injected values exactly: the alphas and
  // a's of joints 2-5.
  for (int i = 1; i < 5; ++i) {
    EXPECT_NEAR(r0.parameters[4 * i + 2].estimate, truth.dh_errors[4 * i + 2], 1e-8) << r0.parameters[4 * i + 2].name;
    EXPECT_NEAR(r0.parameters[4 * i + 3].estimate, truth.dh_errors[4 * i + 3], 1e-8) << r0.parameters[4 * i + 3].name;
  }
  int beyond = 0, checked = 0;
  for (int k : r.free_parameters) {
    const auto& p = r.parameters[k];
    ++checked;
    if (std::abs(p.estimate - r0.parameters[k].estimate) > 3 * p.sigma) {
      ++beyond;
      ADD_FAILURE() << p.name << " estimate " << p.estimate << " truth " << r0.parameters[k].estimate << " sigma "
                    << p.sigma;
    }
  }
  EXPECT_GT(checked, 25);
  EXPECT_EQ(beyond, 0);

  const double noise_rms_3d = std::sqrt(3.0) * kNoise;
  const double before = Rms3d(PredictionErrors(truth.nominal, guess, held_out));
  const double after = Rms3d(PredictionErrors(r.robot, r.T_meas_base, held_out));
  std::printf("KR5 3-D: fixed %zu, free %zu, held-out RMS before %.3f mm, after %.4f mm (noise 3-D RMS %.4f mm)\n",
              fixed.size(), r.free_parameters.size(), before * 1e3, after * 1e3, noise_rms_3d * 1e3);
  EXPECT_LT(after, kHeldOutFactor * noise_rms_3d);
  EXPECT_GT(before, 10 * noise_rms_3d);
  EXPECT_NEAR(r.variance_factor, 1.0, 0.3);
}

TEST(RobotCalibration, SixDofMeasurementsFixTheLastLinkAgainstTheTool) {
  const Truth truth = MakeTruth(21);
  Rng rng(22);
  const auto fit = Measure(truth, RandomPoses(truth.nominal, 60, rng), true, kNoise, 1e-4, rng);
  const auto held_out = Measure(truth, RandomPoses(truth.nominal, 100, rng), true, kNoise, 1e-4, rng);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = kNoise;
  opt.rotation_sigma_rad = 1e-4;
  const RobotCalibrationResult r = CalibrateRobot(truth.nominal, InitialBaseGuess(truth.nominal, fit), fit, opt);
  std::set<std::string> fixed;
  for (const auto* p : r.Fixed()) fixed.insert(p->name);
  for (const char* f : {"A1.theta_offset", "A1.d", "A6.theta_offset", "A6.d"})
    EXPECT_TRUE(fixed.count(f)) << f << " should be fixed";
  EXPECT_FALSE(fixed.count("tool.rx"));
  const auto e = Summarize(PredictionErrors(r.robot, r.T_meas_base, held_out));
  std::printf("KR5 6-D: held-out RMS %.4f mm, %.4f deg (noise %.4f mm, %.4f deg 3-D RMS)\n",
              e.rms_position_m * 1e3, *e.rms_rotation_rad / kDeg, std::sqrt(3.0) * kNoise * 1e3,
              std::sqrt(3.0) * 1e-4 / kDeg);
  EXPECT_LT(e.rms_position_m, kHeldOutFactor * std::sqrt(3.0) * kNoise);
  EXPECT_LT(*e.rms_rotation_rad, kHeldOutFactor * std::sqrt(3.0) * 1e-4);
}

TEST(RobotCalibration, ModifiedDhRobotCalibrates) {
  // A 3-joint modified-DH arm with two parallel axes (2, 3): in modified DH the
  // parallel-axes d ambiguity remains (d2 vs d3), and the fit still reaches the noise.
  std::vector<Joint> j(3);
  j[0].name = "J1";
  j[0].d = 0.3;
  j[1].name = "J2";
  j[1].alpha = -std::numbers::pi / 2;
  j[1].a = 0.05;
  j[2].name = "J3";
  j[2].a = 0.4;
  for (auto& x : j) x.lower = -2.5, x.upper = 2.5;
  Truth t;
  t.nominal = RobotModel("mdh3", ChainConvention::kModified, j, Pose{Mat3::Identity(), Vec3(0.3, 0.0, 0.05)});
  t.dh_errors = Eigen::VectorXd::Constant(12, 0.4e-3);
  t.actual = WithGeometryErrors(t.nominal, t.dh_errors);
  t.T_meas_base = Pose{ExpSO3(Vec3(0.1, 0.2, -0.3)), Vec3(1.0, 0.5, 0.2)};
  Rng rng(31);
  const auto fit = Measure(t, RandomPoses(t.nominal, 50, rng), false, kNoise, 0, rng);
  const auto held_out = Measure(t, RandomPoses(t.nominal, 100, rng), false, kNoise, 0, rng);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = kNoise;
  const auto r = CalibrateRobot(t.nominal, InitialBaseGuess(t.nominal, fit), fit, opt);
  std::set<std::string> fixed;
  for (const auto* p : r.Fixed()) fixed.insert(p->name);
  EXPECT_TRUE(fixed.count("J2.d") || fixed.count("J3.d"));
  EXPECT_LT(Rms3d(PredictionErrors(r.robot, r.T_meas_base, held_out)), kHeldOutFactor * std::sqrt(3.0) * kNoise);
}

TEST(RobotCalibration, CrossValidationBeatsNominal) {
  const Truth truth = MakeTruth(41);
  Rng rng(42);
  const auto ms = Measure(truth, RandomPoses(truth.nominal, 100, rng), false, kNoise, 0, rng);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = kNoise;
  const CrossValidation cv = CrossValidateRobot(truth.nominal, InitialBaseGuess(truth.nominal, ms), ms, opt, 5);
  const double cal = Rms3d(cv.calibrated), nom = Rms3d(cv.nominal);
  std::printf("KR5 5-fold: held-out RMS nominal %.3f mm, calibrated %.4f mm\n", nom * 1e3, cal * 1e3);
  EXPECT_LT(cal, kHeldOutFactor * std::sqrt(3.0) * kNoise);
  EXPECT_LT(cal, 0.2 * nom);
}

TEST(RobotCalibration, CorrelatedPairsAndCovariance) {
  const Truth truth = MakeTruth(51);
  Rng rng(52);
  const auto ms = Measure(truth, RandomPoses(truth.nominal, 40, rng), false, kNoise, 0, rng);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = kNoise;
  opt.correlation_threshold = 0.9;
  const auto r = CalibrateRobot(truth.nominal, InitialBaseGuess(truth.nominal, ms), ms, opt);
  ASSERT_EQ(r.covariance.rows(), static_cast<int>(r.free_parameters.size()));
  EXPECT_TRUE(r.covariance.isApprox(r.covariance.transpose()));
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(r.covariance).eigenvalues().minCoeff(), 0.0);
  for (const auto& c : r.correlated) {
    EXPECT_GT(std::abs(c.rho), 0.9);
    EXPECT_LE(std::abs(c.rho), 1.0);
  }
  EXPECT_GT(r.observability, 0.0);
}

TEST(RobotCalibration, PoseSelectionBeatsRandomPoses) {
  const Truth truth = MakeTruth(61);
  Rng rng(62);
  const auto candidates = RandomPoses(truth.nominal, 300, rng);
  RobotCalibrationOptions opt;
  const auto chosen = SelectPoses(truth.nominal, truth.T_meas_base, candidates, 25, false, opt);
  ASSERT_EQ(chosen.size(), 25u);
  EXPECT_EQ(std::set<int>(chosen.begin(), chosen.end()).size(), 25u);
  std::vector<Eigen::VectorXd> sel;
  for (int i : chosen) sel.push_back(candidates[i]);
  const double o_sel = ObservabilityIndex(truth.nominal, truth.T_meas_base, sel, false, opt);
  // Ten disjoint-ish random subsets of the same size (consecutive candidates, which are
  // independent random draws).
  double best_random = 0.0;
  for (int s = 0; s < 10; ++s) {
    std::vector<Eigen::VectorXd> sub(candidates.begin() + 25 * s, candidates.begin() + 25 * (s + 1));
    best_random = std::max(best_random, ObservabilityIndex(truth.nominal, truth.T_meas_base, sub, false, opt));
  }
  std::printf("observability index: selected %.4g, best of 10 random sets %.4g\n", o_sel, best_random);
  EXPECT_GT(o_sel, best_random);
}

TEST(RobotCalibration, ErrorMotionSameInSolverAndModelForBothConventions) {
  // The solver's cost functor and RobotModel's forward kinematics implement the joint
  // error motion separately; with noise-free 6-D measurements of a robot that has it, the
  // fit must reproduce the measurements to rounding through RobotModel, in both DH
  // conventions, and the error-motion terms it estimates must be the injected ones.
  for (const ChainConvention conv : {ChainConvention::kStandard, ChainConvention::kModified}) {
    std::vector<Joint> j(3);
    j[0].d = 0.3;
    j[1].alpha = -std::numbers::pi / 2;
    j[1].a = 0.05;
    j[2].a = 0.4;
    j[2].alpha = 0.3;
    for (auto& x : j) x.lower = -3.0, x.upper = 3.0;
    Truth t;
    t.nominal = RobotModel("em3", conv, j, Pose{Mat3::Identity(), Vec3(0.1, 0.05, 0.05)});
    Eigen::VectorXd em = Eigen::VectorXd::Zero(24);
    for (int k = 0; k < 24; ++k) em[k] = 1e-4 * std::sin(1.7 * k + 0.3);
    t.dh_errors = Eigen::VectorXd::Zero(12);
    t.actual = WithErrorMotionErrors(t.nominal, {0, 2, 0}, em);
    t.T_meas_base = Pose{ExpSO3(Vec3(0.1, 0.2, -0.3)), Vec3(1.0, 0.5, 0.2)};
    Rng rng(41);
    const auto fit = Measure(t, RandomPoses(t.nominal, 80, rng), true, 0.0, 0.0, rng);
    RobotCalibrationOptions opt;
    opt.position_sigma_m = 1e-5;
    opt.rotation_sigma_rad = 1e-5;
    opt.error_motion_harmonics = {0, 2, 0};
    const auto r = CalibrateRobot(t.nominal, t.T_meas_base, fit, opt);
    // Tolerance: the 4 held terms equal DH/tool changes to first order only, so their
    // injected 1e-4 leaves ~1e-8 (second order); a mismatch between the two
    // implementations would leave the error motion's own size, ~1e-4 rad and 5e-5 m.
    const ErrorStats s = Summarize(r.errors_after);
    EXPECT_LT(s.max_position_m, 1e-7) << (conv == ChainConvention::kStandard ? "standard" : "modified");
    EXPECT_LT(*s.max_rotation_rad, 1e-7);
    const ErrorStats s0 = Summarize(r.errors_before);
    EXPECT_GT(s0.max_position_m, 2e-5);
    // 24 terms for joint 2's two harmonics; the first harmonic's tilt and radial pairs
    // hold 4 (a rotating-frame constant, i.e. DH/tool), the rest are estimated.
    const auto names = CalibrationParameterNames(t.nominal, opt);
    ASSERT_EQ(names.size(), 48u);
    int estimated = 0;
    for (int k = 24; k < 48; ++k) estimated += r.parameters[k].fixed ? 0 : 1;
    EXPECT_EQ(estimated, 20);
    const Eigen::Vector3d q(0.3, -1.1, 0.7);
    const RobotModel back = RobotModel::Parse(r.robot.ToYaml(), "em3");
    EXPECT_LT((back.T_base_tool(q).t - r.robot.T_base_tool(q).t).norm(), 1e-12);
  }
}

TEST(RobotCalibration, BadInputNamesWhatIsMissing) {
  const Truth truth = MakeTruth(71);
  Rng rng(72);
  auto ms = Measure(truth, RandomPoses(truth.nominal, 5, rng), false, kNoise, 0, rng);
  RobotCalibrationOptions opt;
  auto expect_error = [&](const std::vector<RobotMeasurement>& m, const std::string& words) {
    try {
      CalibrateRobot(truth.nominal, truth.T_meas_base, m, opt);
      ADD_FAILURE() << "no error, expected one containing '" << words << "'";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  expect_error(ms, "add poses");  // 15 residuals for ~27 parameters
  auto wrong = ms;
  wrong[2].q.conservativeResize(5);
  expect_error(wrong, "measurement 3 has 5 joint values");
  auto out = ms;
  out[1].q[0] = 3.0;  // A1 limit is 155 deg
  expect_error(out, "above its upper limit");
  auto mixed = ms;
  mixed[0].R_meas_tool = Mat3::Identity();
  expect_error(mixed, "orientations for all measurements");
  expect_error({}, "no measurements");
  opt.position_sigma_m = -1;
  expect_error(ms, "position_sigma_m");
  opt = RobotCalibrationOptions();
  opt.fixed = {"A9.d"};
  expect_error(ms, "'A9.d' is not one of");
  // Every parameter held: singular / nothing to do.
  opt = RobotCalibrationOptions();
  opt.estimate_dh = opt.estimate_base = opt.estimate_tool = false;
  expect_error(ms, "every parameter is fixed");
  opt = RobotCalibrationOptions();
  opt.error_motion_harmonics = {1, 1};
  expect_error(ms, "has 2 counts but robot");
  opt.error_motion_harmonics = {0, 0, 0, 0, 0, 12};
  expect_error(ms, "error_motion_harmonics[5] must be in 0..8");
}

TEST(RobotCalibration, PoorPoseSetIsRefusedOrReported) {
  // 40 poses that never move the wrist (A4..A6 at zero): its parameters cannot be told
  // apart from the others there, although spread poses would identify them.
  const Truth truth = MakeTruth(75);
  Rng rng(76);
  auto poses = RandomPoses(truth.nominal, 40, rng);
  for (auto& q : poses) q.tail(3).setZero();
  const auto ms = Measure(truth, poses, false, kNoise, 0, rng);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = kNoise;
  try {
    CalibrateRobot(truth.nominal, InitialBaseGuess(truth.nominal, ms), ms, opt);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("do not identify"), std::string::npos) << w;
    EXPECT_NE(w.find("A5"), std::string::npos) << w;
    EXPECT_NE(w.find("A4 0.0 deg"), std::string::npos) << w;
  }
  opt.require_pose_identifiability = false;
  const auto r = CalibrateRobot(truth.nominal, InitialBaseGuess(truth.nominal, ms), ms, opt);
  EXPECT_GT(r.Fixed().size(), 10u);
  EXPECT_TRUE(r.converged);
}

TEST(RobotCalibration, MeasurementFileRoundTrip) {
  const Truth truth = MakeTruth(81);
  Rng rng(82);
  const auto ms = Measure(truth, RandomPoses(truth.nominal, 4, rng), true, kNoise, 1e-4, rng);
  const auto dir = test::ScratchDir("robot_measurements");
  WriteRobotMeasurements(dir / "m.yaml", ms);
  const auto back = ReadRobotMeasurements(dir / "m.yaml");
  ASSERT_EQ(back.size(), ms.size());
  for (size_t i = 0; i < ms.size(); ++i) {
    EXPECT_TRUE(back[i].q.isApprox(ms[i].q, 1e-15));
    EXPECT_TRUE(back[i].p_meas.isApprox(ms[i].p_meas, 1e-15));
    ASSERT_TRUE(back[i].R_meas_tool);
    EXPECT_LT((*back[i].R_meas_tool - *ms[i].R_meas_tool).norm(), 1e-14);
  }
  {
    std::ofstream f(dir / "bad.yaml");
    f << "measurements:\n  - {q_rad: [0, 0], position_m: [1, 2]}\n";
  }
  try {
    ReadRobotMeasurements(dir / "bad.yaml");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("measurement 1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("position_m must have 3"), std::string::npos) << e.what();
  }
}

// ---- Registration: the paper's two-circle method vs least squares. ----

TEST(Registration, CircleFitRecoversACircle) {
  const Vec3 c(0.3, -0.2, 1.1), n = Vec3(0.2, -0.3, 1.0).normalized();
  const Vec3 e1 = n.cross(Vec3::UnitX()).normalized(), e2 = n.cross(e1);
  std::vector<Vec3> pts;
  for (int k = 0; k < 7; ++k) {
    const double a = 0.3 * k;  // a 1.8 rad arc
    pts.push_back(c + 0.45 * (std::cos(a) * e1 + std::sin(a) * e2));
  }
  const CircleFit f = FitCircle3D(pts);
  EXPECT_LT((f.centre - c).norm(), 1e-12);
  EXPECT_NEAR(f.radius, 0.45, 1e-12);
  EXPECT_NEAR(std::abs(f.normal.dot(n)), 1.0, 1e-12);
  EXPECT_THROW(FitCircle3D({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0)}), InputError);
}

TEST(Registration, CircleMethodAndLeastSquaresBothRecoverTheBase) {
  // The nominal robot (no DH errors: the registration question alone) with noisy
  // measurements; both methods find the base, least squares over all poses better.
  Truth truth = MakeTruth(91);
  truth.actual = truth.nominal;
  constexpr double noise = 0.1e-3;
  Rng rng(92);
  AxisSweep s1, s2;
  s1.axis = 0;
  s2.axis = 1;
  Eigen::VectorXd home(6);
  home << 0, -60 * kDeg, 80 * kDeg, 0, 40 * kDeg, 0;
  for (int k = 0; k < 12; ++k) {
    Eigen::VectorXd q = home;
    q[0] = (-60 + 10 * k) * kDeg;
    s1.q.push_back(q);
    q = home;
    q[1] = (-120 + 8 * k) * kDeg;
    s2.q.push_back(q);
  }
  for (auto* s : {&s1, &s2})
    for (const auto& q : s->q)
      s->p_meas.push_back((truth.T_meas_base * truth.actual.T_base_tool(q)).t +
                          noise * Vec3(rng.Normal(), rng.Normal(), rng.Normal()));
  const CircleRegistration c = RegisterByAxisCircles(truth.nominal, s1, s2);

  const auto ms = Measure(truth, RandomPoses(truth.nominal, 40, rng), false, noise, 0, rng);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = noise;
  const RobotCalibrationResult l = RegisterLeastSquares(truth.nominal, ms, opt);

  const double rot_c = RotationAngle(c.T_meas_base.R, truth.T_meas_base.R);
  const double rot_l = RotationAngle(l.T_meas_base.R, truth.T_meas_base.R);
  const double pos_c = (c.T_meas_base.t - truth.T_meas_base.t).norm();
  const double pos_l = (l.T_meas_base.t - truth.T_meas_base.t).norm();
  std::printf("registration: circles %.4f mm %.5f deg; least squares %.4f mm %.5f deg\n", pos_c * 1e3,
              rot_c / kDeg, pos_l * 1e3, rot_l / kDeg);
  EXPECT_LT(pos_c, 2e-3);
  EXPECT_LT(rot_c, 0.1 * kDeg);
  EXPECT_LT(pos_l, 0.2e-3);
  EXPECT_LT(rot_l, 0.01 * kDeg);
  EXPECT_LT(pos_l, pos_c);
  EXPECT_LT(rot_l, rot_c);
  // Bad sweeps.
  AxisSweep bad = s1;
  bad.q[3][2] += 0.1;
  EXPECT_THROW(RegisterByAxisCircles(truth.nominal, bad, s2), InputError);
  bad = s1;
  bad.p_meas.pop_back();
  EXPECT_THROW(RegisterByAxisCircles(truth.nominal, bad, s2), InputError);
}

// A URDF chain's joint turns about its own axis (here y), not its frame's z: the circle
// registration asks the chain for the axis (it took z for every convention but the
// standard DH table's, and registered a URDF arm with a y joint 90 deg off).
TEST(Registration, AxisCirclesOfAUrdfChainFollowItsAxes) {
  const RobotModel arm = ParseUrdf(R"(<robot name="yarm"><link name="base"/>
    <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.4"/>
      <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="l1"/>
    <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0.2" rpy="0.2 0 0"/>
      <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="l2"/>
    <joint name="j3" type="revolute"><parent link="l2"/><child link="tool"/><origin xyz="0.5 0 0.05"/>
      <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="tool"/>
    </robot>)", "yarm.urdf", {"base", "tool"});
  const Pose T_meas_base{ExpSO3(Vec3(0.1, -0.2, 0.7)), Vec3(1.0, 0.5, -0.3)};
  Rng rng(7);
  AxisSweep s1, s2;
  s1.axis = 0;
  s2.axis = 1;
  for (int k = 0; k < 12; ++k) {
    Eigen::VectorXd q(3);
    q << (-60 + 10 * k) * kDeg, 0.3, -0.5;
    s1.q.push_back(q);
    q << 0.2, (-50 + 8 * k) * kDeg, -0.5;
    s2.q.push_back(q);
  }
  for (auto* s : {&s1, &s2})
    for (const auto& q : s->q)
      s->p_meas.push_back((T_meas_base * arm.T_base_tool(q)).t + 1e-5 * Vec3(rng.Normal(), rng.Normal(), rng.Normal()));
  const CircleRegistration c = RegisterByAxisCircles(arm, s1, s2);
  EXPECT_LT(RotationAngle(c.T_meas_base.R, T_meas_base.R), 0.05 * kDeg);
  EXPECT_LT((c.T_meas_base.t - T_meas_base.t).norm(), 1e-3);
}

}  // namespace
}  // namespace mcms
