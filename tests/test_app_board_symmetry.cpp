// Symmetric chessboards (issue 14, item 2). A chessboard whose inner-corner grid maps
// onto itself under a turn can be numbered differently by cv::findChessboardCorners
// in two cameras viewing the same placement; the rig solve then fails silently (fx 650
// for a true 1100, exit 0). Here, on rendered images (synthetic/board_renderer.h):
//   - which numberings OpenCV's detector really produces, per pattern size, against
//     CalibrationBoard::NumberingSymmetries;
//   - a 10 x 10 board seen by two cameras with one camera's numbering turned by 90 deg
//     in one frame: without the board's symmetries the solve is wrong and the quality
//     check refuses it; with them the observation is renumbered (and reported) and the
//     rig is right;
//   - an upside-down camera, whose OpenCV numbering differs in every frame;
//   - `mcms calib-rig` on such images (renumbering reported, models right), and on
//     images whose frames do not match between the cameras (refused, nothing written).
#include <numbers>
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "calib/calibration_board.h"
#include "calib/camera_calibration.h"
#include "core/error.h"
#include "core/random.h"
#include "synthetic/board_renderer.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"
#include "vision/camera_model.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

constexpr uint64_t kSeed = 20261202;
constexpr int kWidth = 1280, kHeight = 1024;
constexpr double kTrueFx = 1100.0;
constexpr double kSquareM = 0.040;
constexpr double kSigmas = 4.0;       // solved intrinsics within 4 sigma of the truth ...
constexpr double kRelTol = 0.003;     // ... or 0.3 %, whichever is looser
constexpr double kMaxRmsPx = 0.2;     // per coordinate, rendered corners
constexpr double kMaxBaselineErrM = 0.002;
constexpr double kMaxRotationErrDeg = 0.1;
constexpr double kDecisiveRatioForTest = 0.5;  // the library's kDecisiveRatio

std::vector<double> TrueIntrinsics(int c) {
  // OPENCV4: fx, fy, cx, cy, k1, k2, p1, p2
  return {kTrueFx + 10 * c, kTrueFx + 10 * c + 2, 640.5 - 3 * c, 511.5 + 4 * c, -0.08, 0.03, 0.0004, -0.0003};
}

// Two cameras 0.3 m apart, toed in by 8 deg; camera 1 optionally mounted upside down
// (rolled 180 deg about its optical axis), as happens on real rigs.
CameraRig TrueRig(bool upside_down) {
  CameraRig rig;
  rig.names = {"cam0", "cam1"};
  rig.cameras.emplace_back("LENSMODEL_OPENCV4", TrueIntrinsics(0), kWidth, kHeight, Pose::Identity());
  const Mat3 R = ExpSO3(Vec3(0, 0, upside_down ? std::numbers::pi : 0.0)) * ExpSO3(Vec3(0.01, -8.0 * std::numbers::pi / 180, 0.0));
  // Camera 1's centre 0.3 m to the right of camera 0: t = -R c.
  const Pose T{R, -(R * Vec3(0.3, 0.0, 0.0))};
  rig.cameras.emplace_back("LENSMODEL_OPENCV4", TrueIntrinsics(1), kWidth, kHeight, T);
  return rig;
}

// Board placements in front of the rig, seen whole (with its margin) by every camera;
// tilted 15-40 deg about a random in-plane axis and rolled over the full circle, so
// that the detector's numbering varies.
std::vector<Pose> BoardPlacements(const CameraRig& rig, const CalibrationBoard& board, int n, Rng& rng) {
  const Vec3 centre_board((board.cols - 1) * board.square_m / 2, (board.rows - 1) * board.square_m / 2, 0.0);
  std::vector<Pose> out;
  for (int attempt = 0; static_cast<int>(out.size()) < n && attempt < 20000; ++attempt) {
    const Vec3 centre(rng.Uniform(-0.25, 0.55), rng.Uniform(-0.3, 0.3), rng.Uniform(0.9, 1.5));
    const double tilt = rng.Uniform(15.0, 40.0) * std::numbers::pi / 180.0, axis = rng.Uniform(0.0, 2 * std::numbers::pi);
    const double roll = rng.Uniform(0.0, 2 * std::numbers::pi);
    const Mat3 R = ExpSO3(Vec3(tilt * std::cos(axis), tilt * std::sin(axis), 0.0)) * ExpSO3(Vec3(0, 0, roll));
    const Pose T_rig_board{R, centre - R * centre_board};
    bool inside = true;
    for (size_t c = 0; c < rig.size() && inside; ++c)
      for (int j = -2; j <= board.rows + 1 && inside; ++j)
        for (int i = -2; i <= board.cols + 1 && inside; ++i)
          inside = rig.cameras[c].Sees(rig.cameras[c].T_cam_rig() * (T_rig_board * Vec3(i * board.square_m, j * board.square_m, 0)),
                                       12.0);
    if (inside) out.push_back(T_rig_board);
  }
  EXPECT_EQ(static_cast<int>(out.size()), n) << "not enough board placements fit both views";
  return out;
}

