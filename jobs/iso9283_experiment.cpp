#include "jobs/iso9283_experiment.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <functional>
#include <cstdio>
#include <set>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include "calib/robot_calibration.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/random.h"
#include "core/svg_plot.h"
#include "fusion/stream_fusion.h"
#include "model/robot_model.h"
#include "synthetic/lab_scenario.h"
#include "synthetic/scenario.h"
#include "tracking/pose_refinement.h"
#include "vision/sphere_projection.h"

namespace mcms {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr int kPoses = 5;
// Vertices of each ball's outline polygon for its image centroid: the centroid of a
// 64-gon differs from the exact one by far less than the 0.017 px noise.
constexpr int kOutlinePoints = 64;
// Samples of the Gaussian from which a predicted RP (mean + 3 std of |x - mean|) is taken.
constexpr int kRpSamples = 4000;
// Attained path runs are sampled this far (fraction of the path) beyond both ends, so each
// run crosses the normal planes of the first and last calculation points.
constexpr double kPathOvershoot = 0.05;

// What a controller believes (or what the world is): where the base stands in the rig
// frame and the kinematics including the tool.
struct Kinematics {
  RobotModel robot;  // T_flange_tool = the target on the flange
  Pose T_rig_base;
  // The true robot only: a joint-angle error no DH table describes, per joint
  // gear_amplitude_j sin(2 pi q_j / gear_period + gear_phase_j) (empty: none).
  Eigen::VectorXd gear_amplitude, gear_phase;
  double gear_period = 1.0;
  Eigen::VectorXd Effective(const Eigen::VectorXd& q) const {
    if (gear_amplitude.size() == 0) return q;
    Eigen::VectorXd e = q;
    for (int j = 0; j < q.size(); ++j)
      e[j] += gear_amplitude[j] * std::sin(2.0 * std::numbers::pi * q[j] / gear_period + gear_phase[j]);
    return e;
  }
  Pose Tool(const Eigen::VectorXd& q) const { return T_rig_base * robot.T_base_tool(Effective(q)); }
  Pose Flange(const Eigen::VectorXd& q) const { return T_rig_base * robot.T_base_flange(Effective(q)); }
  // nullopt when out of reach.
  std::optional<Eigen::VectorXd> Ik(const Pose& T_rig_target, const Eigen::VectorXd& seed) const {
    return SolveIk(robot, T_rig_base.Inverse() * T_rig_target * robot.T_flange_tool().Inverse(), seed);
  }
  // The geometric Jacobian of the tool pose in the rig frame's [dtheta; dp] layout.
  Eigen::Matrix<double, 6, Eigen::Dynamic> Jacobian(const Eigen::VectorXd& q) const {
    Eigen::Matrix<double, 6, Eigen::Dynamic> J = robot.Jacobian(q, RobotModel::EndFrame::kTool);
    J.topRows<3>() = T_rig_base.R * J.topRows<3>();
    J.bottomRows<3>() = T_rig_base.R * J.bottomRows<3>();
    return J;
  }
};

double SignedUniform(Rng& rng, double lo, double hi) {
  const double m = rng.Uniform(lo, hi);
  return rng.Uniform() < 0.5 ? -m : m;
}

Vec3 RandomDirection(Rng& rng) {
  Vec3 v(rng.Normal(), rng.Normal(), rng.Normal());
  return v.norm() > 1e-12 ? Vec3(v.normalized()) : Vec3::UnitX();
}

// A rigid-transform error of the given size: rotation `angle` about a random axis,
// translation `length` along a random direction.
Pose RandomError(Rng& rng, double length, double angle) {
  return {ExpSO3(angle * RandomDirection(rng)), length * RandomDirection(rng)};
}

Eigen::VectorXd JointNoise(Rng& rng, int n, double sigma) {
  Eigen::VectorXd e(n);
  for (int j = 0; j < n; ++j) e[j] = rng.Normal(0, sigma);
  return e;
}

// Predicted ISO RP for a zero-mean Gaussian position error with covariance C: l_bar + 3 S_l
// of l = |x|, by a fixed-seed Monte Carlo (no closed form for anisotropic C).
double PredictedRp(const Mat3& C) {
  Eigen::SelfAdjointEigenSolver<Mat3> es(C);
  const Vec3 s = es.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  Rng rng(42);
  double sum = 0, sum2 = 0;
  for (int k = 0; k < kRpSamples; ++k) {
    const double l = Vec3(s[0] * rng.Normal(), s[1] * rng.Normal(), s[2] * rng.Normal()).norm();
    sum += l;
    sum2 += l * l;
  }
  const double mean = sum / kRpSamples;
  const double var = std::max(0.0, (sum2 - kRpSamples * mean * mean) / (kRpSamples - 1));
  return mean + 3.0 * std::sqrt(var);
}

class CameraSimulator {
 public:
  CameraSimulator(const Scenario& sc, double sigma) : rig_(sc.rig), target_(sc.target), sigma_(sigma) {}

