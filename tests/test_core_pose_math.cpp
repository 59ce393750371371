// The pose math every covariance in the project rests on (core/pose_math.h): the tangent
// layout [dtheta; dp] with R = Exp(dtheta) R_hat, p = p_hat + dp. Round trips of
// BoxPlus/BoxMinus and Exp/Log, the left Jacobian and the covariance transform against
// central differences.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/pose_math.h"
#include "core/random.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

constexpr double kPi = std::numbers::pi;

Vec3 RandomVec3(Rng& rng, double scale) {
  return Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * scale;
}

// A rotation vector of the given angle about a random axis.
Vec3 RandomRotationVector(Rng& rng, double angle) {
  return RandomVec3(rng, 1.0).normalized() * angle;
}

Pose RandomPose(Rng& rng) {
  return {ExpSO3(RandomRotationVector(rng, rng.Uniform(0, kPi - 0.1))), RandomVec3(rng, 0.5)};
}

double MaxAbs(const Eigen::MatrixXd& m) {
  return m.cwiseAbs().maxCoeff();
}

TEST(PoseMath, ExpIsAProperRotation) {
  Rng rng(1);
  for (double angle : {0.0, 1e-14, 1e-9, 1e-4, 0.3, 1.0, 2.5, kPi - 1e-6, kPi}) {
    const Mat3 R = ExpSO3(RandomRotationVector(rng, angle));
    EXPECT_LT(MaxAbs(R.transpose() * R - Mat3::Identity()), 1e-14) << "angle " << angle;
    EXPECT_NEAR(R.determinant(), 1.0, 1e-14) << "angle " << angle;
  }
}

TEST(PoseMath, ExpMatchesTheSeriesAndSkewIsTheCrossProduct) {
  Rng rng(2);
  const Vec3 a = RandomVec3(rng, 1.0), b = RandomVec3(rng, 1.0);
  EXPECT_LT((Skew(a) * b - a.cross(b)).norm(), 1e-15);
  EXPECT_EQ(MaxAbs(Skew(a) + Skew(a).transpose()), 0.0);
  // Exp(r) = sum_k [r]x^k / k!, to machine precision for |r| = 0.7.
  const Vec3 r = RandomRotationVector(rng, 0.7);
  Mat3 series = Mat3::Identity(), term = Mat3::Identity();
  for (int k = 1; k < 30; ++k) {
    term = term * Skew(r) / k;
    series += term;
  }
  EXPECT_LT(MaxAbs(ExpSO3(r) - series), 1e-15);
  // A rotation about z by 90 degrees maps x to y (right-handed, active).
  EXPECT_LT((ExpSO3(Vec3(0, 0, kPi / 2)) * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-15);
}

TEST(PoseMath, LogInvertsExpUpToPi) {
  Rng rng(3);
  for (double angle : {0.0, 1e-12, 1e-8, 1e-3, 0.5, 1.5, 3.0, kPi - 1e-4}) {
    for (int k = 0; k < 20; ++k) {
      const Vec3 r = RandomRotationVector(rng, angle);
      const Vec3 back = LogSO3(ExpSO3(r));
      // Relative accuracy for the large angles, absolute near zero.
      EXPECT_LT((back - r).norm(), 1e-12 * std::max(1.0, angle / (kPi - angle))) << "angle " << angle;
    }
  }
  // Beyond pi the logarithm returns the equivalent rotation of angle 2 pi - |r| about -axis.
  const Vec3 axis = Vec3(1, 2, 3).normalized();
  const Vec3 back = LogSO3(ExpSO3(axis * (kPi + 0.5)));
  EXPECT_LT((back - (-axis * (kPi - 0.5))).norm(), 1e-12);
  // And Exp(Log(R)) = R for any rotation.
  for (int k = 0; k < 50; ++k) {
    const Mat3 R = RandomPose(rng).R;
    EXPECT_LT(MaxAbs(ExpSO3(LogSO3(R)) - R), 1e-13);
  }
}

TEST(PoseMath, LeftJacobianMatchesCentralDifferences) {
  Rng rng(4);
  // Both branches: the series below 1e-6 rad and the closed form above.
  for (double angle : {0.0, 1e-7, 1e-3, 0.4, 2.0, 3.0}) {
    const Vec3 r = RandomRotationVector(rng, angle);
    const Vec3 v = RandomVec3(rng, 1.0);
    const auto f = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return ExpSO3(Vec3(x)) * v; };
    const Eigen::MatrixXd numeric = test::NumericJacobian(f, r, 1e-6);
    const Mat3 analytic = -Skew(ExpSO3(r) * v) * LeftJacobianSO3(r);
    EXPECT_LT(MaxAbs(numeric - analytic), 1e-8) << "angle " << angle;
  }
  // The left Jacobian's defining property: Exp(r + e) ~ Exp(J_l(r) e) Exp(r).
  const Vec3 r = RandomRotationVector(rng, 1.2), e = RandomVec3(rng, 1e-6);
  const Mat3 lhs = ExpSO3(r + e), rhs = ExpSO3(LeftJacobianSO3(r) * e) * ExpSO3(r);
  EXPECT_LT(MaxAbs(lhs - rhs), 1e-11);
}

