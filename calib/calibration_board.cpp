#include "calib/calibration_board.h"

#include <numbers>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <sstream>

#include <Eigen/Eigenvalues>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
}

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/yaml.h"

namespace mcms {

CalibrationBoard CalibrationBoard::Chessboard(int cols, int rows, double square_m) {
  CalibrationBoard b;
  b.type = Type::kChessboard;
  b.cols = cols;
  b.rows = rows;
  b.square_m = square_m;
  return b;
}

CalibrationBoard CalibrationBoard::AprilGrid(int tag_cols, int tag_rows, double tag_size_m, double tag_spacing) {
  CalibrationBoard b;
  b.type = Type::kAprilGrid;
  b.tag_cols = tag_cols;
  b.tag_rows = tag_rows;
  b.tag_size_m = tag_size_m;
  b.tag_spacing = tag_spacing;
  return b;
}

bool CalibrationBoard::IsValid(std::string* why) const {
  std::ostringstream s;
  if (type == Type::kChessboard) {
    if (cols < 2 || rows < 2) s << "a chessboard needs at least 2x2 inner corners (got " << cols << "x" << rows << ")";
    // Bounded so that NumPoints() and every per-corner buffer stay far from int overflow.
    else if (cols > kMaxChessboardSide || rows > kMaxChessboardSide)
      s << "a chessboard has at most " << kMaxChessboardSide << " inner corners per side (got " << cols << "x" << rows << ")";
    else if (!(square_m > 0.0) || !std::isfinite(square_m)) s << "chessboard square size must be > 0 m (got " << square_m << ")";
    else if (square_m > kMaxBoardSquareM)
      s << "chessboard square size " << square_m << " m is beyond " << kMaxBoardSquareM
        << " m (millimetres where metres are expected?); give the square in metres";
  } else {
    if (tag_cols < 1 || tag_rows < 1) s << "an AprilGrid needs at least 1x1 tags (got " << tag_cols << "x" << tag_rows << ")";
    // In 64 bits: tagCols: 100000 x tagRows: 100000 overflowed int (found by fuzz/fuzz_target).
    else if (int64_t{tag_cols} * tag_rows > 587) s << "tag36h11 has 587 ids; the grid has " << int64_t{tag_cols} * tag_rows;
    else if (!(tag_size_m > 0.0) || !std::isfinite(tag_size_m)) s << "tagSize must be > 0 m (got " << tag_size_m << ")";
    else if (tag_size_m > kMaxBoardSquareM)
      s << "tagSize " << tag_size_m << " m is beyond " << kMaxBoardSquareM
        << " m (millimetres where metres are expected?); give the tag size in metres";
    else if (!(tag_spacing >= 0.0) || !std::isfinite(tag_spacing)) s << "tagSpacing must be >= 0 (got " << tag_spacing << ")";
  }
  if (why) *why = s.str();
  return s.str().empty();
}

int CalibrationBoard::NumPoints() const {
  return type == Type::kChessboard ? cols * rows : 4 * tag_cols * tag_rows;
}

Vec3 CalibrationBoard::Point(int id) const {
  if (type == Type::kChessboard) return {(id % cols) * square_m, (id / cols) * square_m, 0.0};
  const int tag = id / 4, corner = id % 4;
  const double pitch = tag_size_m * (1.0 + tag_spacing);
  const double x0 = (tag % tag_cols) * pitch, y0 = (tag / tag_cols) * pitch;
  static const int kDx[4] = {0, 1, 1, 0}, kDy[4] = {0, 0, 1, 1};
  return {x0 + kDx[corner] * tag_size_m, y0 + kDy[corner] * tag_size_m, 0.0};
}

std::vector<Pose> CalibrationBoard::NumberingSymmetries() const {
  std::vector<Pose> out;
  if (type != Type::kChessboard || (cols + rows) % 2 != 0) return out;
  const Vec3 centre((cols - 1) * square_m / 2, (rows - 1) * square_m / 2, 0.0);
  for (int quarter = 1; quarter < 4; ++quarter) {
    if (cols != rows && quarter != 2) continue;
    const Mat3 R = ExpSO3(Vec3(0, 0, quarter * std::numbers::pi / 2));
    // Exact entries (0, +-1): the mapped points land exactly on grid points.
    Mat3 Rr = R.array().round().matrix();
    out.push_back(Pose{Rr, centre - Rr * centre});
  }
  return out;
}

double CalibrationBoard::SymmetryAngleDeg(const Pose& S) {
  double a = std::atan2(S.R(1, 0), S.R(0, 0)) * 180.0 / std::numbers::pi;
  if (a < 0) a += 360.0;
  return a;
}

std::string CalibrationBoard::Describe() const {
  std::ostringstream s;
  if (type == Type::kChessboard)
    s << "chessboard " << cols << "x" << rows << " inner corners, " << square_m * 1e3 << " mm squares";
  else
    s << "aprilgrid tag36h11 " << tag_cols << "x" << tag_rows << " tags, " << tag_size_m * 1e3 << " mm, spacing "
      << tag_spacing;
  return s.str();
}

CalibrationBoard CalibrationBoard::Read(const std::filesystem::path& path) {
  YAML::Node y;
  try {
    y = LoadYaml(ReadTextFile(path), path.string());  // bounded, and a folder is refused by name
  } catch (const std::exception& e) {
    Throw("board file ", path.string(), ": cannot read it as YAML (", e.what(), ")");
  }
  if (!y.IsMap()) Throw("board file ", path.string(), ": expected a Kalibr YAML map starting with target_type (aprilgrid or checkerboard)");
  auto need = [&](const char* key) {
    if (!y[key]) Throw("board file ", path.string(), ": missing field '", key, "'");
    return y[key];
  };
  CalibrationBoard b;
  try {
    const std::string type = need("target_type").as<std::string>();
    if (type == "aprilgrid") {
      b = AprilGrid(need("tagCols").as<int>(), need("tagRows").as<int>(), need("tagSize").as<double>(),
                    need("tagSpacing").as<double>());
    } else if (type == "checkerboard" || type == "chessboard") {
      const double row = need("rowSpacingMeters").as<double>(), col = need("colSpacingMeters").as<double>();
      if (std::abs(row - col) > 1e-9 * std::max(1.0, std::abs(row)))
        Throw("board file ", path.string(), ": rowSpacingMeters (", row, ") and colSpacingMeters (", col,
              ") differ; only square chessboards are supported");
      b = Chessboard(need("targetCols").as<int>(), need("targetRows").as<int>(), row);
    } else {
      Throw("board file ", path.string(), ": target_type '", type, "' is not supported (expected aprilgrid or checkerboard)");
    }
  } catch (const YAML::Exception& e) {
    Throw("board file ", path.string(), ": a field has the wrong type (", e.what(), ")");
  }
  std::string why;
  if (!b.IsValid(&why)) Throw("board file ", path.string(), ": ", why);
  return b;
}

namespace {

cv::Mat ToGray8(const cv::Mat& image) {
  if (image.empty()) Throw("DetectBoard: empty image");
  cv::Mat gray;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 4) cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  else gray = image;
  if (gray.depth() != CV_8U) {
    double lo, hi;
    cv::minMaxLoc(gray, &lo, &hi);
    gray.convertTo(gray, CV_8U, hi > lo ? 255.0 / (hi - lo) : 1.0, hi > lo ? -lo * 255.0 / (hi - lo) : 0.0);
  }
  return gray;
}

}  // namespace