// Every rigid motion of the board plane about the grid centre that maps the grid onto
// itself, reflections included (the full dihedral group: 8 for a square grid, 4
// otherwise), identity first.
std::vector<Pose> GridMotions(const CalibrationBoard& board) {
  const Vec3 centre((board.cols - 1) * board.square_m / 2, (board.rows - 1) * board.square_m / 2, 0.0);
  std::vector<Pose> out;
  for (int mirror = 0; mirror < 2; ++mirror)
    for (int q = 0; q < 4; ++q) {
      if (board.cols != board.rows && q % 2 == 1) continue;
      Mat3 R = ExpSO3(Vec3(0, 0, q * std::numbers::pi / 2)).array().round().matrix();
      if (mirror) R = R * Vec3(-1, 1, -1).asDiagonal();  // a mirror in the plane = a flip about the board's y axis
      out.push_back(Pose{R, centre - R * centre});
    }
  return out;
}

// The motion S with which the detection numbered the board: pixel k is the image of
// S * P_k. -1 when none fits within 1 px RMS.
int DetectedNumbering(const BoardDetection& det, const CalibrationBoard& board, const CameraModel& cam,
                      const Pose& T_cam_board, const std::vector<Pose>& motions) {
  for (size_t m = 0; m < motions.size(); ++m) {
    double ss = 0;
    for (size_t k = 0; k < det.size(); ++k)
      ss += (cam.Project(T_cam_board * (motions[m] * board.Point(det.ids[k]))) - det.pixels[k]).squaredNorm();
    if (std::sqrt(ss / (2.0 * det.size())) < 1.0) return static_cast<int>(m);
  }
  return -1;
}

bool SamePose(const Pose& a, const Pose& b) { return (a.R - b.R).norm() < 1e-9 && (a.t - b.t).norm() < 1e-9; }

// Rendered views of one board by a rig, detected with DetectBoard.
struct RenderedViews {
  CameraRig rig;
  CalibrationBoard board;
  std::vector<Pose> T_rig_board;
  std::vector<std::vector<cv::Mat>> images;          // [camera][frame]
  std::vector<std::vector<BoardDetection>> detections;  // [camera][frame]
  std::vector<std::vector<int>> numbering;          // [camera][frame] index into GridMotions
};

RenderedViews Render(const CameraRig& rig, const CalibrationBoard& board, int nframes, uint64_t seed) {
  RenderedViews v;
  v.rig = rig;
  v.board = board;
  Rng rng(seed);
  v.T_rig_board = BoardPlacements(rig, board, nframes, rng);
  const BoardRenderOptions options;
  const std::vector<Pose> motions = GridMotions(board);
  v.images.resize(rig.size());
  v.detections.resize(rig.size());
  v.numbering.resize(rig.size());
  for (size_t c = 0; c < rig.size(); ++c) {
    const RayTable table(rig.cameras[c], BoardRenderPadPx(options) + 2.0);
    for (size_t f = 0; f < v.T_rig_board.size(); ++f) {
      Rng noise(seed + 1000 * (c + 1) + f);
      const Pose T_cam_board = rig.cameras[c].T_cam_rig() * v.T_rig_board[f];
      v.images[c].push_back(RenderBoard(table, board, T_cam_board, options, &noise));
      v.detections[c].push_back(DetectBoard(board, v.images[c].back()));
      const BoardDetection& det = v.detections[c].back();
      EXPECT_EQ(static_cast<int>(det.size()), board.NumPoints()) << "camera " << c << " frame " << f;
      v.numbering[c].push_back(det.size() ? DetectedNumbering(det, board, rig.cameras[c], T_cam_board, motions) : -1);
    }
  }
  return v;
}

