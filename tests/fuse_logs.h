// Fusion logs for the command-line and library tests of `mcms fuse` and `mcms audit
// fusion` (test_app_fuse, test_app_inputs, test_app_audit_fusion): the tracker's poses,
// joint and inclinometer logs and the setup of one cell with the default robot, the robot
// moving every joint on a sine. One generator, two uses:
//  - CleanLogs(): small nearly noise-free logs (2.2 s);
//  - MovingLogs(o): longer logs with the tracker's and the inclinometer's noise and
//    hidden effects (a late joint log, an inclinometer bias, misalignment or clock offset).
#pragma once

#include <numbers>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/pose_math.h"
#include "core/random.h"
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

struct Logs {
  std::map<std::string, Lines> files;  // poses.csv, joints.csv, incl.csv, setup.yaml
};

struct LogOptions {
  // Motion: q_j(t) = q0_j + amplitude sin((frequency + frequency_step j) t + j).
  std::vector<double> q0{0.1, -0.4, 0.6, 0.2, 0.7, 0.1};
  double amplitude = 0.1, frequency = 0.3, frequency_step = 0.1;
  // Joints at 100 Hz from 0 to joint_end_s (columns in deg or rad), inclinometer at 50 Hz
  // from 0 to incl_end_s, `frames` tracker frames every frame_period_s from frame_start_s.
  double joint_end_s = 2.2, incl_end_s = 2.2;
  bool joints_deg = true;
  int frames = 20;
  double frame_start_s = 0.2, frame_period_s = 0.1;
  // Noise (0 = none): the tracker's rotation (rad) and position (m) per axis, written
  // into its covariance (else 1e-8 rad^2, 1e-9 m^2); the inclinometer's reading noise is
  // the setup's sigma (0.01 deg) when incl_noise is set.
  uint64_t seed = 1;
  double tracker_sigma_rotation = 0.0, tracker_sigma_position = 0.0;
  bool incl_noise = false;
  // Hidden effects: the joint log's stamps late by joint_late_s; the inclinometer's
  // readings biased, its mount rotated by Exp(incl_misalignment) (flange frame), its
  // stamps late by incl_late_s (clock_offset = +incl_late_s: a reading stamped t was
  // taken at t + incl_late_s on the tracker's clock).
  double joint_late_s = 0.0;
  Vec2 incl_bias = Vec2::Zero();
  Vec3 incl_misalignment = Vec3::Zero();
  double incl_late_s = 0.0;
  bool with_incl = true;
};