  // The camera rig's measurement of the true pose, or nullopt when fewer than 3 balls are
  // seen. `initial` is the tracker's starting pose (here the controller's prediction).
  std::optional<PoseRefinement> Measure(const Pose& T_rig_target_true, const Pose& initial, Rng& rng) const {
    std::vector<BallObservation> obs;
    std::set<int> balls;
    const double r = target_.ball_radius;
    for (size_t c = 0; c < rig_.size(); ++c) {
      const CameraModel& cam = rig_.cameras[c];
      for (size_t b = 0; b < target_.balls_target.size(); ++b) {
        const Vec3 p_cam = cam.T_cam_rig() * (T_rig_target_true * target_.balls_target[b]);
        if (!(p_cam.z() > 2 * r)) continue;
        const Vec2 u = SphereImageCentroid(cam, p_cam, r, kOutlinePoints);
        // The whole image of the ball inside the frame, with a margin for the detector's window.
        const double radius_px = (cam.Project(p_cam + Vec3(r, 0, 0)) - cam.Project(p_cam)).norm();
        const double margin = 2.0 + 1.5 * radius_px;
        if (!u.allFinite() || u.x() < margin || u.y() < margin || u.x() > cam.Width() - 1 - margin ||
            u.y() > cam.Height() - 1 - margin)
          continue;
        obs.push_back({static_cast<int>(c), static_cast<int>(b),
                       u + Vec2(rng.Normal(0, sigma_), rng.Normal(0, sigma_)), sigma_ * sigma_ * Mat2::Identity()});
        balls.insert(static_cast<int>(b));
      }
    }
    if (balls.size() < 3 || obs.size() < 4) return std::nullopt;
    return RefinePose(rig_, target_, initial, obs);
  }

 private:
  const CameraRig& rig_;
  const Target& target_;
  double sigma_;
};

// The covariance of the calibrated model's tool pose prediction (rig frame) at q from the
// calibration's parameter covariance: J_par C_par J_par^T, J_par by central differences
// over the free parameters in CalibrateRobot's layout.
Mat6 ModelCovariance(const RobotCalibrationResult& cal, const Eigen::VectorXd& q) {
  const Kinematics k{cal.robot, cal.T_meas_base};
  const Pose T0 = k.Tool(q);
  const int nj = cal.robot.NumJoints();
  const double h = 1e-6;
  auto perturbed = [&](int index, double step) {
    Kinematics p = k;
    if (index < 4 * nj) {
      Eigen::VectorXd delta = Eigen::VectorXd::Zero(4 * nj);
      delta[index] = step;
      p.robot = WithGeometryErrors(cal.robot, delta);
    } else if (index < 4 * nj + 6) {
      const int i = index - 4 * nj;
      Vec6 d = Vec6::Zero();
      d[i] = step;
      p.T_rig_base = BoxPlus(k.T_rig_base, d);
    } else {
      const int i = index - 4 * nj - 6;
      Vec6 d = Vec6::Zero();
      d[i] = step;
      p.robot.SetT_flange_tool(BoxPlus(cal.robot.T_flange_tool(), d));
    }
    return p.Tool(q);
  };
  const int nf = static_cast<int>(cal.free_parameters.size());
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, nf);
  for (int c = 0; c < nf; ++c) {
    const int index = cal.free_parameters[c];
    J.col(c) = (BoxMinus(perturbed(index, h), T0) - BoxMinus(perturbed(index, -h), T0)) / (2 * h);
  }
  return J * cal.covariance * J.transpose();
}

struct VisitResult {
  Pose attained;
  std::optional<Mat6> predicted_cov;  // of the attained pose's error (correction conditions)
};

enum class Correction { kNone, kCamera, kFused };

Iso9283Condition Finish(Iso9283Condition c, const std::vector<Pose>& commanded,
                        const std::vector<std::vector<std::optional<Mat6>>>& predicted) {
  double p2 = 0, r2 = 0, pp = 0, pr = 0;
  int n = 0, np = 0;
  for (int i = 0; i < kPoses; ++i) {
    c.poses.push_back(PoseAccuracyRepeatability(commanded[i], c.attained[i]));
    for (size_t j = 0; j < c.attained[i].size(); ++j) {
      p2 += (c.attained[i][j].t - commanded[i].t).squaredNorm();
      const double a = RotationAngle(c.attained[i][j].R, commanded[i].R);
      r2 += a * a;
      ++n;
      if (predicted[i][j]) {
        pp += predicted[i][j]->bottomRightCorner<3, 3>().trace();
        pr += predicted[i][j]->topLeftCorner<3, 3>().trace();
        ++np;
      }
    }
  }
  for (int i = 0; i + 1 < kPoses; ++i)
    c.distances.push_back(DistanceAccuracyRepeatability(commanded[i], commanded[i + 1], c.attained[i], c.attained[i + 1]));
  c.rms_position_m = std::sqrt(p2 / n);
  c.rms_rotation_rad = std::sqrt(r2 / n);
  if (np > 0) {
    c.predicted_rms_position_m = std::sqrt(pp / np);
    c.predicted_rms_rotation_rad = std::sqrt(pr / np);
  }
  return c;
}

}  // namespace

