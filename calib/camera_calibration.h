// Joint calibration of a camera rig from calibration-board observations: every
// camera's intrinsics (mrcal lens models LENSMODEL_PINHOLE / OPENCV4 / 5 / 8 / 12, or
// "auto": the model the data support, see LensModelTrial), the extrinsics T_cam_rig
// (camera 0 defines the rig frame) and one pose T_rig_board per board placement
// ("frame"), by bundle adjustment in Ceres with analytic derivatives
// (calib/reprojection_cost.h: libmrcal's projection gradients on the parameter blocks).
//
// Steps (camera_calibration.cpp): PrepareObservations (validate, drop unusable
// views) -> Initialise (intrinsics, board poses by PnP, PlaceCameras, frame poses)
// -> SolveWithOutlierRejection (RigProblem) -> CollectSolution (residuals) ->
// ComputeCovariance; "auto" runs these per candidate model and SelectLensModel picks.
//
// Initialisation: cv::calibrateCamera per camera, cv::solvePnP per observation,
// extrinsics from the board poses of frames that two cameras share. A board whose
// numbering is symmetric (CameraCalibrationInput::board_symmetries, e.g. a 10 x 10
// chessboard, which OpenCV may number turned by 90, 180 or 270 deg in each image) is
// renumbered there, per frame and camera, to agree with the frame's other cameras:
// each camera's extrinsics from the candidate (one per shared frame and numbering) that
// most frames agree with, each observation's numbering from the reprojection error
// with the board pose the other cameras saw (PlaceCameras; see
// CameraCalibrationResult::renumbered and dropped). A single camera's calibration does
// not depend on the numbering. CalibrationProblems then says whether the solution may
// be trusted (convergence, residual against the views' own noise, outliers per view
// and overall, a positive-definite covariance). Outliers are
// rejected mrcal-style, with hysteresis: after each solve, when some inlier has a
// coordinate error beyond (k + 1) sigma (sigma: inlier RMS per coordinate), every
// point with a coordinate beyond k sigma is dropped and the problem re-solved. Without
// the trigger the loop never settles: each round shrinks sigma and a Gaussian tail
// beyond k sigma always holds a few points (on Figueroa's 18,600 points it dropped
// 771, twice mrcal's count, and stopped at the round limit).
//
// Residual conventions (both reported, do not mix them up):
//   rms_px       = sqrt(sum |e|^2 / (2 N)): per coordinate, mrcal's convention;
//   rms_point_px = sqrt(sum |e|^2 / N):     per point, what OpenCV's calibrateCamera
//                                           returns and calls the reprojection error.
#pragma once

#include <filesystem>
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
  // The numberings the detector may have given one placement of the board, as rigid
  // motions of the board frame mapping its points onto each other
  // (CalibrationBoard::NumberingSymmetries; empty: the numbering is unique). With
  // them, the observations of a frame seen by several cameras are renumbered to agree
  // (see CameraCalibrationResult::renumbered); without them a symmetric board whose
  // numbering differs between cameras gives a wrong rig.
  std::vector<Pose> board_symmetries;
};

// One observation renumbered to agree with the other cameras of its frame: its board
// points were replaced by S * P (S one of the input's board_symmetries, a turn by
// angle_deg about the board normal). rms_px: the initial rig's reprojection error
// (per coordinate) of the observation's pixels with the board pose the frame's other
// cameras saw, under the chosen numbering; next_rms_px: under the next best one.
struct BoardRenumbering {
  int camera = 0, frame = 0;
  double angle_deg = 0.0;
  double rms_px = 0.0, next_rms_px = 0.0;
};

// An observation left out of the solve, and why.
struct DroppedObservation {
  int camera = 0, frame = 0;
  std::string reason;
};

