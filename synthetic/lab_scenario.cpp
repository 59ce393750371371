#include "synthetic/lab_scenario.h"

#include <numbers>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/random.h"

namespace mcms {

bool LabOptions::IsValid(std::string* why) const {
  if (points < 1) return (*why = "points must be >= 1", false);
  if (!(sphere_radius_m >= 0)) return (*why = "sphere_radius_m must be >= 0", false);
  if (!(dwell_s > 0) || !(move_s >= 0)) return (*why = "dwell_s must be positive and move_s >= 0", false);
  if (!(camera_rate_hz > 0) || !(robot_rate_hz > 0)) return (*why = "rates must be positive", false);
  if (!(dh_length_sigma_m >= 0) || !(dh_angle_sigma_rad >= 0)) return (*why = "DH error sigmas must be >= 0", false);
  return inclinometer.IsValid(why);
}

namespace {
RobotModel Perturbed(const RobotModel& nominal, const LabOptions& o, Rng& rng) {
  std::vector<Joint> joints = nominal.Joints();
  for (Joint& j : joints) {
    j.a += rng.Normal(0, o.dh_length_sigma_m);
    j.d += rng.Normal(0, o.dh_length_sigma_m);
    j.alpha += rng.Normal(0, o.dh_angle_sigma_rad);
    j.theta_offset += rng.Normal(0, o.dh_angle_sigma_rad);
  }
  return RobotModel(nominal.Name() + " (true)", nominal.Convention(), joints, nominal.T_flange_tool());
}
}  // namespace

double LabScenario::Duration() const { return options.points * (options.move_s + options.dwell_s); }

Eigen::VectorXd LabScenario::TrueJoints(double t) const {
  const double period = options.move_s + options.dwell_s;
  const int i = std::clamp(static_cast<int>(std::floor(t / period)), 0, options.points - 1);
  const double s = t - i * period;
  if (i == 0 || s >= options.move_s) return q_points[i];
  const double a = s / options.move_s;
  const double smooth = a * a * (3 - 2 * a);  // zero velocity at both ends of the move
  return q_points[i - 1] + smooth * (q_points[i] - q_points[i - 1]);
}

LabScenario MakeLabScenario(const LabOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) Throw("lab scenario options: ", why);
  LabScenario lab;
  lab.options = o;
  lab.vision = Scenario::Default();
  lab.nominal = RobotModel::Default();
  Rng rng(o.seed);
  lab.truth = Perturbed(lab.nominal, o, rng);

  // The robot stands beside the working volume so that the sphere's centre is at a
  // comfortable reach, (0.75, 0, 0.55) in the base frame; base z is up, like the rig's.
  const Vec3 centre_base(0.75, 0.0, 0.55);
  lab.T_base_rig = Pose{Mat3::Identity(), centre_base - o.sphere_centre_rig};
  lab.T_flange_target = Pose{Mat3::Identity(), Vec3(0.0, 0.0, 0.06)};
  // Flange z pointing down (the usual tool orientation), x along base +x.
  Mat3 R_down;
  R_down << 1, 0, 0, 0, -1, 0, 0, 0, -1;

  Eigen::VectorXd seed(6);
  seed << 0.0, -0.35, 0.6, 0.0, 1.3, 0.0;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const double spread = o.orientation_spread_deg * std::numbers::pi / 180.0;
  for (int i = 0; i < o.points; ++i) {
    // Fibonacci lattice: evenly spread points on the sphere.
    const double z = o.points == 1 ? 0.0 : 1.0 - 2.0 * (i + 0.5) / o.points;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const Vec3 dir(r * std::cos(golden * i), r * std::sin(golden * i), z);
    const Vec3 rot(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
    const Pose goal{ExpSO3(rot * spread / std::sqrt(3.0)) * R_down, centre_base + o.sphere_radius_m * dir};
    std::string why;
    const auto q = SolveIk(lab.nominal, goal, i == 0 ? seed : lab.q_points.back(), &why);
    if (!q) Throw("lab scenario: point ", i, " at ", goal.t.transpose(), " m is out of the robot's reach: ", why);
    // The robot is commanded with its nominal model; it really goes where the true
    // kinematics take those joints.
    lab.q_points.push_back(*q);
  }

  // Camera frames.
  const double period = o.move_s + o.dwell_s;
  lab.vision.times.clear();
  lab.vision.T_rig_target.clear();
  const Pose T_rig_base = lab.T_base_rig.Inverse();
  const int frames = static_cast<int>(std::floor(lab.Duration() * o.camera_rate_hz));
  for (int k = 0; k < frames; ++k) {
    const double t = k / o.camera_rate_hz;
    lab.vision.times.push_back(t);
    lab.vision.T_rig_target.push_back(T_rig_base * lab.TrueFlange(t) * lab.T_flange_target);
    const int i = static_cast<int>(std::floor(t / period));
    lab.point_of_frame.push_back(t - i * period >= o.move_s || i == 0 ? i : -1);
  }
  for (int i = 0; i < o.points; ++i) {
    lab.dwell_start_s.push_back(i * period + (i == 0 ? 0.0 : o.move_s));
    lab.dwell_end_s.push_back((i + 1) * period);
  }
  lab.vision.seed = o.seed;

  // Robot and inclinometer streams.
  const int nrobot = static_cast<int>(std::floor(lab.Duration() * o.robot_rate_hz));
  for (int k = 0; k < nrobot; ++k) {
    const double t = k / o.robot_rate_hz;
    Eigen::VectorXd q = lab.TrueJoints(t);
    for (int j = 0; j < q.size(); ++j) q[j] += rng.Normal(0, lab.nominal.Joints()[j].encoder_sigma);
    lab.robot_t.push_back(t);
    lab.robot_q.push_back(q);
  }
  const int nincl = static_cast<int>(std::floor(lab.Duration() / o.inclinometer.period));
  for (int k = 0; k < nincl; ++k) {
    const double t = k * o.inclinometer.period;
    const auto reading = o.inclinometer.Simulate(lab.TrueFlange(t).R, rng);
    if (!reading) continue;
    lab.incl_t.push_back(t);
    lab.incl_reading.push_back(*reading);
  }

  // Accuracy of the nominal model: Monte Carlo over robots like the true one.
  Rng mc(o.seed ^ 0x5eedULL);
  Mat6 S = Mat6::Zero();
  int n = 0;
  for (int s = 0; s < 200; ++s) {
    const RobotModel r = Perturbed(lab.nominal, o, mc);
    for (size_t i = 0; i < lab.q_points.size(); i += std::max<size_t>(1, lab.q_points.size() / 10)) {
      const Vec6 e = BoxMinus(lab.nominal.T_base_flange(lab.q_points[i]), r.T_base_flange(lab.q_points[i]));
      S += e * e.transpose();
      ++n;
    }
  }
  lab.robot_accuracy_cov = S / n;
  return lab;
}

}  // namespace mcms
