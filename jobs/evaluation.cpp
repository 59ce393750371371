#include "jobs/evaluation.h"

#include <numbers>
#include <cmath>
#include <cstdio>
#include <tuple>

#include "core/pose_math.h"
#include "core/error.h"
#include "core/io.h"
#include "core/statistics.h"

namespace mcms {

void Chi2Band(double dof, double p, double* lo, double* hi) { std::tie(*lo, *hi) = ChiSquareBand(dof, p); }

FramePoseError PoseErrorAccumulator::Add(const FrameResult& f, const Pose& truth) {
  ++s_.frames;
  if (f.status == FrameStatus::kOk) ++s_.ok;
  if (f.status == FrameStatus::kDegraded) ++s_.degraded;
  if (f.status == FrameStatus::kLost) ++s_.lost;
  FramePoseError fe;
  if (!f.T_rig_target) return fe;
  const Vec6 e = PoseErrorVector(*f.T_rig_target, truth);
  fe.e = e;
  ++s_.evaluated;
  fe.position_m = e.tail<3>().norm();
  fe.rotation_rad = e.head<3>().norm();
  fe.nees = PoseNees(*f.T_rig_target, truth, f.cov);
  p2_ += fe.position_m * fe.position_m;
  r2_ += fe.rotation_rad * fe.rotation_rad;
  s_.position_max_m = std::max(s_.position_max_m, fe.position_m);
  s_.rotation_max_rad = std::max(s_.rotation_max_rad, fe.rotation_rad);
  nees_ += fe.nees;
  pp_ += f.cov.bottomRightCorner<3, 3>().trace();
  pr_ += f.cov.topLeftCorner<3, 3>().trace();
  dt_ += truth.t.norm();
  de_ += f.T_rig_target->t.norm();
  constexpr double kFar = 30 * std::numbers::pi / 180, kClose = 2 * std::numbers::pi / 180;
  if (fe.rotation_rad > kFar) {
    ++s_.rotation_far;
    if (RotationAngle(f.T_rig_target->R, RotationReadScalarLast(Eigen::Quaterniond(truth.R))) < kClose)
      ++s_.rotation_far_but_scalar_last_close;
  }
  return fe;
}

PoseErrorSummary PoseErrorAccumulator::Summary() const {
  PoseErrorSummary s = s_;
  if (s.evaluated > 0) {
    const double n = s.evaluated;
    s.position_rms_m = std::sqrt(p2_ / n);
    s.rotation_rms_rad = std::sqrt(r2_ / n);
    s.mean_nees = nees_ / n;
    s.predicted_position_rms_m = std::sqrt(pp_ / n);
    s.predicted_rotation_rms_rad = std::sqrt(pr_ / n);
    Chi2Band(6 * n, 0.95, &s.nees_band_lo, &s.nees_band_hi);
    s.nees_band_lo /= n;
    s.nees_band_hi /= n;
    if (de_ > 0) s.truth_to_estimate_distance = dt_ / de_;
  }
  return s;
}

void CheckTruthDistances(const PoseErrorSummary& s, const std::string& truth_file) {
  const double r = s.truth_to_estimate_distance;
  if (s.evaluated == 0 || (r >= 0.2 && r <= 5)) return;
  const bool mm = r > 300 && r < 3000;
  Throw("truth file ", truth_file, ": its positions are on average ", r, " times as far from the rig as the tracked ",
        "ones over ", s.evaluated, " frames", mm ? " (millimetres under metre headers?)" : "",
        "; give the truth of this recording in metres (columns x_m, y_m, z_m)");
}

void CheckTruthRotations(const PoseErrorSummary& s, const std::string& truth_file) {
  if (s.evaluated < 3 || s.rotation_far_but_scalar_last_close * 5 < s.evaluated * 4) return;
  Throw("truth file ", truth_file, ": on ", s.rotation_far, " of ", s.evaluated, " frames its rotations are more than ",
        "30 deg from the tracked ones, but its quaternions read as x, y, z, w (scalar last) agree within 2 deg on ",
        s.rotation_far_but_scalar_last_close, ": quaternions in x, y, z, w order? expected qw, qx, qy, qz");
}

PoseErrorSummary EvaluatePoses(const std::vector<FrameResult>& results, const std::vector<Pose>& truth) {
  PoseErrorAccumulator acc;
  for (size_t i = 0; i < results.size(); ++i) {
    if (results[i].T_rig_target)
      acc.Add(results[i], truth.at(i));
    else
      acc.Add(results[i], Pose());
  }
  return acc.Summary();
}

std::map<size_t, TruthPose> ReadTruthPoses(const std::filesystem::path& path) {
  const CsvTable t = ReadCsv(path);
  const char* names[9] = {"frame", "time_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz"};
  int col[9];
  for (int k = 0; k < 9; ++k) col[k] = t.Column(names[k]);
  if (t.rows.empty()) Throw("truth file ", path.string(), " has a header but no rows");
  std::map<size_t, TruthPose> out;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    double v[9];
    for (int k = 0; k < 9; ++k) v[k] = t.Number(r, col[k]);
    if (v[0] < 0 || v[0] != std::floor(v[0]) || v[0] > 1e15)
      Throw("truth file ", path.string(), " line ", t.line_of_row[r], ", column 'frame': ", t.rows[r][col[0]],
            " is not a frame number (a non-negative integer)");
    const Eigen::Quaterniond q(v[5], v[6], v[7], v[8]);
    if (!(std::abs(q.norm() - 1.0) <= 1e-4))
      Throw("truth file ", path.string(), " line ", t.line_of_row[r], ": quaternion (qw,qx,qy,qz) has norm ", q.norm(),
            ", expected a unit quaternion");
    const size_t frame = static_cast<size_t>(v[0]);
    TruthPose p;
    p.time_s = v[1];
    p.T_rig_target = Pose::FromQuaternion(q.normalized(), Vec3(v[2], v[3], v[4]));
    if (!out.emplace(frame, p).second)
      Throw("truth file ", path.string(), " line ", t.line_of_row[r], ": frame ", frame, " appears twice");
  }
  return out;
}

std::string FormatSummary(const PoseErrorSummary& s) {
  char buf[1024];
  std::snprintf(buf, sizeof(buf),
                "frames: %d (ok %d, degraded %d, lost %d), evaluated %d\n"
                "position error: RMS %.4f mm (predicted %.4f mm), max %.4f mm\n"
                "rotation error: RMS %.5f deg (predicted %.5f deg), max %.5f deg\n"
                "pose NEES: mean %.3f, 95%% band for an honest covariance [%.3f, %.3f] -> %s\n",
                s.frames, s.ok, s.degraded, s.lost, s.evaluated, 1e3 * s.position_rms_m,
                1e3 * s.predicted_position_rms_m, 1e3 * s.position_max_m, s.rotation_rms_rad * 180 / std::numbers::pi,
                s.predicted_rotation_rms_rad * 180 / std::numbers::pi, s.rotation_max_rad * 180 / std::numbers::pi, s.mean_nees,
                s.nees_band_lo, s.nees_band_hi, s.NeesInBand() ? "consistent" : "NOT consistent");
  return buf;
}

}  // namespace mcms