struct CameraCalibrationOptions {
  // A supported mrcal lens model name, or "auto": every model of auto_lensmodels is
  // solved and the one the data support is kept (see LensModelTrial).
  std::string lensmodel = "auto";
  std::vector<std::string> auto_lensmodels = {"LENSMODEL_OPENCV4", "LENSMODEL_OPENCV5", "LENSMODEL_OPENCV8"};
  // "auto" passes over a model with a distortion coefficient whose 1-sigma exceeds
  // this (dimensionless: k_i multiplies r^(2i) of the normalised radius, which is below
  // about 1 over a normal lens' image): such a coefficient is not determined by the views.
  double auto_max_distortion_std = 1.0;
  double outlier_k = 4.0;          // drop points with max(|ex|, |ey|) > k sigma (0 = no rejection)
  double outlier_trigger = 1.0;    // ... but only in rounds where an inlier exceeds (k + this) sigma
  int max_outlier_rounds = 10;
  int max_iterations = 200;        // per Ceres solve (CameraCalibrationResult::converged says whether it sufficed)
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

// The solution's full parameter covariance, sigma^2 (J^T J)^-1 with sigma^2 =
// residual_variance_px2, kept in block form. The parameters are the solver's own:
// "a" = each camera's intrinsics, rt_cam_rig of cameras 1.. (mrcal's rt: rotation
// vector then translation, differentiated as raw parameters, not as perturbations),
// the board warp; then rt_rig_board of every frame in the solve. With the normal
// matrix N = [A B; B^T D] (D block-diagonal, one 6x6 D_f per frame) and
// K_f = D_f^-1 B_f^T, the full covariance is
//   Cov(a)        = a_cov                      = sigma^2 (A - B D^-1 B^T)^-1
//   Cov(a, b_f)   = -a_cov K_f^T
//   Cov(b_f, b_g) = [f == g] frame_conditional_cov[f] + K_f a_cov K_g^T,
// with frame_conditional_cov[f] = sigma^2 D_f^-1. This needs frames * na memory
// instead of frames^2 for a dense inverse.
struct CalibrationCovariance {
  Eigen::MatrixXd a_cov;               // na x na
  std::vector<int> intrinsics_offset;  // per camera, into a; -1 when intrinsics were held fixed
  std::vector<int> extrinsics_offset;  // per camera, into a; -1 for camera 0 (the rig frame)
  int warp_offset = -1;                // -1 when the warp was not solved
  // Per frame index (size = number of frames); in_solve false (and the matrices
  // empty) for frames with no pose or no inlier point.
  std::vector<bool> frame_in_solve;
  std::vector<Mat6> frame_conditional_cov;
  std::vector<Eigen::MatrixXd> frame_gain;  // K_f, 6 x na
};

// One candidate of lens model "auto": its solve and its Bayesian information
// criterion, BIC = n ln(RSS / n) + k ln(n), n = residuals (2 per point), k = free
// parameters (intrinsics, extrinsics, board poses, warp), RSS over the points every
// candidate kept as inliers. Lower is better; a model's extra coefficients must lower
// n ln(RSS) by ln(n) each (7.2 for 700 points) to be worth having.
struct LensModelTrial {
  std::string lensmodel;
  bool converged = false;
  int iterations = 0;                  // of the last solve
  double rms_px = 0.0;                 // per coordinate, over its own inliers
  int num_residuals = 0, num_parameters = 0;
  double bic = 0.0;
  double largest_distortion_std = 0.0;  // largest 1-sigma of a distortion coefficient, any camera
  bool chosen = false;
};

struct CameraCalibrationResult {
  std::string lensmodel;  // the model solved (the chosen one for "auto")
  // The last Ceres solve (after the last outlier round): did it converge (Ceres'
  // CONVERGENCE, not the iteration limit), how many iterations, Ceres' message.
  bool converged = false;
  int iterations = 0;
  std::string solver_message;
  // For lensmodel "auto": every candidate and one line saying which was chosen and why.
  std::vector<LensModelTrial> lens_model_trials;
  std::string lens_model_choice;
  CameraRig rig;                                // intrinsics and T_cam_rig per camera
  std::vector<std::optional<Pose>> T_rig_board;  // per frame index; nullopt when unobserved
  std::vector<CameraResidualStats> residuals;   // per camera
  double rms_px = 0.0;                          // all cameras, per coordinate
  int num_inliers = 0, num_outliers = 0;
  int outlier_rounds = 0;
  // sigma^2 = sum |e|^2 / (2 N_inliers - number of free parameters): the residual
  // variance that scales the inverse normal matrix into covariances.
  double residual_variance_px2 = 0.0;
  double sum_squared_px2 = 0.0;  // sum |e|^2 over the inliers
  int num_parameters = 0;        // free parameters of the solve
  // The observations that took part (points with weight > 0, frames with a board
  // pose), and per observation and point whether it stayed an inlier.
  std::vector<BoardObservation> observations;
  std::vector<std::vector<bool>> observation_inliers;
  // The noise floor of the views: every observation's board pose solved on its own with
  // the solved intrinsics (inlier points), sum |e|^2 / sum (2 n - 6) over them. Views
  // that agree with one rig give residual_variance_px2 close to it; a view numbered
  // differently, taken at another moment or by a moved camera raises the ratio.
  double views_alone_variance_px2 = 0.0;
  // Symmetric boards (input.board_symmetries): the observations renumbered to agree
  // with their frame's other cameras, and those whose numbering could not be matched.
  std::vector<BoardRenumbering> renumbered;
  std::vector<DroppedObservation> dropped;
  // Covariance of each camera's intrinsics (NumIntrinsics square, in the units of
  // the intrinsics; zero when they were held fixed) and std of rt_cam_rig (rad, m; zero for camera 0, which
  // defines the rig frame). Board poses are marginalised (Schur complement).
  // Standard deviations are +infinity (and covariance_singular true) where the normal
  // matrix is singular to working precision: parameters the data do not determine.
  bool covariance_singular = false;
  std::vector<Eigen::MatrixXd> intrinsics_covariance;
  std::vector<Eigen::VectorXd> intrinsics_std;
  std::vector<Vec6> extrinsics_std;
  // Board warp (w_x, w_y) in metres and its std, when solved (else zero).
  Eigen::Vector2d board_warp_m = Eigen::Vector2d::Zero(), board_warp_std_m = Eigen::Vector2d::Zero();
  // Every solved parameter's covariance (what ProjectionCovarianceMeanFrames needs).
  CalibrationCovariance covariance;
};

// When a solution must not be used without a loud warning (calib-rig refuses to write it).
struct CalibrationQualityLimits {
  // sqrt(residual_variance_px2 / views_alone_variance_px2): how far the joint residual
  // is above the views' own noise floor.
  double max_noise_ratio = 1.5;
  double max_rms_px = 1.0;               // per coordinate, inliers, absolute
  double max_outlier_fraction = 0.10;    // rejected points / observed points, overall
  // ... and in any one view (one camera's observation of one frame): most of a view's
  // points rejected means the view disagrees with the rest as a whole (a wrong view,
  // not noisy corners, which spread their outliers over all views).
  double max_view_outlier_fraction = 0.5;
  bool IsValid(std::string* why) const;
};

// Why the solution is not trustworthy, one sentence each with the figures (empty: none):
// the last solve did not converge; the residual is above max_rms_px or far above the
// views' noise floor (max_noise_ratio); more than max_outlier_fraction of the points
// were rejected, or more than max_view_outlier_fraction of one view's (named by camera
// and frame index); a parameter's standard deviation is zero, infinite or not a number
// (the covariance is singular or not positive definite); camera 0 is not among the
// cameras (a result not from CalibrateCameras).
// frame_names (optional, by frame index) name the frames in the sentences.
std::vector<std::string> CalibrationProblems(const CameraCalibrationResult& result,
                                             const CalibrationQualityLimits& limits,
                                             const std::vector<std::string>& frame_names = {});

// Solves. InputError when a camera has no usable observation or is not connected to
// camera 0 through shared frames (message names the camera and the remedy), when the
// lens model is not supported, or when sizes do not match.
CameraCalibrationResult CalibrateCameras(const CameraCalibrationInput& input, const CameraCalibrationOptions& options);

// 1-sigma projection uncertainty (px, sqrt of the largest eigenvalue of the 2x2
// covariance) of the point seen at pixel q at `range_m` along its ray, from the
// intrinsics covariance alone: the point is unprojected with the solved intrinsics,
// held fixed in the camera frame and re-projected through intrinsics perturbed with
// `cov_intrinsics` (first order: J cov J^T with J = dq/dintrinsics). This leaves out
// the camera-pose uncertainty relative to the boards, which mrcal folds in; use
// ProjectionCovarianceMeanFrames for mrcal's definition. nullopt where the pixel
// does not unproject.
std::optional<Mat2> ProjectionCovariance(const CameraModel& camera, const Eigen::MatrixXd& cov_intrinsics,
                                         const Vec2& q, double range_m);

// Projection covariance (px^2) of the point seen by `camera` at pixel q at `range_m`
// along its ray, as mrcal 2.2 defines it (mrcal.projection_uncertainty,
// mrcal-show-projection-uncertainty): the point p_cam is mapped to the rig frame and
// from there into the coordinates of every frame's board; a perturbation of the
// solution (intrinsics, extrinsics, all board poses, warp) moves those board-fixed
// points, which are mapped back to the rig frame, AVERAGED over the frames (the
// "mean-frames" fixed point: the camera is pinned to the boards it saw, not to an
// arbitrary rig frame), and projected by the perturbed camera. First order:
// Var(q) = dq/db Cov(b) dq/db^T over all parameters b (the warp moves no fixed point,
// so it enters only through its correlations). range_m = +infinity gives the
// uncertainty of a point at infinity (translations drop out, as mrcal's atinfinity).
// Noise: Cov(b) is scaled by result.residual_variance_px2 (sum |e|^2 / degrees of
// freedom) unless pixel_sigma_px is given, which replaces sigma (mrcal's default is
// the population std of the board residuals, i.e. about rms_px). nullopt where the
// pixel does not unproject. InputError for a bad camera index, a range that is not
// > 0, a non-positive sigma or a result without the covariance.
std::optional<Mat2> ProjectionCovarianceMeanFrames(const CameraCalibrationResult& result, int camera, const Vec2& q,
                                                   double range_m,
                                                   std::optional<double> pixel_sigma_px = std::nullopt);

// sqrt of the largest eigenvalue of a 2x2 covariance (mrcal's "worstdirection-stdev").
double WorstDirectionStdev(const Mat2& cov);

struct UncertaintyGrid {
  int nx = 0, ny = 0;
  std::vector<Vec2> pixels;       // row-major, ny rows of nx
  std::vector<double> sigma_px;   // NaN where undefined
};
UncertaintyGrid ProjectionUncertaintyGrid(const CameraModel& camera, const Eigen::MatrixXd& cov_intrinsics,
                                          double range_m, int nx = 8, int ny = 6);
// The same grid of worst-direction stdevs from ProjectionCovarianceMeanFrames (the
// camera-pose term included; range_m may be +infinity).
UncertaintyGrid ProjectionUncertaintyGrid(const CameraCalibrationResult& result, int camera, double range_m,
                                          int nx = 8, int ny = 6);

// Text summary (one line per camera plus the parameters with their std).
std::string SummarizeCalibration(const CameraCalibrationResult& result);

// SVG: observed points over the image, coloured by residual size (< 1, 1-3, > 3
// sigma, rejected). Written atomically.
void WriteResidualPlot(const CameraCalibrationResult& result, int camera, const std::filesystem::path& path);

}  // namespace mcms
