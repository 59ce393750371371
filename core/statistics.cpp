#include "core/statistics.h"

#include <cmath>

#include <Eigen/Cholesky>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>

#include "core/error.h"

namespace mcms {

namespace {

void CheckDof(double dof) {
  if (!(dof > 0) || !std::isfinite(dof)) Throw("chi-square: degrees of freedom must be positive, got ", dof);
}
void CheckStatistic(double x) {
  if (std::isnan(x)) Throw("chi-square: statistic is NaN");
}

}  // namespace

double ChiSquareCdf(double x, double dof) {
  CheckDof(dof);
  CheckStatistic(x);
  if (x <= 0) return 0.0;
  if (std::isinf(x)) return 1.0;
  return boost::math::cdf(boost::math::chi_squared(dof), x);
}

double ChiSquareSurvival(double x, double dof) {
  CheckDof(dof);
  CheckStatistic(x);
  if (x <= 0) return 1.0;
  if (std::isinf(x)) return 0.0;
  return boost::math::cdf(boost::math::complement(boost::math::chi_squared(dof), x));
}

double ChiSquareQuantile(double p, double dof) {
  CheckDof(dof);
  if (!(p >= 0.0 && p < 1.0)) Throw("chi-square quantile: probability must be in [0, 1), got ", p);
  if (p == 0.0) return 0.0;
  return boost::math::quantile(boost::math::chi_squared(dof), p);
}

double ChiSquareThreshold(double dof, double alpha) {
  CheckDof(dof);
  if (!(alpha > 0.0 && alpha <= 1.0)) Throw("chi-square threshold: probability must be in (0, 1], got ", alpha);
  return boost::math::quantile(boost::math::complement(boost::math::chi_squared(dof), alpha));
}

std::pair<double, double> ChiSquareBand(double dof, double p) {
  CheckDof(dof);
  if (!(p > 0.0 && p < 1.0)) Throw("chi-square band: probability must be in (0, 1), got ", p);
  const boost::math::chi_squared d(dof);
  return {boost::math::quantile(d, 0.5 * (1 - p)), boost::math::quantile(d, 0.5 * (1 + p))};
}

double FisherSurvival(double x, double d1, double d2) {
  if (!(d1 > 0 && d2 > 0)) Throw("F distribution: degrees of freedom must be positive, got ", d1, " and ", d2);
  if (!(x > 0)) return 1.0;
  return boost::math::cdf(boost::math::complement(boost::math::fisher_f(d1, d2), x));
}

double TwoSidedNormalP(double z) { return std::erfc(std::abs(z) / std::sqrt(2.0)); }

Vec6 PoseErrorVector(const Pose& estimate, const Pose& truth) { return BoxMinus(estimate, truth); }

double PoseNees(const Pose& estimate, const Pose& truth, const Mat6& cov) {
  const Vec6 e = PoseErrorVector(estimate, truth);
  return e.dot(cov.ldlt().solve(e));
}

}  // namespace mcms
