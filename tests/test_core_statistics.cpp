// The chi-square distribution against tabulated values.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/statistics.h"

namespace mcms {
namespace {

TEST(ChiSquare, MatchesTabulatedValues) {
  // Quantiles from standard tables (R: qchisq).
  EXPECT_NEAR(ChiSquareQuantile(0.95, 1), 3.841458820694124, 1e-10);
  EXPECT_NEAR(ChiSquareQuantile(0.95, 2), 5.991464547107979, 1e-10);
  EXPECT_NEAR(ChiSquareQuantile(0.95, 6), 12.591587243743977, 1e-10);
  EXPECT_NEAR(ChiSquareQuantile(0.025, 3), 0.21579528262389785, 1e-10);
  EXPECT_NEAR(ChiSquareQuantile(0.99, 300), 359.9064259503349, 1e-8);
  // Closed forms: chi2(2) is exponential with mean 2.
  for (double x : {0.1, 1.0, 2.0, 7.5, 40.0}) {
    EXPECT_NEAR(ChiSquareCdf(x, 2), 1.0 - std::exp(-x / 2), 1e-14);
    EXPECT_NEAR(ChiSquareSurvival(x, 2) / std::exp(-x / 2), 1.0, 1e-12);
  }
  // Small p-values keep their digits: P(chi2(1) > 100) = erfc(sqrt(50)).
  EXPECT_NEAR(ChiSquareSurvival(100.0, 1) / std::erfc(std::sqrt(50.0)), 1.0, 1e-10);
  EXPECT_EQ(ChiSquareCdf(0.0, 3), 0.0);
  EXPECT_EQ(ChiSquareSurvival(-1.0, 3), 1.0);
  // Round trips. At large dof the exponent -x + a ln x - lgamma(a) cancels terms of ~1e4,
  // which leaves ~1e-16 * 1e4 relative error in the CDF.
  for (double dof : {1.0, 4.0, 17.0, 6000.0})
    for (double p : {0.01, 0.5, 0.975})
      EXPECT_NEAR(ChiSquareCdf(ChiSquareQuantile(p, dof), dof), p, dof > 100 ? 1e-11 : 1e-13) << dof << " " << p;
}

TEST(ChiSquare, BadArguments) {
  EXPECT_THROW(ChiSquareCdf(1.0, 0.0), InputError);
  EXPECT_THROW(ChiSquareSurvival(NAN, 2.0), InputError);
  EXPECT_THROW(ChiSquareQuantile(1.0, 2.0), InputError);
  EXPECT_THROW(ChiSquareQuantile(-0.1, 2.0), InputError);
}

}  // namespace
}  // namespace mcms
