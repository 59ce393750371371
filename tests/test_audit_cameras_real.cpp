// The camera audit on measured multi-camera data: caliscope's real recording of four
// unsynchronised 1280x720 webcams viewing a 4x5 ChArUco board (../shared/data/caliscope-4cam;
// skipped with the reason when absent). The board's 12 inner corners stand in for the
// target's balls (radius 0: their images are their projections), each view's corners for
// the blobs, and the rig is our own joint calibration of the same views (mrcal's OPENCV5,
// started from caliscope's intrinsics). Each corner's sigma is its camera's calibration
// residual RMS per coordinate (scaled by the solve's degrees of freedom), what a user of
// such a rig knows.
//
// What the real data has that the audit's simulation does not: the webcams are not
// triggered together (caliscope groups the frames nearest in time: within one sync index
// the four exposures differ by up to 46 ms while the board is moved by hand), so each
// frame's cameras see the board at slightly different poses; the audit has one time per
// frame. The tests below measure what that does to the clean audit, and then hide effects
// in the rig file (the data stays measured) and require the audit to find them.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <set>

#include "audit/camera_audit.h"
#include "calib/camera_calibration.h"
#include "tests/caliscope.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

struct RealRecording {
  CameraRig rig;  // our joint calibration
  Target target;  // the board's 12 inner corners, radius 0
  std::vector<FrameResult> results;
  std::vector<double> sigma_px;  // per camera, per coordinate
  std::vector<double> max_lag_s;  // per frame: the spread of its views' exposure times
};

RealRecording Load(const std::filesystem::path& dir) {
  RealRecording rec;
  std::vector<double> times;
  const CameraCalibrationInput in = test::ReadCaliscopeViews(dir, &times);
  const auto ref = test::ReadCaliscopeToml(dir / "camera_array.toml");
  CameraCalibrationOptions opt;
  opt.lensmodel = "LENSMODEL_OPENCV5";
  for (int c = 0; c < 4; ++c) opt.initial_intrinsics.push_back(ref.at(c).Opencv5Intrinsics());
  const CameraCalibrationResult cal = CalibrateCameras(in, opt);
  rec.rig = cal.rig;
  std::printf("calibration: %d inliers, %d outliers, residual variance %.4f px^2, views alone %.4f px^2\n",
              cal.num_inliers, cal.num_outliers, cal.residual_variance_px2, cal.views_alone_variance_px2);
  // The corners' in-sample RMS, raised to the solve's residual variance (its degrees of
  // freedom), per camera.
  const double dof_factor = std::sqrt(cal.residual_variance_px2) / cal.rms_px;
  for (int c = 0; c < 4; ++c) rec.sigma_px.push_back(cal.residuals[c].rms_px * dof_factor);

  rec.target.name = "caliscope ChArUco 4x5, 12 inner corners";
  rec.target.ball_radius = 0;
  std::map<std::pair<long, long>, int> corner_of;  // board (x, y) in um -> corner index
  for (const BoardObservation& o : in.observations)
    for (const Vec3& p : o.points_board) {
      const std::pair<long, long> key{std::lround(p.x() * 1e6), std::lround(p.y() * 1e6)};
      if (corner_of.emplace(key, static_cast<int>(rec.target.balls_target.size())).second)
        rec.target.balls_target.push_back(p);
    }

  std::map<int, FrameResult> by_frame;
  std::map<int, std::vector<double>> frame_times;
  std::map<std::pair<int, int>, double> view_time;
  double t0 = 1e300;
  for (double t : times) t0 = std::min(t0, t);
  for (size_t k = 0; k < in.observations.size(); ++k) {
    frame_times[in.observations[k].frame].push_back(times[k] - t0);
    view_time[{in.observations[k].frame, in.observations[k].camera}] = times[k] - t0;
  }
  // The views the calibration kept, their inlier corners (its outliers are not the
  // audit's question).
  for (size_t k = 0; k < cal.observations.size(); ++k) {
    const BoardObservation& o = cal.observations[k];
    if (o.frame >= static_cast<int>(cal.T_rig_board.size()) || !cal.T_rig_board[o.frame]) continue;
    FrameResult& f = by_frame[o.frame];
    f.frame = static_cast<size_t>(o.frame);
    f.status = FrameStatus::kOk;
    f.T_rig_target = *cal.T_rig_board[o.frame];
    f.image_points.resize(4);
    f.camera_time_s.resize(4, std::nan(""));
    f.camera_time_s[o.camera] = view_time.at({o.frame, o.camera});
    const double s = rec.sigma_px[o.camera];
    for (size_t i = 0; i < o.pixels.size(); ++i)
      if (cal.observation_inliers[k][i]) f.image_points[o.camera].push_back({o.pixels[i], Mat2::Identity() * s * s});
  }
  for (auto& [frame, f] : by_frame) {
    const std::vector<double>& t = frame_times[frame];
    f.time_s = std::accumulate(t.begin(), t.end(), 0.0) / static_cast<double>(t.size());
    rec.max_lag_s.push_back(*std::max_element(t.begin(), t.end()) - *std::min_element(t.begin(), t.end()));
    rec.results.push_back(f);
  }
  std::printf("caliscope-4cam: %zu frames with a board pose, corners' sigma %.3f %.3f %.3f %.3f px; exposures within "
              "a frame spread up to %.1f ms\n",
              rec.results.size(), rec.sigma_px[0], rec.sigma_px[1], rec.sigma_px[2], rec.sigma_px[3],
              1e3 * *std::max_element(rec.max_lag_s.begin(), rec.max_lag_s.end()));
  return rec;
}

