#include "synthetic/lab_experiment.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "fusion/kalman.h"
#include "fusion/moifa.h"
#include "synthetic/evaluation.h"

namespace mcms {

namespace {

void Score(PointEstimate* e, const Pose& truth) {
  e->error = BoxMinus(e->T, truth);
  e->nees = e->error.dot(e->cov.ldlt().solve(e->error));
}

LabMethodSummary Summarize(const std::string& name, const std::vector<PointEstimate>& v, bool with_nees) {
  LabMethodSummary s;
  s.name = name;
  double p2 = 0, t2 = 0, y2 = 0, nees = 0, sum = 0, sum2 = 0;
  for (const auto& e : v) {
    if (!e.valid) continue;
    ++s.points;
    const double p = e.error.tail<3>().norm();
    p2 += p * p;
    sum += p;
    sum2 += p * p;
    t2 += e.error.head<2>().squaredNorm();
    y2 += e.error[2] * e.error[2];
    nees += e.nees;
  }
  if (s.points == 0) return s;
  const double n = s.points;
  s.position_rms_m = std::sqrt(p2 / n);
  const double mean = sum / n, var = std::max(0.0, sum2 / n - mean * mean) * n / std::max(1.0, n - 1);
  s.position_3sigma_m = mean + 3 * std::sqrt(var);
  s.tilt_rms_rad = std::sqrt(t2 / n);
  s.yaw_rms_rad = std::sqrt(y2 / n);
  if (with_nees) {
    s.mean_nees = nees / n;
    Chi2Band(6 * n, 0.95, &s.nees_band_lo, &s.nees_band_hi);
    s.nees_band_lo /= n;
    s.nees_band_hi /= n;
  }
  return s;
}

}  // namespace

LabResult RunLabExperiment(const LabScenario& lab, const std::vector<FrameResult>& tracked,
                           const LabExperimentOptions& options) {
  const int np = lab.options.points;
  LabResult r;
  r.methods = {"camera", "robot", "MOIFA", "KF"};
  r.estimates.assign(4, std::vector<PointEstimate>(np));
  const Pose T_target_flange = lab.T_flange_target.Inverse();

  // Camera poses as flange poses in the base frame, with their covariances.
  auto camera_flange = [&](const FrameResult& f, Pose* T, Mat6* cov) {
    *T = lab.T_base_rig * *f.T_rig_target * T_target_flange;
    *cov = TransformPoseCovariance(f.cov, lab.T_base_rig, *f.T_rig_target, T_target_flange);
  };

  for (int i = 0; i < np; ++i) {
    const double t0 = lab.dwell_start_s[i], t1 = lab.dwell_end_s[i];
    const Pose truth = lab.TrueFlange(0.5 * (t0 + t1));
    r.truth.push_back(truth);
    // Camera: every tracked frame of the dwell, fused (a minimum-variance average).
    std::vector<PoseMeasurement> cam;
    for (size_t k = 0; k < tracked.size(); ++k) {
      if (lab.point_of_frame[k] != i || !tracked[k].T_rig_target) continue;
      Pose T;
      Mat6 C;
      camera_flange(tracked[k], &T, &C);
      cam.push_back(PoseMeasurement::FromCovariance("camera frame " + std::to_string(k), T, C));
    }
    PointEstimate& ce = r.estimates[0][i];
    if (!cam.empty()) {
      const FusedPose f = FusePoses(cam);
      ce = {true, f.T, f.covariance};
      Score(&ce, truth);
    }
    // Robot: mean encoder reading over the dwell, nominal model.
    Eigen::VectorXd qsum = Eigen::VectorXd::Zero(lab.nominal.NumJoints());
    int nq = 0;
    for (size_t k = 0; k < lab.robot_t.size(); ++k)
      if (lab.robot_t[k] >= t0 && lab.robot_t[k] < t1) {
        qsum += lab.robot_q[k];
        ++nq;
      }
    PointEstimate& re = r.estimates[1][i];
    if (nq > 0) {
      const Eigen::VectorXd q = qsum / nq;
      re.valid = true;
      re.T = lab.nominal.T_base_flange(q);
      const Eigen::MatrixXd Q = lab.nominal.EncoderCovariance() / nq;
      re.cov = lab.nominal.PoseCovariance(q, Q, RobotModel::EndFrame::kFlange) + lab.robot_accuracy_cov;
      Score(&re, truth);
    }
    // Inclinometer: mean reading over the dwell, its noise reduced accordingly.
    Vec2 rsum = Vec2::Zero();
    int nr = 0;
    for (size_t k = 0; k < lab.incl_t.size(); ++k)
      if (lab.incl_t[k] >= t0 && lab.incl_t[k] < t1) {
        rsum += lab.incl_reading[k];
        ++nr;
      }
    std::vector<PoseMeasurement> all;
    if (ce.valid) all.push_back(PoseMeasurement::FromCovariance("camera", ce.T, ce.cov));
    if (re.valid) all.push_back(PoseMeasurement::FromCovariance("robot", re.T, re.cov));
    if (nr > 0) {
      Inclinometer incl = lab.options.inclinometer;
      incl.sigma /= std::sqrt(static_cast<double>(nr));
      const Vec2 mean = rsum / nr;
      const Mat3 R_lin = ce.valid ? ce.T.R : re.T.R;
      all.push_back(PoseMeasurement::FromOrientation("inclinometer", incl.Constraint(mean, R_lin)));
      r.incl_tilt_error_rad.push_back((mean - lab.options.inclinometer.Predict(truth.R)).norm());
    }
    PointEstimate& me = r.estimates[2][i];
    if (all.size() >= 2 || (all.size() == 1 && (ce.valid || re.valid))) {
      const FusedPose f = FusePoses(all);
      me = {true, f.T, f.covariance};
      Score(&me, truth);
    }
  }

  // The multi-sensor KF over each dwell's time-ordered streams. The controller knows
  // when the robot stands still, so the filter runs in its static mode there (velocity
  // known to be zero, process noise from the options) and restarts at each dwell from the
  // dwell's first camera frame; a constant-velocity model across the 1 s stop-and-go moves
  // would have to carry process noise so large that every static point is smeared.
  struct Event {
    double t;
    int kind;  // 0 camera, 1 robot, 2 inclinometer
    size_t index;
  };
  std::vector<Event> events;
  for (size_t k = 0; k < tracked.size(); ++k)
    if (tracked[k].T_rig_target && lab.point_of_frame[k] >= 0) events.push_back({tracked[k].time_s, 0, k});
  for (size_t k = 0; k < lab.robot_t.size(); ++k) events.push_back({lab.robot_t[k], 1, k});
  for (size_t k = 0; k < lab.incl_t.size(); ++k) events.push_back({lab.incl_t[k], 2, k});
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) { return a.t < b.t; });
  double nis_sum[3] = {0, 0, 0};
  int nis_dof[3] = {0, 0, 0};
  size_t e0 = 0;
  for (int i = 0; i < np; ++i) {
    const double t0 = lab.dwell_start_s[i], t1 = lab.dwell_end_s[i];
    while (e0 < events.size() && events[e0].t < t0) ++e0;
    PoseKalmanOptions ko;
    ko.angular_acceleration_psd = options.kf_angular_psd;
    ko.linear_acceleration_psd = options.kf_linear_psd;
    ko.initial_angular_velocity_sigma = 1e-10;
    ko.initial_linear_velocity_sigma = 1e-10;
    PoseKalmanFilter kf(ko);
    int robot_samples = 0;
    for (size_t k = e0; k < events.size() && events[k].t < t1; ++k) robot_samples += events[k].kind == 1;
    const Mat6 robot_model_cov =
        lab.robot_accuracy_cov * (options.inflate_robot_for_correlation ? std::max(1, robot_samples) : 1);
    for (size_t k = e0; k < events.size() && events[k].t < t1; ++k) {
      const Event& e = events[k];
      PoseKalmanFilter::UpdateResult u;
      if (e.kind == 0) {
        Pose T;
        Mat6 C;
        camera_flange(tracked[e.index], &T, &C);
        if (!kf.Initialized()) {
          kf.Initialize(e.t, T, C);
          continue;
        }
        u = kf.UpdatePose(e.t, T, C);
      } else if (!kf.Initialized()) {
        continue;  // waits for the dwell's first camera frame
      } else if (e.kind == 1) {
        u = kf.UpdateRobot(e.t, lab.nominal, lab.robot_q[e.index], robot_model_cov);
      } else {
        u = kf.UpdateInclinometer(e.t, lab.incl_reading[e.index], lab.options.inclinometer);
      }
      nis_sum[e.kind] += u.nis;
      nis_dof[e.kind] += u.dof;
    }
    if (kf.Initialized()) {
      const auto pred = kf.Predict(std::max(kf.Time(), t1));
      PointEstimate& ke = r.estimates[3][i];
      ke = {true, pred.T, pred.covariance};
      Score(&ke, r.truth[i]);
    }
  }
  for (int k = 0; k < 3; ++k) r.kf_nis_mean.push_back(nis_dof[k] ? nis_sum[k] / nis_dof[k] : 0.0);
  for (size_t m = 0; m < r.methods.size(); ++m) r.summary.push_back(Summarize(r.methods[m], r.estimates[m], true));
  return r;
}

