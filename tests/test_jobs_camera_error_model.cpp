// The camera error model (synthetic/camera_error_model.h): what each effect does to a
// tracked pose and its covariance, its readers, and the demo rendered with the paper's model
// against the no-render lab prediction of the same model.
#include <gtest/gtest.h>

#include <cmath>

#include "core/random.h"
#include "synthetic/camera_error_model.h"
#include "jobs/demo.h"
#include "jobs/fov_map.h"
#include "jobs/fov_map_lab.h"
#include "synthetic/lab_scenario.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

TEST(CameraErrorModel, IdealChangesNothing) {
  const CameraErrorModel m = ReadCameraErrorModel("ideal");
  EXPECT_TRUE(m.IsIdeal());
  Rng rng(3);
  Pose T{ExpSO3(Vec3(0.1, 0.2, 0.3)), Vec3(0.1, 0.2, 0.5)};
  const Pose T0 = T;
  Mat6 cov = 1e-8 * Mat6::Identity();
  m.ScalePixelNoise(&T, &cov, &rng);
  m.AddVisitCovariance(&cov, 7);
  EXPECT_EQ((T.t - T0.t).norm(), 0);
  EXPECT_EQ((T.R - T0.R).norm(), 0);
  EXPECT_EQ((cov - 1e-8 * Mat6::Identity()).norm(), 0);
  EXPECT_EQ(m.DrawVisit(&rng).norm(), 0);
}

// The pixel-noise excess makes the spread k times the tracker's and reports it; the visit
// draw has the per-axis sigma sqrt(floor^2 + g^2).
TEST(CameraErrorModel, EffectsHaveTheirSize) {
  CameraErrorModel m;
  m.pixel_noise_scale = 5;
  m.floor_m = 0.1e-3;
  m.anisotropy_m = Vec3(0, 1e-3, 0.25e-3);
  const Vec3 s = m.VisitSigma();
  EXPECT_NEAR(s.x(), 0.1e-3, 1e-12);
  EXPECT_NEAR(s.y(), std::hypot(0.1e-3, 1e-3), 1e-12);
  Mat6 cov0 = Mat6::Zero();
  cov0.diagonal() << 1e-8, 4e-8, 9e-8, 1e-10, 4e-10, 9e-10;
  Rng rng(11);
  const int n = 4000;
  Vec6 sum2 = Vec6::Zero();
  Vec3 visit2 = Vec3::Zero();
  for (int i = 0; i < n; ++i) {
    Pose T;
    Mat6 cov = cov0;
    m.ScalePixelNoise(&T, &cov, &rng);
    EXPECT_LT((cov - 25 * cov0).norm(), 1e-20);
    Vec6 d = BoxMinus(T, Pose{});
    sum2 += d.cwiseAbs2();
    visit2 += m.DrawVisit(&rng).cwiseAbs2();
  }
  // Excess variance (k^2 - 1) cov0: the sample variance within 4 sd (sd = var sqrt(2 / n)).
  for (int i = 0; i < 6; ++i) {
    const double want = 24 * cov0(i, i);
    EXPECT_NEAR(sum2[i] / n, want, 4 * want * std::sqrt(2.0 / n)) << i;
  }
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(visit2[a] / n, s[a] * s[a], 4 * s[a] * s[a] * std::sqrt(2.0 / n)) << a;
  Mat6 cov = Mat6::Zero();
  m.AddVisitCovariance(&cov, 7);
  EXPECT_NEAR(cov(4, 4), 7 * s.y() * s.y(), 1e-15);
  EXPECT_EQ(cov(0, 0), 0);  // no orientation error per visit
}

