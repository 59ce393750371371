// The project's random numbers (core/random.h): the same sequence everywhere for a seed,
// and the distributions they claim, checked by moments with bounds of several standard
// errors (a wrong sampler misses them by far more).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "core/random.h"

namespace mcms {
namespace {

TEST(Rng, IsTheStandardMersenneTwisterSoSequencesArePortable) {
  // std::mt19937_64 is specified exactly: its 10000th output from the default seed 5489.
  Rng rng(5489);
  uint64_t x = 0;
  for (int i = 0; i < 10000; ++i) x = rng.Bits();
  EXPECT_EQ(x, 9981545732273789042ull);
  // Uniform() is the top 53 bits of the next output, scaled by 2^-53.
  Rng a(17);
  std::mt19937_64 e(17);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(a.Uniform(), std::ldexp(static_cast<double>(e() >> 11), -53));
}

TEST(Rng, SameSeedSameSequenceOtherSeedOtherSequence) {
  Rng a(42), b(42), c(43);
  int differ = 0;
  for (int i = 0; i < 1000; ++i) {
    const double x = a.Normal(), y = b.Normal(), z = c.Normal();
    EXPECT_EQ(x, y);
    differ += x != z;
    EXPECT_EQ(a.Poisson(5.0), b.Poisson(5.0));
    EXPECT_EQ(a.Uniform(-2, 3), b.Uniform(-2, 3));
  }
  EXPECT_GT(differ, 990);
}

struct Moments {
  double mean = 0, var = 0, skew = 0, kurt = 0;
};

Moments MomentsOf(const std::vector<double>& x) {
  Moments m;
  const double n = static_cast<double>(x.size());
  for (double v : x) m.mean += v / n;
  double m2 = 0, m3 = 0, m4 = 0;
  for (double v : x) {
    const double d = v - m.mean;
    m2 += d * d / n;
    m3 += d * d * d / n;
    m4 += d * d * d * d / n;
  }
  m.var = m2;
  m.skew = m3 / std::pow(m2, 1.5);
  m.kurt = m4 / (m2 * m2);
  return m;
}

TEST(Rng, UniformHasTheMomentsOfU01AndStaysInRange) {
  Rng rng(1);
  const int n = 200000;
  std::vector<double> x(n);
  for (auto& v : x) {
    v = rng.Uniform();
    ASSERT_GE(v, 0.0);
    ASSERT_LT(v, 1.0);
  }
  const Moments m = MomentsOf(x);
  // Standard errors: mean sqrt(1/12/n) = 6.5e-4, variance ~ 1.9e-4 (5 sigma bounds).
  EXPECT_NEAR(m.mean, 0.5, 5 * std::sqrt(1.0 / 12 / n));
  EXPECT_NEAR(m.var, 1.0 / 12, 5 * std::sqrt(1.0 / 180 / n));
  for (int i = 0; i < 1000; ++i) {
    const double v = rng.Uniform(-3.0, -1.0);
    ASSERT_GE(v, -3.0);
    ASSERT_LT(v, -1.0);
  }
}

TEST(Rng, NormalHasGaussianMomentsAndIndependentPairs) {
  Rng rng(2);
  const int n = 200000;
  std::vector<double> x(n);
  for (auto& v : x) v = rng.Normal();
  const Moments m = MomentsOf(x);
  // Standard errors for N(0,1): mean 1/sqrt(n), variance sqrt(2/n), skewness sqrt(6/n),
  // kurtosis sqrt(24/n).
  const double sn = std::sqrt(static_cast<double>(n));
  EXPECT_NEAR(m.mean, 0.0, 5 / sn);
  EXPECT_NEAR(m.var, 1.0, 5 * std::sqrt(2.0) / sn);
  EXPECT_NEAR(m.skew, 0.0, 5 * std::sqrt(6.0) / sn);
  EXPECT_NEAR(m.kurt, 3.0, 5 * std::sqrt(24.0) / sn);
  // The polar method returns its variates in pairs; they must be uncorrelated, both
  // within a pair (even, odd) and across pairs (odd, even).
  double within = 0, across = 0;
  for (int i = 0; i + 2 < n; i += 2) {
    within += x[i] * x[i + 1];
    across += x[i + 1] * x[i + 2];
  }
  EXPECT_NEAR(within / (n / 2), 0.0, 5 * std::sqrt(2.0) / sn);
  EXPECT_NEAR(across / (n / 2), 0.0, 5 * std::sqrt(2.0) / sn);
  // The tail: P(|x| > 3) = 0.0027.
  int tail = 0;
  for (double v : x) tail += std::abs(v) > 3;
  const double p = 0.0026998;
  EXPECT_NEAR(tail / static_cast<double>(n), p, 5 * std::sqrt(p * (1 - p) / n));
  // Scaled form.
  Rng a(3), b(3);
  for (int i = 0; i < 100; ++i) EXPECT_DOUBLE_EQ(a.Normal(2.0, 0.5), 2.0 + 0.5 * b.Normal());
}

TEST(Rng, PoissonHasMeanAndVarianceLambdaInBothRegimes) {
  Rng rng(4);
  const int n = 100000;
  // 3.5: Knuth's exact method; 30 and 400: the normal approximation.
  for (double lambda : {0.2, 3.5, 29.0, 30.0, 400.0}) {
    std::vector<double> x(n);
    for (auto& v : x) {
      v = rng.Poisson(lambda);
      ASSERT_GE(v, 0.0);
      ASSERT_EQ(v, std::round(v));
    }
    const Moments m = MomentsOf(x);
    EXPECT_NEAR(m.mean, lambda, 5 * std::sqrt(lambda / n)) << "lambda " << lambda;
    // var of the sample variance ~ (mu4 - sigma^4) / n with mu4 = lambda (1 + 3 lambda).
    const double se_var = std::sqrt((lambda * (1 + 3 * lambda) - lambda * lambda) / n);
    // The rounded normal adds 1/12 of rounding variance; within the bound for lambda >= 30.
    EXPECT_NEAR(m.var, lambda, 5 * se_var + (lambda >= 30 ? 1.0 / 12 : 0.0)) << "lambda " << lambda;
  }
  // Exact below 30: P(0) = exp(-lambda).
  int zeros = 0;
  const double lambda = 2.0, p0 = std::exp(-lambda);
  for (int i = 0; i < n; ++i) zeros += rng.Poisson(lambda) == 0;
  EXPECT_NEAR(zeros / static_cast<double>(n), p0, 5 * std::sqrt(p0 * (1 - p0) / n));
  // A zero or negative (or NaN) mean gives no events.
  EXPECT_EQ(rng.Poisson(0.0), 0.0);
  EXPECT_EQ(rng.Poisson(-1.0), 0.0);
  EXPECT_EQ(rng.Poisson(std::nan("")), 0.0);
}

}  // namespace
}  // namespace mcms
