// A two-axis gravity inclinometer rigidly mounted on the robot flange (the paper's LE-30:
// 0.01 deg accuracy, one reading every 20 ms).
//
// What it can sense: the direction of gravity in its own frame, nothing else. That fixes
// two of the three rotational degrees of freedom, the tilts (pitch and roll) of the sensor
// relative to the horizontal. A rotation about the gravity axis (yaw, heading) leaves the
// gravity direction in the sensor frame unchanged and is UNOBSERVABLE. The paper says the
// inclinometer measures "pitch and yaw"; a gravity inclinometer measures pitch and roll,
// and yaw must come from the other sensors (camera, robot).
//
// Frames: the robot base z axis points up (gravity is -z_base). The sensor frame `incl`
// is fixed to the flange by R_flange_incl; its x and y axes are the two sensing axes.
//
// Reading (radians, per axis k in {x, y}):
//     tilt_k = asin(e_k_incl . up),   up = +z_base expressed in the sensor frame,
// i.e. the angle of the sensor's k axis above the horizontal plane, which is what each
// axis of a dual-axis inclinometer reports (the two axes are independent). A reading is
// tilt + bias + noise. The reading is defined while both |tilt_k| stay within `range`;
// beyond it the sensor saturates and no reading is produced.
//
// Orientation errors use the project's layout (docs/conventions.md): R = Exp(dtheta) R_hat
// with dtheta in the BASE frame.
#pragma once

#include <numbers>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "core/pose_math.h"
#include "core/random.h"

namespace mcms {

// One reading as a constraint on the flange orientation, in information form about
// dtheta at the linearization point R_lin (R = Exp(dtheta) R_lin, base frame):
//   cost(dtheta) = 1/2 dtheta^T information dtheta - information_vector^T dtheta + const.
// information = H^T Sigma^-1 H has rank 2: it is zero along the base z axis (gravity),
// since the inclinometer says nothing about yaw.
struct OrientationInformation {
  Mat3 R_base_flange_lin = Mat3::Identity();
  Mat3 information = Mat3::Zero();       // rad^-2
  Vec3 information_vector = Vec3::Zero();  // rad^-1
};

struct Inclinometer {
  Mat3 R_flange_incl = Mat3::Identity();  // mounting rotation, sensor frame to flange frame
  Vec2 bias = Vec2::Zero();               // rad, per axis, added to the true tilt
  double sigma = 0.01 * std::numbers::pi / 180.0;  // rad, per-axis noise (LE-30: 0.01 deg)
  double period = 0.02;                   // s between readings (LE-30: 20 ms)
  // Largest |tilt| on either axis at which a reading exists. The paper gives no range for
  // the LE-30; 30 deg is taken from its name. The Jacobian grows as 1/cos(tilt).
  double range = 30.0 * std::numbers::pi / 180.0;  // rad

  // Finite rotation, sigma > 0, period > 0, 0 < range < pi/2.
  bool IsValid(std::string* why = nullptr) const;

  // True tilts [tilt_x, tilt_y] (no bias, no noise) of the sensor for a flange
  // orientation R_base_flange. d_tilt_d_dtheta (2x3), when not null, is the Jacobian with
  // respect to dtheta; its null space is the base z axis. Defined for |tilt| < pi/2.
  Vec2 Tilt(const Mat3& R_base_flange, Eigen::Matrix<double, 2, 3>* d_tilt_d_dtheta = nullptr) const;
  // Tilt + bias: the expected reading.
  Vec2 Predict(const Mat3& R_base_flange) const { return Tilt(R_base_flange) + bias; }
  // Whether the sensor produces a reading at this orientation (both |tilt| <= range).
  bool InRange(const Mat3& R_base_flange) const;
  // A noisy reading, or nullopt when out of range.
  std::optional<Vec2> Simulate(const Mat3& R_base_flange, Rng& rng) const;
  // Reading noise covariance, sigma^2 I (rad^2).
  Mat2 Covariance() const { return sigma * sigma * Mat2::Identity(); }

  // The reading as an information-form constraint on dtheta at R_base_flange_lin
  // (first order): information = H^T Sigma^-1 H, information_vector = H^T Sigma^-1
  // (reading - Predict(R_lin)), with H = d_tilt_d_dtheta at R_lin. InputError when the
  // reading is not finite or R_lin is out of range (the constraint would be meaningless).
  OrientationInformation Constraint(const Vec2& reading, const Mat3& R_base_flange_lin) const;
};

}  // namespace mcms
