// Internal to the robot audit (audit/robot_audit.h): the likelihood problem and its fits.
//
// One parameter vector theta holds every candidate the audit may name: the registration
// (6: rotation vector, translation; meas frame), the tool (3, or 6 with its rotation), then
// one block per extension of the catalog (model/extensions.h), the identifiable geometry
// first. Every block's zero is the nominal model. The residuals of every row are
// linearised once at the nominal fit (one Jacobian, Ceres jets); a fit is iterated
// generalized least squares on that Jacobian with the noise covariance (m x m, unknown,
// profiled by maximum likelihood) re-estimated, and the exact nonlinear residuals
// re-evaluated until they agree. Cross-validation is by contiguous blocks of time.
#pragma once

#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "audit/robot_audit_types.h"
#include "model/robot_measurements.h"
#include "core/pose_math.h"
#include "model/extensions.h"
#include "model/robot_model.h"

namespace mcms::robot_audit {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

struct RowData {
  int station = 0;  // the row's placement of the robot in the instrument's frame
  Eigen::VectorXd q;
  MeasurementContext c;
  Vec3 p = Vec3::Zero();      // measured position (the point, or the rigid body's origin)
  Mat3 R = Mat3::Identity();  // measured orientation (6-D)
  // The rigid motion (base frame) the row's measured tilts give the tool (calib/
  // robot_validation.h MeasuredTiltCorrections; identity without tilt sensors).
  Pose tilt = Pose::Identity();
};

struct Problem {
  const RobotModel* robot = nullptr;
  Pose base0, tool0;
  bool six = false;
  int m = 3, N = 0, n = 0, ts = 3;
  double time_span = 1.0;
  // K >= 3 points of one rigid body measured in each row: the body's shape in its own frame
  // (the tool frame of the fit, the rows' measured poses from it); empty for one point.
  std::vector<Vec3> body_points;
  // The payload of the last row (kg; 0 without a payload column) and the factor on the
  // tool point's lumped mass (the payload, or 1 kg without a payload column).
  double payload = 0.0, payload_factor = 1.0;
  std::vector<RowData> rows;
  std::vector<Extension> blocks;
  std::vector<int> offset;  // first parameter of each block
  int P = 0;
  std::vector<double> lower, upper;             // per parameter: +-inf, or a physical bound
  int geometry = -1;                            // the geometry block
  int warmup = -1;                              // parameter index of the warm-up growth; -1 = none
  Eigen::VectorXd theta0;                       // the linearisation point (the nominal fit)
  std::vector<Eigen::MatrixXd> J;               // per residual component a: N x P at theta0
  Eigen::MatrixXd u;                            // N x m: residual change per unit uniform link growth
  int K = 0;  // folds: contiguous blocks of time within each station
  std::vector<std::vector<std::pair<int, int>>> fold_rows;  // per fold its rows, as ranges [begin, end)
  // Blocks of joint space (issue 51): K clusters of each station's postures (k-means on the
  // joint values, each joint scaled by its spread), fold k holding every station's k-th;
  // held out, a model is judged by how it predicts postures outside the region it was
  // fitted on (another session visits other postures).
  std::vector<std::vector<std::pair<int, int>>> posture_rows;
  std::vector<std::vector<Eigen::MatrixXd>> posture_G;
  std::vector<std::vector<Eigen::MatrixXd>> G;  // [fold][a * m + b] = J_a^T J_b over the fold
  std::vector<Eigen::MatrixXd> Gall;
  // Stations (issue 51): rows that share one placement of the robot in the instrument's
  // frame, each with its own registration: station 0's is theta[0..5], station s > 0's
  // 6 parameters at reg_extra + 6 (s - 1), after the blocks; station0 holds each one's
  // starting placement (station0[0] = base0).
  int S = 1;
  int reg_extra = -1;
  std::vector<Pose> station0;
  std::vector<std::string> station_names;
  int RegOffset(int s) const { return s == 0 ? 0 : reg_extra + 6 * (s - 1); }
  // Station 0's registration and the tool (the blocks start after them).
  int NumBase() const { return 6 + ts; }
  // Every registration and the tool: the parameters every model fits.
  std::vector<int> BaseParams() const;
  // Whether parameter p belongs to a block of the catalog (not a registration or the tool).
  bool IsBlockParam(int p) const { return p >= NumBase() && (reg_extra < 0 || p < reg_extra); }
};

// Rows as contiguous ranges [begin, end): all rows, a fold's test block, or its training rows.
struct RowSet {
  std::vector<std::pair<int, int>> ranges;
  int fold = -1;       // -1: all rows
  bool train = false;  // with fold >= 0: every row but the fold's (else the fold's)
  bool posture = false;  // the fold is a block of joint space (else of time)
  int Count() const {
    int c = 0;
    for (const auto& [b, e] : ranges) c += e - b;
    return c;
  }
};
RowSet AllRows(const Problem& pb);
RowSet TestRows(const Problem& pb, int f, bool posture = false);
RowSet TrainRows(const Problem& pb, int f, bool posture = false);

// Per joint: changes of a joint value no larger than this are the encoders' jitter, not a
// move (a repeat of the pose; no new move direction for backlash): the options'
// repeat_tolerance, or 6 sqrt(2) encoder sigmas of the robot file (two readings' jitter at
// six sigma), whichever is larger.
Eigen::VectorXd JitterTolerance(const RobotModel& robot, double repeat_tolerance);

// The rows of `log` with their covariates (move directions, gravity torques and levers,
// times from the log's start), the starting registration and tool, the folds. With
// `frozen` (the problem of a fitted log), the rows of another session for a frozen
// model: its registration and tool start, its rigid body's shape and its blocks.
Problem MakeProblem(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o,
                    const Problem* frozen = nullptr);
// The registration and the tool of the nominal model by maximum likelihood (Ceres; the
// noise re-estimated between solves); sets theta0's first NumBase() values. Returns the
// noise covariance.
Eigen::MatrixXd FitNominal(Problem* pb);
// The Jacobian of every row with respect to every parameter at theta0 (or at `at`), the
// uniform-growth direction and the Gram matrices of each fold. The blocks must be set (P,
// offset, theta0). Fits use it as the chord method's Jacobian from any start.
void Linearize(Problem* pb, const Eigen::VectorXd* at = nullptr);

// Predicted minus measured of one row at theta (position, m; and for 6-D the rotation
// vector of R_pred R_meas^T), and the predicted pose of the tool (the rigid body's frame).
void RowResidual(const Problem& pb, const RowData& row, const double* theta, double* e);
Pose PredictedTool(const Problem& pb, const RowData& row, const Eigen::VectorXd& theta);
// Exact (nonlinear) residuals of the rows of `set` at theta into R (N x m).
void Exact(const Problem& pb, const Eigen::VectorXd& th, const RowSet& set, Eigen::MatrixXd* R);

Eigen::MatrixXd MlCovariance(const Eigen::MatrixXd& R, const RowSet& set);
double LogDet(const Eigen::MatrixXd& S);
Eigen::MatrixXd WhiteningOf(const Eigen::MatrixXd& S);
// Per-row log-likelihood of the rows of `set` under N(0, S) into ll (size N); their sum.
double RowLogLik(const Eigen::MatrixXd& R, const Eigen::MatrixXd& S, const RowSet& set, Eigen::VectorXd* ll);
// Solves H d = r for a symmetric positive semi-definite H, scaled to unit diagonal first
// (the parameters differ by orders of magnitude); the minimum-norm solution when singular.
Eigen::VectorXd SolveScaled(const Eigen::MatrixXd& H, const Eigen::VectorXd& r);
Eigen::MatrixXd InverseScaled(const Eigen::MatrixXd& H);

struct FitResult {
  Eigen::VectorXd theta;
  std::vector<int> free;       // requested free parameters (base, tool, the model's terms)
  std::vector<char> at_bound;  // per free parameter: held at its physical bound (1 lower, 2 upper)
  Eigen::MatrixXd noise;       // m x m
  Eigen::MatrixXd R;           // N x m residuals (predicted - measured) of the fitted rows
  Eigen::VectorXd row_ll;      // N
  double loglik = -kInf;
  Eigen::MatrixXd cov;  // covariance of `free` (0 for those at a bound)
  bool nonlinear = false;  // solved by Gauss-Newton on the exact model (the one Jacobian did not converge)
};

// Column values of the free parameters F: the Jacobian, or the warm-up's column at the
// current time constant; the normal matrix, gradient and linear update of a fit.
struct Columns {
  const Problem& pb;
  const std::vector<int>& F;
  std::vector<int> stat;      // positions in F of static columns
  std::vector<int> stat_idx;  // their parameter indices
  int dyn = -1;               // position in F of the warm-up growth
  Eigen::MatrixXd c;          // N x m warm-up column
  Columns(const Problem& p, const std::vector<int>& f, const Eigen::VectorXd& th);
  // H = sum_ab W_ab J_a(set, F)^T J_b(set, F).
  Eigen::MatrixXd Normal(const RowSet& set, const Eigen::MatrixXd& W) const;
  // g = sum_a J_a(set, F)^T (R W)(set, a).
  Eigen::VectorXd Gradient(const RowSet& set, const Eigen::MatrixXd& W, const Eigen::MatrixXd& R) const;
  // R(set) += J(set, F) d.
  void Apply(const RowSet& set, const Eigen::VectorXd& d, Eigen::MatrixXd* R) const;
};

// The fit of the model whose free parameters are F, on the rows of `rows` (all rows when
// null), from `start`: the chord iterations on the one Jacobian, and where they do not
// converge or end below the start, Levenberg-Marquardt on the exact model. Never ends below
// `start` (issue 51: a model with more free parameters never fits worse than the one it
// extends).
FitResult FitModel(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start,
                   const Eigen::MatrixXd& noise_start, const RowSet* rows = nullptr);
// The same; with the warm-up's growth free, its time constant by the profile likelihood,
// with its standard deviation in *tau_sigma.
FitResult FitProfiled(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start,
                      const Eigen::MatrixXd& noise, double* tau_sigma = nullptr);
double SigmaOf(const FitResult& f, int param);
bool AtBound(const FitResult& f, int param);

// Held-out log-likelihood (summed), position RMS and per-row values of a model by the
// time-blocked folds, each fold's fit starting from the fit on all rows. The held-out
// residuals are scored under one noise covariance `metric` common to the models compared
// (the current model's): every catalog effect changes the predicted mean, and a noise
// covariance refitted on each fold's few rows (21 values for a pose) would score the
// folds' noise estimates instead (on a 37-posture log, 3, 5 or 9 folds turned one clear
// offset's gain from +104 to -22 to +7 nats).
struct HeldOut {
  double loglik = 0.0, rms = 0.0;
  Eigen::VectorXd row_ll;
};
HeldOut CrossValidate(const Problem& pb, const FitResult& all_fit, const Eigen::MatrixXd& metric,
                      bool posture = false);
// Whether a model with `params` free parameters can be cross-validated: every training set
// has at least twice as many residuals.
bool EnoughData(const Problem& pb, int params);

double PositionRms(const Eigen::MatrixXd& R);
std::vector<int> Union(std::vector<int> a, const std::vector<int>& b);
// Parameters a candidate adds: its terms, and the warm-up's profiled time constant.
int ParamCount(const Problem& pb, const std::vector<int>& terms);

}  // namespace mcms::robot_audit
