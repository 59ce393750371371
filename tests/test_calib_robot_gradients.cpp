// The robot calibration's cost function against numeric derivatives (ceres::GradientChecker),
// for 3-D and 6-D measurements, standard and modified DH, with error-motion harmonics.
#include <gtest/gtest.h>

#include <ceres/cost_function.h>
#include <ceres/gradient_checker.h>

#include "calib/robot_calibration.h"
#include "model/robot_model.h"

namespace mcms {
namespace {

void ExpectCostMatchesNumericDerivatives(const RobotModel& robot, bool six_d, const std::vector<int>& harmonics) {
  RobotCalibrationOptions o;
  o.error_motion_harmonics = harmonics;
  RobotMeasurement m;
  m.q = (Eigen::VectorXd(6) << 0.2, -1.1, 0.9, 0.3, 0.8, -0.4).finished();
  const Pose base0{ExpSO3(Vec3(0.01, -0.02, 0.5)), Vec3(1.2, -0.3, 0.4)};
  const Pose truth = base0 * robot.T_base_tool(m.q);
  m.p_meas = truth.t + Vec3(1e-4, -2e-4, 3e-4);
  if (six_d) m.R_meas_tool = ExpSO3(Vec3(1e-3, 0.0, -1e-3)) * truth.R;
  const std::unique_ptr<ceres::CostFunction> cost = MakeRobotMeasurementCost(robot, base0, m, o);
  const int n = NumCalibrationParameters(robot, o);
  ASSERT_EQ(cost->parameter_block_sizes().size(), 1u);
  ASSERT_EQ(cost->parameter_block_sizes()[0], n);
  EXPECT_EQ(cost->num_residuals(), six_d ? 6 : 3);
  // Away from zero, so that every term (including the error motion's) is exercised.
  std::vector<double> x(n);
  for (int k = 0; k < n; ++k) x[k] = 1e-4 * std::sin(1.0 + 2.3 * k);
  const double* blocks[1] = {x.data()};
  ceres::NumericDiffOptions numeric;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(cost.get(), no_manifolds, numeric);
  ceres::GradientChecker::ProbeResults results;
  EXPECT_TRUE(checker.Probe(blocks, 1e-6, &results)) << results.error_log;
  EXPECT_GT(results.jacobians[0].norm(), 0.0);
}

TEST(CalibRobotGradients, StandardDhPositions) {
  ExpectCostMatchesNumericDerivatives(RobotModel::Default(), false, {});
}

TEST(CalibRobotGradients, StandardDhPosesWithErrorMotion) {
  ExpectCostMatchesNumericDerivatives(RobotModel::Default(), true, {0, 2, 0, 0, 0, 1});
}

TEST(CalibRobotGradients, ModifiedDhPosesWithErrorMotion) {
  const RobotModel kr5 = RobotModel::Default();
  const RobotModel modified("modified", ChainConvention::kModified, kr5.Joints(), kr5.T_flange_tool());
  ExpectCostMatchesNumericDerivatives(modified, true, {1, 0, 0, 0, 0, 0});
}

}  // namespace
}  // namespace mcms
