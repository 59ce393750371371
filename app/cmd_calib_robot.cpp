// mcms calib-robot: kinematic calibration of a serial robot from measured target
// positions or poses and joint values (calib/robot_calibration.h).
//
// Input: a measurement file (YAML) in one of two layouts:
//   mcms layout
//     measurements:
//       - {q_rad: [q1, ..., qn], position_m: [x, y, z]}                       # 3-D
//       - {q_deg: [...], position_m: [...], quaternion_wxyz: [w, x, y, z]}    # 6-D
//     (all entries 3-D or all 6-D; positions and orientations of the target in the
//      measuring system's frame `meas`; q within the robot's joint limits)
//   ROS-Industrial industrial_calibration kinematic measurements
//     <id>: {camera_joints: [], target_joints: [q1, ..], pose: {x, y, z, qw, qx, qy, qz}}
// and a robot description (model/robots/*.yaml format; default: the built-in KUKA KR 5
// arc) whose `tool` is the starting target offset T_flange_tool.
// Outputs (each written only after the whole calibration succeeded, atomically):
//   -o ROBOT.yaml    the calibrated robot (DH table, tool and, with --error-motion, the
//                    joints' error-motion harmonics)
//   --report FILE    the report (also printed): starting and final residuals, the
//                    registration T_meas_base, every parameter with its sigma, the fixed
//                    parameters with the reason, correlated pairs, k-fold held-out errors
//   --plot FILE.svg  position error per measurement before and after calibration, and
//                    FILE-joints.svg the same errors against each joint angle
#include <numbers>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "app/commands.h"
#include "jobs/robot_calibration_job.h"
#include "core/limits.h"
#include "core/error.h"
#include "core/io.h"

