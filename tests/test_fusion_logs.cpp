// Fusion of recorded sensor logs (fusion/sensor_logs.h, fusion/log_fusion.h): a synthetic
// round trip through the files. A smooth joint trajectory gives the true flange poses (FK);
// the joint log carries encoder noise plus an absolute-accuracy pose error mapped into the
// joints (J^-1 e), the tracker log T_rig_target with a correlated covariance, the
// inclinometer log tilts with bias and noise. The fused error must be consistent with the
// fused covariance (mean NEES in a band) and smaller than every sensor's own.
#include <numbers>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "core/error.h"
#include "core/random.h"
#include "fusion/log_fusion.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 200;               // camera frames at 10 Hz, from 0.5 s
constexpr double kEncoderSigma = 3e-5;     // rad
constexpr double kAccuracyPos = 2e-5;      // m per axis
constexpr double kAccuracyRot = 2e-5;      // rad per axis
// Mean NEES over the frames must lie in [lo, hi] x 6 (6-dof). For 200 independent frames the
// mean's standard deviation is 6 sqrt(2 / (6 * 200)) = 0.24, so the MOIFA band is ~5 sigma.
constexpr double kMoifaNeesLo = 0.8, kMoifaNeesHi = 1.2;
// The KF's constant-velocity model does not match a smooth sinusoidal motion exactly, and its
// estimates are correlated from frame to frame: a wider band.
constexpr double kKfNeesLo = 0.4, kKfNeesHi = 1.5;
// Rows whose consistency test fails at 1 % significance, as a fraction of all rows.
constexpr double kMaxFailedFraction = 0.05;

