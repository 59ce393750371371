// Synthetic images of a chessboard calibration board seen through any lens model,
// for testing board detection and camera calibration from pixels end to end.
//
// The board (calib/calibration_board.h): inner corner (i, j) at board point
// (i s, j s, 0), s = square size; the pattern has (cols + 1) x (rows + 1) squares,
// square (a, b) covering [a s, (a+1) s] x [b s, (b+1) s] for a = -1..cols-1,
// b = -1..rows-1, dark when a + b is even (so square (-1, -1) is dark). A white
// margin one square wide surrounds the pattern; beyond it, and where a ray misses
// the plane, the scene is a uniform grey background. The board is printed on both
// sides (it is a plane seen from either side).
//
// Image formation:
//   1. Radiance per pixel = the area average of the scene over the pixel's square
//      footprint. The ray through every pixel corner is intersected with the board
//      plane; a pixel whose four corners fall in the same unit cell of the square
//      grid (cells are convex, and over one pixel the image-to-plane map is affine
//      to far below a sub-sample) lies wholly in it and takes its shade; every other
//      pixel (an edge or a corner crosses it) is averaged over N x N regular
//      sub-samples. Rays come from a RayTable (synthetic/renderer.h).
//   2. Optics: a Gaussian blur, on a canvas padded beyond the image.
//   3. Sensor: read noise (normal, DN), rounding, clipping to 0..255.
#pragma once

#include <string>

#include <opencv2/core.hpp>

#include "calib/calibration_board.h"
#include "core/pose_math.h"
#include "core/random.h"
#include "synthetic/renderer.h"

namespace mcms {

struct BoardRenderOptions {
  double dark_dn = 30.0;         // the dark squares
  double light_dn = 220.0;       // the light squares and the margin
  double background_dn = 110.0;  // off the board, and rays that miss its plane
  double blur_sigma_px = 0.7;    // Gaussian optical blur; 0 = none
  double read_noise_dn = 2.0;    // standard deviation of the read noise; 0 = none
  int supersampling = 8;         // N: pixels crossed by an edge get N x N sub-samples
  bool IsValid(std::string* why) const;
};

// The pixel margin a canvas (and the RayTable) needs beyond the image for this blur.
int BoardRenderPadPx(const BoardRenderOptions& options);

// An 8-bit grey image (the table camera's size) of `board` (a chessboard) at pose
// T_cam_board (board frame -> camera frame). The table's pad must be at least
// BoardRenderPadPx(options). `noise` may be null only when read_noise_dn is 0.
// InputError on a board that is not a valid chessboard or on bad options.
cv::Mat RenderBoard(const RayTable& table, const CalibrationBoard& board, const Pose& T_cam_board,
                    const BoardRenderOptions& options, Rng* noise);

}  // namespace mcms
