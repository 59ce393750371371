// Robot kinematic identification time (calib/robot_calibration.h), one thread: the KUKA
// KR 5 arc with injected DH, base and tool errors, N noisy 3-D or 6-D measurements, the
// whole CalibrateRobot call (identifiability analysis, LM solve, covariance). Not a test:
// numbers depend on the machine.
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "calib/robot_calibration.h"
#include "core/random.h"

namespace mcms {
namespace {

struct Problem {
  RobotModel nominal;
  Pose guess;
  std::vector<RobotMeasurement> ms;
};

Problem Make(int n, bool six_dof) {
  Rng rng(7);
  Problem p;
  p.nominal = RobotModel::Default();
  p.nominal.SetT_flange_tool(Pose{Mat3::Identity(), Vec3(0.02, -0.01, 0.15)});
  Eigen::VectorXd dh(4 * p.nominal.NumJoints());
  for (int i = 0; i < dh.size(); ++i) dh[i] = (i % 4 == 0 || i % 4 == 3) ? 8.7e-4 : 5e-4;
  RobotModel actual = WithGeometryErrors(p.nominal, dh);
  actual.SetT_flange_tool(Pose{ExpSO3(Vec3(0.005, -0.003, 0.004)), Vec3(0.021, -0.0107, 0.1508)});
  const Pose T_meas_base{ExpSO3(Vec3(0.2, -0.1, 2.8)), Vec3(2.5, 0.3, -0.4)};
  for (int k = 0; k < n; ++k) {
    Eigen::VectorXd q(6);
    for (int i = 0; i < 6; ++i) {
      const Joint& j = p.nominal.Joints()[i];
      const double lo = std::max(j.lower, -2.6), hi = std::min(j.upper, 2.6);
      q[i] = rng.Uniform(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo));
    }
    const Pose T = T_meas_base * actual.T_base_tool(q);
    RobotMeasurement m;
    m.q = q;
    m.p_meas = T.t + 5e-5 * Vec3(rng.Normal(), rng.Normal(), rng.Normal());
    if (six_dof) m.R_meas_tool = ExpSO3(1e-4 * Vec3(rng.Normal(), rng.Normal(), rng.Normal())) * T.R;
    p.ms.push_back(m);
  }
  p.guess = InitialBaseGuess(p.nominal, p.ms);
  return p;
}

void BM_CalibrateRobot(benchmark::State& state) {
  const Problem p = Make(static_cast<int>(state.range(0)), state.range(1) != 0);
  RobotCalibrationOptions opt;
  opt.position_sigma_m = 5e-5;
  opt.rotation_sigma_rad = 1e-4;
  for (auto _ : state) {
    const RobotCalibrationResult r = CalibrateRobot(p.nominal, p.guess, p.ms, opt);
    benchmark::DoNotOptimize(r.variance_factor);
  }
  state.SetLabel(state.range(1) ? "6-D" : "3-D");
}
BENCHMARK(BM_CalibrateRobot)->Args({100, 0})->Args({1000, 0})->Args({1000, 1})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace mcms

BENCHMARK_MAIN();
