// Inclinometer: tilt geometry, Jacobian against central differences, blindness to yaw,
// simulated noise statistics, and the rank-2 information-form constraint.
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "model/inclinometer.h"
#include "core/error.h"
#include "core/random.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

Mat3 Rot(const Vec3& axis, double angle) { return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix(); }

// Mounted so the sensor is level at the KR 5 arc's zero pose (flange z along base x,
// flange x up): sensor z along flange x.
Inclinometer Mounted() {
  Inclinometer s;
  s.R_flange_incl = Rot(Vec3::UnitY(), kPi / 2) * Rot(Vec3::UnitZ(), 0.3);
  return s;
}
Mat3 KukaZeroPose() {
  Mat3 R;
  R << 0, 0, 1, 0, -1, 0, 1, 0, 0;
  return R;
}

TEST(Inclinometer, TiltGeometry) {
  Inclinometer s;  // sensor frame = flange frame
  EXPECT_LT(s.Tilt(Mat3::Identity()).norm(), 1e-15);
  // Tilting about the sensor's y axis by b lowers its x axis by b: tilt_x = -b.
  const double b = 0.2;
  const Vec2 t = s.Tilt(Rot(Vec3::UnitY(), b));
  EXPECT_NEAR(t.x(), -b, 1e-14);
  EXPECT_NEAR(t.y(), 0.0, 1e-14);
  // Tilting about x by a raises the y axis: tilt_y = a.
  EXPECT_NEAR(s.Tilt(Rot(Vec3::UnitX(), 0.1)).y(), 0.1, 1e-14);
  // The mounting makes the sensor level at the KUKA zero pose.
  EXPECT_LT(Mounted().Tilt(KukaZeroPose()).norm(), 1e-15);
}

TEST(Inclinometer, JacobianMatchesCentralDifferences) {
  const Inclinometer s = Mounted();
  Rng rng(17);
  for (int k = 0; k < 20; ++k) {
    const Vec3 r(rng.Uniform(-0.4, 0.4), rng.Uniform(-0.4, 0.4), rng.Uniform(-3, 3));
    const Mat3 R = ExpSO3(r) * KukaZeroPose();
    Eigen::Matrix<double, 2, 3> H;
    s.Tilt(R, &H);
    const Eigen::MatrixXd Hn = test::NumericJacobian(
        [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return s.Tilt(ExpSO3(Vec3(x)) * R); }, Vec3::Zero(), 1e-6);
    EXPECT_LT((H - Hn).cwiseAbs().maxCoeff(), 1e-8) << H << "\n" << Hn;
  }
}

TEST(Inclinometer, BlindToYaw) {
  const Inclinometer s = Mounted();
  const Mat3 R = ExpSO3(Vec3(0.1, -0.2, 0.3)) * KukaZeroPose();
  for (double yaw : {0.5, 1.7, -2.9}) EXPECT_LT((s.Tilt(Rot(Vec3::UnitZ(), yaw) * R) - s.Tilt(R)).norm(), 1e-14);
  Eigen::Matrix<double, 2, 3> H;
  s.Tilt(R, &H);
  EXPECT_LT((H * Vec3::UnitZ()).norm(), 1e-15);
  EXPECT_EQ((Eigen::FullPivLU<Eigen::Matrix<double, 2, 3>>(H).rank()), 2);
}

