// Errors in three tiers (see docs/conventions.md):
//  - InputError: bad user or file input; the message names the input and what was
//    expected. The CLI prints it as one line and exits non-zero.
//  - Options::IsValid(std::string* why): options structs validate themselves.
//  - MCMS_DCHECK: internal invariants on hot paths, debug builds only.
#pragma once

#include <cassert>
#include <sstream>
#include <stdexcept>
#include <string>

namespace mcms {

class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

// Builds a message from streamable parts: Throw<InputError>("file ", path, ": expected ...").
template <typename E = InputError, typename... Parts>
[[noreturn]] void Throw(const Parts&... parts) {
  std::ostringstream s;
  (s << ... << parts);
  throw E(s.str());
}

}  // namespace mcms

#define MCMS_DCHECK(cond) assert(cond)
