// The predicted field-of-view map (issue 12): the default 4-camera rig over a 50 x 40 x 50
// grid of its 1 x 0.8 x 1 m working volume, one thread, and the cost of one grid point.
// Not a test: numbers depend on the machine.
#include <benchmark/benchmark.h>

#include "jobs/fov_map.h"
#include "synthetic/scenario.h"

namespace mcms {
namespace {

FovMapOptions Options(const std::string& grid) {
  FovMapOptions o;
  o.grid = FovGrid::Parse(grid, "bench grid");
  o.noise.render = Scenario::Default().render;
  o.threads = 1;
  return o;
}

void BM_FovMap_50x40x50_4cams_1thread(benchmark::State& state) {
  const Scenario sc = Scenario::Default();
  const FovMapOptions o = Options("-0.5:0.5:50,-0.4:0.4:40,0:1:50");
  size_t trackable = 0;
  for (auto _ : state) {
    const FovMap map = ComputeFovMap(sc.rig, sc.target, o);
    trackable = 0;
    for (const auto& p : map.points) trackable += p.prediction.trackable;
    benchmark::DoNotOptimize(trackable);
  }
  state.counters["points"] = static_cast<double>(o.grid.size());
  state.counters["trackable"] = static_cast<double>(trackable);
  state.counters["s_per_point"] = benchmark::Counter(static_cast<double>(o.grid.size()),
                                                      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_FovMap_50x40x50_4cams_1thread)->Unit(benchmark::kSecond)->Iterations(1);

// The centre-noise table alone (rendered noise-free blobs through the detector).
void BM_FovCentreTable(benchmark::State& state) {
  FovNoiseModel n;
  n.render = Scenario::Default().render;
  for (auto _ : state) benchmark::DoNotOptimize(BuildCentroidCovarianceTable(n, 3.0, 9.0, 1.8, 1));
}
BENCHMARK(BM_FovCentreTable)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace mcms

BENCHMARK_MAIN();
