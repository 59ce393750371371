#include "calib/robot_calibration.h"

#include <numbers>
#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <map>
#include <memory>
#include <limits>
#include <numeric>
#include <set>
#include <sstream>

#include <Eigen/Dense>

#include "core/error.h"
#include "core/io.h"
#include "core/random.h"
#include "model/kinematics.h"

namespace mcms {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kParamsPerJoint = kDhParamsPerJoint;
constexpr int kBaseAndTool = 12;
constexpr int kPerHarmonic = kErrorMotionParamsPerHarmonic;  // sin [rx ry rz x y z], cos [..]

int BaseOffset(const RobotModel& r) { return kParamsPerJoint * r.NumJoints(); }
int ToolOffset(const RobotModel& r) { return kParamsPerJoint * r.NumJoints() + 6; }
int ErrorMotionOffset(const RobotModel& r) { return kParamsPerJoint * r.NumJoints() + kBaseAndTool; }
// Harmonics of error motion estimated for joint i (options.error_motion_harmonics).
int HarmonicsOf(const RobotCalibrationOptions& o, int i) {
  return o.error_motion_harmonics.empty() ? 0 : o.error_motion_harmonics[i];
}
// Whether parameter k of the layout is an angle (rad) rather than a length (m): DH theta
// and alpha, the rotation parts of base and tool, the rotation parts of error motion.
bool IsAngle(const RobotModel& r, int k) {
  if (k < BaseOffset(r)) return k % kParamsPerJoint == 0 || k % kParamsPerJoint == 3;
  if (k < ErrorMotionOffset(r)) return (k - BaseOffset(r)) % 6 < 3;
  return (k - ErrorMotionOffset(r)) % 6 < 3;
}
int NumParameters(const RobotModel& r, const RobotCalibrationOptions& o) {
  int n = ErrorMotionOffset(r);
  for (int i = 0; i < r.NumJoints(); ++i) n += kPerHarmonic * HarmonicsOf(o, i);
  return n;
}

// ---- The one cost functor: whitened prediction error of one measurement. ----
// Parameter block: the full vector of the header's layout. Residuals: 3 (position) or 6
// (position, then the rotation vector of R_pred R_meas^T), each divided by its sigma.
struct MeasurementCost {
  const RobotModel* robot;
  std::vector<int> harmonics;  // estimated error-motion harmonics per joint
  Eigen::VectorXd q;
  Pose base0, tool0;
  Vec3 p_meas;
  std::optional<Mat3> R_meas;
  double inv_sigma_p, inv_sigma_r;

  template <typename T>
  bool operator()(T const* const* params, T* residual) const {
    using M3 = Eigen::Matrix<T, 3, 3>;
    using V3 = Eigen::Matrix<T, 3, 1>;
    const T* x = params[0];
    ChainCorrections<T> c;
    c.dh = x;
    c.error_motion = x + ErrorMotionOffset(*robot);
    c.error_motion_harmonics = harmonics;
    const PoseT<T> F = ForwardKinematicsT(*robot, q, c);
    const M3& R = F.R;
    const V3& t = F.t;
    const auto& joints = robot->Joints();
    const T* b = x + kParamsPerJoint * joints.size();
    const T* u = b + 6;
    M3 dRb, dRu;
    ceres::AngleAxisToRotationMatrix(b, dRb.data());  // column-major, as Eigen stores
    ceres::AngleAxisToRotationMatrix(u, dRu.data());
    const M3 Rb = dRb * base0.R.cast<T>();
    const V3 tb = base0.t.cast<T>() + V3(b[3], b[4], b[5]);
    const M3 Ru = dRu * tool0.R.cast<T>();
    const V3 tu = tool0.t.cast<T>() + V3(u[3], u[4], u[5]);
    // T_meas_tool = T_meas_base * T_base_flange * T_flange_tool
    const V3 p = Rb * (R * tu + t) + tb;
    for (int k = 0; k < 3; ++k) residual[k] = (p[k] - T(p_meas[k])) * T(inv_sigma_p);
    if (R_meas) {
      const M3 Rp = Rb * R * Ru;
      const M3 E = Rp * R_meas->transpose().cast<T>();
      T r[3];
      ceres::RotationMatrixToAngleAxis(E.data(), r);
      for (int k = 0; k < 3; ++k) residual[3 + k] = r[k] * T(inv_sigma_r);
    }
    return true;
  }
};

using CostFunction = ceres::DynamicAutoDiffCostFunction<MeasurementCost, 4>;

std::unique_ptr<CostFunction> MakeCost(const RobotModel& robot, const Pose& base0, const RobotMeasurement& m,
                                       const RobotCalibrationOptions& o) {
  auto* f = new MeasurementCost{&robot,   o.error_motion_harmonics, m.q, base0, robot.T_flange_tool(), m.p_meas,
                                m.R_meas_tool, 1.0 / o.position_sigma_m, 1.0 / o.rotation_sigma_rad};
  auto c = std::make_unique<CostFunction>(f);
  c->AddParameterBlock(NumParameters(robot, o));
  c->SetNumResiduals(m.R_meas_tool ? 6 : 3);
  return c;
}

}  // namespace

std::unique_ptr<ceres::CostFunction> MakeRobotMeasurementCost(const RobotModel& robot, const Pose& base0,
                                                               const RobotMeasurement& m,
                                                               const RobotCalibrationOptions& options) {
  return MakeCost(robot, base0, m, options);
}