TEST(PoseMath, BoxPlusAndBoxMinusRoundTrip) {
  Rng rng(5);
  for (int k = 0; k < 200; ++k) {
    const Pose T = RandomPose(rng);
    Vec6 d;
    d.head<3>() = RandomRotationVector(rng, rng.Uniform(0, 3.0));
    d.tail<3>() = RandomVec3(rng, 0.3);
    const Pose Tp = BoxPlus(T, d);
    EXPECT_LT((BoxMinus(Tp, T) - d).norm(), 1e-12);
    // BoxPlus(T_hat, BoxMinus(T, T_hat)) = T for any two poses.
    const Pose U = RandomPose(rng);
    const Pose back = BoxPlus(T, BoxMinus(U, T));
    EXPECT_LT(MaxAbs(back.R - U.R), 1e-12);
    EXPECT_LT((back.t - U.t).norm(), 1e-15);
  }
  // The layout: the rotation perturbs on the left (in the frame the pose maps into) and
  // the position adds, so a pure dtheta rotates about the frame's origin, not about p.
  const Pose T{ExpSO3(Vec3(0.1, -0.2, 0.3)), Vec3(1, 2, 3)};
  Vec6 d = Vec6::Zero();
  d[2] = 0.5;
  const Pose Tp = BoxPlus(T, d);
  EXPECT_LT(MaxAbs(Tp.R - ExpSO3(Vec3(0, 0, 0.5)) * T.R), 1e-15);
  EXPECT_EQ(Tp.t, T.t);
  EXPECT_LT(BoxMinus(T, T).norm(), 1e-15);
}

TEST(PoseMath, ComposeInvertAndConvert) {
  Rng rng(6);
  for (int k = 0; k < 50; ++k) {
    const Pose A = RandomPose(rng), B = RandomPose(rng);
    const Vec3 p = RandomVec3(rng, 1.0);
    EXPECT_LT(((A * B) * p - A * (B * p)).norm(), 1e-14);
    const Pose I = A * A.Inverse();
    EXPECT_LT(MaxAbs(I.R - Mat3::Identity()), 1e-14);
    EXPECT_LT(I.t.norm(), 1e-14);
    // mrcal's rt and the quaternion round trips.
    double rt[6];
    A.ToRt(rt);
    const Pose back = Pose::FromRt(rt);
    EXPECT_LT(MaxAbs(back.R - A.R), 1e-13);
    EXPECT_EQ(back.t, A.t);
    const Eigen::Quaterniond q = A.Quaternion();
    EXPECT_GE(q.w(), 0.0);
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    EXPECT_LT(MaxAbs(Pose::FromQuaternion(q, A.t).R - A.R), 1e-14);
    // FromQuaternion normalizes, and q and -q are the same rotation.
    const Eigen::Quaterniond q2(-3 * q.w(), -3 * q.x(), -3 * q.y(), -3 * q.z());
    EXPECT_LT(MaxAbs(Pose::FromQuaternion(q2, A.t).R - A.R), 1e-14);
  }
}

TEST(PoseMath, RotationAngleIsTheGeodesicDistanceAndAccurateNearZero) {
  Rng rng(7);
  for (int k = 0; k < 50; ++k) {
    const Mat3 Ra = RandomPose(rng).R;
    const double angle = rng.Uniform(0, kPi);
    const Mat3 Rb = Ra * ExpSO3(RandomRotationVector(rng, angle));
    EXPECT_NEAR(RotationAngle(Ra, Rb), angle, 1e-12);
    EXPECT_NEAR(RotationAngle(Rb, Ra), angle, 1e-12);
  }
  // 1 nanoradian: acos of the trace would give 0 or ~1e-8 here.
  const Mat3 R = RandomPose(rng).R;
  EXPECT_NEAR(RotationAngle(R, ExpSO3(Vec3(0, 1e-9, 0)) * R), 1e-9, 1e-15);
  EXPECT_EQ(RotationAngle(R, R), 0.0);
}

