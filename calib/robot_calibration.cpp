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
constexpr int kPerHarmonic = kErrorMotionParamsPerHarmonic;  // sin [rx ry rz x y z], cos [..]

// Harmonics of error motion estimated for joint i (options.error_motion_harmonics).
int HarmonicsOf(const RobotCalibrationOptions& o, int i) {
  return o.error_motion_harmonics.empty() ? 0 : o.error_motion_harmonics[i];
}

// Where each part of the parameter vector starts (the header's layout).
struct Layout {
  int geometry = 0, base = 0, tool = 0, points = 0, error_motion = 0, total = 0;
  int num_points = 1;
  Layout(const RobotModel& r, const RobotCalibrationOptions& o, int K) : num_points(std::max(1, K)) {
    base = r.NumGeometryParameters();
    tool = base + 6;
    points = tool + 6;
    error_motion = points + 3 * (num_points - 1);
    total = error_motion;
    for (int i = 0; i < r.NumJoints(); ++i) total += kPerHarmonic * HarmonicsOf(o, i);
  }
  bool IsGeometry(int k) const { return k < base; }
  bool IsBase(int k) const { return k >= base && k < tool; }
  bool IsTool(int k) const { return k >= tool && k < points; }
  bool IsPoint(int k) const { return k >= points && k < error_motion; }
  bool IsErrorMotion(int k) const { return k >= error_motion; }
};

// Whether parameter k of the layout is an angle (rad) rather than a length (m).
bool IsAngle(const RobotModel& r, const Layout& L, int k) {
  if (L.IsGeometry(k)) return GeometryParameterIsAngle(r, k);
  if (L.IsBase(k)) return k - L.base < 3;
  if (L.IsTool(k)) return k - L.tool < 3;
  if (L.IsPoint(k)) return false;
  return (k - L.error_motion) % 6 < 3;
}

int NumPointsOf(const std::vector<RobotMeasurement>& ms) { return ms.empty() ? 1 : ms.front().NumPoints(); }

// ---- The one cost functor: whitened prediction error of one measurement. ----
// Parameter block: the full vector of the header's layout. Residuals: 3 per point (point 1
// at the tool origin, point k at T_flange_tool p_k), and for a pose the rotation vector of
// R_pred R_meas^T, each divided by its sigma.
struct MeasurementCost {
  const RobotModel* robot;
  Layout layout;
  std::vector<int> harmonics;  // estimated error-motion harmonics per joint
  Eigen::VectorXd q;
  Pose base0, tool0;
  std::vector<Vec3> points0;   // starting p_k, k = 2..K (tool frame)
  std::vector<Vec3> measured;  // the K measured points
  std::optional<Mat3> R_meas;
  double inv_sigma_p, inv_sigma_r;

  template <typename T>
  bool operator()(T const* const* params, T* residual) const {
    using M3 = Eigen::Matrix<T, 3, 3>;
    using V3 = Eigen::Matrix<T, 3, 1>;
    const T* x = params[0];
    ChainCorrections<T> c;
    c.geometry = x;
    c.error_motion = x + layout.error_motion;
    c.error_motion_harmonics = harmonics;
    const PoseT<T> F = ForwardKinematicsT(*robot, q, c);
    const T* b = x + layout.base;
    const T* u = x + layout.tool;
    M3 dRb, dRu;
    ceres::AngleAxisToRotationMatrix(b, dRb.data());  // column-major, as Eigen stores
    ceres::AngleAxisToRotationMatrix(u, dRu.data());
    const M3 Rb = dRb * base0.R.cast<T>();
    const V3 tb = base0.t.cast<T>() + V3(b[3], b[4], b[5]);
    const M3 Ru = dRu * tool0.R.cast<T>();
    const V3 tu = tool0.t.cast<T>() + V3(u[3], u[4], u[5]);
    // T_meas_tool = T_meas_base * T_base_flange * T_flange_tool
    const M3 R_mt = Rb * F.R * Ru;
    const V3 t_mt = Rb * (F.R * tu + F.t) + tb;
    for (size_t k = 0; k < measured.size(); ++k) {
      V3 p = t_mt;
      if (k > 0) {
        const T* pk = x + layout.points + 3 * (k - 1);
        p += R_mt * (points0[k - 1].cast<T>() + V3(pk[0], pk[1], pk[2]));
      }
      for (int a = 0; a < 3; ++a) residual[3 * k + a] = (p[a] - T(measured[k][a])) * T(inv_sigma_p);
    }
    if (R_meas) {
      const M3 E = R_mt * R_meas->transpose().cast<T>();
      T r[3];
      ceres::RotationMatrixToAngleAxis(E.data(), r);
      for (int a = 0; a < 3; ++a) residual[3 * measured.size() + a] = r[a] * T(inv_sigma_r);
    }
    return true;
  }
};

