// Camera calibration on real data sets (skipped with the reason when absent).
#include <numbers>
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
}

#include "calib/calibration_board.h"
#include "calib/camera_calibration.h"
#include "core/error.h"
#include "core/io.h"
#include "core/random.h"
#include "tests/caliscope.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

// OpenCV's sample: 13 left views, 9x6 inner corners, 25 mm squares.
constexpr double kOpenCvFx = 535.91573396163199;   // left_intrinsics.yml
constexpr double kOpenCvAvgReproj = 0.39259098975581364;  // sqrt(sum |e|^2 / N points)
constexpr double kFxTolerance = 0.005;              // 0.5 %
constexpr double kRmsTolerance = 0.10;              // 10 %
const char* kPairs[] = {"01", "02", "03", "04", "05", "06", "07", "08", "09", "11", "12", "13", "14"};

CameraCalibrationInput ChessboardInput(const std::filesystem::path& dir, const std::vector<std::string>& sides) {
  const CalibrationBoard board = CalibrationBoard::Chessboard(9, 6, 0.025);
  CameraCalibrationInput in;
  for (const auto& s : sides) {
    in.camera_names.push_back(s);
    in.widths.push_back(640);
    in.heights.push_back(480);
  }
  int frame = 0;
  for (const char* k : kPairs) {
    for (size_t c = 0; c < sides.size(); ++c) {
      const cv::Mat img = cv::imread((dir / (sides[c] + k + ".jpg")).string(), cv::IMREAD_GRAYSCALE);
      EXPECT_FALSE(img.empty()) << sides[c] << k;
      const BoardDetection det = DetectBoard(board, img);
      if (det.size() == 0) continue;
      BoardObservation o;
      o.camera = static_cast<int>(c);
      o.frame = frame;
      o.pixels = det.pixels;
      for (int id : det.ids) o.points_board.push_back(board.Point(id));
      in.observations.push_back(o);
    }
    ++frame;
  }
  return in;
}

TEST(CalibCameraReal, OpenCvChessboardLeftMatchesOpenCv) {
  MCMS_REQUIRE_DATA(dir, "opencv-stereo-chessboard");
  const CameraCalibrationInput in = ChessboardInput(dir, {"left"});
  ASSERT_EQ(in.observations.size(), 13u);
  CameraCalibrationOptions o;
  o.lensmodel = "LENSMODEL_OPENCV5";  // k1 k2 p1 p2 k3: OpenCV's default 5-term model
  o.outlier_k = 0.0;                  // OpenCV rejects nothing: compare like with like
  const CameraCalibrationResult r = CalibrateCameras(in, o);
  const auto& intr = r.rig.cameras[0].Intrinsics();
  std::printf("opencv left: fx %.3f fy %.3f cx %.3f cy %.3f k1 %.5f; RMS %.4f px/point (OpenCV %.4f), %.4f px/coord\n",
              intr[0], intr[1], intr[2], intr[3], intr[4], r.residuals[0].rms_point_px, kOpenCvAvgReproj,
              r.residuals[0].rms_px);
  std::printf("  std fx %.3f cx %.3f cy %.3f k1 %.5f\n", r.intrinsics_std[0][0], r.intrinsics_std[0][2],
              r.intrinsics_std[0][3], r.intrinsics_std[0][4]);
  EXPECT_NEAR(intr[0], kOpenCvFx, kFxTolerance * kOpenCvFx);
  EXPECT_NEAR(r.residuals[0].rms_point_px, kOpenCvAvgReproj, kRmsTolerance * kOpenCvAvgReproj);
  // The uncertainty must be small and positive: 13 views of a 54-point board.
  EXPECT_GT(r.intrinsics_std[0][0], 0.0);
  EXPECT_LT(r.intrinsics_std[0][0], 5.0);
}

