// The paper's lab experiment (section 3.4) as a forward model: a KUKA KR 5 arc carries
// the five-ball target and an inclinometer on its flange to 76 points on a sphere of
// radius 200 mm, dwelling 7 s at each; the camera rig, the robot controller and the
// inclinometer record at their own rates.
//
// Frames: `base` is the robot base (z up, gravity along -z); the rig's frame is placed by
// T_base_rig (known: the registration is taken as calibrated); the target sits on the
// flange at T_flange_target. The truth is the TRUE robot (nominal DH plus small parameter
// errors, the residual of a calibration) driven by the true joint angles; the robot
// "measures" itself with the NOMINAL model and noisy encoders, so its error is systematic
// per configuration, as a real robot's is. Its accuracy covariance (what a robot data sheet
// or a calibration report gives) is computed here by Monte Carlo over robots drawn from the
// same parameter-error distribution, so it is honest by construction.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "model/inclinometer.h"
#include "model/inverse_kinematics.h"
#include "model/robot_model.h"
#include "core/pose_math.h"
#include "synthetic/scenario.h"

namespace mcms {

struct LabOptions {
  int points = 76;
  double sphere_radius_m = 0.2;
  Vec3 sphere_centre_rig = Vec3(0.0, 0.0, 0.5);  // the centre of the rig's working volume
  double dwell_s = 7.0;
  double move_s = 1.0;             // joint-space move between points
  double camera_rate_hz = 1.0;     // frames rendered (the rig itself may run faster)
  double robot_rate_hz = 50.0;     // controller (encoder) rate
  double orientation_spread_deg = 15.0;  // the flange orientation varies by this much over the points
  // Residual kinematic errors of the true robot (1 sigma per DH parameter).
  double dh_length_sigma_m = 5e-5;
  double dh_angle_sigma_rad = 5e-5;
  Inclinometer inclinometer;       // paper: 0.01 deg, 20 ms
  uint64_t seed = 7;
  bool IsValid(std::string* why) const;
};

struct LabScenario {
  LabOptions options;
  Scenario vision;                 // rig, target, camera frame times, true T_rig_target, render settings
  RobotModel nominal, truth;
  Pose T_base_rig, T_flange_target;
  std::vector<Eigen::VectorXd> q_points;      // true joints at each point
  std::vector<double> dwell_start_s, dwell_end_s;
  std::vector<int> point_of_frame;            // camera frame -> point (-1 while moving)
  std::vector<double> robot_t;                // controller samples
  std::vector<Eigen::VectorXd> robot_q;       // encoder readings
  std::vector<double> incl_t;                 // inclinometer samples
  std::vector<Vec2> incl_reading;
  Mat6 robot_accuracy_cov = Mat6::Zero();     // [dtheta; dp] of nominal-model FK vs truth

  Eigen::VectorXd TrueJoints(double t) const;
  Pose TrueFlange(double t) const { return truth.T_base_flange(TrueJoints(t)); }
  double Duration() const;
};

// Builds the scenario: points, inverse kinematics of the nominal robot, the true robot,
// the three sensor streams and the camera frames (not rendered). InputError when the
// options are invalid or a point is out of reach.
LabScenario MakeLabScenario(const LabOptions& options = {});

}  // namespace mcms