CameraAuditResult Audit(const RealRecording& r, const CameraRig& rig) {
  return AuditCameraModel(rig, r.target, r.results, {}, [](const std::string& s) { std::printf("  %s\n", s.c_str()); });
}

void Print(const CameraAuditResult& a) {
  for (const auto& e : a.report.effects) {
    std::printf("  named: %s at %s:", e.name.c_str(), e.where.c_str());
    for (size_t i = 0; i < e.parameters.size(); ++i)
      std::printf(" %s %.4g +- %.2g", e.parameters[i].first.c_str(), e.parameters[i].second,
                  i < e.sigma.size() ? e.sigma[i].second : NAN);
    std::printf("\n");
  }
  for (const auto& t : a.report.tests)
    if (t.failed) std::printf("  test: %s: p %.3g  FAILED\n", t.name.c_str(), t.p_value);
  for (const auto& t : a.report.tests_after)
    std::printf("  still failing with the final model: %s: p %.3g\n", t.name.c_str(), t.p_value);
  std::printf("  %zu of %d tests still fail with the final model\n", a.report.tests_after.size(), a.report.tests_after_run);
}

bool AnyTestFailed(const CameraAuditResult& a) {
  for (const AuditTest& t : a.report.tests)
    if (t.failed) return true;
  return false;
}

const AuditEffect* Named(const CameraAuditResult& a, const std::string& name, const std::string& where) {
  for (const AuditEffect& e : a.report.effects)
    if (e.name == name && e.where == where) return &e;
  return nullptr;
}

// What the audit says about this real rig, with one time per frame (what a tracker of
// synchronised cameras gives) and with each view's own time. Measured on 2026-12-06: both
// fail the residual tests by far (lag-1 autocorrelation in time at p ~ 1e-20 .. 1e-43 on
// every camera; chi-square of cam2 and cam3), and the audit names 3-4 effects on a rig
// calibrated from these very views (a constant time offset of 12-15 ms, part-way moves of
// cam0 or cam1, a principal point of cam3 or one corner of the board), not the same ones
// for the two timings: the model misses something the catalog does not hold, and the
// named causes here are the catalog's nearest, not findings (docs/audits.md), and the
// report says so: 10-11 of its 52 tests still fail with the final model. The
// exposure times do not help at this sampling (the board moved by hand, sampled at 6 Hz:
// the frame's twist from its neighbours 167 ms away does not carry a pose 46 ms along),
// where on smooth motion they make unsynchronised cameras clean
// (AuditCameras.UnsynchronisedCamerasAreCleanWithTheirExposureTimes).
// Then an effect hidden in the rig file (the views stay measured): a focal length 0.5 %
// shorter in the file than the views say at cam3 must be named at cam3 with about its
// size, where the unchanged file gives no focal-length change there.
TEST(AuditCamerasReal, CaliscopeFourWebcams) {
  MCMS_REQUIRE_DATA(dir, "caliscope-4cam");
  const RealRecording rec = Load(dir);
  RealRecording one_time = rec;
  for (FrameResult& f : one_time.results) f.camera_time_s.clear();
  std::printf("one time per frame:\n");
  const CameraAuditResult base = Audit(one_time, rec.rig);
  Print(base);
  std::printf("each camera at its own exposure time:\n");
  const CameraAuditResult timed = Audit(rec, rec.rig);
  Print(timed);
  EXPECT_TRUE(AnyTestFailed(base)) << "the measured views passed every residual test";
  EXPECT_TRUE(AnyTestFailed(timed)) << "the measured views passed every residual test";
  // And the report says that what it names does not explain them.
  EXPECT_FALSE(base.report.tests_after.empty());
  EXPECT_FALSE(timed.report.tests_after.empty());
  EXPECT_EQ(Named(base, "focal_length", "cam3"), nullptr);

  constexpr double kFocal = 0.005;
  CameraRig hidden = rec.rig;
  hidden.cameras[3].MutableIntrinsics()[0] /= 1 + kFocal;
  hidden.cameras[3].MutableIntrinsics()[1] /= 1 + kFocal;
  std::printf("hidden: the file's focal length of cam3 %.1f %% short:\n", 100 * kFocal);
  const CameraAuditResult a = Audit(one_time, hidden);
  Print(a);
  const AuditEffect* f = Named(a, "focal_length", "cam3");
  ASSERT_NE(f, nullptr) << "the hidden focal length was not named at cam3";
  // Its size: the named value is biased by what the catalog leaves unexplained here (0.37 %
  // +- 0.03 % measured), so the bound is half the effect, not its sigma.
  EXPECT_NEAR(f->parameters[0].second, kFocal / (1 + kFocal), 0.5 * kFocal);
}

}  // namespace
}  // namespace mcms
