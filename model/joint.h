// One joint of a serial robot and its link transform, in one of two descriptions: a
// Denavit-Hartenberg table (standard or modified) or a URDF placement (origin and axis, as
// ROS describes robots), with the joint's limits, encoder noise, error motion and the mass
// of the link it moves (model/robot_model.h holds the chain). The link transform and its
// geometric error model are templated on the scalar (double or ceres::Jet), so that
// evaluation, calibration and the audit's extensions share one definition.
//
// Conventions (docs/conventions.md): SI units, T_a_b maps b coordinates to a; standard DH
// T = E(q) Rz(theta) Tz(d) Tx(a) Rx(alpha); modified DH T = Rx(alpha) Tx(a) E(q) Rz(theta)
// Tz(d); URDF T = origin G A E(q) A^T M(axis, q), with E(q) the joint's error motion, G
// the placement's geometric error and A a rotation taking z to the axis.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <ceres/rotation.h>

#include "core/pose_math.h"

namespace mcms {

// How the link transforms are described.
//  kStandard (Denavit-Hartenberg 1955, as in Spong): link i is
//      T_{i-1,i} = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i),
//    joint i turns about the z axis of frame i-1.
//  kModified (Craig 1986): link i is
//      T_{i-1,i} = Rx(alpha_i) Tx(a_i) Rz(theta_i) Tz(d_i),
//    where (alpha_i, a_i) here are Craig's alpha_{i-1}, a_{i-1} stored with joint i;
//    joint i turns about the z axis of frame i.
//  kUrdf (ROS): link i is
//      T_{i-1,i} = origin_i * Rot(axis_i, q_i)   (revolute)   or   origin_i * Trans(q_i axis_i)
//    with frame i the joint's child link frame, origin_i its placement in frame i-1 (the
//    fixed joints before it folded in) and axis_i its unit axis in frame i.
// In all, the last link frame n is the flange.
enum class ChainConvention { kStandard, kModified, kUrdf };

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
  // of mass in frame i (m), from CAD or a data sheet. Empty = not given: a robot gives a
  // mass for every joint or for none (RobotModel::HasMasses). Used for the gravity torque
  // that deflects compliant joints (model/extensions.h GravityTorque).
  std::optional<double> mass_kg;
  Vec3 com_m = Vec3::Zero();
  // URDF placement (ChainConvention::kUrdf; the DH parameters above are then 0, but for
  // theta_offset (revolute) and d (prismatic), which offset the joint's zero as in DH).
  Pose origin;
  Vec3 axis = Vec3::UnitZ();
  // A mimic joint (URDF <mimic>, issue 51): not measured on its own, its value is
  // mimic_multiplier * (the value of joint `mimics`) + mimic_offset, the driving joint being
  // one of the robot's actuated joints (RobotModel::ActuatedJoints): a chain joint, or a
  // joint outside the chain that a log records (a telescopic column's motor driving two
  // segments). Empty: the joint is actuated itself.
  std::string mimics;
  double mimic_multiplier = 1.0, mimic_offset = 0.0;
};

// Where to draw a joint's values when its range is all one knows (identifiability at
// random postures, poses that separate two models): its limits, an open or very wide side
// narrowed to pi rad or 1 m from the other side or from 0; always inside the limits (a
// telescopic column reaching from 1.48 to 3.97 m is drawn there, not around 0).
inline std::pair<double, double> SamplingRange(const Joint& j) {
  const double wide = j.type == JointType::kRevolute ? 3.141592653589793 : 1.0;
  double lo = j.lower, hi = j.upper;
  if (!std::isfinite(lo) && !std::isfinite(hi)) return {-wide, wide};
  if (!std::isfinite(lo)) lo = hi - 2 * wide;
  if (!std::isfinite(hi)) hi = lo + 2 * wide;
  if (hi - lo > 2 * wide) {
    const double mid = std::clamp(0.0, lo + wide, hi - wide);
    lo = mid - wide, hi = mid + wide;
  }
  return {lo, hi};
}

// A rigid transform with scalar T, as Pose is for double.
template <typename T>
struct PoseT {
  Eigen::Matrix<T, 3, 3> R = Eigen::Matrix<T, 3, 3>::Identity();
  Eigen::Matrix<T, 3, 1> t = Eigen::Matrix<T, 3, 1>::Zero();
  PoseT operator*(const PoseT& o) const { return PoseT{R * o.R, R * o.t + t}; }
  static PoseT FromPose(const Pose& p) { return PoseT{p.R.cast<T>(), p.t.cast<T>()}; }
};

