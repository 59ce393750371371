// The one fusion path (fusion/stream_fusion.h) per window, and the writers of the logs it
// reads (fusion/log_fusion.h). A robot stands still in each of 40 windows; its kinematic
// error is one draw per window (systematic: the same at every reading there), the encoders,
// the camera frames and the inclinometer add independent noise. MOIFA and the static KF must
// both be consistent with the truth, and the KF, which sees every robot reading, must not
// count the robot's one systematic error once per reading.
#include <numbers>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <Eigen/Cholesky>

#include "core/error.h"
#include "core/io.h"
#include "core/random.h"
#include "fusion/log_fusion.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

constexpr int kWindows = 40;
constexpr double kWindowS = 2.0, kGapS = 1.0;   // dwell, then a move
constexpr double kCameraHz = 4.0, kRobotHz = 50.0;

Vec6 Draw(const Mat6& C, Rng& rng) {
  Vec6 z;
  for (int i = 0; i < 6; ++i) z[i] = rng.Normal();
  return Mat6(C.llt().matrixL()) * z;
}

struct Static {
  SensorLogs logs;
  FusionSetup setup;
  std::vector<FusionWindow> windows;
  std::vector<Pose> truth;  // T_base_flange per window
};

Static MakeStatic(uint64_t seed) {
  Rng rng(seed);
  Static s;
  s.setup.robot = RobotModel::Default();
  s.setup.robot.SetT_flange_tool(Pose::Identity());
  s.setup.T_base_rig = Pose{ExpSO3(Vec3(0.02, -0.01, 0.6)), Vec3(1.8, -0.9, 0.4)};
  s.setup.T_flange_target = Pose{ExpSO3(Vec3(0.1, 0.0, 0.2)), Vec3(0.01, 0.0, 0.1)};
  s.setup.robot_accuracy_covariance.diagonal() << 4e-10, 4e-10, 4e-10, 9e-10, 9e-10, 9e-10;
  s.setup.kalman.angular_acceleration_psd = 1e-16;
  s.setup.kalman.linear_acceleration_psd = 1e-16;
  s.setup.kalman.initial_angular_velocity_sigma = 1e-10;
  s.setup.kalman.initial_linear_velocity_sigma = 1e-10;
  Vec6 sig;
  sig << 1e-4, 1.2e-4, 0.8e-4, 3e-5, 2.5e-5, 4e-5;
  const Mat6 camera_cov = Mat6(sig.cwiseAbs2().asDiagonal());
  Eigen::VectorXd q0(6);
  q0 << 0.1, -0.4, 0.6, 0.2, 0.7, 0.1;
  s.setup.inclinometer.R_flange_incl = s.setup.robot.T_base_flange(q0).R.transpose();
  s.logs.tracker.source = "test camera";
  s.logs.robot = JointLog{};
  s.logs.inclinometer = InclinometerLog{};
  int frame = 0;
  for (int w = 0; w < kWindows; ++w) {
    const double t0 = w * (kWindowS + kGapS), t1 = t0 + kWindowS;
    s.windows.push_back({t0, t1});
    Eigen::VectorXd q = q0;
    for (int j = 0; j < 6; ++j) q[j] += rng.Uniform(-0.08, 0.08);
    // The robot's own estimate is FK(q); the truth differs by one accuracy draw.
    const Pose truth = BoxPlus(s.setup.robot.T_base_flange(q), Draw(s.setup.robot_accuracy_covariance, rng));
    s.truth.push_back(truth);
    const Pose T_rig_target = s.setup.T_base_rig.Inverse() * truth * s.setup.T_flange_target;
    for (int k = 0; k < kWindowS * kCameraHz; ++k, ++frame) {
      const double t = t0 + k / kCameraHz;
      TrackerSample c;
      c.frame = frame;
      c.time_s = t;
      c.T_rig_target = BoxPlus(T_rig_target, Draw(camera_cov, rng));
      c.covariance = camera_cov;
      s.logs.tracker.samples.push_back(c);
    }
    for (int k = 0; k < kWindowS * kRobotHz; ++k) {
      const double t = t0 + k / kRobotHz;
      Eigen::VectorXd qe = q;
      for (int j = 0; j < 6; ++j) qe[j] += rng.Normal(0, s.setup.robot.Joints()[j].encoder_sigma);
      s.logs.robot->samples.push_back({t, 0, qe});
    }
    for (int k = 0; k * s.setup.inclinometer.period < kWindowS - 1e-9; ++k)
      if (const auto r = s.setup.inclinometer.Simulate(truth.R, rng))
        s.logs.inclinometer->samples.push_back({t0 + k * s.setup.inclinometer.period, 0, *r});
  }
  return s;
}

