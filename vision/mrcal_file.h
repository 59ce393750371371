// mrcal's file format for a camera model's 'optimization_inputs' (mrcal 2.2): the arguments
// of mrcal.optimize() serialised as numpy.savez_compressed() (a zip of .npy arrays,
// deflated with zlib) and base64.b85encode(), written in a .cameramodel as the Python bytes
// literal b'...'. Here the format's building blocks (both ways) and the reader of the
// chessboard problem a .cameramodel stores (what the lens audit refits); the writer of a
// rig calibration's problem is calib/mrcal_optimization_inputs.h.
#pragma once

#include <array>
#include <cstddef>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace mcms {

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