CameraCalibrationInput InputOf(const RenderedViews& v) {
  CameraCalibrationInput in;
  for (size_t c = 0; c < v.rig.size(); ++c) {
    in.camera_names.push_back(v.rig.names[c]);
    in.widths.push_back(kWidth);
    in.heights.push_back(kHeight);
  }
  return in;
}

// The detections as observations, each numbered by motion `relabel[c][f]` applied on
// top of the detector's numbering (index into GridMotions; -2 = as detected).
BoardObservation Observation(const RenderedViews& v, int c, int f, const Pose& relabel) {
  BoardObservation o;
  o.camera = c;
  o.frame = f;
  for (size_t k = 0; k < v.detections[c][f].size(); ++k) {
    o.points_board.push_back(relabel * v.board.Point(v.detections[c][f].ids[k]));
    o.pixels.push_back(v.detections[c][f].pixels[k]);
  }
  return o;
}

// Solved rig against the truth: intrinsics within kSigmas sigma (or kRelTol), the
// extrinsics within kMaxBaselineErrM / kMaxRotationErrDeg.
void ExpectRigRight(const CameraCalibrationResult& r, const CameraRig& truth) {
  ASSERT_EQ(r.rig.size(), truth.size());
  EXPECT_LT(r.rms_px, kMaxRmsPx);
  const char* names[] = {"fx", "fy", "cx", "cy"};
  for (size_t c = 0; c < truth.size(); ++c)
    for (int p = 0; p < 4; ++p) {
      const double t = truth.cameras[c].Intrinsics()[p], s = r.rig.cameras[c].Intrinsics()[p];
      const double sd = r.intrinsics_std[c][p];
      std::printf("  %s %s: true %.2f solved %.2f +- %.2f (%+.2f sigma)\n", truth.names[c].c_str(), names[p], t, s, sd,
                  (s - t) / sd);
      EXPECT_LT(std::abs(s - t), std::max(kSigmas * sd, kRelTol * t)) << truth.names[c] << " " << names[p];
    }
  const Pose d = r.rig.cameras[1].T_cam_rig() * truth.cameras[1].T_cam_rig().Inverse();
  const double dt = (r.rig.cameras[1].T_cam_rig().Inverse().t - truth.cameras[1].T_cam_rig().Inverse().t).norm();
  const double dr = LogSO3(d.R).norm() * 180 / std::numbers::pi;
  std::printf("  cam1 pose error: %.3f mm, %.4f deg\n", dt * 1e3, dr);
  EXPECT_LT(dt, kMaxBaselineErrM);
  EXPECT_LT(dr, kMaxRotationErrDeg);
}

