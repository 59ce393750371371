#include "synthetic/evaluation.h"

#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <cstdio>

namespace mcms {

void Chi2Band(double dof, double p, double* lo, double* hi) {
  const boost::math::chi_squared d(dof);
  *lo = boost::math::quantile(d, 0.5 * (1 - p));
  *hi = boost::math::quantile(d, 0.5 * (1 + p));
}

PoseErrorSummary EvaluatePoses(const std::vector<FrameResult>& results, const std::vector<Pose>& truth) {
  PoseErrorSummary s;
  double p2 = 0, r2 = 0, nees = 0, pp = 0, pr = 0;
  for (size_t i = 0; i < results.size(); ++i) {
    const FrameResult& f = results[i];
    ++s.frames;
    if (f.status == FrameStatus::kOk) ++s.ok;
    if (f.status == FrameStatus::kDegraded) ++s.degraded;
    if (f.status == FrameStatus::kLost) ++s.lost;
    if (!f.T_rig_target) continue;
    const Vec6 e = BoxMinus(*f.T_rig_target, truth.at(i));
    ++s.evaluated;
    const double ep = e.tail<3>().norm(), er = e.head<3>().norm();
    p2 += ep * ep;
    r2 += er * er;
    s.position_max_m = std::max(s.position_max_m, ep);
    s.rotation_max_rad = std::max(s.rotation_max_rad, er);
    nees += e.dot(f.cov.ldlt().solve(e));
    pp += f.cov.bottomRightCorner<3, 3>().trace();
    pr += f.cov.topLeftCorner<3, 3>().trace();
  }
  if (s.evaluated > 0) {
    const double n = s.evaluated;
    s.position_rms_m = std::sqrt(p2 / n);
    s.rotation_rms_rad = std::sqrt(r2 / n);
    s.mean_nees = nees / n;
    s.predicted_position_rms_m = std::sqrt(pp / n);
    s.predicted_rotation_rms_rad = std::sqrt(pr / n);
    Chi2Band(6 * n, 0.95, &s.nees_band_lo, &s.nees_band_hi);
    s.nees_band_lo /= n;
    s.nees_band_hi /= n;
  }
  return s;
}

std::string FormatSummary(const PoseErrorSummary& s) {
  char buf[1024];
  std::snprintf(buf, sizeof(buf),
                "frames: %d (ok %d, degraded %d, lost %d), evaluated %d\n"
                "position error: RMS %.4f mm (predicted %.4f mm), max %.4f mm\n"
                "rotation error: RMS %.5f deg (predicted %.5f deg), max %.5f deg\n"
                "pose NEES: mean %.3f, 95%% band for an honest covariance [%.3f, %.3f] -> %s\n",
                s.frames, s.ok, s.degraded, s.lost, s.evaluated, 1e3 * s.position_rms_m,
                1e3 * s.predicted_position_rms_m, 1e3 * s.position_max_m, s.rotation_rms_rad * 180 / M_PI,
                s.predicted_rotation_rms_rad * 180 / M_PI, s.rotation_max_rad * 180 / M_PI, s.mean_nees,
                s.nees_band_lo, s.nees_band_hi, s.NeesInBand() ? "consistent" : "NOT consistent");
  return buf;
}

}  // namespace mcms
