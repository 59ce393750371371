// ISO 9283 characteristics on small examples computed by hand (calib/iso9283.h).
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>

#include "calib/iso9283.h"
#include "core/error.h"

namespace mcms {
namespace {

Pose At(double x, double y, double z, double rz = 0.0) {
  return Pose{Eigen::AngleAxisd(rz, Vec3::UnitZ()).toRotationMatrix(), Vec3(x, y, z)};
}

TEST(Iso9283, PoseAccuracyAndRepeatabilityByHand) {
  // Attained positions (1.5,0,0), (-0.5,0,0), (0.5,2,0), (0.5,-2,0): barycentre (0.5,0,0),
  // AP = 0.5; l = 1, 1, 2, 2, l_bar = 1.5, S_l = sqrt(4 * 0.25 / 3) = 1/sqrt(3),
  // RP = 1.5 + 3/sqrt(3) = 1.5 + sqrt(3).
  // Rotations about z of 0.01, 0.03, 0.02, 0.02 rad: AP_c = 0.02,
  // S_c = sqrt((1e-4 + 1e-4) / 3), RP_c = 3 S_c.
  const std::vector<Pose> att = {At(1.5, 0, 0, 0.01), At(-0.5, 0, 0, 0.03), At(0.5, 2, 0, 0.02), At(0.5, -2, 0, 0.02)};
  const PoseCharacteristics c = PoseAccuracyRepeatability(At(0, 0, 0), att);
  EXPECT_EQ(c.n, 4);
  EXPECT_NEAR(c.AP_p, 0.5, 1e-15);
  EXPECT_NEAR(c.AP_xyz.x(), 0.5, 1e-15);
  EXPECT_NEAR(c.AP_xyz.y(), 0.0, 1e-15);
  EXPECT_NEAR(c.l_bar, 1.5, 1e-15);
  EXPECT_NEAR(c.S_l, 1.0 / std::sqrt(3.0), 1e-15);
  EXPECT_NEAR(c.RP_l, 1.5 + std::sqrt(3.0), 1e-14);
  EXPECT_NEAR(c.AP_c, 0.02, 1e-15);
  EXPECT_NEAR(c.RP_c, 3.0 * std::sqrt(2e-4 / 3.0), 1e-15);
  EXPECT_NEAR(c.AP_a, 0.0, 1e-15);
  EXPECT_NEAR(c.RP_b, 0.0, 1e-15);
  EXPECT_THROW(PoseAccuracyRepeatability(At(0, 0, 0), {At(1, 0, 0)}), InputError);
}

TEST(Iso9283, OrientationIsMeasuredFromTheCommandedPose) {
  // Commanded orientation 90 deg about x; attained 90 deg about x, then 0.01 rad about
  // base y: AP_b = 0.01 in the base frame, the other angles 0.
  const Mat3 Rc = Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()).toRotationMatrix();
  const Mat3 Ra = Eigen::AngleAxisd(0.01, Vec3::UnitY()).toRotationMatrix() * Rc;
  const auto c = PoseAccuracyRepeatability(Pose{Rc, Vec3::Zero()}, {Pose{Ra, Vec3::Zero()}, Pose{Ra, Vec3::Zero()}});
  EXPECT_NEAR(c.AP_b, 0.01, 1e-12);
  EXPECT_NEAR(c.AP_a, 0.0, 1e-12);
  EXPECT_NEAR(c.AP_c, 0.0, 1e-12);
  EXPECT_NEAR(c.RP_b, 0.0, 1e-12);
}

TEST(Iso9283, DistanceAccuracyAndRepeatabilityByHand) {
  // D_c = 1; attained distances 1.1, 0.9, 1.0, 1.2 along x: D_bar = 1.05, AD = 0.05,
  // S_D = sqrt((0.0025 + 0.0225 + 0.0025 + 0.0225) / 3), RD = 3 S_D.
  const std::vector<Pose> a1 = {At(0, 0, 0), At(0, 0, 0), At(0.1, 0, 0), At(0, 0, 0)};
  const std::vector<Pose> a2 = {At(1.1, 0, 0), At(0.9, 0, 0), At(1.1, 0, 0), At(1.2, 0, 0)};
  const DistanceCharacteristics d = DistanceAccuracyRepeatability(At(0, 0, 0), At(1, 0, 0), a1, a2);
  EXPECT_NEAR(d.D_c, 1.0, 1e-15);
  EXPECT_NEAR(d.D_bar, 1.05, 1e-15);
  EXPECT_NEAR(d.AD_p, 0.05, 1e-15);
  EXPECT_NEAR(d.S_D, std::sqrt(0.05 / 3.0), 1e-15);
  EXPECT_NEAR(d.RD_p, 3.0 * std::sqrt(0.05 / 3.0), 1e-15);
  // Per axis: D_x = x1 - x2 = -1.1, -0.9, -1.0, -1.2 vs D_cx = -1: AD_x = -0.05.
  EXPECT_NEAR(d.AD_xyz.x(), -0.05, 1e-15);
  EXPECT_NEAR(d.RD_xyz.x(), 3.0 * std::sqrt(0.05 / 3.0), 1e-15);
  EXPECT_THROW(DistanceAccuracyRepeatability(At(0, 0, 0), At(1, 0, 0), a1, {At(1, 0, 0)}), InputError);
}

TEST(Iso9283, PathAccuracyAndRepeatabilityOnAStraightLine) {
  // Commanded: x from 0 to 1 at y = z = 0. Runs at z = 0.2 and y = +0.1, -0.1, 0:
  // barycentre at (x, 0, 0.2): AT = 0.2; l = 0.1, 0.1, 0: l_bar = 0.2/3,
  // S_l = sqrt(((0.1 - 0.2/3)^2 * 2 + (0.2/3)^2) / 2), RT = l_bar + 3 S_l.
  std::vector<Vec3> cmd;
  std::vector<std::vector<Vec3>> runs(3);
  for (int k = 0; k <= 10; ++k) cmd.push_back(Vec3(0.1 * k, 0, 0));
  const double ys[3] = {0.1, -0.1, 0.0};
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k <= 20; ++k) runs[r].push_back(Vec3(-0.05 + 0.055 * k, ys[r], 0.2));
  const PathCharacteristics p = PathAccuracyRepeatability(cmd, runs);
  ASSERT_EQ(p.AT_i.size(), 11u);
  const double lbar = 0.2 / 3, S = std::sqrt((2 * std::pow(0.1 - lbar, 2) + lbar * lbar) / 2);
  EXPECT_NEAR(p.AT_p, 0.2, 1e-12);
  EXPECT_NEAR(p.RT_p, lbar + 3 * S, 1e-12);
  for (double a : p.AT_i) EXPECT_NEAR(a, 0.2, 1e-12);
  // Issue 53: a run in millimetres against a commanded path in metres is named as such,
  // not as a run that "never crosses the plane".
  {
    auto mm = runs;
    for (Vec3& p : mm[2]) p *= 1000.0;
    std::string e;
    try {
      PathAccuracyRepeatability(cmd, mm);
    } catch (const InputError& x) {
      e = x.what();
    }
    EXPECT_NE(e.find("attained run 3 is 1100 times as long as the commanded path (millimetres under metre headers?)"),
              std::string::npos)
        << e;
  }
  // A run that stops short never crosses the last normal planes.
  runs[1].resize(5);
  EXPECT_THROW(PathAccuracyRepeatability(cmd, runs), InputError);
}