int NumCalibrationParameters(const RobotModel& robot, const RobotCalibrationOptions& options) {
  return NumParameters(robot, options);
}

void AnalyzeIdentifiability(const Eigen::MatrixXd& J, const std::vector<std::string>& names, double tol,
                            std::vector<CalibrationParameter>* params) {
  const int n = static_cast<int>(J.cols());
  Eigen::MatrixXd Q(J.rows(), 0);
  std::vector<int> kept;
  for (int j = 0; j < n; ++j) {
    CalibrationParameter& p = (*params)[j];
    if (p.fixed) continue;
    const double norm = J.col(j).norm();
    if (!(norm > 1e-12 * std::sqrt(static_cast<double>(J.rows())))) {
      p.fixed = true;
      p.reason = "does not affect the measurements at these poses (zero Jacobian column)";
      continue;
    }
    Eigen::VectorXd c = J.col(j) / norm;
    Eigen::VectorXd res = c;
    for (int pass = 0; pass < 2 && Q.cols() > 0; ++pass) res -= Q * (Q.transpose() * res);
    const double dist = res.norm();
    if (dist < tol) {
      // Which kept parameters it is a combination of: least squares on the kept columns.
      Eigen::MatrixXd A(J.rows(), kept.size());
      for (size_t k = 0; k < kept.size(); ++k) A.col(k) = J.col(kept[k]) / J.col(kept[k]).norm();
      const Eigen::VectorXd coef = A.colPivHouseholderQr().solve(c);
      const double big = coef.cwiseAbs().maxCoeff();
      std::ostringstream s;
      s << "not identifiable: a combination of";
      int listed = 0;
      for (size_t k = 0; k < kept.size(); ++k)
        if (std::abs(coef[k]) > 0.1 * big) s << (listed++ ? ", " : " ") << names[kept[k]];
      s << " (distance from their span " << dist << " < " << tol << ")";
      p.fixed = true;
      p.reason = s.str();
      continue;
    }
    Q.conservativeResize(Eigen::NoChange, Q.cols() + 1);
    Q.col(Q.cols() - 1) = res / dist;
    kept.push_back(j);
  }
}

namespace {

// Whitened residuals and the dense Jacobian (rows: residuals, columns: all parameters).
void Evaluate(const std::vector<std::unique_ptr<CostFunction>>& costs, const Eigen::VectorXd& x,
              Eigen::VectorXd* r, Eigen::MatrixXd* J) {
  int rows = 0;
  for (const auto& c : costs) rows += c->num_residuals();
  r->resize(rows);
  if (J) J->resize(rows, x.size());
  const double* params[] = {x.data()};
  int at = 0;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Ji;
  for (const auto& c : costs) {
    const int m = c->num_residuals();
    Ji.resize(m, x.size());
    double* jac[] = {Ji.data()};
    c->Evaluate(params, r->data() + at, J ? jac : nullptr);
    if (J) J->middleRows(at, m) = Ji;
    at += m;
  }
}

// Priority order of the identifiability analysis: base, tool, the joints' DH errors, then
// the error-motion harmonics (so a harmonic term that duplicates the geometry is the one held).
std::vector<int> PriorityOrder(const RobotModel& robot, int num_parameters) {
  std::vector<int> order;
  for (int k = 0; k < kBaseAndTool; ++k) order.push_back(BaseOffset(robot) + k);
  for (int k = 0; k < BaseOffset(robot); ++k) order.push_back(k);
  for (int k = ErrorMotionOffset(robot); k < num_parameters; ++k) order.push_back(k);
  return order;
}

// Runs the analysis in priority order on a parameter list whose requested fixes are set.
void AnalyzeInPriorityOrder(const RobotModel& robot, const Eigen::MatrixXd& J, double tol,
                            std::vector<CalibrationParameter>* params) {
  const std::vector<int> order = PriorityOrder(robot, static_cast<int>(J.cols()));
  Eigen::MatrixXd Jp(J.rows(), J.cols());
  std::vector<std::string> names;
  std::vector<CalibrationParameter> permuted;
  for (size_t k = 0; k < order.size(); ++k) {
    Jp.col(k) = J.col(order[k]);
    names.push_back((*params)[order[k]].name);
    permuted.push_back((*params)[order[k]]);
  }
  AnalyzeIdentifiability(Jp, names, tol, &permuted);
  for (size_t k = 0; k < order.size(); ++k) (*params)[order[k]] = permuted[k];
}

void CheckMeasurements(const RobotModel& robot, const std::vector<RobotMeasurement>& ms, const char* who) {
  if (ms.empty()) Throw(who, ": no measurements given; give joint values and measured positions");
  const bool six = ms[0].R_meas_tool.has_value();
  for (size_t i = 0; i < ms.size(); ++i) {
    const RobotMeasurement& m = ms[i];
    // "<who>: measurement 5" plus where it was read from, when known.
    const std::string at = m.source.empty() ? std::string() : " (" + m.source + ")";
    if (m.q.size() != robot.NumJoints())
      Throw(who, ": measurement ", i + 1, at, " has ", m.q.size(), " joint values but robot '", robot.Name(), "' has ",
            robot.NumJoints(), " joints; give one value per joint");
    std::string why;
    if (!robot.WithinLimits(m.q, &why))
      Throw(who, ": measurement ", i + 1, at, ": ", why, "; remove the measurement or correct the joint limits");
    if (!m.p_meas.allFinite()) Throw(who, ": measurement ", i + 1, at, " has a non-finite position");
    if (m.R_meas_tool.has_value() != six)
      Throw(who, ": measurement ", i + 1, " is ", m.R_meas_tool ? "6-D" : "3-D", " but measurement 1 is ",
            six ? "6-D" : "3-D", "; give orientations for all measurements or for none");
  }
}

Pose ParsePoseNode(const YAML::Node& n, const std::string& where) {
  for (const char* k : {"x", "y", "z", "qw", "qx", "qy", "qz"})
    if (!n[k]) Throw(where, ": pose is missing '", k, "'");
  const Eigen::Quaterniond q(n["qw"].as<double>(), n["qx"].as<double>(), n["qy"].as<double>(),
                             n["qz"].as<double>());
  if (std::abs(q.norm() - 1.0) > 1e-3) Throw(where, ": pose quaternion has norm ", q.norm(), ", expected 1");
  return Pose::FromQuaternion(q.normalized(), Vec3(n["x"].as<double>(), n["y"].as<double>(), n["z"].as<double>()));
}

std::vector<double> ReadList(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence()) Throw(where, " must be a list of numbers");
  std::vector<double> v;
  for (const auto& e : n) {
    const double d = e.as<double>();
    if (!std::isfinite(d)) Throw(where, " has a non-finite number");
    v.push_back(d);
  }
  return v;
}