bool Iso9283ExperimentOptions::IsValid(std::string* why) const {
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (cycles < 2) return fail("cycles must be >= 2 (ISO 9283: 30), got " + std::to_string(cycles));
  if (path_runs < 2) return fail("path_runs must be >= 2 (ISO 9283: 10), got " + std::to_string(path_runs));
  if (path_points < 2) return fail("path_points must be >= 2, got " + std::to_string(path_points));
  if (!(cube_edge_m > 0) || !std::isfinite(cube_edge_m)) return fail("cube_edge_m must be positive and finite");
  if (!cube_centre_rig.allFinite()) return fail("cube_centre_rig must be finite");
  if (calibration_poses < 10) return fail("calibration_poses must be >= 10, got " + std::to_string(calibration_poses));
  if (!(dh_length_error_min_m >= 0) || !(dh_length_error_max_m >= dh_length_error_min_m))
    return fail("dh_length_error_min_m/max_m must satisfy 0 <= min <= max");
  if (!(dh_angle_error_min_rad >= 0) || !(dh_angle_error_max_rad >= dh_angle_error_min_rad))
    return fail("dh_angle_error_min_rad/max_rad must satisfy 0 <= min <= max");
  if (!(base_error_m >= 0) || !(base_error_rad >= 0) || !(tool_error_m >= 0) || !(tool_error_rad >= 0))
    return fail("base_error_m/rad and tool_error_m/rad must be >= 0");
  if (!(unmodelled_joint_error_rad >= 0) || !(unmodelled_joint_error_period_rad > 0))
    return fail("unmodelled_joint_error_rad must be >= 0 and unmodelled_joint_error_period_rad > 0");
  if (!(repeatability_joint_sigma_rad > 0))
    return fail("repeatability_joint_sigma_rad must be > 0 (it is the robot's repeatability)");
  if (!(pixel_sigma > 0)) return fail("pixel_sigma must be > 0");
  if (inclinometer_readings < 1) return fail("inclinometer_readings must be >= 1");
  std::string w;
  if (!inclinometer.IsValid(&w)) return fail("inclinometer: " + w);
  return true;
}

namespace {

// The path from `from` to `to` (rig frame) at the commanded orientation: the model's joints
// at dense samples (overshooting both ends a little), run o.path_runs times with fresh
// repeatability noise per sample; the attained tool positions per run.
std::vector<std::vector<Vec3>> RunPath(
    const Iso9283ExperimentOptions& o, const Kinematics& model, const Kinematics& truth, Eigen::VectorXd seed,
    const Mat3& R_cmd, const Vec3& from, const Vec3& to,
    const std::function<Eigen::VectorXd(const std::optional<Eigen::VectorXd>&, const std::string&, const Pose&)>& require,
    Rng& crng) {
  const int nj = model.robot.NumJoints();
  const int samples = 4 * (o.path_points - 1) + 1;
  std::vector<Eigen::VectorXd> q_path;
  for (int s = -2; s <= samples + 1; ++s) {
    const double u = (1 + 2 * kPathOvershoot) * s / (samples - 1) - kPathOvershoot;
    const Pose T{R_cmd, (1 - u) * from + u * to};
    seed = require(model.Ik(T, seed), "path point", T);
    q_path.push_back(seed);
  }
  std::vector<std::vector<Vec3>> runs;
  for (int r = 0; r < o.path_runs; ++r) {
    std::vector<Vec3> run;
    for (const auto& q : q_path) run.push_back(truth.Tool(q + JointNoise(crng, nj, o.repeatability_joint_sigma_rad)).t);
    runs.push_back(run);
  }
  return runs;
}

// The true robot: every DH parameter off by a signed uniform draw within the options'
// bounds, the tool and the base off, and an unmodelled periodic joint error (a gear).
Kinematics TrueRobot(const Kinematics& nominal, const Iso9283ExperimentOptions& o, Rng& rng) {
  const int nj = nominal.robot.NumJoints();
  Kinematics truth = nominal;
  std::vector<Joint> joints = nominal.robot.Joints();
  for (Joint& j : joints) {
    j.theta_offset += SignedUniform(rng, o.dh_angle_error_min_rad, o.dh_angle_error_max_rad);
    j.d += SignedUniform(rng, o.dh_length_error_min_m, o.dh_length_error_max_m);
    j.a += SignedUniform(rng, o.dh_length_error_min_m, o.dh_length_error_max_m);
    j.alpha += SignedUniform(rng, o.dh_angle_error_min_rad, o.dh_angle_error_max_rad);
  }
  const Pose tool_error = RandomError(rng, o.tool_error_m, o.tool_error_rad);
  const Pose base_error = RandomError(rng, o.base_error_m, o.base_error_rad);
  const Pose& ft = nominal.robot.T_flange_tool();
  truth.robot = RobotModel(nominal.robot.Name() + " (true)", nominal.robot.Convention(), joints,
                           Pose{tool_error.R * ft.R, ft.t + tool_error.t});
  truth.T_rig_base = Pose{base_error.R * nominal.T_rig_base.R, nominal.T_rig_base.t + base_error.t};
  truth.gear_amplitude.resize(nj);
  truth.gear_phase.resize(nj);
  for (int j = 0; j < nj; ++j) {
    truth.gear_amplitude[j] = o.unmodelled_joint_error_rad;
    truth.gear_phase[j] = rng.Uniform(0, 2 * std::numbers::pi);
  }
  truth.gear_period = o.unmodelled_joint_error_period_rad;
  return truth;
}

}  // namespace