TEST(Iso9283, PathAccuracyOnACircle) {
  // Commanded circle of radius 1 (36 calculation points); attained circles of radius
  // 1.01 and 1.03 finely sampled: crossings in the normal (radial) planes lie at radius
  // 1.01 and 1.03 up to the chord sagitta (r (1 - cos(pi / 720)) < 1e-5), so AT = 0.02,
  // and l = 0.01 for both: RT = 0.01.
  std::vector<Vec3> cmd;
  for (int k = 0; k < 36; ++k) cmd.push_back(Vec3(std::cos(k * std::numbers::pi / 20), std::sin(k * std::numbers::pi / 20), 0));
  std::vector<std::vector<Vec3>> runs(2);
  for (int r = 0; r < 2; ++r)
    for (int k = -10; k < 740; ++k) {
      const double a = k * std::numbers::pi / 360, rad = r == 0 ? 1.01 : 1.03;
      runs[r].push_back(Vec3(rad * std::cos(a), rad * std::sin(a), 0));
    }
  const PathCharacteristics p = PathAccuracyRepeatability(cmd, runs);
  // Interior points: the central-difference direction of the polyline is the exact
  // tangent of the circle. The two end points use the one-sided chord (4.5 deg off), which
  // tilts their normal plane: 0.02 (1 / cos 4.5 deg - 1) = 6e-5 more.
  for (size_t i = 1; i + 1 < p.AT_i.size(); ++i) {
    EXPECT_NEAR(p.AT_i[i], 0.02, 2e-5) << i;
    EXPECT_NEAR(p.RT_i[i], 0.01, 2e-5) << i;
  }
  EXPECT_NEAR(p.AT_p, 0.02, 1e-4);
  EXPECT_NEAR(p.RT_p, 0.01, 1e-4);
}

}  // namespace
}  // namespace mcms
