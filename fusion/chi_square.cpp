#include "fusion/chi_square.h"

#include <cmath>
#include <limits>

#include "core/error.h"

namespace mcms {

namespace {

constexpr double kEps = 1e-16;
constexpr double kTiny = 1e-300;

// Regularized lower incomplete gamma P(a, x) by its series; converges fast for x < a + 1.
double GammaPSeries(double a, double x) {
  double ap = a, sum = 1.0 / a, del = sum;
  for (int n = 0; n < 100000; ++n) {
    ap += 1.0;
    del *= x / ap;
    sum += del;
    if (std::abs(del) < std::abs(sum) * kEps) break;
  }
  return sum * std::exp(-x + a * std::log(x) - std::lgamma(a));
}

// Regularized upper incomplete gamma Q(a, x) by its continued fraction (modified Lentz);
// converges fast for x >= a + 1.
double GammaQContinuedFraction(double a, double x) {
  double b = x + 1.0 - a, c = 1.0 / kTiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < kEps) break;
  }
  return std::exp(-x + a * std::log(x) - std::lgamma(a)) * h;
}

void CheckDof(double dof) {
  if (!(dof > 0) || !std::isfinite(dof)) Throw("chi-square: degrees of freedom must be positive, got ", dof);
}

}  // namespace

double ChiSquareCdf(double x, double dof) {
  CheckDof(dof);
  if (std::isnan(x)) Throw("chi-square: statistic is NaN");
  if (x <= 0) return 0.0;
  if (std::isinf(x)) return 1.0;
  const double a = 0.5 * dof, z = 0.5 * x;
  return z < a + 1.0 ? GammaPSeries(a, z) : 1.0 - GammaQContinuedFraction(a, z);
}

double ChiSquareSurvival(double x, double dof) {
  CheckDof(dof);
  if (std::isnan(x)) Throw("chi-square: statistic is NaN");
  if (x <= 0) return 1.0;
  if (std::isinf(x)) return 0.0;
  const double a = 0.5 * dof, z = 0.5 * x;
  return z < a + 1.0 ? 1.0 - GammaPSeries(a, z) : GammaQContinuedFraction(a, z);
}

double ChiSquareQuantile(double p, double dof) {
  CheckDof(dof);
  if (!(p >= 0.0 && p < 1.0)) Throw("chi-square quantile: probability must be in [0, 1), got ", p);
  if (p == 0.0) return 0.0;
  double lo = 0.0, hi = dof + 10.0 * std::sqrt(2.0 * dof) + 10.0;
  while (ChiSquareCdf(hi, dof) < p) hi *= 2.0;
  // Bisection to the last representable digit.
  for (int i = 0; i < 2000; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    (ChiSquareCdf(mid, dof) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace mcms