TEST(BoardSymmetry, OpenCvNumberingsAreThePredictedSymmetries) {
  // One upright camera; the board rolled over the full circle (every 30 deg) at two tilts.
  const CameraModel cam("LENSMODEL_OPENCV4", TrueIntrinsics(0), kWidth, kHeight);
  const BoardRenderOptions options;
  const RayTable table(cam, BoardRenderPadPx(options) + 2.0);
  struct Pattern {
    int cols, rows;
  };
  for (const Pattern p : {Pattern{10, 10}, Pattern{9, 9}, Pattern{8, 6}, Pattern{9, 7}, Pattern{9, 6}, Pattern{6, 9}}) {
    const CalibrationBoard board = CalibrationBoard::Chessboard(p.cols, p.rows, 0.03);
    const std::vector<Pose> motions = GridMotions(board);
    const std::vector<Pose> predicted = board.NumberingSymmetries();
    const Vec3 centre((p.cols - 1) * 0.015, (p.rows - 1) * 0.015, 0.0);
    std::map<int, int> seen;  // motion -> views
    int views = 0;
    for (int tilt = 0; tilt < 2; ++tilt)
      for (int roll = 0; roll < 360; roll += 30) {
        const Mat3 R = ExpSO3(Vec3(0.35 * tilt, -0.25, 0.0)) * ExpSO3(Vec3(0, 0, roll * std::numbers::pi / 180));
        const Pose T{R, Vec3(0, 0, 0.8) - R * centre};
        Rng noise(kSeed + roll + 1000 * tilt);
        const BoardDetection det = DetectBoard(board, RenderBoard(table, board, T, options, &noise));
        if (det.size() == 0) continue;
        ++views;
        ++seen[DetectedNumbering(det, board, cam, T, motions)];
      }
    std::ostringstream s;
    for (const auto& [m, n] : seen)
      s << " " << (m < 0 ? std::string("none") : (m >= static_cast<int>(motions.size()) / 2 ? "mirror+" : "") +
                                                    std::to_string(static_cast<int>(
                                                        std::lround(CalibrationBoard::SymmetryAngleDeg(motions[m])))) +
                                                    "deg")
        << " x" << n;
    std::printf("%dx%d: %d views, numbering turned by:%s; predicted: identity + %zu turn(s)\n", p.cols, p.rows, views,
                s.str().c_str(), predicted.size());
    EXPECT_EQ(views, 24) << p.cols << "x" << p.rows;
    // Every numbering seen is the identity or one of the predicted turns.
    for (const auto& [m, n] : seen) {
      ASSERT_GE(m, 0) << p.cols << "x" << p.rows << ": a numbering that is no motion of the grid";
      if (m == 0) continue;
      const bool listed = std::any_of(predicted.begin(), predicted.end(),
                                      [&](const Pose& S) { return SamePose(S, motions[m]); });
      EXPECT_TRUE(listed) << p.cols << "x" << p.rows << ": numbering turned by "
                          << CalibrationBoard::SymmetryAngleDeg(motions[m]) << " deg is not predicted";
    }
    // ... and every predicted turn does occur as the board rolls (the prediction is not
    // merely safe).
    EXPECT_EQ(seen.size(), predicted.size() + 1) << p.cols << "x" << p.rows;
  }
}


// Shared rendered data: a 10 x 10 board (40 mm) seen by two cameras, camera 1 upside
// down, 16 placements. Rendered once per process.
const RenderedViews& SquareBoardViews() {
  static const RenderedViews v = Render(TrueRig(true), CalibrationBoard::Chessboard(10, 10, kSquareM), 16, kSeed);
  return v;
}

