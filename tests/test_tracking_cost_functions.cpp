// Every Ceres cost function of tracking/ against numeric derivatives (Ceres'
// GradientChecker): the pose bundle adjustment's ball reprojection, through several lens
// models, about several linearization poses and increments.
#include <gtest/gtest.h>

#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "core/random.h"
#include "tracking/pose_refinement.h"
#include "vision/triangulation.h"

namespace mcms {
namespace {

// Ceres 2.1 has two constructors taking a pointer; name the Manifold one.
const std::vector<const ceres::Manifold*>* kNoManifolds = nullptr;

// A camera 2 m above the origin looking down at it, slightly tilted.
Pose CameraPose() {
  const Vec3 c(0.3, -0.2, 2.0), look(0, 0, 0.3);
  const Vec3 z = (look - c).normalized();
  const Vec3 x = z.cross(Vec3::UnitY()).normalized();
  const Vec3 y = z.cross(x);
  Mat3 R_rig_cam;
  R_rig_cam << x, y, z;
  return Pose{R_rig_cam, c}.Inverse();
}

std::vector<CameraModel> Cameras(Rng& rng) {
  std::vector<CameraModel> cams;
  const Pose T = CameraPose();
  cams.emplace_back("LENSMODEL_PINHOLE", std::vector<double>{1200, 1180, 639.5, 511.5}, 1280, 1024, T);
  cams.emplace_back(
      "LENSMODEL_OPENCV8",
      std::vector<double>{900, 905, 641.2, 509.8, -0.12, 0.03, 0.0004, -0.0002, 0.002, 0.01, -0.003, 0.001}, 1280, 1024,
      T);
  std::vector<double> splined = {700, 702, 640.3, 511.1};
  for (int i = 0; i < 2 * 8 * 6; ++i) splined.push_back(rng.Normal(0, 0.01));
  cams.emplace_back("LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=8_Ny=6_fov_x_deg=100", splined, 1280, 1024, T);
  return cams;
}

struct Probe {
  bool ok = false;
  double max_relative_error = 0;
  std::string log;
};

// Relative agreement required of every Jacobian entry: 1e-7 (the pinhole and OpenCV models
// agree to 1e-8). For the splined model an entry that is small beside its row (a few px/m
// next to 2000 px/m) differs from central differences by ~3e-5 px/m, 1e-8 of the row,
// so it is held to 1e-4, the criterion of tests/test_vision_camera_model.cpp. A real
// derivative error (a sign, a missing term, a factor) is far larger: the last test shows a
// 0.1 % error caught.
double RelativePrecision(const CameraModel& cam) {
  return cam.LensModelName().starts_with("LENSMODEL_SPLINED") ? 1e-4 : 1e-7;
}

Probe Check(const ceres::CostFunction& cost, const Vec6& delta, double relative_precision) {
  ceres::NumericDiffOptions nd;
  ceres::GradientChecker checker(&cost, kNoManifolds, nd);
  const double* params[1] = {delta.data()};
  ceres::GradientChecker::ProbeResults results;
  Probe p;
  p.ok = checker.Probe(params, relative_precision, &results);
  p.max_relative_error = results.maximum_relative_error;
  p.log = results.error_log;
  return p;
}

TEST(CostFunctions, BallReprojectionMatchesNumericDerivatives) {
  Rng rng(11);
  const std::vector<CameraModel> cams = Cameras(rng);
  // The target's five balls, about 0.1 m from its origin.
  const std::vector<Vec3> balls = {Vec3(0, 0, 0), Vec3(0.1, 0, 0.02), Vec3(0, 0.12, -0.01), Vec3(-0.08, 0.05, 0.03),
                                   Vec3(0.04, -0.1, 0.05)};
  Mat2 cov;
  cov << 0.04, 0.01, 0.01, 0.09;  // correlated pixel noise: W is not diagonal
  const Mat2 W = WhiteningOf(cov);
  int checked = 0;
  for (const CameraModel& cam : cams) {
    double worst = 0;
    for (int trial = 0; trial < 6; ++trial) {
      // Linearization poses across the view, including strongly rotated targets.
      const Pose T0{ExpSO3(Vec3(rng.Normal(0, 0.8), rng.Normal(0, 0.8), rng.Normal(0, 0.8))),
                    Vec3(rng.Uniform(-0.4, 0.4), rng.Uniform(-0.3, 0.3), rng.Uniform(0.0, 0.6))};
      for (const Vec3& b : balls) {
        const Vec2 q = cam.Project(cam.T_cam_rig() * (T0 * b)) + Vec2(rng.Normal(0, 0.5), rng.Normal(0, 0.5));
        std::unique_ptr<ceres::CostFunction> cost(NewBallReprojectionCost(cam, T0, b, q, W));
        ASSERT_EQ(cost->num_residuals(), 2);
        ASSERT_EQ(cost->parameter_block_sizes(), std::vector<int32_t>{6});
        // At the linearization point (what RefinePose's covariance uses) and at
        // increments up to 0.3 rad / 3 cm (what its iterations visit).
        for (double scale : {0.0, 1e-3, 0.1, 0.3}) {
          Vec6 delta;
          for (int i = 0; i < 3; ++i) delta[i] = rng.Normal(0, scale);
          for (int i = 3; i < 6; ++i) delta[i] = rng.Normal(0, 0.1 * scale);
          const Probe p = Check(*cost, delta, RelativePrecision(cam));
          EXPECT_TRUE(p.ok) << cam.LensModelName() << ", trial " << trial << ", scale " << scale << "\n" << p.log;
          worst = std::max(worst, p.max_relative_error);
          ++checked;
        }
      }
    }
    RecordProperty("max_relative_error " + cam.LensModelName().substr(0, 30), std::to_string(worst));
    std::printf("%s: worst relative error %.2g\n", cam.LensModelName().c_str(), worst);
  }
  EXPECT_EQ(checked, 3 * 6 * 5 * 4);
}

// The checker itself must catch a wrong derivative of the size that matters (0.1 %), so a
// passing check above means something.
class ScaledJacobian : public ceres::CostFunction {
 public:
  ScaledJacobian(ceres::CostFunction* inner, double scale) : inner_(inner), scale_(scale) {
    set_num_residuals(inner->num_residuals());
    *mutable_parameter_block_sizes() = inner->parameter_block_sizes();
  }
  bool Evaluate(double const* const* p, double* r, double** J) const override {
    if (!inner_->Evaluate(p, r, J)) return false;
    if (J && J[0])
      for (int i = 0; i < num_residuals() * parameter_block_sizes()[0]; ++i) J[0][i] *= scale_;
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> inner_;
  double scale_;
};

TEST(CostFunctions, TheCheckRejectsAJacobianOffByATenthOfAPercent) {
  Rng rng(12);
  const std::vector<CameraModel> cams = Cameras(rng);
  const Pose T0{ExpSO3(Vec3(0.2, -0.1, 0.3)), Vec3(0.1, 0.05, 0.3)};
  const Vec3 b(0.1, 0, 0.02);
  const Vec2 q = cams[1].Project(cams[1].T_cam_rig() * (T0 * b));
  const ScaledJacobian wrong(NewBallReprojectionCost(cams[1], T0, b, q, Mat2::Identity()), 1.001);
  const Probe p = Check(wrong, Vec6::Zero(), 1e-4);
  EXPECT_FALSE(p.ok);
  EXPECT_GT(p.max_relative_error, 1e-4);
}

}  // namespace
}  // namespace mcms