std::string N(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

std::string PoseYaml(const Pose& T) {
  const auto q = T.Quaternion();
  return "  translation_m: [" + N(T.t.x()) + ", " + N(T.t.y()) + ", " + N(T.t.z()) + "]\n  quaternion_wxyz: [" +
         N(q.w()) + ", " + N(q.x()) + ", " + N(q.y()) + ", " + N(q.z()) + "]\n";
}

struct Scenario {
  fs::path dir;
  RobotModel robot;
  Pose T_base_rig, T_flange_target;
  Inclinometer incl;
  Mat6 camera_cov_rig;
  Eigen::VectorXd q0, amp, omega, phase;

  Eigen::VectorXd QTrue(double t) const {
    Eigen::VectorXd q = q0;
    for (int j = 0; j < q.size(); ++j) q[j] += amp[j] * std::sin(omega[j] * t + phase[j]);
    return q;
  }
  Pose Truth(double t) const { return robot.T_base_flange(QTrue(t)); }
  static double CameraTime(int m) { return (50 + 10 * m) / 100.0; }
};

// Writes robot.yaml, setup.yaml, joints.csv (100 Hz, rad), incl.csv (50 Hz, deg) and
// poses.csv (10 Hz, with a lost row every 25 frames) into a scratch folder.
// incl_bias_in_data: bias actually present in the readings (the setup says incl.bias).
Scenario MakeScenario(const std::string& name, uint64_t seed, const Vec2& incl_bias_in_data) {
  Scenario s;
  s.dir = test::ScratchDir("fusion_logs_" + name);
  s.robot = RobotModel::Default();
  std::vector<Joint> joints = s.robot.Joints();
  for (auto& j : joints) j.encoder_sigma = kEncoderSigma;
  s.robot = RobotModel("KR5 test", s.robot.Convention(), joints);
  s.robot.Write(s.dir / "robot.yaml");

  s.q0.resize(6);
  s.q0 << 0.1, -0.4, 0.6, 0.2, 0.7, 0.1;
  s.amp = Eigen::VectorXd::Constant(6, 0.12);
  s.omega.resize(6);
  s.omega << 0.31, 0.43, 0.27, 0.52, 0.38, 0.61;
  s.phase.resize(6);
  s.phase << 0.0, 1.0, 2.0, 0.5, 1.5, 2.5;

  s.T_base_rig.R = ExpSO3(Vec3(0.05, -0.02, 0.5));
  s.T_base_rig.t = Vec3(2.0, -1.0, 0.6);
  s.T_flange_target.R = ExpSO3(Vec3(0.17, 0.0, 0.3));
  s.T_flange_target.t = Vec3(0.01, -0.02, 0.12);
  // Sensor axes level at q0: the readings stay near zero over the motion.
  s.incl.R_flange_incl = s.robot.T_base_flange(s.q0).R.transpose();
  s.incl.bias = Vec2(1.0e-3, -5e-4);
  s.incl.sigma = 0.01 * std::numbers::pi / 180.0;
  s.incl.period = 0.02;

  // Camera covariance in the rig frame: 1e-4 rad and 3e-5 m per axis, correlated.
  Vec6 sig;
  sig << 1e-4, 1.2e-4, 0.8e-4, 3e-5, 2.5e-5, 4e-5;
  Mat6 corr = Mat6::Identity();
  corr(0, 4) = corr(4, 0) = 0.5;
  corr(1, 3) = corr(3, 1) = -0.4;
  corr(3, 5) = corr(5, 3) = 0.3;
  s.camera_cov_rig = sig.asDiagonal() * corr * sig.asDiagonal();

  const auto q = s.incl.R_flange_incl;
  {
    std::ofstream y(s.dir / "setup.yaml");
    const Eigen::Quaterniond qi(q);
    y << "# test setup\nrobot: robot.yaml\nT_base_rig:\n" << PoseYaml(s.T_base_rig) << "T_flange_target:\n"
      << PoseYaml(s.T_flange_target) << "inclinometer:\n  quaternion_wxyz: [" << N(qi.w()) << ", " << N(qi.x())
      << ", " << N(qi.y()) << ", " << N(qi.z()) << "]\n  bias_rad: [" << N(s.incl.bias.x()) << ", "
      << N(s.incl.bias.y()) << "]\n  sigma_deg: 0.01\n  period_s: 0.02\nrobot_accuracy:\n  position_sigma_m: ["
      << N(kAccuracyPos) << ", " << N(kAccuracyPos) << ", " << N(kAccuracyPos) << "]\n  orientation_sigma_rad: "
      << N(kAccuracyRot) << "\nkalman:\n  angular_acceleration_psd: 1e-4\n  linear_acceleration_psd: 1e-4\n";
  }

  Rng rng(seed);
  Mat6 acc = Mat6::Zero();
  acc.topLeftCorner<3, 3>() = kAccuracyRot * kAccuracyRot * Mat3::Identity();
  acc.bottomRightCorner<3, 3>() = kAccuracyPos * kAccuracyPos * Mat3::Identity();
  const Mat6 L_acc = acc.llt().matrixL();
  const Mat6 L_cam = s.camera_cov_rig.llt().matrixL();
  const auto normal6 = [&] {
    Vec6 v;
    for (int i = 0; i < 6; ++i) v[i] = rng.Normal();
    return v;
  };
  {
    std::ofstream j(s.dir / "joints.csv");
    j << "time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad\n";
    const int last = (50 + 10 * (kFrames - 1)) + 50;
    for (int k = 0; k <= last; ++k) {
      const double t = k / 100.0;
      const Eigen::VectorXd qt = s.QTrue(t);
      // The absolute-accuracy pose error e, expressed in the joints: FK(q + J^-1 e) ~ BoxPlus(FK(q), e).
      const Eigen::MatrixXd J = s.robot.Jacobian(qt, RobotModel::EndFrame::kFlange);
      Eigen::VectorXd ql = qt + J.partialPivLu().solve(Eigen::VectorXd(L_acc * normal6()));
      for (int i = 0; i < 6; ++i) ql[i] += kEncoderSigma * rng.Normal();
      j << N(t);
      for (int i = 0; i < 6; ++i) j << "," << N(ql[i]);
      j << "\n";
    }
  }
  {
    std::ofstream f(s.dir / "incl.csv");
    f << "time_s,tilt_x_deg,tilt_y_deg\n";
    const int last = (50 + 10 * (kFrames - 1)) / 2 + 25;
    Inclinometer in_data = s.incl;
    in_data.bias = incl_bias_in_data;
    for (int k = 0; k <= last; ++k) {
      const double t = 2 * k / 100.0;
      const auto r = in_data.Simulate(s.Truth(t).R, rng);
      if (!r) continue;
      f << N(t) << "," << N(r->x() * 180 / std::numbers::pi) << "," << N(r->y() * 180 / std::numbers::pi)
        << "\n";
    }
  }
  {
    std::ofstream p(s.dir / "poses.csv");
    p << "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz,balls";
    const char* ax[6] = {"rx", "ry", "rz", "px", "py", "pz"};
    for (auto& a : ax)
      for (auto& b : ax) p << ",cov_" << a << "_" << b;
    p << "\n";
    for (int m = 0; m < kFrames; ++m) {
      const double t = Scenario::CameraTime(m);
      if (m % 25 == 7) {
        p << m << "," << N(t) << ",lost,\"too few balls\",,,,,,,,2";
        for (int i = 0; i < 36; ++i) p << ",";
        p << "\n";
        continue;
      }
      const Pose T_rig_target = s.T_base_rig.Inverse() * s.Truth(t) * s.T_flange_target;
      const Pose meas = BoxPlus(T_rig_target, L_cam * normal6());
      const auto qq = meas.Quaternion();
      p << m << "," << N(t) << ",ok,\"\"," << N(meas.t.x()) << "," << N(meas.t.y()) << "," << N(meas.t.z()) << ","
        << N(qq.w()) << "," << N(qq.x()) << "," << N(qq.y()) << "," << N(qq.z()) << ",5";
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) p << "," << N(s.camera_cov_rig(r, c));
      p << "\n";
    }
  }
  return s;
}

