// The synthetic image renderer: camera images of the retro-reflective balls of the
// target as a real rig records them, with the ground truth that produced them.
//
// Image formation, per camera image:
//   1. Scene radiance in DN: a background with a linear gradient, and every ball's
//      image as a uniformly bright disc (retro-reflective balls under on-axis light).
//      A ball's image is its TRUE perspective outline through the lens model: a
//      pixel sample belongs to the ball when the sample's ray lies within
//      asin(r/|c|) of the direction to the centre c (the silhouette cone), so the
//      sphere-projection bias of vision/sphere_projection.h is in the images.
//      Pixels are decided at their centre with a margin; only boundary pixels are
//      supersampled (N x N regular sub-samples). Rays come from a RayTable.
//      All balls are equally bright, so where a nearer ball covers a farther one the
//      lit area is the union of their cones (the truth flags the farther one).
//   2. Exposure: every radiance is multiplied by `exposure`.
//   3. Optics: a Gaussian blur (the scene is rendered on a canvas padded beyond the
//      image so that blur near the border is right).
//   4. Sensor: photon noise (electrons = DN * gain, Poisson, back to DN), read
//      noise (normal, DN), rounding and clipping to the bit depth.
//
// Randomness: the events (dropout, occlusion, spurious reflections) and the pixel
// noise of image (frame f, camera c) come from mcms::Rng streams seeded by
// StreamSeed(scenario seed, f, c, stream), a fixed splitmix64 mix, so frames render
// independently and in any order, and a scenario and seed give byte-identical image files.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/pose_math.h"
#include "core/random.h"
#include "vision/camera_model.h"
#include "vision/sphere_projection.h"

namespace mcms {

struct RenderOptions {
  // Radiances in DN of the stored image at exposure 1 (before noise and clipping).
  double exposure = 1.0;         // multiplies every radiance below
  double ball_dn = 200.0;        // the balls: uniformly bright discs
  double background_dn = 12.0;   // background level at the image centre
  // Background change across the image, DN: from the left to the right border (x)
  // and from the top to the bottom border (y); linear in between.
  Vec2 background_gradient_dn = Vec2(4.0, 3.0);
  double blur_sigma_px = 0.6;    // Gaussian optical blur; 0 = none
  double gain_e_per_dn = 4.0;    // electrons per DN for photon noise; 0 = no photon noise
  double read_noise_dn = 1.5;    // standard deviation of the read noise, DN
  int bit_depth = 8;             // 8 or 16
  int supersampling = 16;        // N: boundary pixels get N x N regular sub-samples
  // Spurious reflections: small bright discs at random places in the image (never
  // touching a ball's image or each other, so every one is a separate blob).
  double spurious_per_image = 0.0;  // expected count per image (Poisson)
  double spurious_radius_min_px = 1.0;
  double spurious_radius_max_px = 4.0;  // radius uniform in [min, max]
  double spurious_dn = 150.0;
  // Per ball, per camera, per frame: the ball is hidden in that image (an obstacle).
  double occlusion_probability = 0.0;
  // Per camera, per frame: that camera's image is not recorded at all.
  double dropout_probability = 0.0;
  // No photon or read noise (blur, rounding and clipping stay).
  bool noise_free = false;

  bool IsValid(std::string* why) const;
  double MaxDn() const { return bit_depth == 16 ? 65535.0 : 255.0; }
};

// Per-camera lookup table of the ray through each image point: exact unprojection
// (mrcal, iterative) on a regular grid, bilinear interpolation of the normalized
// image-plane point (x/z, y/z) in between. Interpolating (x/z, y/z) rather than unit
// vectors keeps a pinhole model exact (the map is affine) so that only the lens
// distortion's curvature makes an error. The grid step is halved from 4 px until the
// reprojection error at the cell centres (where bilinear interpolation of a smooth
// map errs most) is below the tolerance; the measured error is kept.
// Rays must point forward (z > 0): fields of view under 180 degrees.
class RayTable {
 public:
  // Covers pixel coordinates [-0.5 - pad_px, width - 0.5 + pad_px] and likewise in v.
  explicit RayTable(const CameraModel& cam, double pad_px = 8.0, double tolerance_px = 2.5e-4);

  const CameraModel& Camera() const { return cam_; }
  double StepPx() const { return step_; }
  double PadPx() const { return pad_; }
  // Largest reprojection error of an interpolated ray at the cell centres, pixels.
  double MeasuredErrorPx() const { return error_px_; }
  // Largest angle between the rays of two points one pixel apart (radians), bounded
  // from the grid with a safety factor: the margin for deciding a whole pixel.
  double MaxAnglePerPx() const { return angle_per_px_; }

