// mrcal's "optimization_inputs" for a rig calibration: the arguments of
// mrcal.optimize() at the solution (intrinsics, extrinsics, board poses, board
// observations with their weights and outliers, flags), serialised as mrcal 2.2 does in
// its .cameramodel files: numpy.savez_compressed() (a zip of .npy arrays, deflated with
// zlib) and base64.b85encode(), written as the Python bytes literal b'...'. With it,
// mrcal's own tools (mrcal.cameramodel(...).optimization_inputs(),
// mrcal.projection_uncertainty, mrcal-show-projection-uncertainty) work on the
// models calib-rig writes.
//
// mrcal describes the board as a regular grid: point (row i, column j) at
// (j * spacing, i * spacing, 0). Every observed board point must sit on such a grid
// (a chessboard with equal row and column spacing, as CalibrationBoard reads it);
// AprilTag grids do not (the gap between tags breaks the spacing).
// The regularisation mrcal adds to its own solves is switched off
// (do_apply_regularization False): the stored problem is the one solved here, so
// mrcal's uncertainty of the stored model is this solution's.
#pragma once

#include <array>
#include <filesystem>
#include <map>
#include <vector>
#include <string>

#include "calib/camera_calibration.h"
#include "vision/mrcal_file.h"  // the format: the building blocks and the reader

namespace mcms {

struct MrcalBoardGrid {
  int width_n = 0;    // points per row (mrcal's calibration_object_width_n)
  int height_n = 0;   // rows
  double spacing_m = 0.0;
};

// The Python literal b'...' (mrcal's serialisation). InputError when the result has
// no covariance/observations (not from CalibrateCameras), a lens model mrcal does not
// know, or a board point that is not on the grid (message names the point).
std::string MrcalOptimizationInputs(const CameraCalibrationResult& result, const MrcalBoardGrid& grid);

// Writes camera `camera` of the result as CameraModel::WriteCameramodel does, plus
// mrcal's keys 'icam_intrinsics' and 'optimization_inputs' (the text returned by
// MrcalOptimizationInputs, shared by every camera of the rig). Atomic.
void WriteCameramodelWithOptimizationInputs(const CameraCalibrationResult& result, int camera,
                                            const std::string& optimization_inputs,
                                            const std::filesystem::path& path);

}  // namespace mcms