SensorLogs ReadAll(const Scenario& s, const FusionSetup& setup) {
  SensorLogs logs;
  logs.tracker = ReadTrackerLog(s.dir / "poses.csv");
  logs.robot = ReadJointLog(s.dir / "joints.csv", setup.robot);
  logs.inclinometer = ReadInclinometerLog(s.dir / "incl.csv");
  return logs;
}

double Nees(const Pose& truth, const Pose& est, const Mat6& cov) {
  const Vec6 e = BoxMinus(truth, est);
  return e.dot(cov.ldlt().solve(e));
}

struct Rms {
  double sum_pos = 0, sum_rot = 0;
  int n = 0;
  void Add(const Pose& truth, const Pose& est) {
    const Vec6 e = BoxMinus(truth, est);
    sum_pos += e.tail<3>().squaredNorm();
    sum_rot += e.head<3>().squaredNorm();
    ++n;
  }
  double Pos() const { return std::sqrt(sum_pos / n); }
  double Rot() const { return std::sqrt(sum_rot / n); }
};

TEST(FusionLogs, SetupAndLogsAreReadAsWritten) {
  const Scenario s = MakeScenario("read", 1, Vec2(1.0e-3, -5e-4));
  const FusionSetup setup = ReadFusionSetup(s.dir / "setup.yaml");
  EXPECT_EQ(setup.robot.NumJoints(), 6);
  EXPECT_NEAR(setup.robot.Joints()[2].encoder_sigma, kEncoderSigma, 1e-15);
  EXPECT_LT((setup.T_base_rig.t - s.T_base_rig.t).norm(), 1e-12);
  EXPECT_LT(RotationAngle(setup.T_flange_target.R, s.T_flange_target.R), 1e-12);
  EXPECT_NEAR(setup.inclinometer.sigma, s.incl.sigma, 1e-15);
  EXPECT_NEAR(setup.robot_accuracy_covariance(4, 4), kAccuracyPos * kAccuracyPos, 1e-20);
  EXPECT_NEAR(setup.kalman.linear_acceleration_psd, 1e-4, 1e-18);
  const SensorLogs logs = ReadAll(s, setup);
  EXPECT_EQ(logs.tracker.lost_rows, 8);
  EXPECT_EQ(logs.tracker.samples.size(), static_cast<size_t>(kFrames - 8));
  EXPECT_LT((logs.tracker.samples[0].covariance - s.camera_cov_rig).norm(), 1e-20);
  // Interpolation inside the log, absence outside it.
  Eigen::VectorXd q;
  EXPECT_TRUE(logs.robot->Interpolate(0.005, &q));
  EXPECT_LT((q - 0.5 * (logs.robot->samples[0].q + logs.robot->samples[1].q)).norm(), 1e-15);
  EXPECT_FALSE(logs.robot->Interpolate(-0.001, &q));
  EXPECT_FALSE(logs.robot->Interpolate(logs.robot->samples.back().time_s + 0.001, &q));
  // Degrees in the file, radians in memory.
  EXPECT_NEAR(logs.inclinometer->samples[0].reading.x(),
              s.incl.Predict(s.Truth(0).R).x(), 6 * s.incl.sigma);
}