// Whitened Jacobian rows of hypothetical measurements at the given poses (measured values
// are the model's own predictions: only the Jacobian matters), over all parameters.
Eigen::MatrixXd PoseJacobian(const RobotModel& robot, const Pose& T_meas_base,
                             const std::vector<Eigen::VectorXd>& poses, bool six_dof,
                             const RobotCalibrationOptions& options) {
  std::vector<std::unique_ptr<CostFunction>> costs;
  for (size_t i = 0; i < poses.size(); ++i) {
    std::string why;
    if (!robot.WithinLimits(poses[i], &why)) Throw("pose ", i + 1, ": ", why);
    RobotMeasurement m;
    m.q = poses[i];
    const Pose T = T_meas_base * robot.T_base_tool(m.q);
    m.p_meas = T.t;
    if (six_dof) m.R_meas_tool = T.R;
    costs.push_back(MakeCost(robot, T_meas_base, m, options));
  }
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  Evaluate(costs, Eigen::VectorXd::Zero(NumParameters(robot, options)), &r, &J);
  return J;
}

// Identifiability at 60 poses drawn uniformly within the joint limits (open or very wide
// limits clamped to +-pi rad or +-1 m), with the requests already applied in `requested`:
// the redundancies that hold for any pose set.
std::vector<CalibrationParameter> ReferenceIdentifiability(const RobotModel& robot, const Pose& T_meas_base,
                                                           bool six_dof, const RobotCalibrationOptions& options,
                                                           const RobotCalibrationResult& requested) {
  Rng rng(20260101);
  std::vector<Eigen::VectorXd> poses;
  for (int k = 0; k < 60; ++k) {
    Eigen::VectorXd q(robot.NumJoints());
    for (int i = 0; i < robot.NumJoints(); ++i) {
      const Joint& j = robot.Joints()[i];
      const double wide = j.type == JointType::kRevolute ? kPi : 1.0;
      q[i] = rng.Uniform(std::max(j.lower, -wide), std::min(j.upper, wide));
    }
    poses.push_back(q);
  }
  const Eigen::MatrixXd J = PoseJacobian(robot, T_meas_base, poses, six_dof, options);
  std::vector<CalibrationParameter> params = requested.parameters;
  for (auto& p : params)
    if (p.reason != "fixed by request" && p.reason.rfind("DH parameters not estimated", 0) != 0) {
      p.fixed = false;
      p.reason.clear();
    }
  AnalyzeInPriorityOrder(robot, J, options.identifiability_tolerance, &params);
  return params;
}

}  // namespace

bool RobotCalibrationOptions::IsValid(std::string* why) const {
  std::string w;
  if (!(position_sigma_m > 0) || !std::isfinite(position_sigma_m)) w = "position_sigma_m must be > 0";
  else if (!(rotation_sigma_rad > 0) || !std::isfinite(rotation_sigma_rad)) w = "rotation_sigma_rad must be > 0";
  else if (!(identifiability_tolerance > 0 && identifiability_tolerance < 1)) w = "identifiability_tolerance must be in (0, 1)";
  else if (!(correlation_threshold > 0 && correlation_threshold <= 1)) w = "correlation_threshold must be in (0, 1]";
  else if (max_iterations < 1) w = "max_iterations must be >= 1";
  for (size_t i = 0; i < error_motion_harmonics.size() && w.empty(); ++i)
    if (error_motion_harmonics[i] < 0 || error_motion_harmonics[i] > 8)
      w = "error_motion_harmonics[" + std::to_string(i) + "] must be in 0..8";
  if (w.empty()) return true;
  if (why) *why = w;
  return false;
}

