#include "core/limits.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <thread>

#include "core/error.h"

namespace mcms {

void CheckThreads(int n, const std::string& what, bool zero_means_all_cores) {
  const int lo = zero_means_all_cores ? 0 : 1;
  if (n < lo || n > kMaxThreads)
    Throw(what, ": expected ", lo, " to ", kMaxThreads, " threads", zero_means_all_cores ? " (0 = all cores)" : "",
          ", got ", n);
}

int ThreadsToUse(int n) { return n > 0 ? n : static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

std::string LengthUnitHint(double ratio) {
  if (!(ratio > 0) || !std::isfinite(ratio)) return "";
  const double decades = std::log10(ratio);
  if (std::abs(decades - 3.0) < 0.05) return " (millimetres under metre headers?)";
  if (std::abs(decades - 2.0) < 0.05) return " (centimetres?)";
  if (std::abs(ratio / 39.37 - 1.0) < 0.05) return " (inches?)";
  if (std::abs(decades + 3.0) < 0.05) return " (kilometres?)";
  return "";
}

void CheckMagnitude(double value, double limit, const std::string& what, const std::string& unit) {
  if (std::isfinite(value) && std::abs(value) <= limit) return;
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", value);
  Throw(what, " = ", b, " ", unit, ": expected a finite value of at most ", limit, " ", unit, " in magnitude");
}

}  // namespace mcms
