#include "model/inverse_kinematics.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <sstream>

namespace mcms {

namespace {
constexpr double kPi = std::numbers::pi;

Eigen::VectorXd Clamped(const RobotModel& robot, Eigen::VectorXd q) {
  for (int i = 0; i < robot.NumJoints(); ++i) {
    const Joint& j = robot.Joints()[i];
    q[i] = std::clamp(q[i], j.lower, j.upper);
  }
  return q;
}
}  // namespace

std::optional<Eigen::VectorXd> SolveIk(const RobotModel& robot, const Pose& T_goal, const Eigen::VectorXd& seed,
                                       std::string* why, const IkOptions& o) {
  const int n = robot.NumJoints();
  if (seed.size() != n || !seed.allFinite()) {
    if (why) *why = "the seed has " + std::to_string(seed.size()) + " values (finite ones expected, one per joint: " +
                    std::to_string(n) + ")";
    return std::nullopt;
  }
  Eigen::VectorXd q = Clamped(robot, seed);
  Vec6 e = BoxMinus(T_goal, robot.T_base_flange(q));
  for (int it = 0; it < o.max_iterations && e.norm() >= 1e-12; ++it) {
    const Eigen::MatrixXd J = robot.Jacobian(q, RobotModel::EndFrame::kFlange);
    const Eigen::MatrixXd JJt = J * J.transpose() + o.damping * o.damping * Eigen::MatrixXd::Identity(6, 6);
    q = Clamped(robot, q + J.transpose() * JJt.ldlt().solve(e));
    e = BoxMinus(T_goal, robot.T_base_flange(q));
  }
  if (e.norm() <= o.tolerance) return q;
  if (why) {
    std::ostringstream s;
    s << "no joint configuration within the limits reaches the pose: the closest found is "
      << e.tail<3>().norm() * 1e3 << " mm and " << e.head<3>().norm() * 180.0 / kPi << " deg away";
    std::string at;
    for (int i = 0; i < n; ++i) {
      const Joint& j = robot.Joints()[i];
      if (q[i] <= j.lower || q[i] >= j.upper) at += (at.empty() ? "" : ", ") + j.name;
    }
    if (!at.empty()) s << " (on a limit: " << at << ")";
    *why = s.str();
  }
  return std::nullopt;
}

}  // namespace mcms