std::vector<const CalibrationParameter*> RobotCalibrationResult::Fixed() const {
  std::vector<const CalibrationParameter*> f;
  for (const auto& p : parameters)
    if (p.fixed) f.push_back(&p);
  return f;
}

std::vector<std::string> CalibrationParameterNames(const RobotModel& robot, const RobotCalibrationOptions& options) {
  std::vector<std::string> names;
  std::vector<std::string> joint;
  for (int i = 0; i < robot.NumJoints(); ++i) {
    std::ostringstream s;
    if (robot.Joints()[i].name.empty()) s << 'J' << i + 1;
    else s << robot.Joints()[i].name;
    joint.push_back(s.str());
  }
  auto joint_name = [&](int i) { return joint[i]; };
  for (int i = 0; i < robot.NumJoints(); ++i)
    for (const char* p : {".theta_offset", ".d", ".a", ".alpha"}) names.push_back(joint_name(i) + p);
  for (const char* f : {"base", "tool"})
    for (const char* c : {".rx", ".ry", ".rz", ".x", ".y", ".z"}) names.push_back(std::string(f) + c);
  for (int i = 0; i < robot.NumJoints(); ++i)
    for (int h = 1; h <= HarmonicsOf(options, i); ++h)
      for (const char* sc : {".sin.", ".cos."})
        for (const char* c : {"rx", "ry", "rz", "x", "y", "z"})
          names.push_back(joint_name(i) + ".em" + std::to_string(h) + sc + c);
  return names;
}

RobotModel WithErrorMotionErrors(const RobotModel& robot, const std::vector<int>& harmonics,
                                 const Eigen::VectorXd& delta) {
  const int n = robot.NumJoints();
  if (!harmonics.empty() && static_cast<int>(harmonics.size()) != n)
    Throw("WithErrorMotionErrors: ", harmonics.size(), " harmonic counts for robot '", robot.Name(), "' with ", n,
          " joints");
  int needed = 0;
  for (int h : harmonics) needed += kPerHarmonic * h;
  if (delta.size() != needed)
    Throw("WithErrorMotionErrors: ", delta.size(), " error-motion values given, the harmonic counts need ", needed);
  std::vector<Joint> joints = robot.Joints();
  int at = 0;
  for (int i = 0; i < n && !harmonics.empty(); ++i) {
    Joint& j = joints[i];
    const int H = harmonics[i];
    if (j.Harmonics() < H) {
      j.error_motion_sin.resize(H, Vec6::Zero());
      j.error_motion_cos.resize(H, Vec6::Zero());
    }
    for (int h = 0; h < H; ++h, at += kPerHarmonic) {
      j.error_motion_sin[h] += delta.segment<6>(at);
      j.error_motion_cos[h] += delta.segment<6>(at + 6);
    }
  }
  return robot.WithJoints(joints);
}

RobotModel WithDhErrors(const RobotModel& robot, const Eigen::VectorXd& delta) {
  if (delta.size() != kParamsPerJoint * robot.NumJoints())
    Throw("WithDhErrors: ", delta.size(), " DH errors given, robot '", robot.Name(), "' needs ",
          kParamsPerJoint * robot.NumJoints());
  std::vector<Joint> joints = robot.Joints();
  for (size_t i = 0; i < joints.size(); ++i) {
    joints[i].theta_offset += delta[4 * i];
    joints[i].d += delta[4 * i + 1];
    joints[i].a += delta[4 * i + 2];
    joints[i].alpha += delta[4 * i + 3];
  }
  return robot.WithJoints(joints);
}

std::vector<PoseError> PredictionErrors(const RobotModel& robot, const Pose& T_meas_base,
                                        const std::vector<RobotMeasurement>& measurements) {
  CheckMeasurements(robot, measurements, "PredictionErrors");
  std::vector<PoseError> e;
  for (const auto& m : measurements) {
    const Pose T = T_meas_base * robot.T_base_tool(m.q);
    PoseError pe;
    pe.dp = T.t - m.p_meas;
    if (m.R_meas_tool) pe.rotation_rad = RotationAngle(*m.R_meas_tool, T.R);
    e.push_back(pe);
  }
  return e;
}

ErrorStats Summarize(const std::vector<PoseError>& errors) {
  ErrorStats s;
  if (errors.empty()) return s;
  double sp = 0, sp2 = 0, sr = 0, sr2 = 0, mr = 0;
  bool rot = false;
  for (const auto& e : errors) {
    const double p = e.position();
    sp += p;
    sp2 += p * p;
    s.max_position_m = std::max(s.max_position_m, p);
    if (e.rotation_rad) {
      rot = true;
      sr += *e.rotation_rad;
      sr2 += *e.rotation_rad * *e.rotation_rad;
      mr = std::max(mr, *e.rotation_rad);
    }
  }
  const double n = static_cast<double>(errors.size());
  s.mean_position_m = sp / n;
  s.rms_position_m = std::sqrt(sp2 / n);
  if (rot) {
    s.mean_rotation_rad = sr / n;
    s.rms_rotation_rad = std::sqrt(sr2 / n);
    s.max_rotation_rad = mr;
  }
  return s;
}

