#include "vision/camera_model.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <regex>
#include <opencv2/core.hpp>
#include <sstream>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/yaml.h"
#include "vision/mrcal_c.h"

namespace mcms {

namespace fs = std::filesystem;
static_assert(sizeof(mrcal_lensmodel_t) <= 32, "lensmodel storage too small");

namespace {
constexpr double kMaxIntrinsic = 1e6;  // px for fx, fy, cx, cy; unitless for distortion
constexpr double kMinBaseline = 1e-3;  // m between two camera centres
constexpr int kMaxSplineKnots = 200;   // per axis of a splined model (mrcal's own use 10..30)
const mrcal_lensmodel_t& Lens(const unsigned char* raw) {
  return *reinterpret_cast<const mrcal_lensmodel_t*>(raw);
}
}  // namespace

CameraModel::CameraModel(const std::string& lensmodel, std::vector<double> intrinsics, int width, int height,
                         const Pose& T_cam_rig)
    : lensmodel_name_(lensmodel), intrinsics_(std::move(intrinsics)), width_(width), height_(height), T_cam_rig_(T_cam_rig) {
  InitLens();
}

void CameraModel::InitLens() {
  mrcal_lensmodel_t lens;
  if (!mrcal_lensmodel_from_name(&lens, lensmodel_name_.c_str()) || !mrcal_lensmodel_type_is_valid(lens.type))
    Throw("unknown or unconfigured lens model '", lensmodel_name_,
          "'; expected an mrcal model name such as LENSMODEL_PINHOLE, LENSMODEL_OPENCV8 or "
          "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=100");
  if (lens.type == MRCAL_LENSMODEL_SPLINED_STEREOGRAPHIC) {
    // libmrcal asserts (aborts the process) when it projects with a spline of another
    // order or with fewer knots than the order needs, and a field of view of 0 or 360
    // degrees and more gives an infinite or negative knot spacing: refuse them here.
    const auto& c = lens.LENSMODEL_SPLINED_STEREOGRAPHIC__config;
    const int min_knots = c.order == 2 ? 3 : 4;
    if ((c.order != 2 && c.order != 3) || c.Nx < min_knots || c.Ny < min_knots || c.Nx > kMaxSplineKnots ||
        c.Ny > kMaxSplineKnots || c.fov_x_deg < 1 || c.fov_x_deg > 359)
      Throw("lens model '", lensmodel_name_, "': order=", c.order, " Nx=", c.Nx, " Ny=", c.Ny, " fov_x_deg=", c.fov_x_deg,
            "; expected order 2 or 3, Nx and Ny from ", min_knots, " to ", kMaxSplineKnots,
            " (at least 3 for order 2, 4 for order 3) and fov_x_deg from 1 to 359");
  }
  if (!mrcal_lensmodel_metadata(&lens).has_gradients)
    Throw("lens model '", lensmodel_name_, "' has no gradients in mrcal and cannot be used for estimation");
  const int n = mrcal_lensmodel_num_params(&lens);
  if (n != static_cast<int>(intrinsics_.size()))
    Throw("lens model '", lensmodel_name_, "' takes ", n, " intrinsics, got ", intrinsics_.size());
  // Sane bounds: a focal length or centre beyond 1e6 px, or a distortion parameter
  // beyond 1e6, is a broken file (such a camera would silently project nothing).
  static const char* const kCore[4] = {"fx", "fy", "cx", "cy"};
  const bool has_core = mrcal_lensmodel_metadata(&lens).has_core;
  for (size_t i = 0; i < intrinsics_.size(); ++i) {
    const double v = intrinsics_[i];
    const std::string name = has_core && i < 4 ? std::string(kCore[i]) : "intrinsics[" + std::to_string(i) + "]";
    if (!std::isfinite(v) || std::abs(v) > kMaxIntrinsic)
      Throw("lens model '", lensmodel_name_, "': ", name, " = ", v, " is not a finite number within +-",
            kMaxIntrinsic);
    if (has_core && i < 2 && !(v > 0.0))
      Throw("lens model '", lensmodel_name_, "': focal length ", name, " = ", v, " px must be positive");
  }
  if (width_ <= 0 || height_ <= 0 || width_ > 100000 || height_ > 100000)
    Throw("camera image size must be positive and at most 100000 px, got ", width_, "x", height_);
  std::memcpy(lensmodel_, &lens, sizeof(lens));
}

bool CameraModel::CanProjectBehindCamera() const {
  return mrcal_lensmodel_metadata(&Lens(lensmodel_)).can_project_behind_camera;
}

Vec2 CameraModel::Project(const Vec3& p_cam, Eigen::Matrix<double, 2, 3>* dq_dp,
                          std::vector<double>* dq_dintrinsics) const {
  mrcal_point3_t p{{p_cam.x(), p_cam.y(), p_cam.z()}};
  mrcal_point2_t q;
  mrcal_point3_t grad[2];
  if (dq_dintrinsics) dq_dintrinsics->assign(2 * intrinsics_.size(), 0.0);
  mrcal_project(&q, dq_dp ? grad : nullptr, dq_dintrinsics ? dq_dintrinsics->data() : nullptr, &p, 1,
                &Lens(lensmodel_), intrinsics_.data());
  if (dq_dp)
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 3; ++c) (*dq_dp)(r, c) = grad[r].xyz[c];
  return {q.x, q.y};
}