using CostFunction = ceres::DynamicAutoDiffCostFunction<MeasurementCost, 4>;

std::unique_ptr<CostFunction> MakeCost(const RobotModel& robot, const Pose& base0, const RobotMeasurement& m,
                                       const RobotCalibrationOptions& o, const std::vector<Vec3>& points0) {
  const int K = m.NumPoints();
  if (static_cast<int>(points0.size()) != K - 1)
    Throw("robot calibration: ", m.source.empty() ? std::string("a measurement") : m.source, " has ", K,
          " points but the body has ", points0.size() + 1);
  std::vector<Vec3> measured{m.p_meas};
  measured.insert(measured.end(), m.other_points.begin(), m.other_points.end());
  auto* f = new MeasurementCost{&robot, Layout(robot, o, K), o.error_motion_harmonics, m.q,
                                base0,  robot.T_flange_tool(), points0, measured, m.R_meas_tool,
                                1.0 / o.position_sigma_m, 1.0 / o.rotation_sigma_rad};
  auto c = std::make_unique<CostFunction>(f);
  c->AddParameterBlock(f->layout.total);
  c->SetNumResiduals(3 * K + (m.R_meas_tool ? 3 : 0));
  return c;
}

}  // namespace

std::unique_ptr<ceres::CostFunction> MakeRobotMeasurementCost(const RobotModel& robot, const Pose& base0,
                                                               const RobotMeasurement& m,
                                                               const RobotCalibrationOptions& options,
                                                               const std::vector<Vec3>& points0) {
  return MakeCost(robot, base0, m, options, points0);
}

int NumCalibrationParameters(const RobotModel& robot, const RobotCalibrationOptions& options, int num_points) {
  return Layout(robot, options, num_points).total;
}

