// Predicted precision of the tracker at one pose of the target in a rig's measuring
// volume: which camera sees which ball, the Cramer-Rao covariance of every triangulated
// ball and of the target's 6-DOF pose, for a given model of the blob-centre noise.
//
// The covariances are those of the tracker's own estimators evaluated at the true
// image points (the sphere images' centroids), so no formula is written twice:
//   - a ball: TriangulateNView (vision/triangulation.h), the 3x3 (sum J^T Sigma^-1 J)^-1;
//   - the pose: RefinePose (tracking/pose_refinement.h), the inverse Gauss-Newton
//     information of the bundle adjustment the tracker minimises (sphere-bias model
//     included), started at the truth so its residuals are zero.
// The blob-centre covariance is a function of the ball image's ellipse (size, elongation,
// orientation); jobs/fov_map.h fills CentroidCovarianceTable by running the blob
// detector's own covariance propagation on rendered noise-free images.
//
// Which observations count, as in the tracker: a ball image whose detection window
// (outline plus border_margin_px) is cut by the image border is dropped (the detector's
// touches_border), as is one whose image comes within crowding_margin_px of another
// ball's (crowded); a ball needs 2 cameras to be triangulated; the target is identified
// when at most IdentificationOptions::max_missing balls are not triangulated; the pose is
// then fitted to every usable observation of every ball.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "tracking/pose_refinement.h"
#include "tracking/target.h"
#include "vision/camera_model.h"
#include "vision/sphere_projection.h"

namespace mcms {

// Blob-centre covariance (px^2) as a function of the ball image's ellipse.
using CentroidCovarianceFn = std::function<Mat2(const Ellipse&)>;

// A table of the centre variances along the major and minor axes of an elliptical blob,
// on a grid of minor semi-axis b (px, log-spaced) and elongation a/b; bilinear in
// (log b, a/b), clamped at the ends. Rotated to the ellipse's angle when evaluated.
class CentroidCovarianceTable {
 public:
  CentroidCovarianceTable() = default;
  // b_px strictly increasing and > 0, ratios strictly increasing and >= 1; var_major and
  // var_minor row-major [b][ratio], px^2. std::invalid_argument when inconsistent.
  CentroidCovarianceTable(std::vector<double> b_px, std::vector<double> ratios, std::vector<double> var_major,
                          std::vector<double> var_minor);
  bool empty() const { return b_.empty(); }
  Mat2 operator()(const Ellipse& e) const;
  // The variances (major, minor) at minor semi-axis b and elongation ratio.
  Vec2 Variances(double b_px, double ratio) const;
  const std::vector<double>& b_px() const { return b_; }
  const std::vector<double>& ratios() const { return r_; }

 private:
  std::vector<double> b_, r_, vmaj_, vmin_;
};

struct FovPredictionOptions {
  double border_margin_px = 3.0;    // the detector's window margin (BlobDetectorOptions::window_margin_px)
  double crowding_margin_px = 3.0;  // two ball images nearer than this (px, outline to outline) are crowded
  int outline_points = 64;          // outline samples for the ellipse of each ball image
  int max_missing_balls = 1;        // IdentificationOptions::max_missing
  PoseRefinementOptions refinement; // the tracker's bundle adjustment
  bool IsValid(std::string* why) const;
};

struct FovBallPrediction {
  int views = 0;            // cameras with a usable image of the ball
  bool triangulated = false;
  Mat3 cov = Mat3::Zero();  // m^2, rig frame (zero when not triangulated)
};

struct FovPointPrediction {
  Pose T_rig_target;
  std::vector<int> balls_in_camera;        // usable ball images per camera
  std::vector<int> balls_in_front;         // balls whose whole outline is in front of and inside the image
  std::vector<FovBallPrediction> balls;    // per target ball
  bool trackable = false;                  // identified and the pose fitted
  int observations = 0;                    // 2-D observations in the pose fit
  Mat6 cov = Mat6::Constant(std::numeric_limits<double>::quiet_NaN());  // [dtheta; dp], rig frame; NaN when not trackable
  double mean_centre_sigma_px = 0;         // RMS over the observations of sqrt(trace(cov)/2)
  double mean_ball_px = 0;                 // mean minor semi-axis of the ball images, px
  // Smallest distance (px) from a ball image's outline to the border of its image, over the
  // usable images of the cameras that see the target: how near the edge of the view.
  double min_border_px = std::numeric_limits<double>::quiet_NaN();
  int CamerasSeeing() const;               // cameras with at least one usable ball image
};

// The prediction at one pose. Throws std::invalid_argument for invalid options or an
// empty covariance function.
FovPointPrediction PredictFovPoint(const CameraRig& rig, const Target& target, const Pose& T_rig_target,
                                   const CentroidCovarianceFn& centre_cov, const FovPredictionOptions& options = {});

// The ellipse of a ball image and whether it is usable by the rules above, without the
// neighbours (crowding): for building centre-noise tables over the sizes that occur.
struct BallImage {
  bool in_front = false;   // the whole outline exists and lies inside the image
  bool usable = false;     // and the detection window is not cut by the border
  Ellipse ellipse;
  Vec2 centroid = Vec2::Zero();
  double border_px = 0;    // distance from the outline's bounding box to the image border
};
BallImage PredictBallImage(const CameraModel& cam, const Vec3& centre_rig, double radius,
                           const FovPredictionOptions& options = {});

}  // namespace mcms