TEST(CalibCameraReal, OpenCvStereoBaseline) {
  MCMS_REQUIRE_DATA(dir, "opencv-stereo-chessboard");
  const CameraCalibrationInput in = ChessboardInput(dir, {"left", "right"});
  CameraCalibrationOptions o;
  o.lensmodel = "LENSMODEL_OPENCV5";
  const CameraCalibrationResult r = CalibrateCameras(in, o);
  const Pose& T = r.rig.cameras[1].T_cam_rig();
  const auto& i1 = r.rig.cameras[1].Intrinsics();
  std::printf("opencv stereo: baseline %.2f mm, t_right_left = (%.2f, %.2f, %.2f) mm +- (%.2f, %.2f, %.2f), "
              "rotation %.3f deg; right fx %.2f (intrinsics.yml M2 534.80); RMS %.4f / %.4f px per coordinate\n",
              T.t.norm() * 1e3, T.t.x() * 1e3, T.t.y() * 1e3, T.t.z() * 1e3, r.extrinsics_std[1][3] * 1e3,
              r.extrinsics_std[1][4] * 1e3, r.extrinsics_std[1][5] * 1e3, LogSO3(T.R).norm() * 180 / std::numbers::pi, i1[0],
              r.residuals[0].rms_px, r.residuals[1].rms_px);
  std::printf("%s", SummarizeCalibration(r).c_str());
  // A side-by-side pair: baseline mostly along x (the right camera sees the left
  // camera's origin at negative x), small relative rotation, and both focal lengths
  // consistent with intrinsics.yml (534.80 for both, with fixed aspect ratio).
  EXPECT_LT(T.t.x(), 0.0);
  EXPECT_GT(std::abs(T.t.x()), 0.9 * T.t.norm());
  EXPECT_LT(LogSO3(T.R).norm(), 5.0 * std::numbers::pi / 180);
  EXPECT_NEAR(i1[0], 534.80, 0.02 * 534.80);
  EXPECT_NEAR(r.rig.cameras[0].Intrinsics()[0], 534.80, 0.02 * 534.80);
}

// AprilTag's regression data, "id, (x y), (x y), (x y), (x y)" per tag in raw
// libapriltag coordinates (pixel centres at +0.5), matched to our detections by id
// and the smallest worst-corner distance.
struct UpstreamMatch {
  int files = 0, expected = 0, found = 0;
  std::vector<double> errors;  // px, sorted; 4 per found tag
  Vec2 mean_d[4] = {Vec2::Zero(), Vec2::Zero(), Vec2::Zero(), Vec2::Zero()};  // ours - expected, per corner
  double Within(double tol) const {
    return std::count_if(errors.begin(), errors.end(), [&](double e) { return e <= tol; }) /
           std::max<double>(1.0, errors.size());
  }
  double Median() const { return errors.empty() ? 1e9 : errors[errors.size() / 2]; }
  double Max() const { return errors.empty() ? 1e9 : errors.back(); }
};

UpstreamMatch MatchUpstream(const std::filesystem::path& dir, const AprilTagOptions& options) {
  constexpr double kFoundPx = 2.0;  // a tag farther than this is counted as missed
  UpstreamMatch m;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".jpg") continue;
    ++m.files;
    const cv::Mat img = cv::imread(entry.path().string(), cv::IMREAD_GRAYSCALE);
    EXPECT_FALSE(img.empty()) << entry.path();
    const auto dets = DetectAprilTags(img, options);
    std::ifstream f(std::filesystem::path(entry.path()).replace_extension(".txt"));
    std::string line;
    while (std::getline(f, line)) {
      int id;
      double c[8];
      if (std::sscanf(line.c_str(), "%d, (%lf %lf), (%lf %lf), (%lf %lf), (%lf %lf)", &id, &c[0], &c[1], &c[2], &c[3],
                      &c[4], &c[5], &c[6], &c[7]) != 9)
        continue;
      ++m.expected;
      double best = 1e9;
      std::vector<Vec2> best_d;
      for (const auto& d : dets) {
        if (d.id != id) continue;
        std::vector<Vec2> dk;
        double worst = 0;
        for (int k = 0; k < 4; ++k) {
          dk.push_back(d.corners[k] + Vec2(0.5, 0.5) - Vec2(c[2 * k], c[2 * k + 1]));
          worst = std::max(worst, dk.back().norm());
        }
        if (worst < best) best = worst, best_d = dk;
      }
      if (best > kFoundPx) continue;
      ++m.found;
      for (int k = 0; k < 4; ++k) {
        m.errors.push_back(best_d[k].norm());
        m.mean_d[k] += best_d[k];
      }
    }
  }
  for (auto& d : m.mean_d) d /= std::max(1, m.found);
  std::sort(m.errors.begin(), m.errors.end());
  return m;
}

