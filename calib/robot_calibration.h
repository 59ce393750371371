// Kinematic calibration of a serial robot (paper section 3.2, issue 4): identification of
// DH parameter errors, the measurement-to-base transform and the tool (target) offset from
// measured target positions (3-D) or full poses (6-D) and the joint values, by
// Levenberg-Marquardt in Ceres; identifiability analysis (which parameters or combinations
// the poses cannot separate, and which are therefore held fixed, with the reason); the
// parameter covariance and strongly correlated pairs; held-out validation; pose selection.
//
// Frames: `meas` is the measuring system's frame (the camera rig, a laser tracker, a
// static sensor). The model predicts
//     T_meas_tool(q) = T_meas_base * T_base_flange(q; DH) * T_flange_tool,
// and a measurement is the measured position p_meas of the tool (target) origin and,
// for 6-D measurements, its orientation R_meas_tool.
//
// A measurement of K >= 3 points of one rigid body (model/robot_measurements.h) predicts
// each: point 1 at the tool origin, point k at T_flange_tool * p_k with p_k unknown.
//
// Parameter vector (SI: rad and m), in this order; `CalibrationParameterNames` gives the
// names used in reports and in RobotCalibrationOptions::fixed / estimate_only:
//   per joint i (name J): the geometric error model of model/joint.h:
//          DH   J.theta_offset, J.d, J.a, J.alpha      (errors added to the DH table)
//          URDF J.offset, J.x, J.y, J.z, J.rx, J.ry, J.rz  (zero offset, placement error)
//   base:  base.rx, base.ry, base.rz (rotation, left perturbation in the meas frame:
//          R = Exp(r) R_hat), base.x, base.y, base.z (translation in the meas frame)
//   tool:  tool.rx, tool.ry, tool.rz (R = Exp(r) R_hat in the flange frame), tool.x, tool.y, tool.z
//   points 2..K of a rigid body: point<k>.x, .y, .z (errors of p_k in the tool frame)
//   then, for each joint i with RobotCalibrationOptions::error_motion_harmonics[i] = H > 0,
//   for h = 1..H: J.em<h>.sin.{rx,ry,rz,x,y,z}, J.em<h>.cos.{rx,ry,rz,x,y,z}
//          (errors added to the joint's error motion, model/robot_model.h: a model
//          extension beyond DH for rotary axes whose motion is not a perfect rotation)
// This is the project's [dtheta; dp] layout for both transforms (docs/conventions.md).
//
// Identifiability: the Jacobian of the whitened residuals w.r.t. all parameters is
// evaluated at the starting values, each column scaled to unit norm, and the columns are
// taken greedily in a fixed priority order (base, tool, points, then the joints from the
// base out; a rank-revealing QR in that order, as FIGAROH and Khalil reduce to the base
// parameters);
// a column whose distance from the span of the columns already taken is below
// `identifiability_tolerance` is held at its starting value, and the report names the
// kept parameters it is (numerically) a combination of. With the base and the tool first,
// this fixes e.g. the first joint's theta offset (= base yaw about axis 1) and d (= base
// translation along axis 1), one of d_i/d_{i+1} for parallel consecutive axes in standard
// DH, and the last joint's parameters that duplicate the tool transform.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "model/identifiability.h"
#include "model/robot_measurements.h"
#include "core/pose_math.h"
#include "model/robot_model.h"

namespace ceres {
class CostFunction;
}