// The case: both cameras' numberings agree (each detection renumbered to the
// true numbering) except in one frame, where camera 1's is turned by 90 deg. Without
// the board's symmetries the solve is wrong and CalibrationProblems says so; with them
// that one observation is renumbered and reported, and the rig is right.
TEST(BoardSymmetry, OneFrameTurnedBy90DegIsRenumbered) {
  const RenderedViews& v = SquareBoardViews();
  const std::vector<Pose> motions = GridMotions(v.board);
  const int turned_frame = 5;
  const Pose quarter = v.board.NumberingSymmetries().at(0);  // a quarter turn
  CameraCalibrationInput in = InputOf(v);
  for (int c = 0; c < 2; ++c)
    for (int f = 0; f < static_cast<int>(v.T_rig_board.size()); ++f) {
      const int m = v.numbering[c][f];
      ASSERT_GE(m, 0);
      // motions[m] P is the true point of pixel k: number it so.
      Pose relabel = motions[m];
      if (c == 1 && f == turned_frame) relabel = quarter * relabel;
      in.observations.push_back(Observation(v, c, f, relabel));
    }
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV4";
  const CalibrationQualityLimits limits;

  // Without the symmetries: the silent failure, now caught.
  const CameraCalibrationResult bad = CalibrateCameras(in, opt);
  const std::vector<std::string> problems = CalibrationProblems(bad, limits);
  std::printf("without the board's symmetries: fx %.1f (true %.1f), RMS %.3f px, %d of %d points rejected, "
              "converged %d; problems:\n",
              bad.rig.cameras[0].Intrinsics()[0], kTrueFx, bad.rms_px, bad.num_outliers,
              bad.num_outliers + bad.num_inliers, bad.converged);
  for (const auto& p : problems) std::printf("  - %s\n", p.c_str());
  EXPECT_FALSE(problems.empty());
  EXPECT_TRUE(bad.renumbered.empty());
  // ... and with the outlier rejection off, the wrong solve (fx far off), caught.
  CameraCalibrationOptions keep_all = opt;
  keep_all.outlier_k = 0.0;
  const CameraCalibrationResult worse = CalibrateCameras(in, keep_all);
  const std::vector<std::string> worse_problems = CalibrationProblems(worse, limits);
  std::printf("... and without outlier rejection: fx %.1f, RMS %.3f px (views alone %.3f px); problems:\n",
              worse.rig.cameras[0].Intrinsics()[0], worse.rms_px, std::sqrt(worse.views_alone_variance_px2));
  for (const auto& p : worse_problems) std::printf("  - %s\n", p.c_str());
  EXPECT_TRUE(std::any_of(worse_problems.begin(), worse_problems.end(),
                          [](const std::string& p) { return p.find("residual RMS") != std::string::npos; }));

  // With them: renumbered, reported, right.
  in.board_symmetries = v.board.NumberingSymmetries();
  const CameraCalibrationResult r = CalibrateCameras(in, opt);
  ASSERT_EQ(r.renumbered.size(), 1u);
  EXPECT_EQ(r.renumbered[0].camera, 1);
  EXPECT_EQ(r.renumbered[0].frame, turned_frame);
  EXPECT_NEAR(r.renumbered[0].angle_deg, 270.0, 1e-6);  // undoes the quarter turn
  EXPECT_LT(r.renumbered[0].rms_px, kDecisiveRatioForTest * r.renumbered[0].next_rms_px);
  EXPECT_TRUE(r.dropped.empty());
  std::printf("with them: renumbered camera %d frame %d by %.0f deg (reprojection %.2f px vs %.2f px); RMS %.4f px, "
              "%d outliers\n",
              r.renumbered[0].camera, r.renumbered[0].frame, r.renumbered[0].angle_deg, r.renumbered[0].rms_px,
              r.renumbered[0].next_rms_px, r.rms_px, r.num_outliers);
  ExpectRigRight(r, v.rig);
  EXPECT_TRUE(CalibrationProblems(r, limits).empty());
}

// Camera 1 mounted upside down: OpenCV numbers the 10 x 10 board from the top of each
// image, so the two cameras' numberings differ in (nearly) every frame. Every such
// observation is renumbered, and only those.
TEST(BoardSymmetry, UpsideDownCameraIsRenumberedInEveryFrame) {
  const RenderedViews& v = SquareBoardViews();
  const std::vector<Pose> motions = GridMotions(v.board);
  CameraCalibrationInput in = InputOf(v);
  std::set<int> differing;
  for (int f = 0; f < static_cast<int>(v.T_rig_board.size()); ++f) {
    if (v.numbering[0][f] != v.numbering[1][f]) differing.insert(f);
    for (int c = 0; c < 2; ++c) in.observations.push_back(Observation(v, c, f, Pose::Identity()));
  }
  std::printf("OpenCV's numberings differ between the cameras in %zu of %zu frames\n", differing.size(),
              v.T_rig_board.size());
  EXPECT_GE(differing.size(), v.T_rig_board.size() / 2);
  in.board_symmetries = v.board.NumberingSymmetries();
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV4";
  const CameraCalibrationResult r = CalibrateCameras(in, opt);
  std::set<int> renumbered;
  for (const BoardRenumbering& n : r.renumbered) {
    EXPECT_EQ(n.camera, 1);
    renumbered.insert(n.frame);
    // Camera 1's numbering turned onto camera 0's: the motion between the two detections.
    const Pose expected = motions[v.numbering[0][n.frame]].Inverse() * motions[v.numbering[1][n.frame]];
    EXPECT_NEAR(n.angle_deg, CalibrationBoard::SymmetryAngleDeg(expected), 1e-6) << "frame " << n.frame;
  }
  EXPECT_EQ(renumbered, differing);
  EXPECT_TRUE(r.dropped.empty());
  ExpectRigRight(r, v.rig);
  EXPECT_TRUE(CalibrationProblems(r, CalibrationQualityLimits{}).empty());
}