void PrintUpstream(const char* what, const UpstreamMatch& m) {
  std::printf("apriltag upstream, %s: %d images, %d/%d tags found; corners %.1f %% within 0.5 px, %.1f %% within "
              "0.01 px, median %.4f px, max %.4f px; mean (dx, dy) per corner index:",
              what, m.files, m.found, m.expected, 100 * m.Within(0.5), 100 * m.Within(0.01), m.Median(), m.Max());
  for (const auto& d : m.mean_d) std::printf(" (%+.3f, %+.3f)", d.x(), d.y());
  std::printf("\n");
}

// Why Debian's libapriltag 3.3 missed AprilTag's regression data (80.7 % of corners
// within 0.5 px, median 0.32 px, 44/47 tags with our former defaults): the data
// hold the UNREFINED quad-fit corners at quad_decimate 1. 3.3 runs refine_edges at
// every decimation (the `quad_decimate > 1` condition is commented out in its
// quad_decode_task, although its header says the option is ignored at 1), and that
// refinement moved the corners by up to 0.8 px, with no common offset (mean dx, dy
// per image and corner index within +-0.16 px, of either sign) and no scale: it is
// the refinement's own noise, not a convention. With the refinement off as in the
// data (AprilTagCornerRefinement::kNone) 3.3 reproduces them: all 47 tags, median
// 0.0002 px (libapriltag keeps quad corners as float), 93.6 % of corners within
// 0.01 px, every corner within 0.15 px. The few corners off by 0.01-0.14 px are not
// the JPEG decoder (decoding with libapriltag's own pjpeg, as the upstream test
// does, leaves the worst at 0.141 px): a small change in the quad fit since 3.3.
TEST(CalibCameraReal, AprilTagUpstreamCornersMatch) {
  MCMS_REQUIRE_DATA(dir, "apriltag-upstream-test");
  constexpr double kTolPx = 0.5;       // issue 4
  constexpr double kMaxPx = 0.2;       // measured 0.140 (one corner; 93.6 % are within 0.01 px)
  constexpr double kMaxMedianPx = 0.005;  // measured 0.0002: libapriltag stores quad corners as float
  // AprilTag's regression settings: full resolution, no edge refinement, and the
  // 2 corrected bits of apriltag_detector_add_family (the 47th tag needs them).
  AprilTagOptions upstream;
  upstream.quad_decimate = 1.0f;
  upstream.corner_refinement = AprilTagCornerRefinement::kNone;
  upstream.max_hamming = 2;
  const UpstreamMatch m = MatchUpstream(dir, upstream);
  PrintUpstream("upstream settings", m);
  EXPECT_EQ(m.files, 3);
  EXPECT_EQ(m.expected, 47);
  EXPECT_EQ(m.found, m.expected);
  EXPECT_EQ(m.Within(kTolPx), 1.0);
  EXPECT_LE(m.Max(), kMaxPx);
  EXPECT_LE(m.Median(), kMaxMedianPx);

  // Our default refinement (kEdgeFit, the most accurate on rendered tags) departs
  // from the unrefined data by the refinement itself (measured: median 0.32 px, max
  // 1.36 px, on small blurred tags); it must still keep every tag.
  constexpr double kEdgeFitMaxPx = 1.5;
  AprilTagOptions ours_options;
  ours_options.max_hamming = 2;
  const UpstreamMatch ours = MatchUpstream(dir, ours_options);
  PrintUpstream("edge fit", ours);
  EXPECT_EQ(ours.found, ours.expected);
  EXPECT_LE(ours.Max(), kEdgeFitMaxPx);
}