  // The normalized image-plane point (x/z, y/z) of the ray through pixel (u, v).
  // False outside the table or next to a grid node without a forward ray.
  bool Normalized(double u, double v, double* x, double* y) const {
    const double fu = (u - u0_) * inv_step_, fv = (v - v0_) * inv_step_;
    if (!(fu >= 0.0 && fv >= 0.0)) return false;
    int iu = static_cast<int>(fu), iv = static_cast<int>(fv);
    if (iu >= nu_ - 1 || iv >= nv_ - 1) {
      // The far border itself belongs to the last cell.
      if (fu > nu_ - 1 || fv > nv_ - 1) return false;
      iu = std::min(iu, nu_ - 2);
      iv = std::min(iv, nv_ - 2);
    }
    const double a = fu - iu, b = fv - iv;
    const double* p00 = &xy_[2 * (static_cast<size_t>(iv) * nu_ + iu)];
    const double* p10 = p00 + 2;
    const double* p01 = p00 + 2 * static_cast<size_t>(nu_);
    const double* p11 = p01 + 2;
    const double w00 = (1 - a) * (1 - b), w10 = a * (1 - b), w01 = (1 - a) * b, w11 = a * b;
    *x = w00 * p00[0] + w10 * p10[0] + w01 * p01[0] + w11 * p11[0];
    *y = w00 * p00[1] + w10 * p10[1] + w01 * p01[1] + w11 * p11[1];
    return std::isfinite(*x) && std::isfinite(*y);
  }

 private:
  void Build(double step);
  CameraModel cam_;
  double pad_ = 0, step_ = 0, inv_step_ = 0, u0_ = 0, v0_ = 0;
  int nu_ = 0, nv_ = 0;
  std::vector<double> xy_;  // row-major grid of (x/z, y/z); NaN where no forward ray
  double error_px_ = 0, angle_per_px_ = 0;
};

// A disc drawn directly in the image (a spurious reflection).
struct ImageDisc {
  Vec2 centre_px = Vec2::Zero();
  double radius_px = 0;
  double level_dn = 0;
};

// The pixel margin a rendering canvas needs beyond the image for this blur.
int RenderPadPx(const RenderOptions& options);

// One camera image (CV_8U or CV_16U, the camera's size) of equally bright spheres of
// the given radius, centres in the camera frame, plus optional image-space discs,
// through the whole image formation above. `noise` may be null only when the
// options make no noise (noise_free, or gain 0 and read noise 0).
// The first form builds a RayTable for the camera (about a second for 1280 x 1024);
// render many images of one camera with the second.
cv::Mat RenderSpheres(const CameraModel& cam, const std::vector<Vec3>& centres_cam, double radius,
                      const RenderOptions& options, Rng* noise);
cv::Mat RenderSpheres(const RayTable& table, const std::vector<Vec3>& centres_cam, double radius,
                      const RenderOptions& options, Rng* noise, const std::vector<ImageDisc>& discs = {});

// Seed of random stream `stream` of image (frame, camera): a splitmix64 chain over
// the four numbers. Stream 0 draws the events, stream 1 the pixel noise.
uint64_t StreamSeed(uint64_t seed, uint64_t frame, uint64_t camera, uint64_t stream);

// The truth of one ball in one camera image.
struct BallTruth {
  int camera = 0, ball = 0;
  // The ball is entirely in front of the camera and its whole outline lies inside
  // the image: a complete blob (unless occluded).
  bool visible = false;
  bool hidden = false;      // removed from this image by the occlusion option
  bool overlapped = false;  // its image overlaps that of a nearer, not hidden ball
  bool occluded() const { return hidden || overlapped; }
  Vec2 centre_px = Vec2::Zero();    // Project(ball centre)
  Vec2 centroid_px = Vec2::Zero();  // SphereImageCentroid: what a centroiding detector measures
  Ellipse ellipse;                  // EllipseFromOutline(SphereOutline(...))
};

struct SpuriousTruth {
  int camera = 0;
  Vec2 centre_px = Vec2::Zero();
  double radius_px = 0;
};

struct FrameTruth {
  size_t frame = 0;
  double time_s = 0;
  Pose T_rig_target;
  std::vector<Vec3> balls_rig;  // ball centres in the rig frame
  // One entry per (recorded camera, ball entirely in front of that camera), ordered
  // by camera then ball. Dropped-out cameras have none.
  std::vector<BallTruth> observations;
  std::vector<SpuriousTruth> spurious;
  std::vector<int> dropped_cameras;
};

struct RenderedFrame {
  std::vector<cv::Mat> images;  // one per camera; empty for a dropped-out camera
  FrameTruth truth;
};

}  // namespace mcms