// One camera: its calibration does not depend on the board's numbering, and nothing is
// renumbered (there is no other camera to agree with).
TEST(BoardSymmetry, SingleCameraKeepsItsNumbering) {
  const RenderedViews& v = SquareBoardViews();
  CameraCalibrationInput in;
  in.camera_names = {"cam1"};
  in.widths = {kWidth};
  in.heights = {kHeight};
  for (int f = 0; f < static_cast<int>(v.T_rig_board.size()); ++f) {
    BoardObservation o = Observation(v, 1, f, Pose::Identity());
    o.camera = 0;
    in.observations.push_back(o);
  }
  in.board_symmetries = v.board.NumberingSymmetries();
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV4";
  const CameraCalibrationResult r = CalibrateCameras(in, opt);
  EXPECT_TRUE(r.renumbered.empty());
  EXPECT_TRUE(r.dropped.empty());
  EXPECT_LT(r.rms_px, kMaxRmsPx);
  const double fx = r.rig.cameras[0].Intrinsics()[0], sd = r.intrinsics_std[0][0];
  EXPECT_LT(std::abs(fx - v.rig.cameras[1].Intrinsics()[0]), std::max(kSigmas * sd, kRelTol * kTrueFx));
}

// CalibrationProblems names each fault of a solution, one sentence each: taken from a
// good solve (no problem) and spoiled one fault at a time.
TEST(BoardSymmetry, CalibrationProblemsNamesEachFault) {
  const RenderedViews& v = SquareBoardViews();
  CameraCalibrationInput in;
  in.camera_names = {"cam0"};
  in.widths = {kWidth};
  in.heights = {kHeight};
  for (int f = 0; f < static_cast<int>(v.T_rig_board.size()); ++f) in.observations.push_back(Observation(v, 0, f, Pose::Identity()));
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV4";
  const CameraCalibrationResult good = CalibrateCameras(in, opt);
  const CalibrationQualityLimits limits;
  ASSERT_TRUE(CalibrationProblems(good, limits).empty());
  auto expect = [&](const char* what, const CameraCalibrationResult& r, const std::string& needle) {
    const std::vector<std::string> p = CalibrationProblems(r, limits, {"a", "b", "c", "d", "e", "f", "g"});
    ASSERT_FALSE(p.empty()) << what;
    bool found = false;
    for (const auto& s : p) found |= s.find(needle) != std::string::npos;
    EXPECT_TRUE(found) << what << ": no '" << needle << "' in " << p[0];
  };
  CameraCalibrationResult r = good;
  r.converged = false;
  expect("not converged", r, "did not converge");
  r = good;
  r.rms_px = 1.5;
  expect("rms", r, "above the limit of 1.000 px");
  r = good;
  r.residual_variance_px2 = 4.0 * r.views_alone_variance_px2;
  expect("noise floor", r, "2.00 times the views' own noise floor");
  r = good;
  r.num_outliers = r.num_inliers / 5;
  expect("outliers", r, "were rejected as outliers");
  r = good;
  r.observation_inliers[3].assign(r.observation_inliers[3].size(), false);
  expect("a rejected view", r, "frame d, cam0: 100 of 100 points were rejected");
  r = good;
  r.intrinsics_std[0][1] = 0.0;
  expect("a zero sigma", r, "standard deviation is zero, infinite or not a number");
  r = good;
  r.covariance_singular = true;
  expect("singular", r, "singular or not positive definite");
  CalibrationQualityLimits bad;
  bad.max_noise_ratio = 0.5;
  EXPECT_THROW(CalibrationProblems(good, bad), InputError);
}

