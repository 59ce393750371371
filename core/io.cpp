#include "core/io.h"

#include <cstring>

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/interrupt.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {
thread_local int tl_run_depth = 0;
thread_local std::set<fs::path> tl_read;

}  // namespace

fs::path ResolvedPath(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p, ec), ec);
  if (ec) r = fs::absolute(p, ec).lexically_normal();
  if (!r.has_filename() && r.has_parent_path()) r = r.parent_path();
  return r;
}

bool PathWithin(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i)
    if (i == inner.end() || *i != *o) return false;
  return true;
}

RunInputsRecord::RunInputsRecord() { ++tl_run_depth; }
RunInputsRecord::~RunInputsRecord() {
  if (--tl_run_depth == 0) tl_read.clear();
}

void NoteInputRead(const fs::path& path) {
  if (tl_run_depth > 0 && !path.empty()) tl_read.insert(ResolvedPath(path));
}

std::vector<fs::path> InputsReadThisRun() { return {tl_read.begin(), tl_read.end()}; }

void RequireNotReadThisRun(const fs::path& output, bool folder) {
  if (tl_read.empty() || output.empty()) return;
  const fs::path o = ResolvedPath(output);
  std::error_code ec;
  for (const fs::path& in : tl_read) {
    const bool in_folder = fs::is_directory(in, ec);
    if (o == in || (fs::exists(output, ec) && fs::exists(in, ec) && fs::equivalent(output, in, ec)))
      Throw("output ", output.string(), " is ", in.string(), ", which this run read; it was not replaced",
            " (choose another output)");
    if (in_folder && PathWithin(o, in))
      Throw("output ", output.string(), " lies inside ", in.string(),
            ", a folder this run read whole; nothing was written there (choose another output)");
    if (folder && PathWithin(in, o))
      Throw("output folder ", output.string(), " holds ", in.string(),
            ", which this run read; the folder was not replaced (choose another output folder)");
  }
}

void RemoveStaleTemporaries(const fs::path& dir, const std::string& prefix) {
  std::error_code ec;
  const fs::path d = dir.empty() ? fs::path(".") : dir;
  for (auto it = fs::directory_iterator(d, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string pid = name.substr(prefix.size());
    if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos || pid.size() > 9) continue;
    const pid_t p = static_cast<pid_t>(std::stol(pid));
    if (p > 0 && ::kill(p, 0) != 0 && errno == ESRCH) {
      std::error_code rm;
      fs::remove_all(it->path(), rm);
    }
  }
}

std::string SystemWriteReason() { return errno ? std::string(": ") + std::strerror(errno) : std::string(); }

void WriteFileAtomically(const fs::path& path, const std::function<void(std::ostream&)>& write) {
  RequireNotReadThisRun(path, false);
  {
    std::error_code ec;
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec) && !fs::is_directory(path, ec))
      Throw("output ", path.string(), " is a device, FIFO or socket, not a file; it was not replaced (give a file name)");
  }
  RemoveStaleTemporaries(path.parent_path(), path.filename().string() + ".partial-");
  if (path.has_parent_path() && !path.parent_path().empty()) {
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
    if (ec) Throw("cannot create folder ", path.parent_path().string(), " for output ", path.string(), ": ", ec.message());
  }
  const fs::path tmp = path.string() + ".partial-" + std::to_string(::getpid());
  const RemovedOnInterrupt remove_if_interrupted(tmp);
  try {
    errno = 0;
    std::ofstream out(tmp, std::ios::binary);
    if (!out) Throw("cannot write output file ", path.string(), SystemWriteReason());
    write(out);
    out.flush();
    if (out) out.close();
    // The system's reason (no space left on device, file too large, ...) where it gave one.
    if (!out) Throw("error while writing output file ", path.string(), SystemWriteReason());
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ec2;
    fs::remove(tmp, ec2);
    Throw("cannot move the finished output into place at ", path.string(), ": ", ec.message());
  }
}

namespace {
// The nearest existing ancestor of p (p itself when it exists); "." for a relative path
// whose ancestors do not exist yet.
fs::path NearestExisting(const fs::path& p) {
  fs::path q = p.empty() ? fs::path(".") : p;
  std::error_code ec;
  while (!fs::exists(q, ec)) {
    if (!q.has_parent_path() || q.parent_path() == q) return fs::path(".");
    q = q.parent_path();
  }
  return q;
}

void RequireWritableAncestor(const fs::path& target, const fs::path& start, const std::string& what) {
  const fs::path anc = NearestExisting(start);
  std::error_code ec;
  if (!fs::is_directory(anc, ec))
    Throw(what, " ", target.string(), ": ", anc.string(), " exists and is not a folder; choose another path");
  if (::access(anc.c_str(), W_OK) != 0)
    Throw(what, " ", target.string(), ": folder ", anc.string(), " is not writable; choose another path");
}
}  // namespace

