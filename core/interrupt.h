// What an interrupted run leaves behind: nothing. The temporaries of a run (a file or
// folder being written under a temporary name beside its output) are registered while
// they exist; when the process is ended by SIGINT, SIGTERM, SIGHUP or SIGQUIT, the handler that
// InstallInterruptCleanup sets removes every registered one, then ends the process as the
// signal would have (exit status 128 + signal). The handler uses only async-signal-safe
// calls (unlinkat, openat, getdents64): it may run at any point of the work.
#pragma once

#include <filesystem>

namespace mcms {

// Sets the handler for SIGINT, SIGTERM, SIGHUP and SIGQUIT (the command-line program does, once;
// the Python module does not: Python keeps its own SIGINT handling, and a run stopped by
// an exception removes its temporaries itself).
void InstallInterruptCleanup();

// Registers `path` (a file or a folder, removed with everything in it) for removal if the
// process is interrupted while this object lives; its destructor only unregisters it (the
// owner removes or renames the temporary on the normal paths). At most 64 at a time;
// beyond that a temporary is simply not registered.
class RemovedOnInterrupt {
 public:
  explicit RemovedOnInterrupt(const std::filesystem::path& path);
  ~RemovedOnInterrupt();
  RemovedOnInterrupt(const RemovedOnInterrupt&) = delete;
  RemovedOnInterrupt& operator=(const RemovedOnInterrupt&) = delete;

 private:
  int slot_ = -1;
};

}  // namespace mcms
