#include "core/format.h"

#include <cstdarg>

namespace mcms {

std::string Format(const char* fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  va_list copy;
  va_copy(copy, ap);
  const int n = std::vsnprintf(nullptr, 0, fmt, copy);
  va_end(copy);
  std::string s(n > 0 ? n : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), static_cast<size_t>(n) + 1, fmt, ap);
  va_end(ap);
  return s;
}

}  // namespace mcms
