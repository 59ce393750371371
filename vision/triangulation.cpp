#include "vision/triangulation.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include "vision/sphere_projection.h"

namespace mcms {

bool TriangulationOptions::IsValid(std::string* why) const {
  if (!(sphere_radius_m >= 0)) return (*why = "sphere_radius_m must be >= 0", false);
  if (max_iterations < 1) return (*why = "max_iterations must be >= 1", false);
  if (bias_outline_points < 8) return (*why = "bias_outline_points must be >= 8", false);
  return true;
}

bool MatchingOptions::IsValid(std::string* why) const {
  if (!(gate_px > 0) || !(gate_sigma > 0)) return (*why = "gate_px and gate_sigma must be positive", false);
  if (min_views < 2) return (*why = "min_views must be >= 2", false);
  if (!(max_chi2_per_dof > 0)) return (*why = "max_chi2_per_dof must be positive", false);
  return triangulation.IsValid(why);
}

Mat2 WhiteningOf(const Mat2& cov) {
  // cov = L_c L_c^T (lower); whitening W = L_c^-1 satisfies W^T W = cov^-1.
  Eigen::LLT<Mat2> llt(cov);
  return llt.matrixL().solve(Mat2::Identity());
}

namespace {

// The predicted measurement of a point (the centre's projection, or the sphere
// image's centroid) and its Jacobian with respect to p_rig (the bias's own
// derivative is second order in r/|c| and left out).
Vec2 Predict(const CameraModel& cam, const Vec3& p_rig, double radius, int outline_points,
             Eigen::Matrix<double, 2, 3>* dq_dprig) {
  const Vec3 p_cam = cam.T_cam_rig() * p_rig;
  Eigen::Matrix<double, 2, 3> dq_dpcam;
  Vec2 q = cam.Project(p_cam, dq_dprig ? &dq_dpcam : nullptr);
  if (dq_dprig) *dq_dprig = dq_dpcam * cam.T_cam_rig().R;
  if (radius > 0) q += SphereProjectionBias(cam, p_cam, radius, outline_points);
  return q;
}

bool InFront(const CameraModel& cam, const Vec3& p_rig, double min_depth) {
  const Vec3 p_cam = cam.T_cam_rig() * p_rig;
  return cam.CanProjectBehindCamera() ? p_cam.norm() > min_depth : p_cam.z() > min_depth;
}

std::optional<Vec3> RayInRig(const CameraModel& cam, const Vec2& q, Vec3* origin) {
  const auto d = cam.Unproject(q);
  if (!d) return std::nullopt;
  const Pose T_rig_cam = cam.T_cam_rig().Inverse();
  *origin = T_rig_cam.t;
  return T_rig_cam.R * *d;
}

// Least-squares point nearest to all rays; nullopt when the rays are nearly parallel.
// n rays (origins[i], dirs[i]); pointers so that matching's pairs need no allocation.
std::optional<Vec3> NearestPointToRays(const Vec3* origins, const Vec3* dirs, size_t n) {
  Mat3 A = Mat3::Zero();
  Vec3 b = Vec3::Zero();
  for (size_t i = 0; i < n; ++i) {
    const Mat3 P = Mat3::Identity() - dirs[i] * dirs[i].transpose();
    A += P;
    b += P * origins[i];
  }
  // Two unit rays at an angle t give A the eigenvalues 1 - |cos t|, 1 + |cos t| and 2: far
  // from the threshold below (1 - |cos t| > 1e-6) the eigen-decomposition cannot decide
  // otherwise and is skipped (matching calls this for every pair of image points).
  const bool clearly_apart = n == 2 && std::abs(dirs[0].squaredNorm() - 1) < 1e-9 &&
                             std::abs(dirs[1].squaredNorm() - 1) < 1e-9 &&
                             1 - std::abs(dirs[0].dot(dirs[1])) > 1e-6;
  if (!clearly_apart) {
    Eigen::SelfAdjointEigenSolver<Mat3> es(A);
    if (es.eigenvalues()[0] < 1e-8 * es.eigenvalues()[2] || es.eigenvalues()[0] < 1e-10) return std::nullopt;
  }
  return A.ldlt().solve(b);
}

// TriangulateNView with the rays of the observations (origin and direction in the rig
// frame, one per observation) already computed.
std::optional<TriangulatedPoint> TriangulateFromRays(const CameraRig& rig,
                                                     const std::vector<std::vector<ImagePoint>>& points,
                                                     const std::vector<PointObservation>& obs,
                                                     const TriangulationOptions& options,
                                                     const std::vector<Vec3>& origins, const std::vector<Vec3>& dirs);

}  // namespace

std::optional<TriangulatedPoint> TriangulateNView(const CameraRig& rig,
                                                  const std::vector<std::vector<ImagePoint>>& points,
                                                  const std::vector<PointObservation>& obs,
                                                  const TriangulationOptions& options) {
  if (obs.size() < 2) return std::nullopt;
  std::vector<Vec3> origins, dirs;
  for (const auto& o : obs) {
    Vec3 c;
    const auto d = RayInRig(rig.cameras[o.camera], points[o.camera][o.index].q, &c);
    if (!d) return std::nullopt;
    origins.push_back(c);
    dirs.push_back(*d);
  }
  return TriangulateFromRays(rig, points, obs, options, origins, dirs);
}

namespace {

std::optional<TriangulatedPoint> TriangulateFromRays(const CameraRig& rig,
                                                     const std::vector<std::vector<ImagePoint>>& points,
                                                     const std::vector<PointObservation>& obs,
                                                     const TriangulationOptions& options,
                                                     const std::vector<Vec3>& origins, const std::vector<Vec3>& dirs) {
  auto p0 = NearestPointToRays(origins.data(), dirs.data(), dirs.size());
  if (!p0) return std::nullopt;
  Vec3 p = *p0;
  std::vector<Mat2> W(obs.size());
  for (size_t k = 0; k < obs.size(); ++k) W[k] = WhiteningOf(points[obs[k].camera][obs[k].index].cov);

  // Normal equations at p: H = sum Jw^T Jw, g = sum Jw^T rw, whitened chi-square and the
  // sum of squared pixel residuals; false when p is behind a camera.
  Mat3 H = Mat3::Zero();
  Vec3 g = Vec3::Zero();
  double chi2 = 0, sq = 0;
  const auto normal_equations = [&](const Vec3& at) {
    H.setZero();
    g.setZero();
    chi2 = sq = 0;
    for (size_t k = 0; k < obs.size(); ++k) {
      const CameraModel& cam = rig.cameras[obs[k].camera];
      if (!InFront(cam, at, 1e-3)) return false;
      Eigen::Matrix<double, 2, 3> J;
      const Vec2 e = points[obs[k].camera][obs[k].index].q -
                     Predict(cam, at, options.sphere_radius_m, options.bias_outline_points, &J);
      const Vec2 r = W[k] * e;
      const Eigen::Matrix<double, 2, 3> Jw = W[k] * J;
      H += Jw.transpose() * Jw;
      g += Jw.transpose() * r;
      chi2 += r.squaredNorm();
      sq += e.squaredNorm();
    }
    return true;
  };
  for (int it = 0; it < options.max_iterations; ++it) {
    if (!normal_equations(p)) return std::nullopt;
    const Vec3 step = H.ldlt().solve(g);
    if (!step.allFinite()) return std::nullopt;
    p += step;
    if (step.norm() < 1e-10) break;
  }
  // Final residuals and covariance at the solution.
  if (!normal_equations(p)) return std::nullopt;
  TriangulatedPoint t;
  t.p_rig = p;
  t.cov = H.inverse();
  if (!t.cov.allFinite()) return std::nullopt;
  t.observations = obs;
  t.chi2 = chi2;
  t.rms_px = std::sqrt(sq / obs.size());
  return t;
}

struct Candidate {
  Vec3 p;
  std::vector<PointObservation> obs;
  double cost;  // sum of squared normalized reprojection errors
};

// The image point of camera c nearest to the prediction q, if within the gate.
int NearestWithinGate(const std::vector<ImagePoint>& pts, const Vec2& q, const MatchingOptions& o, double* d2norm) {
  int best = -1;
  double best_d = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    const Vec2 e = pts[i].q - q;
    const double sigma = std::sqrt(std::max(pts[i].cov(0, 0), pts[i].cov(1, 1)));
    const double gate = std::max(o.gate_px, o.gate_sigma * sigma);
    const double d = e.norm();
    if (d > gate) continue;
    if (best < 0 || d < best_d) {
      best = static_cast<int>(i);
      best_d = d;
    }
  }
  if (best >= 0 && d2norm) *d2norm = best_d * best_d;
  return best;
}

}  // namespace

