// Replays every seed (fuzz/corpus/<target>/) and every input that ever failed a fuzzer
// (fuzz/regressions/<target>/) through the same entry functions the libFuzzer targets run
// (fuzz/fuzz_targets.h): each must finish with at most the expected InputError naming the
// input (caught inside the entry); a crash or any other exception fails the test. Run by
// the normal (GCC) build; scripts/fuzz.sh runs the fuzzers themselves.
#include <gtest/gtest.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include "fuzz/fuzz_targets.h"
#include "test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

std::vector<fs::path> FilesIn(const fs::path& dir) {
  std::vector<fs::path> files;
  if (fs::is_directory(dir))
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file() && e.path().filename().string().front() != '.') files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

// Runs each file through the entry; returns how many ran.
size_t Replay(const fuzz::FuzzTargetInfo& t, const std::vector<fs::path>& files) {
  for (const auto& f : files) {
    const std::string bytes = test::ReadAll(f);
    SCOPED_TRACE(f.string());
    try {
      t.entry(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
    } catch (const std::exception& e) {
      ADD_FAILURE() << "fuzz target " << t.name << ": " << f.string() << " escapes with " << e.what();
    }
  }
  return files.size();
}

class FuzzRegressions : public ::testing::TestWithParam<fuzz::FuzzTargetInfo> {};

TEST_P(FuzzRegressions, SeedsAndFailedInputsFinishWithOnlyInputErrors) {
  const fuzz::FuzzTargetInfo& t = GetParam();
  const fs::path root = fs::path(MCMS_SOURCE_DIR) / "fuzz";
  const size_t seeds = Replay(t, FilesIn(root / "corpus" / t.name));
  EXPECT_GE(seeds, 2u) << "fuzz/corpus/" << t.name << "/ needs seeds";
  Replay(t, FilesIn(root / "regressions" / t.name));
}

INSTANTIATE_TEST_SUITE_P(Targets, FuzzRegressions, ::testing::ValuesIn(fuzz::FuzzTargets()),
                         [](const ::testing::TestParamInfo<fuzz::FuzzTargetInfo>& i) { return std::string(i.param.name); });

}  // namespace
}  // namespace mcms
