// The chi-square distribution, for consistency tests (NIS, NEES, disagreement between
// sensors). Own implementation of the regularized incomplete gamma function (series and
// Lentz continued fraction, Numerical Recipes 6.2), accurate to ~1e-14 relative, so
// that no statistics library is needed.
#pragma once

namespace mcms {

// P(X <= x) for X ~ chi-square with `dof` > 0 degrees of freedom; 0 for x <= 0.
double ChiSquareCdf(double x, double dof);
// P(X > x), computed directly (not 1 - CDF) so small p-values keep their digits.
double ChiSquareSurvival(double x, double dof);
// The x with ChiSquareCdf(x, dof) = p, for 0 <= p < 1 (bisection to the last digit).
double ChiSquareQuantile(double p, double dof);

}  // namespace mcms