Pose InitialBaseGuess(const RobotModel& robot, const std::vector<RobotMeasurement>& measurements) {
  CheckMeasurements(robot, measurements, "robot calibration (starting registration)");
  const int n = static_cast<int>(measurements.size());
  if (n < 3) Throw("InitialBaseGuess: ", n, " measurements; at least 3 non-collinear positions are needed");
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (int i = 0; i < n; ++i) {
    src.col(i) = robot.T_base_tool(measurements[i].q).t;
    dst.col(i) = measurements[i].p_meas;
  }
  const Vec3 cs = src.rowwise().mean(), cd = dst.rowwise().mean();
  const Eigen::Matrix3d H = (dst.colwise() - cd) * (src.colwise() - cs).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  if (svd.singularValues()[1] < 1e-9 * std::max(1e-30, svd.singularValues()[0])) {
    const double spread_meas = (dst.colwise() - cd).norm() / std::sqrt(n);
    const double spread_model = (src.colwise() - cs).norm() / std::sqrt(n);
    const char* why = spread_meas < 1e-6    ? "every measured position is the same (the same row repeated?)"
                      : spread_model < 1e-6 ? "the logged joints put the tool at the same place in every row (are "
                                              "the joint columns filled, in the unit their headers give?)"
                                            : "the measured positions, or the tool positions of the logged "
                                              "joints, lie on one line";
    Throw("the starting registration cannot be found: ", why,
          "; give measurements spread over the workspace, or a starting base transform");
  }
  Mat3 S = Mat3::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) S(2, 2) = -1;
  Pose T;
  T.R = svd.matrixU() * S * svd.matrixV().transpose();
  T.t = cd - T.R * cs;
  return T;
}