namespace {

// A symbolic link whose target does not exist: named before any work (writing through it
// would fail late, or replace the link).
void RequireNotDanglingLink(const fs::path& path, const std::string& what) {
  std::error_code ec;
  if (fs::is_symlink(fs::symlink_status(path, ec)) && !fs::exists(path, ec))
    Throw(what, " ", path.string(), " is a symbolic link to ", fs::read_symlink(path, ec).string(),
          ", which does not exist; give an existing folder's path or a new name (nothing was written)");
}

}  // namespace

void RequireWritableFile(const fs::path& path, const std::string& what) {
  if (path.empty()) Throw(what, ": the output file name is empty");
  if (!path.has_filename())  // "o.csv/": a folder's name, which a file cannot take
    Throw(what, " ", path.string(), " ends with '/', which names a folder; give a file name (nothing was written)");
  RequireNotDanglingLink(path, what);
  std::error_code ec;
  if (fs::is_directory(path, ec))
    Throw(what, " ", path.string(), " is a folder; give a file name (nothing was written)");
  // An output replaces its file whole (a temporary renamed into place): a device, FIFO or
  // socket (/dev/null, /dev/stdout) would be replaced by a regular file.
  if (fs::exists(path, ec) && !fs::is_regular_file(path, ec))
    Throw(what, " ", path.string(), " is a device, FIFO or socket, not a file; give a file name (nothing was written)");
  if (fs::exists(path, ec) && ::access(path.c_str(), W_OK) != 0)
    Throw(what, " ", path.string(), " exists and is not writable; choose another path (nothing was written)");
  RequireWritableAncestor(path, path.has_parent_path() ? path.parent_path() : fs::path("."), what);
}

void RequireWritableFolder(const fs::path& path, const std::string& what) {
  if (path.empty()) Throw(what, ": the output folder name is empty");
  RequireNotDanglingLink(path, what);
  std::error_code ec;
  if (fs::exists(path, ec) && !fs::is_directory(path, ec))
    Throw(what, " ", path.string(), " exists and is not a folder; give a folder for the outputs (nothing was written)");
  RequireWritableAncestor(path, path, what);
}

std::string ReadTextFile(const fs::path& path) {
  NoteInputRead(path);
  std::error_code ec;
  if (fs::is_directory(path, ec)) Throw("cannot read ", path.string(), ": it is a folder, expected a text file");
  // A FIFO with no writer would block forever, a device would never end.
  if (fs::exists(path, ec) && !fs::is_regular_file(path, ec))
    Throw("cannot read ", path.string(), ": not a regular file (a FIFO, socket or device); give a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) Throw("cannot read ", path.string(), ": file missing or not readable");
  // Bounded: a device such as /dev/zero or a huge file given by mistake is refused
  // after kMaxTextFileBytes instead of filling the memory.
  std::string text;
  char buf[1 << 16];
  while (in.read(buf, sizeof(buf)) || in.gcount() > 0) {
    text.append(buf, static_cast<size_t>(in.gcount()));
    if (text.size() > kMaxTextFileBytes)
      Throw("cannot read ", path.string(), ": larger than ", kMaxTextFileBytes / (1024 * 1024),
            " MB, the limit for a text input (is it the right file?)");
  }
  if (in.bad()) Throw("cannot read ", path.string(), ": read error");
  return text;
}

namespace {
// One line's cells, comma-separated, each trimmed of blanks; a cell in double quotes (RFC
// 4180, as CsvQuoted writes it: a reason holding a comma) keeps its commas and blanks, and
// "" inside it is one quote.
std::vector<std::string> SplitCsvLine(const std::string& line) {
  std::vector<std::string> cells;
  const size_t n = line.size();
  if (n == 0) return cells;
  for (size_t i = 0;;) {
    size_t j = line.find_first_not_of(" \t", i);
    if (j != std::string::npos && line[j] == '"') {
      std::string cell;
      for (++j; j < n; ++j) {
        if (line[j] != '"') {
          cell += line[j];
        } else if (j + 1 < n && line[j + 1] == '"') {
          cell += '"';
          ++j;
        } else {
          ++j;
          break;
        }
      }
      cells.push_back(cell);
      j = std::min(line.find(',', j), n);
    } else {
      j = std::min(line.find(',', i), n);
      const std::string cell = line.substr(i, j - i);
      const auto b = cell.find_first_not_of(" \t\r");
      const auto e = cell.find_last_not_of(" \t\r");
      cells.push_back(b == std::string::npos ? std::string() : cell.substr(b, e - b + 1));
    }
    if (j >= n) break;
    i = j + 1;
    if (i == n) {
      cells.emplace_back();  // a trailing comma: an empty last cell
      break;
    }
  }
  return cells;
}
}  // namespace

CsvTable ReadCsv(const fs::path& path) {
  std::string text = ReadTextFile(path);
  const std::string src = path.string();
  // Text that is not UTF-8 (a spreadsheet's "Unicode text" export) would read as garbage.
  if (text.compare(0, 2, "\xFF\xFE") == 0 || text.compare(0, 2, "\xFE\xFF") == 0 ||
      (text.size() >= 4 && text.find('\0') != std::string::npos))
    Throw(src, ": UTF-16 or binary text (NUL bytes); save the CSV as UTF-8 text");
  // A UTF-8 byte order mark (written by some spreadsheet programs) is not part of the
  // first column's name.
  if (text.compare(0, 3, "\xEF\xBB\xBF") == 0) text.erase(0, 3);
  // Line ends: CR LF and old Mac CR alone are line breaks too.
  std::string text_lf;
  text_lf.reserve(text.size());
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '\r') {
      text_lf += '\n';
      if (i + 1 < text.size() && text[i + 1] == '\n') ++i;
    } else {
      text_lf += text[i];
    }
  }
  std::istringstream in(text_lf);
  CsvTable t;
  t.source = path;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line[0] == '#') {
      t.comments.push_back(line);
      continue;
    }
    if (line.empty() || line.find_first_not_of(" \t") == std::string::npos) continue;
    // Excel's separator hint on the first line.
    if (t.header.empty() && line.rfind("sep=", 0) == 0) {
      if (line.substr(4, 1) != ",")
        Throw(src, " line ", lineno, ": the file says its separator is '", line.substr(4, 1),
              "'; mcms reads comma-separated values with decimal points: save the CSV with commas");
      continue;
    }
    auto cells = SplitCsvLine(line);
    if (t.header.empty()) {
      if (cells.size() == 1 && line.find(';') != std::string::npos)
        Throw(src, " line ", lineno, ": the header is separated by ';', not ','; mcms reads comma-separated "
              "values with decimal points (a spreadsheet in a locale with decimal commas?): save the CSV with "
              "commas and points");
      if (cells.size() == 1 && line.find('\t') != std::string::npos)
        Throw(src, " line ", lineno, ": the header is separated by tabs, not commas; save the CSV with commas");
      for (size_t a = 0; a < cells.size(); ++a)
        for (size_t b = a + 1; b < cells.size(); ++b)
          if (!cells[a].empty() && cells[a] == cells[b])
            Throw(src, " line ", lineno, ": column '", cells[a], "' appears twice (columns ", a + 1, " and ", b + 1,
                  "); which one is meant is ambiguous: remove or rename one");
      t.header = std::move(cells);
      continue;
    }
    if (cells.size() != t.header.size()) {
      std::string hint;
      if (cells.size() > t.header.size() && line.find_first_of("0123456789") != std::string::npos)
        hint = " (numbers with decimal commas, such as 1,5 for 1.5? give decimal points)";
      Throw(src, " line ", lineno, ": expected ", t.header.size(), " columns as in the header, found ", cells.size(),
            hint);
    }
    t.rows.push_back(std::move(cells));
    t.line_of_row.push_back(lineno);
  }
  if (t.header.empty()) Throw(src, ": empty file, expected a CSV header row");
  return t;
}

