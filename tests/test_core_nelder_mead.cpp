// The simplex minimiser the repeatability analysis fits its variance components with.
#include <gtest/gtest.h>

#include <cmath>

#include "core/nelder_mead.h"

namespace mcms {
namespace {

TEST(NelderMead, FindsTheMinimumOfRosenbrocksValley) {
  int calls = 0;
  const auto rosenbrock = [&](const std::vector<double>& x) {
    ++calls;
    return 100 * std::pow(x[1] - x[0] * x[0], 2) + std::pow(1 - x[0], 2);
  };
  double f = 0;
  std::vector<double> x = {-1.2, 1.0};
  for (int r = 0; r < 3; ++r) x = NelderMead(rosenbrock, x, r == 0 ? 1.0 : 0.3, 3000, &f);
  EXPECT_NEAR(x[0], 1.0, 1e-4);
  EXPECT_NEAR(x[1], 1.0, 2e-4);
  EXPECT_LT(f, 1e-8);
  EXPECT_GT(calls, 50);
}

TEST(NelderMead, AQuadraticBowlInFourDimensionsAndNoParameters) {
  const std::vector<double> centre = {0.3, -2.0, 5.0, 1e-3};
  const auto bowl = [&](const std::vector<double>& x) {
    double s = 0;
    for (size_t i = 0; i < x.size(); ++i) s += (i + 1) * (x[i] - centre[i]) * (x[i] - centre[i]);
    return s + 7.0;
  };
  double f = 0;
  const std::vector<double> x = NelderMead(bowl, {0, 0, 0, 0}, 1.0, 5000, &f);
  for (size_t i = 0; i < 4; ++i) EXPECT_NEAR(x[i], centre[i], 1e-3) << i;
  EXPECT_NEAR(f, 7.0, 1e-6);
  // Never worse than where it started, and with nothing to vary it evaluates once.
  EXPECT_LE(f, bowl({0, 0, 0, 0}));
  const std::vector<double> none = NelderMead([](const std::vector<double>&) { return 3.5; }, {}, 1.0, 10, &f);
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(f, 3.5);
}

}  // namespace
}  // namespace mcms
