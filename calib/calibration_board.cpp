#include "calib/calibration_board.h"

#include <cmath>
#include <memory>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
}

#include "core/error.h"

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
    else if (!(square_m > 0.0) || !std::isfinite(square_m)) s << "chessboard square size must be > 0 m (got " << square_m << ")";
  } else {
    if (tag_cols < 1 || tag_rows < 1) s << "an AprilGrid needs at least 1x1 tags (got " << tag_cols << "x" << tag_rows << ")";
    else if (tag_cols * tag_rows > 587) s << "tag36h11 has 587 ids; the grid has " << tag_cols * tag_rows;
    else if (!(tag_size_m > 0.0) || !std::isfinite(tag_size_m)) s << "tagSize must be > 0 m (got " << tag_size_m << ")";
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
    y = YAML::LoadFile(path.string());
  } catch (const std::exception& e) {
    Throw("board file ", path.string(), ": cannot read it as YAML (", e.what(), ")");
  }
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

std::vector<AprilTagDetection> DetectAprilTags(const cv::Mat& image, const AprilTagOptions& options) {
  cv::Mat gray = ToGray8(image);
  if (!gray.isContinuous()) gray = gray.clone();
  std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> family(tag36h11_create(), tag36h11_destroy);
  std::unique_ptr<apriltag_detector_t, void (*)(apriltag_detector_t*)> detector(apriltag_detector_create(),
                                                                               apriltag_detector_destroy);
  apriltag_detector_add_family_bits(detector.get(), family.get(), options.max_hamming);
  detector->quad_decimate = options.quad_decimate;
  detector->quad_sigma = options.quad_sigma;
  detector->nthreads = options.threads;
  detector->refine_edges = options.refine_edges;
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
    for (int k = 0; k < 4; ++k) t.corners[k] = Vec2(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
    t.center = Vec2(d->c[0] - 0.5, d->c[1] - 0.5);
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
