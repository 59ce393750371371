// Joint calibration of a camera rig from calibration-board observations: every
// camera's intrinsics (mrcal lens models LENSMODEL_PINHOLE / OPENCV4 / 5 / 8 / 12),
// the extrinsics T_cam_rig (camera 0 defines the rig frame) and one pose
// T_rig_board per board placement ("frame"), by bundle adjustment in Ceres with
// analytic derivatives (CameraModel::Project's dq_dp and dq_dintrinsics).
//
// Initialisation: cv::calibrateCamera per camera, cv::solvePnP per observation,
// extrinsics from the board poses of frames that two cameras share. Outliers are
// rejected mrcal-style: after each solve, points whose reprojection error exceeds
// k sigma (sigma: inlier RMS per coordinate) are dropped and the problem re-solved
// until no new outlier appears.
//
// Residual conventions (both reported, do not mix them up):
//   rms_px       = sqrt(sum |e|^2 / (2 N)): per coordinate, mrcal's convention;
//   rms_point_px = sqrt(sum |e|^2 / N):     per point, what OpenCV's calibrateCamera
//                                           returns and calls the reprojection error.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose_math.h"
#include "vision/camera_model.h"

namespace mcms {

// The board points seen by one camera in one frame (one physical placement of the
// board; several cameras seeing it in the same frame share its pose).
struct BoardObservation {
  int camera = 0;
  int frame = 0;
  std::vector<Vec3> points_board;  // metres, board frame
  std::vector<Vec2> pixels;        // observed, project pixel convention
  // Optional per-point weights (empty = all 1): the residual of a point is
  // weight * (projected - observed), as in mrcal, where the weight is the inverse
  // of the point's relative pixel noise (e.g. from the detector's decimation level).
  // Points with weight <= 0 are ignored.
  std::vector<double> weights;
  double Weight(size_t i) const { return weights.empty() ? 1.0 : weights[i]; }
};

struct CameraCalibrationInput {
  std::vector<std::string> camera_names;  // one per camera
  std::vector<int> widths, heights;       // image size per camera
  std::vector<BoardObservation> observations;
};

struct CameraCalibrationOptions {
  std::string lensmodel = "LENSMODEL_OPENCV8";
  double outlier_k = 4.0;          // drop points with |e| > k sigma (0 = no rejection)
  int max_outlier_rounds = 10;
  int max_iterations = 200;        // per Ceres solve
  int min_points_per_observation = 6;
  // Solve mrcal's board-flatness model ("calobject_warp"): the board point (x, y)
  // sits at z = w_x (1 - u^2) + w_y (1 - v^2), u and v running -1..1 across the
  // board's extent in x and y, w in metres (positive: bulging towards +z).
  bool solve_board_warp = false;
  // Views used by cv::calibrateCamera for the initial intrinsics (evenly spread over
  // each camera's views): its dense Levenberg-Marquardt grows with the cube of the
  // number of views, and the bundle adjustment refines from all of them anyway.
  int max_init_views = 20;
  // Known intrinsics per camera (empty, or one entry per camera; an empty entry means
  // "initialise from OpenCV"). With fix_intrinsics every camera needs one, and only
  // extrinsics, board poses (and warp) are solved: the usual second step when each
  // camera's intrinsics came from its own calibration.
  std::vector<std::vector<double>> initial_intrinsics;
  bool fix_intrinsics = false;
  // Optional progress messages (one line each, no newline).
  std::function<void(const std::string&)> log;
  bool IsValid(std::string* why) const;
};

struct CameraResidualStats {
  int num_points = 0;    // observed points (inliers + outliers)
  int num_outliers = 0;
  int num_observations = 0;
  double rms_px = 0.0;        // per coordinate, inliers
  double rms_point_px = 0.0;  // per point, inliers (OpenCV's convention)
  double max_px = 0.0;        // largest inlier error norm
  // Every observed point: pixel, weighted residual (weight * (projected - observed),
  // which every RMS above is computed from), inlier flag.
  std::vector<Vec2> pixels, residuals;
  std::vector<bool> inlier;
};

struct CameraCalibrationResult {
  CameraRig rig;                                // intrinsics and T_cam_rig per camera
  std::vector<std::optional<Pose>> T_rig_board;  // per frame index; nullopt when unobserved
  std::vector<CameraResidualStats> residuals;   // per camera
  double rms_px = 0.0;                          // all cameras, per coordinate
  int num_inliers = 0, num_outliers = 0;
  int outlier_rounds = 0;
  // sigma^2 = sum |e|^2 / (2 N_inliers - number of free parameters): the residual
  // variance that scales the inverse normal matrix into covariances.
  double residual_variance_px2 = 0.0;
  // Covariance of each camera's intrinsics (NumIntrinsics square, in the units of
  // the intrinsics; zero when they were held fixed) and std of rt_cam_rig (rad, m; zero for camera 0, which
  // defines the rig frame). Board poses are marginalised (Schur complement).
  std::vector<Eigen::MatrixXd> intrinsics_covariance;
  std::vector<Eigen::VectorXd> intrinsics_std;
  std::vector<Vec6> extrinsics_std;
  // Board warp (w_x, w_y) in metres and its std, when solved (else zero).
  Eigen::Vector2d board_warp_m = Eigen::Vector2d::Zero(), board_warp_std_m = Eigen::Vector2d::Zero();
};

// Solves. InputError when a camera has no usable observation or is not connected to
// camera 0 through shared frames (message names the camera and the remedy), when the
// lens model is not supported, or when sizes do not match.
CameraCalibrationResult CalibrateCameras(const CameraCalibrationInput& input, const CameraCalibrationOptions& options);

// 1-sigma projection uncertainty (px, sqrt of the largest eigenvalue of the 2x2
// covariance) of the point seen at pixel q at `range_m` along its ray, from the
// intrinsics covariance alone: the point is unprojected with the solved intrinsics,
// held fixed in the camera frame and re-projected through intrinsics perturbed with
// `cov_intrinsics` (first order: J cov J^T with J = dq/dintrinsics). This leaves out
// the camera-pose uncertainty relative to the boards (mrcal folds that in), so in
// the corners of the image it is an upper bound on what mrcal reports. nullopt
// where the pixel does not unproject.
std::optional<Mat2> ProjectionCovariance(const CameraModel& camera, const Eigen::MatrixXd& cov_intrinsics,
                                         const Vec2& q, double range_m);

struct UncertaintyGrid {
  int nx = 0, ny = 0;
  std::vector<Vec2> pixels;       // row-major, ny rows of nx
  std::vector<double> sigma_px;   // NaN where undefined
};
UncertaintyGrid ProjectionUncertaintyGrid(const CameraModel& camera, const Eigen::MatrixXd& cov_intrinsics,
                                          double range_m, int nx = 8, int ny = 6);

// Text summary (one line per camera plus the parameters with their std).
std::string SummarizeCalibration(const CameraCalibrationResult& result);

// SVG: observed points over the image, coloured by residual size (< 1, 1-3, > 3
// sigma, rejected). Written atomically.
void WriteResidualPlot(const CameraCalibrationResult& result, int camera, const std::filesystem::path& path);

}  // namespace mcms
