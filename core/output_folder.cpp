#include "core/output_folder.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <utility>

#include "core/error.h"
#include "core/interrupt.h"
#include "core/io.h"

namespace mcms {

namespace {

constexpr const char* kManifest = ".mcms-output";

// Every file and folder under `root`, relative, in a stable order.
std::vector<std::string> Entries(const std::filesystem::path& root) {
  namespace fs = std::filesystem;
  std::vector<std::string> out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(root, fs::directory_options::none, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    out.push_back(fs::relative(it->path(), root, ec).generic_string());
  std::sort(out.begin(), out.end());
  return out;
}

// What an entry of an output folder is, as its record keeps it: "d" for a folder, "l <hash>"
// for a symbolic link (of its target), "f <size> <hash>" for a file (64-bit FNV-1a of its
// bytes). A record names only what its run wrote as it wrote it: an entry added to the record
// by hand, or a file changed since, no longer matches and is the user's (issue 53: a record
// edited to list notes.txt must not let a run delete it).
std::string Fingerprint(const std::filesystem::path& p) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto st = fs::symlink_status(p, ec);
  if (ec) return "?";
  uint64_t h = 14695981039346656037ull;
  const auto Mix = [&h](const char* b, size_t n) {
    for (size_t i = 0; i < n; ++i) h = (h ^ static_cast<unsigned char>(b[i])) * 1099511628211ull;
  };
  char hex[17];
  const auto Hex = [&] {
    std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
    return std::string(hex);
  };
  if (fs::is_symlink(st)) {
    const std::string target = fs::read_symlink(p, ec).string();
    Mix(target.data(), target.size());
    return "l " + Hex();
  }
  if (fs::is_directory(st)) return "d";
  if (!fs::is_regular_file(st)) return "?";
  std::ifstream in(p, std::ios::binary);
  if (!in) return "?";
  std::vector<char> buf(1 << 16);
  uint64_t size = 0;
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const auto n = static_cast<size_t>(in.gcount());
    Mix(buf.data(), n);
    size += n;
  }
  return "f " + std::to_string(size) + " " + Hex();
}

// The record an output folder keeps of what its run wrote: "mcms <kind>", then one line per
// entry, its relative path, a tab and its fingerprint. Empty kind when there is none.
std::pair<std::string, std::map<std::string, std::string>> ReadManifest(const std::filesystem::path& folder) {
  std::ifstream in(folder / kManifest);
  std::pair<std::string, std::map<std::string, std::string>> m;
  std::string line;
  if (!in || !std::getline(in, line) || line.rfind("mcms ", 0) != 0) return m;
  m.first = line.substr(5);
  while (std::getline(in, line)) {
    const size_t tab = line.rfind('\t');
    if (!line.empty()) m.second[line.substr(0, tab)] = tab == std::string::npos ? "" : line.substr(tab + 1);
  }
  return m;
}

}  // namespace

std::string RecordedOutputKind(const std::filesystem::path& folder) { return ReadManifest(folder).first; }

void RequireOwnEarlierOutput(const std::filesystem::path& file, const std::function<bool(const std::string&)>& ours,
                             const std::string& what, const std::string& described, const std::string& advice) {
  std::error_code ec;
  if (!std::filesystem::exists(file, ec)) return;
  std::string head;
  if (std::filesystem::is_regular_file(file, ec)) {
    std::ifstream in(file, std::ios::binary);
    head.assign(4096, '\0');
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<size_t>(std::max<std::streamsize>(in.gcount(), 0)));
    if (ours(head)) return;
  }
  Throw(what, " ", file.string(), " exists and is not ", described, "; it was not replaced: ", advice);
}

