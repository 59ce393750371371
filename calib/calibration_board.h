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
  Vec2 corners[4];
  Vec2 center;
};

struct AprilTagOptions {
  float quad_decimate = 1.0f;  // 1 = full resolution (best corner accuracy)
  float quad_sigma = 0.0f;
  int threads = 1;
  bool refine_edges = true;
  int max_hamming = 1;  // bit errors corrected (0..2)
};

// tag36h11 detections in an 8-bit grey (or BGR, converted) image, with corners in
// this project's pixel convention. InputError when the image is empty.
std::vector<AprilTagDetection> DetectAprilTags(const cv::Mat& image, const AprilTagOptions& options = {});

// Detects the board. Chessboards: all corners or none (cv::findChessboardCorners +
// cornerSubPix). AprilGrids: the corners of every tag whose id belongs to the grid.
// Returns an empty detection when the board is not seen.
BoardDetection DetectBoard(const CalibrationBoard& board, const cv::Mat& image);

}  // namespace mcms
