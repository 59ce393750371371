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
// and a robot description (calib/robots/*.yaml format; default: the built-in KUKA KR 5
// arc) whose `tool` is the starting target offset T_flange_tool.
// Outputs (each written only after the whole calibration succeeded, atomically):
//   -o ROBOT.yaml    the calibrated robot (DH table, tool and, with --error-motion, the
//                    joints' error-motion harmonics)
//   --report FILE    the report (also printed): starting and final residuals, the
//                    registration T_meas_base, every parameter with its sigma, the fixed
//                    parameters with the reason, correlated pairs, k-fold held-out errors
//   --plot FILE.svg  position error per measurement before and after calibration
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "app/commands.h"
#include "calib/registration.h"
#include "calib/robot_calibration.h"
#include "core/error.h"
#include "core/io.h"
#include "core/svg_plot.h"

namespace mcms::app {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

struct CalibRobotArgs {
  std::string measurements, robot, output, report, plot;
  std::vector<double> base_guess, tool_guess;
  std::vector<std::string> fixed;
  std::vector<int> error_motion;
  double position_sigma_mm = 0.05, rotation_sigma_deg = 0.05;
  int folds = 5;
  int max_iterations = 200;
  bool registration_only = false, quiet = false;
};

Pose PoseFromArgs(const std::vector<double>& v, const char* option) {
  if (v.size() != 7) Throw("calib-robot: ", option, " takes 7 numbers x y z qw qx qy qz (m, unit quaternion), got ", v.size());
  const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
  if (std::abs(q.norm() - 1.0) > 1e-3) Throw("calib-robot: ", option, " quaternion has norm ", q.norm(), ", expected 1");
  return Pose::FromQuaternion(q.normalized(), Vec3(v[0], v[1], v[2]));
}

std::string PoseText(const Pose& T) {
  const Eigen::Quaterniond q = T.Quaternion();
  std::ostringstream s;
  s.precision(9);
  s << "translation_m [" << T.t.x() << ", " << T.t.y() << ", " << T.t.z() << "], quaternion_wxyz [" << q.w() << ", "
    << q.x() << ", " << q.y() << ", " << q.z() << "]";
  return s.str();
}

std::string StatsText(const ErrorStats& s) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "position mean %.4f mm, RMS %.4f mm, max %.4f mm", s.mean_position_m * 1e3,
                s.rms_position_m * 1e3, s.max_position_m * 1e3);
  std::string out = buf;
  if (s.mean_rotation_rad) {
    std::snprintf(buf, sizeof buf, "; rotation mean %.5f deg, RMS %.5f deg, max %.5f deg", *s.mean_rotation_rad / kDeg,
                  *s.rms_rotation_rad / kDeg, *s.max_rotation_rad / kDeg);
    out += buf;
  }
  return out;
}

// A parameter in report units: mm for lengths, deg for angles.
std::string ValueText(const std::string& name, double v) {
  const bool angle = name.find("theta") != std::string::npos || name.find("alpha") != std::string::npos ||
                     name.find(".r") != std::string::npos;
  char buf[64];
  std::snprintf(buf, sizeof buf, angle ? "%+.5f deg" : "%+.4f mm", angle ? v / kDeg : v * 1e3);
  return buf;
}

