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

void CreateOutputFolder(const std::filesystem::path& folder, const std::string& what) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec || !fs::is_directory(folder, ec))
    Throw(what, ": cannot create the output folder ", folder.string(), ": ",
          ec ? ec.message() : std::string("it exists and is not a folder"), " (nothing was written)");
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
  {
    std::error_code mk;
    fs::create_directories(tmp, mk);
    if (mk) {
      fs::remove_all(tmp, ec);
      Throw(what, ": cannot create the output folder ", out.string(), ": ", mk.message(), " (nothing was written)");
    }
  }
  try {
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

namespace {

namespace fs = std::filesystem;

// The absolute, normal form of a path with its symlinks resolved as far as it exists.
fs::path Resolved(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p, ec), ec);
  if (ec) r = fs::absolute(p, ec).lexically_normal();
  if (!r.has_filename() && r.has_parent_path()) r = r.parent_path();
  return r;
}

// Whether `inner` is `outer` or lies inside it (both resolved).
bool Within(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i)
    if (i == inner.end() || *i != *o) return false;
  return true;
}

bool SameFile(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  return fs::exists(a, ec) && fs::exists(b, ec) && fs::equivalent(a, b, ec) && !ec;
}

}  // namespace

void RequireOutputsSpareInputs(const std::vector<RunOutput>& outputs, const std::vector<fs::path>& inputs) {
  std::error_code ec;
  for (const RunOutput& out : outputs) {
    if (out.path.empty()) continue;
    const fs::path o = Resolved(out.path);
    for (const fs::path& in : inputs) {
      if (in.empty() || !fs::exists(in, ec)) continue;
      const fs::path i = Resolved(in);
      const bool in_folder = fs::is_directory(in, ec);
      const std::string named = "; it would overwrite an input of this run: choose another output";
      if (!out.folder) {
        if (SameFile(out.path, in) || o == i)
          Throw(out.what, " ", out.path.string(), " is the input ", in.string(), named);
        if (in_folder && Within(o, i) && fs::exists(out.path, ec) && !fs::is_directory(out.path, ec))
          Throw(out.what, " ", out.path.string(), " is a file inside the input folder ", in.string(), named);
        continue;
      }
      if (SameFile(out.path, in) || o == i)
        Throw(out.what, " ", out.path.string(), " is the input ", in.string(),
              "; the output folder would replace it: choose another output folder");
      if (Within(i, o) && fs::exists(out.path, ec))
        Throw(out.what, " ", out.path.string(), " holds the input ", in.string(),
              "; writing the output folder would remove it: choose another output folder");
      if (in_folder && Within(o, i) && fs::exists(out.path, ec))
        Throw(out.what, " ", out.path.string(), " lies inside the input folder ", in.string(),
              " and exists; replacing it would change what this run reads: choose another output folder");
    }
  }
}

}  // namespace mcms
