// The set-up texts: the fusion setup YAML of `mcms fuse`, the scenario YAML of
// `mcms render`/`demo` (from text, relative files resolved in the fuzzer's temporary
// folder) and the grid text of `mcms fov-map --grid`.
#include <string>

#include "fusion/sensor_logs.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "jobs/fov_map.h"
#include "synthetic/scenario.h"

namespace mcms::fuzz {

int FuzzSetup(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const std::string setup = "setup fuzz-input.yaml";
  ExpectInputError(setup, [&] { (void)ParseFusionSetup(text, setup, InputFolder()); });
  const std::string scenario = "scenario fuzz-input.yaml";
  ExpectInputError(scenario, [&] {
    const Scenario s = Scenario::Parse(text, scenario, InputFolder());
    // Write() is documented to give back this scenario through Read().
    try {
      (void)Scenario::Parse(s.ToYaml(), "written scenario", InputFolder());
    } catch (const InputError& e) {
      throw std::logic_error(std::string("Scenario::Parse refuses the ToYaml() of a scenario it accepted: ").append(e.what()));
    }
  });
  const std::string grid = "--grid";
  ExpectInputError(grid, [&] { (void)FovGrid::Parse(text, grid); });
  return 0;
}

}  // namespace mcms::fuzz
