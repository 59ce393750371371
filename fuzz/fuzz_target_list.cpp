// The table of targets, for the regression test (not linked into the libFuzzer binaries,
// which hold one target each).
#include "fuzz/fuzz_targets.h"

namespace mcms::fuzz {

const std::vector<FuzzTargetInfo>& FuzzTargets() {
  static const std::vector<FuzzTargetInfo> targets = {
      {"csv", FuzzCsv}, {"camera", FuzzCamera}, {"target", FuzzTarget}, {"robot", FuzzRobot},
      {"logs", FuzzLogs}, {"setup", FuzzSetup}, {"png", FuzzPng},
  };
  return targets;
}

}  // namespace mcms::fuzz