TEST(FusionLogs, CameraCovarianceFollowsTheFixedTransforms) {
  const Scenario s = MakeScenario("jacobian", 2, Vec2(1.0e-3, -5e-4));
  FusionSetup setup = ReadFusionSetup(s.dir / "setup.yaml");
  setup.T_base_rig_covariance.diagonal() << 1e-10, 2e-10, 3e-10, 4e-10, 5e-10, 6e-10;
  const Pose T_rt = s.T_base_rig.Inverse() * s.Truth(1.0) * s.T_flange_target;
  const PoseWithCovariance c = CameraFlangePose(T_rt, s.camera_cov_rig, setup);
  // Numerical Jacobians of T_base_flange w.r.t. the rig-frame error of T_rig_target and
  // the base-frame error of T_base_rig.
  const auto f_cam = [&](const Eigen::VectorXd& d) -> Eigen::VectorXd {
    return BoxMinus(s.T_base_rig * BoxPlus(T_rt, d) * s.T_flange_target.Inverse(), c.T);
  };
  const auto f_reg = [&](const Eigen::VectorXd& d) -> Eigen::VectorXd {
    return BoxMinus(BoxPlus(s.T_base_rig, d) * T_rt * s.T_flange_target.Inverse(), c.T);
  };
  const Eigen::MatrixXd J1 = test::NumericJacobian(f_cam, Vec6::Zero(), 1e-7);
  const Eigen::MatrixXd J2 = test::NumericJacobian(f_reg, Vec6::Zero(), 1e-7);
  const Mat6 expected = J1 * s.camera_cov_rig * J1.transpose() + J2 * setup.T_base_rig_covariance * J2.transpose();
  EXPECT_LT((c.covariance - expected).norm(), 1e-6 * expected.norm());
}