// Two cameras that share a single frame: with a symmetric board that frame cannot show
// which numbering of camera 1 matches camera 0's; refused with the reason.
TEST(BoardSymmetry, OneSharedFrameIsRefusedWithTheReason) {
  const RenderedViews& v = SquareBoardViews();
  CameraCalibrationInput in = InputOf(v);
  // Camera 0 sees frames 0..15, camera 1 frame 0 and (as frames of its own, 25..31)
  // the placements 9..15.
  for (int f = 0; f < static_cast<int>(v.T_rig_board.size()); ++f) {
    in.observations.push_back(Observation(v, 0, f, Pose::Identity()));
    if (f == 0 || f >= 9) {
      BoardObservation o = Observation(v, 1, f, Pose::Identity());
      if (f != 0) o.frame = 16 + f;
      in.observations.push_back(o);
    }
  }
  in.board_symmetries = v.board.NumberingSymmetries();
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV4";
  try {
    CalibrateCameras(in, opt);
    ADD_FAILURE() << "one shared frame of a symmetric board was accepted";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("cam1"), std::string::npos) << m;
    EXPECT_NE(m.find("symmetric"), std::string::npos) << m;
    EXPECT_NE(m.find("9 x 6"), std::string::npos) << m;
  }
}

// --- mcms calib-rig --------------------------------------------------------------------

using test::CliRun;
using test::Mcms;
using test::ReadAll;

std::string FrameName(int f) {
  char name[16];
  std::snprintf(name, sizeof name, "%02d.png", f + 1);
  return name;
}

// The rendered views as one folder per camera; `name_of[c][f]` the file name of camera
// c's image of placement f.
void WriteViews(const RenderedViews& v, const fs::path& dir, const std::vector<std::vector<std::string>>& name_of) {
  for (size_t c = 0; c < v.rig.size(); ++c) {
    fs::create_directories(dir / v.rig.names[c]);
    for (size_t f = 0; f < v.images[c].size(); ++f)
      ASSERT_TRUE(cv::imwrite((dir / v.rig.names[c] / name_of[c][f]).string(), v.images[c][f]));
  }
}

std::vector<std::vector<std::string>> NaturalNames(const RenderedViews& v) {
  std::vector<std::vector<std::string>> names(v.rig.size());
  for (size_t c = 0; c < v.rig.size(); ++c)
    for (size_t f = 0; f < v.images[c].size(); ++f) names[c].push_back(FrameName(static_cast<int>(f)));
  return names;
}

void WriteBoardYaml(const fs::path& p, const CalibrationBoard& b) {
  std::ofstream o(p);
  o << "target_type: checkerboard\ntargetCols: " << b.cols << "\ntargetRows: " << b.rows
    << "\nrowSpacingMeters: " << b.square_m << "\ncolSpacingMeters: " << b.square_m << "\n";
}

size_t Count(const std::string& text, const std::string& needle) {
  size_t n = 0;
  for (size_t p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1)) ++n;
  return n;
}

// The upside-down camera through the command line: every frame whose numberings differ
// is reported by name as renumbered, and the written models are right.
TEST(AppCalibRigSymmetry, UpsideDownCameraIsRenumberedAndReported) {
  const RenderedViews& v = SquareBoardViews();
  const fs::path d = test::ScratchDir("app_calib_rig_symmetric");
  WriteBoardYaml(d / "board.yaml", v.board);
  WriteViews(v, d, NaturalNames(v));
  const CliRun r = Mcms(d, "calib-rig -q board.yaml cam0 cam1 -m LENSMODEL_OPENCV4 -o out");
  std::printf("%s", r.out.c_str());
  ASSERT_EQ(r.code, 0) << r.err;
  size_t differing = 0;
  for (size_t f = 0; f < v.T_rig_board.size(); ++f)
    if (v.numbering[0][f] != v.numbering[1][f]) {
      ++differing;
      EXPECT_NE(r.out.find("frame " + FrameName(static_cast<int>(f)).substr(0, 2) + ": cam1 renumbered"),
                std::string::npos)
          << "frame " << f;
    }
  EXPECT_EQ(Count(r.out, " renumbered ("), differing);
  EXPECT_NE(r.out.find("the board's numbering is symmetric"), std::string::npos);
  EXPECT_EQ(r.out.find("WARNING"), std::string::npos);
  for (size_t c = 0; c < 2; ++c) {
    const CameraModel m = CameraModel::Read(d / "out" / (v.rig.names[c] + ".cameramodel"));
    for (int p = 0; p < 4; ++p)
      EXPECT_NEAR(m.Intrinsics()[p], v.rig.cameras[c].Intrinsics()[p], 2.0) << v.rig.names[c] << " " << p;
  }
}

