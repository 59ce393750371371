// Fusion throughput, one thread: 3-sensor 6-DOF MOIFA (camera, robot, inclinometer) and the
// multi-sensor pose Kalman filter's updates. Not a test: numbers depend on the machine.
#include <numbers>
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "core/random.h"
#include "fusion/kalman.h"
#include "fusion/moifa.h"

namespace mcms {
namespace {

struct Scene {
  Pose truth;
  Inclinometer incl;
  Mat6 Cc, Cr;
  std::vector<PoseMeasurement> cams, robs, incs;
  Scene() {
    Mat3 R;
    R << 0, 0, 1, 0, -1, 0, 1, 0, 0;  // KR 5 arc flange at q = 0
    truth = {R, Vec3(0.9, 0.0, 1.1)};
    incl.R_flange_incl = Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitY()).toRotationMatrix();
    Cc = (Vec6() << 5e-4, 5e-4, 5e-4, 1.5e-4, 1.5e-4, 1.5e-4).finished().cwiseAbs2().asDiagonal();
    Cr = (Vec6() << 3e-4, 3e-4, 3e-4, 1.57e-4, 0.87e-4, 0.43e-4).finished().cwiseAbs2().asDiagonal();
    Rng rng(1);
    const auto noise = [&](const Mat6& C) {
      Vec6 n;
      for (int i = 0; i < 6; ++i) n[i] = std::sqrt(C(i, i)) * rng.Normal();
      return n;
    };
    for (int k = 0; k < 1024; ++k) {
      cams.push_back(PoseMeasurement::FromCovariance("camera", BoxPlus(truth, noise(Cc)), Cc));
      robs.push_back(PoseMeasurement::FromCovariance("robot", BoxPlus(truth, noise(Cr)), Cr));
      incs.push_back(PoseMeasurement::FromOrientation(
          "inclinometer", incl.Constraint(*incl.Simulate(truth.R, rng), cams.back().T_ref.R)));
    }
  }
};

const Scene& TheScene() {
  static const Scene s;
  return s;
}

// Fused poses per second: FusePoses on prebuilt camera, robot and inclinometer measurements.
void BM_Moifa3SensorPose(benchmark::State& state) {
  const Scene& s = TheScene();
  FusePosesOptions o;
  o.iterations = static_cast<int>(state.range(0));
  size_t k = 0;
  for (auto _ : state) {
    const size_t i = k++ % s.cams.size();
    benchmark::DoNotOptimize(FusePoses({s.cams[i], s.robs[i], s.incs[i]}, o));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Moifa3SensorPose)->Arg(1)->Arg(2);

void BM_KalmanPoseUpdate(benchmark::State& state) {
  const Scene& s = TheScene();
  PoseKalmanFilter kf;
  kf.Initialize(0.0, s.truth, s.Cc);
  double t = 0.0;
  size_t k = 0;
  for (auto _ : state) {
    t += 0.004;
    benchmark::DoNotOptimize(kf.UpdatePose(t, s.robs[k++ % s.robs.size()].T_ref, s.Cr));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_KalmanPoseUpdate);

void BM_KalmanInclinometerUpdate(benchmark::State& state) {
  const Scene& s = TheScene();
  PoseKalmanFilter kf;
  kf.Initialize(0.0, s.truth, s.Cc);
  double t = 0.0;
  for (auto _ : state) {
    t += 0.02;
    benchmark::DoNotOptimize(kf.UpdateInclinometer(t, Vec2(1e-4, -1e-4), s.incl));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_KalmanInclinometerUpdate);

void BM_KalmanRobotUpdate(benchmark::State& state) {
  const Scene& s = TheScene();
  const RobotModel robot = RobotModel::Default();
  Eigen::VectorXd q(6);
  q << 0.1, -0.2, 0.3, 0.0, 0.4, 0.2;
  PoseKalmanFilter kf;
  kf.Initialize(0.0, robot.T_base_tool(q), s.Cr);
  double t = 0.0;
  for (auto _ : state) {
    t += 0.004;
    benchmark::DoNotOptimize(kf.UpdateRobot(t, robot, q, s.Cr));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_KalmanRobotUpdate);

}  // namespace
}  // namespace mcms

BENCHMARK_MAIN();
