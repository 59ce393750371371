#include "fusion/log_fusion.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <Eigen/Cholesky>

#include "core/error.h"
#include "core/io.h"
#include "fusion/chi_square.h"
#include "fusion/consistency.h"

namespace mcms {

namespace {

std::string Range(const std::filesystem::path& file, double first, double last) {
  char b[96];
  std::snprintf(b, sizeof b, " covers [%.6g, %.6g] s", first, last);
  return file.string() + b;
}

// The inclinometer readings within +-period/2 of t: their mean, and the model with the
// noise of that mean (sigma / sqrt(n)). nullopt when there is none.
std::optional<std::pair<Vec2, Inclinometer>> InclinometerAt(const InclinometerLog& log, double t,
                                                            const Inclinometer& model) {
  const double half = 0.5 * model.period;
  auto it = std::lower_bound(log.samples.begin(), log.samples.end(), t - half,
                             [](const InclinometerSample& s, double v) { return s.time_s < v; });
  Vec2 sum = Vec2::Zero();
  int n = 0;
  for (; it != log.samples.end() && it->time_s <= t + half; ++it, ++n) sum += it->reading;
  if (n == 0) return std::nullopt;
  Inclinometer mean_model = model;
  mean_model.sigma = model.sigma / std::sqrt(static_cast<double>(n));
  return std::make_pair(Vec2(sum / n), mean_model);
}

std::string Joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ";") + x;
  return s;
}

}  // namespace

const char* ToString(FusionMethod m) { return m == FusionMethod::kMoifa ? "moifa" : "kf"; }

void CheckTimeOverlap(const SensorLogs& logs) {
  if (!logs.robot && !logs.inclinometer)
    Throw("fusion needs the tracker log and at least one other sensor log (robot joints or inclinometer)");
  const TrackerLog& tr = logs.tracker;
  const double a0 = tr.samples.front().time_s, a1 = tr.samples.back().time_s;
  const auto check = [&](const std::filesystem::path& file, double b0, double b1) {
    if (std::max(a0, b0) > std::min(a1, b1))
      Throw("no time overlap between the sensors: ", Range(tr.source, a0, a1), " (tracked frames), ",
            Range(file, b0, b1));
  };
  if (logs.robot) check(logs.robot->source, logs.robot->samples.front().time_s, logs.robot->samples.back().time_s);
  if (logs.inclinometer)
    check(logs.inclinometer->source, logs.inclinometer->samples.front().time_s,
          logs.inclinometer->samples.back().time_s);
}

PoseWithCovariance CameraFlangePose(const Pose& T_rig_target, const Mat6& covariance_rig, const FusionSetup& setup) {
  return CameraFlangePose(CellGeometry{setup.T_base_rig, setup.T_base_rig_covariance, setup.T_flange_target},
                          T_rig_target, covariance_rig);
}

PoseWithCovariance RobotFlangePose(const Eigen::VectorXd& q, const FusionSetup& setup) {
  PoseWithCovariance out =
      RobotFlangePose(setup.robot, q, setup.robot.EncoderCovariance(), setup.robot_accuracy_covariance);
  if (out.covariance.llt().info() != Eigen::Success || !(out.covariance.diagonal().minCoeff() > 0))
    Throw("robot '", setup.robot.Name(), "': its pose covariance is singular; give encoder sigmas in the robot file or ",
          "robot_accuracy in the setup file ", setup.source.string());
  return out;
}

std::vector<FusedSample> FuseLogsMoifa(const SensorLogs& logs, const FusionSetup& setup) {
  CheckTimeOverlap(logs);
  ConsistencyOptions copt;
  copt.significance = setup.consistency_significance;
  std::vector<FusedSample> out;
  for (const TrackerSample& s : logs.tracker.samples) {
    std::vector<PoseMeasurement> full;
    const PoseWithCovariance cam = CameraFlangePose(s.T_rig_target, s.covariance, setup);
    full.push_back(PoseMeasurement::FromCovariance("camera", cam.T, cam.covariance));
    Eigen::VectorXd q;
    if (logs.robot && logs.robot->Interpolate(s.time_s, &q)) {
      const PoseWithCovariance rob = RobotFlangePose(q, setup);
      full.push_back(PoseMeasurement::FromCovariance("robot", rob.T, rob.covariance));
    }
    FusedPose fused = FusePoses(full);
    std::vector<PoseMeasurement> all = full;
    if (logs.inclinometer) {
      if (const auto incl = InclinometerAt(*logs.inclinometer, s.time_s, setup.inclinometer)) {
        // Linearize at the other sensors' fused orientation, then once more at the result:
        // the constraint is first order in the orientation error.
        for (int pass = 0; pass < 2; ++pass) {
          if (!incl->second.InRange(fused.T.R)) break;
          all = full;
          all.push_back(
              PoseMeasurement::FromOrientation("inclinometer", incl->second.Constraint(incl->first, fused.T.R)));
          fused = FusePoses(all);
        }
      }
    }
    FusedSample r;
    r.frame = s.frame;
    r.time_s = s.time_s;
    r.method = FusionMethod::kMoifa;
    r.T_base_flange = fused.T;
    r.covariance = fused.covariance;
    for (const auto& m : all) r.sensors.push_back(m.name);
    const ConsistencyReport rep = CheckConsistency(all, copt);
    r.dof = rep.dof;
    r.p_value = rep.p_value;
    for (const auto& sc : rep.sensors)
      if (sc.flagged) r.flagged.push_back(sc.name);
    out.push_back(std::move(r));
  }
  return out;
}