// Camera 1's image of one frame taken a moment later than camera 0's, the board moved
// by 2 mm and 0.2 deg in between: that view disagrees with the rest, CalibrationProblems
// says so (by frame name), and nothing is written; --allow-poor-fit writes it with the
// warning. A 9 x 6 board: its numbering is unique, so this is not the symmetry at work.
// (Two images swapped between frames are caught earlier: that solve does not converge.)
TEST(AppCalibRigSymmetry, ViewOfAnotherMomentIsRefusedWithoutOutput) {
  const CalibrationBoard board = CalibrationBoard::Chessboard(9, 6, kSquareM);
  RenderedViews v = Render(TrueRig(false), board, 12, kSeed + 7);
  EXPECT_TRUE(board.NumberingSymmetries().empty());
  const int late = 3;
  const cv::Mat on_time = v.images[1][late].clone();
  {
    const BoardRenderOptions options;
    const RayTable table(v.rig.cameras[1], BoardRenderPadPx(options) + 2.0);
    const Pose moved = Pose{ExpSO3(Vec3(0.2 * std::numbers::pi / 180, 0, 0)), Vec3(0.002, 0, 0)} * v.T_rig_board[late];
    Rng noise(kSeed + 99);
    v.images[1][late] = RenderBoard(table, board, v.rig.cameras[1].T_cam_rig() * moved, options, &noise);
  }
  const fs::path d = test::ScratchDir("app_calib_rig_late_view");
  WriteBoardYaml(d / "board.yaml", board);
  WriteViews(v, d, NaturalNames(v));
  const CliRun r = Mcms(d, "calib-rig -q board.yaml cam0 cam1 -m LENSMODEL_OPENCV4 -o out");
  std::printf("stderr: %s\n", r.err.c_str());
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("not trustworthy"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no output written"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--allow-poor-fit"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("frame 04, cam"), std::string::npos) << r.err;
  for (const char* f : {"cam0.cameramodel", "cam1.cameramodel", "cam0.yml", "rig.yaml", "residuals-cam0.svg"})
    EXPECT_FALSE(fs::exists(d / "out" / f)) << f;

  const CliRun w = Mcms(d, "calib-rig -q board.yaml cam0 cam1 -m LENSMODEL_OPENCV4 -o out --allow-poor-fit");
  EXPECT_EQ(w.code, 0) << w.err;
  EXPECT_NE(w.err.find("WARNING: the calibration is not trustworthy"), std::string::npos) << w.err;
  EXPECT_NE(w.out.find("WARNING: the calibration is not trustworthy"), std::string::npos) << w.out;
  EXPECT_TRUE(fs::exists(d / "out" / "rig.yaml"));

  // Without the outlier rejection the view stays in: the residual is far above the
  // views' own noise floor.
  const CliRun k0 = Mcms(d, "calib-rig -q board.yaml cam0 cam1 -m LENSMODEL_OPENCV4 --outlier-k 0 -o out0");
  std::printf("stderr (--outlier-k 0): %s\n", k0.err.c_str());
  EXPECT_EQ(k0.code, 2) << k0.err;
  EXPECT_NE(k0.err.find("times the views' own noise floor"), std::string::npos) << k0.err;
  EXPECT_FALSE(fs::exists(d / "out0" / "rig.yaml"));

  // The views taken at the same moment pass every check.
  v.images[1][late] = on_time;
  const fs::path ok = test::ScratchDir("app_calib_rig_matched");
  WriteBoardYaml(ok / "board.yaml", board);
  WriteViews(v, ok, NaturalNames(v));
  const CliRun g = Mcms(ok, "calib-rig -q board.yaml cam0 cam1 -m LENSMODEL_OPENCV4 -o out");
  EXPECT_EQ(g.code, 0) << g.err;
  std::printf("%s", g.out.c_str());
}

}  // namespace
}  // namespace mcms