RobotCalibrationResult CalibrateRobot(const RobotModel& robot, const Pose& T_meas_base_guess,
                                      const std::vector<RobotMeasurement>& measurements,
                                      const RobotCalibrationOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("robot calibration options: ", why);
  CheckMeasurements(robot, measurements, "robot calibration");
  if (!options.error_motion_harmonics.empty()) {
    if (static_cast<int>(options.error_motion_harmonics.size()) != robot.NumJoints())
      Throw("robot calibration: error_motion_harmonics (--error-motion) has ", options.error_motion_harmonics.size(),
            options.error_motion_harmonics.size() == 1 ? " count" : " counts", " but robot '", robot.Name(), "' has ", robot.NumJoints(), " joints; give one count per joint");
    for (int i = 0; i < robot.NumJoints(); ++i)
      if (options.error_motion_harmonics[i] > 0 && robot.Joints()[i].type != JointType::kRevolute)
        Throw("robot calibration: error_motion_harmonics asks for harmonics of joint ", i + 1,
              ", which is prismatic; error motion is for revolute joints (give 0 for it)");
  }
  const int np = NumParameters(robot, options);
  const std::vector<std::string> names = CalibrationParameterNames(robot, options);

  RobotCalibrationResult result;
  result.parameters.resize(np);
  for (int k = 0; k < np; ++k) {
    result.parameters[k].name = names[k];
    result.parameters[k].angle = IsAngle(robot, k);
  }
  for (const std::string& f : options.fixed) {
    const auto it = std::find(names.begin(), names.end(), f);
    if (it == names.end())
      Throw("robot calibration: fixed parameter '", f, "' is not one of the ", np, " parameters of robot '",
            robot.Name(), "' (names like ", names[0], ", base.x, tool.rz)");
    auto& p = result.parameters[it - names.begin()];
    p.fixed = true;
    p.reason = "fixed by request";
  }
  for (int k = 0; k < np; ++k) {
    auto& p = result.parameters[k];
    const bool dh = k < BaseOffset(robot) || k >= ErrorMotionOffset(robot), base = k >= BaseOffset(robot) && k < ToolOffset(robot),
               tool = k >= ToolOffset(robot) && k < ErrorMotionOffset(robot);
    if (p.fixed) continue;
    if ((dh && !options.estimate_dh) || (base && !options.estimate_base) || (tool && !options.estimate_tool)) {
      p.fixed = true;
      p.reason = dh ? "DH parameters not estimated (registration only)" : "fixed by request";
    }
  }

  std::vector<std::unique_ptr<CostFunction>> costs;
  for (const auto& m : measurements) costs.push_back(MakeCost(robot, T_meas_base_guess, m, options));
  Eigen::VectorXd x = Eigen::VectorXd::Zero(np);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  Evaluate(costs, x, &r, &J);
  AnalyzeInPriorityOrder(robot, J, options.identifiability_tolerance, &result.parameters);

  std::vector<int> free, held;
  for (int k = 0; k < np; ++k) (result.parameters[k].fixed ? held : free).push_back(k);
  const int nr = static_cast<int>(r.size());
  const int dim = measurements[0].R_meas_tool ? 6 : 3;
  if (free.empty())
    Throw("robot calibration: every parameter is fixed; nothing to identify (allow DH, base or tool estimation)");
  if (nr <= static_cast<int>(free.size()))
    Throw("robot calibration: ", measurements.size(), " ", dim, "-D measurements give ", nr, " residuals for ",
          free.size(), " identifiable parameters; at least ", free.size() / dim + 1,
          " measurements are needed (3-5 times that for a useful calibration) - add poses");

  if (options.require_pose_identifiability) {
    // The same analysis on well-spread poses tells structural redundancies (fixed there
    // too) from ones this pose set causes.
    const std::vector<CalibrationParameter> reference =
        ReferenceIdentifiability(robot, T_meas_base_guess, measurements[0].R_meas_tool.has_value(), options, result);
    std::vector<std::string> weak;
    for (int k = 0; k < np; ++k)
      if (result.parameters[k].fixed && !reference[k].fixed) weak.push_back(names[k]);
    if (!weak.empty()) {
      std::ostringstream s;
      s << "robot calibration: the " << measurements.size() << " measurements do not identify";
      for (size_t k = 0; k < weak.size(); ++k) s << (k ? ", " : " ") << weak[k];
      s << " (at these poses each is a combination of other parameters; poses spread over the joint ranges "
           "separate them). Joint ranges covered:";
      for (int i = 0; i < robot.NumJoints(); ++i) {
        double lo = measurements[0].q[i], hi = lo;
        for (const auto& m : measurements) lo = std::min(lo, m.q[i]), hi = std::max(hi, m.q[i]);
        const bool rev = robot.Joints()[i].type == JointType::kRevolute;
        s << (i ? ", " : " ") << names[kParamsPerJoint * i].substr(0, names[kParamsPerJoint * i].find('.')) << " "
          << std::fixed << std::setprecision(rev ? 1 : 4) << (rev ? (hi - lo) * 180.0 / kPi : hi - lo)
          << (rev ? " deg" : " m");
      }
      s << ". Add measurements that move every joint over a wide range, or hold these parameters (fixed).";
      Throw(s.str());
    }
  }

  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  for (const auto& c : costs) problem.AddResidualBlock(c.get(), nullptr, x.data());
  if (!held.empty()) problem.SetManifold(x.data(), new ceres::SubsetManifold(np, held));

  struct Callback : ceres::IterationCallback {
    const std::function<void(int, double)>* f;
    ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
      if (*f) (*f)(s.iteration, s.cost);
      return ceres::SOLVER_CONTINUE;
    }
  } callback;
  callback.f = &options.progress;
  ceres::Solver::Options so;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = options.max_iterations;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.logging_type = ceres::SILENT;
  so.callbacks.push_back(&callback);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  result.iterations = static_cast<int>(summary.iterations.size());
  result.converged = summary.termination_type == ceres::CONVERGENCE;

  // Covariance of the free parameters from the Jacobian at the solution.
  Evaluate(costs, x, &r, &J);
  Eigen::MatrixXd Jf(J.rows(), free.size());
  for (size_t k = 0; k < free.size(); ++k) Jf.col(k) = J.col(free[k]);
  const Eigen::VectorXd scale = Jf.colwise().norm().transpose();
  const Eigen::MatrixXd Js = Jf * scale.cwiseInverse().asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  result.observability = sv[sv.size() - 1] / std::sqrt(static_cast<double>(measurements.size()));
  if (!(sv[sv.size() - 1] > 1e-10 * sv[0]))
    Throw("robot calibration: the problem is singular at the solution (condition number ",
          sv[0] / std::max(sv[sv.size() - 1], 1e-300),
          "); the poses do not separate the parameters - add poses that move every joint, or fix parameters");
  const Eigen::VectorXd inv = sv.cwiseInverse().cwiseAbs2();
  Eigen::MatrixXd cov_scaled = svd.matrixV() * inv.asDiagonal() * svd.matrixV().transpose();
  result.variance_factor = r.squaredNorm() / std::max(1, nr - static_cast<int>(free.size()));
  result.covariance = scale.cwiseInverse().asDiagonal() * cov_scaled * scale.cwiseInverse().asDiagonal();
  if (options.scale_covariance) result.covariance *= result.variance_factor;
  result.free_parameters = free;

  for (int k = 0; k < np; ++k) result.parameters[k].estimate = x[k];
  for (size_t k = 0; k < free.size(); ++k) result.parameters[free[k]].sigma = std::sqrt(result.covariance(k, k));
  for (size_t a = 0; a < free.size(); ++a)
    for (size_t b = a + 1; b < free.size(); ++b) {
      const double rho =
          result.covariance(a, b) / std::sqrt(result.covariance(a, a) * result.covariance(b, b));
      if (std::abs(rho) > options.correlation_threshold)
        result.correlated.push_back({names[free[a]], names[free[b]], rho});
    }

  // Calibrated model and registration.
  RobotModel calibrated = WithErrorMotionErrors(WithDhErrors(robot, x.head(BaseOffset(robot))),
                                                options.error_motion_harmonics,
                                                x.tail(np - ErrorMotionOffset(robot)));
  const Vec3 ub = x.segment<3>(BaseOffset(robot)), tb = x.segment<3>(BaseOffset(robot) + 3);
  const Vec3 uu = x.segment<3>(ToolOffset(robot)), tu = x.segment<3>(ToolOffset(robot) + 3);
  result.T_meas_base = Pose{ExpSO3(ub) * T_meas_base_guess.R, T_meas_base_guess.t + tb};
  calibrated.SetT_flange_tool(Pose{ExpSO3(uu) * robot.T_flange_tool().R, robot.T_flange_tool().t + tu});
  result.robot = calibrated;
  result.errors_before = PredictionErrors(robot, T_meas_base_guess, measurements);
  result.errors_after = PredictionErrors(result.robot, result.T_meas_base, measurements);
  return result;
}

