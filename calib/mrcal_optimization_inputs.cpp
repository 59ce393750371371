#include "calib/mrcal_optimization_inputs.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <numeric>
#include <optional>
#include <sstream>

#include <zlib.h>

#include "core/error.h"
#include "core/limits.h"
#include "core/io.h"
#include "vision/camera_model.h"
#include "vision/mrcal_file.h"

namespace mcms {

namespace {

using mrcal_io::Npy;

std::string F64(const std::vector<double>& v) {
  std::string s(v.size() * sizeof(double), '\0');
  static_assert(sizeof(double) == 8);
  // An empty vector's data() may be null, which memcpy must not get even for 0 bytes (UBSan).
  if (!v.empty()) std::memcpy(s.data(), v.data(), s.size());  // x86-64 and aarch64: little-endian
  return s;
}
std::string I32(const std::vector<int32_t>& v) {
  std::string s(v.size() * sizeof(int32_t), '\0');
  if (!v.empty()) std::memcpy(s.data(), v.data(), s.size());
  return s;
}
std::string NpyF64(const std::vector<size_t>& shape, const std::vector<double>& v) { return Npy("<f8", shape, F64(v)); }
std::string NpyI32(const std::vector<size_t>& shape, const std::vector<int32_t>& v) { return Npy("<i4", shape, I32(v)); }
std::string NpyBool(bool b) { return Npy("|b1", {}, std::string(1, b ? '\1' : '\0')); }
std::string NpyScalar(double v) { return NpyF64({}, {v}); }
// numpy's unicode string: UCS-4, little-endian. None is stored as '' (mrcal's convention).
std::string NpyStr(const std::string& s) {
  std::string data;
  for (unsigned char c : s) {
    data.push_back(static_cast<char>(c));
    data.append(3, '\0');
  }
  if (s.empty()) data.assign(4, '\0');
  return Npy("<U" + std::to_string(std::max<size_t>(1, s.size())), {}, data);
}
std::string NpyNone() { return NpyStr(""); }

}  // namespace

std::string MrcalOptimizationInputs(const CameraCalibrationResult& r, const MrcalBoardGrid& grid) {
  const int ncam = static_cast<int>(r.rig.size());
  if (ncam == 0 || r.observations.empty() || r.observations.size() != r.observation_inliers.size() ||
      static_cast<int>(r.covariance.intrinsics_offset.size()) != ncam)
    Throw("mrcal optimization_inputs: the calibration result carries no observations (it must come from "
          "CalibrateCameras)");
  if (grid.width_n < 2 || grid.height_n < 2 || !(grid.spacing_m > 0.0))
    Throw("mrcal optimization_inputs: board grid ", grid.width_n, "x", grid.height_n, " spacing ", grid.spacing_m,
          " m is not a valid grid");
  const std::string lensmodel = r.rig.cameras[0].LensModelName();
  const int n_intr = r.rig.cameras[0].NumIntrinsics();
  for (const CameraModel& m : r.rig.cameras)
    if (m.LensModelName() != lensmodel) Throw("mrcal optimization_inputs: the cameras have different lens models");

  // Frames with a board pose and an observation, renumbered 0.. in order.
  std::map<int, int> frame_index;
  for (const BoardObservation& o : r.observations) frame_index[o.frame] = 0;
  std::vector<double> frames;
  int nf = 0;
  for (auto& [f, k] : frame_index) {
    if (f >= static_cast<int>(r.T_rig_board.size()) || !r.T_rig_board[f])
      Throw("mrcal optimization_inputs: frame ", f, " is observed but has no board pose");
    k = nf++;
    double rt[6];
    r.T_rig_board[f]->ToRt(rt);
    frames.insert(frames.end(), rt, rt + 6);
  }
  // Observations sorted by frame then camera, as mrcal stores them.
  std::vector<size_t> order(r.observations.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const auto& oa = r.observations[a];
    const auto& ob = r.observations[b];
    return std::make_pair(oa.frame, oa.camera) < std::make_pair(ob.frame, ob.camera);
  });
  const size_t W = grid.width_n, H = grid.height_n;
  std::vector<double> board(order.size() * H * W * 3);
  std::vector<int32_t> indices;
  for (size_t k = 0; k < order.size(); ++k) {
    const BoardObservation& o = r.observations[order[k]];
    const std::vector<bool>& inl = r.observation_inliers[order[k]];
    double* ob = board.data() + k * H * W * 3;
    for (size_t p = 0; p < H * W; ++p) ob[3 * p] = ob[3 * p + 1] = ob[3 * p + 2] = -1.0;  // not observed
    for (size_t i = 0; i < o.points_board.size(); ++i) {
      const Vec3& P = o.points_board[i];
      const double ju = P.x() / grid.spacing_m, iu = P.y() / grid.spacing_m;
      const long j = std::lround(ju), row = std::lround(iu);
      if (std::abs(ju - j) > 1e-6 || std::abs(iu - row) > 1e-6 || std::abs(P.z()) > 1e-9 || j < 0 || row < 0 ||
          j >= grid.width_n || row >= grid.height_n)
        Throw("mrcal optimization_inputs: board point (", P.x(), ", ", P.y(), ", ", P.z(), ") m of camera ",
              r.rig.names[o.camera], ", frame ", o.frame, " is not on mrcal's ", grid.width_n, "x", grid.height_n,
              " grid of spacing ", grid.spacing_m, " m (mrcal knows only regular grids of board points)");
      double* e = ob + 3 * (static_cast<size_t>(row) * W + static_cast<size_t>(j));
      e[0] = o.pixels[i].x();
      e[1] = o.pixels[i].y();
      e[2] = inl[i] ? o.Weight(i) : -1.0;  // negative weight: outlier, as mrcal marks them
    }
    indices.push_back(frame_index.at(o.frame));
    indices.push_back(o.camera);
    indices.push_back(o.camera - 1);  // camera 0 is the reference: -1
  }
  std::vector<double> intrinsics, extrinsics;
  std::vector<int32_t> sizes;
  for (int c = 0; c < ncam; ++c) {
    const CameraModel& m = r.rig.cameras[c];
    intrinsics.insert(intrinsics.end(), m.Intrinsics().begin(), m.Intrinsics().end());
    sizes.push_back(m.Width());
    sizes.push_back(m.Height());
    if (c > 0) {
      double rt[6];
      m.T_cam_rig().ToRt(rt);
      extrinsics.insert(extrinsics.end(), rt, rt + 6);
    }
  }
  const bool warp = r.covariance.warp_offset >= 0;
  const bool intrinsics_free = r.covariance.intrinsics_offset[0] >= 0;
  const size_t ncam_s = static_cast<size_t>(ncam);
  const std::vector<std::pair<std::string, std::string>> members = {
      {"intrinsics.npy", NpyF64({ncam_s, static_cast<size_t>(n_intr)}, intrinsics)},
      {"extrinsics_rt_fromref.npy", NpyF64({ncam_s - 1, 6}, extrinsics)},
      {"frames_rt_toref.npy", NpyF64({static_cast<size_t>(nf), 6}, frames)},
      {"points.npy", NpyNone()},
      {"observations_board.npy", NpyF64({order.size(), H, W, 3}, board)},
      {"indices_frame_camintrinsics_camextrinsics.npy", NpyI32({order.size(), 3}, indices)},
      {"observations_point.npy", NpyNone()},
      {"indices_point_camintrinsics_camextrinsics.npy", NpyNone()},
      {"lensmodel.npy", NpyStr(lensmodel)},
      {"imagersizes.npy", NpyI32({ncam_s, 2}, sizes)},
      {"calobject_warp.npy", warp ? NpyF64({2}, {r.board_warp_m[0], r.board_warp_m[1]}) : NpyNone()},
      {"do_optimize_intrinsics_core.npy", NpyBool(intrinsics_free)},
      {"do_optimize_intrinsics_distortions.npy", NpyBool(intrinsics_free)},
      {"do_optimize_extrinsics.npy", NpyBool(true)},
      {"do_optimize_frames.npy", NpyBool(true)},
      {"do_optimize_calobject_warp.npy", NpyBool(warp)},
      {"calibration_object_spacing.npy", NpyScalar(grid.spacing_m)},
      {"do_apply_outlier_rejection.npy", NpyBool(true)},
      {"observed_pixel_uncertainty.npy", NpyScalar(r.rms_px)},
      {"do_apply_regularization.npy", NpyBool(false)},
      {"verbose.npy", NpyBool(false)},
  };
  return "b'" + mrcal_io::B85Encode(mrcal_io::Zip(members)) + "'";
}

void WriteCameramodelWithOptimizationInputs(const CameraCalibrationResult& result, int camera,
                                            const std::string& optimization_inputs,
                                            const std::filesystem::path& path) {
  if (camera < 0 || camera >= static_cast<int>(result.rig.size()))
    Throw("WriteCameramodelWithOptimizationInputs: no camera ", camera);
  // The model's own text comes from its one writer (CameraModel::WriteCameramodel,
  // full precision), written beside the target and read back; the two keys go
  // before the dict's closing brace.
  const std::filesystem::path model_text = path.string() + ".model.tmp";
  result.rig.cameras[camera].WriteCameramodel(model_text);
  std::string text;
  {
    std::ifstream f(model_text, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  std::error_code ec;
  std::filesystem::remove(model_text, ec);
  const size_t close = text.rfind('}');
  if (close == std::string::npos) Throw("camera model text for ", path.string(), " has no closing brace");
  text.insert(close, "\n    'icam_intrinsics': " + std::to_string(camera) + ",\n\n    'optimization_inputs': " +
                         optimization_inputs + ",\n");
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

}  // namespace mcms