namespace mcms::app {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct CalibRobotArgs {
  std::string measurements, robot, output, report, plot, json, base_link, tip_link;
  std::vector<std::string> validate, estimate;
  std::vector<int> points;
  std::vector<double> base_guess, tool_guess;
  std::vector<std::string> fixed;
  std::vector<int> error_motion;
  double position_sigma_mm = 0.05, rotation_sigma_deg = 0.05;
  int folds = 5;
  int max_iterations = 200;
  bool registration_only = false, quiet = false, allow_poor_fit = false;
};

int RunCalibRobot(const CalibRobotArgs& a) {
  RobotCalibrationJob job;
  job.measurements = a.measurements;
  job.robot = a.robot;
  job.output = a.output;
  job.report = a.report;
  job.plot = a.plot;
  job.json = a.json;
  job.chain = {a.base_link, a.tip_link};
  job.points = a.points;
  job.estimate_only = a.estimate;
  for (const auto& v : a.validate) job.validate.push_back(v);
  if (!a.base_guess.empty()) job.base_guess = PoseFromArgs(a.base_guess, "calib-robot", "--base-guess");
  if (!a.tool_guess.empty()) {
    job.tool_guess = PoseFromArgs(a.tool_guess, "calib-robot", "--tool-guess");
    const double d = job.tool_guess->t.norm();
    if (d > kMaxToolOffsetM)
      Throw("calib-robot: --tool-guess puts the tool ", d, " m from the flange; expected at most ", kMaxToolOffsetM,
            " m (x y z in metres: ", d > 1000 * 0.01 && d < 1000 * kMaxToolOffsetM ? "millimetres?" : "mistyped?",
            ")");
  }
  job.fixed = a.fixed;
  job.error_motion_harmonics = a.error_motion;
  // From a laser interferometer's 0.1 um to a tape measure (issue 53: 1e-6 mm was taken and
  // ended as "did not converge", the cost beyond what the solver's tolerances resolve).
  if (!(a.position_sigma_mm >= 1e-4 && a.position_sigma_mm <= 1e3))
    Throw("calib-robot: --position-sigma-mm is ", a.position_sigma_mm,
          "; expected 1e-4 mm (an interferometer's 0.1 um) to 1000 mm");
  if (!(a.rotation_sigma_deg >= 1e-6 && a.rotation_sigma_deg <= 90))
    Throw("calib-robot: --rotation-sigma-deg is ", a.rotation_sigma_deg, "; expected 1e-6 to 90 deg");
  job.position_sigma_m = a.position_sigma_mm * 1e-3;
  job.rotation_sigma_rad = a.rotation_sigma_deg * kDeg;
  job.folds = a.folds;
  job.max_iterations = a.max_iterations;
  job.allow_poor_fit = a.allow_poor_fit;
  job.registration_only = a.registration_only;
  RunRobotCalibrationJob(job, CommandOutput("calib-robot", a.quiet));
  return 0;
}

const McmsCommand kCalibRobot([](CLI::App& app) {
  auto args = std::make_shared<CalibRobotArgs>();
  CLI::App* sub = app.add_subcommand("calib-robot", "Kinematic calibration of a robot from measured target poses");
  sub->description(
      "Identify DH parameter errors, the measuring system to base transform (T_meas_base) and the tool\n"
      "(target) offset from measured target positions or poses and joint values, by Levenberg-Marquardt.\n"
      "Parameters that the poses cannot separate (e.g. joint 1's theta offset vs the base yaw) are held\n"
      "and listed with the reason.\n"
      "MEASUREMENTS (YAML), either\n"
      "  measurements:\n"
      "    - {q_rad: [q1, .., qn], position_m: [x, y, z]}          3-D (q_deg also accepted)\n"
      "    - {q_rad: [..], position_m: [..], quaternion_wxyz: [w, x, y, z]}   6-D\n"
      "  (positions/orientations of the target in the measuring frame; all 3-D or all 6-D), or the\n"
      "  ROS-Industrial industrial_calibration layout  <id>: {camera_joints: [], target_joints: [..],\n"
      "  pose: {x, y, z, qw, qx, qy, qz}}.\n"
      "The robot file's tool (or --tool-guess) starts the tool offset; without --base-guess the\n"
      "registration starts from a rigid fit of the nominal tool positions to the measured ones.\n"
      "Writes the calibrated robot (-o), the report (stdout and --report) and an SVG of the error per\n"
      "measurement (--plot). Nothing is written when the calibration fails.");
  sub->add_option("MEASUREMENTS", args->measurements,
                  "Measurement file: CSV (time, joint columns q1_rad.. or the robot's joint names, x_m,y_m,z_m or "
                  "x1,y1,z1..xK,yK,zK of K points of one rigid body; model/robot_measurements.h) or YAML")
      ->required()
      ->check(CLI::ExistingFile);
  sub->add_option("--robot", args->robot, "Robot description: YAML or URDF (default: built-in KUKA KR 5 arc)")
      ->check(CLI::ExistingFile);
  sub->add_option("--base-link", args->base_link, "URDF: the chain's base link (default: the URDF's root)");
  sub->add_option("--tip-link", args->tip_link,
                  "URDF: the chain's tip link, where the measured points are fixed (default: the unambiguous leaf)");
  sub->add_option("-o,--output", args->output,
                  "Calibrated robot to write (required): FILE.urdf (for a URDF robot: its URDF with the corrections "
                  "folded into the joints' <origin>, each with its sigma in a comment) or FILE.yaml")
      ->type_name("FILE");
  sub->add_option("--json", args->json, "Machine-readable report (parameters, residuals per point, validation)")
      ->type_name("FILE");
  sub->add_option("--points", args->points,
                  "Use only these points of a rigid body (1-based, e.g. 1 for FIGAROH's point-1 protocol; default: all)")
      ->delimiter(',');
  sub->add_option("--estimate", args->estimate,
                  "Estimate only these geometric parameters (globs, e.g. 'arm_[2-6]_joint.offset' or '*.offset'); the "
                  "registration is always fitted")
      ->delimiter(',');
  sub->add_option("--validate", args->validate,
                  "Other sessions (one or more files): scored with the robot frozen, the instrument placed anew per "
                  "station or where it moved; mean, median, RMS, 95 % and max per point and posture group")
      ->check(CLI::ExistingFile)
      ->expected(1, -1);
  sub->add_option("--report", args->report, "Also write the report to this file")->type_name("FILE");
  sub->add_option("--plot", args->plot, "SVG plot of the error per measurement (and FILE-joints.svg: against each joint angle)")->type_name("FILE.svg");
  sub->add_option("--base-guess", args->base_guess, "Starting T_meas_base: x y z qw qx qy qz")->expected(7);
  sub->add_option("--tool-guess", args->tool_guess, "Starting T_flange_tool: x y z qw qx qy qz")->expected(7);
  sub->add_option("--position-sigma-mm", args->position_sigma_mm, "Measurement noise per axis, mm (default 0.05)")
      ->check(PositiveNumber());
  sub->add_option("--rotation-sigma-deg", args->rotation_sigma_deg,
                  "Orientation noise per axis, deg (default 0.05; 6-D only)")
      ->check(PositiveNumber());
  sub->add_option("--fix", args->fixed, "Hold these parameters (e.g. A2.a base.z tool.rx)");
  sub->add_option("--folds", args->folds, "k-fold held-out validation (default 5; 0 = none)")->check(NonNegativeNumber());
  sub->add_option("--max-iterations", args->max_iterations, "Solver iterations (default 200)")
      ->check(PositiveNumber());
  sub->add_option("--error-motion", args->error_motion,
                  "Error-motion harmonics to estimate per joint, one count each (e.g. 0 3: joint 2's angle-dependent\n"
                  "tilt, radial, axial and angular errors to the 3rd harmonic; model/robot_model.h)")
      ->delimiter(',')
      ->type_name("H1 H2 ..");
  sub->add_flag("--registration-only", args->registration_only, "Fit only base and tool, DH held nominal");
  sub->add_flag("--quiet", args->quiet, "No progress on stderr");
  sub->add_flag("--allow-poor-fit", args->allow_poor_fit,
                "Write a calibration that did not converge, misses the measurements by more than 2 % of the robot's "
                "reach or fits worse than the nominal model registered, with a warning (default: refused, nothing "
                "written)");
  return std::make_pair(sub, Runner([args] { return RunCalibRobot(*args); }));
});

}  // namespace
}  // namespace mcms::app
