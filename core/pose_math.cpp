#include "core/pose_math.h"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>

namespace mcms {

Pose Pose::FromQuaternion(const Eigen::Quaterniond& q, const Vec3& t) {
  return {q.normalized().toRotationMatrix(), t};
}

Pose Pose::FromRt(const double rt[6]) {
  return {ExpSO3(Vec3(rt[0], rt[1], rt[2])), Vec3(rt[3], rt[4], rt[5])};
}

void Pose::ToRt(double rt[6]) const {
  const Vec3 r = LogSO3(R);
  for (int i = 0; i < 3; ++i) {
    rt[i] = r[i];
    rt[3 + i] = t[i];
  }
}

Eigen::Quaterniond Pose::Quaternion() const {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;
  return q;
}

Mat3 Skew(const Vec3& v) {
  Mat3 S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

Mat3 ExpSO3(const Vec3& r) {
  const double th = r.norm();
  if (th < 1e-12) return Mat3::Identity() + Skew(r);
  return Eigen::AngleAxisd(th, r / th).toRotationMatrix();
}

Vec3 LogSO3(const Mat3& R) {
  Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

Mat3 LeftJacobianSO3(const Vec3& r) {
  const double th = r.norm();
  const Mat3 K = Skew(r);
  if (th < 1e-6) return Mat3::Identity() + 0.5 * K + K * K / 6.0;
  const double th2 = th * th;
  return Mat3::Identity() + (1.0 - std::cos(th)) / th2 * K + (th - std::sin(th)) / (th2 * th) * K * K;
}

Pose BoxPlus(const Pose& T, const Vec6& d) {
  return {ExpSO3(d.head<3>()) * T.R, T.t + d.tail<3>()};
}

Vec6 BoxMinus(const Pose& T, const Pose& T_hat) {
  Vec6 d;
  d.head<3>() = LogSO3(T.R * T_hat.R.transpose());
  d.tail<3>() = T.t - T_hat.t;
  return d;
}

Mat6 TransformPoseCovariance(const Mat6& cov, const Pose& A, const Pose& T, const Pose& B) {
  Mat6 J = Mat6::Zero();
  J.topLeftCorner<3, 3>() = A.R;
  J.bottomLeftCorner<3, 3>() = -A.R * Skew(T.R * B.t);
  J.bottomRightCorner<3, 3>() = A.R;
  return J * cov * J.transpose();
}

double RotationAngle(const Mat3& R_a, const Mat3& R_b) {
  // Through the quaternion: acos of the trace loses half the digits near zero.
  const Eigen::Quaterniond q(R_a.transpose() * R_b);
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

Pose RigidFit(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, double* spread) {
  const Vec3 cs = src.rowwise().mean(), cd = dst.rowwise().mean();
  const Mat3 H = (dst.colwise() - cd) * (src.colwise() - cs).transpose();
  Eigen::JacobiSVD<Mat3> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  if (spread) {
    const Vec3 sv = svd.singularValues();
    *spread = sv[0] > 0 ? sv[1] / sv[0] : 0.0;
  }
  Mat3 S = Mat3::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) S(2, 2) = -1;
  Pose T;
  T.R = svd.matrixU() * S * svd.matrixV().transpose();
  T.t = cd - T.R * cs;
  return T;
}

Vec3 RpyOf(const Mat3& R) {
  // R = Rz(y) Ry(p) Rx(r): R(2,0) = -sin p.
  const double sp = std::clamp(-R(2, 0), -1.0, 1.0);
  const double p = std::asin(sp);
  double r, y;
  if (std::abs(sp) < 1.0 - 1e-12) {
    r = std::atan2(R(2, 1), R(2, 2));
    y = std::atan2(R(1, 0), R(0, 0));
  } else {
    // Gimbal lock: only r -/+ y is defined; take y = 0.
    y = 0.0;
    r = std::atan2(-R(1, 2), R(1, 1));
  }
  return Vec3(r, p, y);
}

Mat3 RotationOfRpy(const Vec3& rpy) {
  return (Eigen::AngleAxisd(rpy[2], Vec3::UnitZ()) * Eigen::AngleAxisd(rpy[1], Vec3::UnitY()) *
          Eigen::AngleAxisd(rpy[0], Vec3::UnitX()))
      .toRotationMatrix();
}

}  // namespace mcms