TEST(FusionLogs, SyntheticRoundTripIsConsistentAndBeatsEverySensor) {
  const Scenario s = MakeScenario("roundtrip", 3, Vec2(1.0e-3, -5e-4));
  const FusionSetup setup = ReadFusionSetup(s.dir / "setup.yaml");
  const SensorLogs logs = ReadAll(s, setup);
  const auto moifa = FuseMoifa(logs, setup);
  const auto kf = FuseKalman(logs, setup);
  ASSERT_EQ(moifa.size(), logs.tracker.samples.size());
  ASSERT_EQ(kf.size(), logs.tracker.samples.size());
  WriteFusedPoseCsv(s.dir / "fused.csv", moifa);

  Rms cam, rob, fm, fk;
  double nees_c = 0, nees_r = 0, nees_m = 0, nees_k = 0, tilt_incl = 0, tilt_fused = 0;
  int flagged = 0, nk = 0, total_fail = 0;
  std::map<std::string, int> flags_per_sensor;
  for (size_t i = 0; i < moifa.size(); ++i) {
    const TrackerSample& ts = logs.tracker.samples[i];
    const Pose truth = s.Truth(ts.time_s);
    const PoseWithCovariance c = CameraFlangePose(ts.T_rig_target, ts.covariance, setup);
    cam.Add(truth, c.T);
    nees_c += Nees(truth, c.T, c.covariance);
    Eigen::VectorXd q;
    ASSERT_TRUE(logs.robot->Interpolate(ts.time_s, &q));
    const PoseWithCovariance r = RobotFlangePose(q, setup);
    rob.Add(truth, r.T);
    nees_r += Nees(truth, r.T, r.covariance);
    fm.Add(truth, moifa[i].T_base_flange);
    nees_m += Nees(truth, moifa[i].T_base_flange, moifa[i].covariance);
    // Every sensor is fused, or left out as inconsistent and named (a chance failure of the
    // row's test, at the significance level).
    std::vector<std::string> seen = moifa[i].sensors;
    seen.insert(seen.end(), moifa[i].excluded.begin(), moifa[i].excluded.end());
    std::sort(seen.begin(), seen.end());
    EXPECT_EQ(seen, (std::vector<std::string>{"camera", "inclinometer", "robot"}));
    flagged += moifa[i].flagged.empty() ? 0 : 1;
    total_fail += moifa[i].p_value < setup.consistency_significance ? 1 : 0;
    for (const auto& f : moifa[i].flagged) ++flags_per_sensor[f];
    // Tilt errors: the inclinometer's own reading against the fused orientation's tilt.
    const Vec2 true_tilt = s.incl.Tilt(truth.R);
    for (const auto& r : logs.inclinometer->samples)
      if (std::abs(r.time_s - ts.time_s) < 1e-9) tilt_incl += (r.reading - s.incl.bias - true_tilt).squaredNorm();
    tilt_fused += (s.incl.Tilt(moifa[i].T_base_flange.R) - true_tilt).squaredNorm();
    if (i >= 10) {  // past the filter's start-up
      fk.Add(truth, kf[i].T_base_flange);
      nees_k += Nees(truth, kf[i].T_base_flange, kf[i].covariance);
      ++nk;
    }
  }
  nees_m /= static_cast<double>(moifa.size());
  nees_k /= nk;
  std::printf("mean NEES camera %.2f, robot %.2f\n", nees_c / static_cast<double>(moifa.size()),
              nees_r / static_cast<double>(moifa.size()));
  const double n = static_cast<double>(moifa.size());
  std::printf("position RMS: camera %.2f um, robot %.2f um, MOIFA %.2f um, KF %.2f um\n", 1e6 * cam.Pos(),
              1e6 * rob.Pos(), 1e6 * fm.Pos(), 1e6 * fk.Pos());
  std::printf("rotation RMS: camera %.2f urad, robot %.2f urad, MOIFA %.2f urad, KF %.2f urad\n", 1e6 * cam.Rot(),
              1e6 * rob.Rot(), 1e6 * fm.Rot(), 1e6 * fk.Rot());
  std::printf("tilt RMS: inclinometer %.2f urad, MOIFA %.2f urad; mean NEES MOIFA %.2f, KF %.2f (6 dof); "
              "rows flagged %d of %zu (camera %d, robot %d, inclinometer %d), total test failed %d\n",
              1e6 * std::sqrt(tilt_incl / n), 1e6 * std::sqrt(tilt_fused / n), nees_m, nees_k, flagged, moifa.size(),
              flags_per_sensor["camera"], flags_per_sensor["robot"], flags_per_sensor["inclinometer"], total_fail);
  EXPECT_GT(nees_m, kMoifaNeesLo * 6);
  EXPECT_LT(nees_m, kMoifaNeesHi * 6);
  EXPECT_GT(nees_k, kKfNeesLo * 6);
  EXPECT_LT(nees_k, kKfNeesHi * 6);
  EXPECT_LT(fm.Pos(), std::min(cam.Pos(), rob.Pos()));
  EXPECT_LT(fm.Rot(), std::min(cam.Rot(), rob.Rot()));
  EXPECT_LT(fk.Pos(), std::min(cam.Pos(), rob.Pos()));
  EXPECT_LT(fk.Rot(), std::min(cam.Rot(), rob.Rot()));
  EXPECT_LT(tilt_fused, tilt_incl);
  // At 1 % significance the total test of consistent sensors fails in about 1 % of the rows
  // (binomial over 192 rows: 2 expected); each sensor is flagged about as rarely.
  EXPECT_LT(total_fail, static_cast<int>(kMaxFailedFraction * n));
  for (const auto& [name, count] : flags_per_sensor)
    EXPECT_LT(count, static_cast<int>(kMaxFailedFraction * n)) << name;
}

TEST(FusionLogs, AWrongInclinometerBiasIsFlagged) {
  // The readings carry 3 mrad more bias on x than the setup says: 17 sigma of one reading.
  const Scenario s = MakeScenario("bias", 4, Vec2(4.0e-3, -5e-4));
  const FusionSetup setup = ReadFusionSetup(s.dir / "setup.yaml");
  const SensorLogs logs = ReadAll(s, setup);
  const auto moifa = FuseMoifa(logs, setup);
  int incl_flagged = 0;
  for (const auto& r : moifa)
    for (const auto& f : r.flagged) incl_flagged += f == "inclinometer" ? 1 : 0;
  EXPECT_GT(incl_flagged, static_cast<int>(0.9 * static_cast<double>(moifa.size())));
  EXPECT_LT(moifa[0].p_value, 1e-6);
}