// The geometric error model of a joint (what calibration identifies and the audit's
// `geometry` fits), per joint in this order:
//   DH:   [dtheta, dd, da, dalpha]    added to the DH table (rad, m); the zero offset is
//                                     dtheta (revolute) or dd (prismatic);
//   URDF: [offset, x, y, z, rx, ry, rz]  the joint's zero offset (rad, or m for a prismatic
//                                     joint), then a small placement error G = [Exp(r), t]
//                                     right after its origin, in the joint frame (the
//                                     component of r or t along the axis duplicates the
//                                     offset). Translations before rotations, as FIGAROH
//                                     orders them: the identifiability analysis keeps the
//                                     first of a redundant group.
constexpr int kDhParamsPerJoint = 4;
constexpr int kUrdfParamsPerJoint = 7;
constexpr int GeometryParamsPerJoint(ChainConvention c) {
  return c == ChainConvention::kUrdf ? kUrdfParamsPerJoint : kDhParamsPerJoint;
}
// Index of the zero offset in a joint's geometric error block.
constexpr int OffsetParameter(ChainConvention c, JointType type) {
  return c == ChainConvention::kUrdf || type == JointType::kRevolute ? 0 : 1;
}
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
// it inside), with the geometric errors `geometry` (GeometryParamsPerJoint values or null)
// and error motion `xi` (6 values or null = none).
template <typename T>
PoseT<T> LinkTransformT(ChainConvention convention, const Joint& j, const T& q, const T* geometry, const T* xi) {
  using M3 = Eigen::Matrix<T, 3, 3>;
  using V3 = Eigen::Matrix<T, 3, 1>;
  const bool rev = j.type == JointType::kRevolute;
  if (convention == ChainConvention::kUrdf) {
    // origin G A E A^T M(axis, q + offset)
    PoseT<T> L = PoseT<T>::FromPose(j.origin);
    T value = q + T(rev ? j.theta_offset : j.d);
    if (geometry) {
      value += geometry[0];
      PoseT<T> G;
      ceres::AngleAxisToRotationMatrix(geometry + 4, G.R.data());
      G.t << geometry[1], geometry[2], geometry[3];
      L = L * G;
    }
    if (xi) {
      // The error motion acts in the joint's axis frame A (z along the axis).
      const Vec3 a = j.axis;
      const Vec3 helper = std::abs(a.z()) < 0.9 ? Vec3::UnitZ() : Vec3::UnitX();
      Mat3 A;
      A.col(2) = a;
      A.col(0) = helper.cross(a).normalized();
      A.col(1) = a.cross(A.col(0));
      M3 Re;
      ceres::AngleAxisToRotationMatrix(xi, Re.data());
      const M3 Ac = A.cast<T>();
      L = L * PoseT<T>{Ac * Re * Ac.transpose(), Ac * V3(xi[3], xi[4], xi[5])};
    }
    PoseT<T> M;
    if (rev) {
      const T aa[3] = {T(j.axis.x()) * value, T(j.axis.y()) * value, T(j.axis.z()) * value};
      ceres::AngleAxisToRotationMatrix(aa, M.R.data());
    } else {
      M.t = j.axis.cast<T>() * value;
    }
    return L * M;
  }
  T theta = T(j.theta_offset) + (rev ? q : T(0));
  T d = T(j.d) + (rev ? T(0) : q);
  T a = T(j.a);
  T alpha = T(j.alpha);
  if (geometry) {
    theta += geometry[0];
    d += geometry[1];
    a += geometry[2];
    alpha += geometry[3];
  }
  using std::cos;
  using std::sin;
  const T ct = cos(theta), st = sin(theta), ca = cos(alpha), sa = sin(alpha);
  PoseT<T> L;
  if (convention == ChainConvention::kStandard) {
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
  if (convention == ChainConvention::kStandard) return PoseT<T>{Re, te} * L;
  // A E A^-1 L with A = [Rx(alpha), (a, 0, 0)]: E acts in the joint's axis frame.
  M3 Ra;
  Ra << T(1), T(0), T(0), T(0), ca, -sa, T(0), sa, ca;
  const V3 ta(a, T(0), T(0));
  const M3 Rc = Ra * Re * Ra.transpose();
  const V3 tc = Ra * te + ta - Rc * ta;
  return PoseT<T>{Rc, tc} * L;
}

}  // namespace mcms