bool AprilTagOptions::IsValid(std::string* why) const {
  std::ostringstream s;
  if (!(quad_decimate >= 1.0f) || !std::isfinite(quad_decimate))
    s << "quad_decimate must be >= 1 (got " << quad_decimate << ")";
  else if (!(quad_sigma >= 0.0f) || !std::isfinite(quad_sigma))
    s << "quad_sigma must be >= 0 px (got " << quad_sigma << ")";
  else if (threads < 1)
    s << "threads must be >= 1 (got " << threads << ")";
  else if (max_hamming < 0 || max_hamming > 2)
    s << "max_hamming must be 0, 1 or 2 (got " << max_hamming << ")";
  if (why) *why = s.str();
  return s.str().empty();
}

namespace {

// Grey level at (x, y) in this project's convention (pixel centres at integers),
// bilinear between the four nearest pixel centres; nullopt within one pixel of the
// border, where the four neighbours do not exist.
std::optional<double> Bilinear(const cv::Mat& gray, double x, double y) {
  const double fx = std::floor(x), fy = std::floor(y);
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  if (!(x0 >= 0 && y0 >= 0 && x0 + 1 < gray.cols && y0 + 1 < gray.rows)) return std::nullopt;
  const double a = x - fx, b = y - fy;
  const uchar* r0 = gray.ptr<uchar>(y0) + x0;
  const uchar* r1 = gray.ptr<uchar>(y0 + 1) + x0;
  return (1 - a) * (1 - b) * r0[0] + a * (1 - b) * r0[1] + (1 - a) * b * r1[0] + a * b * r1[1];
}

// A line {p : n . (p - point) = 0}, n a unit normal.
struct Line2 {
  Vec2 point, normal;
};

std::optional<Vec2> Intersect(const Line2& a, const Line2& b) {
  Eigen::Matrix2d A;
  A << a.normal.transpose(), b.normal.transpose();
  // Adjacent tag edges meet at a clear angle in any usable view; below ~0.06 deg the
  // crossing is ill-defined.
  if (std::abs(A.determinant()) < 1e-3) return std::nullopt;
  return A.inverse() * Vec2(a.normal.dot(a.point), b.normal.dot(b.point));
}

// Re-fits the four edges of a tag quad to the image gradient and returns the corners
// where adjacent fitted edges cross; nullopt (keep the corners given) when an edge
// finds too little gradient or a corner would move further than the search range.
// `corners` in this project's convention, in cyclic order around the quad.
//
// Per edge, at max(16, length/8) points spread along it (avoiding the corners,
// whose neighbourhood mixes two edges), the grey-level step across the edge is
// sampled every 1/4 px along the outward normal within +-range px; each sample's
// weight is the squared difference of the grey levels 1 px outside and 1 px inside
// it, kept only where the outside is the brighter (tag36h11's black border on its
// white surround), and the weighted mean offset is that point's edge crossing.
// The line through the crossings is the total-least-squares fit. This is the
// refinement of later libapriltag versions (bilinear reads at the right half-pixel,
// which 3.3's truncated integer reads get wrong); range = quad_decimate + 1 as
// there, the uncertainty of the quad fit in the (decimated) threshold image.
std::optional<std::array<Vec2, 4>> RefineTagEdges(const cv::Mat& gray, const std::array<Vec2, 4>& corners,
                                                  double range) {
  constexpr double kStepPx = 0.25, kHalfBaselinePx = 1.0;
  constexpr int kMinCrossings = 4;
  const Vec2 centre = 0.25 * (corners[0] + corners[1] + corners[2] + corners[3]);
  std::array<Line2, 4> lines;
  for (int e = 0; e < 4; ++e) {
    const Vec2& a = corners[e];
    const Vec2& b = corners[(e + 1) % 4];
    const double length = (b - a).norm();
    if (!(length > 0)) return std::nullopt;
    Vec2 n(b.y() - a.y(), a.x() - b.x());
    n /= length;
    if (n.dot(0.5 * (a + b) - centre) < 0) n = -n;  // outward
    const int nsamples = std::max(16, static_cast<int>(length / 8));
    std::vector<Vec2> crossings;
    for (int s = 0; s < nsamples; ++s) {
      const double alpha = (1.0 + s) / (nsamples + 1);
      const Vec2 p0 = alpha * a + (1 - alpha) * b;
      double sum_wn = 0, sum_w = 0;
      const int steps = static_cast<int>(std::floor(2 * range / kStepPx)) + 1;
      for (int k = 0; k < steps; ++k) {
        const double t = -range + kStepPx * k;
        const auto outside = Bilinear(gray, p0.x() + (t + kHalfBaselinePx) * n.x(), p0.y() + (t + kHalfBaselinePx) * n.y());
        const auto inside = Bilinear(gray, p0.x() + (t - kHalfBaselinePx) * n.x(), p0.y() + (t - kHalfBaselinePx) * n.y());
        if (!outside || !inside || *outside < *inside) continue;
        const double w = (*outside - *inside) * (*outside - *inside);
        sum_wn += w * t;
        sum_w += w;
      }
      if (sum_w > 0) crossings.push_back(p0 + (sum_wn / sum_w) * n);
    }
    if (static_cast<int>(crossings.size()) < kMinCrossings) return std::nullopt;
    Vec2 mean = Vec2::Zero();
    for (const Vec2& c : crossings) mean += c;
    mean /= static_cast<double>(crossings.size());
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const Vec2& c : crossings) cov += (c - mean) * (c - mean).transpose();
    // The normal of the best-fit line: the eigenvector of the smaller eigenvalue.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    lines[e] = {mean, eig.eigenvectors().col(0)};
  }
  std::array<Vec2, 4> out;
  for (int e = 0; e < 4; ++e) {
    // Corner e + 1 is where edge e (corners e -> e+1) meets edge e + 1.
    const int k = (e + 1) % 4;
    const auto x = Intersect(lines[e], lines[k]);
    if (!x || (*x - corners[k]).norm() > range + kHalfBaselinePx) return std::nullopt;
    out[k] = *x;
  }
  return out;
}