TEST(CameraErrorModel, BadSpecsRefused) {
  const fs::path s = test::ScratchDir("camera_model_bad");
  EXPECT_NE(test::ErrorOf([] { ReadCameraErrorModel("papr"); }).find("expected ideal, paper, or the JSON"),
            std::string::npos);
  test::WriteText(s / "broken.json", "{\"effects\": [ {\"name\": ");
  EXPECT_NE(test::ErrorOf([&] { ReadCameraErrorModel((s / "broken.json").string()); }).find("not valid JSON"),
            std::string::npos);
  test::WriteText(s / "noeffects.json", "{\"heldout_loglik_gain\": 3}");
  EXPECT_NE(test::ErrorOf([&] { ReadCameraErrorModel((s / "noeffects.json").string()); }).find("no \"effects\""),
            std::string::npos);
  test::WriteText(s / "unknown.json", "{\"effects\": [{\"name\": \"wobble\", \"parameters\": {}}]}");
  EXPECT_NE(test::ErrorOf([&] { ReadCameraErrorModel((s / "unknown.json").string()); }).find("unknown effect \"wobble\""),
            std::string::npos);
  test::WriteText(s / "negative.json", "{\"effects\": [{\"name\": \"anisotropy_y\", \"parameters\": {\"sigma_y_m\": -1}}]}");
  EXPECT_NE(test::ErrorOf([&] { ReadCameraErrorModel((s / "negative.json").string()); }).find("sigma_y_m"),
            std::string::npos);
  test::WriteText(s / "missing.json", "{\"effects\": [{\"name\": \"noise_floor\", \"parameters\": {\"floor\": 1}}]}");
  EXPECT_NE(test::ErrorOf([&] { ReadCameraErrorModel((s / "missing.json").string()); }).find("parameters.floor_m"),
            std::string::npos);
  test::WriteText(s / "small.json", "{\"effects\": [{\"name\": \"pixel_noise_scale\", \"parameters\": {\"scale\": 0.5}}]}");
  EXPECT_NE(test::ErrorOf([&] { ReadCameraErrorModel((s / "small.json").string()); }).find(">= 1"), std::string::npos);
  // A good one: every effect read, misidentification skipped.
  test::WriteText(s / "good.json",
                  "{\"effects\": [{\"name\": \"misidentification\", \"parameters\": {\"probability\": 0.2, \"sigma_m\": 0.01}},"
                  "{\"name\": \"noise_floor\", \"parameters\": {\"floor_m\": 2e-4}},"
                  "{\"name\": \"anisotropy_x\", \"parameters\": {\"sigma_x_m\": 3e-4}},"
                  "{\"name\": \"pixel_noise_scale\", \"parameters\": {\"scale\": 4.5}}]}");
  const CameraErrorModel m = ReadCameraErrorModel((s / "good.json").string());
  EXPECT_DOUBLE_EQ(m.pixel_noise_scale, 4.5);
  EXPECT_DOUBLE_EQ(m.floor_m, 2e-4);
  EXPECT_DOUBLE_EQ(m.anisotropy_m.x(), 3e-4);
  EXPECT_EQ(m.anisotropy_m.y(), 0);
}

// The rendered demo with the paper's camera: the camera alone in the paper's range (3.94 mm
// by the three-sigma rule), its NEES in the band (the tracker reports the model), and the
// reductions those of the no-render prediction of the same model.
TEST(CameraErrorModel, DemoWithPaperCameraMatchesPrediction) {
  const fs::path s = test::ScratchDir("camera_model_demo");
  DemoOptions o;
  o.out = s / "demo";
  o.points = 12;
  o.iso9283 = false;
  o.quiet = true;
  o.threads = 2;
  o.camera_model = PaperCameraErrorModel();
  const DemoResult r = RunDemo(o, {});
  ASSERT_EQ(r.lab.summary.size(), 4u);
  const auto& cam = r.lab.summary[0];
  EXPECT_EQ(cam.name, "camera");
  EXPECT_EQ(cam.points, 12);
  EXPECT_GT(cam.position_3sigma_m, 1.5e-3);
  EXPECT_LT(cam.position_3sigma_m, 6e-3);
  EXPECT_GT(cam.mean_nees, cam.nees_band_lo);
  EXPECT_LT(cam.mean_nees, cam.nees_band_hi);
  EXPECT_NE(r.paper_report.find("paper 38.2 %"), std::string::npos);
  EXPECT_NE(test::ReadAll(s / "demo" / "camera_model.txt").find("paper: pixel noise x11.08"), std::string::npos);

  LabOptions lo;
  lo.points = 12;
  const LabScenario lab = MakeLabScenario(lo);
  FovMapOptions mo;
  mo.noise.render = lab.vision.render;
  mo.threads = 2;
  const std::vector<FovMapPoint> centre = PredictFovPoints(lab.vision.rig, lab.vision.target, mo, {lo.sphere_centre_rig});
  ASSERT_TRUE(centre[0].prediction.trackable);
  const std::vector<LabReduction> pred = PredictLabReductions(PaperCameraErrorModel(), centre[0].prediction.cov, 5, 12, 0);
  ASSERT_EQ(pred.size(), 2u);
  const LabReduction& p = pred[1];
  EXPECT_NEAR(cam.position_3sigma_m, p.camera_3sigma_m, 0.5 * p.camera_3sigma_m);
  for (const auto& [m, predicted, predicted_sd] :
       {std::tuple<int, double, double>{2, p.moifa_reduction, p.moifa_reduction_sd}, {3, p.kf_reduction, p.kf_reduction_sd}}) {
    const double red = 1 - r.lab.summary[m].position_3sigma_m / cam.position_3sigma_m;
    const double sd = std::hypot(r.reduction_sd[m], predicted_sd);
    EXPECT_NEAR(red, predicted, 4 * sd + 0.01) << r.lab.summary[m].name;
  }
}

}  // namespace
}  // namespace mcms