inline Logs MovingLogs(const LogOptions& o) {
  const RobotModel robot = RobotModel::Default();
  Eigen::VectorXd q0(6);
  for (int j = 0; j < 6; ++j) q0[j] = o.q0[j];
  const auto q_at = [&](double t) {
    Eigen::VectorXd q = q0;
    for (int j = 0; j < 6; ++j) q[j] += o.amplitude * std::sin((o.frequency + o.frequency_step * j) * t + j);
    return q;
  };
  Pose T_base_rig;
  T_base_rig.R = ExpSO3(Vec3(0.0, 0.0, 0.4));
  T_base_rig.t = Vec3(2.0, -1.0, 0.5);
  Pose T_flange_target;
  T_flange_target.t = Vec3(0.0, 0.0, 0.1);
  Inclinometer incl;  // as the setup says: level at q0
  incl.R_flange_incl = robot.T_base_flange(q0).R.transpose();
  const Eigen::Quaterniond qi(incl.R_flange_incl);
  const auto qr = T_base_rig.Quaternion();
  Rng rng(o.seed);

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
  j.push_back(o.joints_deg ? "time_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg"
                           : "time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad");
  const int nj = static_cast<int>(std::lround(o.joint_end_s * 100));
  for (int k = 0; k <= nj; ++k) {
    const Eigen::VectorXd q = q_at(k / 100.0 - o.joint_late_s);  // stamped late: an earlier moment's value
    std::string row = N(k / 100.0);
    for (int i = 0; i < 6; ++i) (row += ",") += N(o.joints_deg ? q[i] * 180.0 / std::numbers::pi : q[i]);
    j.push_back(row);
  }
  if (o.with_incl) {
    Inclinometer truth = incl;
    truth.bias = o.incl_bias;
    truth.R_flange_incl = ExpSO3(o.incl_misalignment) * incl.R_flange_incl;
    Lines& in = l.files["incl.csv"];
    in.push_back("time_s,tilt_x_rad,tilt_y_rad");
    const int ni = static_cast<int>(std::lround(o.incl_end_s * 50));
    for (int k = 0; k <= ni; ++k) {
      const Mat3 R = robot.T_base_flange(q_at(k / 50.0 + o.incl_late_s)).R;
      Vec2 r = truth.Predict(R);
      if (o.incl_noise) r += Vec2(rng.Normal(), rng.Normal()) * truth.sigma;
      if (!truth.InRange(R)) continue;  // saturated: no reading
      in.push_back(N(k / 50.0) + "," + N(r.x()) + "," + N(r.y()));
    }
  }
  Lines& p = l.files["poses.csv"];
  std::string header = "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz";
  const char* ax[6] = {"rx", "ry", "rz", "px", "py", "pz"};
  for (auto& a : ax)
    for (auto& b : ax) header += std::string(",cov_") + a + "_" + b;
  p.push_back(header);
  const double sr = o.tracker_sigma_rotation, sp = o.tracker_sigma_position;
  const double vr = sr > 0 ? sr * sr : 1e-8, vp = sp > 0 ? sp * sp : 1e-9;
  const double start_ms = std::round(o.frame_start_s * 1000), period_ms = std::round(o.frame_period_s * 1000);
  for (int m = 0; m < o.frames; ++m) {
    const double t = (start_ms + m * period_ms) / 1000.0;
    Pose T = T_base_rig.Inverse() * robot.T_base_flange(q_at(t)) * T_flange_target;
    if (sr > 0) T.R = ExpSO3(Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * sr) * T.R;
    if (sp > 0) T.t += Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * sp;
    const auto q = T.Quaternion();
    std::string row = std::to_string(m) + "," + N(t) + ",ok,\"\"," + N(T.t.x()) + "," + N(T.t.y()) + "," +
                      N(T.t.z()) + "," + N(q.w()) + "," + N(q.x()) + "," + N(q.y()) + "," + N(q.z());
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) (row += ",") += N(r != c ? 0.0 : r < 3 ? vr : vp);
    p.push_back(row);
  }
  return l;
}

// Small clean logs: 20 camera frames at 10 Hz from 0.2 s, joints at 100 Hz and the
// inclinometer at 50 Hz from 0 to 2.2 s, default robot, nearly noise-free readings.
inline Logs CleanLogs() { return MovingLogs(LogOptions{}); }

// 40 s of larger motion (joints +-0.4 rad, in rad), 400 tracker frames at 10 Hz from
// 0.5 s with the tracker's noise (5e-5 rad, 3e-5 m) and the inclinometer's (0.01 deg).
inline LogOptions AuditLogOptions(uint64_t seed) {
  LogOptions o;
  o.q0 = {0.1, -0.6, 0.9, 0.2, 0.7, 0.1};
  o.amplitude = 0.4;
  o.frequency = 0.15;
  o.frequency_step = 0.05;
  o.joint_end_s = 41.0;
  o.incl_end_s = 41.0;
  o.joints_deg = false;
  o.frames = 400;
  o.frame_start_s = 0.5;
  o.frame_period_s = 0.1;
  o.seed = seed;
  o.tracker_sigma_rotation = 5e-5;
  o.tracker_sigma_position = 3e-5;
  o.incl_noise = true;
  return o;
}

inline void Write(const std::filesystem::path& dir, const Logs& l) {
  for (const auto& [name, lines] : l.files) {
    std::ofstream o(dir / name);
    for (const auto& s : lines) o << s << "\n";
  }
}

}  // namespace mcms::test
