// The catalog of model extensions: named, optional terms that plug into the nominal forward
// model of a sensor, each with its own parameters. The audit (issue 11) fits them one at a
// time and keeps those that earn their parameters; the calibrations and the simulation use
// the same terms, so "what the model can be wrong about" is written once, here.
//
// Each extension is one small templated unit (scalar T = double or ceres::Jet): it takes
// its parameter block and what the measurement knows (MeasurementContext) and changes one
// quantity of the nominal model:
//   robot          joint values (dq) and DH table (dh): joint_offset, joint_scale,
//                  gravity_compliance, backlash, link_length, link_twist, thermal_drift,
//                  geometry (every DH parameter at once); error_motion is the joint's
//                  harmonic error motion (model/kinematics.h, 12 / harmonic);
//   cameras        camera_moved (T_rig_cam), focal_length, principal_point,
//                  radial_distortion (intrinsics), camera_time_offset (the target's pose at
//                  a shifted time), pixel_noise_scale (the noise model), target_geometry
//                  (one ball's position on the target);
//   bending links  link_compliance, segment_play, axis_tilt (a link's tilt under the
//                  moment it carries, or with its travel, seen by a tilt sensor above it:
//                  LinkBendingT);
//   inclinometer   inclinometer_bias, inclinometer_misalignment;
//   clocks         clock_offset, clock_drift (a sensor's time stamps).
// Parameter units are SI (rad, m, s); relative factors (scale, focal) are dimensionless.
#pragma once

#include <cmath>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <ceres/rotation.h>

#include "core/pose_math.h"
#include "model/kinematics.h"
#include "model/robot_model.h"

namespace mcms {

enum class Effect {
  // robot
  kJointOffset, kLinkLength, kJointScale, kGravityCompliance, kThermalDrift, kBacklash, kErrorMotion,
  kLinkTwist, kGeometry, kLinkCompliance, kSegmentPlay, kAxisTilt,
  // cameras
  kCameraMoved, kFocalLength, kPrincipalPoint, kRadialDistortion, kCameraTimeOffset, kPixelNoiseScale,
  kTargetGeometry,
  // inclinometer and clocks
  kInclinometerBias, kInclinometerMisalignment, kClockOffset, kClockDrift,
};

enum class SensorKind { kRobot, kCamera, kInclinometer, kClock };

struct EffectInfo {
  Effect effect;
  const char* name;         // the catalog name reports and tests use, e.g. "joint_offset"
  SensorKind sensor;
  const char* description;  // one line
};

// Every effect, in the order above.
const std::vector<EffectInfo>& EffectCatalog();
const EffectInfo& Info(Effect e);
const char* Name(Effect e);
// nullopt for a name not in the catalog.
std::optional<Effect> EffectFromName(std::string_view name);

// One extension: an effect at one place.
//  index:   the joint (0-based) for joint_offset, joint_scale, gravity_compliance, backlash,
//           error_motion, link_twist, link_compliance and segment_play (the joint whose
//           child link bends: its frame tilts); the link (0-based) for link_length; the camera for
//           camera effects; the ball for target_geometry; unused (-1) otherwise.
//  variant: link_length 0 = a, 1 = d; inclinometer_misalignment 0 = the mounting rotation
//           (3), 1 = its turn about the sensor's own vertical alone (1: a tilt of the mount
//           reads as a bias to first order, a turn about the vertical never does); thermal_drift 0 = exponential warm-up in time,
//           1 = linear in temperature; error_motion = the number of harmonics (>= 1);
//           geometry = the robot's number of geometric parameters (RobotModel::
//           NumGeometryParameters: the error model of model/joint.h, per joint DH [dtheta,
//           dd, da, dalpha] or URDF [offset, x, y, z, rx, ry, rz]); link_length and link_twist
//           are DH terms (a URDF joint's are in its placement, which `geometry` holds);
//           gravity_compliance 0 = the joint's
//           compliance (rad per N m) times the gravity torque of the robot's own masses
//           and the payload (MeasurementContext::gravity_torque), 2 n + 1 = lumped masses:
//           compliance x mass (rad kg / (N m)) at each link frame's origin o_1..o_n, at
//           each link's DH corner c_1..c_n and at the tool point, times the torque per kg
//           there (MeasurementContext::gravity_lever), for robots whose masses are not
//           given (a centre of mass on a link's DH path is a positive sum of them).
struct Extension {
  Effect effect = Effect::kJointOffset;
  int index = -1;
  int variant = 0;

