// The robot audit (calib/robot_audit.h) over the whole catalog, one thread: a KUKA KR 5 arc
// log of N measurements (N/5 poses x 5 passes over 2 h, anisotropic noise, a hidden
// joint 3 offset), the whole AuditRobot call (nominal fit, residual tests, screening of
// every candidate, full fits, time-blocked cross-validation). The named peer in the same
// process is calib-robot's CalibrateRobot (DH identification) on the same measurements:
// the ratio says what an audit costs beyond one calibration. Not a test: numbers depend
// on the machine.
//   build/bench/bench_robot_audit --benchmark_filter=10000
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "calib/robot_audit.h"
#include "calib/robot_calibration.h"
#include "core/random.h"

namespace mcms {
namespace {

RobotLog Make(int n) {
  Rng rng(11);
  const RobotModel robot = RobotModel::Default();
  const int poses = std::max(4, n / 5);
  std::vector<Eigen::VectorXd> qs;
  const double lo[6] = {-1.2, -1.6, 0.2, -2.5, -1.6, -3.0}, hi[6] = {1.2, 0.4, 2.2, 2.5, 1.6, 3.0};
  for (int i = 0; i < poses; ++i) {
    Eigen::VectorXd q(6);
    for (int j = 0; j < 6; ++j) q[j] = rng.Uniform(lo[j], hi[j]);
    qs.push_back(q);
  }
  const Pose T_meas_base{ExpSO3(Vec3(0.0, 0.0, 2.5)), Vec3(2.0, 0.5, -0.2)};
  const Extension ext{Effect::kJointOffset, 2, 0};
  const double p = 1e-4;
  const double* params[1] = {&p};
  RobotLog log;
  log.has_time = true;
  for (int k = 0; k < n; ++k) {
    RobotLogRow r;
    r.q = qs[k % poses];
    r.time_s = 7200.0 * k / n;
    MeasurementContext c;
    const PoseT<double> F = ExtendedFlangeT<double>(robot, {ext}, params, r.q, c);
    r.p_meas = T_meas_base.R * (F.R * robot.T_flange_tool().t + F.t) + T_meas_base.t +
               1e-3 * Vec3(0.02 * rng.Normal(), 0.03 * rng.Normal(), 0.05 * rng.Normal());
    log.rows.push_back(r);
  }
  return log;
}

void BM_AuditRobot(benchmark::State& state) {
  const RobotLog log = Make(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    const RobotAuditResult r = AuditRobot(RobotModel::Default(), log);
    benchmark::DoNotOptimize(r.report.effects.size());
  }
  state.counters["measurements"] = static_cast<double>(log.rows.size());
}
BENCHMARK(BM_AuditRobot)->Arg(400)->Arg(2000)->Arg(10000)->Unit(benchmark::kSecond)->Iterations(1);

// The peer: one DH calibration of the same log (calib-robot).
void BM_CalibrateRobotPeer(benchmark::State& state) {
  const RobotLog log = Make(static_cast<int>(state.range(0)));
  std::vector<RobotMeasurement> ms(log.rows.size());
  for (size_t i = 0; i < ms.size(); ++i) {
    ms[i].q = log.rows[i].q;
    ms[i].p_meas = log.rows[i].p_meas;
  }
  const RobotModel robot = RobotModel::Default();
  const Pose guess = InitialBaseGuess(robot, ms);
  RobotCalibrationOptions o;
  o.position_sigma_m = 4e-5;
  for (auto _ : state) {
    const RobotCalibrationResult r = CalibrateRobot(robot, guess, ms, o);
    benchmark::DoNotOptimize(r.variance_factor);
  }
}
BENCHMARK(BM_CalibrateRobotPeer)->Arg(400)->Arg(2000)->Arg(10000)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
}  // namespace mcms

BENCHMARK_MAIN();
