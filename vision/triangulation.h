// Multi-camera matching of unlabeled image points and N-view triangulation.
//
// Image points are blob centres with their 2x2 covariances (px^2). When the points
// are images of spheres of known radius, `sphere_radius_m` > 0 makes the measurement
// model the sphere's image centroid (vision/sphere_projection.h) instead of the
// projection of its centre, which removes the sphere-projection bias.
#pragma once

#include <optional>
#include <vector>

#include "core/pose_math.h"
#include "vision/camera_model.h"

namespace mcms {

struct ImagePoint {
  Vec2 q;                          // px
  Mat2 cov = Mat2::Identity() * 0.01;  // px^2
};

// One observation of a 3-D point: which camera, which of its image points.
struct PointObservation {
  int camera = -1;
  int index = -1;  // into that camera's ImagePoint list
};

struct TriangulatedPoint {
  Vec3 p_rig = Vec3::Zero();
  Mat3 cov = Mat3::Zero();  // m^2, rig frame: (sum J^T Sigma^-1 J)^-1, the Cramer-Rao bound for the given 2-D noise
  std::vector<PointObservation> observations;
  double chi2 = 0;          // sum of whitened squared residuals, dof = 2*views - 3
  double rms_px = 0;        // RMS reprojection residual
  int views() const { return static_cast<int>(observations.size()); }
};

struct TriangulationOptions {
  double sphere_radius_m = 0;  // > 0: correct the sphere-projection bias
  int max_iterations = 10;
  int bias_outline_points = 32;  // outline samples for the bias correction (exact for an ellipse)
  bool IsValid(std::string* why) const;
};

// Linear start (the least-squares point closest to all rays), then Gauss-Newton on
// the whitened reprojection residuals. nullopt when fewer than 2 views, the rays are
// (nearly) parallel, or the point falls behind a camera.
std::optional<TriangulatedPoint> TriangulateNView(const CameraRig& rig,
                                                  const std::vector<std::vector<ImagePoint>>& points,
                                                  const std::vector<PointObservation>& observations,
                                                  const TriangulationOptions& options = {});

struct MatchingOptions {
  double gate_px = 3.0;         // max reprojection error (px) of a view joined to a candidate point
  double gate_sigma = 5.0;      // ... or this many standard deviations, whichever is larger
  int min_views = 2;            // points seen by fewer cameras are not reported
  double max_chi2_per_dof = 9;  // a refined point worse than this loses its worst view (or is dropped)
  double min_depth_m = 0.05;    // candidate points nearer than this to a camera are rejected
  TriangulationOptions triangulation;
  bool IsValid(std::string* why) const;
};

// Matches unlabeled image points across all cameras by epipolar geometry and
// triangulates them: every pair of views proposes a point, every other camera
// supports it with the image point that reprojects within the gate, the best
// supported, best fitting points are accepted greedily with each image point used
// once, and each accepted point is re-triangulated from all its views with outlier
// views removed. Spurious reflections seen by one camera and false (ghost) pair
// matches that no third camera supports lose to real points.
std::vector<TriangulatedPoint> MatchAndTriangulate(const CameraRig& rig,
                                                   const std::vector<std::vector<ImagePoint>>& points,
                                                   const MatchingOptions& options = {});

// Whitening factor L with L^T L = cov^-1 (so residual L*e has unit covariance).
Mat2 WhiteningOf(const Mat2& cov);

// Association of a predicted image point with detected ones: the index of the point not yet
// used that is nearest to q, closer than `gate` px, marked used; -1 when there is none.
int ClaimNearest(const std::vector<ImagePoint>& points, const Vec2& q, double gate, std::vector<bool>* used);

}  // namespace mcms