double Nees(const FusedSample& f, const Pose& truth) {
  const Vec6 e = BoxMinus(f.T_base_flange, truth);
  return e.dot(f.covariance.ldlt().solve(e));
}

TEST(StreamFusion, WindowsGiveConsistentMoifaAndStaticKf) {
  const Static s = MakeStatic(11);
  const auto moifa = FuseMoifa(s.logs, s.setup, s.windows);
  const auto kf = FuseKalman(s.logs, s.setup, s.windows);
  ASSERT_EQ(moifa.size(), static_cast<size_t>(kWindows));
  ASSERT_EQ(kf.size(), static_cast<size_t>(kWindows));
  double nm = 0, nk = 0, trace_ratio = 0;
  for (int w = 0; w < kWindows; ++w) {
    EXPECT_EQ(moifa[w].frame, w);
    EXPECT_EQ(kf[w].frame, w);
    EXPECT_EQ(moifa[w].time_s, s.windows[w].end_s);
    EXPECT_EQ(moifa[w].sensors, (std::vector<std::string>{"camera", "robot", "inclinometer"}));
    EXPECT_EQ(kf[w].sensors, (std::vector<std::string>{"camera", "robot", "inclinometer"}));
    nm += Nees(moifa[w], s.truth[w]) / kWindows;
    nk += Nees(kf[w], s.truth[w]) / kWindows;
    trace_ratio += kf[w].covariance.bottomRightCorner<3, 3>().trace() /
                   moifa[w].covariance.bottomRightCorner<3, 3>().trace() / kWindows;
  }
  // 6-dof NEES averaged over 40 windows: standard deviation of the mean 6 sqrt(2 / 240) = 0.55.
  EXPECT_GT(nm, 6 - 3 * 0.55);
  EXPECT_LT(nm, 6 + 3 * 0.55);
  EXPECT_GT(nk, 6 - 3 * 0.55);
  EXPECT_LT(nk, 6 + 3 * 0.55);
  // The KF holds the robot's accuracy once per window, as MOIFA does: had it counted it once
  // per reading (100 per window), its position variance would be far below MOIFA's.
  EXPECT_GT(trace_ratio, 0.8);
  EXPECT_LT(trace_ratio, 1.25);
}

TEST(StreamFusion, WindowMoifaIsTheEpochFusionOfTheWindowsMeasurements) {
  const Static s = MakeStatic(12);
  const auto moifa = FuseMoifa(s.logs, s.setup, s.windows);
  const WindowMeasurements m = MeasureWindow(s.logs, s.setup, s.windows[3]);
  EXPECT_EQ(m.camera_frames, static_cast<int>(kWindowS * kCameraHz));
  EXPECT_EQ(m.robot_readings, static_cast<int>(kWindowS * kRobotHz));
  ASSERT_TRUE(m.camera && m.robot && m.inclinometer);
  const EpochFusion e = FuseEpoch({PoseMeasurement::FromCovariance("camera", m.camera->T, m.camera->covariance),
                                   PoseMeasurement::FromCovariance("robot", m.robot->T, m.robot->covariance)},
                                  m.inclinometer, ConsistencyOptions{});
  EXPECT_LT(BoxMinus(moifa[3].T_base_flange, e.fused.T).norm(), 1e-15);
  EXPECT_EQ(moifa[3].covariance, e.fused.covariance);
  EXPECT_EQ(moifa[3].p_value, e.consistency.p_value);
  // The mean joint reading's encoder covariance shrinks with the readings, the accuracy does not.
  const Mat6 one = RobotFlangePose(s.logs.robot->samples[3 * 100 + 5].q, s.setup).covariance;
  EXPECT_LT(m.robot->covariance.trace(), one.trace());
  EXPECT_GT(m.robot->covariance.trace(), s.setup.robot_accuracy_covariance.trace());
}