std::vector<Vec2> CameraModel::Project(const std::vector<Vec3>& p_cam) const {
  std::vector<Vec2> out;
  Project(p_cam, &out);
  return out;
}

void CameraModel::Project(const std::vector<Vec3>& p_cam, std::vector<Vec2>* q) const {
  // Eigen's fixed-size vectors of doubles are laid out as mrcal's points (no padding):
  // mrcal reads and writes them in place.
  static_assert(sizeof(Vec3) == sizeof(mrcal_point3_t) && sizeof(Vec2) == sizeof(mrcal_point2_t));
  q->resize(p_cam.size());
  if (!p_cam.empty())
    mrcal_project(reinterpret_cast<mrcal_point2_t*>(q->data()), nullptr, nullptr,
                  reinterpret_cast<const mrcal_point3_t*>(p_cam.data()), static_cast<int>(p_cam.size()),
                  &Lens(lensmodel_), intrinsics_.data());
}

std::optional<Vec3> CameraModel::Unproject(const Vec2& q) const { return Unproject(std::vector<Vec2>{q})[0]; }

std::vector<std::optional<Vec3>> CameraModel::Unproject(const std::vector<Vec2>& qs) const {
  std::vector<mrcal_point2_t> q(qs.size());
  for (size_t i = 0; i < q.size(); ++i) q[i] = mrcal_point2_t{{qs[i].x(), qs[i].y()}};
  std::vector<mrcal_point3_t> v(q.size());
  std::vector<std::optional<Vec3>> out(q.size());
  if (q.empty()) return out;
  // mrcal_unproject reports failure for the whole batch; points that did not converge
  // come back as NaN, which we turn into nullopt.
  mrcal_unproject(v.data(), q.data(), static_cast<int>(q.size()), &Lens(lensmodel_), intrinsics_.data());
  for (size_t i = 0; i < q.size(); ++i) {
    const Vec3 d(v[i].x, v[i].y, v[i].z);
    if (!d.allFinite() || d.norm() == 0.0) continue;
    // Check the round trip: a non-converged solve does not reproject to q.
    const Vec2 back = Project(d);
    if (!back.allFinite() || (back - qs[i]).norm() > 1e-3) continue;
    out[i] = d.normalized();
  }
  return out;
}

bool CameraModel::Sees(const Vec3& p_cam, double margin) const {
  if (!(p_cam.z() > 0.0) && !CanProjectBehindCamera()) return false;
  const Vec2 q = Project(p_cam);
  return q.allFinite() && q.x() >= -0.5 + margin && q.y() >= -0.5 + margin && q.x() <= width_ - 0.5 - margin &&
         q.y() <= height_ - 0.5 - margin;
}

namespace {
// The text without a leading UTF-8 byte order mark (written by some editors).
std::string WithoutBom(std::string text) {
  if (text.compare(0, 3, "\xEF\xBB\xBF") == 0) text.erase(0, 3);
  return text;
}

constexpr const char* kCameramodelFormat =
    "expected mrcal's Python-literal format: '#' comment lines, then a dict {'lensmodel': 'LENSMODEL_...', "
    "'intrinsics': [...], 'extrinsics': [...], 'imagersize': [w, h]}";

// The value text after a top-level key 'key' (or "key") and its colon; npos when absent.
size_t ValueOf(const std::string& text, const std::string& key) {
  for (const char q : {'\'', '"'}) {
    const std::string k = std::string(1, q) + key + q;
    size_t at = text.find(k);
    while (at != std::string::npos) {
      const size_t colon = text.find_first_not_of(" \t\r\n", at + k.size());
      if (colon != std::string::npos && text[colon] == ':') return colon + 1;
      at = text.find(k, at + 1);
    }
  }
  return std::string::npos;
}
}  // namespace