void RequireReplaceableFolder(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                              const std::string& kind, const std::string& what) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(folder, ec)) return;
  if (!fs::is_directory(folder, ec)) Throw(what, ": ", folder.string(), " exists and is not a folder");
  if (fs::is_empty(folder, ec)) return;
  // A run replaces only what a run of the same kind recorded writing: a folder holding
  // anything else (the user's own files) is refused, and nothing in it is touched.
  const auto [recorded_kind, recorded] = ReadManifest(folder);
  std::vector<std::string> foreign;
  for (const std::string& e : Entries(folder)) {
    if (e == kManifest) continue;
    const auto it = recorded.find(e);
    if (it == recorded.end() || it->second != Fingerprint(folder / e)) foreign.push_back(e);
  }
  if (recorded_kind == kind && foreign.empty()) {
    // Replacing it removes every file in it: a folder inside that cannot be written would
    // stop that half-way (and leave the old output beside the new one).
    if (::access(folder.c_str(), W_OK) != 0)
      Throw(what, ": folder ", folder.string(), " holds an earlier ", kind, " but is not writable; it cannot be replaced");
    for (const std::string& e : Entries(folder))
      if (fs::is_directory(folder / e, ec) && !fs::is_symlink(folder / e, ec) && ::access((folder / e).c_str(), W_OK) != 0)
        Throw(what, ": folder ", folder.string(), " holds an earlier ", kind, " whose folder ", e,
              " is not writable, so it cannot be replaced; nothing in it was touched: make it writable or choose a new folder");
    return;
  }
  std::string list;
  for (size_t i = 0; i < foreign.size() && i < 5; ++i) list += (i ? ", " : "") + foreign[i];
  if (foreign.size() > 5) list += ", ... (" + std::to_string(foreign.size()) + " in all)";
  std::string markers;
  for (const std::string& m : marker_files) markers += (markers.empty() ? "" : ", ") + m;
  if (recorded_kind.empty())
    Throw(what, ": folder ", folder.string(), " exists and does not hold an earlier ", kind,
          " (no record of an mcms run, ", kManifest, ", beside its files: ", list,
          markers.empty() ? "" : "; an earlier " + kind + " holds " + markers,
          "); nothing in it was touched: choose a new folder or remove it");
  if (recorded_kind != kind)
    Throw(what, ": folder ", folder.string(), " holds the output of mcms ", recorded_kind, ", not of ", kind,
          "; nothing in it was touched: choose a new folder or remove it");
  Throw(what, ": folder ", folder.string(), " holds an earlier ", kind,
        " and files that run did not write (or that changed since): ", list,
        "; nothing in it was touched: move them out, or choose a new folder");
}

void RecordOutputFolder(const std::filesystem::path& folder, const std::string& kind) {
  std::vector<std::string> written = Entries(folder);
  std::erase(written, std::string(kManifest));
  std::ofstream m(folder / kManifest);
  m << "mcms " << kind << "\n";
  for (const std::string& e : written) m << e << "\t" << Fingerprint(folder / e) << "\n";
  if (!m.flush()) Throw("cannot write ", (folder / kManifest).string());
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
  // What an interrupted run left beside `out` (of a process that no longer runs).
  for (const char* tag : {".partial-", ".old-"})
    RemoveStaleTemporaries(out.parent_path(), std::string(".").append(out.filename().string()).append(tag));
  RequireReplaceableFolder(out, marker_files, kind, what);
  RequireNotReadThisRun(out, true);
  // (not "." + string: GCC 12 reports a false -Wrestrict overlap in that concatenation)
  const std::string stem = std::string(".").append(out.filename().string());
  const std::string pid = std::to_string(::getpid());
  const fs::path tmp = out.parent_path() / (stem + ".partial-" + pid);
  const RemovedOnInterrupt remove_if_interrupted(tmp);
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
    RecordOutputFolder(tmp, kind);  // so that the next run of the same kind may replace it
    RequireReplaceableFolder(out, marker_files, kind, what);
    RequireNotReadThisRun(out, true);
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
  } catch (const InputError& e) {
    // A file of the folder that could not be written is named where it was to go, not in
    // the hidden folder it was being written to.
    fs::remove_all(tmp, ec);
    std::string m = e.what();
    const std::string from = tmp.string(), to = out.string();
    for (size_t at = 0; (at = m.find(from, at)) != std::string::npos; at += to.size()) m.replace(at, from.size(), to);
    throw InputError(m);
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
}

