// Calibration boards: their description (Kalibr-style YAML) and their detection in
// images.
//
// Board frame: planar, z = 0 on the board surface. For chessboards x runs along the
// rows of inner corners as cv::findChessboardCorners orders them and y along the
// columns, origin at the first corner found. For AprilTag grids (Kalibr's aprilgrid
// convention) tag 0 sits at the bottom-left, ids grow along x (to the right) then
// along y (upwards), z points out of the printed side; the four corners of tag
// `id` are board points 4*id + k, k = 0..3 = bottom-left, bottom-right, top-right,
// top-left (libapriltag's corner order det->p[k] for an upright tag).
// Pixels: (0,0) is the centre of the top-left pixel (docs/conventions.md).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/pose_math.h"

namespace mcms {

struct CalibrationBoard {
  enum class Type { kChessboard, kAprilGrid };
  Type type = Type::kChessboard;
  // Chessboard: inner corners per row (cols) and per column (rows), square size (m).
  int cols = 0, rows = 0;
  static constexpr int kMaxChessboardSide = 500;
  double square_m = 0.0;
  // AprilGrid (tag36h11): tags per row and column, tag edge (m), gap between tags
  // as a fraction of the tag edge (Kalibr's tagSpacing).
  int tag_cols = 0, tag_rows = 0;
  double tag_size_m = 0.0, tag_spacing = 0.0;

  static CalibrationBoard Chessboard(int cols, int rows, double square_m);
  static CalibrationBoard AprilGrid(int tag_cols, int tag_rows, double tag_size_m, double tag_spacing);

  // YAML in Kalibr's format:
  //   target_type: aprilgrid                 target_type: checkerboard
  //   tagCols: 6                             targetCols: 9        # inner corners
  //   tagRows: 6                             targetRows: 6
  //   tagSize: 0.088        # m              rowSpacingMeters: 0.025
  //   tagSpacing: 0.3       # fraction       colSpacingMeters: 0.025  (must equal rowSpacingMeters)
  // InputError naming the file and the field on anything missing or out of range.
  static CalibrationBoard Read(const std::filesystem::path& path);

  bool IsValid(std::string* why) const;
  int NumPoints() const;
  // The numberings of the board's points a detector may report for one physical
  // placement, as the rigid motions S of the board frame (in its plane, about the
  // centre of the point grid) that map every point onto another: a view numbered
  // through S reports the pixel of point S * P as the pixel of P. Identity excluded.
  //
  // cv::findChessboardCorners (the classic quad detector DetectBoard uses) starts
  // its numbering at a grid corner next to a dark corner square, transposes to
  // `cols` corners per row and then restores the handedness of the view, and for an
  // even x even grid puts the first row above the last in the image. So, for a board
  // seen from its printed side (tests/test_app_board_symmetry.cpp renders it):
  //   cols + rows odd (e.g. 9 x 6):        the dark squares fix the numbering: none;
  //   cols != rows, cols + rows even:      the half turn (which corner starts depends
  //                                        on the image: how the camera is rolled);
  //   cols == rows (any parity):           the quarter, half and three-quarter turns.
  // AprilGrids: none (every tag carries its id).
  std::vector<Pose> NumberingSymmetries() const;
  // "half turn", "quarter turn" etc. of a symmetry from NumberingSymmetries: its
  // rotation angle in degrees about the board normal, 0..360.
  static double SymmetryAngleDeg(const Pose& S);
  // Board coordinates (m, z = 0) of point `id` (0 <= id < NumPoints()).
  Vec3 Point(int id) const;
  std::string Describe() const;
};

// The board points found in one image: pixel and point id (index into the board).
struct BoardDetection {
  std::vector<Vec2> pixels;
  std::vector<int> ids;
  size_t size() const { return ids.size(); }
};

// One tag36h11 detection: id and the four corners in libapriltag's order.
struct AprilTagDetection {
  int id = -1;
  int hamming = 0;
  double decision_margin = 0.0;
  Vec2 corners[4] = {Vec2::Zero(), Vec2::Zero(), Vec2::Zero(), Vec2::Zero()};
  Vec2 center = Vec2::Zero();  // the image of the tag centre: where the quad's diagonals cross
};

// How the corners of a decoded tag are placed to sub-pixel accuracy. Figures: corner
// error per coordinate on rendered tags with exact corners (blur 0.8 px, noise 2 DN;
// tests/test_calib_camera_real.cpp AprilTagRenderedCornerAccuracy).
enum class AprilTagCornerRefinement {
  // The corners of libapriltag's quad fit to the thresholded boundary, unrefined:
  // RMS 0.053 px, biased by -0.04 px in x and y. At quad_decimate 1 this is what
  // AprilTag's own regression data hold (apriltag-upstream-test: median 0.0002 px
  // from its expected corners).
  kNone,
  // libapriltag 3.3's refine_edges (it reads grey levels at truncated integer
  // positions): RMS 0.041 px. What ViSP's detector used for its
  // ground_truth_detection.txt (visp-apriltag: worst corner 0.044 px from it).
  kLibApriltag33,
  // Each of the four edges re-fitted to the grey-level gradient, the corners where
  // the fitted lines cross: the refinement of later libapriltag versions (grey
  // levels read by bilinear interpolation at the right half-pixel). RMS 0.012 px,
  // bias below 0.005 px.
  kEdgeFit,
};

struct AprilTagOptions {
  float quad_decimate = 1.0f;  // 1 = full resolution (best corner accuracy); >= 1
  float quad_sigma = 0.0f;     // Gaussian blur (px) of the image the quads are found in
  int threads = 1;             // >= 1
  AprilTagCornerRefinement corner_refinement = AprilTagCornerRefinement::kEdgeFit;
  int max_hamming = 1;  // bit errors corrected (0..2)
  bool IsValid(std::string* why) const;
};

// tag36h11 detections in an 8-bit grey (or BGR, converted) image, with corners in
// this project's pixel convention. InputError when the image is empty or the
// options are invalid.
std::vector<AprilTagDetection> DetectAprilTags(const cv::Mat& image, const AprilTagOptions& options = {});

// Detects the board. Chessboards: all corners or none (cv::findChessboardCorners +
// cornerSubPix). AprilGrids: the corners of every tag whose id belongs to the grid.
// Returns an empty detection when the board is not seen.
BoardDetection DetectBoard(const CalibrationBoard& board, const cv::Mat& image);

}  // namespace mcms
