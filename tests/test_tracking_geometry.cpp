// Triangulation, identification and pose refinement on exact projections with known
// Gaussian pixel noise: the estimators must reach the bound they report.
#include <gtest/gtest.h>

#include <boost/math/distributions/chi_squared.hpp>

#include "core/random.h"
#include "tests/test_util.h"
#include "tracking/identify.h"
#include "tracking/pose_refinement.h"
#include "tracking/target.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms {
namespace {

// Four cameras above a 1 x 0.8 x 1 m volume looking at its centre (as the paper's rig).
CameraRig TestRig() {
  CameraRig rig;
  const Vec3 look(0, 0, 0.5);
  int i = 0;
  for (const Vec3& c : {Vec3(0.8, 0.7, 2.2), Vec3(-0.8, 0.7, 2.2), Vec3(-0.8, -0.7, 2.2), Vec3(0.8, -0.7, 2.2)}) {
    const Vec3 z = (look - c).normalized();
    const Vec3 x = z.cross(Vec3::UnitZ()).normalized();
    const Vec3 y = z.cross(x);
    Mat3 R_rig_cam;
    R_rig_cam << x, y, z;
    const Pose T_cam_rig = Pose{R_rig_cam, c}.Inverse();
    rig.cameras.emplace_back(
        "LENSMODEL_OPENCV8",
        std::vector<double>{900, 900, 639.5, 511.5, -0.1, 0.02, 0.0002, -0.0001, 0.001, 0.0, 0.0, 0.0}, 1280, 1024,
        T_cam_rig);
    rig.names.push_back("cam" + std::to_string(i++));
  }
  return rig;
}

double Chi2Quantile(double dof, double p) {
  return boost::math::quantile(boost::math::chi_squared(dof), p);
}

TEST(Triangulation, ReachesTheCramerRaoBoundAndCorrectsSphereBias) {
  const CameraRig rig = TestRig();
  Rng rng(7);
  const double sigma_px = 0.05, radius = 0.0125;
  double err2 = 0, bound2 = 0, nees = 0;
  const int n = 400;
  for (int k = 0; k < n; ++k) {
    const Vec3 p(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.4, 0.4), rng.Uniform(0, 1));
    std::vector<std::vector<ImagePoint>> pts(rig.size());
    std::vector<PointObservation> obs;
    for (size_t c = 0; c < rig.size(); ++c) {
      const Vec3 pc = rig.cameras[c].T_cam_rig() * p;
      // What a centroiding detector measures: the sphere image's centroid, plus noise.
      const Vec2 q = SphereImageCentroid(rig.cameras[c], pc, radius, 256) +
                     Vec2(rng.Normal(0, sigma_px), rng.Normal(0, sigma_px));
      pts[c].push_back({q, Mat2::Identity() * sigma_px * sigma_px});
      obs.push_back({static_cast<int>(c), 0});
    }
    TriangulationOptions o;
    o.sphere_radius_m = radius;
    const auto t = TriangulateNView(rig, pts, obs, o);
    ASSERT_TRUE(t.has_value());
    const Vec3 e = t->p_rig - p;
    err2 += e.squaredNorm();
    bound2 += t->cov.trace();
    nees += e.dot(t->cov.inverse() * e);
  }
  const double ratio = std::sqrt(err2 / bound2);
  RecordProperty("rms_over_crb", std::to_string(ratio));
  EXPECT_NEAR(ratio, 1.0, 0.1) << "3-D RMS error over the Cramer-Rao bound";
  EXPECT_GT(nees, Chi2Quantile(3 * n, 0.025));
  EXPECT_LT(nees, Chi2Quantile(3 * n, 0.975));
}

TEST(Triangulation, WithoutBiasCorrectionTheEstimateIsBiased) {
  const CameraRig rig = TestRig();
  const double radius = 0.0125;
  const Vec3 p(0.45, 0.35, 0.05);  // a corner of the volume: far off-axis in every camera
  std::vector<std::vector<ImagePoint>> pts(rig.size());
  std::vector<PointObservation> obs;
  for (size_t c = 0; c < rig.size(); ++c) {
    pts[c].push_back({SphereImageCentroid(rig.cameras[c], rig.cameras[c].T_cam_rig() * p, radius, 256),
                      Mat2::Identity() * 1e-4});
    obs.push_back({static_cast<int>(c), 0});
  }
  TriangulationOptions with, without;
  with.sphere_radius_m = radius;
  const double e_with = (TriangulateNView(rig, pts, obs, with)->p_rig - p).norm();
  const double e_without = (TriangulateNView(rig, pts, obs, without)->p_rig - p).norm();
  EXPECT_LT(e_with, 2e-6);
  EXPECT_GT(e_without, 10 * e_with);
}

struct Scene {
  std::vector<std::vector<ImagePoint>> pts;
};

Scene Observe(const CameraRig& rig, const std::vector<Vec3>& balls_rig, double radius, double sigma, Rng& rng) {
  Scene s;
  s.pts.resize(rig.size());
  for (size_t c = 0; c < rig.size(); ++c)
    for (const Vec3& b : balls_rig) {
      const Vec3 pc = rig.cameras[c].T_cam_rig() * b;
      if (!rig.cameras[c].Sees(pc, 5)) continue;
      s.pts[c].push_back({SphereImageCentroid(rig.cameras[c], pc, radius, 256) +
                              Vec2(rng.Normal(0, sigma), rng.Normal(0, sigma)),
                          Mat2::Identity() * sigma * sigma});
    }
  return s;
}