Iso9283Experiment RunIso9283Experiment(const Iso9283ExperimentOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) Throw("iso9283 experiment options: ", why);
  Iso9283Experiment ex;
  ex.options = o;
  const Scenario sc = Scenario::Default();
  const CameraSimulator camera(sc, o.pixel_sigma);
  Rng rng(o.seed);

  // The controller's belief: the nominal robot where the lab experiment places it
  // (synthetic/lab_scenario.cpp), the target 60 mm out on the flange.
  Kinematics nominal{RobotModel::Default(), Pose{Mat3::Identity(), Vec3(0.0, 0.0, 0.5) - Vec3(0.75, 0.0, 0.55)}};
  nominal.robot.SetT_flange_tool(Pose{Mat3::Identity(), Vec3(0.0, 0.0, 0.06)});
  const int nj = nominal.robot.NumJoints();
  const double enc_sigma = nominal.robot.Joints()[0].encoder_sigma;
  const Eigen::MatrixXd Q_enc = nominal.robot.EncoderCovariance();
  const Eigen::MatrixXd Q_rep =
      o.repeatability_joint_sigma_rad * o.repeatability_joint_sigma_rad * Eigen::MatrixXd::Identity(nj, nj);

  // The true robot.
  const Kinematics truth = TrueRobot(nominal, o, rng);

  // The ISO cube's poses, flange z down (the usual tool orientation).
  Mat3 R_down;
  R_down << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  const Mat3 R_cmd = R_down * nominal.robot.T_flange_tool().R;
  const double h = 0.5 * o.cube_edge_m;
  const Vec3 corners[4] = {Vec3(-h, -h, h), Vec3(h, h, h), Vec3(h, h, -h), Vec3(-h, -h, -h)};
  ex.commanded.push_back({R_cmd, o.cube_centre_rig});
  // 10 % of the diagonal (2 |corner|) from the corner = 80 % of the way from the centre.
  for (const Vec3& c : corners) ex.commanded.push_back({R_cmd, o.cube_centre_rig + 0.8 * c});
  const char* names[kPoses] = {"P1", "P2", "P3", "P4", "P5"};
  Eigen::VectorXd home(nj);
  home << 0.0, -0.35, 0.6, 0.0, 1.3, 0.0;
  auto require = [&](const std::optional<Eigen::VectorXd>& q, const std::string& what, const Pose& T) {
    if (!q)
      Throw("iso9283 experiment: ", what, " at ", T.t.transpose(), " m (rig) is out of the robot's reach; ",
            "choose a smaller cube_edge_m (", o.cube_edge_m, " m) or another cube_centre_rig");
    return *q;
  };
  for (int i = 0; i < kPoses; ++i) {
    const auto q = require(nominal.Ik(ex.commanded[i], home), std::string("pose ") + names[i], ex.commanded[i]);
    Rng probe(o.seed ^ 0x1509ULL);
    if (!camera.Measure(truth.Tool(q), ex.commanded[i], probe))
      Throw("iso9283 experiment: pose ", names[i], " at ", ex.commanded[i].t.transpose(),
            " m (rig) is not seen by the camera rig (fewer than 3 balls); choose a smaller cube_edge_m (",
            o.cube_edge_m, " m) or another cube_centre_rig");
  }
  for (int k = 0; k < o.path_points; ++k) {
    const double s = static_cast<double>(k) / (o.path_points - 1);
    ex.path_commanded.push_back((1 - s) * ex.commanded[1].t + s * ex.commanded[3].t);
  }

  // Calibration from camera measurements at other configurations.
  RobotCalibrationResult cal;
  Mat6 unmodelled = Mat6::Zero();
  {
    std::vector<RobotMeasurement> meas;
    double pos_var = 0, rot_var = 0;
    Rng pick(o.seed ^ 0xca1bULL);
    for (int attempt = 0; attempt < 40 * o.calibration_poses && static_cast<int>(meas.size()) < o.calibration_poses;
         ++attempt) {
      Vec3 dp;
      do dp = Vec3(pick.Uniform(-1, 1), pick.Uniform(-1, 1), pick.Uniform(-1, 1));
      while (dp.norm() > 1.0);
      const Vec3 rot(pick.Uniform(-1, 1), pick.Uniform(-1, 1), pick.Uniform(-1, 1));
      const Pose goal{ExpSO3(25.0 * kDeg * rot / std::sqrt(3.0)) * R_cmd, o.cube_centre_rig + 0.25 * dp};
      const auto qc = nominal.Ik(goal, home);
      if (!qc) continue;
      const Eigen::VectorXd qa = *qc + JointNoise(pick, nj, o.repeatability_joint_sigma_rad);
      if (!truth.robot.WithinLimits(qa)) continue;
      const auto m = camera.Measure(truth.Tool(qa), goal, pick);
      if (!m) continue;
      const Eigen::VectorXd qe = qa + JointNoise(pick, nj, enc_sigma);
      RobotMeasurement rm;
      rm.q = qe;
      rm.p_meas = m->T_rig_target.t;
      rm.R_meas_tool = m->T_rig_target.R;
      meas.push_back(rm);
      const Mat6 enc = TransformPoseCovariance(nominal.robot.PoseCovariance(*qc, Q_enc), nominal.T_rig_base,
                                               nominal.robot.T_base_tool(*qc), Pose::Identity());
      pos_var += (m->cov + enc).bottomRightCorner<3, 3>().trace() / 3;
      rot_var += (m->cov + enc).topLeftCorner<3, 3>().trace() / 3;
    }
    if (static_cast<int>(meas.size()) < o.calibration_poses)
      Throw("iso9283 experiment: only ", meas.size(), " of calibration_poses = ", o.calibration_poses,
            " configurations near cube_centre_rig (", o.cube_centre_rig.transpose(),
            " m) are reachable and seen by the rig");
    RobotCalibrationOptions co;
    co.position_sigma_m = std::sqrt(pos_var / meas.size());
    co.rotation_sigma_rad = std::sqrt(rot_var / meas.size());
    // Poses near one region may not separate every parameter; those are held and reported.
    co.require_pose_identifiability = false;
    cal = CalibrateRobot(nominal.robot, nominal.T_rig_base, meas, co);
    ex.calibration_rms_before_m = Summarize(cal.errors_before).rms_position_m;
    ex.calibration_rms_after_m = Summarize(cal.errors_after).rms_position_m;
    ex.calibration_parameters = static_cast<int>(cal.parameters.size());
    ex.calibration_fixed = static_cast<int>(cal.Fixed().size());
    // What the calibration cannot explain, per axis: the fit's residual (camera noise
    // included, so on the safe side). The robot's covariance carries it in the fusion.
    const ErrorStats after = Summarize(cal.errors_after);
    unmodelled.diagonal().head<3>().setConstant(std::pow(after.rms_rotation_rad.value_or(0.0), 2) / 3);
    unmodelled.diagonal().tail<3>().setConstant(after.rms_position_m * after.rms_position_m / 3);
  }
  const Kinematics calibrated{cal.robot, cal.T_meas_base};

  // The four conditions.
  const char* cond_names[4] = {"before calibration", "after calibration", "calibrated + camera correction",
                               "calibrated + MOIFA correction"};
  const Kinematics* models[4] = {&nominal, &calibrated, &calibrated, &calibrated};
  const Correction corrections[4] = {Correction::kNone, Correction::kNone, Correction::kCamera, Correction::kFused};
  Inclinometer incl = o.inclinometer;
  incl.sigma /= std::sqrt(static_cast<double>(o.inclinometer_readings));  // the mean of the readings

  for (int k = 0; k < 4; ++k) {
    const Kinematics& model = *models[k];
    Rng crng(o.seed + 1000 * (k + 1));
    std::vector<Eigen::VectorXd> q_cmd;
    for (int i = 0; i < kPoses; ++i)
      q_cmd.push_back(require(model.Ik(ex.commanded[i], home), std::string("pose ") + names[i], ex.commanded[i]));
    Iso9283Condition c;
    c.name = cond_names[k];
    c.attained.assign(kPoses, {});
    std::vector<std::vector<std::optional<Mat6>>> predicted(kPoses);
    for (int i = 0; i < kPoses; ++i) {
      const Mat6 rep = model.Jacobian(q_cmd[i]) * Q_rep * model.Jacobian(q_cmd[i]).transpose();
      c.predicted_RP_m.push_back(PredictedRp(rep.bottomRightCorner<3, 3>()));
    }
    for (int cycle = 0; cycle < o.cycles; ++cycle) {
      for (int i = 0; i < kPoses; ++i) {
        const Eigen::VectorXd qa = q_cmd[i] + JointNoise(crng, nj, o.repeatability_joint_sigma_rad);
        if (corrections[k] == Correction::kNone) {
          c.attained[i].push_back(truth.Tool(qa));
          predicted[i].push_back(std::nullopt);
          continue;
        }
        const Eigen::VectorXd qe = qa + JointNoise(crng, nj, enc_sigma);
        const Pose T_pred = model.Tool(qe);
        const auto cm = camera.Measure(truth.Tool(qa), T_pred, crng);
        if (!cm)
          Throw("iso9283 experiment: pose ", names[i], " left the rig's view in cycle ", cycle,
                "; choose a smaller cube_edge_m");
        const auto J = model.Jacobian(qe);
        const Mat6 enc = J * Q_enc * J.transpose();
        Pose T_est = cm->T_rig_target;
        Mat6 P_est = cm->cov;
        Mat6 W_robot = Mat6::Zero();
        if (corrections[k] == Correction::kFused) {
          const Mat6 C_robot = enc + ModelCovariance(cal, qe) + unmodelled;
          std::vector<PoseMeasurement> poses;
          poses.push_back(PoseMeasurement::FromCovariance("camera", cm->T_rig_target, cm->cov));
          poses.push_back(PoseMeasurement::FromCovariance("robot", T_pred, C_robot));
          // The inclinometer sits on the target plate, its mounting known (see the header).
          // The one fusion path's instant MOIFA (fusion/stream_fusion.h): linearized at the
          // camera's and robot's fused orientation, then at the result.
          std::optional<TiltReading> tilt;
          if (const auto reading = incl.Simulate(truth.Tool(qa).R, crng)) tilt = TiltReading{*reading, incl};
          // Without fault exclusion: the error model below needs the robot's weight (index 1),
          // and this simulation has no faults (an excluded sensor would only be a false alarm).
          const FusedPose f = FuseEpoch(poses, tilt, ConsistencyOptions{}, false).fused;
          T_est = f.T;
          P_est = f.covariance;
          W_robot = f.weights[1];
        }
        // One correction move from where the encoders say the robot is.
        const Vec6 e = BoxMinus(ex.commanded[i], T_est);
        const Eigen::VectorXd dq = J.completeOrthogonalDecomposition().solve(e);
        const Eigen::VectorXd qa2 = qe + dq + JointNoise(crng, nj, o.repeatability_joint_sigma_rad);
        c.attained[i].push_back(truth.Tool(qa2));
        // Error after the move: -(estimation error) + J (eps' + nu); the robot's share of
        // the estimate, W_robot J nu, cancels part of J nu (see the header comment).
        const Mat6 I_W = Mat6::Identity() - W_robot;
        predicted[i].push_back(Mat6(P_est - W_robot * enc * W_robot.transpose() + I_W * enc * I_W.transpose() +
                                    J * Q_rep * J.transpose()));
      }
    }
    for (int i = 0; i < kPoses; ++i) {
      if (corrections[k] == Correction::kNone) continue;
      Mat6 mean = Mat6::Zero();
      for (const auto& p : predicted[i]) mean += *p / static_cast<double>(predicted[i].size());
      c.predicted_RP_m[i] = PredictedRp(mean.bottomRightCorner<3, 3>());
    }

    // The path: the model's joints at dense samples, fresh repeatability noise per sample.
    if (k >= 2) {
      c.path = ex.conditions[1].path;
      c.path_attained = ex.conditions[1].path_attained;
      c.path_note = "path run with the calibrated model, no correction (as after calibration)";
    } else {
      std::vector<std::vector<Vec3>> runs = RunPath(o, model, truth, q_cmd[1], R_cmd, ex.commanded[1].t,
                                                    ex.commanded[3].t, require, crng);
      c.path = PathAccuracyRepeatability(ex.path_commanded, runs);
      c.path_attained = std::move(runs);
    }
    ex.conditions.push_back(Finish(std::move(c), ex.commanded, predicted));
  }
  return ex;
}

