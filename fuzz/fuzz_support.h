// Helpers shared by the fuzz targets (fuzz/fuzz_targets.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "core/error.h"

namespace mcms::fuzz {

// Writes the bytes to <temp>/mcms-fuzz-<pid>/input<extension> (the same file on every
// call of this process; the folder is removed at exit) and returns its path.
std::filesystem::path WriteInput(const uint8_t* data, size_t size, const std::string& extension);
// The per-process temporary folder (relative paths inside inputs resolve there).
const std::filesystem::path& InputFolder();

// Runs fn(); an InputError is the expected outcome for bad input but must name `input`
// (the file or source text's name): otherwise std::logic_error. Other exceptions escape.
template <typename F>
void ExpectInputError(const std::string& input, F&& fn) {
  try {
    fn();
  } catch (const InputError& e) {
    if (std::string(e.what()).find(input) == std::string::npos)
      throw std::logic_error(std::string("InputError does not name the input ").append(input).append(": ").append(e.what()));
  }
}

}  // namespace mcms::fuzz