// A joint log frozen at its first reading while the arm moves (a stalled controller stream,
// the second attack's F14): both fusers must leave the robot out. The KF followed the frozen
// robot before, rejecting the camera and the inclinometer: the robot's accepted updates kept
// resetting the others' contradiction streaks, so the state that followed it never restarted.
TEST(FusionLogs, AFrozenJointLogIsLeftOutByBothFusers) {
  const Scenario s = MakeScenario("frozen", 6, Vec2(1.0e-3, -5e-4));
  const FusionSetup setup = ReadFusionSetup(s.dir / "setup.yaml");
  SensorLogs logs = ReadAll(s, setup);
  const Eigen::VectorXd q_first = logs.robot->samples.front().q;
  for (auto& r : logs.robot->samples) r.q = q_first;
  const Pose frozen = setup.robot.T_base_flange(q_first);
  const auto moifa = FuseMoifa(logs, setup);
  const auto kf = FuseKalman(logs, setup);
  ASSERT_EQ(kf.size(), moifa.size());
  const auto has = [](const FusedSample& f, const std::string& x) {
    return std::find(f.excluded.begin(), f.excluded.end(), x) != f.excluded.end();
  };
  int far = 0, moifa_out = 0, kf_out = 0, kf_close = 0, restarts = 0, kf_used_robot = 0;
  for (size_t i = 0; i < kf.size(); ++i) {
    const Pose truth = s.Truth(kf[i].time_s);
    restarts += kf[i].fault.find("restarted") != std::string::npos ? 1 : 0;
    // Rows where the frozen robot is 100 robot-accuracy sigmas off the arm.
    if (BoxMinus(truth, frozen).tail<3>().norm() < 100 * kAccuracyPos) continue;
    ++far;
    moifa_out += has(moifa[i], "robot") ? 1 : 0;
    kf_out += has(kf[i], "robot") ? 1 : 0;
    kf_used_robot +=
        std::find(kf[i].sensors.begin(), kf[i].sensors.end(), "robot") != kf[i].sensors.end() ? 1 : 0;
    kf_close += BoxMinus(truth, kf[i].T_base_flange).tail<3>().norm() < 1e-3 ? 1 : 0;
    if (!has(moifa[i], "robot") || !has(kf[i], "robot"))
      std::printf("row %zu moifa [%s] kf [%s]\n", i, moifa[i].fault.c_str(), kf[i].fault.c_str());
  }
  std::printf("%d of %zu rows with the frozen robot off the arm: robot left out by MOIFA %d, by the KF %d "
              "(KF used it in %d); KF within 1 mm %d; %d rows with a restart\n",
              far, kf.size(), moifa_out, kf_out, kf_used_robot, kf_close, restarts);
  ASSERT_GT(far, static_cast<int>(kf.size()) / 2);
  // MOIFA judges each row alone: where the frozen robot's tilt happens to match the arm's, the
  // inclinometer agrees with both full poses and no single sensor explains the row (it then
  // widens the covariance instead); the KF remembers which one it left out.
  EXPECT_GE(moifa_out, far - 2);
  // The KF restarts once two sensors have each contradicted it twice running (one chance
  // rejection beside a faulty sensor must not restart it): the first camera frame, before the
  // second contradiction, still follows the robot.
  EXPECT_LE(kf_used_robot, 1);
  EXPECT_GE(kf_out, far - 1);
  EXPECT_GE(kf_close, far - 1);
  EXPECT_GE(restarts, 1);
}

TEST(FusionLogs, LogsWithoutTimeOverlapAreRefused) {
  const Scenario s = MakeScenario("overlap", 5, Vec2(1.0e-3, -5e-4));
  const FusionSetup setup = ReadFusionSetup(s.dir / "setup.yaml");
  SensorLogs logs = ReadAll(s, setup);
  for (auto& r : logs.robot->samples) r.time_s += 1000.0;
  try {
    FuseMoifa(logs, setup);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("no time overlap"), std::string::npos) << m;
    EXPECT_NE(m.find("joints.csv covers [1000"), std::string::npos) << m;
    EXPECT_NE(m.find("poses.csv covers [0.5, 20.4]"), std::string::npos) << m;
  }
}

}  // namespace
}  // namespace mcms
