// The residual tests of the robot audit: each fit's whitened residuals against the
// covariates of the log (time, each joint's angle, gravity torque, move direction,
// temperature), the lack of fit of the repeated poses, at a family-wise false-alarm rate.
// Internal to the robot audit (audit/robot_audit.h).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "audit/audit_report.h"
#include "audit/robot_audit_problem.h"
#include "model/robot_measurements.h"
#include "model/robot_model.h"

namespace mcms::robot_audit {

// A joint as reports name it: "joint 3", or a URDF chain's joint by its name.
std::string JointText(const RobotModel& robot, int j);

// The covariate an effect depends on, for plots.
std::string CovariateOf(const RobotModel& robot, const Extension& e, bool has_temperature);

// One covariate of the log's rows, by name.
struct Covariate {
  std::string name;
  std::vector<double> v;
};
std::vector<Covariate> Covariates(const RobotModel& robot, const RobotLog& log, const Problem& s);

// Residual tests of a fit (the nominal one; the final one for what remains unexplained).
// Returns the lack-of-fit statistic (chi-square per dof of the pose means against the
// scatter of the repeats), NaN without repeats. `num_tests`: how many tests were run.
double TestResiduals(const RobotLog& log, const Problem& s, const FitResult& nominal, const std::vector<Covariate>& cov,
                     double alpha, int num_params, const Eigen::VectorXd& repeat_tolerance, AuditReport* rep,
                     int* num_tests = nullptr, int* num_failed = nullptr);

}  // namespace mcms::robot_audit