// Mean and standard deviation of simulated readings: 20000 samples, tolerances of about
// 4 standard errors (sigma/sqrt(n) = 0.007 sigma for the mean, 0.005 sigma for the std).
TEST(Inclinometer, SimulatedReadingsHaveBiasAndNoise) {
  Inclinometer s = Mounted();
  s.bias = Vec2(0.002, -0.001);
  const Mat3 R = ExpSO3(Vec3(0.05, 0.1, 0.2)) * KukaZeroPose();
  const Vec2 truth = s.Tilt(R);
  Rng rng(23);
  const int n = 20000;
  Vec2 sum = Vec2::Zero(), sum2 = Vec2::Zero();
  for (int k = 0; k < n; ++k) {
    const Vec2 e = *s.Simulate(R, rng) - truth;
    sum += e;
    sum2 += e.cwiseProduct(e);
  }
  const Vec2 mean = sum / n;
  const Vec2 sd = (sum2 / n - mean.cwiseProduct(mean)).cwiseSqrt();
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(mean[i], s.bias[i], 0.03 * s.sigma);
    EXPECT_NEAR(sd[i] / s.sigma, 1.0, 0.02);
  }
  // Beyond the range there is no reading.
  EXPECT_FALSE(s.Simulate(Rot(Vec3::UnitY(), 40 * kDeg) * KukaZeroPose(), rng).has_value());
  EXPECT_FALSE(s.InRange(Rot(Vec3::UnitX(), -40 * kDeg) * KukaZeroPose()));
  EXPECT_TRUE(s.InRange(Rot(Vec3::UnitX(), -20 * kDeg) * KukaZeroPose()));
}

TEST(Inclinometer, ConstraintIsRankTwoAndPointsToTheTruth) {
  const Inclinometer s = Mounted();
  const Mat3 R_true = ExpSO3(Vec3(0.05, -0.08, 1.0)) * KukaZeroPose();
  const Vec2 reading = s.Predict(R_true);  // noise-free
  // Linearize 2 mrad away (tilt and yaw); the constraint's minimizer must undo the tilt
  // part of the offset and say nothing about yaw.
  const Vec3 offset(0.0015, -0.001, 0.002);
  const Mat3 R_lin = ExpSO3(offset) * R_true;
  const OrientationInformation c = s.Constraint(reading, R_lin);
  Eigen::SelfAdjointEigenSolver<Mat3> es(c.information);
  EXPECT_LT(std::abs(es.eigenvalues()[0]), 1e-9 * es.eigenvalues()[2]);
  EXPECT_GT(es.eigenvalues()[1], 0.5 / (s.sigma * s.sigma));
  EXPECT_LT((c.information * Vec3::UnitZ()).norm(), 1e-9 * es.eigenvalues()[2]);
  // Minimizer of 1/2 x^T L x - eta^T x: x = L^+ eta, the correction from R_lin to R_true.
  const Mat3 pinv = es.eigenvectors().rightCols<2>() * es.eigenvalues().tail<2>().cwiseInverse().asDiagonal() *
                    es.eigenvectors().rightCols<2>().transpose();
  const Vec3 x = pinv * c.information_vector;
  const Vec3 expected(-offset.x(), -offset.y(), 0.0);
  EXPECT_LT((x - expected).norm(), 1e-5) << x.transpose();  // first order: error ~ |offset|^2
  EXPECT_NEAR(x.z(), 0.0, 1e-12);
}

TEST(Inclinometer, BadSettingsAndInputs) {
  std::string why;
  Inclinometer s;
  EXPECT_TRUE(s.IsValid(&why)) << why;
  s.sigma = 0;
  EXPECT_FALSE(s.IsValid(&why));
  EXPECT_NE(why.find("sigma"), std::string::npos);
  s = Inclinometer();
  s.range = 2.0;
  EXPECT_FALSE(s.IsValid(&why));
  s = Inclinometer();
  s.R_flange_incl(0, 1) = 0.5;
  EXPECT_FALSE(s.IsValid(&why));
  EXPECT_THROW(s.Constraint(Vec2::Zero(), Mat3::Identity()), InputError);
  const Inclinometer m = Mounted();
  EXPECT_THROW(m.Constraint(Vec2(NAN, 0), KukaZeroPose()), InputError);
  EXPECT_THROW(m.Constraint(Vec2::Zero(), Rot(Vec3::UnitX(), 1.0) * KukaZeroPose()), InputError);
}

}  // namespace
}  // namespace mcms