CrossValidation CrossValidateRobot(const RobotModel& robot, const Pose& T_meas_base_guess,
                                   const std::vector<RobotMeasurement>& measurements,
                                   const RobotCalibrationOptions& options, int folds) {
  const int n = static_cast<int>(measurements.size());
  if (folds < 2 || folds > n)
    Throw("cross-validation: ", folds, " folds for ", n, " measurements; use 2 <= folds <= measurements");
  CrossValidation cv;
  cv.calibrated.resize(n);
  cv.nominal.resize(n);
  RobotCalibrationOptions reg = options;
  reg.estimate_dh = false;
  reg.error_motion_harmonics.clear();
  reg.progress = nullptr;
  RobotCalibrationOptions cal = options;
  cal.progress = nullptr;
  for (int f = 0; f < folds; ++f) {
    std::vector<RobotMeasurement> train, test;
    std::vector<int> test_index;
    for (int i = 0; i < n; ++i) {
      if (i % folds == f) {
        test.push_back(measurements[i]);
        test_index.push_back(i);
      } else {
        train.push_back(measurements[i]);
      }
    }
    const RobotCalibrationResult c = CalibrateRobot(robot, T_meas_base_guess, train, cal);
    const RobotCalibrationResult b = CalibrateRobot(robot, T_meas_base_guess, train, reg);
    const auto ec = PredictionErrors(c.robot, c.T_meas_base, test);
    const auto eb = PredictionErrors(b.robot, b.T_meas_base, test);
    for (size_t k = 0; k < test_index.size(); ++k) {
      cv.calibrated[test_index[k]] = ec[k];
      cv.nominal[test_index[k]] = eb[k];
    }
  }
  return cv;
}

namespace {

std::vector<int> KeptColumns(const RobotModel& robot, const Eigen::MatrixXd& J, const RobotCalibrationOptions& o) {
  std::vector<CalibrationParameter> params(J.cols());
  const auto names = CalibrationParameterNames(robot, o);
  for (size_t k = 0; k < params.size(); ++k) {
    params[k].name = names[k];
    params[k].angle = IsAngle(robot, static_cast<int>(k));
  }
  for (const auto& f : o.fixed)
    for (auto& p : params)
      if (p.name == f) p.fixed = true;
  for (int k = 0; k < static_cast<int>(params.size()); ++k)
    if (!o.estimate_dh && (k < BaseOffset(robot) || k >= ErrorMotionOffset(robot))) params[k].fixed = true;
  AnalyzeInPriorityOrder(robot, J, o.identifiability_tolerance, &params);
  std::vector<int> kept;
  for (size_t k = 0; k < params.size(); ++k)
    if (!params[k].fixed) kept.push_back(static_cast<int>(k));
  return kept;
}

}  // namespace

double ObservabilityIndex(const RobotModel& robot, const Pose& T_meas_base, const std::vector<Eigen::VectorXd>& poses,
                          bool six_dof, const RobotCalibrationOptions& options) {
  if (poses.empty()) Throw("ObservabilityIndex: no poses given");
  const Eigen::MatrixXd J = PoseJacobian(robot, T_meas_base, poses, six_dof, options);
  const std::vector<int> kept = KeptColumns(robot, J, options);
  if (kept.empty()) return 0.0;
  Eigen::MatrixXd Jk(J.rows(), kept.size());
  for (size_t k = 0; k < kept.size(); ++k) Jk.col(k) = J.col(kept[k]) / J.col(kept[k]).norm();
  const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd>(Jk).singularValues();
  return sv[sv.size() - 1] / std::sqrt(static_cast<double>(poses.size()));
}

std::vector<int> SelectPoses(const RobotModel& robot, const Pose& T_meas_base,
                             const std::vector<Eigen::VectorXd>& candidates, int k, bool six_dof,
                             const RobotCalibrationOptions& options) {
  const int n = static_cast<int>(candidates.size());
  if (k < 1 || k > n) Throw("SelectPoses: asked for ", k, " poses from ", n, " candidates; use 1 <= k <= candidates");
  const Eigen::MatrixXd J = PoseJacobian(robot, T_meas_base, candidates, six_dof, options);
  const std::vector<int> kept = KeptColumns(robot, J, options);
  const int dim = six_dof ? 6 : 3;
  const int p = static_cast<int>(kept.size());
  Eigen::MatrixXd Jk(J.rows(), p);
  for (int c = 0; c < p; ++c) Jk.col(c) = J.col(kept[c]);
  // Criterion on the column-normalized information matrix D M D (D = diag(M)^-1/2, the
  // same scaling ObservabilityIndex uses): while fewer residuals than parameters are
  // chosen its smallest eigenvalue is 0 for every candidate, so log det with a small
  // ridge (D-optimality) ranks them; after that the smallest eigenvalue itself, i.e. the
  // squared observability index (E-optimality).
  auto criterion = [&](const Eigen::MatrixXd& M, bool full_rank) {
    const Eigen::VectorXd d = M.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const Eigen::MatrixXd N = d.asDiagonal() * M * d.asDiagonal();
    if (!full_rank) {
      const Eigen::LLT<Eigen::MatrixXd> llt(N + 1e-6 * Eigen::MatrixXd::Identity(p, p));
      return 2.0 * llt.matrixLLT().diagonal().array().log().sum();
    }
    return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(N, Eigen::EigenvaluesOnly).eigenvalues()[0];
  };
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(p, p);
  std::vector<int> chosen;
  std::vector<bool> used(n, false);
  for (int step = 0; step < k; ++step) {
    const bool full_rank = (step + 1) * dim >= p;
    int best = -1;
    double best_value = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) {
      if (used[i]) continue;
      const Eigen::MatrixXd Ji = Jk.middleRows(i * dim, dim);
      const double value = criterion(M + Ji.transpose() * Ji, full_rank);
      if (value > best_value) {
        best_value = value;
        best = i;
      }
    }
    used[best] = true;
    chosen.push_back(best);
    const Eigen::MatrixXd Jb = Jk.middleRows(best * dim, dim);
    M += Jb.transpose() * Jb;
  }
  return chosen;
}

