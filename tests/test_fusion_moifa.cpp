// MOIFA: weights sum to the identity, eq. 19, the paper's misprinted eq. 13, Monte-Carlo
// NEES of positions and poses, partial (information-form) inputs, the inclinometer's
// rank-2 orientation information, and singular inputs.
#include <numbers>
#include <gtest/gtest.h>

#include <cmath>

#include <Eigen/Eigenvalues>

#include "model/inclinometer.h"
#include "core/error.h"
#include "core/random.h"
#include "core/statistics.h"
#include "fusion/moifa.h"

namespace mcms {
namespace {

template <int N>
Eigen::Matrix<double, N, N> RandomSpd(Rng& rng, double scale) {
  Eigen::Matrix<double, N, N> A;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) A(i, j) = rng.Normal();
  return scale * scale * (A * A.transpose() / N + 0.2 * Eigen::Matrix<double, N, N>::Identity());
}

template <int N>
Eigen::Matrix<double, N, 1> Sample(Rng& rng, const Eigen::Matrix<double, N, N>& C) {
  const Eigen::Matrix<double, N, N> L = C.llt().matrixL();
  Eigen::Matrix<double, N, 1> z;
  for (int i = 0; i < N; ++i) z[i] = rng.Normal();
  return L * z;
}

template <int N>
double MinEigenvalue(const Eigen::Matrix<double, N, N>& A) {
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>>(A).eigenvalues()[0];
}

// 95 % two-sided band of the mean of n chi-square(dof) values.
std::pair<double, double> MeanChi2Band(int n, int dof) {
  return {ChiSquareQuantile(0.025, n * dof) / n, ChiSquareQuantile(0.975, n * dof) / n};
}

TEST(Moifa, WeightsSumToIdentityAndCovarianceIsEquation19) {
  Rng rng(1);
  std::vector<Mat3> C = {RandomSpd<3>(rng, 1e-4), RandomSpd<3>(rng, 2e-4), RandomSpd<3>(rng, 5e-5)};
  std::vector<Vec3> p = {Vec3(0.1, 0.2, 0.3), Vec3(0.1001, 0.1998, 0.3002), Vec3(0.09995, 0.2001, 0.2999)};
  std::vector<PositionMeasurement> m;
  const char* names[] = {"camera", "robot", "tracker"};
  for (int i = 0; i < 3; ++i) m.push_back(PositionMeasurement::FromCovariance(names[i], p[i], C[i]));
  const FusedPosition f = FusePositions(m);
  Mat3 sum = Mat3::Zero(), info = Mat3::Zero();
  Vec3 weighted = Vec3::Zero();
  for (int i = 0; i < 3; ++i) {
    sum += f.weights[i];
    info += C[i].inverse();
    weighted += f.weights[i] * p[i];
  }
  EXPECT_LT((sum - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((f.covariance - info.inverse()).cwiseAbs().maxCoeff(), 1e-12 * f.covariance.norm());
  EXPECT_LT((f.p - weighted).norm(), 1e-15);
  for (int i = 0; i < 3; ++i) EXPECT_GT(MinEigenvalue<3>(C[i] - f.covariance), -1e-20) << "sensor " << i;
}

// The paper's eq. (13)/(16) puts the inverse outside the sum. For its own section 3.3
// sigmas the weights sum to diag(1803, 5872, 24037) mm^-4 instead of I.
TEST(Moifa, PaperPrintedWeightsDoNotSumToIdentity) {
  const Mat3 Pc = Vec3(0.15, 0.15, 0.15).cwiseAbs2().asDiagonal();      // mm^2
  const Mat3 Pr = Vec3(0.157, 0.087, 0.043).cwiseAbs2().asDiagonal();  // mm^2
  const auto printed = PrintedEquation13Weights({Pc, Pr});
  const Mat3 printed_sum = printed[0] + printed[1];
  std::printf("paper eq. 13 weights sum (mm^-4): diag(%.1f, %.1f, %.1f)\n", printed_sum(0, 0), printed_sum(1, 1),
              printed_sum(2, 2));
  EXPECT_NEAR(printed_sum(0, 0), 1803.1, 0.5);
  EXPECT_NEAR(printed_sum(1, 1), 5871.9, 0.5);
  EXPECT_NEAR(printed_sum(2, 2), 24037.0, 1.0);
  const FusedPosition f = FusePositions({PositionMeasurement::FromCovariance("camera", Vec3::Zero(), Pc),
                                         PositionMeasurement::FromCovariance("robot", Vec3::Zero(), Pr)});
  EXPECT_LT((f.weights[0] + f.weights[1] - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-12);
  // Scaling the unit changes the printed weights (they are not dimensionless): in metres
  // the same sum is 1e12 times larger.
  const auto printed_m = PrintedEquation13Weights({Pc * 1e-6, Pr * 1e-6});
  EXPECT_NEAR((printed_m[0] + printed_m[1])(0, 0) / printed_sum(0, 0), 1e12, 1e3);
}

// Fused errors against eq. 19: NEES of 4000 trials inside its 95 % band, and the sample
// covariance within 10 % (in the metric of the predicted covariance).
TEST(Moifa, PositionMonteCarloMatchesEquation19) {
  Rng rng(2);
  const std::vector<Mat3> C = {RandomSpd<3>(rng, 1.5e-4), RandomSpd<3>(rng, 1e-4), RandomSpd<3>(rng, 3e-4)};
  const Vec3 truth(0.5, -0.2, 1.1);
  const int n = 4000;
  double nees = 0.0;
  Mat3 S = Mat3::Zero(), P;
  for (int k = 0; k < n; ++k) {
    std::vector<PositionMeasurement> m;
    for (int i = 0; i < 3; ++i) m.push_back(PositionMeasurement::FromCovariance("s", truth + Sample<3>(rng, C[i]), C[i]));
    const FusedPosition f = FusePositions(m);
    const Vec3 e = f.p - truth;
    nees += e.dot(f.covariance.inverse() * e);
    S += e * e.transpose() / n;
    P = f.covariance;
  }
  const auto band = MeanChi2Band(n, 3);
  EXPECT_GT(nees / n, band.first);
  EXPECT_LT(nees / n, band.second);
  const Mat3 L = P.llt().matrixL();
  const Mat3 W = L.inverse() * S * L.inverse().transpose();
  EXPECT_LT((W - Mat3::Identity()).cwiseAbs().maxCoeff(), 0.1);
}

TEST(Moifa, PartialPositionMeasurements) {
  // A full camera estimate plus a height gauge that only measures z (rank-1 information).
  const Mat3 Cc = Vec3(0.15e-3, 0.15e-3, 0.15e-3).cwiseAbs2().asDiagonal();
  const double sz = 0.02e-3, z = 0.30002;
  const Mat3 Lz = Vec3(0, 0, 1.0 / (sz * sz)).asDiagonal();
  const PositionMeasurement cam = PositionMeasurement::FromCovariance("camera", Vec3(0.1, 0.2, 0.3), Cc);
  const PositionMeasurement gauge = PositionMeasurement::FromInformation("gauge", Lz, Lz * Vec3(0, 0, z));
  const FusedPosition f = FusePositions({cam, gauge});
  EXPECT_NEAR(f.p.x(), 0.1, 1e-15);
  EXPECT_NEAR(f.p.y(), 0.2, 1e-15);
  const double wz = (1 / (sz * sz)) / (1 / (sz * sz) + 1 / Cc(2, 2));
  EXPECT_NEAR(f.p.z(), wz * z + (1 - wz) * 0.3, 1e-12);
  EXPECT_NEAR(f.covariance(0, 0), Cc(0, 0), 1e-20);
  EXPECT_LT(f.covariance(2, 2), sz * sz);
  EXPECT_LT((f.weights[0] + f.weights[1] - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT(f.weights[1].topRows<2>().cwiseAbs().maxCoeff(), 1e-15);  // the gauge says nothing of x, y

  // Two gauges along z alone leave x and y unobserved: a clear error naming the problem.
  try {
    FusePositions({gauge, gauge});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("singular (rank 1 of 3)"), std::string::npos) << e.what();
  }
  EXPECT_THROW(FusePositions({}), InputError);
  // Bad inputs name the sensor.
  try {
    PositionMeasurement::FromCovariance("bumped camera", Vec3::Zero(), Mat3::Zero());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bumped camera"), std::string::npos);
  }
  EXPECT_THROW(PositionMeasurement::FromInformation("x", Lz, Vec3(1, 0, 0)), InputError);   // pull along no info
  EXPECT_THROW(PositionMeasurement::FromInformation("x", -Lz, Vec3::Zero()), InputError);   // not PSD
  Mat3 asym = Cc;
  asym(0, 1) = 1e-9;
  EXPECT_THROW(PositionMeasurement::FromCovariance("x", Vec3::Zero(), asym), InputError);
}

// --- Poses ---------------------------------------------------------------------------

Mat3 LevelFlange() {  // the KR 5 arc's flange at q = 0: z along base x
  Mat3 R;
  R << 0, 0, 1, 0, -1, 0, 1, 0, 0;
  return R;
}
Inclinometer MountedInclinometer() {
  Inclinometer s;
  s.R_flange_incl = Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitY()).toRotationMatrix();
  return s;
}

// A camera pose covariance: 0.5 mrad, 0.15 mm, with correlations between rotation and
// position (as a five-ball target seen from one side gives).
Mat6 CameraCovariance(Rng& rng) {
  Mat6 C = RandomSpd<6>(rng, 1.0);
  const Vec6 s = (Vec6() << 0.5e-3, 0.5e-3, 0.5e-3, 0.15e-3, 0.15e-3, 0.15e-3).finished();
  const Eigen::VectorXd d = C.diagonal().cwiseSqrt().cwiseInverse().cwiseProduct(s);
  return d.asDiagonal() * C * d.asDiagonal();
}

TEST(Moifa, PoseMonteCarloMatchesEquation19) {
  Rng rng(3);
  const Pose truth{ExpSO3(Vec3(0.05, -0.1, 0.4)) * LevelFlange(), Vec3(0.9, 0.1, 1.1)};
  const Mat6 Cc = CameraCovariance(rng);
  const Mat6 Cr = (Vec6() << 3e-4, 3e-4, 3e-4, 0.157e-3, 0.087e-3, 0.043e-3).finished().cwiseAbs2().asDiagonal();
  const Inclinometer incl = MountedInclinometer();
  const int n = 3000;
  double nees = 0.0;
  Mat6 S = Mat6::Zero(), P = Mat6::Zero();
  for (int k = 0; k < n; ++k) {
    const PoseMeasurement cam = PoseMeasurement::FromCovariance("camera", BoxPlus(truth, Sample<6>(rng, Cc)), Cc);
    const PoseMeasurement rob = PoseMeasurement::FromCovariance("robot", BoxPlus(truth, Sample<6>(rng, Cr)), Cr);
    const Vec2 reading = *incl.Simulate(truth.R, rng);
    // Linearize the inclinometer at the camera's orientation, as a real pipeline would.
    const PoseMeasurement inc = PoseMeasurement::FromOrientation("inclinometer", incl.Constraint(reading, cam.T_ref.R));
    const FusedPose f = FusePoses({cam, rob, inc});
    const Vec6 e = BoxMinus(truth, f.T);
    nees += e.dot(f.covariance.inverse() * e);
    S += e * e.transpose() / n;
    P = f.covariance;
    if (k == 0) {
      Mat6 sum = Mat6::Zero();
      for (const Mat6& W : f.weights) sum += W;
      EXPECT_LT((sum - Mat6::Identity()).cwiseAbs().maxCoeff(), 1e-9);
      for (const Mat6& C : {Cc, Cr}) EXPECT_GT(MinEigenvalue<6>(C - f.covariance), -1e-20);
    }
  }
  const auto band = MeanChi2Band(n, 6);
  EXPECT_GT(nees / n, band.first);
  EXPECT_LT(nees / n, band.second);
  const Mat6 L = P.llt().matrixL();
  const Mat6 W = L.inverse() * S * L.inverse().transpose();
  EXPECT_LT((W - Mat6::Identity()).cwiseAbs().maxCoeff(), 0.12);
}

// The inclinometer sharpens roll and pitch (rotation about horizontal base axes) and leaves
// yaw (about base z) exactly as the camera gave it.
TEST(Moifa, InclinometerImprovesRollPitchAndLeavesYaw) {
  Rng rng(4);
  const Pose truth{ExpSO3(Vec3(0.02, 0.03, -0.5)) * LevelFlange(), Vec3(0.9, 0.0, 1.1)};
  // Camera rotation covariance without yaw correlations, so yaw is exactly separable.
  Mat6 Cc = Mat6::Zero();
  Cc.diagonal() << 1e-6, 1e-6, 1e-6, 2.25e-8, 2.25e-8, 2.25e-8;
  Cc(0, 1) = Cc(1, 0) = 3e-7;
  const Inclinometer incl = MountedInclinometer();
  const int n = 3000;
  Vec3 sum2_cam = Vec3::Zero(), sum2_fused = Vec3::Zero();
  Mat6 P;
  for (int k = 0; k < n; ++k) {
    const PoseMeasurement cam = PoseMeasurement::FromCovariance("camera", BoxPlus(truth, Sample<6>(rng, Cc)), Cc);
    const PoseMeasurement inc =
        PoseMeasurement::FromOrientation("inclinometer", incl.Constraint(*incl.Simulate(truth.R, rng), cam.T_ref.R));
    const FusedPose f = FusePoses({cam, inc});
    sum2_cam += BoxMinus(truth, cam.T_ref).head<3>().cwiseAbs2();
    sum2_fused += BoxMinus(truth, f.T).head<3>().cwiseAbs2();
    P = f.covariance;
  }
  const Vec3 rms_cam = (sum2_cam / n).cwiseSqrt(), rms_fused = (sum2_fused / n).cwiseSqrt();
  std::printf("rotation error RMS (mrad) about base x, y, z: camera %.3f %.3f %.3f, with inclinometer %.3f %.3f %.3f\n",
              rms_cam.x() * 1e3, rms_cam.y() * 1e3, rms_cam.z() * 1e3, rms_fused.x() * 1e3, rms_fused.y() * 1e3,
              rms_fused.z() * 1e3);
  // Roll and pitch: down to about the inclinometer's 0.17 mrad (predicted by eq. 19 within 5 %).
  for (int a = 0; a < 2; ++a) {
    EXPECT_LT(rms_fused[a], 0.25 * rms_cam[a]);
    EXPECT_NEAR(rms_fused[a] / std::sqrt(P(a, a)), 1.0, 0.05);
  }
  // Yaw: the camera's, unchanged, up to second-order terms of composing mrad rotations
  // (the SO(3) Jacobians mix ~1e-3 of roll/pitch into yaw): the covariance to 1e-5, the
  // errors to 5e-3 (the cross term 1/2 a x b).
  EXPECT_NEAR(P(2, 2), Cc(2, 2), 1e-5 * Cc(2, 2));
  EXPECT_NEAR(rms_fused.z() / rms_cam.z(), 1.0, 5e-3);

  // The inclinometer with a position-only sensor leaves yaw unobserved: a clear error.
  Mat6 Lp = Mat6::Zero();
  Lp.bottomRightCorner<3, 3>() = Mat3::Identity() / 2.25e-8;
  const PoseMeasurement position_only = PoseMeasurement::FromInformation("camera position", truth, Lp, Vec6::Zero());
  const PoseMeasurement inc =
      PoseMeasurement::FromOrientation("inclinometer", incl.Constraint(incl.Predict(truth.R), truth.R));
  try {
    FusePoses({position_only, inc});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("singular (rank 5 of 6)"), std::string::npos) << what;
    EXPECT_NE(what.find("0 0 1 0 0 0"), std::string::npos) << what;  // the yaw direction
  }
}

// Gauss-Newton on the tangent: the result does not depend on which estimate is the first
// linearization point, even for estimates 50 mrad apart.
TEST(Moifa, PoseFusionIndependentOfLinearizationPoint) {
  Rng rng(5);
  const Pose a{ExpSO3(Vec3(0.3, -0.2, 1.0)), Vec3(0.2, 0.3, 0.4)};
  const Pose b = BoxPlus(a, (Vec6() << 0.03, -0.02, 0.035, 1e-3, -2e-3, 5e-4).finished());
  const Mat6 Ca = CameraCovariance(rng), Cb = CameraCovariance(rng) * 2.0;
  const std::vector<PoseMeasurement> m = {PoseMeasurement::FromCovariance("a", a, Ca),
                                          PoseMeasurement::FromCovariance("b", b, Cb)};
  FusePosesOptions o0, o1;
  o0.linearization_index = 0;
  o1.linearization_index = 1;
  o0.iterations = o1.iterations = 4;
  const FusedPose f0 = FusePoses(m, o0), f1 = FusePoses(m, o1);
  EXPECT_LT(BoxMinus(f0.T, f1.T).norm(), 1e-12);
  EXPECT_LT((f0.covariance - f1.covariance).norm(), 1e-6 * f0.covariance.norm());
  FusePosesOptions bad;
  bad.iterations = 0;
  EXPECT_THROW(FusePoses(m, bad), InputError);
  bad = FusePosesOptions();
  bad.linearization_index = 5;
  EXPECT_THROW(FusePoses(m, bad), InputError);
}

}  // namespace
}  // namespace mcms
