// Kalman filters: the paper's per-sensor random-walk filter and eq. 14 fusion, and the
// multi-sensor pose filter, Monte-Carlo consistent (NEES, NIS, prediction NEES inside their
// bands) on a smooth simulated trajectory with asynchronous camera, inclinometer and robot.
#include <numbers>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "core/error.h"
#include "core/random.h"
#include "core/statistics.h"
#include "fusion/kalman.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

constexpr double kPi = std::numbers::pi;

using test::ErrorOf;

// --- (a) the paper's scheme ------------------------------------------------------------

// With Q = 0 the filter is a running mean: x_k = mean(y_1..y_k), P_k = R / k.
TEST(RandomWalkKalman, StaticFilterIsARunningMean) {
  Rng rng(1);
  const Mat3 R = Vec3(1e-8, 2e-8, 4e-8).asDiagonal();
  RandomWalkKalmanFilter f;
  Vec3 sum = Vec3::Zero();
  for (int k = 1; k <= 50; ++k) {
    const Vec3 y(rng.Normal(0, 1e-4), rng.Normal(0, 1e-4), rng.Normal(0, 2e-4));
    sum += y;
    if (k == 1) {
      f.Initialize(y, R);
    } else {
      f.Predict(Mat3::Zero());
      f.Update(y, R);
    }
    EXPECT_LT((f.State() - sum / k).norm(), 1e-15);
    EXPECT_LT((f.Covariance() - R / k).cwiseAbs().maxCoeff(), 1e-22);
  }
  EXPECT_THROW(RandomWalkKalmanFilter().Update(Vec3::Zero(), R), InputError);
  EXPECT_THROW(f.Predict(-Mat3::Identity()), InputError);
}