namespace mcms {

struct RobotCalibrationOptions {
  // One standard deviation of the measurement noise per axis: position (m) and
  // orientation (rad, per rotation-vector component). Residuals are divided by them.
  double position_sigma_m = 5e-5;
  double rotation_sigma_rad = 1e-3;
  bool estimate_dh = true;    // false: registration only (base and tool with nominal DH and error motion)
  // Error-motion harmonics to estimate per joint (empty = none; else one count per joint,
  // 0..8, > 0 only for revolute joints). Analyzed after the DH parameters, so the
  // terms that duplicate the DH table or the tool (e.g. the sine/cosine pair of a first
  // harmonic that is a constant offset in the rotating frame) are held with that reason.
  std::vector<int> error_motion_harmonics;
  bool estimate_base = true;
  bool estimate_tool = true;
  // Parameter names (see the header comment) held at their starting value by request.
  std::vector<std::string> fixed;
  // Parameters held as weakly identifiable (name -> reason), by the calibration itself: a
  // geometric parameter whose sigma at the solution exceeds what a placement could be off
  // (model/robot_model.h WeakGeometrySigma) is held at nominal and the problem solved again.
  std::vector<std::pair<std::string, std::string>> held_weak;
  // When not empty: only the geometric and error-motion parameters whose names match one of
  // these patterns (shell globs: "arm_[2-6]_joint.offset", "*.offset") are estimated, with
  // the registration (base, tool, points); the others are held at their starting value.
  std::vector<std::string> estimate_only;
  // Relative distance (0..1) of a scaled Jacobian column from the span of the columns
  // kept before it below which the parameter counts as not identifiable.
  double identifiability_tolerance = 1e-6;
  // When true, a parameter that this pose set cannot identify although well-spread poses
  // would (i.e. not a structural redundancy of the model) is an InputError naming it and
  // the joint ranges covered; when false it is held and reported like the structural ones.
  bool require_pose_identifiability = true;
  double correlation_threshold = 0.95;  // report pairs with |rho| above this
  int max_iterations = 200;
  // When true the covariance is scaled by the a-posteriori variance factor
  // (chi^2 / degrees of freedom), i.e. the sigmas above need only be right relatively.
  bool scale_covariance = true;
  // Called after each solver iteration with (iteration, cost); may be empty.
  std::function<void(int, double)> progress;
  bool IsValid(std::string* why) const;
};

// Whether `name` matches the shell glob `pattern` (*, ?, [..]).
bool GlobMatch(const std::string& pattern, const std::string& name);

struct CalibrationParameter {
  std::string name;
  double initial = 0.0;   // starting value of the error parameter (0 for the DH errors)
  double estimate = 0.0;  // identified value (= initial when fixed)
  double sigma = 0.0;     // standard deviation (0 when fixed)
  bool fixed = false;
  bool requested = false; // fixed by request (fixed, estimate_only, registration only), not by the analysis
  bool angle = false;     // rad (an angle) or m (a length): how reports print it
  std::string reason;     // why it was fixed; empty when estimated
};

struct CorrelatedPair {
  std::string a, b;
  double rho = 0.0;
};

// Prediction error of one measurement: predicted minus measured, in the meas frame.
struct PoseError {
  Vec3 dp = Vec3::Zero();                 // m, point 1
  std::vector<Vec3> other_dp;             // m, points 2..K of a rigid body
  std::optional<double> rotation_rad;     // angle of R_pred R_meas^T (6-D only)
  double position() const { return dp.norm(); }
  // Point k (0-based).
  const Vec3& Point(int k) const { return k == 0 ? dp : other_dp[k - 1]; }
};

struct ErrorStats {
  double mean_position_m = 0.0, rms_position_m = 0.0, max_position_m = 0.0;
  std::optional<double> mean_rotation_rad, rms_rotation_rad, max_rotation_rad;
};
ErrorStats Summarize(const std::vector<PoseError>& errors);
// The same for point k (0-based) of a rigid body, over the rows `rows` (empty: all).
ErrorStats SummarizePoint(const std::vector<PoseError>& errors, int k, const std::vector<int>& rows = {});

struct RobotCalibrationResult {
  RobotModel robot;       // calibrated DH table and tool
  Pose T_meas_base;       // calibrated registration
  std::vector<Vec3> points_tool;  // points 2..K of the rigid body in the tool frame (empty: one point)
  std::vector<CalibrationParameter> parameters;  // all of the layout, in its order
  // Covariance of the free parameters (SI), in the order of `free_parameters`.
  Eigen::MatrixXd covariance;
  std::vector<int> free_parameters;  // indices into `parameters`
  std::vector<CorrelatedPair> correlated;
  std::vector<PoseError> errors_before, errors_after;  // fitting set, starting vs final model
  double variance_factor = 1.0;   // chi^2 / dof of the final fit
  // Smallest singular value of the whitened Jacobian over the free parameters with its
  // columns scaled to unit norm, / sqrt(measurements): the observability index of
  // ObservabilityIndex (larger = better conditioned).
  double observability = 0.0;
  int iterations = 0;
  // Ceres converged, or settled: its cost (half the chi-square of the residuals whitened by
  // the position and rotation sigmas) changed by less than kSettledCostChange over the last
  // 10 iterations, a hundredth of what moving any parameter by one sigma changes (an
  // ill-conditioned problem crawls along a flat direction within Ceres' tight tolerances).
  bool converged = false;
  static constexpr double kSettledCostChange = 0.01;
  // |cost 10 iterations before the end - final cost| (inf with 10 or fewer iterations).
  double last_cost_change = std::numeric_limits<double>::infinity();
  std::vector<const CalibrationParameter*> Fixed() const;
};

// Names of the parameters in the layout order (the geometric parameters, 12, 3 (K - 1) for
// K points of a rigid body, then the error-motion terms that `options` asks for).
// The calibration's cost of one measurement: one parameter block of the layout above (all
// parameters, errors relative to the starting values), 3 or 6 residuals whitened by the
// options' sigmas; base0 is the starting T_meas_base, the tool starts at the robot's, the
// points 2..K of a rigid body at points0 (tool frame). Exposed so that its derivatives can
// be checked against numeric ones.
std::unique_ptr<ceres::CostFunction> MakeRobotMeasurementCost(const RobotModel& robot, const Pose& base0,
                                                               const RobotMeasurement& m,
                                                               const RobotCalibrationOptions& options,
                                                               const std::vector<Vec3>& points0 = {});
int NumCalibrationParameters(const RobotModel& robot, const RobotCalibrationOptions& options, int num_points = 1);

std::vector<std::string> CalibrationParameterNames(const RobotModel& robot,
                                                   const RobotCalibrationOptions& options = {}, int num_points = 1);
// The model with error-motion errors added: `harmonics` as in the options, delta with
// 12 values per harmonic (sin then cos, [rx ry rz x y z]) in joint order.
RobotModel WithErrorMotionErrors(const RobotModel& robot, const std::vector<int>& harmonics,
                                 const Eigen::VectorXd& delta);
// Predicted T_meas_tool for each measurement compared with the measurement; for a rigid body
// every point (points 2..K at points_tool in the tool frame).
std::vector<PoseError> PredictionErrors(const RobotModel& robot, const Pose& T_meas_base,
                                        const std::vector<RobotMeasurement>& measurements,
                                        const std::vector<Vec3>& points_tool = {});


// Identifies the parameters (see the header comment). `robot` holds the nominal DH table
// and the starting tool; `T_meas_base_guess` the starting registration; the points 2..K of a
// rigid body start where the nominal model and the first rows put them. With geometric
// parameters to estimate, the registration (base, tool, points) is fitted first with the
// geometry nominal, and the identifiability analysis and the solve start from there; the
// base and tool parameters are then corrections of that registration.
// InputError: joint counts differ from the robot's, joint values out of limits, mixed 3-D
// and 6-D measurements, too few measurements for the free parameters, parameters that
// these poses cannot separate but other poses would (require_pose_identifiability), or a
// singular problem; each message says what is missing and what would fix it.
RobotCalibrationResult CalibrateRobot(const RobotModel& robot, const Pose& T_meas_base_guess,
                                      const std::vector<RobotMeasurement>& measurements,
                                      const RobotCalibrationOptions& options);

// k-fold cross-validation: each measurement is predicted by a model fitted without its
// fold (fold of measurement i = i mod k). `nominal` holds the errors of the nominal DH
// table registered (base and tool fitted) on the same training folds, the fair baseline.
struct CrossValidation {
  std::vector<PoseError> calibrated, nominal;
};
CrossValidation CrossValidateRobot(const RobotModel& robot, const Pose& T_meas_base_guess,
                                   const std::vector<RobotMeasurement>& measurements,
                                   const RobotCalibrationOptions& options, int folds);


// Greedy pose selection: picks k of the candidate joint vectors, each step the one that
// most improves the column-normalized information matrix of the identifiable parameters
// (the identifiability analysis runs on all candidates first): log det (D-optimal) while
// fewer residuals than parameters are chosen, then its smallest eigenvalue, i.e. the
// observability index below (E-optimal). Returns the
// indices in the order chosen. `six_dof` says whether orientation will be measured.
std::vector<int> SelectPoses(const RobotModel& robot, const Pose& T_meas_base,
                             const std::vector<Eigen::VectorXd>& candidates, int k, bool six_dof,
                             const RobotCalibrationOptions& options);

// Observability index of a pose set: smallest singular value of the whitened, column-
// normalized Jacobian over the parameters that the identifiability analysis keeps,
// divided by sqrt(number of measurements) so pose sets of different sizes compare.
double ObservabilityIndex(const RobotModel& robot, const Pose& T_meas_base,
                          const std::vector<Eigen::VectorXd>& poses, bool six_dof,
                          const RobotCalibrationOptions& options);

}  // namespace mcms