// Faults per window (issue 14): a robot joint offset over a whole dwell, a glitch in the
// window's first camera frame (the KF starts on it, so it must restart), inclinometer readings
// beyond its range. Each is named and left out, and the row's covariance covers its error.
TEST(StreamFusion, FaultsInAWindowAreLeftOutAndNamed) {
  Static s = MakeStatic(15);
  const auto in = [&](double t, int w) { return t >= s.windows[w].start_s && t < s.windows[w].end_s; };
  for (auto& r : s.logs.robot->samples)
    if (in(r.time_s, 5)) r.q[1] += 0.5 * std::numbers::pi / 180.0;
  for (auto& c : s.logs.tracker.samples)
    if (c.time_s == s.windows[9].start_s)
      c.T_rig_target = BoxPlus(c.T_rig_target, (Vec6() << 3e-3, 0, 0, 2e-3, 0, 0).finished());
  for (auto& r : s.logs.inclinometer->samples)
    if (in(r.time_s, 12)) r.reading = Vec2(1.4, 0.0);  // 80 deg on a 30 deg sensor
  const auto moifa = FuseMoifa(s.logs, s.setup, s.windows);
  const auto kf = FuseKalman(s.logs, s.setup, s.windows);
  ASSERT_EQ(moifa.size(), static_cast<size_t>(kWindows));
  ASSERT_EQ(kf.size(), static_cast<size_t>(kWindows));
  const auto has = [](const FusedSample& f, const std::string& x) {
    return std::find(f.excluded.begin(), f.excluded.end(), x) != f.excluded.end();
  };
  EXPECT_TRUE(has(moifa[5], "robot")) << moifa[5].fault;
  EXPECT_TRUE(has(kf[5], "robot")) << kf[5].fault;
  EXPECT_TRUE(has(moifa[9], "camera")) << moifa[9].fault;
  EXPECT_NE(kf[9].fault.find("restarted"), std::string::npos) << kf[9].fault;
  EXPECT_TRUE(has(kf[9], "camera")) << kf[9].fault;
  EXPECT_TRUE(has(moifa[12], "inclinometer")) << moifa[12].fault;
  EXPECT_TRUE(has(kf[12], "inclinometer")) << kf[12].fault;
  EXPECT_NE(moifa[12].fault.find("beyond its range"), std::string::npos) << moifa[12].fault;
  for (int w : {5, 9, 12})
    std::printf("window %d\n  moifa: excluded %zu, fault: %s\n  kf: excluded %zu, fault: %s\n", w,
                moifa[w].excluded.size(), moifa[w].fault.c_str(), kf[w].excluded.size(), kf[w].fault.c_str());
  const double q999 = 22.46;  // chi-square 6 dof, 99.9 %
  double nm = 0, nk = 0;
  for (int w : {5, 9, 12}) {
    EXPECT_LT(Nees(moifa[w], s.truth[w]), q999) << w << " " << moifa[w].fault;
    EXPECT_LT(Nees(kf[w], s.truth[w]), q999) << w << " " << kf[w].fault;
  }
  for (int w = 0; w < kWindows; ++w) {
    nm += Nees(moifa[w], s.truth[w]) / kWindows;
    nk += Nees(kf[w], s.truth[w]) / kWindows;
  }
  EXPECT_LT(nm, 6 + 3 * 0.55);
  EXPECT_LT(nk, 6 + 3 * 0.55);
}

TEST(StreamFusion, BadWindowsAreRefused) {
  const Static s = MakeStatic(13);
  EXPECT_THROW(FuseMoifa(s.logs, s.setup, {{1.0, 1.0}}), InputError);
  EXPECT_THROW(FuseKalman(s.logs, s.setup, {{0.0, 2.0}, {1.5, 3.0}}), InputError);
  EXPECT_THROW(FuseEpoch({}, std::nullopt, ConsistencyOptions{}), InputError);
}

