#include "core/output_folder.h"

#include <unistd.h>

#include "core/error.h"

namespace mcms {

void RequireReplaceableFolder(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                              const std::string& kind, const std::string& what) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(folder, ec)) return;
  if (!fs::is_directory(folder, ec)) Throw(what, ": ", folder.string(), " exists and is not a folder");
  if (fs::is_empty(folder, ec)) return;
  bool earlier = !marker_files.empty();
  for (const std::string& m : marker_files) earlier = earlier && fs::exists(folder / m, ec);
  if (earlier) return;
  Throw(what, ": folder ", folder.string(), " exists and does not hold an earlier ", kind, "; choose a new folder or ",
        "remove it");
}

void WriteFolderAtomically(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                           const std::string& kind, const std::string& what,
                           const std::function<void(const std::filesystem::path&)>& write) {
  namespace fs = std::filesystem;
  fs::path out = fs::absolute(folder).lexically_normal();
  if (!out.has_filename()) out = out.parent_path();
  RequireReplaceableFolder(out, marker_files, kind, what);
  // (not "." + string: GCC 12 reports a false -Wrestrict overlap in that concatenation)
  const std::string stem = std::string(".").append(out.filename().string());
  const std::string pid = std::to_string(::getpid());
  const fs::path tmp = out.parent_path() / (stem + ".partial-" + pid);
  std::error_code ec;
  fs::remove_all(tmp, ec);
  try {
    fs::create_directories(tmp);
    write(tmp);
    RequireReplaceableFolder(out, marker_files, kind, what);
    if (fs::exists(out)) {
      const fs::path old = out.parent_path() / (stem + ".old-" + pid);
      fs::remove_all(old, ec);
      fs::rename(out, old);
      fs::rename(tmp, out);
      fs::remove_all(old, ec);
    } else {
      fs::rename(tmp, out);
    }
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(tmp, ec);
    Throw(what, ": cannot write ", out.string(), ": ", e.code().message());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
}

}  // namespace mcms
