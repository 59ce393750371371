// Simulated robot measurement logs for the robot audit's tests and benchmark: a true robot
// (every DH parameter a little off when asked, as every real robot is), the arm's own
// weight deflecting compliant joints (link masses and a payload), hidden catalog effects
// (model/extensions.h), an unknown registration and tool, anisotropic noise in a rotated
// frame, repeats over hours. Everything is drawn from the seed.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include <Eigen/Core>

#include "audit/robot_audit.h"
#include "calib/robot_calibration.h"
#include "core/random.h"
#include "model/extensions.h"
#include "model/urdf.h"
#include "tests/urdf_robots.h"

namespace mcms::test {

struct Hidden {
  Extension ext;
  std::vector<double> p;
};

struct RobotLogSpec {
  int poses = 40, repeats = 4;
  bool consecutive = false;      // repeats of a pose one after the other (else pass by pass)
  double heteroscedastic = 0.0;  // noise sigma x (1 + h * (distance from the base - 1 m) / 1 m)
  double hours = 2.0;
  Vec3 noise_mm = Vec3(0.02, 0.03, 0.05);  // per axis of a rotated frame
  double payload_kg = 5.0;
  bool payload_column = true;
  // Joint ranges of the poses (rad); empty: a working region of the KR 5 arc.
  std::vector<double> lo, hi;
  // Every DH parameter of the true robot off by N(0, sigma).
  double dh_length_sigma_m = 0.0, dh_angle_sigma_rad = 0.0;
  // The arm's own weight: per joint compliance (rad / N m, >= 0; empty = rigid) on the
  // gravity torque of `masses`' links and tool and of the payload.
  std::vector<double> compliance;
  const RobotModel* masses = nullptr;
};

struct RobotTruth {
  RobotModel robot;  // the true DH table
  Pose T_meas_base;
  Vec3 tool_t = Vec3::Zero();
  Mat3 noise_frame = Mat3::Identity();
  std::vector<Hidden> hidden;
  RobotLogSpec spec;
};

inline RobotTruth MakeTruth(const RobotModel& nominal, Rng& rng, const std::vector<Hidden>& hidden,
                            const RobotLogSpec& spec) {
  RobotTruth t{nominal, {}, {}, {}, hidden, spec};
  if (spec.dh_length_sigma_m > 0 || spec.dh_angle_sigma_rad > 0) {
    // Every geometric parameter of the error model (a DH table's a, d, alpha, theta; a URDF
    // joint's offset and placement) off by its sigma, lengths and angles in the model's order.
    Eigen::VectorXd d(nominal.NumGeometryParameters());
    for (int k = 0; k < d.size(); ++k)
      d[k] = rng.Normal(0, GeometryParameterIsAngle(nominal, k) ? spec.dh_angle_sigma_rad : spec.dh_length_sigma_m);
    t.robot = WithGeometryErrors(nominal, d);
  }
  t.T_meas_base = Pose{ExpSO3(Vec3(0.05, -0.1, 2.0) + 0.02 * Vec3(rng.Normal(), rng.Normal(), rng.Normal())),
                       Vec3(1.8, -0.4, 0.3) + 0.05 * Vec3(rng.Normal(), rng.Normal(), rng.Normal())};
  t.tool_t = nominal.T_flange_tool().t + Vec3(0.01 * rng.Normal(), 0.01 * rng.Normal(), 0.01 * rng.Normal());
  t.noise_frame = ExpSO3(Vec3(0.3, -0.2, 0.5));
  return t;
}

// Appends one measured row per pose (in order) at times t0, t0 + dt, ...
inline void AppendRows(const RobotTruth& truth, const std::vector<Eigen::VectorXd>& qs, double t0, double dt,
                       Rng& rng, RobotLog* log) {
  const RobotModel& robot = truth.robot;
  const int n = robot.NumJoints();
  const RobotLogSpec& spec = truth.spec;
  std::vector<Extension> ext;
  std::vector<const double*> params;
  for (const auto& h : truth.hidden) {
    ext.push_back(h.ext);
    params.push_back(h.p.data());
  }
  // The arm's weight: joint compliance on the gravity torque of the masses.
  std::vector<double> comp = spec.compliance;
  comp.resize(n, 0.0);
  for (int j = 0; j < n; ++j)
    if (comp[j] != 0) {
      ext.push_back({Effect::kGravityCompliance, j, 0});
      params.push_back(&comp[j]);
    }
  // The last move's direction of every joint, from the log's history.
  Eigen::VectorXd dir = Eigen::VectorXd::Zero(n);
  const auto Step = [&](const Eigen::VectorXd& from, const Eigen::VectorXd& to) {
    for (int j = 0; j < n; ++j) {
      const double d = to[j] - from[j];
      if (std::abs(d) > 1e-9) dir[j] = d > 0 ? 1 : -1;
    }
  };
  for (size_t i = 1; i < log->rows.size(); ++i) Step(log->rows[i - 1].q, log->rows[i].q);
  for (size_t k = 0; k < qs.size(); ++k) {
    const Eigen::VectorXd& q = qs[k];
    if (!log->rows.empty()) Step(log->rows.back().q, q);
    MeasurementContext c;
    c.time_s = t0 + dt * k;
    c.move_direction = dir;
    c.gravity_torque = spec.masses ? GravityTorque(*spec.masses, q, spec.payload_kg)
                                   : Eigen::VectorXd(GravityTorquePerKg(robot, q) * spec.payload_kg);
    const PoseT<double> F = ExtendedFlangeT<double>(robot, ext, params.data(), q, c);
    const Vec3 p = truth.T_meas_base.R * (F.R * truth.tool_t + F.t) + truth.T_meas_base.t;
    const double scale = 1.0 + spec.heteroscedastic * ((F.R * truth.tool_t + F.t).norm() - 1.0);
    const Vec3 e = scale * Vec3(rng.Normal() * spec.noise_mm[0], rng.Normal() * spec.noise_mm[1],
                                rng.Normal() * spec.noise_mm[2]);
    RobotMeasurement r;
    r.time_s = c.time_s;
    r.q = q;
    r.p_meas = p + truth.noise_frame * e * 1e-3;
    r.payload_kg = spec.payload_kg;
    log->rows.push_back(r);
  }
}

// Poses drawn within the spec's joint ranges.
inline std::vector<Eigen::VectorXd> DrawPoses(const RobotModel& robot, const RobotLogSpec& spec, Rng& rng) {
  const int n = robot.NumJoints();
  std::vector<double> lo = spec.lo, hi = spec.hi;
  if (lo.empty()) {
    lo = {-1.2, -1.6, 0.2, -2.5, -1.6, -3.0};
    hi = {1.2, 0.4, 2.2, 2.5, 1.6, 3.0};
  }
  std::vector<Eigen::VectorXd> poses;
  for (int i = 0; i < spec.poses; ++i) {
    Eigen::VectorXd q(n);
    for (int j = 0; j < n; ++j) q[j] = lo[j] + (hi[j] - lo[j]) * rng.Uniform();
    poses.push_back(q);
  }
  return poses;
}

// A log of `nominal`'s true counterpart with the hidden effects, reproducible from the seed.
inline RobotLog MakeRobotLog(const RobotModel& nominal, uint64_t seed, const std::vector<Hidden>& hidden,
                             const RobotLogSpec& spec = {}, RobotTruth* truth_out = nullptr) {
  Rng rng(seed);
  const std::vector<Eigen::VectorXd> poses = DrawPoses(nominal, spec, rng);
  const RobotTruth truth = MakeTruth(nominal, rng, hidden, spec);
  RobotLog log;
  log.source = "generated";
  log.has_time = true;
  log.has_payload = spec.payload_column;
  const int N = spec.poses * spec.repeats;
  std::vector<Eigen::VectorXd> order;
  for (int k = 0; k < N; ++k) order.push_back(spec.consecutive ? poses[k / spec.repeats] : poses[k % spec.poses]);
  AppendRows(truth, order, 0.0, spec.hours * 3600.0 / N, rng, &log);
  if (truth_out) *truth_out = truth;
  return log;
}

// The seven-joint robot of SevenJointUrdf as the audit's tests read it, and the joint ranges
// (and payload) of its logs.
inline RobotModel SevenJoints() { return ParseUrdf(SevenJointUrdf(), "seven.urdf", {"world", "tool"}); }
inline RobotLogSpec SevenSpec() {
  RobotLogSpec s;
  s.lo = {0.02, -1.4, -1.4, -1.4, -1.4, -1.4, -2.5};
  s.hi = {0.38, 1.4, 1.4, 1.4, 1.4, 1.4, 2.5};
  s.payload_kg = 1.0;
  return s;
}

}  // namespace mcms::test