TEST(CalibCameraReal, AprilTagBadOptionsNameTheField) {
  const cv::Mat img(32, 32, CV_8U, cv::Scalar(128));
  auto message = [&](const AprilTagOptions& o) {
    try {
      DetectAprilTags(img, o);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  AprilTagOptions o;
  o.quad_decimate = 0.5f;
  EXPECT_NE(message(o).find("quad_decimate"), std::string::npos) << message(o);
  o = {};
  o.quad_sigma = -1.0f;
  EXPECT_NE(message(o).find("quad_sigma"), std::string::npos) << message(o);
  o = {};
  o.threads = 0;
  EXPECT_NE(message(o).find("threads"), std::string::npos) << message(o);
  o = {};
  o.max_hamming = 3;
  EXPECT_NE(message(o).find("max_hamming"), std::string::npos) << message(o);
  EXPECT_EQ(message(AprilTagOptions{}), "no error");  // valid options, a blank image: no tags, no error
  EXPECT_THROW(DetectAprilTags(cv::Mat()), InputError);
}

// ViSP: ground_truth_detection.txt holds per tag "36h11_id:_N" then 4 corner lines;
// ground_truth_pose.txt "36h11_id:_N" then "tx ty tz tux tuy tuz" (T_cam_tag).
std::map<int, std::vector<std::vector<double>>> ReadVispFile(const std::filesystem::path& p) {
  std::map<int, std::vector<std::vector<double>>> out;
  std::ifstream f(p);
  std::string line;
  int id = -1;
  while (std::getline(f, line)) {
    if (line.rfind("36h11_id:_", 0) == 0) {
      id = std::stoi(line.substr(10));
      continue;
    }
    std::istringstream s(line);
    std::vector<double> v;
    double x;
    while (s >> x) v.push_back(x);
    if (!v.empty() && id >= 0) out[id].push_back(v);
  }
  return out;
}

TEST(CalibCameraReal, VispAprilTagCornersAndPoses) {
  MCMS_REQUIRE_DATA(dir, "visp-apriltag");
  constexpr double kTolPx = 0.5, kTagSize = 0.053;
  constexpr double kPosTolM = 0.0005, kAngTolDeg = 0.5;
  const cv::Mat img = cv::imread((dir / "AprilTag.pgm").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty());
  // ViSP's corners are its own detector's output (libapriltag with 3.3's edge
  // refinement at quad_decimate 1), not measured truth: compare like with like.
  // AprilTagRenderedCornerAccuracy and VispAprilTagCornerRefinementAccuracy judge
  // accuracy.
  AprilTagOptions visp_options;
  visp_options.corner_refinement = AprilTagCornerRefinement::kLibApriltag33;
  const auto dets = DetectAprilTags(img, visp_options);
  const auto truth = ReadVispFile(dir / "ground_truth_detection.txt");
  const auto poses = ReadVispFile(dir / "ground_truth_pose.txt");
  ASSERT_EQ(truth.size(), 12u);
  const cv::Mat K = (cv::Mat_<double>(3, 3) << 615.167, 0, 312.189, 0, 615.168, 243.437, 0, 0, 1);
  int matched = 0;
  double worst_px = 0, worst_pos = 0, worst_ang = 0;
  for (const auto& d : dets) {
    const auto it = truth.find(d.id);
    if (it == truth.end()) continue;
    // ViSP writes (row, col) = (v, u) in its own convention; ViSP's apriltag
    // wrapper passes libapriltag's raw corners, so add the half pixel back.
    double e = 0;
    for (int k = 0; k < 4; ++k)
      e = std::max(e, (d.corners[k] + Vec2(0.5, 0.5) - Vec2(it->second[k][1], it->second[k][0])).norm());
    worst_px = std::max(worst_px, e);
    if (e <= kTolPx) ++matched;
    // ViSP's tag frame is libapriltag's turned 180 deg about x: corners p[0..3] at
    // (-s/2, -s/2), (s/2, -s/2), (s/2, s/2), (-s/2, s/2), z into the tag. ViSP
    // solved with libapriltag's raw corners (pixel centres at +0.5), so compare like
    // with like using those; with this project's convention the tags shift by the
    // half pixel (reported as "ours").
    const double h = kTagSize / 2;
    const std::vector<cv::Point3d> obj = {{-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}};
    auto pose = [&](double shift) {
      std::vector<cv::Point2d> im;
      for (int k = 0; k < 4; ++k) im.emplace_back(d.corners[k].x() + shift, d.corners[k].y() + shift);
      cv::Mat rvec, tvec;
      cv::solvePnP(obj, im, K, cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_IPPE);
      cv::solvePnPRefineLM(obj, im, K, cv::Mat(), rvec, tvec);
      const double rt[6] = {rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2),
                            tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)};
      return Pose::FromRt(rt);
    };
    const Pose T = pose(0.5), T_ours = pose(0.0);
    const auto& g = poses.at(d.id)[0];
    const Vec3 t_gt(g[0], g[1], g[2]);
    const Mat3 R_gt = ExpSO3(Vec3(g[3], g[4], g[5]));
    const double dpos = (T.t - t_gt).norm();
    const double dang = RotationAngle(T.R, R_gt) * 180 / std::numbers::pi;
    std::printf("visp tag %2d: corners max %.3f px; pose diff %.3f mm, %.3f deg (range %.0f mm); ours %.3f mm, %.3f deg\n",
                d.id, e, dpos * 1e3, dang, T.t.norm() * 1e3, (T_ours.t - t_gt).norm() * 1e3,
                RotationAngle(T_ours.R, R_gt) * 180 / std::numbers::pi);
    worst_pos = std::max(worst_pos, dpos);
    worst_ang = std::max(worst_ang, dang);
  }
  std::printf("visp apriltag: %d/12 tags within %.1f px (worst %.3f px); poses worst %.2f mm, %.2f deg\n", matched,
              kTolPx, worst_px, worst_pos * 1e3, worst_ang);
  EXPECT_EQ(matched, 12);
  EXPECT_LT(worst_pos, kPosTolM);
  EXPECT_LT(worst_ang, kAngTolDeg);
}

