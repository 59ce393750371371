// The per-pose precision prediction of the field-of-view map: the centre-noise table,
// the ball covariance against an independent Gauss-Newton computation, the pose
// covariance's scaling with the centre noise, and visibility.
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "tests/test_util.h"
#include "tracking/fov_prediction.h"

namespace mcms {
namespace {

// A pinhole camera at `centre` looking at `at`, with rig +z up in the image.
CameraModel LookAt(const Vec3& centre, const Vec3& at, double f = 900, int w = 1280, int h = 1024) {
  const Vec3 z = (at - centre).normalized();
  const Vec3 x = z.cross(Vec3::UnitZ()).normalized();
  const Vec3 y = z.cross(x);
  Pose T_rig_cam;
  T_rig_cam.R.col(0) = x;
  T_rig_cam.R.col(1) = y;
  T_rig_cam.R.col(2) = z;
  T_rig_cam.t = centre;
  return CameraModel("LENSMODEL_PINHOLE", {f, f, (w - 1) / 2.0, (h - 1) / 2.0}, w, h, T_rig_cam.Inverse());
}

CameraRig FourCameras() {
  CameraRig rig;
  const Vec3 at(0, 0, 0.5);
  for (const Vec3& c : {Vec3(0.8, 0.7, 2.2), Vec3(-0.8, 0.7, 2.2), Vec3(-0.8, -0.7, 2.2), Vec3(0.8, -0.7, 2.2)}) {
    rig.cameras.push_back(LookAt(c, at));
    rig.names.push_back("cam" + std::to_string(rig.names.size()));
  }
  return rig;
}

Target FiveBalls() {
  Target t;
  t.balls_target = {Vec3(0.000, 0.000, 0.000), Vec3(-0.095, 0.090, -0.090), Vec3(0.080, -0.010, -0.055),
                    Vec3(-0.055, -0.090, 0.030), Vec3(0.095, 0.060, -0.075)};
  return t;
}

TEST(CentroidCovarianceTable, InterpolatesAndRotates) {
  // Variances proportional to 1/b^2 (log-linear interpolation is exact for a power law).
  const std::vector<double> b{2, 4, 8}, r{1, 2};
  std::vector<double> vmaj, vmin;
  for (double bb : b)
    for (double rr : r) vmaj.push_back(rr * 0.01 / (bb * bb)), vmin.push_back(0.01 / (bb * bb));
  const CentroidCovarianceTable t(b, r, vmaj, vmin);
  const Vec2 v = t.Variances(std::sqrt(8.0), 1.0);
  EXPECT_NEAR(v.x(), 0.01 / 8, 1e-12);
  EXPECT_NEAR(v.y(), 0.01 / 8, 1e-12);
  Ellipse e;
  e.a = 8;
  e.b = 4;
  e.angle = std::numbers::pi / 2;  // major axis along y
  const Mat2 C = t(e);
  EXPECT_NEAR(C(1, 1), 2 * 0.01 / 16, 1e-12);
  EXPECT_NEAR(C(0, 0), 0.01 / 16, 1e-12);
  EXPECT_NEAR(C(0, 1), 0.0, 1e-15);
  EXPECT_THROW(CentroidCovarianceTable({2, 1}, {1}, {1, 1}, {1, 1}), InternalError);
}

// The ball covariance equals (sum J^T Sigma^-1 J)^-1 with J the numeric derivative of the
// projection of the ball centre (the sphere bias is held fixed by the estimator).
TEST(FovPrediction, BallCovarianceIsTheGaussNewtonBound) {
  const CameraRig rig = FourCameras();
  const Target target = FiveBalls();
  const double s2 = 0.02 * 0.02;
  const CentroidCovarianceFn iso = [s2](const Ellipse&) { return Mat2(Mat2::Identity() * s2); };
  Pose T;
  T.t = Vec3(0.1, -0.05, 0.4);
  const FovPointPrediction p = PredictFovPoint(rig, target, T, iso);
  ASSERT_TRUE(p.trackable);
  EXPECT_EQ(p.CamerasSeeing(), 4);
  EXPECT_EQ(p.observations, 20);
  for (size_t b = 0; b < target.balls_target.size(); ++b) {
    ASSERT_TRUE(p.balls[b].triangulated);
    const Vec3 X = T * target.balls_target[b];
    Mat3 H = Mat3::Zero();
    for (const auto& cam : rig.cameras) {
      const Eigen::MatrixXd J = test::NumericJacobian(
          [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return cam.Project(cam.T_cam_rig() * Vec3(x)); }, X, 1e-7);
      H += J.transpose() * J / s2;
    }
    const Mat3 C = H.inverse();
    EXPECT_LT((p.balls[b].cov - C).norm(), 1e-3 * C.norm()) << "ball " << b;
  }
  // The pose covariance scales with the centre variance.
  const CentroidCovarianceFn iso4 = [s2](const Ellipse&) { return Mat2(Mat2::Identity() * 4 * s2); };
  const FovPointPrediction p4 = PredictFovPoint(rig, target, T, iso4);
  ASSERT_TRUE(p4.trackable);
  EXPECT_LT((p4.cov - 4 * p.cov).norm(), 1e-6 * p4.cov.norm());
  // Position sigma of a few hundredths of a mm for 0.02 px at ~2 m with f = 900 px.
  const double sd = std::sqrt(p.cov.diagonal().tail<3>().sum());
  EXPECT_GT(sd, 5e-6);
  EXPECT_LT(sd, 1e-4);
}

TEST(FovPrediction, VisibilityAndBorders) {
  const CameraRig rig = FourCameras();
  const Target target = FiveBalls();
  const CentroidCovarianceFn iso = [](const Ellipse&) { return Mat2(Mat2::Identity() * 1e-4); };
  Pose T;
  T.t = Vec3(5.0, 5.0, 0.5);  // far outside every view
  const FovPointPrediction out = PredictFovPoint(rig, target, T, iso);
  EXPECT_FALSE(out.trackable);
  EXPECT_EQ(out.CamerasSeeing(), 0);
  EXPECT_TRUE(std::isnan(out.cov(0, 0)));
  // A ball image whose window reaches the border is not usable.
  const CameraModel& cam = rig.cameras[0];
  const auto ray = cam.Unproject(Vec2(3.0, 500.0));
  ASSERT_TRUE(ray.has_value());
  const Vec3 p_cam = *ray * 1.5;
  const BallImage edge = PredictBallImage(cam, cam.T_cam_rig().Inverse() * p_cam, 0.0125);
  EXPECT_FALSE(edge.in_front);  // the outline leaves the image
  const auto ray2 = cam.Unproject(Vec2(12.0, 500.0));
  const BallImage near_edge = PredictBallImage(cam, cam.T_cam_rig().Inverse() * (*ray2 * 1.5), 0.0125);
  EXPECT_TRUE(near_edge.in_front);
  EXPECT_FALSE(near_edge.usable);  // radius ~7.5 px + margin 3 px > 12 px
  const auto ray3 = cam.Unproject(Vec2(640.0, 500.0));
  const BallImage centre = PredictBallImage(cam, cam.T_cam_rig().Inverse() * (*ray3 * 1.5), 0.0125);
  EXPECT_TRUE(centre.usable);
  EXPECT_NEAR(centre.ellipse.b, 900 * 0.0125 / 1.5, 0.1);
}

}  // namespace
}  // namespace mcms
