#include "core/statistics.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
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

Eigen::VectorXd MarginalSigmas(const Eigen::MatrixXd& information) {
  const Eigen::MatrixXd& H = information;
  const Eigen::Index n = H.rows();
  if (H.cols() != n || !H.allFinite())
    Throw("MarginalSigmas: information must be a finite square matrix, got ", H.rows(), "x", H.cols());
  constexpr double kInf = std::numeric_limits<double>::infinity();
  Eigen::VectorXd sigma = Eigen::VectorXd::Constant(n, kInf);
  // Scaled to unit diagonal, so that the rank threshold does not depend on the units.
  std::vector<Eigen::Index> kept;
  for (Eigen::Index i = 0; i < n; ++i)
    if (H(i, i) > 0) kept.push_back(i);
  const Eigen::Index m = static_cast<Eigen::Index>(kept.size());
  if (m == 0) return sigma;
  Eigen::VectorXd d(m);
  for (Eigen::Index i = 0; i < m; ++i) d[i] = 1 / std::sqrt(H(kept[i], kept[i]));
  Eigen::MatrixXd S(m, m);
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < m; ++j) S(i, j) = 0.5 * (H(kept[i], kept[j]) + H(kept[j], kept[i])) * d[i] * d[j];
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(S);
  const Eigen::VectorXd& ev = es.eigenvalues();
  const Eigen::MatrixXd& V = es.eigenvectors();
  const double floor = 1e-10 * ev[m - 1];
  for (Eigen::Index i = 0; i < m; ++i) {
    double var = 0, null_part = 0;
    for (Eigen::Index k = 0; k < m; ++k) {
      const double v2 = V(i, k) * V(i, k);
      if (ev[k] > floor)
        var += v2 / ev[k];
      else
        null_part += v2;
    }
    // A parameter outside every unconstrained direction has a component there of the
    // eigen-solver's rounding (~1e-16 squared); one inside has a share of order one.
    if (null_part < 1e-8) sigma[kept[i]] = std::sqrt(var) * d[i];
  }
  return sigma;
}

double SigmaOfTwoSidedP(double p) {
  if (!(p > 0)) return std::numeric_limits<double>::infinity();
  if (p >= 1) return 0.0;
  double lo = 0.0, hi = 40.0;
  for (int it = 0; it < 200 && hi - lo > 1e-12; ++it) {
    const double mid = 0.5 * (lo + hi);
    (TwoSidedNormalP(mid) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double SelectedMedian(std::vector<double>& v) {
  if (v.empty()) return std::nan("");
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(h), v.end());
  const double upper = v[h];
  if (v.size() % 2) return upper;
  const double lower = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(h));
  return 0.5 * (lower + upper);
}

double Percentile(std::vector<double>& v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const double r = std::clamp(p, 0.0, 100.0) / 100.0 * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(r)), hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (r - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

namespace {

// The bins holding ranks (n - 1) / 2 and n / 2 of the counts c[0..bins).
void MiddleBins(const int* c, int bins, size_t n, int* a, int* b) {
  const size_t lo_rank = (n - 1) / 2, hi_rank = n / 2;
  size_t seen = 0;
  *a = *b = -1;
  for (int i = 0; i < bins && *b < 0; ++i) {
    seen += static_cast<size_t>(c[i]);
    if (*a < 0 && seen > lo_rank) *a = i;
    if (seen > hi_rank) *b = i;
  }
}

// MedianAndMad by counting; false (nothing computed) when v is not integers of a small span.
bool CountedMedianAndMad(const std::vector<double>& v, std::vector<int>* counts, double* median, double* mad) {
  const size_t n = v.size();
  const auto [lo_it, hi_it] = std::minmax_element(v.begin(), v.end());
  const double lo = *lo_it, hi = *hi_it;
  if (!(hi - lo <= 4.0 * static_cast<double>(n) + 256.0) || !(std::abs(lo) < 1e9)) return false;
  const int base = static_cast<int>(lo), bins = static_cast<int>(hi - lo) + 1;
  // counts[0, bins): the values from base; counts[bins, 3 bins): twice the deviations.
  counts->assign(3 * static_cast<size_t>(bins), 0);
  int* values = counts->data();
  int* twice_dev = values + bins;
  for (const double x : v) {
    const int k = static_cast<int>(x) - base;
    if (static_cast<double>(k + base) != x) return false;
    ++values[k];
  }
  // The arithmetic of SelectedMedian on the same values: exact for integers and halves.
  int a, b;
  MiddleBins(values, bins, n, &a, &b);
  const double va = a + base, vb = b + base;
  *median = n % 2 ? vb : 0.5 * (va + vb);
  const int twice_m = static_cast<int>(2 * *median) - 2 * base;  // |2 x - 2 median| < 2 bins
  for (int k = 0; k < bins; ++k)
    if (values[k]) twice_dev[std::abs(2 * k - twice_m)] += values[k];
  MiddleBins(twice_dev, 2 * bins, n, &a, &b);
  const double da = a * 0.5, db = b * 0.5;
  *mad = n % 2 ? db : 0.5 * (da + db);
  return true;
}

}  // namespace

void MedianAndMad(std::vector<double>& v, std::vector<int>* counts, double* median, double* mad) {
  if (v.empty()) Throw("MedianAndMad: no values");
  if (CountedMedianAndMad(v, counts, median, mad)) return;
  *median = SelectedMedian(v);
  for (double& x : v) x = std::abs(x - *median);
  *mad = SelectedMedian(v);
}

}  // namespace mcms