std::string CsvTime(double seconds, int significant) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", significant, seconds);
  if (std::isfinite(seconds) && !(std::abs(std::strtod(b, nullptr) - seconds) <= 1e-7))
    std::snprintf(b, sizeof b, "%.6f", seconds);
  return b;
}

std::string CsvQuoted(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string q = "\"";
  for (char c : text) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

bool CsvTable::HasColumn(const std::string& name) const {
  for (const auto& h : header)
    if (h == name) return true;
  return false;
}

int CsvTable::Column(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<int>(i);
  Throw(source.string(), ": missing column '", name, "' in the header");
}

double CsvTable::Number(size_t row, int column) const {
  const std::string& cell = rows.at(row).at(column);
  char* end = nullptr;
  const double v = std::strtod(cell.c_str(), &end);
  if (cell.empty() || end != cell.c_str() + cell.size() || !std::isfinite(v))
    Throw(source.string(), " line ", line_of_row[row], ", column '", header[column], "': expected a finite number, found '", cell, "'");
  return v;
}

Progress::Progress(std::string label, size_t total, bool quiet)
    : label_(std::move(label)), total_(total), quiet_(quiet), tty_(::isatty(2)) {}

void Progress::Update(size_t done) {
  if (quiet_ || total_ == 0) return;
  using clock = std::chrono::steady_clock;
  const double now = std::chrono::duration<double>(clock::now().time_since_epoch()).count();
  const double interval = tty_ ? 0.2 : 5.0;
  if (done < total_ && last_ >= 0 && now - last_ < interval) return;
  last_ = now;
  printed_total_ = done >= total_;
  std::fprintf(stderr, "%s%s: %zu/%zu (%.0f%%)%s", tty_ ? "\r" : "", label_.c_str(), done, total_,
               100.0 * static_cast<double>(done) / static_cast<double>(total_), tty_ ? "" : "\n");
  std::fflush(stderr);
}

void Progress::Finish() {
  if (quiet_ || total_ == 0 || finished_) return;
  if (!printed_total_) {
    last_ = -1.0;
    Update(total_);
  }
  if (tty_) std::fprintf(stderr, "\n");
  finished_ = true;
}

}  // namespace mcms