// Where the diagonals of the quad cross: the image of the tag centre under the
// homography through the four corners (what libapriltag reports as c).
Vec2 DiagonalCrossing(const Vec2 p[4], const Vec2& fallback) {
  const Vec2 d0 = p[2] - p[0], d1 = p[3] - p[1];
  Eigen::Matrix2d A;
  A << d0.x(), -d1.x(), d0.y(), -d1.y();
  if (std::abs(A.determinant()) < 1e-9) return fallback;
  const Vec2 st = A.inverse() * (p[1] - p[0]);
  return p[0] + st[0] * d0;
}

}  // namespace

std::vector<AprilTagDetection> DetectAprilTags(const cv::Mat& image, const AprilTagOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("DetectAprilTags: options: ", why);
  cv::Mat gray = ToGray8(image);
  if (!gray.isContinuous()) gray = gray.clone();
  std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> family(tag36h11_create(), tag36h11_destroy);
  std::unique_ptr<apriltag_detector_t, void (*)(apriltag_detector_t*)> detector(apriltag_detector_create(),
                                                                               apriltag_detector_destroy);
  apriltag_detector_add_family_bits(detector.get(), family.get(), options.max_hamming);
  detector->quad_decimate = options.quad_decimate;
  detector->quad_sigma = options.quad_sigma;
  detector->nthreads = options.threads;
  // libapriltag 3.3 refines before decoding, so kLibApriltag33 also decodes the
  // refined quad; the other modes decode the unrefined quad (as AprilTag's own
  // regression data did; there all 47 of its tags decode from the unrefined quad at
  // max_hamming 2, 45 from 3.3's refined one; 46 and 44 at max_hamming 1).
  detector->refine_edges = options.corner_refinement == AprilTagCornerRefinement::kLibApriltag33;
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step[0]), gray.data};
  zarray_t* found = apriltag_detector_detect(detector.get(), &im);
  std::vector<AprilTagDetection> out;
  for (int i = 0; i < zarray_size(found); ++i) {
    apriltag_detection_t* d;
    zarray_get(found, i, &d);
    AprilTagDetection t;
    t.id = d->id;
    t.hamming = d->hamming;
    t.decision_margin = d->decision_margin;
    // libapriltag puts the top-left corner of the top-left pixel at (0,0) (its
    // decimation maps x -> (x - 0.5) d + 0.5); this project puts that pixel's centre
    // there, hence the half-pixel shift.
    std::array<Vec2, 4> corners;
    for (int k = 0; k < 4; ++k) corners[k] = Vec2(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
    if (options.corner_refinement == AprilTagCornerRefinement::kEdgeFit) {
      if (const auto refined = RefineTagEdges(gray, corners, options.quad_decimate + 1.0)) corners = *refined;
    }
    for (int k = 0; k < 4; ++k) t.corners[k] = corners[k];
    t.center = DiagonalCrossing(t.corners, Vec2(d->c[0] - 0.5, d->c[1] - 0.5));
    out.push_back(t);
  }
  apriltag_detections_destroy(found);
  return out;
}

BoardDetection DetectBoard(const CalibrationBoard& board, const cv::Mat& image) {
  const cv::Mat gray = ToGray8(image);
  BoardDetection det;
  if (board.type == CalibrationBoard::Type::kChessboard) {
    std::vector<cv::Point2f> corners;
    const bool ok = cv::findChessboardCorners(
        gray, cv::Size(board.cols, board.rows), corners,
        cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK);
    if (!ok) return det;
    cv::cornerSubPix(gray, corners, cv::Size(11, 11), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 0.01));
    for (size_t i = 0; i < corners.size(); ++i) {
      det.pixels.emplace_back(corners[i].x, corners[i].y);
      det.ids.push_back(static_cast<int>(i));
    }
    return det;
  }
  const int ntags = board.tag_cols * board.tag_rows;
  for (const AprilTagDetection& t : DetectAprilTags(gray)) {
    if (t.id < 0 || t.id >= ntags) continue;
    for (int k = 0; k < 4; ++k) {
      det.pixels.push_back(t.corners[k]);
      det.ids.push_back(4 * t.id + k);
    }
  }
  return det;
}

}  // namespace mcms
