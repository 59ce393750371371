// Shared helpers of the tests that run the `mcms` executable: run it (or any shell
// command) in a folder, capture its exit code, stdout and stderr.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "tests/test_util.h"

namespace mcms::test {

struct CliRun {
  int code;  // exit status; -1 when the process did not exit normally (killed by a signal)
  std::string out, err;
};

// Runs a shell command in `dir` (relative names in its arguments and messages are the
// ones given); stdout and stderr are captured in dir/stdout.txt and dir/stderr.txt.
inline CliRun Shell(const std::filesystem::path& dir, const std::string& command) {
  const std::string cmd =
      std::string("cd '").append(dir.string()).append("' && ").append(command).append(" > stdout.txt 2> stderr.txt");
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, ReadAll(dir / "stdout.txt"), ReadAll(dir / "stderr.txt")};
}

// Runs `mcms ARGS` in `dir`.
inline CliRun Mcms(const std::filesystem::path& dir, const std::string& args) {
  // Built by append: `"'" + std::string(...)` trips GCC 12's -Wrestrict false positive.
  std::string command = std::string("'").append(MCMS_CLI).append("' ").append(args);
  return Shell(dir, command);
}

}  // namespace mcms::test
