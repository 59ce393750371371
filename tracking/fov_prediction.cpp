#include "tracking/fov_prediction.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/error.h"

#include "vision/triangulation.h"

namespace mcms {

CentroidCovarianceTable::CentroidCovarianceTable(std::vector<double> b_px, std::vector<double> ratios,
                                                 std::vector<double> var_major, std::vector<double> var_minor)
    : b_(std::move(b_px)), r_(std::move(ratios)), vmaj_(std::move(var_major)), vmin_(std::move(var_minor)) {
  MCMS_CHECK(!b_.empty() && !r_.empty(), "CentroidCovarianceTable: empty axis");
  MCMS_CHECK(vmaj_.size() == b_.size() * r_.size() && vmin_.size() == vmaj_.size(), "CentroidCovarianceTable: values do not match the axes");
  for (size_t i = 0; i < b_.size(); ++i)
    MCMS_CHECK(b_[i] > 0 && (i == 0 || b_[i] > b_[i - 1]), "CentroidCovarianceTable: b must be positive and increasing");
  for (size_t i = 0; i < r_.size(); ++i)
    MCMS_CHECK(r_[i] >= 1 && (i == 0 || r_[i] > r_[i - 1]), "CentroidCovarianceTable: ratios must be >= 1 and increasing");
  for (size_t i = 0; i < vmaj_.size(); ++i)
    MCMS_CHECK(vmaj_[i] > 0 && vmin_[i] > 0 && std::isfinite(vmaj_[i]) && std::isfinite(vmin_[i]), "CentroidCovarianceTable: variances must be positive and finite");
}

namespace {
// Index and weight of x on an increasing axis (clamped): value = (1-w) v[i] + w v[i+1].
void Locate(const std::vector<double>& axis, double x, bool log_axis, size_t* i, double* w) {
  if (axis.size() == 1 || x <= axis.front()) return (void)(*i = 0, *w = 0.0);
  if (x >= axis.back()) return (void)(*i = axis.size() - 2, *w = 1.0);
  const size_t k = static_cast<size_t>(std::upper_bound(axis.begin(), axis.end(), x) - axis.begin()) - 1;
  *i = k;
  *w = log_axis ? std::log(x / axis[k]) / std::log(axis[k + 1] / axis[k]) : (x - axis[k]) / (axis[k + 1] - axis[k]);
}
}  // namespace

Vec2 CentroidCovarianceTable::Variances(double b_px, double ratio) const {
  MCMS_CHECK(!empty(), "CentroidCovarianceTable: empty table");
  size_t ib = 0, ir = 0;
  double wb = 0, wr = 0;
  Locate(b_, b_px, true, &ib, &wb);
  Locate(r_, ratio, false, &ir, &wr);
  const size_t nr = r_.size();
  auto at = [&](const std::vector<double>& v, size_t i, size_t j) {
    return v[std::min(i, b_.size() - 1) * nr + std::min(j, nr - 1)];
  };
  auto interp = [&](const std::vector<double>& v) {
    // Log-linear in the variances: they span decades over b.
    const double v00 = std::log(at(v, ib, ir)), v01 = std::log(at(v, ib, ir + 1));
    const double v10 = std::log(at(v, ib + 1, ir)), v11 = std::log(at(v, ib + 1, ir + 1));
    return std::exp((1 - wb) * ((1 - wr) * v00 + wr * v01) + wb * ((1 - wr) * v10 + wr * v11));
  };
  return {interp(vmaj_), interp(vmin_)};
}

Mat2 CentroidCovarianceTable::operator()(const Ellipse& e) const {
  const double b = std::max(e.b, 1e-3);
  const Vec2 v = Variances(b, std::max(1.0, e.a / b));
  const double c = std::cos(e.angle), s = std::sin(e.angle);
  Mat2 R;
  R << c, -s, s, c;
  return R * v.asDiagonal() * R.transpose();
}

bool FovPredictionOptions::IsValid(std::string* why) const {
  if (!(border_margin_px >= 0)) return (*why = "border_margin_px must be >= 0", false);
  if (!(crowding_margin_px >= 0)) return (*why = "crowding_margin_px must be >= 0", false);
  if (outline_points < 8) return (*why = "outline_points must be >= 8", false);
  if (max_missing_balls < 0) return (*why = "max_missing_balls must be >= 0", false);
  return refinement.IsValid(why);
}

int FovPointPrediction::CamerasSeeing() const {
  int n = 0;
  for (int b : balls_in_camera) n += b > 0;
  return n;
}

BallImage PredictBallImage(const CameraModel& cam, const Vec3& centre_rig, double radius,
                           const FovPredictionOptions& options) {
  BallImage out;
  const Vec3 c = cam.T_cam_rig() * centre_rig;
  if (!(c.z() > radius) && !cam.CanProjectBehindCamera()) return out;
  const std::vector<Vec2> outline = SphereOutline(cam, c, radius, options.outline_points);
  if (outline.empty()) return out;
  const double W = cam.Width(), H = cam.Height();
  double border = INFINITY;
  for (const Vec2& q : outline) {
    if (!(q.x() >= -0.5 && q.x() <= W - 0.5 && q.y() >= -0.5 && q.y() <= H - 0.5)) return out;
    border = std::min({border, q.x() + 0.5, W - 0.5 - q.x(), q.y() + 0.5, H - 0.5 - q.y()});
  }
  out.in_front = true;
  out.border_px = border;
  out.ellipse = EllipseFromOutline(outline);
  out.centroid = SphereImageCentroid(cam, c, radius, options.outline_points);
  // The detector's window: the ellipse widened by the margin, cut by the border = dropped.
  const Ellipse& e = out.ellipse;
  const double A = e.a + options.border_margin_px, B = e.b + options.border_margin_px;
  const double co = std::cos(e.angle), si = std::sin(e.angle);
  const double wx = std::sqrt(A * A * co * co + B * B * si * si), wy = std::sqrt(A * A * si * si + B * B * co * co);
  const Vec2& m = e.centre;
  out.usable = m.x() - wx >= 0 && m.x() + wx <= W - 1 && m.y() - wy >= 0 && m.y() + wy <= H - 1;
  return out;
}

FovPointPrediction PredictFovPoint(const CameraRig& rig, const Target& target, const Pose& T_rig_target,
                                   const CentroidCovarianceFn& centre_cov, const FovPredictionOptions& options) {
  std::string why;
  MCMS_CHECK(options.IsValid(&why), "FovPredictionOptions: " + why);
  MCMS_CHECK(centre_cov, "PredictFovPoint: no centre covariance model");
  const size_t nc = rig.size(), nb = target.balls_target.size();
  FovPointPrediction out;
  out.T_rig_target = T_rig_target;
  out.balls_in_camera.assign(nc, 0);
  out.balls_in_front.assign(nc, 0);
  out.balls.resize(nb);

  // Usable image points per camera; index of ball b's point in camera c (-1: none).
  std::vector<std::vector<ImagePoint>> points(nc);
  std::vector<std::vector<int>> index(nc, std::vector<int>(nb, -1));
  std::vector<std::vector<PointObservation>> views(nb);
  double sum_px2 = 0, sum_b = 0;
  int n_obs = 0;
  for (size_t c = 0; c < nc; ++c) {
    const CameraModel& cam = rig.cameras[c];
    std::vector<BallImage> img(nb);
    for (size_t b = 0; b < nb; ++b) img[b] = PredictBallImage(cam, T_rig_target * target.balls_target[b], target.ball_radius, options);
    for (size_t b = 0; b < nb; ++b) {
      if (!img[b].in_front) continue;
      ++out.balls_in_front[c];
      if (!img[b].usable) continue;
      bool crowded = false;
      for (size_t o = 0; o < nb && !crowded; ++o)
        if (o != b && img[o].in_front)
          crowded = (img[b].ellipse.centre - img[o].ellipse.centre).norm() <
                    img[b].ellipse.a + img[o].ellipse.a + options.crowding_margin_px;
      if (crowded) continue;
      ImagePoint p;
      p.q = img[b].centroid;
      p.cov = centre_cov(img[b].ellipse);
      index[c][b] = static_cast<int>(points[c].size());
      views[b].push_back({static_cast<int>(c), index[c][b]});
      points[c].push_back(p);
      ++out.balls_in_camera[c];
      sum_px2 += 0.5 * p.cov.trace();
      sum_b += img[b].ellipse.b;
      ++n_obs;
      if (!(out.min_border_px <= img[b].border_px)) out.min_border_px = img[b].border_px;
    }
  }
  if (n_obs > 0) {
    out.mean_centre_sigma_px = std::sqrt(sum_px2 / n_obs);
    out.mean_ball_px = sum_b / n_obs;
  }

  TriangulationOptions topt;
  topt.sphere_radius_m = target.ball_radius;
  int triangulated = 0;
  for (size_t b = 0; b < nb; ++b) {
    out.balls[b].views = static_cast<int>(views[b].size());
    if (views[b].size() < 2) continue;
    const auto t = TriangulateNView(rig, points, views[b], topt);
    if (!t) continue;
    out.balls[b].triangulated = true;
    out.balls[b].cov = t->cov;
    ++triangulated;
  }
  if (triangulated < 3 || triangulated + options.max_missing_balls < static_cast<int>(nb)) return out;

  std::vector<BallObservation> obs;
  for (size_t c = 0; c < nc; ++c)
    for (size_t b = 0; b < nb; ++b)
      if (index[c][b] >= 0) {
        const ImagePoint& p = points[c][index[c][b]];
        obs.push_back({static_cast<int>(c), static_cast<int>(b), p.q, p.cov});
      }
  const PoseRefinement ref = RefinePose(rig, target, T_rig_target, obs, options.refinement);
  if (!ref.converged || !ref.cov.allFinite()) return out;
  out.trackable = true;
  out.observations = static_cast<int>(ref.kept.size());
  out.cov = ref.cov;
  return out;
}

}  // namespace mcms