// The pose covariance under T' = A T B: compare the closed form with the numeric
// Jacobian of delta -> BoxMinus(A BoxPlus(T, delta) B, A T B).
TEST(PoseMath, TransformPoseCovarianceMatchesTheNumericJacobian) {
  Rng rng(8);
  for (int k = 0; k < 20; ++k) {
    const Pose A = RandomPose(rng), T = RandomPose(rng), B = RandomPose(rng);
    const Pose T1 = A * T * B;
    const auto f = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd {
      return BoxMinus(A * BoxPlus(T, Vec6(x)) * B, T1);
    };
    const Mat6 J = test::NumericJacobian(f, Vec6::Zero(), 1e-6);
    // A random covariance with correlations between rotation and position, of very
    // different scales (mrad^2 and mm^2), as the tracker reports.
    Mat6 L = Mat6::Zero();
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j <= i; ++j) L(i, j) = rng.Normal();
    Vec6 scale;
    scale << 1e-3, 1e-3, 2e-3, 1e-4, 3e-4, 2e-4;
    const Mat6 cov = scale.asDiagonal() * (L * L.transpose()) * scale.asDiagonal();
    const Mat6 expected = J * cov * J.transpose();
    const Mat6 got = TransformPoseCovariance(cov, A, T, B);
    EXPECT_LT(MaxAbs(got - expected), 1e-8 * MaxAbs(expected)) << "pose " << k;
    EXPECT_LT(MaxAbs(got - got.transpose()), 1e-20);
  }
}

TEST(PoseMath, TransformPoseCovarianceSpecialCases) {
  Rng rng(9);
  const Pose T = RandomPose(rng), A = RandomPose(rng);
  Mat6 cov = Mat6::Identity() * 1e-6;
  // Identity A and B leave the covariance as it is.
  EXPECT_LT(MaxAbs(TransformPoseCovariance(cov, Pose::Identity(), T, Pose::Identity()) - cov), 1e-22);
  // A pure rotation of the frame rotates both blocks; isotropic blocks stay as they are.
  EXPECT_LT(MaxAbs(TransformPoseCovariance(cov, {A.R, Vec3::Zero()}, T, Pose::Identity()) - cov), 1e-21);
  // A lever arm B turns rotation uncertainty into position uncertainty of |lever| * sigma.
  cov = Mat6::Zero();
  cov(0, 0) = 1e-6;  // 1 mrad about x, exact position
  const Pose B{Mat3::Identity(), Vec3(0, 0, 0.5)};
  const Mat6 out = TransformPoseCovariance(cov, Pose::Identity(), Pose::Identity(), B);
  EXPECT_NEAR(out(4, 4), 0.25 * 1e-6, 1e-18);  // y position: 0.5 m * 1 mrad
  EXPECT_NEAR(out(3, 3), 0.0, 1e-22);
  EXPECT_NEAR(out(5, 5), 0.0, 1e-22);
}

// Monte Carlo: perturbations drawn with the covariance, pushed through the exact map,
// have the transformed covariance (the first-order map holds at these small scales).
TEST(PoseMath, TransformPoseCovarianceAgreesWithSampling) {
  Rng rng(10);
  const Pose A = RandomPose(rng), T = RandomPose(rng), B{ExpSO3(Vec3(0.2, 0.1, 0)), Vec3(0.1, -0.3, 0.4)};
  Vec6 sigma;
  sigma << 2e-3, 1e-3, 3e-3, 5e-4, 5e-4, 1e-3;
  const Mat6 cov = sigma.cwiseAbs2().asDiagonal();
  const Mat6 predicted = TransformPoseCovariance(cov, A, T, B);
  const Pose T1 = A * T * B;
  const int n = 20000;
  Mat6 sample = Mat6::Zero();
  for (int k = 0; k < n; ++k) {
    Vec6 d;
    for (int i = 0; i < 6; ++i) d[i] = sigma[i] * rng.Normal();
    const Vec6 e = BoxMinus(A * BoxPlus(T, d) * B, T1);
    sample += e * e.transpose();
  }
  sample /= n;
  // Each diagonal element's sampling error is sqrt(2 / n) ~ 1 % relative; allow 5 %.
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(sample(i, i) / predicted(i, i), 1.0, 0.05) << "element " << i;
}

}  // namespace
}  // namespace mcms
