// End to end on rendered images: render -> detect -> match -> triangulate -> identify
// -> bundle-adjust, over sequences of at least 100 frames from 4 cameras, measured
// against the ground truth and against the bound the pipeline reports.
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>

#include "jobs/evaluation.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "synthetic/scenario.h"
#include "tests/test_util.h"
#include "tracking/tracker.h"
#include "vision/blob_detector.h"
#include "vision/sphere_projection.h"

namespace mcms {
namespace {

struct RunResult {
  std::vector<FrameResult> frames;
  std::vector<FrameTruth> truth;
  std::vector<FrameResult> windowed;  // the same frames, detected in predicted windows
  size_t window_detections = 0, whole_detections = 0;
};

// Tracks the scenario's frames; with `windows`, a second tracker detects on the same images
// in windows around the predicted ball images (TrackerOptions::predicted_windows).
RunResult TrackScenario(const Scenario& sc, bool windows = false) {
  ScenarioRenderer renderer(sc, 2);
  TrackerOptions opts;
  opts.detector.gain_e_per_dn = sc.render.gain_e_per_dn;
  Tracker tracker(sc.rig, sc.target, opts);
  opts.predicted_windows = true;
  Tracker windowed(sc.rig, sc.target, opts);
  RunResult r;
  for (size_t f = 0; f < sc.NumFrames(); ++f) {
    RenderedFrame rf = renderer.Render(f);
    r.frames.push_back(tracker.ProcessFrame(f, sc.times[f], rf.images));
    if (windows) r.windowed.push_back(windowed.ProcessFrame(f, sc.times[f], rf.images));
    r.truth.push_back(rf.truth);
  }
  r.window_detections = windowed.window_detections();
  r.whole_detections = windowed.whole_image_detections();
  return r;
}

TEST(Pipeline, DefaultScenarioPoseIsAccurateAndItsCovarianceHonest) {
  const Scenario sc = Scenario::Default();
  ASSERT_GE(sc.NumFrames(), 100u);
  ASSERT_EQ(sc.rig.size(), 4u);
  const RunResult r = TrackScenario(sc, true);
  std::vector<Pose> truth;
  for (const auto& t : r.truth) truth.push_back(t.T_rig_target);
  // Detection in predicted windows gives the same frames: statuses, poses (to rounding),
  // covariances, while most camera images are read only in the windows.
  std::printf("predicted windows: %zu camera images detected in windows, %zu whole\n", r.window_detections,
              r.whole_detections);
  EXPECT_GT(r.window_detections, 4 * r.whole_detections);
  for (size_t f = 0; f < r.frames.size(); ++f) {
    const FrameResult &a = r.frames[f], &b = r.windowed[f];
    EXPECT_EQ(a.status, b.status) << "frame " << f << ": " << a.reason << " | " << b.reason;
    ASSERT_EQ(a.T_rig_target.has_value(), b.T_rig_target.has_value()) << f;
    if (!a.T_rig_target) continue;
    EXPECT_LT((a.T_rig_target->t - b.T_rig_target->t).norm(), 1e-9) << f;
    EXPECT_LT((a.cov - b.cov).norm(), 1e-6 * a.cov.norm()) << f;
  }
  const PoseErrorSummary s = EvaluatePoses(r.frames, truth);
  std::printf("%s", FormatSummary(s).c_str());
  // Frames where no two balls' images overlap in any camera must be ok; where they do
  // (the default trajectory has such frames), the merged blob is an outlier and the
  // frame is degraded with the reason.
  int clean = 0, clean_ok = 0, overlapped_degraded = 0, overlapped = 0;
  for (size_t f = 0; f < r.frames.size(); ++f) {
    bool any = false;
    for (const auto& o : r.truth[f].observations) any = any || o.overlapped || !o.visible;
    if (any) {
      ++overlapped;
      overlapped_degraded += r.frames[f].status == FrameStatus::kDegraded && !r.frames[f].reason.empty();
    } else {
      ++clean;
      clean_ok += r.frames[f].status == FrameStatus::kOk;
    }
  }
  std::printf("frames with all balls clear in all cameras: %d (%d ok); with overlapping ball images: %d (%d degraded)\n",
              clean, clean_ok, overlapped, overlapped_degraded);
  EXPECT_EQ(s.lost, 0);
  EXPECT_GE(clean, 100);
  EXPECT_GE(clean_ok, clean - 1);
  // Accuracy: the paper's rig class reaches ~0.1 mm; rendered noise allows far better.
  EXPECT_LT(s.position_rms_m, 5e-5);
  EXPECT_LT(s.rotation_rms_rad, 0.05 * std::numbers::pi / 180);
  // Honesty: the mean NEES of the 6-DOF pose error inside its 95 % chi-square band.
  EXPECT_TRUE(s.NeesInBand()) << "mean NEES " << s.mean_nees << " not in [" << s.nees_band_lo << ", "
                              << s.nees_band_hi << "]";

  // Triangulated points against the Cramer-Rao bound they report.
  double e2 = 0, bound2 = 0;
  int n = 0;
  for (size_t f = 0; f < r.frames.size(); ++f)
    for (const auto& p : r.frames[f].points) {
      double best = 1e9;
      Vec3 e;
      for (const Vec3& b : r.truth[f].balls_rig)
        if ((p.p_rig - b).norm() < best) {
          best = (p.p_rig - b).norm();
          e = p.p_rig - b;
        }
      if (best > 0.005) continue;  // not a ball
      e2 += e.squaredNorm();
      bound2 += p.cov.trace();
      ++n;
    }
  const double ratio = std::sqrt(e2 / bound2);
  std::printf("triangulated points: %d, RMS error %.4f mm, Cramer-Rao bound %.4f mm, ratio %.3f\n", n,
              1e3 * std::sqrt(e2 / n), 1e3 * std::sqrt(bound2 / n), ratio);
  EXPECT_GT(n, 400);
  EXPECT_NEAR(ratio, 1.0, 0.10);
}

TEST(Pipeline, OcclusionsSpuriousReflectionsAndMissingCamerasDegradeButDoNotBreakTracking) {
  Scenario sc = Scenario::Default();
  sc.render.occlusion_probability = 0.06;
  sc.render.spurious_per_image = 2.0;
  sc.render.dropout_probability = 0.05;
  sc.seed = 99;
  const RunResult r = TrackScenario(sc, true);
  std::vector<Pose> truth;
  int dropped_frames = 0, dropped_and_degraded = 0;
  for (size_t f = 0; f < r.frames.size(); ++f) {
    truth.push_back(r.truth[f].T_rig_target);
    if (!r.truth[f].dropped_cameras.empty()) {
      ++dropped_frames;
      const std::string cam = sc.rig.names[r.truth[f].dropped_cameras[0]];
      if (r.frames[f].status != FrameStatus::kOk && r.frames[f].reason.find(cam) != std::string::npos)
        ++dropped_and_degraded;
    }
  }
  const PoseErrorSummary s = EvaluatePoses(r.frames, truth);
  std::printf("%s", FormatSummary(s).c_str());
  // Detection in predicted windows: where the windows hold every ball the camera saw in the
  // last frame, the poses are those of the whole-image detection (to rounding); an occluded
  // ball, a dropped camera or a lost frame sends a camera back to the whole image. Spurious
  // reflections outside the windows are not seen, so statuses may differ only there.
  const PoseErrorSummary w = EvaluatePoses(r.windowed, truth);
  std::printf("predicted windows: %zu camera images detected in windows, %zu whole\n%s", r.window_detections,
              r.whole_detections, FormatSummary(w).c_str());
  EXPECT_GT(r.window_detections, 2 * r.whole_detections);
  EXPECT_LE(w.lost, s.lost);
  EXPECT_LT(w.position_max_m, 5e-4);
  EXPECT_LT(w.position_rms_m, 1.05 * s.position_rms_m);
  EXPECT_GT(dropped_frames, 0);
  EXPECT_EQ(dropped_and_degraded, dropped_frames) << "a frame with a missing camera must say so";
  EXPECT_GT(s.degraded, 0);
  EXPECT_LE(s.lost, 2);
  EXPECT_LT(s.position_max_m, 5e-4) << "no frame may be grossly wrong (a wrong identification)";
  EXPECT_LT(s.position_rms_m, 1e-4);
}

// The sphere-projection bias: a centroiding detector sees the centroid of the ball's
// outline, not the image of its centre. Corrected, the centre is within 0.02 px
// everywhere in the field of view; uncorrected, the error grows toward the edge.
TEST(Pipeline, SphereBiasCorrectionHoldsAcrossTheFieldOfView) {
  const Scenario sc = Scenario::Default();
  const CameraModel& cam = sc.rig.cameras[0];
  RayTable table(cam);
  RenderOptions ro = sc.render;
  ro.noise_free = true;
  ro.bit_depth = 16;
  ro.ball_dn = 40000;
  ro.background_dn = 2000;
  const double radius = sc.target.ball_radius;
  double worst_corrected = 0, centre_uncorrected = 0, edge_uncorrected = 0;
  for (double fu : {0.5, 0.05, 0.95, 0.25, 0.75})
    for (double fv : {0.5, 0.06, 0.94, 0.3}) {
      const Vec2 q(fu * (cam.Width() - 1), fv * (cam.Height() - 1));
      const Vec3 c = *cam.Unproject(q) * 1.0;  // a ball 1 m away along that ray
      const cv::Mat im = RenderSpheres(table, {c}, radius, ro, nullptr);
      BlobDetectorOptions bo;
      bo.threshold_dn = 1000;  // a noise-free image has no noise to set the threshold from
      const auto blobs = DetectBlobs(im, bo);
      ASSERT_EQ(blobs.size(), 1u);
      const Vec2 truth = cam.Project(c);
      const Vec2 corrected = blobs[0].centre - SphereProjectionBias(cam, c, radius);
      const double raw = (blobs[0].centre - truth).norm();
      worst_corrected = std::max(worst_corrected, (corrected - truth).norm());
      if (fu == 0.5 && fv == 0.5) centre_uncorrected = raw;
      if ((fu == 0.05 || fu == 0.95) && (fv == 0.06 || fv == 0.94)) edge_uncorrected = std::max(edge_uncorrected, raw);
    }
  std::printf("ball centre error: corrected worst %.4f px; uncorrected %.4f px at the centre, %.4f px at the corners\n",
              worst_corrected, centre_uncorrected, edge_uncorrected);
  EXPECT_LT(worst_corrected, 0.02);
  EXPECT_GT(edge_uncorrected, 0.1);
  EXPECT_GT(edge_uncorrected, 5 * worst_corrected);
}

}  // namespace
}  // namespace mcms