std::string FormatIso9283Experiment(const Iso9283Experiment& e) {
  std::string out;
  char buf[512];
  auto add = [&](const char* fmt, auto... args) {
    if constexpr (sizeof...(args) == 0) {
      out += fmt;  // plain text (a format string without arguments would be a format to clang)
    } else {
      std::snprintf(buf, sizeof(buf), fmt, args...);
      out += buf;
    }
  };
  const auto& o = e.options;
  add("ISO 9283 on the forward model: KR 5 arc with DH errors %.1f-%.1f mm / %.2f-%.2f deg, base %.1f mm / %.2f "
      "deg, tool %.1f mm / %.2f deg; cube %.0f mm at rig (%.2f, %.2f, %.2f) m; n = %d cycles, %d path runs; "
      "repeatability %.1e rad per joint; camera %.3f px\n",
      1e3 * o.dh_length_error_min_m, 1e3 * o.dh_length_error_max_m, o.dh_angle_error_min_rad / kDeg,
      o.dh_angle_error_max_rad / kDeg, 1e3 * o.base_error_m, o.base_error_rad / kDeg, 1e3 * o.tool_error_m,
      o.tool_error_rad / kDeg, 1e3 * o.cube_edge_m, o.cube_centre_rig.x(), o.cube_centre_rig.y(),
      o.cube_centre_rig.z(), o.cycles, o.path_runs, o.repeatability_joint_sigma_rad, o.pixel_sigma);
  add("calibration: %d camera poses (6-D), %d of %d parameters held; fitting-set RMS position error %.4f mm nominal "
      "-> %.4f mm calibrated\n",
      o.calibration_poses, e.calibration_fixed, e.calibration_parameters, 1e3 * e.calibration_rms_before_m,
      1e3 * e.calibration_rms_after_m);
  for (const auto& c : e.conditions) {
    add("\n[%s]\n", c.name.c_str());
    add("%-4s %9s %9s %9s %9s %9s %9s %9s %9s %9s %9s %9s %9s\n", "pose", "AP mm", "RP mm", "RPpred mm",
        "AP_x mm", "AP_y mm", "AP_z mm", "AP_a deg", "AP_b deg", "AP_c deg", "RP_a deg", "RP_b deg", "RP_c deg");
    for (size_t i = 0; i < c.poses.size(); ++i) {
      const auto& p = c.poses[i];
      add("P%-3zu %9.4f %9.4f %9.4f %9.4f %9.4f %9.4f %9.5f %9.5f %9.5f %9.5f %9.5f %9.5f\n", i + 1, 1e3 * p.AP_p,
          1e3 * p.RP_l, 1e3 * c.predicted_RP_m[i], 1e3 * p.AP_xyz.x(), 1e3 * p.AP_xyz.y(), 1e3 * p.AP_xyz.z(),
          p.AP_a / kDeg, p.AP_b / kDeg, p.AP_c / kDeg, p.RP_a / kDeg, p.RP_b / kDeg, p.RP_c / kDeg);
    }
    add("%s", "distances:");
    for (size_t i = 0; i < c.distances.size(); ++i)
      add(" P%zu-P%zu AD %+.4f RD %.4f mm;", i + 1, i + 2, 1e3 * c.distances[i].AD_p, 1e3 * c.distances[i].RD_p);
    add("\npath (P2 -> P4, %zu calculation points): AT %.4f mm, RT %.4f mm%s%s\n", e.path_commanded.size(),
        1e3 * c.path.AT_p, 1e3 * c.path.RT_p, c.path_note.empty() ? "" : "; ", c.path_note.c_str());
    add("all visits: RMS position error %.4f mm, RMS rotation error %.5f deg", 1e3 * c.rms_position_m,
        c.rms_rotation_rad / kDeg);
    if (c.predicted_rms_position_m)
      add(" (predicted from the covariances: %.4f mm, %.5f deg)", 1e3 * *c.predicted_rms_position_m,
          *c.predicted_rms_rotation_rad / kDeg);
    add("\n");
  }
  add("\nsummary (mean over P1..P5)\n%-32s %9s %9s %9s %10s %10s %9s %9s\n", "condition", "AP mm", "RP mm",
      "RPpred mm", "APang deg", "RPang deg", "AT mm", "RT mm");
  for (const auto& c : e.conditions) {
    double ap = 0, rp = 0, rpp = 0, apa = 0, rpa = 0;
    for (size_t i = 0; i < c.poses.size(); ++i) {
      const auto& p = c.poses[i];
      ap += p.AP_p / c.poses.size();
      rp += p.RP_l / c.poses.size();
      rpp += c.predicted_RP_m[i] / c.poses.size();
      apa += Vec3(p.AP_a, p.AP_b, p.AP_c).norm() / c.poses.size();
      rpa += Vec3(p.RP_a, p.RP_b, p.RP_c).norm() / c.poses.size();
    }
    add("%-32s %9.4f %9.4f %9.4f %10.5f %10.5f %9.4f %9.4f\n", c.name.c_str(), 1e3 * ap, 1e3 * rp, 1e3 * rpp,
        apa / kDeg, rpa / kDeg, 1e3 * c.path.AT_p, 1e3 * c.path.RT_p);
  }
  add("APang, RPang: |(AP_a, AP_b, AP_c)| and |(RP_a, RP_b, RP_c)|. RP is the robot's (joint noise of every move);\n"
      "RPpred from the covariances: repeatability alone without correction, estimate + move after a correction.\n");
  return out;
}