  int NumParameters() const;
  std::vector<std::string> ParameterNames() const;
  // Parameter values of the nominal model (no effect): zeros, except the warm-up time
  // constant of thermal_drift (a starting value, 1800 s) and the relative factors of
  // pixel_noise_scale (1).
  std::vector<double> InitialParameters() const;
  // Where it acts, as reports name it: "joint 2", "a2"/"d4", "cam1" (camera_names given),
  // "ball 3", the sensor's name.
  std::string Where(const std::vector<std::string>& camera_names = {}) const;
  // "joint_offset at joint 2".
  std::string Label(const std::vector<std::string>& camera_names = {}) const;
  // The same for a robot effect of `robot`: a URDF chain's joints by their names
  // ("backlash at arm_6_joint"), a DH table's by number.
  std::string Where(const RobotModel& robot) const;
  std::string Label(const RobotModel& robot) const;
  // InputError when the index does not fit the robot (joints, links) or the variant is
  // unknown; num_cameras / num_balls bound the camera and ball indices (0 = unchecked).
  void Check(const RobotModel* robot, int num_cameras = 0, int num_balls = 0) const;
};

// What one measurement knows besides the joint values: the covariates an effect depends on.
struct MeasurementContext {
  double time_s = 0.0;
  std::optional<double> temperature_c;   // empty when the log has no temperature
  double reference_temperature_c = 20.0; // temperature at which the DH table holds
  // Per joint: the sign (+1, -1, 0) of the last move's direction (backlash), and the
  // gravity torque on it (N m): of the robot's own masses and the payload when the robot
  // gives its masses (GravityTorque), else of the flange load alone.
  Eigen::VectorXd move_direction;
  Eigen::VectorXd gravity_torque;
  // n x (2 n + 1): torque on joint i (N m) per kg at link frame origin o_k (column k - 1,
  // k = 1..n), at link k's DH corner (column n + k - 1: standard DH o_{k-1} + d_k z_{k-1},
  // modified o_{k-1} + a_k x_{k-1}) and at the tool point (column 2 n, times the payload
  // when it is known): the covariates of lumped-mass gravity compliance (GravityLever).
  // Empty = none.
  Eigen::MatrixXd gravity_lever;
  // Per joint: the joint velocity at the measurement (rad/s or m/s; empty = at rest), for
  // a clock offset between the robot's log and the measuring instrument.
  Eigen::VectorXd joint_velocity;
};

// Torque (N m) that 1 kg at the flange origin puts on each joint by gravity (base z up,
// g = 9.80665): tau_i = (z_i x (p_flange - o_i)) . (0, 0, -g) for a revolute joint i with
// axis z_i through o_i; (z_i . (0, 0, -g)) for a prismatic one. Compliance deflects each
// joint in proportion to it (a stiffness is positive: the audit bounds it at 0).
Eigen::VectorXd GravityTorquePerKg(const RobotModel& robot, const Eigen::VectorXd& q);
// Gravity torque (N m) on each joint of the robot's own links (Joint::mass_kg at com_m),
// the tool's mass (RobotModel::Tool) and a payload at the tool point; only joints that
// move a mass feel it. InputError when the robot gives no masses (HasMasses).
Eigen::VectorXd GravityTorque(const RobotModel& robot, const Eigen::VectorXd& q, double payload_kg);
// The lumped-mass covariates of MeasurementContext::gravity_lever: n x (2 n + 1), torque
// on each joint per kg at each link frame's origin, each link's DH corner and the tool point.
Eigen::MatrixXd GravityLever(const RobotModel& robot, const Eigen::VectorXd& q);

// ---- robot units ------------------------------------------------------------------
// Adds the effect of `e` with parameters p to the joint corrections dq (n) and the geometric
// corrections dh (RobotModel::NumGeometryParameters, model/joint.h's layout). error_motion is
// not handled here (ChainCorrections::error_motion carries it).
template <typename T>
void AddRobotCorrectionT(const RobotModel& robot, const Extension& e, const T* p, const Eigen::VectorXd& q,
                         const MeasurementContext& c, T* dq, T* dh) {
  const int i = e.index;
  switch (e.effect) {
    case Effect::kJointOffset: dq[i] += p[0]; break;
    case Effect::kJointScale: dq[i] += p[0] * q[i]; break;
    case Effect::kGravityCompliance:
      if (e.variant == 0) {
        if (c.gravity_torque.size() > i) dq[i] += p[0] * c.gravity_torque[i];
      } else if (c.gravity_lever.rows() > i) {
        for (int k = 0; k < e.variant && k < c.gravity_lever.cols(); ++k) dq[i] += p[k] * c.gravity_lever(i, k);
      }
      break;
    case Effect::kBacklash:
      // The link lags the motor-side encoder by half the backlash against the last move:
      // q_link = q_encoder - b/2 sign(last move), b >= 0.
      if (c.move_direction.size() > i) dq[i] -= 0.5 * p[0] * c.move_direction[i];
      break;
    case Effect::kLinkLength:
      if (robot.Convention() != ChainConvention::kUrdf) dh[kDhParamsPerJoint * i + (e.variant == 0 ? 2 : 1)] += p[0];
      break;
    case Effect::kLinkTwist:
      if (robot.Convention() != ChainConvention::kUrdf) dh[kDhParamsPerJoint * i + 3] += p[0];
      break;
    case Effect::kGeometry:
      for (int k = 0; k < robot.NumGeometryParameters(); ++k) dh[k] += p[k];
      break;
    case Effect::kThermalDrift: {
      // Every link length grows by the same relative amount s.
      T s;
      if (e.variant == 0) {
        using std::exp;
        s = p[0] * (1.0 - exp(-c.time_s / p[1]));
      } else {
        s = p[0] * (c.temperature_c ? *c.temperature_c - c.reference_temperature_c : 0.0);
      }
      const int g = robot.GeometryParamsPerJoint();
      for (int k = 0; k < robot.NumJoints(); ++k) {
        const Joint& j = robot.Joints()[k];
        if (robot.Convention() == ChainConvention::kUrdf) {
          const Vec3 grow = j.origin.R.transpose() * j.origin.t;  // as UniformGrowth
          for (int a = 0; a < 3; ++a) dh[g * k + 1 + a] += s * grow[a];
        } else {
          dh[g * k + 1] += s * j.d;
          dh[g * k + 2] += s * j.a;
        }
      }
      break;
    }
    case Effect::kClockOffset:
    case Effect::kClockDrift: {
      // The robot's time stamp t is t + dt on the instrument's clock (ReferenceTimeT): the
      // pose at the measurement's time T was logged at T - dt, q(T - dt) = q - dt qdot to
      // first order in the motion (dt < 0: the robot's stamps are late).
      if (c.joint_velocity.size() != robot.NumJoints()) break;
      T dt = p[0];
      if (e.effect == Effect::kClockDrift) dt += p[1] * c.time_s;
      for (int k = 0; k < robot.NumJoints(); ++k) dq[k] -= dt * c.joint_velocity[k];
      break;
    }
    default: break;
  }
}

// T_base_flange of `robot` at q with the robot extensions `ext` (params[k] is the block of
// ext[k]) applied: joint and DH corrections, and error motion.
template <typename T>
PoseT<T> ExtendedFlangeT(const RobotModel& robot, const std::vector<Extension>& ext, T const* const* params,
                         const Eigen::VectorXd& q, const MeasurementContext& c) {
  const int n = robot.NumJoints();
  std::vector<T> dq(n, T(0)), dh(robot.NumGeometryParameters(), T(0));
  std::vector<int> harmonics(n, 0);
  std::vector<T> em;
  // Error motion: the blocks of the error_motion extensions, joint by joint.
  std::vector<const T*> em_of(n, nullptr);
  for (size_t k = 0; k < ext.size(); ++k) {
    if (ext[k].effect == Effect::kErrorMotion) {
      harmonics[ext[k].index] = ext[k].variant;
      em_of[ext[k].index] = params[k];
    } else {
      AddRobotCorrectionT(robot, ext[k], params[k], q, c, dq.data(), dh.data());
    }
  }
  for (int i = 0; i < n; ++i)
    for (int m = 0; m < kErrorMotionParamsPerHarmonic * harmonics[i]; ++m) em.push_back(em_of[i][m]);
  ChainCorrections<T> cc;
  cc.geometry = dh.data();
  cc.dq = dq.data();
  cc.error_motion = em.empty() ? nullptr : em.data();
  cc.error_motion_harmonics = harmonics;
  return ForwardKinematicsT(robot, q, cc);
}

// ---- bending links (issue 52) -------------------------------------------------------
// The least overlap telescopic segments keep (m): segment_play variant 1 never divides by
// less.
inline constexpr double kMinSegmentOverlapM = 1e-3;
// The moment (N m, base frame, gravity along -z) of the weight of everything link frame
// `frame` (0 = base, k = after joint k) carries, about that frame's origin: the links beyond
// it at their centres of mass, the tool's mass and a payload at the tool point. It bends
// the link below the frame. InputError when the robot gives no masses.
Vec3 CarriedMoment(const RobotModel& robot, const Eigen::VectorXd& q, int frame, double payload_kg = 0.0);

// The tilt (rotation vector, base frame) of a link's frame (orientation R_base_link) under
// the horizontal part M_h of the moment it carries (CarriedMoment) at a bending length L (m,
// the link's extended length below the frame): link_compliance (p0, p1) L M about the
// link frame's x and y axes (>= 0, rad per N m^2: a cantilever's L / (E I) per metre for
// each principal axis of its section; the tilt grows with the extension), segment_play
// p0 M_h / |M_h| (p0 >= 0, rad: the clearance between telescopic segments taken up with
// the sign of the moment; variant 1, telescopic play: the clearance's tilt grows as the
// segments' overlap shrinks, (p0 s_x, p1 s_y) / (p2 + t)^2 about the link frame's x and y,
// s the unit horizontal moment in that frame, t the travel left to the joint's upper limit
// (m) and p2 the overlap left at full extension (m): p0, p1 >= 0 rad m^2, p2 >= 0),
// axis_tilt (p0, p1) L (rad per m, base frame x and y: a linear axis's angular error
// motion, its moving part leaning in proportion to its travel, ISO 230-1's pitch and yaw;
// the constant part is the sensor's bias). Other effects: zero.
template <typename T>
Eigen::Matrix<T, 3, 1> LinkBendingT(const Extension& e, const T* p, const Vec3& moment, double length_m,
                                    const Mat3& R_base_link, double travel_left_m = 0.0) {
  const Vec3 mh(moment.x(), moment.y(), 0.0);
  Eigen::Matrix<T, 3, 1> b = Eigen::Matrix<T, 3, 1>::Zero();
  if (e.effect == Effect::kLinkCompliance) {
    const Vec3 ml = R_base_link.transpose() * moment;
    Eigen::Matrix<T, 3, 1> bl(p[0] * (length_m * ml.x()), p[1] * (length_m * ml.y()), T(0));
    b = R_base_link.cast<T>() * bl;
  } else if (e.effect == Effect::kAxisTilt) {
    for (int k = 0; k < 2; ++k) b[k] = p[k] * length_m;
  } else if (e.effect == Effect::kSegmentPlay && e.variant == 1) {
    const Vec3 ml = R_base_link.transpose() * moment;
    const double n = std::hypot(ml.x(), ml.y());
    if (n > 1e-9) {
      T overlap = p[2] + travel_left_m;
      if (overlap < T(kMinSegmentOverlapM)) overlap = T(kMinSegmentOverlapM);
      const T inv2 = 1.0 / (overlap * overlap);
      const Eigen::Matrix<T, 3, 1> bl(p[0] * (ml.x() / n) * inv2, p[1] * (ml.y() / n) * inv2, T(0));
      b = R_base_link.cast<T>() * bl;
    }
  } else if (e.effect == Effect::kSegmentPlay) {
    const double n = mh.norm();
    if (n > 1e-9)
      for (int k = 0; k < 2; ++k) b[k] = p[0] * (mh[k] / n);
  }
  return b;
}

// ---- camera units -----------------------------------------------------------------
// camera_moved: T_rig_cam' = Exp(p) T_rig_cam, p = [rotation vector; translation] in the
// rig frame (the [dtheta; dp] layout).
template <typename T>
PoseT<T> MovedCameraT(const Pose& T_rig_cam, const T* p) {
  PoseT<T> D;
  ceres::AngleAxisToRotationMatrix(p, D.R.data());
  D.t << p[3], p[4], p[5];
  const PoseT<T> C = PoseT<T>::FromPose(T_rig_cam);
  return PoseT<T>{D.R * C.R, D.R * C.t + D.t};
}

// Intrinsics [fx, fy, cx, cy, k1, ...] (mrcal's order for the OpenCV and pinhole models)
// changed by focal_length (fx, fy scaled by 1 + p0), principal_point (cx += p0, cy += p1)
// or radial_distortion (k1 += p0; a lens model without k1 is left unchanged, so the caller
// must not offer it). Other effects leave them unchanged.
template <typename T>
void ExtendIntrinsicsT(const Extension& e, const T* p, T* intrinsics, int num_intrinsics) {
  switch (e.effect) {
    case Effect::kFocalLength:
      intrinsics[0] *= 1.0 + p[0];
      intrinsics[1] *= 1.0 + p[0];
      break;
    case Effect::kPrincipalPoint:
      intrinsics[2] += p[0];
      intrinsics[3] += p[1];
      break;
    case Effect::kRadialDistortion:
      if (num_intrinsics > 4) intrinsics[4] += p[0];
      break;
    default: break;
  }
}

// camera_time_offset: the camera's image shows the target at t + p0, so its pose is the
// nominal T_rig_target moved along its motion: T' = M T with M the move of MovedCameraT
// (rotation vector, translation; rig frame) x(p0) = twist p0 + accel p0^2, twist
// [omega; v] (rad/s, m/s; v = pdot - omega x p) and accel its half-derivative (a
// quadratic through the neighbouring frames' moves: second order in the motion; zero:
// first order).
template <typename T>
PoseT<T> TimeShiftedPoseT(const Pose& T_rig_target, const Vec6& twist, const Vec6& accel, const T* p) {
  T r[6];
  for (int k = 0; k < 6; ++k) r[k] = p[0] * twist[k] + p[0] * p[0] * accel[k];
  return MovedCameraT<T>(T_rig_target, r);
}

// pixel_noise_scale: the pixel noise model is off by a factor p0 on its standard deviation
// (a wrong gain or read noise); returns the factor on the pixel covariance, p0^2.
template <typename T>
T PixelVarianceScaleT(const T* p) {
  return p[0] * p[0];
}

// target_geometry: ball `e.index` at balls_target + p.
template <typename T>
Eigen::Matrix<T, 3, 1> MovedBallT(const Vec3& ball_target, const T* p) {
  return ball_target.cast<T>() + Eigen::Matrix<T, 3, 1>(p[0], p[1], p[2]);
}

// ---- inclinometer and clocks --------------------------------------------------------
// The inclinometer reading (tilts [x, y], rad; model/inclinometer.h) of a sensor mounted
// at R_flange_incl, misaligned by Exp(misalignment) (3, flange frame; null = none), with
// the bias (2; null = none), at flange orientation R_base_flange (a function of the
// parameters too, e.g. of a clock offset: InclinometerReadingOfT).
template <typename T>
Eigen::Matrix<T, 2, 1> InclinometerReadingOfT(const Eigen::Matrix<T, 3, 3>& R_base_flange, const Mat3& R_flange_incl,
                                              const T* misalignment, const T* bias) {
  Eigen::Matrix<T, 3, 3> M = Eigen::Matrix<T, 3, 3>::Identity();
  if (misalignment) ceres::AngleAxisToRotationMatrix(misalignment, M.data());
  const Eigen::Matrix<T, 3, 3> R_base_incl = R_base_flange * M * R_flange_incl.cast<T>();
  // up in the sensor frame = row 2 of R_base_incl; tilt_k = asin(e_k . up).
  using std::asin;
  Eigen::Matrix<T, 2, 1> tilt(asin(R_base_incl(2, 0)), asin(R_base_incl(2, 1)));
  if (bias) {
    tilt[0] += bias[0];
    tilt[1] += bias[1];
  }
  return tilt;
}
template <typename T>
Eigen::Matrix<T, 2, 1> InclinometerReadingT(const Mat3& R_base_flange, const Mat3& R_flange_incl,
                                            const T* misalignment, const T* bias) {
  return InclinometerReadingOfT<T>(R_base_flange.cast<T>(), R_flange_incl, misalignment, bias);
}

// A sensor's time stamp on the reference clock: clock_offset t + p0; clock_drift
// t + p0 + p1 (t - t0).
template <typename T>
T ReferenceTimeT(const Extension& e, const T* p, double t, double t0) {
  if (e.effect == Effect::kClockOffset) return T(t) + p[0];
  if (e.effect == Effect::kClockDrift) return T(t) + p[0] + p[1] * (t - t0);
  return T(t);
}

}  // namespace mcms
