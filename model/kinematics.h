// Forward kinematics of a serial robot, templated on the scalar so that one piece of code
// serves evaluation (double) and Ceres' automatic differentiation (ceres::Jet): the
// RobotModel's own link transforms, the robot calibration's cost and the audit's
// extensions all run through LinkTransformT / ForwardKinematicsT.
//
// Conventions (docs/conventions.md, model/robot_model.h): SI units, T_a_b maps b
// coordinates to a; standard DH  T = E(q) Rz(theta) Tz(d) Tx(a) Rx(alpha);
// modified DH T = Rx(alpha) Tx(a) E(q) Rz(theta) Tz(d), with E(q) the joint's error motion.
#pragma once

#include <cmath>
#include <vector>

#include <Eigen/Core>
#include <ceres/rotation.h>

#include "model/robot_model.h"

namespace mcms {

// A rigid transform with scalar T, as Pose is for double.
template <typename T>
struct PoseT {
  Eigen::Matrix<T, 3, 3> R = Eigen::Matrix<T, 3, 3>::Identity();
  Eigen::Matrix<T, 3, 1> t = Eigen::Matrix<T, 3, 1>::Zero();
  PoseT operator*(const PoseT& o) const { return PoseT{R * o.R, R * o.t + t}; }
  static PoseT FromPose(const Pose& p) { return PoseT{p.R.cast<T>(), p.t.cast<T>()}; }
};

// Corrections to the nominal chain, each optional (null = none):
//  - dh: 4 per joint, [dtheta, dd, da, dalpha] added to the DH table (rad, m);
//  - dq: 1 per joint, added to the joint value before the link transform (rad or m), the
//    place where joint offsets, scale errors, compliance and backlash enter;
//  - error_motion: per joint, 12 per estimated harmonic ([rx ry rz x y z] of sin(h q),
//    then of cos(h q)), added to the joint's own error motion; error_motion_harmonics[i]
//    is the number of estimated harmonics of joint i (empty = none).
template <typename T>
struct ChainCorrections {
  const T* dh = nullptr;
  const T* dq = nullptr;
  const T* error_motion = nullptr;
  std::vector<int> error_motion_harmonics;
};

constexpr int kDhParamsPerJoint = 4;
constexpr int kErrorMotionParamsPerHarmonic = 12;

// Error motion vector xi(q) = [rx ry rz x y z] of joint j at value q: the joint's own
// harmonics plus `h_est` estimated harmonics from `em` (12 per harmonic; may be null when
// h_est = 0).
template <typename T>
void ErrorMotionT(const Joint& j, double q, int h_est, const T* em, T xi[6]) {
  for (int k = 0; k < 6; ++k) xi[k] = T(0);
  const int h_all = std::max(j.Harmonics(), h_est);
  for (int h = 0; h < h_all; ++h) {
    const double sh = std::sin((h + 1) * q), ch = std::cos((h + 1) * q);
    for (int k = 0; k < 6; ++k) {
      if (h < j.Harmonics()) xi[k] += T(sh * j.error_motion_sin[h][k] + ch * j.error_motion_cos[h][k]);
      if (h < h_est) {
        xi[k] += sh * em[kErrorMotionParamsPerHarmonic * h + k] + ch * em[kErrorMotionParamsPerHarmonic * h + 6 + k];
      }
    }
  }
}

// Link transform T_{i-1,i} of joint j at joint value q (the nominal value; `dq` is added to
// it inside), with the DH corrections `dh` (4 values or null) and error motion `xi` (6
// values or null = the joint's own error motion only if `own_error_motion`).
template <typename T>
PoseT<T> LinkTransformT(DhConvention convention, const Joint& j, const T& q, const T* dh, const T* xi) {
  using M3 = Eigen::Matrix<T, 3, 3>;
  using V3 = Eigen::Matrix<T, 3, 1>;
  const bool rev = j.type == JointType::kRevolute;
  T theta = T(j.theta_offset) + (rev ? q : T(0));
  T d = T(j.d) + (rev ? T(0) : q);
  T a = T(j.a);
  T alpha = T(j.alpha);
  if (dh) {
    theta += dh[0];
    d += dh[1];
    a += dh[2];
    alpha += dh[3];
  }
  using std::cos;
  using std::sin;
  const T ct = cos(theta), st = sin(theta), ca = cos(alpha), sa = sin(alpha);
  PoseT<T> L;
  if (convention == DhConvention::kStandard) {
    // Rz(theta) Tz(d) Tx(a) Rx(alpha)
    L.R << ct, -st * ca, st * sa, st, ct * ca, -ct * sa, T(0), sa, ca;
    L.t << a * ct, a * st, d;
  } else {
    // Rx(alpha) Tx(a) Rz(theta) Tz(d)
    L.R << ct, -st, T(0), ca * st, ca * ct, -sa, sa * st, sa * ct, ca;
    L.t << a, -sa * d, ca * d;
  }
  if (!xi) return L;
  M3 Re;
  ceres::AngleAxisToRotationMatrix(xi, Re.data());  // column-major, as Eigen stores
  const V3 te(xi[3], xi[4], xi[5]);
  if (convention == DhConvention::kStandard) return PoseT<T>{Re, te} * L;
  // A E A^-1 L with A = [Rx(alpha), (a, 0, 0)]: E acts in the joint's axis frame.
  M3 Ra;
  Ra << T(1), T(0), T(0), T(0), ca, -sa, T(0), sa, ca;
  const V3 ta(a, T(0), T(0));
  const M3 Rc = Ra * Re * Ra.transpose();
  const V3 tc = Ra * te + ta - Rc * ta;
  return PoseT<T>{Rc, tc} * L;
}

// T_base_flange at joint values q (nominal, double) with the corrections `c`.
template <typename T>
PoseT<T> ForwardKinematicsT(const RobotModel& robot, const Eigen::VectorXd& q, const ChainCorrections<T>& c) {
  PoseT<T> X;
  const T* em = c.error_motion;
  for (int i = 0; i < robot.NumJoints(); ++i) {
    const Joint& j = robot.Joints()[i];
    const int h_est = i < static_cast<int>(c.error_motion_harmonics.size()) ? c.error_motion_harmonics[i] : 0;
    T qi = T(q[i]);
    if (c.dq) qi += c.dq[i];
    const T* dh = c.dh ? c.dh + kDhParamsPerJoint * i : nullptr;
    if (j.Harmonics() > 0 || h_est > 0) {
      T xi[6];
      ErrorMotionT(j, q[i], h_est, em, xi);
      X = X * LinkTransformT(robot.Convention(), j, qi, dh, xi);
    } else {
      X = X * LinkTransformT<T>(robot.Convention(), j, qi, dh, nullptr);
    }
    if (em) em += kErrorMotionParamsPerHarmonic * h_est;
  }
  return X;
}

}  // namespace mcms
