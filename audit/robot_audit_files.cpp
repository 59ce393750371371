#include "audit/robot_audit.h"

#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

#include "audit/robot_audit.h"
#include "audit/tilt_sensor_audit.h"
#include "audit/robot_audit_problem.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "model/urdf.h"

namespace mcms {

using robot_audit::PositionRms;

void WriteNextPoses(const std::filesystem::path& path, const RobotAuditResult& result, const RobotModel& robot) {
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "pair";
    const auto& act = robot.ActuatedJoints();
    for (int j = 0; j < robot.NumActuated(); ++j) {
      const char* unit = act[j].type == JointType::kRevolute ? "_rad" : "_m";
      if (robot.HasMimicJoints())
        os << "," << act[j].name << unit;
      else
        os << ",q" << j + 1 << unit;
    }
    os << ",x_a_m,y_a_m,z_a_m,x_b_m,y_b_m,z_b_m,difference_mm,separation_sigma,readings_each\n";
    char b[64];
    for (const auto& np : result.next_poses)
      for (const auto& p : np.poses) {
        os << '"' << np.a << " | " << np.b << '"';
        const Eigen::VectorXd qa = robot.ActuatedValues(p.q);
        for (int j = 0; j < qa.size(); ++j) {
          std::snprintf(b, sizeof b, ",%.9g", qa[j]);
          os << b;
        }
        for (const Vec3* v : {&p.p_meas_a, &p.p_meas_b})
          for (int k = 0; k < 3; ++k) {
            std::snprintf(b, sizeof b, ",%.9g", (*v)[k]);
            os << b;
          }
        std::snprintf(b, sizeof b, ",%.6f,%.3f,%d\n", (p.p_meas_a - p.p_meas_b).norm() * 1e3, p.separation_sigma,
                      np.readings);
        os << b;
      }
  });
}

}  // namespace mcms
