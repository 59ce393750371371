// Small clean fusion logs for the command-line tests of `mcms fuse` (test_app_fuse,
// test_app_inputs): the tracker's poses, joint and inclinometer logs and the setup of one
// cell with the default robot, nearly noise-free.
#pragma once

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/pose_math.h"
#include "model/inclinometer.h"
#include "model/robot_model.h"

namespace mcms::test {

using Lines = std::vector<std::string>;

// %.17g: every double exactly.
inline std::string N(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

// Small clean logs: 20 camera frames at 10 Hz from 0.2 s, joints at 100 Hz and the
// inclinometer at 50 Hz from 0 to 2.2 s, default robot, nearly noise-free readings.
struct Logs {
  std::map<std::string, Lines> files;  // poses.csv, joints.csv, incl.csv, setup.yaml
};

inline Logs CleanLogs() {
  const RobotModel robot = RobotModel::Default();
  Eigen::VectorXd q0(6);
  q0 << 0.1, -0.4, 0.6, 0.2, 0.7, 0.1;
  const auto q_at = [&](double t) {
    Eigen::VectorXd q = q0;
    for (int j = 0; j < 6; ++j) q[j] += 0.1 * std::sin((0.3 + 0.1 * j) * t + j);
    return q;
  };
  Pose T_base_rig;
  T_base_rig.R = ExpSO3(Vec3(0.0, 0.0, 0.4));
  T_base_rig.t = Vec3(2.0, -1.0, 0.5);
  Pose T_flange_target;
  T_flange_target.t = Vec3(0.0, 0.0, 0.1);
  Inclinometer incl;
  incl.R_flange_incl = robot.T_base_flange(q0).R.transpose();
  const Eigen::Quaterniond qi(incl.R_flange_incl);
  const auto qr = T_base_rig.Quaternion();

  Logs l;
  l.files["setup.yaml"] = {
      "T_base_rig:",
      "  translation_m: [2.0, -1.0, 0.5]",
      "  quaternion_wxyz: [" + N(qr.w()) + ", " + N(qr.x()) + ", " + N(qr.y()) + ", " + N(qr.z()) + "]",
      "  sigma_rotation_rad: 1e-6",
      "  sigma_translation_m: 1e-6",
      "T_flange_target:",
      "  translation_m: [0, 0, 0.1]",
      "  quaternion_wxyz: [1, 0, 0, 0]",
      "inclinometer:",
      "  quaternion_wxyz: [" + N(qi.w()) + ", " + N(qi.x()) + ", " + N(qi.y()) + ", " + N(qi.z()) + "]",
      "  sigma_deg: 0.01",
      "robot_accuracy:",
      "  position_sigma_m: [2e-5, 2e-5, 2e-5]",
      "  orientation_sigma_deg: 0.001",
  };
  Lines& j = l.files["joints.csv"];
  j.push_back("time_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg");
  for (int k = 0; k <= 220; ++k) {
    const Eigen::VectorXd q = q_at(k / 100.0);
    std::string row = N(k / 100.0);
    for (int i = 0; i < 6; ++i) (row += ",") += N(q[i] * 180.0 / 3.14159265358979323846);
    j.push_back(row);
  }
  Lines& in = l.files["incl.csv"];
  in.push_back("time_s,tilt_x_rad,tilt_y_rad");
  for (int k = 0; k <= 110; ++k) {
    const Vec2 r = incl.Predict(robot.T_base_flange(q_at(2 * k / 100.0)).R);
    in.push_back(N(2 * k / 100.0) + "," + N(r.x()) + "," + N(r.y()));
  }
  Lines& p = l.files["poses.csv"];
  std::string header = "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz";
  const char* ax[6] = {"rx", "ry", "rz", "px", "py", "pz"};
  for (auto& a : ax)
    for (auto& b : ax) header += std::string(",cov_") + a + "_" + b;
  p.push_back(header);
  for (int m = 0; m < 20; ++m) {
    const double t = (20 + 10 * m) / 100.0;
    const Pose T = T_base_rig.Inverse() * robot.T_base_flange(q_at(t)) * T_flange_target;
    const auto q = T.Quaternion();
    std::string row = std::to_string(m) + "," + N(t) + ",ok,\"\"," + N(T.t.x()) + "," + N(T.t.y()) + "," +
                      N(T.t.z()) + "," + N(q.w()) + "," + N(q.x()) + "," + N(q.y()) + "," + N(q.z());
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) (row += ",") += N(r != c ? 0.0 : r < 3 ? 1e-8 : 1e-9);
    p.push_back(row);
  }
  return l;
}

inline void Write(const std::filesystem::path& dir, const Logs& l) {
  for (const auto& [name, lines] : l.files) {
    std::ofstream o(dir / name);
    for (const auto& s : lines) o << s << "\n";
  }
}

}  // namespace mcms::test
