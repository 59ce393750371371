// An output folder written as a whole: filled under a temporary name beside it and renamed
// into place only when complete, so a failure leaves nothing half-written; an existing
// folder is replaced only when it holds an earlier output of the same kind.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace mcms {

// `write` fills a temporary folder beside `folder`, which is renamed into place only when
// `write` returned normally; the folder records what the run wrote in `.mcms-output`
// ("mcms <kind>", then per entry its relative path and fingerprint: size and content hash of
// a file). An existing `folder` is replaced only when it is empty or holds an earlier output
// of the same `kind` (e.g. "render") and nothing but what that run recorded, unchanged: a
// folder with any other file (the user's own, a file the record names but the run did not
// write as it stands, an output of another command, one written before the record existed)
// is refused before
// `write` runs, and nothing in it is touched (InputError naming `what`, e.g. "fov-map -o",
// the folder and the foreign files; `marker_files` are named in the message). What an
// interrupted run left beside the folder (".<name>.partial-PID" of a process that no
// longer runs) is removed first.
void WriteFolderAtomically(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                           const std::string& kind, const std::string& what,
                           const std::function<void(const std::filesystem::path&)>& write);
// Writes `folder`/.mcms-output, the record of what a run of `kind` wrote there: every file
// and folder under it now. For an output written in place rather than by
// WriteFolderAtomically (the demo), called when the run is done.
void RecordOutputFolder(const std::filesystem::path& folder, const std::string& kind);
// The kind of run `folder`/.mcms-output records ("audit robot", "demo", ...); "" when the
// folder keeps no record (or a record without its first line).
std::string RecordedOutputKind(const std::filesystem::path& folder);
// The refusal test of WriteFolderAtomically alone, for checking before long work.
void RequireReplaceableFolder(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                              const std::string& kind, const std::string& what);

// A file a command writes by default beside the user's data (track's DIR/poses.csv,
// report's report.html) is replaced only when an earlier run wrote it: `ours` tests the
// file's first 4 KiB. Otherwise InputError: "<what> <file> exists and is not <described>;
// it was not replaced: <advice>". Nothing to check when the file does not exist.
void RequireOwnEarlierOutput(const std::filesystem::path& file, const std::function<bool(const std::string&)>& ours,
                             const std::string& what, const std::string& described, const std::string& advice);

// Creates an output folder (and its parents). InputError naming `what` (e.g. "demo -o")
// and the folder, with the system's reason, instead of a filesystem_error, when it cannot
// be created (a path in /proc, a read-only file system, a file in the way).
void CreateOutputFolder(const std::filesystem::path& folder, const std::string& what);

// An output of a run, to be checked against the run's inputs before anything is written.
struct RunOutput {
  std::filesystem::path path;
  std::string what;     // how the user named it, e.g. "fuse -o", "audit robot --json"
  bool folder = false;  // a folder written (or replaced) as a whole
};

// Never lose a user's data: InputError naming the output and the input (and nothing
// written) when an output would overwrite or remove an input of the same run:
//  - an output file that is an input file (the same file by device and inode where it
//    exists, so a symlink or another spelling of the path is caught) or an existing file
//    inside an input folder;
//  - an output folder (replaced as a whole) that is an input, holds one, or lies inside an
//    input folder where it would replace what the run reads.
// Empty output paths are skipped; inputs that do not exist are ignored (the reader names
// them).
void RequireOutputsSpareInputs(const std::vector<RunOutput>& outputs, const std::vector<std::filesystem::path>& inputs);

}  // namespace mcms
