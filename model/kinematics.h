// Forward kinematics of a serial robot, templated on the scalar so that one piece of code
// serves evaluation (double) and Ceres' automatic differentiation (ceres::Jet): the
// RobotModel's own link transforms, the robot calibration's cost and the audit's
// extensions all run through LinkTransformT / ForwardKinematicsT.
//
// Conventions (docs/conventions.md, model/robot_model.h): SI units, T_a_b maps b
// coordinates to a; standard DH  T = E(q) Rz(theta) Tz(d) Tx(a) Rx(alpha);
// modified DH T = Rx(alpha) Tx(a) E(q) Rz(theta) Tz(d); URDF T = origin G A E(q) A^T M(axis, q)
// (model/joint.h), with E(q) the joint's error motion and G the placement's geometric error.
#pragma once

#include <cmath>
#include <vector>

#include <Eigen/Core>
#include <ceres/rotation.h>

#include "model/joint.h"
#include "model/robot_model.h"

namespace mcms {

// Corrections to the nominal chain, each optional (null = none):
//  - geometry: GeometryParamsPerJoint per joint, the geometric error model of model/joint.h
//    (DH [dtheta, dd, da, dalpha]; URDF [offset, x, y, z, rx, ry, rz]);
//  - dq: 1 per joint, added to the joint value before the link transform (rad or m), the
//    place where joint offsets, scale errors, compliance and backlash enter;
//  - error_motion: per joint, 12 per estimated harmonic ([rx ry rz x y z] of sin(h q),
//    then of cos(h q)), added to the joint's own error motion; error_motion_harmonics[i]
//    is the number of estimated harmonics of joint i (empty = none).
template <typename T>
struct ChainCorrections {
  const T* geometry = nullptr;
  const T* dq = nullptr;
  const T* error_motion = nullptr;
  std::vector<int> error_motion_harmonics;
};

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
    const T* g = c.geometry ? c.geometry + GeometryParamsPerJoint(robot.Convention()) * i : nullptr;
    if (j.Harmonics() > 0 || h_est > 0) {
      T xi[6];
      ErrorMotionT(j, q[i], h_est, em, xi);
      X = X * LinkTransformT(robot.Convention(), j, qi, g, xi);
    } else {
      X = X * LinkTransformT<T>(robot.Convention(), j, qi, g, nullptr);
    }
    if (em) em += kErrorMotionParamsPerHarmonic * h_est;
  }
  return X;
}

}  // namespace mcms
