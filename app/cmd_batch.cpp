// mcms batch: many recordings on Dask distributed. The work is python/mcms_batch.py (each
// recording a task calling mcms.track_recording, jobs/track_recording.h); this command
// finds it beside the executable and runs it with the arguments as given.
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "app/commands.h"
#include "core/error.h"

namespace mcms::app {
namespace {

namespace fs = std::filesystem;

// The build's python/ folder (the module mcms and mcms_batch.py): beside the folder of the
// executable (build/app/mcms -> build/python).
fs::path PythonDir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) Throw("batch: cannot find the mcms executable's folder (/proc/self/exe: ", ec.message(), ")");
  const fs::path dir = exe.parent_path().parent_path() / "python";
  if (!fs::exists(dir / "mcms_batch.py"))
    Throw("batch: ", (dir / "mcms_batch.py").string(),
          " not found: `mcms batch` needs the Python module of this build (configure with MCMS_BUILD_PYTHON=ON, "
          "which needs pybind11-dev and python3-dev, and build the target mcms_python)");
  bool module = false;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    module = module || (name.rfind("mcms.", 0) == 0 && e.path().extension() == ".so");
  }
  if (!module)
    Throw("batch: the Python module mcms is not built in ", dir.string(), " (build the target mcms_python)");
  return dir;
}

int RunBatch(const std::vector<std::string>& args) {
  const fs::path dir = PythonDir();
  // The interpreter with numpy and dask: Debian's, unless MCMS_PYTHON names another.
  const char* env_python = std::getenv("MCMS_PYTHON");
  const std::string python = env_python && *env_python ? env_python : "/usr/bin/python3";
  if (::access(python.c_str(), X_OK) != 0)
    Throw("batch: the Python interpreter ", python, " is missing or not executable (install python3 and "
          "python3-distributed, or set MCMS_PYTHON to an interpreter that has numpy and dask.distributed)");
  const char* old = std::getenv("PYTHONPATH");
  std::string path = dir.string();
  if (old && *old) path.append(":").append(old);
  ::setenv("PYTHONPATH", path.c_str(), 1);
  std::vector<std::string> argv_s = {python, "-m", "mcms_batch"};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& s : argv_s) argv.push_back(s.data());
  argv.push_back(nullptr);
  std::fflush(stdout);
  ::execv(python.c_str(), argv.data());
  Throw("batch: cannot run ", python, ": ", std::strerror(errno));
}

const McmsCommand kBatch([](CLI::App& app) {
  CLI::App* cmd = app.add_subcommand(
      "batch",
      "Track many recordings on Dask distributed: DIR_OR_LIST -o OUT [--scheduler ADDR] [--workers N] [--truth "
      "auto|none|PATH] ...; each recording (a sub-folder of DIR, or a line of the list file) is tracked as `mcms "
      "track` does, in a worker process; results and per-recording failures go to OUT/summary.csv. Runs "
      "python/mcms_batch.py of this build with /usr/bin/python3 (or $MCMS_PYTHON); `mcms batch --help` lists its "
      "options.");
  cmd->set_help_flag();  // --help goes to mcms_batch
  cmd->allow_extras();
  cmd->prefix_command();
  return std::make_pair(cmd, Runner([cmd] { return RunBatch(cmd->remaining()); }));
});

}  // namespace
}  // namespace mcms::app
