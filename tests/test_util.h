// Shared test helpers: where the real data lives, a central-difference Jacobian check.
#pragma once

#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <string>

#include <Eigen/Core>

#include "core/error.h"

namespace mcms::test {

// ../shared/data beside the project, or $MCMS_DATA_DIR.
inline std::filesystem::path DataRoot() {
  if (const char* env = std::getenv("MCMS_DATA_DIR")) return env;
  return std::filesystem::path(MCMS_SOURCE_DIR) / ".." / "shared" / "data";
}

// The folder of one real data set, or nullopt when it is not present.
inline std::optional<std::filesystem::path> RealData(const std::string& name) {
  const auto p = DataRoot() / name;
  if (std::filesystem::is_directory(p)) return p;
  return std::nullopt;
}

#define MCMS_REQUIRE_DATA(var, name)                                                           \
  const auto var##_opt = ::mcms::test::RealData(name);                                        \
  if (!var##_opt) GTEST_SKIP() << "skipped: real data not present: " << (::mcms::test::DataRoot() / name); \
  const std::filesystem::path var = *var##_opt

// Central differences of f: R^n -> R^m at x.
inline Eigen::MatrixXd NumericJacobian(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                                       const Eigen::VectorXd& x, double h = 1e-6) {
  const Eigen::VectorXd f0 = f(x);
  Eigen::MatrixXd J(f0.size(), x.size());
  for (int i = 0; i < x.size(); ++i) {
    Eigen::VectorXd xp = x, xm = x;
    xp[i] += h;
    xm[i] -= h;
    J.col(i) = (f(xp) - f(xm)) / (2 * h);
  }
  return J;
}

// The message of the InputError that `f` throws, "(no InputError)" when it throws none.
inline std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no InputError)";
}

// The whole file, "" when it does not exist. One stream per file: `s << in.rdbuf()` of an
// empty file sets failbit on `s`.
inline std::string ReadAll(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void WriteText(const std::filesystem::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

// A fresh scratch folder of this process: ctest runs test cases as separate processes in
// parallel, so the name carries the process id (two cases of one suite sharing a name
// would otherwise remove each other's files).
inline std::filesystem::path ScratchDir(const std::string& name) {
  const auto p = std::filesystem::path(MCMS_BINARY_DIR) / "test-scratch" / (name + "-" + std::to_string(::getpid()));
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p;
}

}  // namespace mcms::test
