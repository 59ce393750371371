// The libFuzzer entry of one target: compiled once per target with
// -DMCMS_FUZZ_ENTRY=FuzzXxx (fuzz/CMakeLists.txt, MCMS_BUILD_FUZZ=ON, clang only).
#include "fuzz/fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return mcms::fuzz::MCMS_FUZZ_ENTRY(data, size);
}