Pose RandomPose(Rng& rng) {
  const Vec3 r(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5), rng.Uniform(-3, 3));
  return {ExpSO3(r), Vec3(rng.Uniform(-0.3, 0.3), rng.Uniform(-0.25, 0.25), rng.Uniform(0.3, 0.7))};
}

TEST(MatchingAndIdentification, FindsTheTargetAmongSpuriousPointsWithOneBallMissing) {
  const CameraRig rig = TestRig();
  const Target target = Target::Default();
  Rng rng(11);
  int correct = 0;
  const int n = 60;
  double min_margin = 1e300;
  for (int k = 0; k < n; ++k) {
    const Pose T = RandomPose(rng);
    std::vector<Vec3> balls;
    for (size_t b = 0; b < target.balls_target.size(); ++b)
      if (b != static_cast<size_t>(k % 5)) balls.push_back(T * target.balls_target[b]);  // one ball missing
    Scene s = Observe(rig, balls, target.ball_radius, 0.1, rng);
    // Spurious reflections: single-camera blobs, and two extra real points nearby.
    for (auto& cam : s.pts)
      cam.push_back({Vec2(rng.Uniform(50, 1200), rng.Uniform(50, 950)), Mat2::Identity() * 0.01});
    Scene extra = Observe(rig, {T * Vec3(0.3, 0.2, 0.1), T * Vec3(-0.25, 0.1, -0.2)}, 0.0125, 0.1, rng);
    for (size_t c = 0; c < rig.size(); ++c) s.pts[c].insert(s.pts[c].end(), extra.pts[c].begin(), extra.pts[c].end());
    MatchingOptions mo;
    mo.triangulation.sphere_radius_m = target.ball_radius;
    const auto points = MatchAndTriangulate(rig, s.pts, mo);
    const auto id = IdentifyTarget(target, points);
    ASSERT_TRUE(id.has_value());
    EXPECT_EQ(id->balls_found, 4);
    const bool ok = (id->T_rig_target.t - T.t).norm() < 1e-3 && RotationAngle(id->T_rig_target.R, T.R) < 1e-2;
    correct += ok;
    min_margin = std::min(min_margin, id->margin);
  }
  EXPECT_EQ(correct, n);
  EXPECT_GT(min_margin, 25.0) << "identification margin (chi-square) of the worst frame";
}

TEST(PoseRefinement, CovarianceIsHonestAndReachesTheBound) {
  const CameraRig rig = TestRig();
  const Target target = Target::Default();
  Rng rng(1);
  const double sigma = 0.08;
  const int n = 500;
  double nees = 0;
  for (int k = 0; k < n; ++k) {
    const Pose T = RandomPose(rng);
    std::vector<BallObservation> obs;
    for (size_t c = 0; c < rig.size(); ++c)
      for (size_t b = 0; b < target.balls_target.size(); ++b) {
        const Vec3 pc = rig.cameras[c].T_cam_rig() * (T * target.balls_target[b]);
        obs.push_back({static_cast<int>(c), static_cast<int>(b),
                       SphereImageCentroid(rig.cameras[c], pc, target.ball_radius, 256) +
                           Vec2(rng.Normal(0, sigma), rng.Normal(0, sigma)),
                       Mat2::Identity() * sigma * sigma});
      }
    // Start well away from the truth.
    Vec6 d;
    for (int i = 0; i < 6; ++i) d[i] = rng.Normal(0, i < 3 ? 0.05 : 0.01);
    const PoseRefinement r = RefinePose(rig, target, BoxPlus(T, d), obs);
    ASSERT_TRUE(r.converged);
    const Vec6 e = BoxMinus(r.T_rig_target, T);
    nees += e.dot(r.cov.inverse() * e);
  }
  EXPECT_GT(nees, Chi2Quantile(6 * n, 0.025));
  EXPECT_LT(nees, Chi2Quantile(6 * n, 0.975));
}

TEST(PoseRefinement, DropsAnOutlierObservation) {
  const CameraRig rig = TestRig();
  const Target target = Target::Default();
  Rng rng(5);
  const Pose T = RandomPose(rng);
  std::vector<BallObservation> obs;
  for (size_t c = 0; c < rig.size(); ++c)
    for (size_t b = 0; b < target.balls_target.size(); ++b) {
      const Vec3 pc = rig.cameras[c].T_cam_rig() * (T * target.balls_target[b]);
      obs.push_back({static_cast<int>(c), static_cast<int>(b),
                     SphereImageCentroid(rig.cameras[c], pc, target.ball_radius, 256), Mat2::Identity() * 0.01});
    }
  obs[7].q += Vec2(4.0, -3.0);
  const PoseRefinement r = RefinePose(rig, target, T, obs);
  ASSERT_EQ(r.dropped.size(), 1u);
  EXPECT_EQ(r.dropped[0].camera, obs[7].camera);
  EXPECT_LT((r.T_rig_target.t - T.t).norm(), 1e-6);
}

}  // namespace
}  // namespace mcms
