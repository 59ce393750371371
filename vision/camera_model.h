// A camera: lens model and intrinsics (through libmrcal's C API), image size, and
// its pose in the rig, T_cam_rig (mrcal's rt_cam_ref). Pixel (0,0) is the centre of
// the top-left pixel; camera axes x right, y down, z forward (docs/conventions.md).
//
// Supported lens models: every mrcal model with gradients (LENSMODEL_PINHOLE,
// LENSMODEL_STEREOGRAPHIC, LENSMODEL_OPENCV4/5/8/12, LENSMODEL_CAHVOR and
// LENSMODEL_SPLINED_STEREOGRAPHIC_order=..._Nx=..._Ny=..._fov_x_deg=...).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/pose_math.h"

namespace mcms {

class CameraModel {
 public:
  CameraModel() = default;
  // lensmodel: a full mrcal model name (configured for the splined model).
  // InputError when the name is unknown or the intrinsics count does not fit.
  CameraModel(const std::string& lensmodel, std::vector<double> intrinsics, int width, int height,
              const Pose& T_cam_rig = Pose::Identity());

  const std::string& LensModelName() const { return lensmodel_name_; }
  const std::vector<double>& Intrinsics() const { return intrinsics_; }
  std::vector<double>& MutableIntrinsics() { return intrinsics_; }
  int NumIntrinsics() const { return static_cast<int>(intrinsics_.size()); }
  int Width() const { return width_; }
  int Height() const { return height_; }
  const Pose& T_cam_rig() const { return T_cam_rig_; }
  void SetT_cam_rig(const Pose& T) { T_cam_rig_ = T; }
  // Focal lengths of the intrinsics core (fx, fy), or of the splined model's core.
  Vec2 FocalLengths() const { return {intrinsics_.at(0), intrinsics_.at(1)}; }
  bool CanProjectBehindCamera() const;

  // Projects a point in camera coordinates. dq_dp (2x3) and dq_dintrinsics
  // (2 x NumIntrinsics, row-major) are filled when not null.
  Vec2 Project(const Vec3& p_cam, Eigen::Matrix<double, 2, 3>* dq_dp = nullptr,
               std::vector<double>* dq_dintrinsics = nullptr) const;
  // Many points at once (one mrcal call).
  std::vector<Vec2> Project(const std::vector<Vec3>& p_cam) const;
  // The same into *q (resized to p_cam's size; its storage is reused from call to call).
  void Project(const std::vector<Vec3>& p_cam, std::vector<Vec2>* q) const;
  // Unit ray direction in camera coordinates for pixel q. std::nullopt when mrcal's
  // iterative unprojection does not converge (far outside the valid domain).
  std::optional<Vec3> Unproject(const Vec2& q) const;
  std::vector<std::optional<Vec3>> Unproject(const std::vector<Vec2>& q) const;

  // True when the point is in front of the camera (z > 0 or the model sees behind)
  // and projects inside the image, `margin` pixels from the border.
  bool Sees(const Vec3& p_cam, double margin = 0.0) const;

  // mrcal .cameramodel files (read and written by libmrcal itself, so Debian's mrcal
  // tools read what we write). InputError naming the file on failure.
  // A UTF-8 byte order mark before the text is skipped.
  static CameraModel ReadCameramodel(const std::filesystem::path& path);
  // The checks of a .cameramodel's text that need no complete model (the lens audit reads
  // files whose extrinsics mrcal's parser would refuse): after an optional UTF-8 BOM and
  // '#' comment lines, a Python dict '{...}'; its 'lensmodel' an mrcal lens model name and
  // its 'intrinsics' finite numbers. InputError naming `path` and the field otherwise.
  static void CheckCameramodelText(const std::string& text, const std::filesystem::path& path);
  void WriteCameramodel(const std::filesystem::path& path) const;

  // OpenCV FileStorage YAML: camera_matrix, distortion_coefficients (0, 4, 5, 8 or
  // 12 values), image_width, image_height, and optional extrinsics rvec/tvec
  // (T_cam_rig as a rotation vector and translation in metres). Only pinhole and
  // OpenCV lens models can be written.
  static CameraModel ReadOpenCvYaml(const std::filesystem::path& path);
  void WriteOpenCvYaml(const std::filesystem::path& path) const;

  // Reads either format by content (mrcal files start with '{' or '#').
  static CameraModel Read(const std::filesystem::path& path);

 private:
  void InitLens();
  std::string lensmodel_name_;
  std::vector<double> intrinsics_;
  int width_ = 0, height_ = 0;
  Pose T_cam_rig_;
  // mrcal_lensmodel_t, stored as raw bytes so this header does not pull in mrcal.
  alignas(8) unsigned char lensmodel_[32] = {};
};

// A rig: N cameras and their poses in the common rig frame.
struct CameraRig {
  std::vector<std::string> names;
  std::vector<CameraModel> cameras;
  size_t size() const { return cameras.size(); }

  // Rig file (YAML):
  //   cameras:
  //     - name: cam0
  //       model: cam0.cameramodel        # mrcal or OpenCV YAML, relative to the rig file
  //     - name: cam1
  //       lensmodel: LENSMODEL_OPENCV8   # or inline
  //       intrinsics: [fx, fy, cx, cy, k1, ...]
  //       imagersize: [1280, 1024]
  //       rt_cam_rig: [rx, ry, rz, tx, ty, tz]   # rotation vector (rad), metres
  static CameraRig Read(const std::filesystem::path& path);
  // InputError naming `where` and the two cameras when two share one centre (within 1 mm):
  // a rig without a baseline triangulates nothing. Read checks it; so does a scenario.
  void CheckBaselines(const std::string& where) const;
  // Writes the rig file with inline cameras, and if `models_dir` is given also one
  // .cameramodel per camera there.
  void Write(const std::filesystem::path& path) const;
};

}  // namespace mcms