TEST(StreamFusion, WrittenLogsReadBackExactly) {
  const fs::path d = test::ScratchDir("fusion_stream_roundtrip");
  Static s = MakeStatic(14);
  s.setup.T_base_rig_covariance.diagonal() << 1e-10, 1e-10, 1e-10, 4e-10, 4e-10, 4e-10;
  s.setup.robot_accuracy_covariance(0, 4) = s.setup.robot_accuracy_covariance(4, 0) = 1e-10;
  s.setup.consistency_significance = 0.05;
  WriteFusionSetup(d / "setup.yaml", s.setup);
  WriteJointLog(d / "joints.csv", *s.logs.robot, s.setup.robot);
  WriteInclinometerLog(d / "incl.csv", *s.logs.inclinometer);
  WriteFusionWindows(d / "windows.csv", s.windows);

  const FusionSetup r = ReadFusionSetup(d / "setup.yaml");
  EXPECT_LT(BoxMinus(r.T_base_rig, s.setup.T_base_rig).norm(), 1e-15);
  EXPECT_LT(BoxMinus(r.T_flange_target, s.setup.T_flange_target).norm(), 1e-15);
  EXPECT_LT((r.T_base_rig_covariance - s.setup.T_base_rig_covariance).norm(), 1e-24);
  EXPECT_EQ(r.robot_accuracy_covariance, s.setup.robot_accuracy_covariance);
  EXPECT_LT((r.inclinometer.R_flange_incl - s.setup.inclinometer.R_flange_incl).norm(), 1e-15);
  EXPECT_EQ(r.inclinometer.sigma, s.setup.inclinometer.sigma);
  EXPECT_EQ(r.kalman.initial_linear_velocity_sigma, 1e-10);
  EXPECT_EQ(r.kalman.angular_acceleration_psd, 1e-16);
  EXPECT_EQ(r.consistency_significance, 0.05);
  EXPECT_EQ(r.robot.Name(), s.setup.robot.Name());

  const JointLog j = ReadJointLog(d / "joints.csv", r.robot);
  ASSERT_EQ(j.samples.size(), s.logs.robot->samples.size());
  for (size_t i = 0; i < j.samples.size(); ++i) {
    EXPECT_EQ(j.samples[i].time_s, s.logs.robot->samples[i].time_s);
    EXPECT_EQ(j.samples[i].q, s.logs.robot->samples[i].q);
  }
  const InclinometerLog in = ReadInclinometerLog(d / "incl.csv");
  ASSERT_EQ(in.samples.size(), s.logs.inclinometer->samples.size());
  EXPECT_EQ(in.samples.back().reading, s.logs.inclinometer->samples.back().reading);
  const auto w = ReadFusionWindows(d / "windows.csv");
  ASSERT_EQ(w.size(), s.windows.size());
  EXPECT_EQ(w[7].start_s, s.windows[7].start_s);
  EXPECT_EQ(w[7].end_s, s.windows[7].end_s);

  // An anisotropic registration covariance has no place in the format: refused, not rounded.
  s.setup.T_base_rig_covariance(1, 1) *= 2;
  EXPECT_THROW(WriteFusionSetup(d / "bad.yaml", s.setup), InputError);
}

TEST(StreamFusion, BadAccuracyCovariancesAndWindowFilesAreRefused) {
  const std::string frames =
      "T_base_rig:\n  translation_m: [0, 0, 0]\n  quaternion_wxyz: [1, 0, 0, 0]\n"
      "T_flange_target:\n  translation_m: [0, 0, 0.1]\n  quaternion_wxyz: [1, 0, 0, 0]\n";
  const auto setup = [&](const std::string& accuracy) {
    return ParseFusionSetup(frames + "robot_accuracy:\n" + accuracy, "test.yaml", ".");
  };
  std::string diag = "  covariance: [";
  for (int i = 0; i < 36; ++i) diag += std::string(i ? ", " : "") + (i % 7 == 0 ? "1e-8" : "0");
  EXPECT_EQ(setup(diag + "]\n").robot_accuracy_covariance, Mat6(1e-8 * Mat6::Identity()));
  const auto message = [&](const std::string& accuracy) {
    try {
      setup(accuracy);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("  covariance: [1, 2, 3]\n").find("36 numbers"), std::string::npos);
  std::string asym = diag;
  asym.replace(asym.find("0,"), 1, "1e-9");  // entry (0, 1) without (1, 0)
  EXPECT_NE(message(asym + "]\n").find("symmetric"), std::string::npos);
  std::string negative = diag;
  negative.replace(negative.find("1e-8"), 4, "-1e-8");
  EXPECT_NE(message(negative + "]\n").find("positive semi-definite"), std::string::npos);
  EXPECT_NE(message(diag + "]\n  orientation_sigma_rad: 1e-4\n").find("not both"), std::string::npos);
  // Issue 53: an inclinometer sigma of 1e300 rad is no tilt sensor.
  EXPECT_NE(message(diag + "]\ninclinometer:\n  sigma_rad: 1e300\n").find("at most 0.1 rad: is it in another unit?"),
            std::string::npos);
  EXPECT_EQ(message(diag + "]\ninclinometer:\n  sigma_rad: 1e-4\n"), "no error");

  const fs::path d = test::ScratchDir("fusion_stream_windows");
  const auto windows_error = [&](const std::string& text) {
    WriteFileAtomically(d / "w.csv", [&](std::ostream& o) { o << text; });
    try {
      ReadFusionWindows(d / "w.csv");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(windows_error("start_s,end_s\n0,1\n2,2\n").find("line 3"), std::string::npos);
  EXPECT_NE(windows_error("start_s,end_s\n0,1\n0.5,2\n").find("must not overlap"), std::string::npos);
  EXPECT_NE(windows_error("start_s,end_s\n").find("no data rows"), std::string::npos);
  EXPECT_NE(windows_error("start,end_s\n0,1\n").find("start_s"), std::string::npos);
}

}  // namespace
}  // namespace mcms
