// The statistics the project tests with, in one place (on boost::math): the chi-square
// distribution (consistency tests: NIS, NEES, likelihood ratios), the F and normal tails,
// and the NEES of an estimated pose against the truth. Every layer uses these; no other
// file computes a chi-square, F or normal tail or quantile.
#pragma once

#include <utility>
#include <vector>

#include "core/pose_math.h"

namespace mcms {

// X ~ chi-square with `dof` > 0 degrees of freedom.
// P(X <= x); 0 for x <= 0.
double ChiSquareCdf(double x, double dof);
// P(X > x), computed directly (not 1 - CDF), so small p-values keep their digits; 1 for x <= 0.
double ChiSquareSurvival(double x, double dof);
// The x with P(X <= x) = p, 0 <= p < 1.
double ChiSquareQuantile(double p, double dof);
// The x with P(X > x) = alpha, 0 < alpha <= 1 (a test's threshold; precise for tiny alpha).
double ChiSquareThreshold(double dof, double alpha);
// The central interval that holds X with probability p: [quantile((1 - p) / 2),
// quantile((1 + p) / 2)].
std::pair<double, double> ChiSquareBand(double dof, double p);

// P(F > x) for F ~ F(d1, d2); 1 for x <= 0.
double FisherSurvival(double x, double d1, double d2);
// P(|Z| > |z|) for Z ~ N(0, 1).
double TwoSidedNormalP(double z);
// Its inverse: the |z| ("sigma") with TwoSidedNormalP(z) = p, for p in (0, 1]; +inf for p <= 0.
double SigmaOfTwoSidedP(double p);

// The median of v by selection (nth_element; v reordered); an even count's median is the
// mean of its two middle values; NaN when v is empty.
double SelectedMedian(std::vector<double>& v);
// The p-th percentile (0..100) of v with linear interpolation between the order statistics
// (numpy's default: rank p/100 (n - 1)); v reordered; NaN when v is empty.
double Percentile(std::vector<double>& v, double p);

// The median of v and the median of the absolute deviations from it (unscaled; 1.4826
// times it estimates a normal sigma). An even count's median is the mean of its two middle
// values. Values that are all integers spanning at most 4 n + 256 (pixel values) are
// counted in `counts` (linear time, v kept); others are selected (nth_element, v
// reordered). Both give the same figures, to the bit. v must not be empty.
void MedianAndMad(std::vector<double>& v, std::vector<int>* counts, double* median, double* mad);

// Each parameter's standard deviation from an information matrix H (symmetric, positive
// semi-definite, e.g. J^T W J with the nuisance parameters marginalised): the square roots
// of the diagonal of H's inverse, and +infinity for a parameter that has a component along
// a direction H does not constrain (an eigenvalue of H scaled to unit diagonal at or below
// 1e-10 of the largest; a zero diagonal). A pseudo-inverse would report such a parameter
// as known; a Cholesky solve would report noise.
Eigen::VectorXd MarginalSigmas(const Eigen::MatrixXd& information);

// The error of an estimated pose against the truth in the project's [dtheta; dp] layout
// (docs/conventions.md): BoxMinus(estimate, truth), and its NEES e^T cov^-1 e, which is
// chi-square(6) when cov is the estimate's honest covariance.
Vec6 PoseErrorVector(const Pose& estimate, const Pose& truth);
double PoseNees(const Pose& estimate, const Pose& truth, const Mat6& cov);

}  // namespace mcms
