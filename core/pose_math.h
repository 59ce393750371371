// Rigid transforms and the project's pose-perturbation layout (docs/conventions.md):
//   R = Exp(dtheta) * R_hat,  p = p_hat + dp,  tangent vector [dtheta; dp].
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace mcms {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat2 = Eigen::Matrix2d;
using Mat3 = Eigen::Matrix3d;
using Mat6 = Eigen::Matrix<double, 6, 6>;

// A rigid transform T_a_b: p_a = R * p_b + t.
struct Pose {
  Mat3 R = Mat3::Identity();
  Vec3 t = Vec3::Zero();

  static Pose Identity() { return {}; }
  static Pose FromQuaternion(const Eigen::Quaterniond& q, const Vec3& t);
  // mrcal's rt = [rotation vector; translation].
  static Pose FromRt(const double rt[6]);
  void ToRt(double rt[6]) const;
  Eigen::Quaterniond Quaternion() const;  // normalized, w >= 0

  Vec3 operator*(const Vec3& p) const { return R * p + t; }
  Pose operator*(const Pose& o) const { return {R * o.R, R * o.t + t}; }
  Pose Inverse() const { return {R.transpose(), -(R.transpose() * t)}; }
};

Mat3 Skew(const Vec3& v);
Mat3 ExpSO3(const Vec3& r);
Vec3 LogSO3(const Mat3& R);
// Left Jacobian of SO(3): d(Exp(r) v)/dr = -[Exp(r) v]x * LeftJacobianSO3(r).
Mat3 LeftJacobianSO3(const Vec3& r);

// The tangent layout of every pose covariance: [dtheta; dp].
Pose BoxPlus(const Pose& T, const Vec6& delta);
Vec6 BoxMinus(const Pose& T, const Pose& T_hat);  // T = BoxPlus(T_hat, result)

// Maps a covariance of T in the [dtheta; dp] layout to that of T' = A * T * B, with A and
// B exact (e.g. a registration and a mounting offset): dtheta' = R_A dtheta,
// dp' = R_A (dp - [R p_B]x dtheta).
Mat6 TransformPoseCovariance(const Mat6& cov, const Pose& A, const Pose& T, const Pose& B);

// Angle of the relative rotation R_a^T R_b, radians.
double RotationAngle(const Mat3& R_a, const Mat3& R_b);

// A quaternion read from a file is a rotation when its norm is 1 within 1e-3: four digits
// typed by hand (0.7071, 0.7071, 0, 0: 0.99999) pass, a wrong order or a missing sign's
// worth of error does not. Every reader uses this one tolerance, then normalises.
inline constexpr double kQuaternionNormTolerance = 1e-3;
inline bool IsUnitQuaternion(const Eigen::Quaterniond& q) {
  return std::abs(q.norm() - 1.0) <= kQuaternionNormTolerance;
}

// The rotation a file meant when it wrote a quaternion's four numbers as x, y, z, w under
// qw, qx, qy, qz headers and they were read as `q` (scalar first): the same four numbers
// read scalar last. One helper for every reader's quaternion-order check.
inline Mat3 RotationReadScalarLast(const Eigen::Quaterniond& q) {
  return Eigen::Quaterniond(q.z(), q.w(), q.x(), q.y()).normalized().toRotationMatrix();
}

// The rigid transform T minimising sum |T src_i - dst_i|^2 (Kabsch / Umeyama, no scale;
// columns are points). `spread`, when not null, receives the second singular value of the
// centred cross-covariance over the first (0: the points lie on a line or at one place,
// and T is not determined).
Pose RigidFit(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, double* spread = nullptr);

// URDF's rpy (fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation, and back.
Vec3 RpyOf(const Mat3& R);
Mat3 RotationOfRpy(const Vec3& rpy);

}  // namespace mcms