// A check of corner accuracy that does not lean on any detector's output: a printed
// tag is a square of known size, so with the camera's calibration the four corners
// of a tag must be the image of such a square. The residual of that fit (OpenCV's
// IPPE + LM; 8 coordinates, 6 pose parameters, so 2 degrees of freedom per tag)
// measures how far the corners are from being consistent, whatever their source.
// RMS per coordinate over the 12 tags, px, scaled by sqrt(8 / 2) so that it
// estimates the corner noise itself.
double VispSquareFitRms(const std::vector<AprilTagDetection>& dets) {
  constexpr double kTagSize = 0.053;
  const cv::Mat K = (cv::Mat_<double>(3, 3) << 615.167, 0, 312.189, 0, 615.168, 243.437, 0, 0, 1);
  const double h = kTagSize / 2;
  const std::vector<cv::Point3d> obj = {{-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}};
  double sum2 = 0;
  int n = 0;
  for (const auto& d : dets) {
    std::vector<cv::Point2d> im;
    for (int k = 0; k < 4; ++k) im.emplace_back(d.corners[k].x(), d.corners[k].y());
    cv::Mat rvec, tvec;
    cv::solvePnP(obj, im, K, cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_IPPE);
    cv::solvePnPRefineLM(obj, im, K, cv::Mat(), rvec, tvec);
    std::vector<cv::Point2d> proj;
    cv::projectPoints(obj, rvec, tvec, K, cv::Mat(), proj);
    for (int k = 0; k < 4; ++k) {
      sum2 += (proj[k].x - im[k].x) * (proj[k].x - im[k].x) + (proj[k].y - im[k].y) * (proj[k].y - im[k].y);
      n += 2;
    }
  }
  return n == 0 ? 1e9 : std::sqrt(sum2 / n * 8.0 / 2.0);
}

TEST(CalibCameraReal, VispAprilTagCornerRefinementAccuracy) {
  MCMS_REQUIRE_DATA(dir, "visp-apriltag");
  const cv::Mat img = cv::imread((dir / "AprilTag.pgm").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty());
  const auto truth = ReadVispFile(dir / "ground_truth_detection.txt");
  // ViSP's own corners, in this project's convention.
  std::vector<AprilTagDetection> visp;
  for (const auto& [id, rows] : truth) {
    AprilTagDetection d;
    d.id = id;
    for (int k = 0; k < 4; ++k) d.corners[k] = Vec2(rows[k][1] - 0.5, rows[k][0] - 0.5);
    visp.push_back(d);
  }
  const double visp_rms = VispSquareFitRms(visp);
  std::printf("visp square fit: ViSP's ground_truth_detection %.4f px\n", visp_rms);
  const std::pair<const char*, AprilTagCornerRefinement> modes[] = {
      {"none", AprilTagCornerRefinement::kNone},
      {"libapriltag 3.3", AprilTagCornerRefinement::kLibApriltag33},
      {"edge fit", AprilTagCornerRefinement::kEdgeFit}};
  std::map<AprilTagCornerRefinement, double> rms;
  for (const auto& [name, mode] : modes) {
    AprilTagOptions o;
    o.corner_refinement = mode;
    const auto dets = DetectAprilTags(img, o);
    EXPECT_EQ(dets.size(), 12u) << name;
    double worst = 0;
    for (const auto& d : dets) {
      const auto it = truth.find(d.id);
      if (it == truth.end()) continue;
      for (int k = 0; k < 4; ++k)
        worst = std::max(worst, (d.corners[k] + Vec2(0.5, 0.5) - Vec2(it->second[k][1], it->second[k][0])).norm());
    }
    rms[mode] = VispSquareFitRms(dets);
    std::printf("visp square fit: %-16s %.4f px (%zu tags; worst corner %.3f px from ViSP's)\n", name, rms[mode],
                dets.size(), worst);
  }
  // Measured: edge fit 0.2904, ViSP's corners 0.2961, 3.3 0.3002, none 0.3162 px. The
  // common floor (~0.29 px) is what no corner placement removes (print, lens, the
  // given calibration), so the margins are small, but the order is that of the
  // rendered tags, and the image is fixed, so the figures are exact regressions.
  EXPECT_LT(rms[AprilTagCornerRefinement::kEdgeFit], rms[AprilTagCornerRefinement::kLibApriltag33]);
  EXPECT_LT(rms[AprilTagCornerRefinement::kEdgeFit], rms[AprilTagCornerRefinement::kNone]);
  EXPECT_LE(rms[AprilTagCornerRefinement::kEdgeFit], visp_rms);
}

