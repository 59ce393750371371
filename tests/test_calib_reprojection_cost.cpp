// The rig calibration's cost function against numeric derivatives (ceres::GradientChecker)
// for every lens model it calibrates, with and without extrinsics and board warp; its
// residual against CameraModel::Project; and a deliberately wrong Jacobian that the
// check must catch (so the check can fail). Also mrcal's optimization_inputs encoding
// blocks (base85, .npy) against the bytes Python writes.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <ceres/gradient_checker.h>

#include "calib/mrcal_optimization_inputs.h"
#include "calib/reprojection_cost.h"
#include "tests/test_util.h"
#include "core/error.h"
#include "vision/camera_model.h"

namespace mcms {
namespace {

// Realistic intrinsics per model: 1280x960, f 900 px, moderate distortion.
std::vector<double> Intrinsics(const std::string& lensmodel) {
  std::vector<double> k = {900.0, 905.0, 641.0, 479.0};
  const std::vector<double> d = {-0.21, 0.08, 0.0012, -0.0007, -0.015, 0.02, -0.01, 0.004, 0.001, -0.0008, 0.0006, 0.0003};
  const int n = lensmodel == "LENSMODEL_PINHOLE" ? 0
                : lensmodel == "LENSMODEL_OPENCV4" ? 4
                : lensmodel == "LENSMODEL_OPENCV5" ? 5
                : lensmodel == "LENSMODEL_OPENCV8" ? 8
                                                   : 12;
  k.insert(k.end(), d.begin(), d.begin() + n);
  return k;
}

struct Case {
  std::string lensmodel;
  bool extrinsics;
  bool warp;
};

const ceres::NumericDiffOptions kCentral = [] {
  ceres::NumericDiffOptions o;
  o.relative_step_size = 1e-6;
  return o;
}();
// Relative agreement between analytic and central-difference Jacobians. Central
// differences with step 1e-6 agree to about 1e-8 on the large entries; the smallest
// (e.g. d v / d k6 = -2.4e-7 px at this point) carry about 1e-6 relative rounding noise
// (measured worst: 1.4e-6), so 1e-5. A 1 % error is caught (CheckerCatchesAWrongJacobian).
constexpr double kRelativePrecision = 1e-5;

const std::vector<const ceres::Manifold*>* kNoManifolds = nullptr;

// Parameters: the board 0.8 m in front of the rig, tilted; camera 0.2 m to the side.
struct Params {
  std::vector<double> intrinsics;
  double rt_rig_board[6] = {0.3, -0.2, 0.1, -0.15, -0.1, 0.8};
  double rt_cam_rig[6] = {0.02, -0.05, 0.01, -0.2, 0.003, 0.01};
  double warp[2] = {0.0012, -0.0007};
  std::vector<double*> Blocks(const Case& c) {
    std::vector<double*> b = {intrinsics.data(), rt_rig_board};
    if (c.extrinsics) b.push_back(rt_cam_rig);
    if (c.warp) b.push_back(warp);
    return b;
  }
};

TEST(CalibReprojectionCost, AnalyticJacobiansMatchNumericDerivatives) {
  const Vec3 points[] = {{0.0, 0.0, 0.0}, {0.24, 0.0, 0.0}, {0.12, 0.09, 0.0}, {0.0, 0.18, 0.0}, {0.24, 0.18, 0.0}};
  const Eigen::Vector2d shapes[] = {{0.0, 0.0}, {0.0, 0.0}, {1.0, 1.0}, {0.0, 0.0}, {0.0, 0.0}};
  int probes = 0;
  for (const std::string lens : {"LENSMODEL_PINHOLE", "LENSMODEL_OPENCV4", "LENSMODEL_OPENCV5", "LENSMODEL_OPENCV8",
                                 "LENSMODEL_OPENCV12"})
    for (bool ext : {false, true})
      for (bool warp : {false, true}) {
        const Case c{lens, ext, warp};
        Params p;
        p.intrinsics = Intrinsics(lens);
        for (size_t i = 0; i < std::size(points); ++i) {
          SCOPED_TRACE(lens + (ext ? " with extrinsics" : "") + (warp ? " with warp" : "") + ", point " +
                       std::to_string(i));
          // Weight 1.7: the weight must scale every block.
          const Eigen::Vector2d shape = i == 2 ? shapes[2] : Eigen::Vector2d(0.5, 0.75);
          ReprojectionCost cost(lens, points[i], Vec2(600.0, 400.0), 1.7, ext,
                                warp ? std::optional<Eigen::Vector2d>(shape) : std::nullopt);
          ceres::GradientChecker checker(&cost, kNoManifolds, kCentral);
          ceres::GradientChecker::ProbeResults results;
          const std::vector<double*> blocks = p.Blocks(c);
          EXPECT_TRUE(checker.Probe(blocks.data(), kRelativePrecision, &results)) << results.error_log;
          EXPECT_LT(results.maximum_relative_error, kRelativePrecision);
          ++probes;
        }
      }
  EXPECT_EQ(probes, 5 * 2 * 2 * 5);
}

TEST(CalibReprojectionCost, ResidualIsTheCameraModelsProjection) {
  for (const std::string lens : {"LENSMODEL_OPENCV5", "LENSMODEL_OPENCV8"}) {
    Params p;
    p.intrinsics = Intrinsics(lens);
    const Case c{lens, true, false};
    const Vec3 P(0.12, 0.06, 0.0);
    const Vec2 q_obs(610.0, 380.0);
    const double weight = 0.8;
    ReprojectionCost cost(lens, P, q_obs, weight, true, std::nullopt);
    Vec2 r;
    const std::vector<double*> blocks = p.Blocks(c);
    ASSERT_TRUE(cost.Evaluate(blocks.data(), r.data(), nullptr));
    const Pose T = Pose::FromRt(p.rt_cam_rig) * Pose::FromRt(p.rt_rig_board);
    const CameraModel cam(lens, p.intrinsics, 1280, 960);
    const Vec2 expected = weight * (cam.Project(T * P) - q_obs);
    EXPECT_NEAR(r.x(), expected.x(), 1e-9);
    EXPECT_NEAR(r.y(), expected.y(), 1e-9);
  }
}

// A cost whose board-pose Jacobian is 1 % off: the checker must reject it.
class SkewedCost final : public ceres::CostFunction {
 public:
  explicit SkewedCost(const ReprojectionCost& inner) : inner_(inner) {
    set_num_residuals(2);
    *mutable_parameter_block_sizes() = inner.parameter_block_sizes();
  }
  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    if (!inner_.Evaluate(params, residuals, jacobians)) return false;
    if (jacobians && jacobians[1])
      for (int k = 0; k < 12; ++k) jacobians[1][k] *= 1.01;
    return true;
  }