void CameraModel::CheckCameramodelText(const std::string& raw, const fs::path& path) {
  const std::string text = WithoutBom(raw);
  size_t at = 0;
  while (true) {
    at = text.find_first_not_of(" \t\r\n", at);
    if (at == std::string::npos || text[at] != '#') break;
    at = text.find('\n', at);
  }
  if (at == std::string::npos || text[at] != '{')
    Throw(path.string(), " is not a .cameramodel (", kCameramodelFormat, "); it ",
          at == std::string::npos ? std::string("holds no dict (empty or only comments)")
                                  : std::string("does not start with '{'"));
  const size_t lm = ValueOf(text, "lensmodel");
  if (lm != std::string::npos) {
    const size_t q = text.find_first_not_of(" \t\r\n", lm);
    const size_t e = q == std::string::npos ? q : text.find(text[q], q + 1);
    if (q == std::string::npos || (text[q] != '\'' && text[q] != '"') || e == std::string::npos)
      Throw(path.string(), ": field 'lensmodel' is not a quoted name (", kCameramodelFormat, ")");
    const std::string name = text.substr(q + 1, e - q - 1);
    mrcal_lensmodel_t lens;
    if (!mrcal_lensmodel_from_name(&lens, name.c_str()) || !mrcal_lensmodel_type_is_valid(lens.type))
      Throw(path.string(), ": field 'lensmodel' is '", name.substr(0, 80),
            "'; expected an mrcal lens model name such as LENSMODEL_PINHOLE, LENSMODEL_OPENCV8 or "
            "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=100");
  }
  const size_t in = ValueOf(text, "intrinsics");
  if (in != std::string::npos) {
    const size_t open = text.find_first_not_of(" \t\r\n", in);
    const size_t close = open == std::string::npos ? open : text.find(']', open);
    if (open == std::string::npos || text[open] != '[' || close == std::string::npos)
      Throw(path.string(), ": field 'intrinsics' is not a list [fx, fy, cx, cy, ...] of numbers");
    static const char* const kCore[4] = {"fx", "fy", "cx", "cy"};
    std::stringstream list(text.substr(open + 1, close - open - 1));
    std::string cell;
    for (size_t i = 0; std::getline(list, cell, ','); ++i) {
      const size_t b = cell.find_first_not_of(" \t\r\n");
      if (b == std::string::npos) continue;  // the trailing comma mrcal writes
      const size_t e = cell.find_last_not_of(" \t\r\n");
      const std::string v = cell.substr(b, e - b + 1);
      char* end = nullptr;
      const double x = std::strtod(v.c_str(), &end);
      const std::string name = i < 4 ? std::string(kCore[i]) : "intrinsics[" + std::to_string(i) + "]";
      if (end == v.c_str() || *end != 0 || !std::isfinite(x))
        Throw(path.string(), ": field 'intrinsics', ", name, " is '", v.substr(0, 40), "'; expected a finite number");
    }
  }
}

CameraModel CameraModel::ReadCameramodel(const fs::path& path) {
  if (!fs::exists(path)) Throw("camera model file ", path.string(), " does not exist");
  const std::string text = WithoutBom(ReadTextFile(path));
  CheckCameramodelText(text, path);
  mrcal_cameramodel_t* m = mrcal_read_cameramodel_string(text.data(), static_cast<int>(text.size()));
  if (!m) Throw("cannot parse mrcal camera model ", path.string(), ": ", kCameramodelFormat);
  std::unique_ptr<mrcal_cameramodel_t, void (*)(mrcal_cameramodel_t*)> guard(
      m, [](mrcal_cameramodel_t* p) { mrcal_free_cameramodel(&p); });
  char name[256];
  if (!mrcal_lensmodel_name(name, sizeof(name), &m->lensmodel)) Throw("camera model ", path.string(), ": bad lens model");
  const int n = mrcal_lensmodel_num_params(&m->lensmodel);
  std::vector<double> intr(m->intrinsics, m->intrinsics + n);
  for (int i = 0; i < 6; ++i)
    if (!std::isfinite(m->rt_cam_ref[i]))
      Throw("camera model ", path.string(), ": extrinsics[", i, "] = ", m->rt_cam_ref[i], "; expected finite numbers");
  try {
    return CameraModel(name, intr, static_cast<int>(m->imagersize[0]), static_cast<int>(m->imagersize[1]),
                       Pose::FromRt(m->rt_cam_ref));
  } catch (const InputError& e) {
    Throw("camera model ", path.string(), ": ", e.what());
  }
}

