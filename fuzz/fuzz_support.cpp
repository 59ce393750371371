#include "fuzz/fuzz_support.h"

#include <fstream>
#include <system_error>
#include <unistd.h>

namespace mcms::fuzz {

namespace fs = std::filesystem;

namespace {
struct Folder {
  fs::path path;
  Folder() {
    path = fs::temp_directory_path() / std::string("mcms-fuzz-").append(std::to_string(::getpid()));
    fs::create_directories(path);
  }
  ~Folder() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};
}  // namespace

const fs::path& InputFolder() {
  static const Folder folder;
  return folder.path;
}

fs::path WriteInput(const uint8_t* data, size_t size, const std::string& extension) {
  const fs::path p = InputFolder() / std::string("input").append(extension);
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) throw std::runtime_error(std::string("fuzz: cannot write ").append(p.string()));
  return p;
}

}  // namespace mcms::fuzz