void WriteIso9283ExperimentCsv(const std::filesystem::path& path, const Iso9283Experiment& e) {
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "condition,pose,AP_mm,AP_x_mm,AP_y_mm,AP_z_mm,RP_mm,RP_pred_mm,AP_a_deg,AP_b_deg,AP_c_deg,RP_a_deg,"
          "RP_b_deg,RP_c_deg\n";
    os.precision(9);
    for (const auto& c : e.conditions)
      for (size_t i = 0; i < c.poses.size(); ++i) {
        const auto& p = c.poses[i];
        os << '"' << c.name << "\",P" << i + 1 << ',' << 1e3 * p.AP_p << ',' << 1e3 * p.AP_xyz.x() << ','
           << 1e3 * p.AP_xyz.y() << ',' << 1e3 * p.AP_xyz.z() << ',' << 1e3 * p.RP_l << ','
           << 1e3 * c.predicted_RP_m[i] << ',' << p.AP_a / kDeg << ',' << p.AP_b / kDeg << ',' << p.AP_c / kDeg
           << ',' << p.RP_a / kDeg << ',' << p.RP_b / kDeg << ',' << p.RP_c / kDeg << '\n';
      }
  });
}

void WriteIso9283AttainedCsv(const std::filesystem::path& path, const Iso9283Experiment& e, int condition) {
  if (condition < 0 || condition >= static_cast<int>(e.conditions.size()))
    Throw("WriteIso9283AttainedCsv: condition ", condition, " not in [0, ", e.conditions.size(), ")");
  const auto& c = e.conditions[condition];
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "pose,cycle,cmd_x_m,cmd_y_m,cmd_z_m,cmd_qw,cmd_qx,cmd_qy,cmd_qz,x_m,y_m,z_m,qw,qx,qy,qz\n";
    os.precision(17);
    for (size_t i = 0; i < c.attained.size(); ++i)
      for (size_t j = 0; j < c.attained[i].size(); ++j) {
        os << 'P' << i + 1 << ',' << j + 1;
        for (const Pose* T : {&e.commanded[i], &c.attained[i][j]}) {
          const Eigen::Quaterniond q = T->Quaternion();
          os << ',' << T->t.x() << ',' << T->t.y() << ',' << T->t.z() << ',' << q.w() << ',' << q.x() << ','
             << q.y() << ',' << q.z();
        }
        os << '\n';
      }
  });
}

