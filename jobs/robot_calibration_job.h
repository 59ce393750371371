// The whole `mcms calib-robot` job as a library function: read the measurements, calibrate,
// compare with the registered nominal model and by k-fold held-out errors, write the
// report, the plot and the calibrated robot (the robot last; each file atomically; nothing
// when the calibration fails). The command only parses options and prints.
#pragma once

#include <numbers>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "calib/robot_calibration.h"
#include "jobs/job.h"
#include "core/pose_math.h"

namespace mcms {

struct RobotCalibrationJob {
  std::filesystem::path measurements;   // CSV or YAML (model/robot_measurements.h ReadRobotLog)
  std::filesystem::path robot;          // robot description (YAML or URDF); empty = the built-in default
  ChainSelection chain;                 // of a URDF robot
  // Calibrated robot (required): a URDF (.urdf, or whenever the robot was read from one: the
  // corrections folded into the joints' <origin>, each joint's parameters with sigma in a
  // comment beside it) or a YAML description.
  std::filesystem::path output;
  std::filesystem::path json;           // machine-readable report (optional)
  // Points of a rigid body to use (1-based; empty = every point of the file).
  std::vector<int> points;
  // Only these geometric parameters are estimated (globs, RobotCalibrationOptions::estimate_only).
  std::vector<std::string> estimate_only;
  // Other sessions in the same measuring frame, scored with the fitted models frozen.
  std::vector<std::filesystem::path> validate;
  // optional; with `plot` also the errors against each joint angle (JointPlotPath(plot))
  std::filesystem::path report, plot;
  std::optional<Pose> base_guess;       // T_meas_base; default: rigid fit of nominal tool positions
  std::optional<Pose> tool_guess;       // T_flange_tool; default: the robot file's tool
  std::vector<std::string> fixed;
  std::vector<int> error_motion_harmonics;
  double position_sigma_m = 0.05e-3;
  double rotation_sigma_rad = 0.05 * std::numbers::pi / 180.0;
  int folds = 5;                        // 0 = no held-out validation
  int max_iterations = 200;
  bool registration_only = false;
  // A calibration that did not converge, misses its measurements by more than 2 % of the
  // robot's reach (units or the wrong robot), or fits worse than the nominal model
  // registered (a wrong minimum) is refused and nothing is written, unless this is set (then
  // it is written with the warning in the report and on stderr).
  bool allow_poor_fit = false;
};

// Runs the job; out.print receives the report text (also written to `report` when given),
// out.progress (may be empty) its progress lines. InputError naming the input when anything
// is wrong; outputs are checked writable before the solve.
void RunRobotCalibrationJob(const RobotCalibrationJob& job, const JobOutput& out);

// Where the errors-against-joint-angle plot goes: "err.svg" -> "err-joints.svg".
std::filesystem::path JointPlotPath(const std::filesystem::path& plot);

// "translation_m [x, y, z], quaternion_wxyz [w, x, y, z]".
std::string PoseText(const Pose& T);
// Position (mm) and, when present, rotation (deg) mean, RMS and max.
std::string ErrorStatsText(const ErrorStats& s);

}  // namespace mcms
