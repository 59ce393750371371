// The paper's lab experiment on the forward model, shortened: rendered camera frames
// tracked by the pipeline, robot encoders and inclinometer at their own rates, fused by
// MOIFA and by the KF. Checks what the fusion must do, against the truth.
#include <gtest/gtest.h>

#include <cmath>

#include "jobs/evaluation.h"
#include "jobs/lab_experiment.h"
#include "synthetic/lab_scenario.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "core/error.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

TEST(LabExperiment, FusionIsConsistentAndTheInclinometerFixesTiltNotYaw) {
  LabOptions lo;
  lo.points = 10;
  lo.dwell_s = 3.0;
  lo.camera_rate_hz = 2.0;
  const LabScenario lab = MakeLabScenario(lo);
  ScenarioRenderer renderer(lab.vision, 2);
  TrackerOptions topts;
  topts.detector.gain_e_per_dn = lab.vision.render.gain_e_per_dn;
  Tracker tracker(lab.vision.rig, lab.vision.target, topts);
  std::vector<FrameResult> tracked;
  for (size_t f = 0; f < lab.vision.NumFrames(); ++f)
    tracked.push_back(tracker.ProcessFrame(f, lab.vision.times[f], renderer.Render(f).images));
  const LabResult r = RunLabExperiment(lab, tracked);
  std::printf("%s", FormatLabTable(r).c_str());
  ASSERT_EQ(r.summary.size(), 4u);
  const auto& cam = r.summary[0];
  const auto& robot = r.summary[1];
  const auto& moifa = r.summary[2];
  const auto& kf = r.summary[3];
  for (const auto& s : r.summary) EXPECT_EQ(s.points, lo.points) << s.name;
  // Every method's covariance is honest at the points (6-dof NEES in its 95 % band, with
  // 10 points the band is wide; the robot's is honest by construction of its accuracy model).
  for (const auto* s : {&cam, &robot, &moifa, &kf})
    EXPECT_TRUE(s->mean_nees >= s->nees_band_lo && s->mean_nees <= s->nees_band_hi)
        << s->name << " mean NEES " << s->mean_nees;
  // The inclinometer sees tilt, not yaw: fused tilt far better than the camera's, fused yaw
  // no better than what camera and robot give.
  EXPECT_LT(moifa.tilt_rms_rad, 0.4 * cam.tilt_rms_rad);
  EXPECT_GT(moifa.yaw_rms_rad, 0.5 * std::min(cam.yaw_rms_rad, robot.yaw_rms_rad));
  // Fusion never makes position worse than the best single sensor by more than chance.
  EXPECT_LT(moifa.position_rms_m, 1.3 * std::min(cam.position_rms_m, robot.position_rms_m));
  EXPECT_LT(kf.position_rms_m, 1.5 * std::min(cam.position_rms_m, robot.position_rms_m));
  // KF innovations of the camera and the inclinometer consistent (NIS per dof near 1).
  ASSERT_EQ(r.kf_nis_mean.size(), 3u);
  EXPECT_NEAR(r.kf_nis_mean[0], 1.0, 0.35) << "camera NIS per dof";
  EXPECT_NEAR(r.kf_nis_mean[2], 1.0, 0.1) << "inclinometer NIS per dof";
}

TEST(LabExperiment, PosesOutOfReachAreRefused) {
  LabOptions lo;
  lo.points = 3;
  lo.sphere_radius_m = 2.5;
  EXPECT_THROW(MakeLabScenario(lo), InputError);
  lo.sphere_radius_m = 0.2;
  lo.dwell_s = 0;
  EXPECT_THROW(MakeLabScenario(lo), InputError);
}

}  // namespace
}  // namespace mcms