void WriteIso9283PathCsv(const std::filesystem::path& path, const Iso9283Experiment& e, int condition) {
  if (condition < 0 || condition >= static_cast<int>(e.conditions.size()))
    Throw("WriteIso9283PathCsv: condition ", condition, " not in [0, ", e.conditions.size(), ")");
  const auto& c = e.conditions[condition];
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "run,x_m,y_m,z_m\n";
    os.precision(17);
    for (const Vec3& p : e.path_commanded) os << "commanded," << p.x() << ',' << p.y() << ',' << p.z() << '\n';
    for (size_t r = 0; r < c.path_attained.size(); ++r)
      for (const Vec3& p : c.path_attained[r])
        os << "run" << r + 1 << ',' << p.x() << ',' << p.y() << ',' << p.z() << '\n';
  });
}

void WriteIso9283ExperimentSvg(const std::filesystem::path& ap_path, const std::filesystem::path& rp_path,
                               const Iso9283Experiment& e) {
  const char* colors[4] = {"#d62728", "#ff7f0e", "#1f77b4", "#2ca02c"};
  // AP spans two and a half decades over the conditions (0.9 mm before calibration, a few
  // um after a correction): a log axis (labelled in mm) keeps all four readable.
  Plot ap{"ISO 9283 pose accuracy AP per pose", "pose (P1..P5)", "AP (mm)", {}};
  ap.log_y = true;
  Plot rp{"ISO 9283 pose repeatability RP per pose (markers: measured, lines: predicted)", "pose (P1..P5)", "RP (mm)", {}};
  for (size_t k = 0; k < e.conditions.size(); ++k) {
    const auto& c = e.conditions[k];
    PlotSeries a{c.name, {}, {}, colors[k % 4], true}, r{c.name, {}, {}, colors[k % 4], true},
        rpred{c.name + " (predicted)", {}, {}, colors[k % 4], false};
    for (size_t i = 0; i < c.poses.size(); ++i) {
      a.x.push_back(i + 1);
      a.y.push_back(1e3 * c.poses[i].AP_p);
      r.x.push_back(i + 1);
      r.y.push_back(1e3 * c.poses[i].RP_l);
      rpred.x.push_back(i + 1);
      rpred.y.push_back(1e3 * c.predicted_RP_m[i]);
    }
    ap.series.push_back(a);
    rp.series.push_back(r);
    rp.series.push_back(rpred);
  }
  ap.WriteSvg(ap_path);
  rp.WriteSvg(rp_path);
}

void WriteIso9283Measurements(const std::filesystem::path& dir, const std::string& prefix, const Iso9283Experiment& e) {
  CreateOutputFolder(dir, "iso9283 --write-measurements");
  for (int k = 0; k < static_cast<int>(e.conditions.size()); ++k) {
    WriteIso9283AttainedCsv(dir / (prefix + "attained_" + std::to_string(k + 1) + ".csv"), e, k);
    WriteIso9283PathCsv(dir / (prefix + "path_" + std::to_string(k + 1) + ".csv"), e, k);
  }
}

}  // namespace mcms
