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

// The building blocks, exposed for tests.
namespace mrcal_io {
// Python's base64.b85encode (RFC 1924 alphabet, the last group padded and cut).
std::string B85Encode(const std::string& bytes);
// One .npy file (format 1.0): descr as numpy spells it ("<f8", "<i4", "|b1", "<U17"),
// shape (empty = a 0-d array), raw little-endian data.
std::string Npy(const std::string& descr, const std::vector<size_t>& shape, const std::string& data);
// A zip archive of the named members, each deflated (zlib, raw deflate), as
// numpy.savez_compressed writes it.
std::string Zip(const std::vector<std::pair<std::string, std::string>>& members);
}  // namespace mrcal_io

}  // namespace mcms

namespace mcms {

// The chessboard problem stored in a .cameramodel's 'optimization_inputs' (mrcal 2.x:
// the inverse of WriteCameramodelWithOptimizationInputs): the arguments of
// mrcal.optimize() that the lens audit (audit/lens_audit.h) refits. Arrays are
// row-major as numpy stores them.
struct MrcalOptimizationInputsData {
  std::string lensmodel;
  int icam_intrinsics = 0;                     // the camera the .cameramodel describes
  std::vector<std::vector<double>> intrinsics;  // per camera
  std::vector<std::array<int, 2>> imagersizes;  // per camera (width, height)
  std::vector<std::array<double, 6>> extrinsics_rt_fromref, frames_rt_toref;
  // Per board observation: (frame, camera intrinsics, camera extrinsics (-1 = reference)).
  std::vector<std::array<int, 3>> indices_frame_camintrinsics_camextrinsics;
  int board_width_n = 0, board_height_n = 0;
  double spacing_m = 0.0;
  // observations x height x width x (x px, y px, weight; weight < 0: outlier).
  std::vector<double> observations_board;
  bool has_calobject_warp = false;
  std::array<double, 2> calobject_warp{0.0, 0.0};
};

// Reads the optimization_inputs of a .cameramodel. InputError naming the file when it has
// no optimization_inputs, when they hold no chessboard observations (observations_board
// missing or empty, or discrete points instead), when an array has an unexpected type or
// shape, or when an observation or parameter is not finite.
MrcalOptimizationInputsData ReadMrcalOptimizationInputs(const std::filesystem::path& path);

namespace mrcal_io {
// The inverses of the writers above (exposed for tests).
std::string B85Decode(const std::string& text);  // InputError on a character outside the alphabet
// Members of a zip archive (stored or deflated), by name.
std::map<std::string, std::string> Unzip(const std::string& zip);
struct NpyArray {
  std::string descr;  // "<f8", "<i4", "|b1", "<U17", "|O"
  std::vector<size_t> shape;
  std::string data;   // raw
};
NpyArray ParseNpy(const std::string& npy);
}  // namespace mrcal_io

}  // namespace mcms
