#include "model/extensions.h"

#include <cmath>
#include <sstream>

#include "core/error.h"

namespace mcms {

const std::vector<EffectInfo>& EffectCatalog() {
  static const std::vector<EffectInfo> catalog = {
      {Effect::kJointOffset, "joint_offset", SensorKind::kRobot, "a constant offset of one joint's zero (rad or m)"},
      {Effect::kLinkLength, "link_length", SensorKind::kRobot, "one DH length a or d off (m)"},
      {Effect::kJointScale, "joint_scale", SensorKind::kRobot, "a gear-ratio error: the joint moves (1 + s) q"},
      {Effect::kGravityCompliance, "gravity_compliance", SensorKind::kRobot,
       "joint deflection proportional to the gravity torque of the links beyond it and the payload (compliance >= 0)"},
      {Effect::kThermalDrift, "thermal_drift", SensorKind::kRobot,
       "every link length grows by a relative amount: exponential warm-up in time, or linear in temperature"},
      {Effect::kBacklash, "backlash", SensorKind::kRobot,
       "a joint lags its motor-side encoder by half its backlash against the last move (backlash >= 0)"},
      {Effect::kErrorMotion, "error_motion", SensorKind::kRobot, "harmonic error motion of a rotary joint (ISO 230-7)"},
      {Effect::kLinkTwist, "link_twist", SensorKind::kRobot, "one DH twist alpha off (rad)"},
      {Effect::kGeometry, "geometry", SensorKind::kRobot,
       "every geometric parameter the data identify (a DH table's theta offset, d, a, alpha of each joint; a URDF "
       "chain's offsets and placement errors) at once"},
      {Effect::kLinkCompliance, "link_compliance", SensorKind::kRobot,
       "a link bends under the moment it carries: its frame tilts by c L M about each principal axis of its section "
       "(compliances >= 0, rad per N m^2; seen by a tilt sensor above it)"},
      {Effect::kSegmentPlay, "segment_play", SensorKind::kRobot,
       "play between telescopic segments: a tilt step with the sign of the moment the link carries (>= 0, rad); "
       "variant 1: the step grows as 1 / overlap^2 as the segments extend (>= 0, rad m^2 about x and y, and the "
       "overlap left at full extension, m)"},
      {Effect::kAxisTilt, "axis_tilt", SensorKind::kRobot,
       "a linear axis leans in proportion to its travel (angular error motion, rad per m in x and y; seen by a tilt "
       "sensor above it)"},
      {Effect::kCameraMoved, "camera_moved", SensorKind::kCamera, "the camera's pose in the rig moved (6 dof)"},
      {Effect::kFocalLength, "focal_length", SensorKind::kCamera, "both focal lengths scaled by 1 + s"},
      {Effect::kPrincipalPoint, "principal_point", SensorKind::kCamera, "the principal point shifted (px)"},
      {Effect::kRadialDistortion, "radial_distortion", SensorKind::kCamera, "k1 changed"},
      {Effect::kCameraTimeOffset, "camera_time_offset", SensorKind::kCamera, "the camera's images are late (s)"},
      {Effect::kPixelNoiseScale, "pixel_noise_scale", SensorKind::kCamera,
       "the pixel noise is a factor larger than the noise model says"},
      {Effect::kTargetGeometry, "target_geometry", SensorKind::kCamera,
       "a ball of the target is not where the target file says (m)"},
      {Effect::kInclinometerBias, "inclinometer_bias", SensorKind::kInclinometer, "a constant bias per axis (rad)"},
      {Effect::kInclinometerMisalignment, "inclinometer_misalignment", SensorKind::kInclinometer,
       "the sensor's mounting rotation on the flange is off (rad)"},
      {Effect::kClockOffset, "clock_offset", SensorKind::kClock, "a sensor's clock is offset (s)"},
      {Effect::kClockDrift, "clock_drift", SensorKind::kClock, "a sensor's clock is offset and runs at a rate 1 + r"},
  };
  return catalog;
}

const EffectInfo& Info(Effect e) {
  for (const EffectInfo& i : EffectCatalog())
    if (i.effect == e) return i;
  Throw("unknown effect ", static_cast<int>(e));
}

const char* Name(Effect e) { return Info(e).name; }

std::optional<Effect> EffectFromName(std::string_view name) {
  for (const EffectInfo& i : EffectCatalog())
    if (name == i.name) return i.effect;
  return std::nullopt;
}

int Extension::NumParameters() const {
  switch (effect) {
    case Effect::kThermalDrift: return variant == 0 ? 2 : 1;
    case Effect::kErrorMotion: return kErrorMotionParamsPerHarmonic * variant;
    case Effect::kGeometry: return variant;
    case Effect::kGravityCompliance: return variant == 0 ? 1 : variant;
    case Effect::kCameraMoved: return 6;
    case Effect::kPrincipalPoint:
    case Effect::kInclinometerBias:
    case Effect::kAxisTilt:
    case Effect::kLinkCompliance:
    case Effect::kClockDrift: return 2;
    case Effect::kInclinometerMisalignment: return variant == 1 ? 1 : 3;
    case Effect::kSegmentPlay: return variant == 1 ? 3 : 1;
    case Effect::kTargetGeometry: return 3;
    default: return 1;
  }
}

std::vector<std::string> Extension::ParameterNames() const {
  switch (effect) {
    case Effect::kJointOffset: return {"offset_rad"};
    case Effect::kLinkLength: return {"delta_m"};
    case Effect::kJointScale: return {"scale"};
    case Effect::kGravityCompliance: {
      if (variant == 0) return {"compliance_rad_per_Nm"};
      std::vector<std::string> names;
      const int n = (variant - 1) / 2;
      for (int k = 1; k <= n; ++k) names.push_back(std::string("c_m_o").append(std::to_string(k)));
      for (int k = 1; k <= n; ++k) names.push_back(std::string("c_m_c").append(std::to_string(k)));
      names.push_back("c_m_tool");
      return names;
    }
    case Effect::kLinkTwist: return {"delta_rad"};
    case Effect::kGeometry: {
      // The robot's own names: GeometryParameterNames (model/robot_model.h).
      std::vector<std::string> names;
      for (int k = 1; k <= variant; ++k) {
        std::string name = std::to_string(k);  // (GCC 12 -Wrestrict misfires on "g" + ...)
        name.insert(0, "geometry_");
        names.push_back(name);
      }
      return names;
    }
    case Effect::kThermalDrift:
      return variant == 0 ? std::vector<std::string>{"growth", "time_constant_s"}
                          : std::vector<std::string>{"growth_per_K"};
    case Effect::kBacklash: return {"backlash_rad"};
    case Effect::kLinkCompliance: return {"compliance_x_rad_per_Nm2", "compliance_y_rad_per_Nm2"};
    case Effect::kSegmentPlay:
      return variant == 1 ? std::vector<std::string>{"play_x_rad_m2", "play_y_rad_m2", "overlap_at_full_extension_m"}
                          : std::vector<std::string>{"play_rad"};
    case Effect::kAxisTilt: return {"tilt_x_rad_per_m", "tilt_y_rad_per_m"};
    case Effect::kErrorMotion: {
      std::vector<std::string> names;
      const char* axes[6] = {"rx", "ry", "rz", "x", "y", "z"};
      for (int h = 1; h <= variant; ++h)
        for (const char* f : {"sin", "cos"})
          for (const char* a : axes) names.push_back(std::string(f) + std::to_string(h) + "_" + a);
      return names;
    }
    case Effect::kCameraMoved: return {"rx_rad", "ry_rad", "rz_rad", "x_m", "y_m", "z_m"};
    case Effect::kFocalLength: return {"relative_change"};
    case Effect::kPrincipalPoint: return {"dcx_px", "dcy_px"};
    case Effect::kRadialDistortion: return {"dk1"};
    case Effect::kCameraTimeOffset: return {"offset_s"};
    case Effect::kPixelNoiseScale: return {"scale"};
    case Effect::kTargetGeometry: return {"dx_m", "dy_m", "dz_m"};
    case Effect::kInclinometerBias: return {"bias_x_rad", "bias_y_rad"};
    case Effect::kInclinometerMisalignment:
      return variant == 1 ? std::vector<std::string>{"rz_rad"} : std::vector<std::string>{"rx_rad", "ry_rad", "rz_rad"};
    case Effect::kClockOffset: return {"offset_s"};
    case Effect::kClockDrift: return {"offset_s", "rate"};
  }
  return {};
}

std::vector<double> Extension::InitialParameters() const {
  std::vector<double> p(NumParameters(), 0.0);
  if (effect == Effect::kThermalDrift && variant == 0) p[1] = 1800.0;
  if (effect == Effect::kPixelNoiseScale) p[0] = 1.0;
  if (effect == Effect::kSegmentPlay && variant == 1) p[2] = 0.2;  // a fifth of a metre of overlap left, to start
  return p;
}

std::string Extension::Where(const std::vector<std::string>& camera_names) const {
  switch (Info(effect).sensor) {
    case SensorKind::kRobot:
      if (effect == Effect::kThermalDrift) return "robot";
      if (effect == Effect::kGeometry) return "DH table";
      if (effect == Effect::kLinkLength) return std::string(variant == 0 ? "a" : "d") + std::to_string(index + 1);
      if (effect == Effect::kLinkTwist) return "alpha" + std::to_string(index + 1);
      return "joint " + std::to_string(index + 1);
    case SensorKind::kCamera:
      if (effect == Effect::kTargetGeometry) return "ball " + std::to_string(index + 1);
      if (index >= 0 && index < static_cast<int>(camera_names.size())) return camera_names[index];
      return index >= 0 ? "camera " + std::to_string(index + 1) : "cameras";
    case SensorKind::kInclinometer: return "inclinometer";
    case SensorKind::kClock: return index >= 0 ? "sensor " + std::to_string(index + 1) : "clock";
  }
  return "";
}

std::string Extension::Where(const RobotModel& robot) const {
  const bool joint = Info(effect).sensor == SensorKind::kRobot && effect != Effect::kThermalDrift &&
                     effect != Effect::kGeometry && effect != Effect::kLinkLength && effect != Effect::kLinkTwist;
  if (joint && robot.Convention() == ChainConvention::kUrdf && index >= 0 && index < robot.NumJoints() &&
      !robot.Joints()[index].name.empty())
    return robot.Joints()[index].name;
  if (effect == Effect::kGeometry && robot.Convention() == ChainConvention::kUrdf) return "URDF chain";
  return Where();
}

std::string Extension::Label(const RobotModel& robot) const { return std::string(Name(effect)) + " at " + Where(robot); }

std::string Extension::Label(const std::vector<std::string>& camera_names) const {
  return std::string(Name(effect)) + " at " + Where(camera_names);
}

void Extension::Check(const RobotModel* robot, int num_cameras, int num_balls) const {
  const EffectInfo& info = Info(effect);
  const auto bad = [&](const std::string& what) { Throw("extension ", info.name, ": ", what); };
  switch (effect) {
    case Effect::kJointOffset:
    case Effect::kJointScale:
    case Effect::kGravityCompliance:
    case Effect::kBacklash:
    case Effect::kErrorMotion:
    case Effect::kLinkLength:
    case Effect::kLinkTwist:
    case Effect::kLinkCompliance:
    case Effect::kSegmentPlay:
    case Effect::kAxisTilt:
      if (!robot) bad("needs a robot");
      if (index < 0 || index >= robot->NumJoints())
        bad("joint index " + std::to_string(index) + " is outside the robot's " +
            std::to_string(robot->NumJoints()) + " joints");
      if (effect == Effect::kLinkLength && variant != 0 && variant != 1) bad("variant must be 0 (a) or 1 (d)");
      if (effect == Effect::kErrorMotion && variant < 1) bad("needs at least one harmonic");
      if ((effect == Effect::kLinkLength || effect == Effect::kLinkTwist) &&
          robot->Convention() == ChainConvention::kUrdf)
        bad("is a DH term; a URDF joint's lengths and twists are in its placement (geometry)");
      if (effect == Effect::kErrorMotion && robot->Joints()[index].type != JointType::kRevolute)
        bad("error motion is for revolute joints");
      if (effect == Effect::kSegmentPlay && variant == 1 &&
          !(robot->Joints()[index].type == JointType::kPrismatic && std::isfinite(robot->Joints()[index].upper)))
        bad("telescopic play is for a prismatic joint with an upper limit");
      if (effect == Effect::kGravityCompliance && variant != 0 && variant != 2 * robot->NumJoints() + 1)
        bad("variant must be 0 (the robot's masses) or 2 n + 1 (lumped masses)");
      break;
    case Effect::kGeometry:
      if (!robot) bad("needs a robot");
      if (variant != robot->NumGeometryParameters())
        bad("variant must be the robot's number of geometric parameters (" +
            std::to_string(robot->NumGeometryParameters()) + ")");
      break;
    case Effect::kThermalDrift:
      if (variant != 0 && variant != 1) bad("variant must be 0 (warm-up in time) or 1 (linear in temperature)");
      break;
    case Effect::kTargetGeometry:
      if (index < 0 || (num_balls > 0 && index >= num_balls))
        bad("ball index " + std::to_string(index) + " is outside the target's " + std::to_string(num_balls) + " balls");
      break;
    default:
      if (info.sensor == SensorKind::kCamera && num_cameras > 0 && (index < 0 || index >= num_cameras))
        bad("camera index " + std::to_string(index) + " is outside the rig's " + std::to_string(num_cameras) +
            " cameras");
      break;
  }
}

namespace {

// Torque on joint i (of a robot whose link frames are `frames`) of a force f at point p of
// link k (1-based; moved by joints 1..k).
void AddPointTorque(const RobotModel& robot, const std::vector<Pose>& frames, int k, const Vec3& p, const Vec3& f,
                    double scale, Eigen::Ref<Eigen::VectorXd> tau) {
  for (int i = 0; i < k && i < robot.NumJoints(); ++i) {
    const JointAxis ax = robot.AxisOf(frames, i);
    tau[i] += scale * (robot.Joints()[i].type == JointType::kRevolute ? ax.w.cross(p - ax.o).dot(f) : ax.w.dot(f));
  }
}

}  // namespace

Eigen::VectorXd GravityTorque(const RobotModel& robot, const Eigen::VectorXd& q, double payload_kg) {
  if (!robot.HasMasses())
    Throw("robot '", robot.Name(), "' gives no link masses (mass_kg per joint); its gravity torque is not known");
  const std::vector<Pose> frames = robot.LinkFrames(q);
  const Vec3 g(0.0, 0.0, -kStandardGravity);
  const int n = robot.NumJoints();
  Eigen::VectorXd tau = Eigen::VectorXd::Zero(n);
  for (int k = 1; k <= n; ++k) {
    const Joint& j = robot.Joints()[k - 1];
    if (j.mass_kg > 0) AddPointTorque(robot, frames, k, frames[k] * j.com_m, g, *j.mass_kg, tau);
  }
  const ToolMass& tm = robot.Tool();
  if (tm.mass_kg > 0) AddPointTorque(robot, frames, n, frames[n] * tm.com_m, g, tm.mass_kg, tau);
  if (payload_kg > 0) AddPointTorque(robot, frames, n, (frames[n] * robot.T_flange_tool()).t, g, payload_kg, tau);
  return tau;
}

Eigen::MatrixXd GravityLever(const RobotModel& robot, const Eigen::VectorXd& q) {
  const std::vector<Pose> frames = robot.LinkFrames(q);
  const Vec3 g(0.0, 0.0, -kStandardGravity);
  const int n = robot.NumJoints();
  const bool standard = robot.Convention() == ChainConvention::kStandard;
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(n, 2 * n + 1);
  for (int k = 1; k <= n; ++k) {
    AddPointTorque(robot, frames, k, frames[k].t, g, 1.0, L.col(k - 1));
    // The corner of link k's DH path: standard o_{k-1} + d_k z_{k-1} (on link k); modified
    // o_{k-1} + a_k x_{k-1} (fixed to link k-1); URDF: the middle of the straight link from
    // o_{k-1} to o_k (fixed to link k-1).
    const Joint& j = robot.Joints()[k - 1];
    if (robot.Convention() == ChainConvention::kUrdf) {
      AddPointTorque(robot, frames, k - 1, 0.5 * (frames[k - 1].t + frames[k].t), g, 1.0, L.col(n + k - 1));
    } else if (standard) {
      const double d = j.type == JointType::kRevolute ? j.d : j.d + q[k - 1];
      AddPointTorque(robot, frames, k, frames[k - 1] * Vec3(0.0, 0.0, d), g, 1.0, L.col(n + k - 1));
    } else {
      AddPointTorque(robot, frames, k - 1, frames[k - 1] * Vec3(j.a, 0.0, 0.0), g, 1.0, L.col(n + k - 1));
    }
  }
  AddPointTorque(robot, frames, n, (frames[n] * robot.T_flange_tool()).t, g, 1.0, L.col(2 * n));
  return L;
}

Vec3 CarriedMoment(const RobotModel& robot, const Eigen::VectorXd& q, int frame, double payload_kg) {
  if (!robot.HasMasses())
    Throw("robot '", robot.Name(), "' gives no link masses (mass_kg per joint); the moment its links carry is not known");
  const std::vector<Pose> frames = robot.LinkFrames(q);
  const int n = robot.NumJoints();
  if (frame < 0 || frame > n) Throw("link frame ", frame, " is outside the robot's frames 0..", n);
  const Vec3 g(0.0, 0.0, -kStandardGravity);
  const Vec3 o = frames[frame].t;
  Vec3 M = Vec3::Zero();
  for (int k = frame + 1; k <= n; ++k) {
    const Joint& j = robot.Joints()[k - 1];
    if (j.mass_kg > 0) M += (frames[k] * j.com_m - o).cross(*j.mass_kg * g);
  }
  const ToolMass& tm = robot.Tool();
  if (tm.mass_kg > 0) M += (frames[n] * tm.com_m - o).cross(tm.mass_kg * g);
  if (payload_kg > 0) M += ((frames[n] * robot.T_flange_tool()).t - o).cross(payload_kg * g);
  return M;
}

Eigen::VectorXd GravityTorquePerKg(const RobotModel& robot, const Eigen::VectorXd& q) {
  const std::vector<Pose> frames = robot.LinkFrames(q);
  const Vec3 p = frames.back().t;
  const Vec3 force(0.0, 0.0, -kStandardGravity);
  Eigen::VectorXd tau(robot.NumJoints());
  for (int i = 0; i < robot.NumJoints(); ++i) {
    const JointAxis ax = robot.AxisOf(frames, i);
    tau[i] = robot.Joints()[i].type == JointType::kRevolute ? ax.w.cross(p - ax.o).dot(force) : ax.w.dot(force);
  }
  return tau;
}

}  // namespace mcms