 private:
  const ReprojectionCost& inner_;
};

TEST(CalibReprojectionCost, CheckerCatchesAWrongJacobian) {
  Params p;
  p.intrinsics = Intrinsics("LENSMODEL_OPENCV8");
  const ReprojectionCost inner("LENSMODEL_OPENCV8", Vec3(0.1, 0.1, 0.0), Vec2(600.0, 400.0), 1.0, false, std::nullopt);
  const SkewedCost skewed(inner);
  ceres::GradientChecker checker(&skewed, kNoManifolds, kCentral);
  ceres::GradientChecker::ProbeResults results;
  const std::vector<double*> blocks = p.Blocks(Case{"LENSMODEL_OPENCV8", false, false});
  EXPECT_FALSE(checker.Probe(blocks.data(), kRelativePrecision, &results));
  EXPECT_GT(results.maximum_relative_error, 1e-3);
}

TEST(CalibReprojectionCost, RefusesModelsWithoutDenseGradients) {
  EXPECT_THROW(ReprojectionCost("LENSMODEL_NOSUCH", Vec3::Zero(), Vec2::Zero(), 1.0, false, std::nullopt), InputError);
  EXPECT_THROW(ReprojectionCost("LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=100", Vec3::Zero(),
                                Vec2::Zero(), 1.0, false, std::nullopt),
               InputError);
}

// Python: base64.b85encode(b'hello') == b'Xk~0{Zv'; of bytes 00 01 02 03 ff fe fd: b'009C6|Ni{'.
TEST(CalibMrcalOptimizationInputs, Base85IsPythons) {
  EXPECT_EQ(mrcal_io::B85Encode("hello"), "Xk~0{Zv");
  EXPECT_EQ(mrcal_io::B85Encode(std::string("\x00\x01\x02\x03\xff\xfe\xfd", 7)), "009C6|Ni{");
  EXPECT_EQ(mrcal_io::B85Encode(""), "");
}

// A deflate bomb (a member stating 3.75 GB inflated in a few bytes) is refused before
// anything is allocated (core/limits.h kMaxInflatedBytes; issue 37: 11.8 GB RSS, 68 s).
TEST(CalibMrcalOptimizationInputs, AZipMemberStatingGigabytesIsRefused) {
  std::string zip = mrcal_io::Zip({{"a.npy", mrcal_io::Npy("<f8", {2}, std::string(16, '\0'))}});
  ASSERT_EQ(mrcal_io::Unzip(zip).size(), 1u);
  const size_t cd = zip.find("PK\x01\x02");
  ASSERT_NE(cd, std::string::npos);
  for (int k = 0; k < 4; ++k) zip[cd + 24 + k] = static_cast<char>(k == 3 ? 0xF0 : 0x00);  // usize 0xF0000000
  const std::string e = test::ErrorOf([&] { mrcal_io::Unzip(zip); });
  EXPECT_NE(e.find("zip member a.npy states 4026531840 bytes inflated"), std::string::npos) << e;
  EXPECT_NE(e.find("a corrupt or hostile archive"), std::string::npos) << e;
}

// numpy's .npy 1.0: magic, version, little-endian header length, a dict literal padded
// with spaces to a multiple of 64 bytes and ended by a newline (numpy reads any such
// header; the app test has numpy read whole files).
TEST(CalibMrcalOptimizationInputs, NpyHeaderIsNumpys) {
  const std::string npy = mrcal_io::Npy("<f8", {2, 3}, std::string(48, '\0'));
  EXPECT_EQ(npy.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
  const size_t header_len = static_cast<unsigned char>(npy[8]) + 256u * static_cast<unsigned char>(npy[9]);
  EXPECT_EQ((10 + header_len) % 64, 0u);
  EXPECT_EQ(npy.size(), 10 + header_len + 48);
  const std::string dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }";
  EXPECT_EQ(npy.substr(10, dict.size()), dict);
  EXPECT_EQ(npy[10 + header_len - 1], '\n');
  EXPECT_NE(mrcal_io::Npy("<f8", {2}, std::string(16, '\0')).find("'shape': (2,)"), std::string::npos);
  EXPECT_NE(mrcal_io::Npy("|b1", {}, std::string(1, '\1')).find("'shape': ()"), std::string::npos);
}

}  // namespace
}  // namespace mcms
