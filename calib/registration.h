// Registration of the measuring system's frame (camera rig, `meas`) to the robot base:
// T_meas_base, so that p_meas = T_meas_base * p_base.
//
// (a) The paper's method (section 3.2): turn axis 1 alone, then axis 2 alone, while the
//     cameras measure the target; the target moves on a circle about each axis. A plane
//     fit gives each axis direction (the circle's normal, signed by the sense of the
//     joint motion), a circle fit in the plane gives a point on the axis (the centre).
//     With the axis directions known in both frames the rotation follows from the two
//     directions (for the paper's robot: z from axis 1, x from axis 2, y = z cross x), and
//     the translation from requiring the two centres to lie on the nominal axis lines.
// (b) A full least-squares fit of the base transform and the tool offset over all
//     measurements with the nominal kinematics (CalibrateRobot with estimate_dh = false).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "calib/robot_calibration.h"
#include "model/robot_model.h"
#include "core/pose_math.h"

namespace mcms {

struct PlaneFit {
  Vec3 centroid = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();  // unit; sign arbitrary
  double rms = 0.0;             // RMS distance of the points from the plane, m
};
// Total least squares plane (smallest principal axis). InputError for < 3 points or
// collinear points.
PlaneFit FitPlane(const std::vector<Vec3>& points);

struct CircleFit {
  Vec3 centre = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();  // unit, sign arbitrary (the plane's)
  double radius = 0.0;
  double rms = 0.0;  // RMS radial residual in the plane, m
};
// Plane fit, then the algebraic (Kasa) circle fit in that plane refined by Gauss-Newton
// on the geometric distances. InputError for < 3 points or a degenerate arc.
CircleFit FitCircle3D(const std::vector<Vec3>& points);

// One single-axis sweep: the joint vectors (only joint `axis` changes) and the measured
// target positions in the meas frame.
struct AxisSweep {
  int axis = 0;  // 0-based joint index
  std::vector<Eigen::VectorXd> q;
  std::vector<Vec3> p_meas;
};

struct CircleRegistration {
  Pose T_meas_base;
  CircleFit circle1, circle2;
  Vec3 axis1_meas = Vec3::Zero(), axis2_meas = Vec3::Zero();  // measured axis directions
};

// Method (a). The sweeps must turn two non-parallel revolute joints (normally axes 1 and 2);
// their nominal directions and positions in the base frame come from `robot` at the
// sweep's joint values. InputError on fewer than 3 points per sweep, a sweep that moves
// other joints, prismatic or parallel axes.
CircleRegistration RegisterByAxisCircles(const RobotModel& robot, const AxisSweep& sweep1, const AxisSweep& sweep2);

// Method (b): base and tool by least squares with the nominal DH table; `guess` starts
// the solver (InitialBaseGuess when nullopt).
RobotCalibrationResult RegisterLeastSquares(const RobotModel& robot, const std::vector<RobotMeasurement>& measurements,
                                            const RobotCalibrationOptions& options,
                                            const std::optional<Pose>& guess = std::nullopt);

}  // namespace mcms
