// Numbers as messages and reports print them.
#pragma once

#include <cstdio>
#include <string>

namespace mcms {

// printf into a string, of any length.
std::string Format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

// Four significant digits (%.4g): what a message needs to name a value.
inline std::string Num4(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4g", v);
  return b;
}

}  // namespace mcms
