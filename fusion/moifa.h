// MOIFA, the paper's "multi-sensor optimal information fusion algorithm" (section 2.2.2):
// linear minimum-variance fusion of n estimates of one quantity with full covariances,
// for 3-D positions and for 6-DOF poses, accepting partial measurements in information form.
//
// The estimator. n unbiased estimates x_i with covariances P_i are fused as
//     x = sum_i W_i x_i,   W_i = (sum_j P_j^-1)^-1 P_i^-1,   P = (sum_i P_i^-1)^-1   (eq. 19)
// The weights sum to the identity (so x is unbiased, eq. 10-11) and P is no larger than
// any P_i in the positive semi-definite sense. Everything is computed in information form
// (Lambda_i = P_i^-1, eta_i = Lambda_i x_i), so a measurement that constrains only some
// directions (singular Lambda_i, e.g. the inclinometer's rank-2 orientation information,
// model/inclinometer.h) enters the same sum; only the total information must be invertible.
//
// The paper's misprint. Equations (13) and (16) print the weight as
//     W_i = { sum_j P_j }^-1 P_i^-1          (inverse OUTSIDE the sum)
// which is not the minimum-variance weight: the W_i do not sum to the identity, so the
// fused value is biased by (sum_i W_i - I) x, and W_i is not even dimensionless (units of
// 1/length^4 for positions). For the paper's own section 3.3 sigmas (camera 0.15 mm per
// axis, robot 0.157/0.087/0.043 mm) the printed weights sum to diag(1803, 5872, 24037) mm^-4
// (PrintedEquation13Weights; test_fusion_moifa.cpp). The minimum-variance weight (Nakamura
// and Xu 1989, the paper's ref. 13) has the inverse inside the sum, consistent with the
// paper's own eq. 19 for the covariance and its 46.1 % result. We implement that one.
//
// Poses use the project's tangent layout [dtheta; dp] (docs/conventions.md:
// R = Exp(dtheta) R_hat, p = p_hat + dp, both in the frame the pose maps into). Poses are
// fused by Gauss-Newton on that tangent: pick a linearization point (the most precise full
// estimate), express every measurement on its tangent (BoxMinus, with the SO(3) left
// Jacobian transporting the information), fuse linearly, BoxPlus back, and repeat.
// All measurements must describe the same body in the same frame.
#pragma once

#include <string>
#include <vector>

#include "model/inclinometer.h"
#include "core/pose_math.h"

namespace mcms {

// A Gaussian measurement of a 3-D position in information form:
//   cost(p) = 1/2 p^T information p - information_vector^T p + const.
struct PositionMeasurement {
  std::string name;                        // names the sensor in errors and reports
  Mat3 information = Mat3::Zero();         // m^-2, symmetric positive semi-definite
  Vec3 information_vector = Vec3::Zero();  // m^-1, in the range of `information`

  // A full estimate p with covariance C (symmetric positive definite, m^2):
  // information = C^-1, information_vector = C^-1 p. InputError naming `name` otherwise.
  static PositionMeasurement FromCovariance(std::string name, const Vec3& p, const Mat3& covariance);
  // A possibly partial measurement. InputError when not finite, not symmetric, not
  // positive semi-definite, or when information_vector has a component in the null space
  // of information (a measurement cannot pull along a direction it has no information on).
  static PositionMeasurement FromInformation(std::string name, const Mat3& information,
                                             const Vec3& information_vector);
};

struct FusedPosition {
  Vec3 p = Vec3::Zero();
  Mat3 covariance = Mat3::Zero();  // eq. 19, (sum_i information_i)^-1, m^2
  // W_i = covariance * information_i, in input order; sum_i W_i = I. For a full estimate
  // p_i the fused value is sum_i W_i p_i (eq. 15).
  std::vector<Mat3> weights;
};

// InputError when there is no measurement or when the total information is singular (the
// message names the unobserved direction).
FusedPosition FusePositions(const std::vector<PositionMeasurement>& measurements);

// The weights as printed in the paper's eq. (13)/(16), W_i = (sum_j P_j)^-1 P_i^-1, from
// full covariances. For comparison only (see the header comment): they do not sum to I.
std::vector<Mat3> PrintedEquation13Weights(const std::vector<Mat3>& covariances);

// A Gaussian measurement of a pose in information form on the [dtheta; dp] tangent at
// T_ref: with x = BoxMinus(T, T_ref),
//   cost(T) = 1/2 x^T information x - information_vector^T x + const.
struct PoseMeasurement {
  std::string name;
  Pose T_ref;                              // the estimate itself, or the linearization point
  Mat6 information = Mat6::Zero();         // [rad^-2, rad^-1 m^-1; ..., m^-2]
  Vec6 information_vector = Vec6::Zero();  // zero for a full estimate at T_ref

  // A full estimate with 6x6 covariance in [dtheta; dp] (symmetric positive definite).
  static PoseMeasurement FromCovariance(std::string name, const Pose& T, const Mat6& covariance);
  // A possibly partial measurement (same checks as PositionMeasurement::FromInformation).
  static PoseMeasurement FromInformation(std::string name, const Pose& T_ref, const Mat6& information,
                                         const Vec6& information_vector);
  // An orientation-only constraint (e.g. Inclinometer::Constraint): the rotation block of
  // the information, nothing on position.
  static PoseMeasurement FromOrientation(std::string name, const OrientationInformation& orientation);
};

struct FusePosesOptions {
  // Gauss-Newton relinearizations. Pose measurements of a few mrad disagreement converge
  // to 1e-12 rad in two; the paper's linear eq. 15 is iterations = 1 around one estimate.
  int iterations = 2;
  // Index of the measurement whose T_ref is the first linearization point; -1 picks the
  // full-rank measurement with the largest information determinant.
  int linearization_index = -1;
  bool IsValid(std::string* why = nullptr) const;
};

struct FusedPose {
  Pose T;
  Mat6 covariance = Mat6::Zero();  // [dtheta; dp] at T, eq. 19
  // W_i = covariance * information_i on the tangent at T, in input order; sum_i W_i = I.
  std::vector<Mat6> weights;
};

// InputError when there is no measurement, options are invalid, or the total information is
// singular (e.g. an inclinometer and a position-only sensor leave yaw unobserved).
FusedPose FusePoses(const std::vector<PoseMeasurement>& measurements, const FusePosesOptions& options = {});

}  // namespace mcms
