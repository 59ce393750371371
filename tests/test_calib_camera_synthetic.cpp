// Synthetic end to end: board corners projected through a known 3-camera OPENCV8
// rig with Gaussian pixel noise; the calibration must recover the rig within its
// reported uncertainty, report the noise level as its RMS, and reject bad input
// with an InputError naming what is missing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "calib/calibration_board.h"
#include "calib/camera_calibration.h"
#include "core/error.h"
#include "core/random.h"

namespace mcms {
namespace {

constexpr uint64_t kSeed = 20261122;
constexpr double kNoisePx = 0.3;
constexpr double kSigmas = 4.5;  // each parameter within 4.5 sigma of the truth

CameraRig TrueRig() {
  CameraRig rig;
  const std::vector<double> intr = {820, 815, 645, 478, 0.12, -0.05, 0.0008, -0.0005, 0.01, 0.45, -0.03, 0.02};
  for (int c = 0; c < 3; ++c) {
    std::vector<double> k = intr;
    k[0] += 20 * c;
    k[1] += 20 * c;
    const Pose T = Pose{ExpSO3(Vec3(0.02 * c, -0.15 * c, 0.01 * c)), Vec3(-0.25 * c, 0.01 * c, 0.02 * c)};
    rig.names.push_back("cam" + std::to_string(c));
    rig.cameras.emplace_back("LENSMODEL_OPENCV8", k, 1280, 960, T);
  }
  return rig;
}

CameraCalibrationInput Observe(const CameraRig& rig, const CalibrationBoard& board, int nframes, Rng& rng) {
  CameraCalibrationInput in;
  for (size_t c = 0; c < rig.size(); ++c) {
    in.camera_names.push_back(rig.names[c]);
    in.widths.push_back(rig.cameras[c].Width());
    in.heights.push_back(rig.cameras[c].Height());
  }
  const double bw = (board.cols - 1) * board.square_m, bh = (board.rows - 1) * board.square_m;
  for (int f = 0; f < nframes; ++f) {
    // Board 0.6-1.2 m in front of the rig, tilted up to ~35 deg, spread over the view.
    const Vec3 centre(rng.Uniform(-0.45, 0.15), rng.Uniform(-0.25, 0.25), rng.Uniform(0.6, 1.2));
    const Mat3 R = ExpSO3(Vec3(rng.Uniform(-0.6, 0.6), rng.Uniform(-0.6, 0.6), rng.Uniform(-0.4, 0.4)));
    const Pose T_rig_board{R, centre - R * Vec3(bw / 2, bh / 2, 0)};
    for (size_t c = 0; c < rig.size(); ++c) {
      const CameraModel& cam = rig.cameras[c];
      BoardObservation o;
      o.camera = static_cast<int>(c);
      o.frame = f;
      bool all = true;
      for (int id = 0; id < board.NumPoints(); ++id) {
        const Vec3 p = cam.T_cam_rig() * (T_rig_board * board.Point(id));
        if (!cam.Sees(p, 5.0)) {
          all = false;
          break;
        }
        o.points_board.push_back(board.Point(id));
        o.pixels.push_back(cam.Project(p) + Vec2(rng.Normal(0, kNoisePx), rng.Normal(0, kNoisePx)));
      }
      if (all) in.observations.push_back(o);  // chessboards are found whole or not at all
    }
  }
  return in;
}

TEST(CalibCameraSynthetic, RecoversOpenCv8RigWithinUncertainty) {
  Rng rng(kSeed);
  const CameraRig truth = TrueRig();
  const CalibrationBoard board = CalibrationBoard::Chessboard(10, 8, 0.04);
  const CameraCalibrationInput in = Observe(truth, board, 60, rng);
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV8";
  const CameraCalibrationResult r = CalibrateCameras(in, opt);
  std::printf("%s", SummarizeCalibration(r).c_str());
  // The RMS per coordinate estimates the noise (a few % low: the fit absorbs
  // #parameters / #residuals of it).
  EXPECT_NEAR(r.rms_px, kNoisePx, 0.05 * kNoisePx);
  EXPECT_NEAR(std::sqrt(r.residual_variance_px2), kNoisePx, 0.05 * kNoisePx);
  double worst = 0.0;
  for (size_t c = 0; c < truth.size(); ++c) {
    const auto& est = r.rig.cameras[c].Intrinsics();
    const auto& tru = truth.cameras[c].Intrinsics();
    for (size_t i = 0; i < est.size(); ++i) {
      const double z = std::abs(est[i] - tru[i]) / r.intrinsics_std[c][i];
      worst = std::max(worst, z);
      EXPECT_LT(z, kSigmas) << "camera " << c << " intrinsic " << i << ": " << est[i] << " vs " << tru[i] << " +- "
                            << r.intrinsics_std[c][i];
    }
    if (c == 0) continue;
    double rt_est[6], rt_true[6];
    r.rig.cameras[c].T_cam_rig().ToRt(rt_est);
    truth.cameras[c].T_cam_rig().ToRt(rt_true);
    for (int i = 0; i < 6; ++i) {
      const double z = std::abs(rt_est[i] - rt_true[i]) / r.extrinsics_std[c][i];
      worst = std::max(worst, z);
      EXPECT_LT(z, kSigmas) << "camera " << c << " rt " << i;
    }
  }
  std::printf("synthetic: RMS %.4f px (noise %.2f), worst parameter error %.2f sigma\n", r.rms_px, kNoisePx, worst);
  // Projection uncertainty: positive where defined, defined in the middle of the
  // image (the extreme corners of this strongly distorted rational lens do not
  // unproject, and are NaN), and smaller in the middle than the worst cell.
  const UncertaintyGrid g = ProjectionUncertaintyGrid(r.rig.cameras[0], r.intrinsics_covariance[0], 1.0);
  double max_sigma = 0.0;
  for (double s : g.sigma_px) {
    if (!std::isfinite(s)) continue;
    EXPECT_GT(s, 0.0);
    max_sigma = std::max(max_sigma, s);
  }
  const double centre = g.sigma_px[(g.ny / 2) * g.nx + g.nx / 2];
  ASSERT_TRUE(std::isfinite(centre));
  EXPECT_GT(centre, 0.0);
  EXPECT_LE(centre, max_sigma);
  std::printf("synthetic: projection sigma at 1 m: centre %.3f px, worst defined cell %.3f px\n", centre, max_sigma);
}

TEST(CalibCameraSynthetic, BadInputNamesTheCameraAndTheRemedy) {
  Rng rng(kSeed + 1);
  const CameraRig truth = TrueRig();
  const CalibrationBoard board = CalibrationBoard::Chessboard(10, 8, 0.04);
  CameraCalibrationInput in = Observe(truth, board, 20, rng);
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV4";
  // A camera that never sees the board.
  CameraCalibrationInput none = in;
  std::erase_if(none.observations, [](const BoardObservation& o) { return o.camera == 2; });
  try {
    CalibrateCameras(none, opt);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cam2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("take more images"), std::string::npos) << e.what();
  }
  // A camera that sees the board, but never together with the others.
  CameraCalibrationInput apart = in;
  std::erase_if(apart.observations, [](const BoardObservation& o) { return o.camera == 2; });
  apart.camera_names.pop_back();
  apart.widths.pop_back();
  apart.heights.pop_back();
  for (auto& o : apart.observations)
    if (o.camera == 1) o.frame += 1000;
  try {
    CalibrateCameras(apart, opt);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cam1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("same frame"), std::string::npos) << e.what();
  }
  // An unsupported lens model.
  opt.lensmodel = "LENSMODEL_CAHVOR";
  EXPECT_THROW(CalibrateCameras(in, opt), InputError);
}

TEST(CalibCameraSynthetic, BoardGeometryAndFile) {
  const CalibrationBoard g = CalibrationBoard::AprilGrid(6, 6, 0.088, 0.3);
  EXPECT_EQ(g.NumPoints(), 144);
  // Tag 7 = column 1, row 1; corner 2 = top-right.
  EXPECT_TRUE(g.Point(4 * 7 + 2).isApprox(Vec3(0.088 * 1.3 + 0.088, 0.088 * 1.3 + 0.088, 0.0)));
  const CalibrationBoard c = CalibrationBoard::Chessboard(9, 6, 0.025);
  EXPECT_TRUE(c.Point(10).isApprox(Vec3(0.025, 0.025, 0.0)));
  std::string why;
  EXPECT_FALSE(CalibrationBoard::Chessboard(1, 6, 0.025).IsValid(&why));
  EXPECT_THROW(CalibrationBoard::Read("/nonexistent/board.yaml"), InputError);
}

}  // namespace
}  // namespace mcms