namespace {

namespace fs = std::filesystem;

bool SameFile(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  return fs::exists(a, ec) && fs::exists(b, ec) && fs::equivalent(a, b, ec) && !ec;
}

}  // namespace

void RequireOutputsSpareInputs(const std::vector<RunOutput>& outputs, const std::vector<fs::path>& named_inputs) {
  std::error_code ec;
  // The inputs the run named and those it has read so far through them (a rig's model
  // files, a setup's robot: RunInputsRecord).
  std::vector<fs::path> inputs = named_inputs;
  for (const fs::path& p : InputsReadThisRun()) inputs.push_back(p);
  // Two outputs of one run on one file: the one written last would silently replace the
  // other (calib-robot -o x.yaml --report x.yaml); a file inside an output folder would be
  // removed when the folder is replaced.
  for (size_t a = 0; a < outputs.size(); ++a)
    for (size_t b = a + 1; b < outputs.size(); ++b) {
      const RunOutput &x = outputs[a], &y = outputs[b];
      if (x.path.empty() || y.path.empty() || (x.path == y.path && x.what == y.what)) continue;
      const fs::path px = ResolvedPath(x.path), py = ResolvedPath(y.path);
      if (px == py || SameFile(x.path, y.path))
        Throw(x.what, " ", x.path.string(), " and ", y.what, " ", y.path.string(),
              " name the same file: one output would replace the other; choose different outputs");
      if ((x.folder && PathWithin(py, px)) || (y.folder && PathWithin(px, py)))
        Throw(x.what, " ", x.path.string(), " and ", y.what, " ", y.path.string(),
              ": one lies inside the other's output folder, which is replaced as a whole; choose outputs apart");
    }
  for (const RunOutput& out : outputs) {
    if (out.path.empty()) continue;
    const fs::path o = ResolvedPath(out.path);
    for (size_t k = 0; k < inputs.size(); ++k) {
      const fs::path& in = inputs[k];
      if (in.empty() || !fs::exists(in, ec)) continue;
      const fs::path i = ResolvedPath(in);
      // An input read through another one (a rig's camera model) is named as such.
      const std::string the_input =
          k < named_inputs.size() ? "the input " + in.string()
                                  : in.string() + ", a file this run reads through another of its inputs";
      const bool in_folder = fs::is_directory(in, ec);
      const std::string named = "; it would overwrite an input of this run: choose another output";
      if (!out.folder) {
        if (SameFile(out.path, in) || o == i)
          Throw(out.what, " ", out.path.string(), " is ", the_input, named);
        // New or not: a file written into a folder the run reads whole becomes part of what
        // the next run reads (a poses.csv among the images is taken for a camera's folder).
        if (in_folder && PathWithin(o, i))
          Throw(out.what, " ", out.path.string(), " lies inside the input folder ", in.string(),
                ", which this run reads whole: choose an output outside it");
        continue;
      }
      if (SameFile(out.path, in) || o == i)
        Throw(out.what, " ", out.path.string(), " is ", the_input,
              "; the output folder would replace it: choose another output folder");
      if (PathWithin(i, o) && fs::exists(out.path, ec))
        Throw(out.what, " ", out.path.string(), " holds ", the_input,
              "; writing the output folder would remove it: choose another output folder");
      if (in_folder && PathWithin(o, i))
        Throw(out.what, " ", out.path.string(), " lies inside the input folder ", in.string(),
              ", which this run reads whole: writing it would change what this run reads; choose another output folder");
    }
  }
}

}  // namespace mcms