// The real images above have no true corners (both references are some detector's
// output), so the choice of refinement is settled on rendered tags whose corners
// are known exactly: tag36h11 tags under random rotation, scale (8..14 px per bit
// cell) and perspective, each pixel the area average of the scene (8 x 8
// sub-samples where a cell edge crosses it), then a Gaussian optical blur and read
// noise, as a camera forms them.
cv::Mat RenderTag36h11(int id, const cv::Mat& H_px_cell, int size_px, double blur_px, double noise_dn, Rng* rng) {
  constexpr double kDark = 30, kLight = 220, kBackground = 200;
  constexpr int kSub = 8;
  std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> fam(tag36h11_create(), tag36h11_destroy);
  const uint64_t code = fam->codes[id];
  // Cells: [-1, 9)^2 in bit-cell units; -1 and 8 the white surround, 0 and 7 the
  // black border, the data bits inside (bit b = code bit nbits-1-b, 1 = light).
  cv::Mat cell(10, 10, CV_64F, cv::Scalar(kDark));
  for (int v = -1; v <= 8; ++v)
    for (int u = -1; u <= 8; ++u)
      if (u == -1 || v == -1 || u == 8 || v == 8) cell.at<double>(v + 1, u + 1) = kLight;
  for (uint32_t b = 0; b < fam->nbits; ++b)
    if ((code >> (fam->nbits - 1 - b)) & 1) cell.at<double>(fam->bit_y[b] + 1, fam->bit_x[b] + 1) = kLight;
  const cv::Mat Hi = H_px_cell.inv();
  auto to_cell = [&](double x, double y) {
    const double w = Hi.at<double>(2, 0) * x + Hi.at<double>(2, 1) * y + Hi.at<double>(2, 2);
    return cv::Point2d((Hi.at<double>(0, 0) * x + Hi.at<double>(0, 1) * y + Hi.at<double>(0, 2)) / w,
                       (Hi.at<double>(1, 0) * x + Hi.at<double>(1, 1) * y + Hi.at<double>(1, 2)) / w);
  };
  auto shade = [&](const cv::Point2d& c) {
    const int u = static_cast<int>(std::floor(c.x)), v = static_cast<int>(std::floor(c.y));
    return (u < -1 || v < -1 || u > 8 || v > 8) ? kBackground : cell.at<double>(v + 1, u + 1);
  };
  auto cell_id = [](const cv::Point2d& c) {
    return std::make_pair(static_cast<int>(std::floor(std::clamp(c.x, -2.0, 9.0))),
                          static_cast<int>(std::floor(std::clamp(c.y, -2.0, 9.0))));
  };
  cv::Mat radiance(size_px, size_px, CV_64F);
  for (int y = 0; y < size_px; ++y)
    for (int x = 0; x < size_px; ++x) {
      // Pixel (x, y) covers [x - 0.5, x + 0.5] x [y - 0.5, y + 0.5] (pixel centres at integers).
      const auto c0 = cell_id(to_cell(x - 0.5, y - 0.5));
      if (c0 == cell_id(to_cell(x + 0.5, y - 0.5)) && c0 == cell_id(to_cell(x - 0.5, y + 0.5)) &&
          c0 == cell_id(to_cell(x + 0.5, y + 0.5))) {
        radiance.at<double>(y, x) = shade(to_cell(x, y));
        continue;
      }
      double sum = 0;
      for (int j = 0; j < kSub; ++j)
        for (int i = 0; i < kSub; ++i) sum += shade(to_cell(x - 0.5 + (i + 0.5) / kSub, y - 0.5 + (j + 0.5) / kSub));
      radiance.at<double>(y, x) = sum / (kSub * kSub);
    }
  cv::GaussianBlur(radiance, radiance, cv::Size(0, 0), blur_px);
  cv::Mat img(size_px, size_px, CV_8U);
  for (int y = 0; y < size_px; ++y)
    for (int x = 0; x < size_px; ++x)
      img.at<uchar>(y, x) = cv::saturate_cast<uchar>(radiance.at<double>(y, x) + rng->Normal(0.0, noise_dn));
  return img;
}

