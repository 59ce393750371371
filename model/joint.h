// One joint of a serial robot and its link transform: the Denavit-Hartenberg convention,
// the joint's DH parameters, limits, encoder noise, error motion and the mass of the link
// it moves (model/robot_model.h holds the chain), with the link transform templated on the
// scalar (double or ceres::Jet), so that evaluation, calibration and the audit's
// extensions share one definition.
//
// Conventions (docs/conventions.md): SI units, T_a_b maps b coordinates to a; standard DH
// T = E(q) Rz(theta) Tz(d) Tx(a) Rx(alpha); modified DH T = Rx(alpha) Tx(a) E(q) Rz(theta)
// Tz(d), with E(q) the joint's error motion.
#pragma once

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <ceres/rotation.h>

#include "core/pose_math.h"

namespace mcms {

// Which DH convention the link transforms follow.
//  kStandard (Denavit-Hartenberg 1955, as in Spong): link i is
//      T_{i-1,i} = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i),
//    joint i turns about the z axis of frame i-1.
//  kModified (Craig 1986): link i is
//      T_{i-1,i} = Rx(alpha_i) Tx(a_i) Rz(theta_i) Tz(d_i),
//    where (alpha_i, a_i) here are Craig's alpha_{i-1}, a_{i-1} stored with joint i;
//    joint i turns about the z axis of frame i.
// In both, the last link frame n is the flange.
enum class DhConvention { kStandard, kModified };

enum class JointType { kRevolute, kPrismatic };

struct Joint {
  std::string name;
  JointType type = JointType::kRevolute;
  // DH parameters of the link transform. The joint value q adds to theta_offset for a
  // revolute joint (theta = q + theta_offset) and to d for a prismatic one (d = q + d).
  double a = 0.0;             // m
  double alpha = 0.0;         // rad
  double d = 0.0;             // m
  double theta_offset = 0.0;  // rad
  // Limits on the joint value q (rad or m), lower <= q <= upper.
  double lower = -std::numeric_limits<double>::infinity();
  double upper = std::numeric_limits<double>::infinity();
  // Standard deviation of the encoder reading of q (rad or m); 0 = noise-free.
  double encoder_sigma = 0.0;
  // Error motion of a revolute joint (ISO 230-7's "error motion of a rotary axis": how
  // the moving link departs from a perfect rotation as a function of the angle): the
  // small transform E(q) = [Exp(xi_rot(q)), xi_pos(q)] with
  //     xi(q) = sum_h  sin(h q) error_motion_sin[h-1] + cos(h q) error_motion_cos[h-1],
  // xi = [rx, ry, rz, x, y, z] (rad, m) in the joint's fixed axis frame (z = the joint
  // axis, attached to the preceding link): rx, ry are tilt error motion, rz angular
  // positioning error, x, y radial and z axial error motion. It is applied just before the
  // joint's rotation: standard DH  E(q) Rz(theta) Tz(d) Tx(a) Rx(alpha),
  //                  modified DH  Rx(alpha) Tx(a) E(q) Rz(theta) Tz(d).
  // The constant (h = 0) part is not here: the DH table holds it. Both lists have the same
  // length (the number of harmonics); empty = a perfect rotation. Not for prismatic joints.
  std::vector<Vec6> error_motion_sin, error_motion_cos;
  int Harmonics() const { return static_cast<int>(error_motion_sin.size()); }
  // Mass of the link this joint moves (link i, whose DH frame is frame i) and its centre
  // of mass in frame i (m), from CAD or a data sheet. NaN = not given: a robot gives a
  // mass for every joint or for none (RobotModel::HasMasses). Used for the gravity torque
  // that deflects compliant joints (model/extensions.h GravityTorque).
  double mass_kg = std::numeric_limits<double>::quiet_NaN();
  Vec3 com_m = Vec3::Zero();
};

// A rigid transform with scalar T, as Pose is for double.
template <typename T>
struct PoseT {
  Eigen::Matrix<T, 3, 3> R = Eigen::Matrix<T, 3, 3>::Identity();
  Eigen::Matrix<T, 3, 1> t = Eigen::Matrix<T, 3, 1>::Zero();
  PoseT operator*(const PoseT& o) const { return PoseT{R * o.R, R * o.t + t}; }
  static PoseT FromPose(const Pose& p) { return PoseT{p.R.cast<T>(), p.t.cast<T>()}; }
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

}  // namespace mcms
