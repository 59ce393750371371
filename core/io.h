// File helpers shared by every module: atomic output (no half-written files),
// plain-text reading with the file named in every error, CSV writing.
#pragma once

#include <filesystem>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace mcms {

// The absolute, normal form of a path, its symlinks resolved as far as it exists (as the
// OS resolves it), without a trailing separator.
std::filesystem::path ResolvedPath(const std::filesystem::path& p);
// Whether `inner` is `outer` or lies inside it (both resolved).
bool PathWithin(const std::filesystem::path& inner, const std::filesystem::path& outer);

// The files a run reads, so that no output of the run replaces one: not only the inputs
// it names (checked by RequireOutputsSpareInputs) but those read through another input
// (a rig's camera model files, a fusion setup's robot, the files of a reported folder).
// While a RunInputsRecord lives on a thread (each job opens one; nested ones share the
// outermost, which forgets the files when it ends), every file that thread reads through
// ReadTextFile, and every folder a reader walks (NoteInputRead), is recorded; reads on
// other threads are not (concurrent jobs of one process, a Dask worker's, stay apart).
class RunInputsRecord {
 public:
  RunInputsRecord();
  ~RunInputsRecord();
  RunInputsRecord(const RunInputsRecord&) = delete;
  RunInputsRecord& operator=(const RunInputsRecord&) = delete;
};
// Records `path` (a file or a folder read whole) as read by the current run, if one is open.
void NoteInputRead(const std::filesystem::path& path);
// What the current run has read so far (absolute paths), empty without a run.
std::vector<std::filesystem::path> InputsReadThisRun();
// InputError when `output` is a file the current run read, or (`folder`) holds one or
// lies inside a folder it read whole: the last check before an output replaces anything.
void RequireNotReadThisRun(const std::filesystem::path& output, bool folder);

// Removes the entries of `dir` named `prefix` + a process id of a process that no longer
// runs: the temporaries a killed run left (".out.partial-PID", "poses.csv.rows.partial-PID").
void RemoveStaleTemporaries(const std::filesystem::path& dir, const std::string& prefix);

// Writes a file through a temporary name in the same folder and renames it into
// place only when `write` returned normally, so a failure leaves no partial file.
// Refused (RequireNotReadThisRun) when the file is one the run read. What a killed run
// left beside it ("<name>.partial-PID") is removed first.
// ": <the system's reason>" for the last failed write (errno: "No space left on device",
// "File too large", ...), "" when the system gave none. Clear errno before the writes.
std::string SystemWriteReason();

void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write);

// Checks, before any long work, that `path` can be written as a file: not an existing
// folder, its folder either creatable or writable. InputError naming `what` (e.g. "-o")
// and the path otherwise, so a run refuses bad outputs before it computes anything.
void RequireWritableFile(const std::filesystem::path& path, const std::string& what);
// The same for an output folder: an existing non-folder, or a folder that cannot be
// written, is refused.
void RequireWritableFolder(const std::filesystem::path& path, const std::string& what);

// Reads the whole file; InputError naming the file when it cannot be read, is a folder,
// or is larger than kMaxTextFileBytes (64 MB: every text input of mcms is far smaller).
constexpr size_t kMaxTextFileBytes = size_t{64} << 20;
std::string ReadTextFile(const std::filesystem::path& path);

// Simple CSV reading: a header row and numeric/text cells. Errors name file and row.
// A leading UTF-8 byte order mark is skipped.
struct CsvTable {
  std::filesystem::path source;
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  std::vector<int> line_of_row;  // 1-based line number in the file
  std::vector<std::string> comments;  // the '#' lines, as written (a report shows them)

  // Column index; InputError naming the file and the column when absent.
  int Column(const std::string& name) const;
  bool HasColumn(const std::string& name) const;
  // Number in a cell; InputError naming file, line and column when not a finite number.
  double Number(size_t row, int column) const;
};
CsvTable ReadCsv(const std::filesystem::path& path);
// A CSV cell: the text as is, or in double quotes (inner quotes doubled) when it holds a
// comma, a quote or a line break.
std::string CsvQuoted(const std::string& text);
// A time (s) in a CSV cell: `significant` digits (%g) where they hold it to a microsecond,
// otherwise to the microsecond (%.6f): Unix-epoch times (1.7e9 s) keep their milliseconds.
std::string CsvTime(double seconds, int significant);

// Progress on stderr for long runs: "label: 37/120 frames (31%)", throttled to a few
// updates per second, silent when quiet.
class Progress {
 public:
  Progress(std::string label, size_t total, bool quiet = false);
  void Update(size_t done);
  void Finish();

 private:
  std::string label_;
  size_t total_;
  bool quiet_;
  double last_ = -1.0;
  bool tty_;
  bool printed_total_ = false, finished_ = false;
};

}  // namespace mcms
