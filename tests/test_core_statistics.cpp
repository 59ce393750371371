// The chi-square distribution against tabulated values; the median selections; marginal sigmas.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Dense>

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

// The median and the median absolute deviation, counted for pixel values and selected
// otherwise, against a sort: the same figures to the bit (the blob detector's background
// ring depends on it), for odd and even counts, half-integer medians, wide spans (selected)
// and non-integers.
TEST(MedianAndMad, CountingAndSelectionGiveTheSortedFigures) {
  auto sorted_median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t h = v.size() / 2;
    return v.size() % 2 ? v[h] : 0.5 * (v[h - 1] + v[h]);
  };
  std::mt19937 gen(7);
  int counted = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const size_t n = 1 + gen() % 300;
    std::vector<double> v(n);
    const int kind = trial % 4;
    for (double& x : v) {
      if (kind == 0) x = 40 + static_cast<int>(gen() % 9);           // 8-bit background and noise
      if (kind == 1) x = -3 + static_cast<int>(gen() % 7);           // negative integers
      if (kind == 2) x = static_cast<int>(gen() % 65536);            // a wide span: selected
      if (kind == 3) x = (gen() % 1000) / 7.0;                       // not integers: selected
    }
    if (trial % 50 == 0) v.back() = 1e12;  // an outlier far beyond the span: selected
    const double m = sorted_median(v);
    std::vector<double> dev(n);
    for (size_t i = 0; i < n; ++i) dev[i] = std::abs(v[i] - m);
    const double mad = sorted_median(dev);
    std::vector<double> w = v;
    std::vector<int> counts;
    double got_m = -1, got_mad = -1;
    MedianAndMad(w, &counts, &got_m, &got_mad);
    EXPECT_EQ(got_m, m) << "trial " << trial << " n " << n;
    EXPECT_EQ(got_mad, mad) << "trial " << trial << " n " << n;
    counted += w == v && (kind <= 1) && trial % 50 != 0;  // counting keeps v as given
  }
  EXPECT_EQ(counted, 1000 - 20) << "integers of a small span are counted";
  std::vector<double> none;
  std::vector<int> counts;
  double m, mad;
  EXPECT_THROW(MedianAndMad(none, &counts, &m, &mad), InputError);
}

// Marginal sigmas from an information matrix: the inverse's diagonal where the matrix is
// invertible, whatever the parameters' units (scales 1e-6 .. 1e6); infinity for the
// parameters in a direction it does not constrain (two columns of J that only their sum
// reaches, a column of zeros), and the constrained one unaffected by them.
TEST(MarginalSigmas, InverseDiagonalAndInfinityWhereUnconstrained) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n01;
  Eigen::MatrixXd J(40, 4);
  for (int r = 0; r < J.rows(); ++r)
    for (int c = 0; c < J.cols(); ++c) J(r, c) = n01(rng);
  const Eigen::Vector4d units(1e-6, 1.0, 1e3, 1e6);
  const Eigen::MatrixXd Ju = J * units.asDiagonal();
  const Eigen::MatrixXd H = Ju.transpose() * Ju;
  const Eigen::VectorXd exact = H.inverse().diagonal().cwiseSqrt();
  const Eigen::VectorXd s = MarginalSigmas(H);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(s[i] / exact[i], 1.0, 1e-9) << i;

  // Columns 0 and 1 equal: only their sum is seen; column 3 never.
  Eigen::MatrixXd K = J;
  K.col(1) = K.col(0);
  K.col(3).setZero();
  const Eigen::VectorXd t = MarginalSigmas(K.transpose() * K);
  EXPECT_TRUE(std::isinf(t[0]) && std::isinf(t[1]) && std::isinf(t[3])) << t.transpose();
  // Column 2's sigma with the sum as the other parameter.
  Eigen::MatrixXd R(40, 2);
  R.col(0) = K.col(0);
  R.col(1) = K.col(2);
  EXPECT_NEAR(t[2], std::sqrt((R.transpose() * R).inverse()(1, 1)), 1e-12);

  EXPECT_THROW(MarginalSigmas(Eigen::MatrixXd::Zero(2, 3)), InputError);
  Eigen::MatrixXd bad = Eigen::MatrixXd::Identity(2, 2);
  bad(0, 1) = NAN;
  EXPECT_THROW(MarginalSigmas(bad), InputError);
}

}  // namespace
}  // namespace mcms