TEST(RandomWalkKalman, PerSensorFusionUsesCorrectedWeights) {
  const Mat3 Rc = Vec3(0.15e-3, 0.15e-3, 0.15e-3).cwiseAbs2().asDiagonal();
  const Mat3 Rr = Vec3(0.157e-3, 0.087e-3, 0.043e-3).cwiseAbs2().asDiagonal();
  // A filter that must follow a moving state (Q >> R) returns its latest measurement, up to
  // the remaining weight R / (P + Q) ~ 2e-6 of the previous estimate (jumps of ~0.1 m).
  PerSensorKalmanFusion tracking(2, 0.01 * Mat3::Identity());
  Rng rng(2);
  for (int k = 0; k < 5; ++k) {
    const Vec3 yc(rng.Uniform(0, 0.1), rng.Uniform(0, 0.1), rng.Uniform(0, 0.1));
    const Vec3 yr = yc + Vec3(1e-4, -1e-4, 5e-5);
    const auto r = tracking.Step({yc, yr}, {Rc, Rr});
    EXPECT_LT((tracking.Filter(0).State() - yc).norm(), 1e-6);
    const FusedPosition f = FusePositions({PositionMeasurement::FromCovariance("c", yc, Rc),
                                           PositionMeasurement::FromCovariance("r", yr, Rr)});
    EXPECT_LT((r.fused.p - f.p).norm(), 1e-6);
    EXPECT_LT((r.fused.weights[0] + r.fused.weights[1] - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_EQ(std::isnan(r.nis[0]), k == 0);
  }
  EXPECT_THROW(tracking.Step({Vec3::Zero()}, {Rc}), InputError);
  EXPECT_THROW(PerSensorKalmanFusion(0, Mat3::Zero()), InputError);
}

// --- (b) the multi-sensor pose filter ---------------------------------------------------

Mat3 LevelFlange() {
  Mat3 R;
  R << 0, 0, 1, 0, -1, 0, 1, 0, 0;
  return R;
}

// A smooth trajectory drawn from the filter's own constant-velocity model (white
// acceleration), sampled exactly between event times, so that consistency is testable.
struct Truth {
  Pose T;
  Vec3 w, v;
  void Advance(double dt, const PoseKalmanOptions& o, Rng& rng) {
    if (dt <= 0) return;
    for (int k = 0; k < 2; ++k) {
      const double q = k == 0 ? o.angular_acceleration_psd : o.linear_acceleration_psd;
      // Per axis [x; rate] ~ N(0, q [dt^3/3, dt^2/2; dt^2/2, dt]) by its Cholesky factor.
      const double a = std::sqrt(q * dt * dt * dt / 3), b = q * dt * dt / 2 / a, c = std::sqrt(q * dt - b * b);
      Vec3 dx, drate;
      for (int i = 0; i < 3; ++i) {
        const double z1 = rng.Normal(), z2 = rng.Normal();
        dx[i] = a * z1;
        drate[i] = b * z1 + c * z2;
      }
      if (k == 0) {
        T.R = ExpSO3(dx) * ExpSO3(w * dt) * T.R;
        w += drate;
      } else {
        T.t += v * dt + dx;
        v += drate;
      }
    }
  }
};

Vec6 Sample6(Rng& rng, const Mat6& C) {
  const Mat6 L = C.llt().matrixL();
  Vec6 z;
  for (int i = 0; i < 6; ++i) z[i] = rng.Normal();
  return L * z;
}

Mat6 CameraCovariance() {
  Mat6 C = (Vec6() << 0.5e-3, 0.5e-3, 0.5e-3, 0.15e-3, 0.15e-3, 0.15e-3).finished().cwiseAbs2().asDiagonal();
  // A rotation-position correlation, as a target seen from one side gives (rho = 0.5).
  C(1, 3) = C(3, 1) = 0.5 * 0.5e-3 * 0.15e-3;
  return C;
}
Mat6 RobotCovariance() {
  return (Vec6() << 0.3e-3, 0.3e-3, 0.3e-3, 0.157e-3, 0.087e-3, 0.043e-3).finished().cwiseAbs2().asDiagonal();
}

enum class Event { kCamera, kInclinometer, kRobot, kCheck, kLookahead };

std::vector<std::pair<double, Event>> Schedule(double duration, double lookahead) {
  std::vector<std::pair<double, Event>> e;
  for (double t = 0.0031; t < duration; t += 1.0 / 30) e.push_back({t, Event::kCamera});
  for (double t = 0.0070; t < duration; t += 0.02) e.push_back({t, Event::kInclinometer});
  for (double t = 0.0005; t < duration; t += 0.004) e.push_back({t, Event::kRobot});
  for (double t = 0.5; t <= duration + 1e-9; t += 0.5) {
    e.push_back({t, Event::kCheck});
    e.push_back({t + lookahead, Event::kLookahead});
  }
  std::stable_sort(e.begin(), e.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return e;
}

double Nees12(const Truth& x, const PoseKalmanFilter::Prediction& p, const Eigen::Matrix<double, 12, 12>& P) {
  Eigen::Matrix<double, 12, 1> e;
  e << BoxMinus(x.T, p.T), x.w - p.w, x.v - p.v;
  return e.dot(P.ldlt().solve(e));
}

// 40 runs of 3 s. Bands: 99 % two-sided for each checkpoint's NEES summed over runs
// (chi2(12 * runs)) and for each sensor's NIS summed over all its updates (chi2(sum dof));
// a consistent filter's innovations are white, so the sums are chi-square.
TEST(PoseKalman, ConsistentOnAsynchronousSensors) {
  PoseKalmanOptions o;
  o.angular_acceleration_psd = 1e-3;
  o.linear_acceleration_psd = 1e-3;
  o.initial_angular_velocity_sigma = 0.05;
  o.initial_linear_velocity_sigma = 0.05;
  Inclinometer incl;
  incl.R_flange_incl = Eigen::AngleAxisd(kPi / 2, Vec3::UnitY()).toRotationMatrix();
  const Mat6 Cc = CameraCovariance(), Cr = RobotCovariance();
  const Mat6 C0 = (Vec6() << 2e-3, 2e-3, 2e-3, 1e-3, 1e-3, 1e-3).finished().cwiseAbs2().asDiagonal();
  const double duration = 3.0, lookahead = 0.05;
  const auto events = Schedule(duration, lookahead);
  const int runs = 40;
  const int checks = 6;
  std::vector<double> nees(checks, 0.0), nees_ahead(checks, 0.0);
  double nis[3] = {0, 0, 0};
  int nis_dof[3] = {0, 0, 0};
  Rng rng(42);
  for (int run = 0; run < runs; ++run) {
    Truth x;
    x.T = {ExpSO3(Vec3(0.05, -0.05, rng.Uniform(-1, 1))) * LevelFlange(), Vec3(0.9, 0.0, 1.1)};
    x.w = Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * o.initial_angular_velocity_sigma;
    x.v = Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * o.initial_linear_velocity_sigma;
    PoseKalmanFilter kf(o);
    kf.Initialize(0.0, BoxPlus(x.T, Sample6(rng, C0)), C0);
    double t = 0.0;
    int check = 0, ahead = 0;
    PoseKalmanFilter::Prediction pending;
    Eigen::Matrix<double, 12, 12> pending_P;
    for (const auto& [te, type] : events) {
      x.Advance(te - t, o, rng);
      t = te;
      PoseKalmanFilter::UpdateResult r;
      int sensor = -1;
      switch (type) {
        case Event::kCamera:
          r = kf.UpdatePose(t, BoxPlus(x.T, Sample6(rng, Cc)), Cc);
          sensor = 0;
          break;
        case Event::kInclinometer:
          if (const auto reading = incl.Simulate(x.T.R, rng)) {
            r = kf.UpdateInclinometer(t, *reading, incl);
            sensor = 1;
          }
          break;
        case Event::kRobot:
          r = kf.UpdatePose(t, BoxPlus(x.T, Sample6(rng, Cr)), Cr);
          sensor = 2;
          break;
        case Event::kCheck: {
          kf.PropagateTo(t);
          nees[check++] += Nees12(x, kf.Predict(t), kf.Covariance());
          // The prediction lookahead seconds ahead, with its 12x12 covariance from a copy.
          PoseKalmanFilter copy = kf;
          copy.PropagateTo(t + lookahead);
          pending = kf.Predict(t + lookahead);
          pending_P = copy.Covariance();
          EXPECT_LT(BoxMinus(copy.PoseEstimate(), pending.T).norm(), 1e-15);
          break;
        }
        case Event::kLookahead:
          nees_ahead[ahead++] += Nees12(x, pending, pending_P);
          break;
      }
      if (sensor >= 0) {
        nis[sensor] += r.nis;
        nis_dof[sensor] += r.dof;
        EXPECT_TRUE(r.accepted);
      }
    }
  }
  const double lo = ChiSquareQuantile(0.005, 12 * runs), hi = ChiSquareQuantile(0.995, 12 * runs);
  for (int c = 0; c < checks; ++c) {
    std::printf("t = %.1f s: mean NEES %.2f, %.0f ms prediction %.2f (12 expected, 99%% band %.2f .. %.2f)\n",
                0.5 * (c + 1), nees[c] / runs, lookahead * 1e3, nees_ahead[c] / runs, lo / runs, hi / runs);
    EXPECT_GT(nees[c], lo);
    EXPECT_LT(nees[c], hi);
    EXPECT_GT(nees_ahead[c], lo);
    EXPECT_LT(nees_ahead[c], hi);
  }
  const char* names[] = {"camera", "inclinometer", "robot"};
  for (int s = 0; s < 3; ++s) {
    const double nlo = ChiSquareQuantile(0.005, nis_dof[s]), nhi = ChiSquareQuantile(0.995, nis_dof[s]);
    std::printf("%s: mean NIS per dof %.4f (99%% band %.4f .. %.4f, %d dof)\n", names[s], nis[s] / nis_dof[s],
                nlo / nis_dof[s], nhi / nis_dof[s], nis_dof[s]);
    EXPECT_GT(nis[s], nlo) << names[s];
    EXPECT_LT(nis[s], nhi) << names[s];
  }
  EXPECT_GT(nis_dof[1], 0);
}

// The inclinometer sharpens roll and pitch in the filter and leaves yaw to the camera.
TEST(PoseKalman, InclinometerLeavesYawToOtherSensors) {
  PoseKalmanOptions o;
  Inclinometer incl;
  incl.R_flange_incl = Eigen::AngleAxisd(kPi / 2, Vec3::UnitY()).toRotationMatrix();
  const Pose T{LevelFlange(), Vec3(0.9, 0, 1.1)};
  Mat6 Cc = CameraCovariance();
  Cc(1, 3) = Cc(3, 1) = 0.0;
  PoseKalmanFilter camera_only(o), both(o);
  camera_only.Initialize(0.0, T, Cc);
  both.Initialize(0.0, T, Cc);
  for (int k = 1; k <= 60; ++k) {
    const double t = k / 30.0;
    camera_only.UpdatePose(t, T, Cc);
    both.UpdatePose(t, T, Cc);
    both.UpdateInclinometer(t + 0.001, incl.Predict(T.R), incl);
  }
  camera_only.PropagateTo(both.Time());
  const Mat6 Pc = camera_only.PoseCovariance(), Pb = both.PoseCovariance();
  std::printf("rotation sigma (mrad) camera only %.4f %.4f %.4f, with inclinometer %.4f %.4f %.4f\n",
              std::sqrt(Pc(0, 0)) * 1e3, std::sqrt(Pc(1, 1)) * 1e3, std::sqrt(Pc(2, 2)) * 1e3,
              std::sqrt(Pb(0, 0)) * 1e3, std::sqrt(Pb(1, 1)) * 1e3, std::sqrt(Pb(2, 2)) * 1e3);
  EXPECT_LT(Pb(0, 0), 0.5 * Pc(0, 0));
  EXPECT_LT(Pb(1, 1), 0.5 * Pc(1, 1));
  EXPECT_NEAR(Pb(2, 2) / Pc(2, 2), 1.0, 1e-6);
}

TEST(PoseKalman, RobotFkUpdateAndNisGate) {
  const RobotModel robot = RobotModel::Default();
  Eigen::VectorXd q(6);
  q << 0.1, -0.2, 0.3, 0.0, 0.4, 0.2;
  const Pose fk = robot.T_base_tool(q);
  PoseKalmanOptions o;
  o.nis_gate_probability = 0.999;
  PoseKalmanFilter kf(o);
  const Mat6 C0 = (Vec6() << 1e-2, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2).finished().cwiseAbs2().asDiagonal();
  kf.Initialize(0.0, BoxPlus(fk, (Vec6() << 5e-3, 0, -5e-3, 4e-3, 2e-3, -1e-3).finished()), C0);
  PoseKalmanFilter::UpdateResult r;
  for (int k = 1; k <= 250; ++k) r = kf.UpdateRobot(k * 0.004, robot, q, RobotCovariance());
  EXPECT_EQ(r.dof, 6);
  EXPECT_LT(BoxMinus(kf.PoseEstimate(), fk).norm(), 1e-5);
  // A camera frame 10 mm off is refused by the gate and leaves the state alone.
  const Pose before = kf.PoseEstimate();
  Pose off = fk;
  off.t.x() += 0.01;
  const auto g = kf.UpdatePose(1.004, off, CameraCovariance());
  EXPECT_FALSE(g.accepted);
  EXPECT_GT(g.nis, 1000.0);
  EXPECT_LT(BoxMinus(kf.PoseEstimate(), before).norm(), 1e-6);  // only propagation
}

TEST(PoseKalman, TimeOrderAndBadInputs) {
  PoseKalmanFilter kf;
  const Mat6 C = CameraCovariance();
  EXPECT_NE(ErrorOf([&] { kf.UpdatePose(0.0, Pose(), C); }).find("before Initialize"), std::string::npos);
  kf.Initialize(1.0, Pose(), C);
  kf.UpdatePose(1.5, Pose(), C);
  kf.UpdatePose(1.5, Pose(), C);  // equal time stamps are fine
  const std::string late = ErrorOf([&] { kf.UpdatePose(1.2, Pose(), C); });
  EXPECT_NE(late.find("1.200000000 s is earlier than the filter time 1.500000000 s"), std::string::npos) << late;
  EXPECT_THROW(kf.Predict(1.0), InputError);
  EXPECT_THROW(kf.UpdatePose(2.0, Pose(), Mat6::Zero()), InputError);
  EXPECT_THROW(kf.UpdatePose(NAN, Pose(), C), InputError);
  PoseKalmanOptions o;
  o.linear_acceleration_psd = 0.0;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("linear_acceleration_psd"), std::string::npos);
  EXPECT_THROW(PoseKalmanFilter{o}, InputError);
  o = PoseKalmanOptions();
  o.nis_gate_probability = 1.0;
  EXPECT_THROW(PoseKalmanFilter{o}, InputError);
  // Predict does not change the filter.
  const Pose before = kf.PoseEstimate();
  const double t0 = kf.Time();
  kf.Predict(5.0);
  EXPECT_EQ(kf.Time(), t0);
  EXPECT_EQ(BoxMinus(kf.PoseEstimate(), before).norm(), 0.0);
}

}  // namespace
}  // namespace mcms