std::vector<TriangulatedPoint> MatchAndTriangulate(const CameraRig& rig,
                                                   const std::vector<std::vector<ImagePoint>>& points,
                                                   const MatchingOptions& options) {
  const int ncam = static_cast<int>(rig.size());
  // Rays of every image point, once.
  std::vector<std::vector<std::optional<Vec3>>> dirs(ncam);
  std::vector<Vec3> centres(ncam);
  for (int c = 0; c < ncam; ++c) {
    const Pose T_rig_cam = rig.cameras[c].T_cam_rig().Inverse();
    centres[c] = T_rig_cam.t;
    std::vector<Vec2> qs;
    for (const auto& ip : points[c]) qs.push_back(ip.q);
    auto d = rig.cameras[c].Unproject(qs);
    for (auto& v : d)
      if (v) v = T_rig_cam.R * *v;
    dirs[c] = std::move(d);
  }

  // Gating uses the plain projection: the sphere bias (< 0.01 px for the default rig,
  // under 0.2 px anywhere) is far inside the gate, and leaving it out here saves most of
  // the matching time. The accepted points are refined with it (TriangulateNView).
  const double r = 0.0;
  const int nb = options.triangulation.bias_outline_points;
  std::vector<Candidate> cands;
  for (int a = 0; a < ncam; ++a)
    for (int b = a + 1; b < ncam; ++b)
      for (size_t i = 0; i < points[a].size(); ++i) {
        if (!dirs[a][i]) continue;
        for (size_t j = 0; j < points[b].size(); ++j) {
          if (!dirs[b][j]) continue;
          const Vec3 pair_origins[2] = {centres[a], centres[b]}, pair_dirs[2] = {*dirs[a][i], *dirs[b][j]};
          const auto p = NearestPointToRays(pair_origins, pair_dirs, 2);
          if (!p || !InFront(rig.cameras[a], *p, options.min_depth_m) ||
              !InFront(rig.cameras[b], *p, options.min_depth_m))
            continue;
          // The pair itself must be consistent (the epipolar test in pixels).
          Candidate cand{*p, {}, 0.0};
          bool ok = true;
          for (auto [c, k] : {std::pair<int, size_t>{a, i}, std::pair<int, size_t>{b, j}}) {
            const Vec2 e = points[c][k].q - Predict(rig.cameras[c], *p, r, nb, nullptr);
            const double sigma = std::sqrt(std::max(points[c][k].cov(0, 0), points[c][k].cov(1, 1)));
            if (e.norm() > std::max(options.gate_px, options.gate_sigma * sigma)) {
              ok = false;
              break;
            }
            cand.cost += e.squaredNorm();
            if (cand.obs.empty()) cand.obs.reserve(ncam);  // one allocation per candidate
            cand.obs.push_back({c, static_cast<int>(k)});
          }
          if (!ok) continue;
          // Support from the other cameras.
          for (int c = 0; c < ncam; ++c) {
            if (c == a || c == b || !InFront(rig.cameras[c], *p, options.min_depth_m)) continue;
            double d2 = 0;
            const int k = NearestWithinGate(points[c], Predict(rig.cameras[c], *p, r, nb, nullptr), options, &d2);
            if (k >= 0) {
              cand.obs.push_back({c, k});
              cand.cost += d2;
            }
          }
          if (static_cast<int>(cand.obs.size()) >= options.min_views) cands.push_back(std::move(cand));
        }
      }
  // Most views first, then best fit per view.
  std::sort(cands.begin(), cands.end(), [](const Candidate& x, const Candidate& y) {
    if (x.obs.size() != y.obs.size()) return x.obs.size() > y.obs.size();
    return x.cost / x.obs.size() < y.cost / y.obs.size();
  });
  std::vector<std::vector<bool>> used(ncam);
  for (int c = 0; c < ncam; ++c) used[c].assign(points[c].size(), false);
  std::vector<TriangulatedPoint> out;
  // TriangulateNView on the rays computed above (the same ones it would compute).
  const auto triangulate = [&](const std::vector<PointObservation>& obs) -> std::optional<TriangulatedPoint> {
    if (obs.size() < 2) return std::nullopt;
    std::vector<Vec3> o, d;
    for (const auto& v : obs) {
      if (!dirs[v.camera][v.index]) return std::nullopt;
      o.push_back(centres[v.camera]);
      d.push_back(*dirs[v.camera][v.index]);
    }
    return TriangulateFromRays(rig, points, obs, options.triangulation, o, d);
  };
  for (const Candidate& cand : cands) {
    std::vector<PointObservation> obs;
    for (const auto& o : cand.obs)
      if (!used[o.camera][o.index]) obs.push_back(o);
    // A candidate that lost views to better points is only kept if it keeps them all
    // or still has enough views; re-ranking is not needed for the few points we see.
    if (static_cast<int>(obs.size()) < options.min_views || obs.size() < cand.obs.size()) continue;
    std::optional<TriangulatedPoint> t = triangulate(obs);
    // Remove outlier views while the fit is poor and views remain.
    while (t && t->views() > options.min_views &&
           t->chi2 / std::max(1, 2 * t->views() - 3) > options.max_chi2_per_dof) {
      int worst = -1;
      double worst_e = -1;
      for (int k = 0; k < t->views(); ++k) {
        const auto& o = t->observations[k];
        const Mat2 W = WhiteningOf(points[o.camera][o.index].cov);
        const double e =
            (W * (points[o.camera][o.index].q - Predict(rig.cameras[o.camera], t->p_rig, r, nb, nullptr))).squaredNorm();
        if (e > worst_e) {
          worst_e = e;
          worst = k;
        }
      }
      auto reduced = t->observations;
      reduced.erase(reduced.begin() + worst);
      t = triangulate(reduced);
    }
    if (!t) continue;
    const int dof = 2 * t->views() - 3;
    if (dof > 0 && t->chi2 / dof > options.max_chi2_per_dof) continue;
    for (const auto& o : t->observations) used[o.camera][o.index] = true;
    out.push_back(std::move(*t));
  }
  return out;
}

int ClaimNearest(const std::vector<ImagePoint>& points, const Vec2& q, double gate, std::vector<bool>* used) {
  int best = -1;
  double best_d = gate;
  for (size_t k = 0; k < points.size(); ++k) {
    if ((*used)[k]) continue;
    const double d = (points[k].q - q).norm();
    if (d < best_d) {
      best_d = d;
      best = static_cast<int>(k);
    }
  }
  if (best >= 0) (*used)[best] = true;
  return best;
}

}  // namespace mcms