bool GlobMatch(const std::string& pattern, const std::string& name) {
  // Iterative matcher with backtracking to the last '*'.
  size_t p = 0, n = 0, star = std::string::npos, mark = 0;
  const auto ClassEnd = [&](size_t at) {
    size_t e = at + 1;
    if (e < pattern.size() && (pattern[e] == '!' || pattern[e] == '^')) ++e;
    if (e < pattern.size() && pattern[e] == ']') ++e;
    while (e < pattern.size() && pattern[e] != ']') ++e;
    return e;  // at ']' or pattern.size()
  };
  const auto InClass = [&](size_t at, char c) {
    size_t i = at + 1;
    bool negate = false;
    if (i < pattern.size() && (pattern[i] == '!' || pattern[i] == '^')) negate = true, ++i;
    bool hit = false;
    const size_t end = ClassEnd(at);
    for (bool first = true; i < end; first = false) {
      if (pattern[i] == ']' && !first) break;
      if (i + 2 < end && pattern[i + 1] == '-') {
        hit |= c >= pattern[i] && c <= pattern[i + 2];
        i += 3;
      } else {
        hit |= c == pattern[i];
        ++i;
      }
    }
    return hit != negate;
  };
  while (n < name.size()) {
    if (p < pattern.size() && pattern[p] == '*') {
      star = p++;
      mark = n;
    } else if (p < pattern.size() && pattern[p] == '?') {
      ++p, ++n;
    } else if (p < pattern.size() && pattern[p] == '[' && ClassEnd(p) < pattern.size()) {
      if (!InClass(p, name[n])) {
        if (star == std::string::npos) return false;
        p = star + 1, n = ++mark;
        continue;
      }
      p = ClassEnd(p) + 1, ++n;
    } else if (p < pattern.size() && pattern[p] == name[n]) {
      ++p, ++n;
    } else if (star != std::string::npos) {
      p = star + 1, n = ++mark;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
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

// Priority order of the identifiability analysis: base, tool, the points of a rigid body,
// the joints' geometric errors, then the error-motion harmonics (so a harmonic term that
// duplicates the geometry is the one held).
std::vector<int> PriorityOrder(const Layout& L) {
  std::vector<int> order;
  for (int k = L.base; k < L.error_motion; ++k) order.push_back(k);
  for (int k = 0; k < L.base; ++k) order.push_back(k);
  for (int k = L.error_motion; k < L.total; ++k) order.push_back(k);
  return order;
}

// Runs the analysis in priority order on a parameter list whose requested fixes are set.
void AnalyzeInPriorityOrder(const Layout& L, const Eigen::MatrixXd& J, double tol,
                            std::vector<CalibrationParameter>* params) {
  const std::vector<int> order = PriorityOrder(L);
  Eigen::MatrixXd Jp(J.rows(), J.cols());
  std::vector<std::string> names;
  std::vector<CalibrationParameter> permuted;
  for (size_t k = 0; k < order.size(); ++k) {
    Jp.col(k) = J.col(order[k]);
    names.push_back((*params)[order[k]].name);
    permuted.push_back((*params)[order[k]]);
  }
  std::vector<ParameterStatus> status(permuted.size());
  for (size_t k = 0; k < permuted.size(); ++k) status[k] = {permuted[k].fixed, permuted[k].reason};
  AnalyzeIdentifiability(Jp, names, tol, &status);
  for (size_t k = 0; k < order.size(); ++k) {
    permuted[k].fixed = status[k].fixed;
    permuted[k].reason = status[k].reason;
    (*params)[order[k]] = permuted[k];
  }
}

// Where points 2..K of a rigid body start in the tool frame: their mean offset from point 1
// over the measurements, turned into the tool frame the nominal model and the starting
// registration give.
std::vector<Vec3> StartingPoints(const RobotModel& robot, const Pose& T_meas_base,
                                 const std::vector<RobotMeasurement>& ms) {
  const int K = NumPointsOf(ms);
  std::vector<Vec3> p(K - 1, Vec3::Zero());
  for (const auto& m : ms) {
    const Mat3 R_meas_tool = T_meas_base.R * robot.T_base_tool(m.q).R;
    for (int k = 1; k < K; ++k) p[k - 1] += R_meas_tool.transpose() * (m.other_points[k - 1] - m.p_meas);
  }
  for (auto& v : p) v /= static_cast<double>(ms.size());
  return p;
}

// Whitened Jacobian rows of hypothetical measurements at the given poses (measured values
// are the model's own predictions: only the Jacobian matters), over all parameters.
Eigen::MatrixXd PoseJacobian(const RobotModel& robot, const Pose& T_meas_base,
                             const std::vector<Eigen::VectorXd>& poses, bool six_dof,
                             const RobotCalibrationOptions& options, const std::vector<Vec3>& points0 = {}) {
  std::vector<std::unique_ptr<CostFunction>> costs;
  for (size_t i = 0; i < poses.size(); ++i) {
    std::string why;
    if (!robot.WithinLimits(poses[i], &why)) Throw("pose ", i + 1, ": ", why);
    RobotMeasurement m;
    m.q = poses[i];
    const Pose T = T_meas_base * robot.T_base_tool(m.q);
    m.p_meas = T.t;
    for (const Vec3& p : points0) m.other_points.push_back(T * p);
    if (six_dof) m.R_meas_tool = T.R;
    costs.push_back(MakeCost(robot, T_meas_base, m, options, points0));
  }
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  Evaluate(costs, Eigen::VectorXd::Zero(Layout(robot, options, 1 + points0.size()).total), &r, &J);
  return J;
}

// Identifiability at 60 poses drawn uniformly within the joint limits (open or very wide
// limits clamped to +-pi rad or +-1 m), with the requests already applied in `requested`:
// the redundancies that hold for any pose set.
std::vector<CalibrationParameter> ReferenceIdentifiability(const RobotModel& robot, const Pose& T_meas_base,
                                                           bool six_dof, const RobotCalibrationOptions& options,
                                                           const RobotCalibrationResult& requested,
                                                           const std::vector<Vec3>& points0) {
  Rng rng(20260101);
  std::vector<Eigen::VectorXd> poses;
  for (int k = 0; k < 60; ++k) {
    Eigen::VectorXd q(robot.NumJoints());
    for (int i = 0; i < robot.NumJoints(); ++i) {
      const Joint& j = robot.Joints()[i];
      const auto [lo, hi] = SamplingRange(j);
      q[i] = rng.Uniform(lo, hi);
    }
    if (robot.HasMimicJoints()) q = robot.ChainValues(robot.ActuatedValues(q));  // mimic joints follow
    poses.push_back(q);
  }
  const Eigen::MatrixXd J = PoseJacobian(robot, T_meas_base, poses, six_dof, options, points0);
  std::vector<CalibrationParameter> params = requested.parameters;
  for (auto& p : params)
    if (!p.requested) {
      p.fixed = false;
      p.reason.clear();
    }
  AnalyzeInPriorityOrder(Layout(robot, options, 1 + points0.size()), J, options.identifiability_tolerance, &params);
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

std::vector<std::string> CalibrationParameterNames(const RobotModel& robot, const RobotCalibrationOptions& options,
                                                   int num_points) {
  std::vector<std::string> names = GeometryParameterNames(robot);
  for (const char* f : {"base", "tool"})
    for (const char* c : {".rx", ".ry", ".rz", ".x", ".y", ".z"}) names.push_back(std::string(f) + c);
  for (int k = 2; k <= num_points; ++k)
    for (const char* c : {".x", ".y", ".z"}) names.push_back("point" + std::to_string(k) + c);
  for (int i = 0; i < robot.NumJoints(); ++i) {
    std::string joint = robot.Joints()[i].name;
    if (joint.empty()) {
      joint = std::to_string(i + 1);  // (GCC 12 -Wrestrict misfires on "J" + ...)
      joint.insert(joint.begin(), 'J');
    }
    for (int h = 1; h <= HarmonicsOf(options, i); ++h)
      for (const char* sc : {".sin.", ".cos."})
        for (const char* c : {"rx", "ry", "rz", "x", "y", "z"})
          names.push_back(joint + ".em" + std::to_string(h) + sc + c);
  }
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

std::vector<PoseError> PredictionErrors(const RobotModel& robot, const Pose& T_meas_base,
                                        const std::vector<RobotMeasurement>& measurements,
                                        const std::vector<Vec3>& points_tool) {
  CheckRobotMeasurements(robot, measurements, "PredictionErrors");
  std::vector<PoseError> e;
  for (const auto& m : measurements) {
    const Pose T = T_meas_base * robot.T_base_tool(m.q);
    PoseError pe;
    pe.dp = T.t - m.p_meas;
    for (size_t k = 0; k < m.other_points.size() && k < points_tool.size(); ++k)
      pe.other_dp.push_back(T * points_tool[k] - m.other_points[k]);
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

ErrorStats SummarizePoint(const std::vector<PoseError>& errors, int k, const std::vector<int>& rows) {
  std::vector<PoseError> one;
  const auto Add = [&](const PoseError& e) {
    if (k > 0 && k - 1 >= static_cast<int>(e.other_dp.size())) return;
    PoseError p;
    p.dp = e.Point(k);
    one.push_back(p);
  };
  if (rows.empty())
    for (const auto& e : errors) Add(e);
  else
    for (int i : rows) Add(errors.at(i));
  return Summarize(one);
}

RobotCalibrationResult CalibrateRobot(const RobotModel& robot_in, const Pose& T_meas_base_guess,
                                      const std::vector<RobotMeasurement>& measurements,
                                      const RobotCalibrationOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("robot calibration options: ", why);
  RobotModel robot = robot_in;  // its tool becomes the registered one below
  CheckRobotMeasurements(robot, measurements, "robot calibration");
  if (!options.error_motion_harmonics.empty()) {
    if (static_cast<int>(options.error_motion_harmonics.size()) != robot.NumJoints())
      Throw("robot calibration: error_motion_harmonics (--error-motion) has ", options.error_motion_harmonics.size(),
            options.error_motion_harmonics.size() == 1 ? " count" : " counts", " but robot '", robot.Name(), "' has ", robot.NumJoints(), " joints; give one count per joint");
    for (int i = 0; i < robot.NumJoints(); ++i)
      if (options.error_motion_harmonics[i] > 0 && robot.Joints()[i].type != JointType::kRevolute)
        Throw("robot calibration: error_motion_harmonics asks for harmonics of joint ", i + 1,
              ", which is prismatic; error motion is for revolute joints (give 0 for it)");
  }
  const int K = NumPointsOf(measurements);
  const Layout L(robot, options, K);
  const int np = L.total;
  const std::vector<std::string> names = CalibrationParameterNames(robot, options, K);
  const bool six = measurements[0].R_meas_tool.has_value();

  RobotCalibrationResult result;
  result.parameters.resize(np);
  for (int k = 0; k < np; ++k) {
    result.parameters[k].name = names[k];
    result.parameters[k].angle = IsAngle(robot, L, k);
  }
  const auto Hold = [&](int k, const std::string& reason) {
    auto& p = result.parameters[k];
    if (p.fixed) return;
    p.fixed = true;
    p.requested = true;
    p.reason = reason;
  };
  for (const std::string& f : options.fixed) {
    const auto it = std::find(names.begin(), names.end(), f);
    if (it == names.end())
      Throw("robot calibration: fixed parameter '", f, "' is not one of the ", np, " parameters of robot '",
            robot.Name(), "' (names like ", names[0], ", base.x, tool.rz)");
    Hold(static_cast<int>(it - names.begin()), "fixed by request");
  }
  for (const auto& [name, why] : options.held_weak) {
    const auto it = std::find(names.begin(), names.end(), name);
    if (it != names.end()) Hold(static_cast<int>(it - names.begin()), why);
  }
  for (const std::string& pattern : options.estimate_only) {
    bool any = false;
    for (int k = 0; k < np; ++k) any |= (L.IsGeometry(k) || L.IsErrorMotion(k)) && GlobMatch(pattern, names[k]);
    if (!any)
      Throw("robot calibration: --estimate '", pattern, "' matches none of the geometric parameters of robot '",
            robot.Name(), "' (names like ", names[0], ", ", names[std::min<int>(1, np - 1)], ")");
  }
  for (int k = 0; k < np; ++k) {
    const bool model = L.IsGeometry(k) || L.IsErrorMotion(k);
    if (model && !options.estimate_dh) Hold(k, "geometry not estimated (registration only)");
    if (L.IsBase(k) && !options.estimate_base) Hold(k, "fixed by request");
    if ((L.IsTool(k) || L.IsPoint(k)) && !options.estimate_tool) Hold(k, "fixed by request");
    if (model && !options.estimate_only.empty()) {
      bool match = false;
      for (const std::string& pattern : options.estimate_only) match |= GlobMatch(pattern, names[k]);
      if (!match) Hold(k, "not among the estimated parameters (--estimate)");
    }
    // Points measured without an orientation: the points' own offsets carry the tool's rotation.
    if (K > 1 && !six && L.IsTool(k) && k - L.tool < 3)
      Hold(k, "the points' offsets in the tool frame carry the tool's rotation (points measured, no orientation)");
  }

  Pose base0 = T_meas_base_guess;
  std::vector<Vec3> points0 = StartingPoints(robot, base0, measurements);
  const std::vector<Vec3> points_guess = points0;
  // The registration first, with the geometry nominal: the geometry's identifiability is
  // judged, and its solve started, where the nominal model fits the data, not at a starting
  // guess (a tool point there may sit on a joint's axis and hide that joint's terms).
  bool geometry_free = false;
  for (int k = 0; k < np; ++k) geometry_free |= (L.IsGeometry(k) || L.IsErrorMotion(k)) && !result.parameters[k].fixed;
  if (geometry_free && (options.estimate_base || options.estimate_tool)) {
    RobotCalibrationOptions reg = options;
    reg.estimate_dh = false;
    reg.error_motion_harmonics.clear();
    reg.estimate_only.clear();
    reg.progress = nullptr;
    const RobotCalibrationResult first = CalibrateRobot(robot, base0, measurements, reg);
    base0 = first.T_meas_base;
    // The tool (and the body's points) only where the registration moved them by more than
    // a centimetre and their own uncertainty: the robot file's tool within a centimetre is
    // the target the user measured, and stays exact (on a joint's axis, say, where that
    // joint's terms are not identifiable; the registration would put it a residual's width
    // off the axis and make them look weakly identifiable); a target far from the tool frame
    // (motion-capture markers 12 cm from a URDF's tip link) is started where it is.
    double moved = (first.robot.T_flange_tool().t - robot.T_flange_tool().t).norm(), sigma = 0;
    for (const auto& p : first.parameters)
      if (!p.fixed && (p.name == "tool.x" || p.name == "tool.y" || p.name == "tool.z")) sigma = std::max(sigma, p.sigma);
    for (size_t k = 0; k < points0.size() && k < first.points_tool.size(); ++k)
      moved = std::max(moved, (first.points_tool[k] - points0[k]).norm());
    if (moved > std::max(0.01, 3.0 * sigma)) {
      robot.SetT_flange_tool(first.robot.T_flange_tool());
      points0 = first.points_tool;
    }
  }
  std::vector<std::unique_ptr<CostFunction>> costs;
  for (const auto& m : measurements) costs.push_back(MakeCost(robot, base0, m, options, points0));
  Eigen::VectorXd x = Eigen::VectorXd::Zero(np);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  Evaluate(costs, x, &r, &J);
  AnalyzeInPriorityOrder(L, J, options.identifiability_tolerance, &result.parameters);

  std::vector<int> free, held;
  for (int k = 0; k < np; ++k) (result.parameters[k].fixed ? held : free).push_back(k);
  const int nr = static_cast<int>(r.size());
  const int dim = 3 * K + (six ? 3 : 0);
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
        ReferenceIdentifiability(robot, base0, six, options, result, points0);
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
        const std::string& jn = names[robot.GeometryParamsPerJoint() * i];
        s << (i ? ", " : " ") << jn.substr(0, jn.find('.')) << " "
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
    std::vector<double> costs;  // after each iteration
    ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
      costs.push_back(s.cost);
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
  // Ceres lists iteration 0 (the start) too: the count of steps is one less.
  result.iterations = std::max(0, static_cast<int>(summary.iterations.size()) - 1);
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  // Ceres' tolerances here are tight (1e-12): an ill-conditioned but settled problem runs
  // out of iterations while its cost no longer moves. Settled counts as converged: the
  // (whitened) cost changed by less than kSettledCostChange over the last 10 iterations.
  if (callback.costs.size() > 10) {
    const double last = callback.costs.back(), before = callback.costs[callback.costs.size() - 11];
    result.last_cost_change = std::abs(before - last);
  }
  if (!result.converged && summary.termination_type == ceres::NO_CONVERGENCE)
    result.converged = result.last_cost_change <= RobotCalibrationResult::kSettledCostChange;

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
  RobotModel calibrated = WithErrorMotionErrors(WithGeometryErrors(robot, x.head(L.base)),
                                                options.error_motion_harmonics, x.tail(np - L.error_motion));
  const Vec3 ub = x.segment<3>(L.base), tb = x.segment<3>(L.base + 3);
  const Vec3 uu = x.segment<3>(L.tool), tu = x.segment<3>(L.tool + 3);
  result.T_meas_base = Pose{ExpSO3(ub) * base0.R, base0.t + tb};
  calibrated.SetT_flange_tool(Pose{ExpSO3(uu) * robot.T_flange_tool().R, robot.T_flange_tool().t + tu});
  result.robot = calibrated;
  for (int k = 1; k < K; ++k) result.points_tool.push_back(points0[k - 1] + x.segment<3>(L.points + 3 * (k - 1)));
  result.errors_before = PredictionErrors(robot_in, T_meas_base_guess, measurements, points_guess);
  result.errors_after = PredictionErrors(result.robot, result.T_meas_base, measurements, result.points_tool);
  // Weakly identifiable (issue 51): a geometric parameter known only to worse than a
  // placement could be off is held at nominal, never written into the calibrated robot; the
  // worst first, then the problem is solved again without it (a solve that did not converge
  // is refused as it is, its sigmas unknown).
  {
    int worst = -1;
    double ratio = 1.0;
    for (size_t k = 0; k < free.size(); ++k) {
      const int p = free[k];
      if (!L.IsGeometry(p)) continue;
      const double r = result.parameters[p].sigma / WeakGeometrySigma(robot, p);
      if (r > ratio) ratio = r, worst = p;
    }
    if (worst >= 0 && result.converged && options.held_weak.size() < static_cast<size_t>(np)) {
      RobotCalibrationOptions again = options;
      std::ostringstream why;
      why << "weakly identifiable: these poses give it a standard deviation of " << result.parameters[worst].sigma
          << (result.parameters[worst].angle ? " rad" : " m") << ", more than a robot's placement could be off ("
          << WeakGeometrySigma(robot, worst) << "); held at nominal";
      again.held_weak.push_back({names[worst], why.str()});
      return CalibrateRobot(robot_in, T_meas_base_guess, measurements, again);
    }
  }
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
    const auto ec = PredictionErrors(c.robot, c.T_meas_base, test, c.points_tool);
    const auto eb = PredictionErrors(b.robot, b.T_meas_base, test, b.points_tool);
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
  const Layout L(robot, o, 1);
  for (size_t k = 0; k < params.size(); ++k) {
    params[k].name = names[k];
    params[k].angle = IsAngle(robot, L, static_cast<int>(k));
  }
  for (const auto& f : o.fixed)
    for (auto& p : params)
      if (p.name == f) p.fixed = true;
  for (int k = 0; k < static_cast<int>(params.size()); ++k) {
    const bool model = L.IsGeometry(k) || L.IsErrorMotion(k);
    if (model && !o.estimate_dh) params[k].fixed = true;
    if (model && !o.estimate_only.empty()) {
      bool match = false;
      for (const std::string& pattern : o.estimate_only) match |= GlobMatch(pattern, names[k]);
      if (!match) params[k].fixed = true;
    }
  }
  AnalyzeInPriorityOrder(L, J, o.identifiability_tolerance, &params);
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

}  // namespace mcms