std::string FormatLabTable(const LabResult& r) {
  std::string out;
  char buf[512];
  std::snprintf(buf, sizeof(buf), "%-8s %6s %12s %12s %10s %12s %12s %10s %s\n", "method", "points", "pos RMS mm",
                "pos 3sig mm", "reduction", "tilt RMS deg", "yaw RMS deg", "mean NEES", "95% band");
  out += buf;
  const double cam3 = r.summary.empty() ? 0 : r.summary[0].position_3sigma_m;
  for (const auto& s : r.summary) {
    const double red = cam3 > 0 ? 100.0 * (1.0 - s.position_3sigma_m / cam3) : 0.0;
    std::snprintf(buf, sizeof(buf), "%-8s %6d %12.4f %12.4f %9.1f%% %12.5f %12.5f %10.2f [%.2f, %.2f]\n",
                  s.name.c_str(), s.points, 1e3 * s.position_rms_m, 1e3 * s.position_3sigma_m, red,
                  s.tilt_rms_rad * 180 / M_PI, s.yaw_rms_rad * 180 / M_PI, s.mean_nees, s.nees_band_lo, s.nees_band_hi);
    out += buf;
  }
  if (!r.incl_tilt_error_rad.empty()) {
    double s2 = 0;
    for (double e : r.incl_tilt_error_rad) s2 += e * e;
    std::snprintf(buf, sizeof(buf),
                  "inclinometer alone: tilt reading RMS error %.5f deg (dwell mean); yaw: not observable\n",
                  std::sqrt(s2 / r.incl_tilt_error_rad.size()) * 180 / M_PI);
    out += buf;
  }
  if (r.kf_nis_mean.size() == 3) {
    std::snprintf(buf, sizeof(buf), "KF mean NIS per dof: camera %.3f, robot %.3f, inclinometer %.3f (1 when consistent)\n",
                  r.kf_nis_mean[0], r.kf_nis_mean[1], r.kf_nis_mean[2]);
    out += buf;
  }
  out += "reduction = 1 - (method's 3-sigma position error) / (camera's), as the paper reports it\n";
  out += "On static points the KF with a static model and MOIFA use the same information and agree; the paper's\n"
         "larger KF reduction (78.2 % in its simulation) comes from averaging many samples over time, not from\n"
         "fusing sensors (see `mcms paper fusion`). The robot's NEES is low because its kinematic error is one\n"
         "draw, correlated over the points, of the distribution its covariance describes.\n";
  return out;
}

}  // namespace mcms
