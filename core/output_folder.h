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
// `write` returned normally. An existing `folder` is replaced only when it is empty or
// holds all of `marker_files` (an earlier output of the same `kind`, e.g. "render");
// anything else is refused before `write` runs (InputError naming `what`, e.g.
// "fov-map -o", and the folder).
void WriteFolderAtomically(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                           const std::string& kind, const std::string& what,
                           const std::function<void(const std::filesystem::path&)>& write);
// The refusal test of WriteFolderAtomically alone, for checking before long work.
void RequireReplaceableFolder(const std::filesystem::path& folder, const std::vector<std::string>& marker_files,
                              const std::string& kind, const std::string& what);

}  // namespace mcms
