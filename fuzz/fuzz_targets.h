// Fuzz targets for every parser of mcms (issue 14). Each target is a plain function
// `int FuzzXxx(const uint8_t* data, size_t size)` that hands the bytes to one family of
// parsers (through a temporary file when the parser takes a path) and returns 0.
//
// The only expected outcome for bad input is mcms::InputError (core/error.h) whose message
// names the input; every other exception escapes (a finding), and so does an InputError
// that does not name the input (a std::logic_error). Crashes, sanitizer reports, timeouts
// and memory blow-ups are findings of the fuzzer itself.
//
// The same functions run under libFuzzer (fuzz/libfuzzer_main.cpp, built with clang by
// scripts/fuzz.sh) and in the normal GCC build from tests/test_fuzz_regressions.cpp, which
// replays every seed (fuzz/corpus/<target>/) and every input that ever failed
// (fuzz/regressions/<target>/).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mcms::fuzz {

int FuzzCsv(const uint8_t* data, size_t size);     // core CSV, truth poses, ISO 9283 poses, fusion windows, fov-map measured points/lines
int FuzzCamera(const uint8_t* data, size_t size);  // mrcal .cameramodel (and its optimization_inputs), OpenCV YAML camera, rig YAML
int FuzzTarget(const uint8_t* data, size_t size);  // tracking target YAML, calibration board YAML
int FuzzRobot(const uint8_t* data, size_t size);   // robot description YAML, robot measurement YAML
int FuzzLogs(const uint8_t* data, size_t size);    // tracker/joint/inclinometer logs, robot audit log CSV
int FuzzSetup(const uint8_t* data, size_t size);   // fusion setup YAML, scenario YAML, fov-map grid text
int FuzzPng(const uint8_t* data, size_t size);     // a camera frame image (PNG path of mcms track)

struct FuzzTargetInfo {
  const char* name;  // fuzz/corpus/<name>/, fuzz/regressions/<name>/, executable fuzz_<name>
  int (*entry)(const uint8_t*, size_t);
};
const std::vector<FuzzTargetInfo>& FuzzTargets();

}  // namespace mcms::fuzz