void CameraModel::WriteCameramodel(const fs::path& path) const {
  // We write the file ourselves: libmrcal 2.2's mrcal_write_cameramodel_file() prints
  // with "%f", which keeps 6 decimals and destroys small distortion coefficients and
  // rotations. The text is the same Python-literal format mrcal writes, at full
  // precision; libmrcal and Debian's mrcal tools read it (tests check both).
  double rt[6];
  T_cam_rig_.ToRt(rt);
  char buf[64];
  auto num = [&](double v) {
    std::snprintf(buf, sizeof(buf), "%.17g", v);
    return std::string(buf);
  };
  std::ostringstream s;
  s << "# generated by mcms\n{\n";
  s << "    'lensmodel':  '" << lensmodel_name_ << "',\n\n";
  s << "    # intrinsics are fx,fy,cx,cy,distortion0,distortion1,....\n";
  s << "    'intrinsics': [ ";
  for (size_t i = 0; i < intrinsics_.size(); ++i) s << (i ? ", " : "") << num(intrinsics_[i]);
  s << ",],\n\n";
  s << "    # extrinsics are rt_fromref\n    'extrinsics': [ ";
  for (int i = 0; i < 6; ++i) s << (i ? ", " : "") << num(rt[i]);
  s << ",],\n\n";
  s << "    'imagersize': [ " << width_ << ", " << height_ << ",],\n}\n";
  const std::string text = s.str();
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

namespace {
// OpenCV distortion counts -> mrcal model names.
std::string LensFromDistortionCount(int n, const fs::path& path) {
  switch (n) {
    case 0: return "LENSMODEL_PINHOLE";
    case 4: return "LENSMODEL_OPENCV4";
    case 5: return "LENSMODEL_OPENCV5";
    case 8: return "LENSMODEL_OPENCV8";
    case 12: return "LENSMODEL_OPENCV12";
  }
  Throw(path.string(), ": distortion_coefficients has ", n, " values; expected 0, 4, 5, 8 or 12");
}

// An !!opencv-matrix field read with yaml-cpp. OpenCV's own FileStorage parser is not used
// for reading: fuzzing found it asserting on malformed matrices, allocating what a file
// claims (2^31 rows) and looping forever on 83 bytes of `%`-directive lines inside a
// document (fuzz/regressions/camera/opencv_filestorage_hang.yaml). yaml-cpp refuses such text
// with a line number. Every matrix of a camera file is small (3x3, at most 1x14).
constexpr int kMaxOpenCvMatrixSide = 16;
struct OpenCvMatrix {
  int rows = 0, cols = 0;
  std::vector<double> data;  // row-major
  bool empty() const { return data.empty(); }
};
OpenCvMatrix ReadSmallMatrix(const YAML::Node& root, const char* field, const fs::path& path) {
  OpenCvMatrix m;
  const YAML::Node n = root[field];
  if (!n || n.IsNull()) return m;
  const auto fail = [&](const auto&... what) {
    Throw("cannot parse OpenCV YAML ", path.string(), ": field ", field, " (line ", n.Mark().line + 1, ") ", what...,
          " (an !!opencv-matrix has rows, cols, dt and rows x cols numbers in data)");
  };
  if (!n.IsMap()) fail("is not an !!opencv-matrix (a map with rows, cols, dt, data)");
  const auto side = [&](const char* key) {
    const YAML::Node d = n[key];
    int v = -1;
    if (d && d.IsScalar()) {
      try {
        v = d.as<int>();
      } catch (const YAML::Exception&) {
        v = -1;
      }
    }
    if (v < 0 || v > kMaxOpenCvMatrixSide)
      fail("declares ", key, " '", d && d.IsScalar() ? d.Scalar() : std::string("(none)"), "'; expected ", key,
           " from 0 to ", kMaxOpenCvMatrixSide);
    return v;
  };
  m.rows = side("rows");
  m.cols = side("cols");
  const YAML::Node dt = n["dt"];
  if (!dt || !dt.IsScalar()) fail("has no dt (element type)");
  // dt is OpenCV's element type: one of u c w s i f d, optionally preceded by a channel
  // count; a camera matrix has one channel.
  const std::string t = dt.Scalar();
  if (t.size() != 1 || std::string("ucwsifd").find(t[0]) == std::string::npos)
    fail("has dt '", t, "'; expected one channel of u, c, w, s, i, f or d");
  const YAML::Node data = n["data"];
  if (!data || !data.IsSequence()) fail("has no data list");
  for (const auto& e : data) {
    double v = 0;
    bool number = e.IsScalar();
    if (number) {
      try {
        v = e.as<double>();
      } catch (const YAML::Exception&) {
        number = false;
      }
    }
    if (!number) fail("holds '", e.IsScalar() ? e.Scalar() : std::string("a list"), "' in data; expected numbers");
    if (!std::isfinite(v)) fail("holds ", e.Scalar(), " in data; expected finite numbers");
    m.data.push_back(v);
  }
  if (static_cast<int>(m.data.size()) != m.rows * m.cols)
    fail("declares ", m.rows, "x", m.cols, " but data has ", m.data.size(), " numbers");
  return m;
}

int ReadImageSide(const YAML::Node& root, const char* field, const fs::path& path) {
  const YAML::Node n = root[field];
  if (!n) return 0;
  try {
    if (n.IsScalar()) return n.as<int>();
  } catch (const YAML::Exception&) {
  }
  Throw("cannot parse OpenCV YAML ", path.string(), ": field ", field, " (line ", n.Mark().line + 1, ") is '",
        n.IsScalar() ? n.Scalar() : std::string("not a number"), "'; expected the image size in pixels");
}
}  // namespace

CameraModel CameraModel::ReadOpenCvYaml(const fs::path& path) {
  if (!fs::exists(path)) Throw("camera file ", path.string(), " does not exist");
  std::string text = WithoutBom(ReadTextFile(path));
  // OpenCV writes "%YAML:1.0" (and older files "%YAML 1.0") as the first line; the colon
  // form is not YAML, so that one line is blanked (line numbers stay right).
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && text.compare(first, 5, "%YAML") == 0) {
    const auto eol = std::min(text.find('\n', first), text.size());
    static const std::regex kHeader(R"(%YAML[: ]1\.[0-9]+[ \t\r]*)");
    if (std::regex_match(text.begin() + static_cast<std::ptrdiff_t>(first), text.begin() + static_cast<std::ptrdiff_t>(eol), kHeader))
      text.replace(first, eol - first, "");
  }
  YAML::Node root;
  try {
    root = LoadYaml(text, path.string());
  } catch (const YAML::Exception& e) {
    Throw("cannot parse OpenCV YAML ", path.string(), ": line ", e.mark.line + 1, ": ", e.msg,
          " (expected an OpenCV FileStorage file: %YAML:1.0, then camera_matrix, distortion_coefficients, "
          "image_width, image_height)");
  }
  if (!root.IsMap())
    Throw("cannot parse OpenCV YAML ", path.string(),
          ": expected a map of fields (camera_matrix, distortion_coefficients, image_width, image_height)");
  OpenCvMatrix K = ReadSmallMatrix(root, "camera_matrix", path);
  if (K.empty()) K = ReadSmallMatrix(root, "M1", path);
  OpenCvMatrix D = ReadSmallMatrix(root, "distortion_coefficients", path);
  if (D.empty()) D = ReadSmallMatrix(root, "D1", path);
  const int w = ReadImageSide(root, "image_width", path);
  const int h = ReadImageSide(root, "image_height", path);
  const OpenCvMatrix rvec = ReadSmallMatrix(root, "rvec", path);
  const OpenCvMatrix tvec = ReadSmallMatrix(root, "tvec", path);
  if (K.rows != 3 || K.cols != 3) Throw(path.string(), ": field camera_matrix missing or not 3x3");
  if (w <= 0 || h <= 0) Throw(path.string(), ": fields image_width and image_height missing or not positive");
  std::vector<double> intr = {K.data[0], K.data[4], K.data[2], K.data[5]};
  intr.insert(intr.end(), D.data.begin(), D.data.end());
  const std::string lens = LensFromDistortionCount(static_cast<int>(D.data.size()), path);
  Pose T;
  if (!rvec.empty() && !tvec.empty()) {
    if (rvec.data.size() != 3 || tvec.data.size() != 3) Throw(path.string(), ": rvec and tvec must have 3 values each");
    double rt[6];
    for (int i = 0; i < 3; ++i) {
      rt[i] = rvec.data[i];
      rt[3 + i] = tvec.data[i];
    }
    T = Pose::FromRt(rt);
  }
  try {
    return CameraModel(lens, intr, w, h, T);
  } catch (const InputError& e) {
    Throw(path.string(), ": ", e.what());
  }
}