int RunCalibRobot(const CalibRobotArgs& a) {
  if (a.output.empty()) Throw("calib-robot: the output robot file is missing; give -o ROBOT.yaml");
  RobotModel robot = a.robot.empty() ? RobotModel::Default() : RobotModel::Read(a.robot);
  if (!a.tool_guess.empty()) robot.SetT_flange_tool(PoseFromArgs(a.tool_guess, "--tool-guess"));
  // Refuse unwritable outputs before the solve, not after it.
  RequireWritableFile(a.output, "-o");
  if (!a.report.empty()) RequireWritableFile(a.report, "--report");
  if (!a.plot.empty()) RequireWritableFile(a.plot, "--plot");
  const std::vector<RobotMeasurement> ms = ReadRobotMeasurements(a.measurements);

  RobotCalibrationOptions opt;
  opt.position_sigma_m = a.position_sigma_mm * 1e-3;
  opt.rotation_sigma_rad = a.rotation_sigma_deg * kDeg;
  opt.fixed = a.fixed;
  opt.max_iterations = a.max_iterations;
  opt.estimate_dh = !a.registration_only;
  opt.error_motion_harmonics = a.error_motion;
  // Progress: the iteration count is not known in advance, so a line at most every half
  // second (long solves only) instead of a percentage.
  using Clock = std::chrono::steady_clock;
  auto last = Clock::now();
  if (!a.quiet)
    opt.progress = [&](int iteration, double cost) {
      if (Clock::now() - last < std::chrono::milliseconds(500)) return;
      last = Clock::now();
      std::fprintf(stderr, "calib-robot: iteration %d, cost %.6g\n", iteration, cost);
    };

  const Pose guess = a.base_guess.empty() ? InitialBaseGuess(robot, ms) : PoseFromArgs(a.base_guess, "--base-guess");
  const RobotCalibrationResult r = CalibrateRobot(robot, guess, ms, opt);
  if (!a.quiet)
    std::fprintf(stderr, "calib-robot: %s after %d iterations\n", r.converged ? "converged" : "stopped", r.iterations);

  // The fair baseline: the nominal DH table with base and tool fitted.
  RobotCalibrationOptions reg = opt;
  reg.estimate_dh = false;
  reg.error_motion_harmonics.clear();
  reg.progress = nullptr;
  const RobotCalibrationResult nominal = CalibrateRobot(robot, guess, ms, reg);

  std::optional<CrossValidation> cv;
  if (a.folds >= 2) {
    if (a.folds > static_cast<int>(ms.size()))
      Throw("calib-robot: --folds ", a.folds, " exceeds the ", ms.size(), " measurements; use fewer folds or 0");
    if (!a.quiet) std::fprintf(stderr, "calib-robot: %d-fold cross-validation\n", a.folds);
    RobotCalibrationOptions cv_opt = opt;
    cv_opt.progress = nullptr;
    cv = CrossValidateRobot(robot, guess, ms, cv_opt, a.folds);
  }

  std::ostringstream rep;
  rep << "# mcms calib-robot report\n";
  rep << "robot: " << robot.Name() << " (" << robot.NumJoints() << " joints)\n";
  rep << "measurements: " << ms.size() << " (" << (ms[0].R_meas_tool ? "6-D poses" : "3-D positions") << ") from "
      << a.measurements << "\n";
  rep << "solver: " << (r.converged ? "converged" : "did NOT converge") << " after " << r.iterations
      << " iterations; variance factor " << r.variance_factor << "; observability index " << r.observability << "\n";
  rep << "T_meas_base: " << PoseText(r.T_meas_base) << "\n";
  rep << "T_flange_tool: " << PoseText(r.robot.T_flange_tool()) << "\n";
  rep << "residuals, starting model:            " << StatsText(Summarize(r.errors_before)) << "\n";
  rep << "residuals, nominal DH registered:     " << StatsText(Summarize(nominal.errors_after)) << "\n";
  rep << "residuals, calibrated:                " << StatsText(Summarize(r.errors_after)) << "\n";
  if (cv) {
    rep << "held out (" << a.folds << "-fold), nominal DH: " << StatsText(Summarize(cv->nominal)) << "\n";
    rep << "held out (" << a.folds << "-fold), calibrated: " << StatsText(Summarize(cv->calibrated)) << "\n";
  }
  rep << "parameters (identified error, 1 sigma):\n";
  for (const auto& p : r.parameters) {
    if (p.fixed) continue;
    rep << "  " << p.name << ": " << ValueText(p.name, p.estimate) << " +- " << ValueText(p.name, p.sigma).substr(1)
        << "\n";
  }
  rep << "fixed parameters:\n";
  for (const auto* p : r.Fixed()) rep << "  " << p->name << ": " << p->reason << "\n";
  rep << "correlated pairs (|rho| > " << opt.correlation_threshold << "):" << (r.correlated.empty() ? " none" : "")
      << "\n";
  for (const auto& c : r.correlated) rep << "  " << c.a << " ~ " << c.b << ": rho " << c.rho << "\n";
  const std::string report = rep.str();

  // Everything computed: write the outputs, the robot model last, so that a failed
  // report or plot leaves no model behind (each file is written atomically).
  if (!a.report.empty()) WriteFileAtomically(a.report, [&](std::ostream& o) { o << report; });
  if (!a.plot.empty()) {
    Plot plot;
    plot.title = "Position error per measurement";
    plot.x_label = "measurement";
    plot.y_label = "position error (mm)";
    auto series = [&](const std::string& label, const std::vector<PoseError>& e, const std::string& color) {
      PlotSeries s;
      s.label = label;
      s.color = color;
      s.points = true;
      for (size_t i = 0; i < e.size(); ++i) {
        s.x.push_back(static_cast<double>(i + 1));
        s.y.push_back(e[i].position() * 1e3);
      }
      plot.series.push_back(s);
    };
    series("nominal DH, registered", nominal.errors_after, "#d62728");
    series("calibrated", r.errors_after, "#1f77b4");
    if (cv) series("calibrated, held out", cv->calibrated, "#2ca02c");
    plot.WriteSvg(a.plot);
  }
  r.robot.Write(a.output);
  std::fputs(report.c_str(), stdout);
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
  sub->add_option("MEASUREMENTS", args->measurements, "Measurement file (YAML)")->required()->check(CLI::ExistingFile);
  sub->add_option("--robot", args->robot, "Robot description YAML (default: built-in KUKA KR 5 arc)")
      ->check(CLI::ExistingFile);
  sub->add_option("-o,--output", args->output, "Calibrated robot YAML to write (required)")->type_name("FILE");
  sub->add_option("--report", args->report, "Also write the report to this file")->type_name("FILE");
  sub->add_option("--plot", args->plot, "SVG plot of the error per measurement")->type_name("FILE.svg");
  sub->add_option("--base-guess", args->base_guess, "Starting T_meas_base: x y z qw qx qy qz")->expected(7);
  sub->add_option("--tool-guess", args->tool_guess, "Starting T_flange_tool: x y z qw qx qy qz")->expected(7);
  sub->add_option("--position-sigma-mm", args->position_sigma_mm, "Measurement noise per axis, mm (default 0.05)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--rotation-sigma-deg", args->rotation_sigma_deg,
                  "Orientation noise per axis, deg (default 0.05; 6-D only)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--fix", args->fixed, "Hold these parameters (e.g. A2.a base.z tool.rx)");
  sub->add_option("--folds", args->folds, "k-fold held-out validation (default 5; 0 = none)")->check(CLI::NonNegativeNumber);
  sub->add_option("--max-iterations", args->max_iterations, "Solver iterations (default 200)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--error-motion", args->error_motion,
                  "Error-motion harmonics to estimate per joint, one count each (e.g. 0 3: joint 2's angle-dependent\n"
                  "tilt, radial, axial and angular errors to the 3rd harmonic; calib/robot_model.h)")
      ->delimiter(',')
      ->type_name("H1 H2 ..");
  sub->add_flag("--registration-only", args->registration_only, "Fit only base and tool, DH held nominal");
  sub->add_flag("--quiet", args->quiet, "No progress on stderr");
  return std::make_pair(sub, Runner([args] { return RunCalibRobot(*args); }));
});

}  // namespace
}  // namespace mcms::app