TEST(CalibCameraReal, AprilTagRenderedCornerAccuracy) {
  constexpr int kTags = 24, kSizePx = 240;
  constexpr double kBlurPx = 0.8, kNoiseDn = 2.0;
  constexpr double kEdgeFitRmsPx = 0.03;   // measured 0.018 px
  constexpr double kEdgeFitBiasPx = 0.01;  // |mean error| per axis; measured < 0.003 px
  Rng rng(20261122);
  struct Stats {
    double sum2 = 0, sx = 0, sy = 0;
    int n = 0, tags = 0;
  };
  const AprilTagCornerRefinement modes[] = {AprilTagCornerRefinement::kNone, AprilTagCornerRefinement::kLibApriltag33,
                                            AprilTagCornerRefinement::kEdgeFit};
  const char* names[] = {"none", "libapriltag 3.3", "edge fit"};
  Stats stats[3];
  for (int t = 0; t < kTags; ++t) {
    const int id = 3 * t;
    const double s = rng.Uniform(8.0, 14.0), angle = rng.Uniform(-std::numbers::pi, std::numbers::pi);
    const double cx = kSizePx / 2.0 + rng.Uniform(-10.0, 10.0), cy = kSizePx / 2.0 + rng.Uniform(-10.0, 10.0);
    const std::vector<cv::Point2f> cells = {{0, 0}, {8, 0}, {8, 8}, {0, 8}};
    std::vector<cv::Point2f> px;
    for (const auto& c : cells) {
      const double x = (c.x - 4) * s, y = (c.y - 4) * s, k = 1 + rng.Uniform(-0.15, 0.15);  // perspective
      px.emplace_back(cx + k * (std::cos(angle) * x - std::sin(angle) * y),
                      cy + k * (std::sin(angle) * x + std::cos(angle) * y));
    }
    const cv::Mat img = RenderTag36h11(id, cv::getPerspectiveTransform(cells, px), kSizePx, kBlurPx, kNoiseDn, &rng);
    for (int m = 0; m < 3; ++m) {
      AprilTagOptions o;
      o.corner_refinement = modes[m];
      for (const auto& d : DetectAprilTags(img, o)) {
        if (d.id != id) continue;
        ++stats[m].tags;
        for (const Vec2& c : d.corners) {
          Vec2 best(1e9, 1e9);
          for (const auto& q : px)
            if ((c - Vec2(q.x, q.y)).norm() < best.norm()) best = c - Vec2(q.x, q.y);
          stats[m].sum2 += best.squaredNorm() / 2;  // per coordinate
          stats[m].sx += best.x();
          stats[m].sy += best.y();
          ++stats[m].n;
        }
      }
    }
  }
  double rms[3];
  for (int m = 0; m < 3; ++m) {
    const Stats& st = stats[m];
    rms[m] = std::sqrt(st.sum2 / std::max(1, st.n));
    std::printf("rendered tags, %-16s: %d/%d found, corner error RMS %.4f px per coordinate, mean (%+.4f, %+.4f) px\n",
                names[m], st.tags, kTags, rms[m], st.sx / std::max(1, st.n), st.sy / std::max(1, st.n));
    EXPECT_EQ(st.tags, kTags) << names[m];
  }
  EXPECT_LT(rms[2], kEdgeFitRmsPx);
  EXPECT_LT(rms[2], rms[1]);
  EXPECT_LT(rms[2], rms[0]);
  EXPECT_LT(std::abs(stats[2].sx / stats[2].n), kEdgeFitBiasPx);
  EXPECT_LT(std::abs(stats[2].sy / stats[2].n), kEdgeFitBiasPx);
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// xy.csv holds caliscope's extrinsic-calibration detections: few points per view
// (a 4x5 ChArUco board, partly seen), while caliscope's intrinsics came from separate
// per-camera intrinsic sessions. So (1) with caliscope's intrinsics held fixed, the
// extrinsics are compared; (2) the joint solve (intrinsics too, started from
// caliscope's) is compared within a few sigma of our reported uncertainty.
TEST(CalibCameraReal, Caliscope4CamMatchesCaliscope) {
  MCMS_REQUIRE_DATA(dir, "caliscope-4cam");
  constexpr double kPosTolM = 0.03;       // relative camera positions (1-1.6 m apart)
  constexpr double kAngTolDeg = 1.0;
  constexpr double kSigmas = 4.0;         // joint solve: focal lengths within 4 sigma
  CameraCalibrationInput in = test::ReadCaliscopeViews(dir);
  const auto ref = test::ReadCaliscopeToml(dir / "camera_array.toml");
  ASSERT_EQ(ref.size(), 4u);
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV5";  // caliscope's k1 k2 p1 p2 k3
  for (int c = 0; c < 4; ++c) opt.initial_intrinsics.push_back(ref.at(c).Opencv5Intrinsics());
  auto T_ref = [&](int c) { return ref.at(c).T_cam_world(); };
  const char* kCaliscopeRms[] = {"0.19", "0.469", "0.656", "0.276"};
  for (const bool fixed : {true, false}) {
    opt.fix_intrinsics = fixed;
    const CameraCalibrationResult r = CalibrateCameras(in, opt);
    std::printf("caliscope, %s:\n%s", fixed ? "caliscope's intrinsics held fixed" : "joint solve",
                SummarizeCalibration(r).c_str());
    // The views' noise floor: each view's board pose fitted alone fits at least as well as
    // the rig does (the views of one frame disagree a little: the webcams are not triggered
    // together). Each view's pose is the better of the planar solution and the joint one,
    // refined: the planar one alone ended in far worse minima on some views of few corners
    // and put the floor at 5.39 px^2, 20 times the joint residual, hiding any disagreement.
    std::printf("  residual variance %.4f px^2, views alone %.4f px^2 (ratio %.3f)\n", r.residual_variance_px2,
                r.views_alone_variance_px2, std::sqrt(r.residual_variance_px2 / r.views_alone_variance_px2));
    EXPECT_LT(r.views_alone_variance_px2, r.residual_variance_px2);
    for (int c = 0; c < 4; ++c) {
      const auto& mine = r.rig.cameras[c].Intrinsics();
      const auto& m = ref.at(c).matrix;
      const Pose T_c_0 = T_ref(c) * T_ref(0).Inverse();  // caliscope's camera c relative to camera 0
      const Pose& T = r.rig.cameras[c].T_cam_rig();
      const double dpos = (T.Inverse().t - T_c_0.Inverse().t).norm();
      const double dang = RotationAngle(T.R, T_c_0.R) * 180 / std::numbers::pi;
      std::printf("  cam%d: fx %.1f/%.1f fy %.1f/%.1f cx %.1f/%.1f cy %.1f/%.1f (ours/caliscope); position in cam0 "
                  "frame differs by %.1f mm of %.0f mm, rotation by %.2f deg; RMS %.3f px/point (caliscope %s)\n",
                  c, mine[0], m[0], mine[1], m[4], mine[2], m[2], mine[3], m[5], dpos * 1e3, T_c_0.t.norm() * 1e3,
                  dang, r.residuals[c].rms_point_px, kCaliscopeRms[c]);
      if (fixed) {
        EXPECT_LT(dpos, kPosTolM) << "cam" << c;
        EXPECT_LT(dang, kAngTolDeg) << "cam" << c;
      } else {
        EXPECT_NEAR(mine[0], m[0], kSigmas * r.intrinsics_std[c][0]) << "cam" << c;
        EXPECT_NEAR(mine[1], m[4], kSigmas * r.intrinsics_std[c][1]) << "cam" << c;
      }
    }
  }
}

}  // namespace
}  // namespace mcms
