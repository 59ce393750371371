#include "model/inverse_kinematics.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"

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

bool IkOptions::IsValid(std::string* why) const {
  std::string w;
  if (max_iterations < 1 || max_iterations > 1000000)
    w = "max_iterations must be 1 to 1000000, is " + std::to_string(max_iterations);
  else if (!(damping >= 0 && damping <= 1e3))
    w = "damping must be 0 to 1000, is " + std::to_string(damping);
  else if (!(tolerance > 0 && tolerance <= 1))
    w = "tolerance must be positive and at most 1 (rad, m), is " + std::to_string(tolerance);
  if (why && !w.empty()) *why = w;
  return w.empty();
}

std::optional<Eigen::VectorXd> SolveIk(const RobotModel& robot, const Pose& T_goal, const Eigen::VectorXd& seed,
                                       std::string* why, const IkOptions& o) {
  if (std::string w; !o.IsValid(&w)) Throw("inverse kinematics options: ", w);
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
