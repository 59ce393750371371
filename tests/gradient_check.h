// Checks a templated cost functor's autodiff Jacobian against Ceres' numeric one (Ridders'
// method) at one point: one parameter block of n values, m residuals.
#pragma once

#include <gtest/gtest.h>

#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/gradient_checker.h>

#include <vector>

#include <Eigen/Core>

namespace mcms::test {

// Returns the autodiff Jacobian (m x n) so that a caller can test its columns. A Jacobian
// that is zero everywhere would pass trivially: it must depend on x.
template <typename F>
Eigen::MatrixXd ExpectGradientsMatch(const F& functor, int n, int m, std::vector<double> x, double precision = 1e-6) {
  SCOPED_TRACE(testing::Message() << n << " parameters, " << m << " residuals");
  ceres::DynamicAutoDiffCostFunction<F, 8> cost(new F(functor));
  cost.AddParameterBlock(n);
  cost.SetNumResiduals(m);
  // GradientChecker differentiates by Ridders' method; its default first step (1e-2, not
  // relative to small parameters) spans a strongly curved range of units such as the
  // compliance and error-motion ones (tens of mrad of joint motion), where the
  // extrapolation fails.
  ceres::NumericDiffOptions numeric;
  numeric.ridders_relative_initial_step_size = 1e-3;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(&cost, no_manifolds, numeric);
  ceres::GradientChecker::ProbeResults results;
  const double* blocks[1] = {x.data()};
  EXPECT_TRUE(checker.Probe(blocks, precision, &results)) << results.error_log;
  if (results.jacobians.empty()) return Eigen::MatrixXd::Zero(m, n);
  EXPECT_GT(results.jacobians[0].norm(), 0.0);
  return results.jacobians[0];
}

}  // namespace mcms::test