std::vector<RobotMeasurement> ReadRobotMeasurements(const std::filesystem::path& path) {
  const std::string source = "measurement file " + path.string();
  YAML::Node root;
  try {
    root = YAML::Load(ReadTextFile(path));
  } catch (const YAML::Exception& e) {
    Throw(source, ": not valid YAML: ", e.what());
  }
  std::vector<RobotMeasurement> out;
  try {
    if (root.IsMap() && root["measurements"]) {
      const YAML::Node list = root["measurements"];
      if (!list.IsSequence() || list.size() == 0) Throw(source, ": 'measurements' must be a non-empty list");
      for (size_t i = 0; i < list.size(); ++i) {
        const YAML::Node e = list[i];
        const std::string where = source + " measurement " + std::to_string(i + 1) + " (line " +
                                  std::to_string(e.Mark().line + 1) + ")";
        RobotMeasurement m;
        std::vector<double> q;
        if (e["q_rad"]) {
          q = ReadList(e["q_rad"], where + " q_rad");
        } else if (e["q_deg"]) {
          q = ReadList(e["q_deg"], where + " q_deg");
          for (double& v : q) v *= kPi / 180.0;
        } else {
          Throw(where, ": missing 'q_rad' (or 'q_deg'), the joint values");
        }
        m.q = Eigen::Map<Eigen::VectorXd>(q.data(), static_cast<int>(q.size()));
        if (!e["position_m"]) Throw(where, ": missing 'position_m' [x, y, z]");
        const auto p = ReadList(e["position_m"], where + " position_m");
        if (p.size() != 3) Throw(where, ": position_m must have 3 numbers, has ", p.size());
        m.p_meas = Vec3(p[0], p[1], p[2]);
        if (e["quaternion_wxyz"]) {
          const auto v = ReadList(e["quaternion_wxyz"], where + " quaternion_wxyz");
          if (v.size() != 4) Throw(where, ": quaternion_wxyz must have 4 numbers");
          const Eigen::Quaterniond qq(v[0], v[1], v[2], v[3]);
          if (std::abs(qq.norm() - 1.0) > 1e-3) Throw(where, ": quaternion_wxyz has norm ", qq.norm(), ", expected 1");
          m.R_meas_tool = qq.normalized().toRotationMatrix();
        }
        m.source = where;
        out.push_back(m);
      }
    } else if (root.IsMap() && root.size() > 0) {
      for (const auto& kv : root) {
        const std::string where = source + " entry '" + kv.first.as<std::string>() + "' (line " +
                                  std::to_string(kv.first.Mark().line + 1) + ")";
        const YAML::Node e = kv.second;
        if (!e.IsMap() || !e["pose"] || !e["target_joints"])
          Throw(where, ": expected 'pose' and 'target_joints' (industrial_calibration layout) or a top-level "
                       "'measurements' list (mcms layout)");
        if (e["camera_joints"] && e["camera_joints"].size() > 0)
          Throw(where, ": camera_joints is not empty; only a static measuring system is supported");
        const auto q = ReadList(e["target_joints"], where + " target_joints");
        RobotMeasurement m;
        m.q = Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<int>(q.size()));
        const Pose T = ParsePoseNode(e["pose"], where);
        m.p_meas = T.t;
        m.R_meas_tool = T.R;
        m.source = where;
        out.push_back(m);
      }
    } else {
      Throw(source, ": expected a 'measurements' list or a map of industrial_calibration measurements");
    }
  } catch (const YAML::Exception& e) {
    Throw(source, ": ", e.what());
  }
  return out;
}

void WriteRobotMeasurements(const std::filesystem::path& path, const std::vector<RobotMeasurement>& ms) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap << YAML::Key << "measurements" << YAML::Value << YAML::BeginSeq;
  for (const auto& m : ms) {
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "q_rad" << YAML::Value << YAML::Flow
        << std::vector<double>(m.q.data(), m.q.data() + m.q.size());
    out << YAML::Key << "position_m" << YAML::Value << YAML::Flow
        << std::vector<double>{m.p_meas.x(), m.p_meas.y(), m.p_meas.z()};
    if (m.R_meas_tool) {
      Eigen::Quaterniond q(*m.R_meas_tool);
      if (q.w() < 0) q.coeffs() *= -1.0;
      out << YAML::Key << "quaternion_wxyz" << YAML::Value << YAML::Flow
          << std::vector<double>{q.w(), q.x(), q.y(), q.z()};
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  const std::string text = std::string(out.c_str()) + "\n";
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

}  // namespace mcms
