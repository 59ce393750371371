// Errors in three tiers (see docs/conventions.md):
//  - InputError: bad user or file input; the message names the input and what was
//    expected. The CLI prints it as one line and exits non-zero.
//  - Options::IsValid(std::string* why): options structs validate themselves.
//  - MCMS_CHECK(cond, message): a programmer's error (a caller broke a function's
//    contract, an internal table is inconsistent), checked in every build: throws
//    InternalError naming the file and line. The CLI prints it as "internal error" and exits 3.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace mcms {

class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

class InternalError : public std::logic_error {
 public:
  explicit InternalError(const std::string& what) : std::logic_error(what) {}
};

// Builds a message from streamable parts: Throw<InputError>("file ", path, ": expected ...").
template <typename E = InputError, typename... Parts>
[[noreturn]] void Throw(const Parts&... parts) {
  std::ostringstream s;
  (s << ... << parts);
  throw E(s.str());
}

}  // namespace mcms

#define MCMS_CHECK(cond, message)                                                                 \
  do {                                                                                             \
    if (!(cond)) ::mcms::Throw<::mcms::InternalError>(__FILE__, ":", __LINE__, ": ", message);    \
  } while (false)