std::vector<FusedSample> FuseLogsKalman(const SensorLogs& logs, const FusionSetup& setup) {
  CheckTimeOverlap(logs);
  enum Kind { kRobot = 0, kIncl = 1, kCamera = 2 };
  static const char* const kName[3] = {"robot", "inclinometer", "camera"};
  struct Event {
    double t;
    Kind kind;
    size_t index;
  };
  std::vector<Event> events;
  const double t_end = logs.tracker.samples.back().time_s;
  for (size_t i = 0; i < logs.tracker.samples.size(); ++i)
    events.push_back({logs.tracker.samples[i].time_s, kCamera, i});
  if (logs.robot)
    for (size_t i = 0; i < logs.robot->samples.size(); ++i)
      if (logs.robot->samples[i].time_s <= t_end) events.push_back({logs.robot->samples[i].time_s, kRobot, i});
  if (logs.inclinometer)
    for (size_t i = 0; i < logs.inclinometer->samples.size(); ++i)
      if (logs.inclinometer->samples[i].time_s <= t_end)
        events.push_back({logs.inclinometer->samples[i].time_s, kIncl, i});
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.t < b.t || (a.t == b.t && a.kind < b.kind); });

  PoseKalmanFilter kf(setup.kalman);
  double nis[3] = {0, 0, 0};
  int dof[3] = {0, 0, 0};
  bool used[3] = {false, false, false};
  const auto note = [&](Kind k, const PoseKalmanFilter::UpdateResult& u) {
    used[k] = true;
    if (u.accepted) {
      nis[k] += u.nis;
      dof[k] += u.dof;
    }
  };
  std::vector<FusedSample> out;
  for (const Event& e : events) {
    if (e.kind == kIncl) {
      // Needs an orientation to linearize at, and one the sensor can read.
      if (!kf.Initialized() || !setup.inclinometer.InRange(kf.Predict(e.t).T.R)) continue;
      note(kIncl, kf.UpdateInclinometer(e.t, logs.inclinometer->samples[e.index].reading, setup.inclinometer));
      continue;
    }
    PoseWithCovariance m;
    if (e.kind == kRobot) {
      m = RobotFlangePose(logs.robot->samples[e.index].q, setup);
    } else {
      const TrackerSample& s = logs.tracker.samples[e.index];
      m = CameraFlangePose(s.T_rig_target, s.covariance, setup);
    }
    if (!kf.Initialized()) {
      kf.Initialize(e.t, m.T, m.covariance);
      used[e.kind] = true;
    } else {
      note(e.kind, kf.UpdatePose(e.t, m.T, m.covariance));
    }
    if (e.kind != kCamera) continue;
    const TrackerSample& s = logs.tracker.samples[e.index];
    FusedSample r;
    r.frame = s.frame;
    r.time_s = s.time_s;
    r.method = FusionMethod::kKalman;
    r.T_base_flange = kf.PoseEstimate();
    r.covariance = kf.PoseCovariance();
    double total = 0.0;
    for (int k = 0; k < 3; ++k) {
      if (used[k]) r.sensors.push_back(kName[k]);
      total += nis[k];
      r.dof += dof[k];
      if (dof[k] > 0 && ChiSquareSurvival(nis[k], dof[k]) < setup.consistency_significance)
        r.flagged.push_back(kName[k]);
    }
    // Camera first, as in the MOIFA rows.
    std::rotate(r.sensors.rbegin(), r.sensors.rbegin() + 1, r.sensors.rend());
    r.p_value = r.dof > 0 ? ChiSquareSurvival(total, r.dof) : 1.0;
    out.push_back(std::move(r));
    for (int k = 0; k < 3; ++k) {
      nis[k] = 0;
      dof[k] = 0;
      used[k] = false;
    }
  }
  return out;
}

void WriteFusedPoseCsv(const std::filesystem::path& path, const std::vector<FusedSample>& samples) {
  static const char* kAxes[6] = {"rx", "ry", "rz", "px", "py", "pz"};
  WriteFileAtomically(path, [&](std::ostream& o) {
    o << "frame,time_s,method,x_m,y_m,z_m,qw,qx,qy,qz,sensors,dof,p_value,flagged";
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) o << ",cov_" << kAxes[r] << "_" << kAxes[c];
    o << "\n";
    char buf[64];
    const auto num = [&](double v) {
      std::snprintf(buf, sizeof buf, "%.12g", v);
      return std::string(buf);
    };
    for (const FusedSample& s : samples) {
      const auto q = s.T_base_flange.Quaternion();
      const Vec3& t = s.T_base_flange.t;
      o << s.frame << "," << num(s.time_s) << "," << ToString(s.method) << "," << num(t.x()) << "," << num(t.y())
        << "," << num(t.z()) << "," << num(q.w()) << "," << num(q.x()) << "," << num(q.y()) << "," << num(q.z())
        << "," << Joined(s.sensors) << "," << s.dof << "," << num(s.p_value) << "," << Joined(s.flagged);
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) o << "," << num(s.covariance(r, c));
      o << "\n";
    }
  });
}

}  // namespace mcms