void CameraModel::WriteOpenCvYaml(const fs::path& path) const {
  const std::string& n = lensmodel_name_;
  if (n != "LENSMODEL_PINHOLE" && n.rfind("LENSMODEL_OPENCV", 0) != 0)
    Throw("cannot write ", path.string(), " as OpenCV YAML: lens model ", n, " has no OpenCV equivalent");
  cv::Mat K = (cv::Mat_<double>(3, 3) << intrinsics_[0], 0, intrinsics_[2], 0, intrinsics_[1], intrinsics_[3], 0, 0, 1);
  cv::Mat D(1, static_cast<int>(intrinsics_.size()) - 4, CV_64F);
  for (int i = 0; i < D.cols; ++i) D.at<double>(0, i) = intrinsics_[4 + i];
  double rt[6];
  T_cam_rig_.ToRt(rt);
  cv::Mat rvec = (cv::Mat_<double>(3, 1) << rt[0], rt[1], rt[2]);
  cv::Mat tvec = (cv::Mat_<double>(3, 1) << rt[3], rt[4], rt[5]);
  cv::FileStorage out(".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  out << "image_width" << width_ << "image_height" << height_ << "camera_matrix" << K;
  if (D.cols > 0) out << "distortion_coefficients" << D;
  out << "rvec" << rvec << "tvec" << tvec;
  const std::string text = out.releaseAndGetString();
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

CameraModel CameraModel::Read(const fs::path& path) {
  const std::string text = WithoutBom(ReadTextFile(path));
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && (text[first] == '{' || text[first] == '#')) return ReadCameramodel(path);
  return ReadOpenCvYaml(path);
}

namespace {
std::vector<double> NumberList(const YAML::Node& n, const std::string& what, const fs::path&) {
  if (!n || !n.IsSequence()) Throw("field '", what, "' missing or not a list of numbers");
  std::vector<double> v;
  for (const auto& e : n) {
    try {
      v.push_back(e.as<double>());
    } catch (const YAML::Exception&) {
      Throw("line ", e.Mark().line + 1, ": field '", what, "' must hold numbers");
    }
    if (!std::isfinite(v.back()))
      Throw("line ", e.Mark().line + 1, ": field '", what, "' holds ", e.Scalar(),
            "; expected finite numbers");
  }
  return v;
}
}  // namespace

CameraRig CameraRig::Read(const fs::path& path) {
  if (!fs::exists(path)) Throw("rig file ", path.string(), " does not exist");
  YAML::Node root;
  try {
    root = LoadYaml(ReadTextFile(path), "rig file " + path.string());
  } catch (const YAML::Exception& e) {
    Throw("cannot parse rig file ", path.string(), ": ", e.what());
  }
  if (!root.IsMap())
    Throw(path.string(), ": expected a YAML map with a list 'cameras', found ",
          root.IsScalar() ? "a single value '" + root.Scalar() + "'" : root.IsSequence() ? std::string("a list") : std::string("nothing"));
  const YAML::Node cams = root["cameras"];
  if (!cams || !cams.IsSequence() || cams.size() == 0)
    Throw(path.string(), ": expected a non-empty list 'cameras'");
  CameraRig rig;
  for (size_t i = 0; i < cams.size(); ++i) {
    const YAML::Node c = cams[i];
    if (!c.IsMap()) Throw(path.string(), " line ", c.Mark().line + 1, ": camera ", i, " must be a map (name, model or lensmodel, ...)");
    if (c["name"] && !c["name"].IsScalar()) Throw(path.string(), " line ", c.Mark().line + 1, ": camera ", i, ": 'name' must be a text");
    const std::string name = c["name"] ? c["name"].as<std::string>() : "cam" + std::to_string(i);
    if (name.size() > kMaxCameraNameLength)
      Throw(path.string(), " line ", c.Mark().line + 1, ": camera name '", name.substr(0, 20), "...' has ", name.size(),
            " characters, at most ", kMaxCameraNameLength, " (it names the camera's image folder)");
    if (std::find(rig.names.begin(), rig.names.end(), name) != rig.names.end())
      Throw(path.string(), " line ", c.Mark().line + 1, ": camera name '", name,
            "' is used twice; every camera needs its own name (its image folder)");
    const std::string where = path.string() + ", camera " + name;
    try {
      if (c["model"]) {
        fs::path model = c["model"].as<std::string>();
        if (model.is_relative()) model = path.parent_path() / model;
        rig.cameras.push_back(CameraModel::Read(model));
      } else {
        if (!c["lensmodel"]) Throw("needs either 'model' (a file) or 'lensmodel', 'intrinsics', 'imagersize'");
        const auto size = NumberList(c["imagersize"], "imagersize", path);
        // Checked before the conversion to int (a double beyond int's range has no int value).
        if (size.size() != 2 || size[0] != std::floor(size[0]) || size[1] != std::floor(size[1]) || size[0] < 1 ||
            size[1] < 1 || size[0] > 100000 || size[1] > 100000)
          Throw("'imagersize' must be [width, height] in whole pixels from 1 to 100000, got ", size.size(), " values",
                size.size() == 2 ? std::string(" [").append(std::to_string(size[0])).append(", ").append(std::to_string(size[1])).append("]") : std::string());
        Pose T;
        if (c["rt_cam_rig"]) {
          const auto rt = NumberList(c["rt_cam_rig"], "rt_cam_rig", path);
          if (rt.size() != 6) Throw("'rt_cam_rig' must have 6 numbers (rotation vector, translation in m)");
          T = Pose::FromRt(rt.data());
        }
        rig.cameras.emplace_back(c["lensmodel"].as<std::string>(), NumberList(c["intrinsics"], "intrinsics", path),
                                 static_cast<int>(size[0]), static_cast<int>(size[1]), T);
      }
    } catch (const InputError& e) {
      Throw(where, ": ", e.what());
    } catch (const YAML::Exception& e) {
      Throw(where, ": ", e.what());
    }
    rig.names.push_back(name);
  }
  rig.CheckBaselines(path.string());
  return rig;
}

void CameraRig::CheckBaselines(const std::string& where) const {
  // A rig whose cameras share one centre has no baseline: nothing can be triangulated.
  for (size_t i = 0; i < size(); ++i)
    for (size_t j = i + 1; j < size(); ++j) {
      const Vec3 ci = cameras[i].T_cam_rig().Inverse().t, cj = cameras[j].T_cam_rig().Inverse().t;
      if ((ci - cj).norm() < kMinBaseline)
        Throw(where, ": cameras '", names[i], "' and '", names[j], "' are both at (", ci.x(), ", ", ci.y(), ", ",
              ci.z(), ") m in the rig frame (", (ci - cj).norm() * 1e3,
              " mm apart, at least 1 mm needed); check their positions (rt_cam_rig): a rig needs a baseline");
    }
}

void CameraRig::Write(const fs::path& path) const {
  YAML::Emitter out;
  out << YAML::BeginMap << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  out.SetDoublePrecision(17);
  for (size_t i = 0; i < cameras.size(); ++i) {
    const CameraModel& c = cameras[i];
    double rt[6];
    c.T_cam_rig().ToRt(rt);
    out << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << (i < names.size() ? names[i] : "cam" + std::to_string(i));
    out << YAML::Key << "lensmodel" << YAML::Value << c.LensModelName();
    out << YAML::Key << "intrinsics" << YAML::Value << YAML::Flow << c.Intrinsics();
    out << YAML::Key << "imagersize" << YAML::Value << YAML::Flow << std::vector<int>{c.Width(), c.Height()};
    out << YAML::Key << "rt_cam_rig" << YAML::Value << YAML::Flow << std::vector<double>(rt, rt + 6);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  const std::string text = out.c_str();
  WriteFileAtomically(path, [&](std::ostream& o) { o << text << "\n"; });
}

}  // namespace mcms
