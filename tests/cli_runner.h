// Shared helpers of the tests that run the `mcms` executable: run it (or any shell
// command) in a folder, capture its exit code, stdout and stderr.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <map>
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

// Every entry under `dir` (but the runner's stdout.txt / stderr.txt): its content for a
// file, its target for a symlink, "<dir>" for a folder.
inline std::map<std::string, std::string> Snapshot(const std::filesystem::path& dir) {
  std::map<std::string, std::string> s;
  for (auto it = std::filesystem::recursive_directory_iterator(dir);
       it != std::filesystem::recursive_directory_iterator(); ++it) {
    const std::filesystem::path rel = std::filesystem::relative(it->path(), dir);
    if (rel == "stdout.txt" || rel == "stderr.txt") continue;
    if (it->is_symlink())
      s[rel.string()] = "-> " + std::filesystem::read_symlink(it->path()).string();
    else if (it->is_directory())
      s[rel.string()] = "<dir>";
    else
      s[rel.string()] = ReadAll(it->path());
  }
  return s;
}

}  // namespace mcms::test
