// The rig's precision over its measuring volume (issue 12): a predicted map over a 3-D
// grid of target positions (tracking/fov_prediction.h at every grid point, with the
// blob-centre noise of the renderer's image formation measured by the blob detector's own
// covariance propagation), and a Monte-Carlo check of it through the renderer and the
// tracker at a sample of the grid points.
//
// Centre-noise model: the centre covariance of a ball image depends on its size and
// elongation (and on the levels, blur and noise of the images). It is tabulated by
// rendering noise-free images of one sphere through a pinhole (synthetic/renderer.h, the
// same image formation as every rendered frame) at a grid of sizes and off-axis angles,
// and running DetectBlobs on them with the noise model given (read_noise_dn, gain): the
// detector propagates the pixel variances of the EXPECTED image to the centre, which is
// the covariance it reports on average for the noisy images. Nothing is re-derived.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "synthetic/renderer.h"
#include "tracking/fov_prediction.h"
#include "tracking/target.h"
#include "tracking/tracker.h"
#include "vision/blob_detector.h"
#include "vision/camera_model.h"

namespace mcms {

// The pixel-noise model: the image formation (levels, blur, photon and read noise, bit
// depth) and what the detector is told. detector_read_noise_dn is the detector's noise std
// of a background pixel (mcms track --read-noise); 0 = the renderer's: read noise, the
// background's photon noise and the quantization, sqrt(read^2 + bg/gain + 1/12).
// detector_gain_e_per_dn < 0 = the renderer's gain.
struct FovNoiseModel {
  RenderOptions render;
  double detector_read_noise_dn = 0;
  double detector_gain_e_per_dn = -1;
  BlobDetectorOptions Detector() const;
  bool IsValid(std::string* why) const;
};

// Tabulates the detector's centre covariance over minor semi-axes [b_min, b_max] px and
// elongations [1, ratio_max] (see the top of this file).
CentroidCovarianceTable BuildCentroidCovarianceTable(const FovNoiseModel& noise, double b_min_px, double b_max_px,
                                                     double ratio_max, int threads = 1);

// A regular grid in the rig frame: "x0:x1:nx,y0:y1:ny,z0:z1:nz" (metres; n >= 1, n = 1
// takes x0). InputError naming `source` (e.g. "--grid") otherwise.
struct FovGrid {
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();
  int n[3] = {1, 1, 1};
  static FovGrid Parse(const std::string& text, const std::string& source);
  size_t size() const { return static_cast<size_t>(n[0]) * n[1] * n[2]; }
  double Coord(int axis, int i) const { return n[axis] == 1 ? lo[axis] : lo[axis] + (hi[axis] - lo[axis]) * i / (n[axis] - 1); }
  // Index order: x fastest, then y, then z.
  Vec3 Point(size_t index) const;
  std::string ToString() const;
};

struct FovMapOptions {
  FovGrid grid;
  Mat3 R_rig_target = Mat3::Identity();  // orientation of the target at every grid point
  FovNoiseModel noise;
  FovPredictionOptions prediction;
  int threads = 1;
  double threshold_mm = 0.05;  // the region where sigma_d is below this
  bool IsValid(std::string* why) const;
};

struct FovMapPoint {
  Vec3 p_rig = Vec3::Zero();
  FovPointPrediction prediction;
  double mean_distance_m = 0;  // mean distance from the cameras that see a ball
  // Standard deviations (m, rad; NaN when not trackable) of the target's position and
  // orientation, and the compound sigma_d = sqrt(sx^2 + sy^2 + sz^2).
  Vec3 sigma_p() const;
  Vec3 sigma_r() const;
  double sigma_d() const { return sigma_p().norm(); }
  double mean_ball_sigma_d() const;  // over the triangulated balls, m; NaN when none
};

struct FovMap {
  CameraRig rig;
  Target target;
  FovMapOptions options;
  CentroidCovarianceTable centre_table;
  std::vector<FovMapPoint> points;  // grid order
};

// The predicted map. `progress(done, total)` is called from the calling thread.
FovMap ComputeFovMap(const CameraRig& rig, const Target& target, const FovMapOptions& options,
                     const std::function<void(size_t, size_t)>& progress = {});

// Predictions at arbitrary positions (orientation options.R_rig_target; the grid of the
// options is not used), with a centre-noise table built for their bounding box.
std::vector<FovMapPoint> PredictFovPoints(const CameraRig& rig, const Target& target, const FovMapOptions& options,
                                          const std::vector<Vec3>& positions);

// Monte Carlo at a few grid points: `repeats` rendered frames of the target at each pose,
// each tracked independently (frames 10 s apart: no prediction), the sample standard
// deviations of the tracked pose about its mean beside the predicted ones.
struct FovSimulatedPoint {
  size_t grid_index = 0;
  Vec3 p_rig = Vec3::Zero();
  Vec3 predicted_sigma_p = Vec3::Zero(), predicted_sigma_r = Vec3::Zero();
  Vec3 simulated_sigma_p = Vec3::Zero(), simulated_sigma_r = Vec3::Zero();
  Vec3 mean_error_p = Vec3::Zero();  // mean tracked position minus truth, m
  int tracked = 0, lost = 0;
  // Per axis (x, y, z, rx, ry, rz): the sample variance is inside the two-sided 99 % band of
  // (tracked - 1) s^2 / sigma^2 ~ chi-square(tracked - 1) around the predicted sigma.
  bool consistent[6] = {false, false, false, false, false, false};
  bool AllConsistent() const;
};
struct FovSimulationOptions {
  int points = 4;
  int repeats = 30;
  uint64_t seed = 1;
  int threads = 1;
  TrackerOptions tracker;  // detector noise options: the map's noise model unless set
  // False with the reason (fewer than 1 point or 2 repeats, threads out of range, tracker
  // options invalid).
  bool IsValid(std::string* why) const;
};
// Picks `points` trackable grid points spread over the map (evenly in grid order).
std::vector<size_t> PickSimulationPoints(const FovMap& map, int points);
std::vector<FovSimulatedPoint> SimulateFovPoints(const FovMap& map, const std::vector<size_t>& grid_indices,
                                                 const FovSimulationOptions& options,
                                                 const std::function<void(size_t, size_t)>& progress = {});

// Writes into `dir` (created; files replaced atomically one by one; the CLI writes into a
// temporary folder and renames it): map.csv, heatmap_z<k>.svg per z plane of the grid,
// heatmap_x_centre.svg and heatmap_y_centre.svg (vertical slices through the grid's middle
// x and middle y: z against y, z against x; same colour scale), sigma_vs_distance.svg, region.txt (the region where sigma_d < threshold), and, when
// given, simulated.csv and simulated.svg.
void WriteFovMap(const FovMap& map, const std::filesystem::path& dir,
                 const std::vector<FovSimulatedPoint>& simulated = {});

// Summary lines (the region below the threshold, the best and worst points) for stdout.
std::string FovMapSummary(const FovMap& map);

}  // namespace mcms
