// The robot audit (audit/robot_audit.h) over the whole catalog, one thread: a KUKA KR 5 arc
// log of N measurements (N/5 poses x 5 passes over 2 h, anisotropic noise) as a real robot
// gives it: every DH parameter a little off (0.05 mm, 5e-5 rad), the arm's own weight on
// compliant joints 2 and 3 and a hidden joint 3 offset; the whole AuditRobot call
// (nominal fit, residual tests, one Jacobian of every candidate, geometry first, the
// catalog confirmed on top of the geometry, time-blocked cross-validation, pruning). The
// named peer in the same process is calib-robot's CalibrateRobot (DH identification) on
// the same measurements: the ratio says what an audit costs beyond one calibration. Not a
// test: numbers depend on the machine.
// The real TIAGo (../shared/data/tiago-mocap, skipped without it): loading its 89-link URDF
// (peer: reading the same file's text alone), and the whole audit of 2021-11-30 with
// 2021-11-26 scored frozen (--validate), as `mcms audit robot` runs them.
//   build/bench/bench_robot_audit --benchmark_filter=10000
//   build/bench/bench_robot_audit --benchmark_filter=Tiago
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include <cstdlib>
#include <filesystem>

#include "audit/robot_audit.h"
#include "calib/robot_calibration.h"
#include "core/io.h"
#include "core/random.h"
#include "model/urdf.h"
#include "tests/robot_logs.h"

namespace mcms {
namespace {

// The KR 5 arc with its links' masses (the arm's weight on its compliant joints).
const RobotModel& Massed() {
  static const RobotModel massed = [] {
    std::vector<Joint> j = RobotModel::Default().Joints();
    const double m[6] = {25.0, 18.0, 12.0, 4.0, 2.0, 0.5};
    for (int k = 0; k < 6; ++k) j[k].mass_kg = m[k];
    return RobotModel::Default().WithJoints(j);
  }();
  return massed;
}

RobotLog Make(int n) {
  const RobotModel& massed = Massed();
  test::RobotLogSpec spec;
  spec.poses = std::max(4, n / 5);
  spec.repeats = 5;
  spec.dh_length_sigma_m = 0.05e-3;
  spec.dh_angle_sigma_rad = 5e-5;
  spec.masses = &massed;
  spec.compliance = {0, 1.5e-6, 2.5e-6, 0, 0, 0};
  return test::MakeRobotLog(RobotModel::Default(), 11, {{{Effect::kJointOffset, 2, 0}, {1e-4}}}, spec);
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

// Issue 51: a user's arm of 1,000 distinct postures (a laser tracker's calibration run: every
// DH term off, the arm's weight, a hidden offset) audited with 20 other postures scored
// frozen (--validate), as `mcms audit robot LOG --validate OTHER` runs it; the goal is under
// 30 s on one core.
void BM_AuditRobot1000PosturesWithValidate(benchmark::State& state) {
  const RobotModel& massed = Massed();
  test::RobotLogSpec spec;
  spec.poses = 1020;
  spec.repeats = 1;
  spec.dh_length_sigma_m = 0.05e-3;
  spec.dh_angle_sigma_rad = 5e-5;
  spec.masses = &massed;
  spec.compliance = {0, 1.5e-6, 2.5e-6, 0, 0, 0};
  const RobotLog all = test::MakeRobotLog(RobotModel::Default(), 12, {{{Effect::kJointOffset, 2, 0}, {1e-4}}}, spec);
  RobotLog fit = all, other = all;
  fit.rows.assign(all.rows.begin(), all.rows.begin() + 1000);
  other.rows.assign(all.rows.begin() + 1000, all.rows.end());
  other.source = "other.csv";
  for (auto _ : state) {
    const RobotAuditResult r = AuditRobot(RobotModel::Default(), fit, {}, {other});
    benchmark::DoNotOptimize(r.report.effects.size());
  }
  state.counters["measurements"] = static_cast<double>(fit.rows.size());
}
BENCHMARK(BM_AuditRobot1000PosturesWithValidate)->Unit(benchmark::kSecond)->Iterations(1);

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

// The real TIAGo's folder, or empty when the data is not here.
std::filesystem::path Tiago() {
  const char* env = std::getenv("MCMS_DATA_DIR");
  const std::filesystem::path root =
      env ? std::filesystem::path(env) : std::filesystem::path(MCMS_SOURCE_DIR) / ".." / "shared" / "data";
  const auto d = root / "tiago-mocap";
  return std::filesystem::is_directory(d) ? d : std::filesystem::path();
}

void BM_LoadTiagoUrdf(benchmark::State& state) {
  const auto d = Tiago();
  if (d.empty()) {
    state.SkipWithError("real data not present (../shared/data/tiago-mocap)");
    return;
  }
  for (auto _ : state) {
    const RobotModel r = ReadUrdf(d / "tiago_48_hey5.urdf", {"", "wrist_ft_tool_link"});
    benchmark::DoNotOptimize(r.NumJoints());
  }
}
BENCHMARK(BM_LoadTiagoUrdf)->Unit(benchmark::kMillisecond);

// The peer: reading the URDF's text alone.
void BM_ReadTiagoUrdfTextPeer(benchmark::State& state) {
  const auto d = Tiago();
  if (d.empty()) {
    state.SkipWithError("real data not present (../shared/data/tiago-mocap)");
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(ReadTextFile(d / "tiago_48_hey5.urdf").size());
}
BENCHMARK(BM_ReadTiagoUrdfTextPeer)->Unit(benchmark::kMillisecond);

void BM_AuditTiagoWithValidation(benchmark::State& state) {
  const auto d = Tiago();
  if (d.empty()) {
    state.SkipWithError("real data not present (../shared/data/tiago-mocap)");
    return;
  }
  for (auto _ : state) {
    const RobotModel described = ReadUrdf(d / "tiago_48_hey5.urdf", {"", "wrist_ft_tool_link"});
    const RobotLog fit = ReadRobotLog(d / "qualisys_2021-11-30_static_postures.csv", described);
    const RobotLog other = ReadRobotLog(d / "qualisys_2021-11-26_static_postures.csv", described);
    const RobotModel robot = CoverReadings(described, {&fit, &other});
    const RobotAuditResult r = AuditRobot(robot, fit, {}, {other});
    benchmark::DoNotOptimize(r.report.validation.size());
  }
}
BENCHMARK(BM_AuditTiagoWithValidation)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
}  // namespace mcms

BENCHMARK_MAIN();
