#include "calib/robot_audit.h"

#include <algorithm>
#include <cctype>
#include <limits>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <memory>
#include <numeric>
#include <sstream>

#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/normal.hpp>
#include <ceres/ceres.h>
#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/rotation.h>

#include "calib/robot_calibration.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "model/model_selection.h"

namespace mcms {
namespace {

// ---------------------------------------------------------------------------------
// Reading

std::string LineOf(const RobotLog& log, size_t i) {
  std::ostringstream o;
  o << log.source.string();
  if (log.rows[i].line > 0) o << " line " << log.rows[i].line;
  else o << " row " << i + 1;
  return o.str();
}

}  // namespace

void CheckRobotLog(const RobotLog& log, const RobotModel& robot) {
  const std::string src = log.source.empty() ? std::string("robot log") : log.source.string();
  if (static_cast<int>(log.rows.size()) < kMinRobotLogRows)
    Throw(src, ": ", log.rows.size(), log.rows.size() == 1 ? " measurement" : " measurements", "; the audit needs at least ",
          kMinRobotLogRows, " (the registration alone has 9 parameters; repeated poses over time show the noise)");
  const bool six = log.rows.front().R_meas_tool.has_value();
  for (size_t i = 0; i < log.rows.size(); ++i) {
    const RobotLogRow& r = log.rows[i];
    if (r.q.size() != robot.NumJoints())
      Throw(LineOf(log, i), ": ", r.q.size(), " joint values but robot '", robot.Name(), "' has ", robot.NumJoints(),
            " joints; give the robot description the log was measured with (--robot)");
    std::string why;
    if (!robot.WithinLimits(r.q, &why)) Throw(LineOf(log, i), ": ", why);
    if (!r.p_meas.allFinite()) Throw(LineOf(log, i), ": the measured position is not finite");
    if (!std::isfinite(r.time_s)) Throw(LineOf(log, i), ": time_s is not finite");
    if (i > 0 && r.time_s < log.rows[i - 1].time_s)
      Throw(LineOf(log, i), ": time_s ", r.time_s, " is before the previous row's ", log.rows[i - 1].time_s,
            "; rows must be in time order");
    if (r.R_meas_tool.has_value() != six)
      Throw(LineOf(log, i), ": some rows have a measured orientation and some do not; give all or none");
    if (log.has_temperature && !std::isfinite(r.temperature_c))
      Throw(LineOf(log, i), ": temperature_c is not a finite number");
    if (log.has_payload && !(std::isfinite(r.payload_kg) && r.payload_kg >= 0))
      Throw(LineOf(log, i), ": payload_kg is ", r.payload_kg, "; expected a finite mass >= 0");
  }
}

RobotLog ReadRobotLog(const std::filesystem::path& path, const RobotModel& robot) {
  RobotLog log;
  log.source = path;
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".yaml" || ext == ".yml") {
    const std::vector<RobotMeasurement> m = ReadRobotMeasurements(path);
    for (size_t i = 0; i < m.size(); ++i) {
      RobotLogRow r;
      r.time_s = static_cast<double>(i);
      r.q = m[i].q;
      r.p_meas = m[i].p_meas;
      r.R_meas_tool = m[i].R_meas_tool;
      log.rows.push_back(r);
    }
  } else {
    const CsvTable t = ReadCsv(path);
    int nq = 0;
    while (t.HasColumn("q" + std::to_string(nq + 1) + "_rad")) ++nq;
    if (nq == 0)
      Throw(path.string(), ": no joint columns; expected q1_rad..q", robot.NumJoints(),
            "_rad (with time_s, x_m, y_m, z_m)");
    if (nq != robot.NumJoints())
      Throw(path.string(), ": ", nq, " joint columns (q1_rad..q", nq, "_rad) but robot '", robot.Name(), "' has ",
            robot.NumJoints(), " joints; give the robot description the log was measured with (--robot)");
    const int ct = t.Column("time_s"), cx = t.Column("x_m"), cy = t.Column("y_m"), cz = t.Column("z_m");
    std::vector<int> cq(nq);
    for (int j = 0; j < nq; ++j) cq[j] = t.Column("q" + std::to_string(j + 1) + "_rad");
    const bool has_q = t.HasColumn("qw") || t.HasColumn("qx") || t.HasColumn("qy") || t.HasColumn("qz");
    int cqw = -1, cqx = -1, cqy = -1, cqz = -1;
    if (has_q) cqw = t.Column("qw"), cqx = t.Column("qx"), cqy = t.Column("qy"), cqz = t.Column("qz");
    log.has_temperature = t.HasColumn("temperature_c");
    log.has_payload = t.HasColumn("payload_kg");
    const int ctemp = log.has_temperature ? t.Column("temperature_c") : -1;
    const int cpay = log.has_payload ? t.Column("payload_kg") : -1;
    log.has_time = true;
    for (size_t i = 0; i < t.rows.size(); ++i) {
      RobotLogRow r;
      r.line = t.line_of_row[i];
      r.time_s = t.Number(i, ct);
      r.q.resize(nq);
      for (int j = 0; j < nq; ++j) r.q[j] = t.Number(i, cq[j]);
      r.p_meas = Vec3(t.Number(i, cx), t.Number(i, cy), t.Number(i, cz));
      if (has_q) {
        const Eigen::Quaterniond qq(t.Number(i, cqw), t.Number(i, cqx), t.Number(i, cqy), t.Number(i, cqz));
        if (std::abs(qq.norm() - 1.0) > 1e-3)
          Throw(path.string(), " line ", r.line, ": quaternion (qw, qx, qy, qz) has norm ", qq.norm(), "; expected 1");
        r.R_meas_tool = qq.normalized().toRotationMatrix();
      }
      if (ctemp >= 0) r.temperature_c = t.Number(i, ctemp);
      if (cpay >= 0) r.payload_kg = t.Number(i, cpay);
      log.rows.push_back(r);
    }
  }
  CheckRobotLog(log, robot);
  return log;
}

bool RobotAuditOptions::IsValid(std::string* why) const {
  const auto fail = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (!(false_alarm > 0 && false_alarm < 0.5)) return fail("false_alarm must be in (0, 0.5)");
  if (folds < 2) return fail("folds must be at least 2");
  if (max_effects < 0) return fail("max_effects must be >= 0");
  if (max_full_fits < 1) return fail("max_full_fits must be >= 1");
  if (!(repeat_tolerance >= 0)) return fail("repeat_tolerance must be >= 0");
  for (const auto& n : only) {
    const auto e = EffectFromName(n);
    if (!e) return fail("'" + n + "' is not in the catalog of effects");
    if (Info(*e).sensor != SensorKind::kRobot && *e != Effect::kClockOffset)
      return fail("'" + n + "' is not a robot effect (or clock_offset)");
  }
  return true;
}

namespace {

constexpr double kLog2Pi = 1.8378770664093453;

// ---------------------------------------------------------------------------------
// The model of one row, shared by the fits

struct RowData {
  Eigen::VectorXd q;
  MeasurementContext c;
  Vec3 p = Vec3::Zero();
  Mat3 R = Mat3::Identity();
};

struct Setup {
  const RobotModel* robot = nullptr;
  Pose base0, tool0;
  bool six = false;
  int m = 3;  // residuals per row
  double time_span = 1.0;  // s, last - first row
  std::vector<RowData> rows;
};

// Predicted minus measured for one row: position (m) and, for 6-D rows, the rotation
// vector of R_pred R_meas^T (rad).
struct RowResidual {
  const Setup* s;
  const std::vector<Extension>* ext;
  const RowData* row;
  const Eigen::MatrixXd* Linv;  // whitening, m x m (null = none)

  template <typename T>
  bool operator()(T const* const* p, T* res) const {
    const T* b = p[0];
    const T* tl = p[1];
    const PoseT<T> F = ExtendedFlangeT<T>(*s->robot, *ext, p + 2, row->q, row->c);
    using V3 = Eigen::Matrix<T, 3, 1>;
    using M3 = Eigen::Matrix<T, 3, 3>;
    const V3 t_tool = s->tool0.t.cast<T>() + V3(tl[0], tl[1], tl[2]);
    M3 Rb;
    ceres::AngleAxisToRotationMatrix(b, Rb.data());
    const M3 R_mb = Rb * s->base0.R.cast<T>();
    const V3 t_mb = s->base0.t.cast<T>() + V3(b[3], b[4], b[5]);
    const V3 p_pred = R_mb * (F.R * t_tool + F.t) + t_mb;
    T e[6];
    for (int k = 0; k < 3; ++k) e[k] = p_pred[k] - T(row->p[k]);
    if (s->six) {
      M3 Rt;
      ceres::AngleAxisToRotationMatrix(tl + 3, Rt.data());
      const M3 R_pred = R_mb * F.R * Rt * s->tool0.R.cast<T>();
      const M3 E = R_pred * row->R.transpose().cast<T>();
      ceres::RotationMatrixToAngleAxis(E.data(), e + 3);
    }
    for (int i = 0; i < s->m; ++i) {
      if (Linv) {
        T acc(0);
        for (int k = 0; k <= i; ++k) acc += (*Linv)(i, k) * e[k];
        res[i] = acc;
      } else {
        res[i] = e[i];
      }
    }
    return true;
  }
};

// Parameter state of one model.
struct State {
  std::vector<double> base = std::vector<double>(6, 0.0);
  std::vector<double> tool = std::vector<double>(6, 0.0);
  std::vector<std::vector<double>> ext;
  std::vector<std::vector<bool>> held;  // per extension, per parameter
};

int ToolSize(const Setup& s) { return s.six ? 6 : 3; }

std::vector<double*> Blocks(State& st) {
  std::vector<double*> b{st.base.data(), st.tool.data()};
  for (auto& e : st.ext) b.push_back(e.data());
  return b;
}

// Unwhitened residuals of `rows` (rows x m).
Eigen::MatrixXd Residuals(const Setup& s, const std::vector<Extension>& ext, State st, const std::vector<int>& rows) {
  Eigen::MatrixXd R(rows.size(), s.m);
  std::vector<double*> b = Blocks(st);
  for (size_t i = 0; i < rows.size(); ++i) {
    RowResidual f{&s, &ext, &s.rows[rows[i]], nullptr};
    double e[6];
    f(b.data(), e);
    for (int k = 0; k < s.m; ++k) R(i, k) = e[k];
  }
  return R;
}

// ML covariance of zero-mean residuals, with a floor so that noise-free data stays finite.
Eigen::MatrixXd MlCovariance(const Eigen::MatrixXd& R) {
  Eigen::MatrixXd S = R.transpose() * R / std::max<double>(1.0, R.rows());
  const double floor = 1e-12 * std::max(1e-30, S.trace() / S.rows()) + 1e-24;
  S.diagonal().array() += floor;
  return S;
}

double LogDet(const Eigen::MatrixXd& S) {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  return 2.0 * llt.matrixL().toDenseMatrix().diagonal().array().log().sum();
}

// Log-likelihood of residual rows under N(0, S).
double LogLik(const Eigen::MatrixXd& R, const Eigen::MatrixXd& S) {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  const Eigen::MatrixXd W = llt.matrixL().solve(R.transpose());
  const double ld = LogDet(S);
  return -0.5 * (W.squaredNorm() + R.rows() * (ld + S.rows() * kLog2Pi));
}

Eigen::MatrixXd WhiteningOf(const Eigen::MatrixXd& S) {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  const Eigen::MatrixXd L = llt.matrixL();
  return L.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(S.rows(), S.cols()));
}

struct FitOut {
  State st;
  Eigen::MatrixXd noise, residuals;
  double loglik = 0.0;
  bool converged = true;
};

// Maximum-likelihood fit of the registration, the tool and the free extension parameters
// on `rows`, with the noise covariance re-estimated between solves.
FitOut Fit(const Setup& s, const std::vector<Extension>& ext, State st, const std::vector<int>& rows,
           Eigen::MatrixXd noise) {
  auto Linv = std::make_shared<Eigen::MatrixXd>(WhiteningOf(noise));
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  std::vector<double*> b = Blocks(st);
  for (int r : rows) {
    auto* cost = new ceres::DynamicAutoDiffCostFunction<RowResidual, 8>(
        new RowResidual{&s, &ext, &s.rows[r], Linv.get()});
    cost->AddParameterBlock(6);
    cost->AddParameterBlock(ToolSize(s));
    for (const auto& e : ext) cost->AddParameterBlock(e.NumParameters());
    cost->SetNumResiduals(s.m);
    problem.AddResidualBlock(cost, nullptr, b);
  }
  for (size_t k = 0; k < ext.size(); ++k) {
    const int np = ext[k].NumParameters();
    std::vector<int> held;
    for (int j = 0; j < np; ++j)
      if (st.held[k][j]) held.push_back(j);
    if (static_cast<int>(held.size()) == np) {
      problem.SetParameterBlockConstant(b[2 + k]);
    } else if (!held.empty()) {
      problem.SetManifold(b[2 + k], new ceres::SubsetManifold(np, held));
    }
    if (ext[k].effect == Effect::kThermalDrift && ext[k].variant == 0 && !st.held[k][1])
    {
      // A time constant far beyond the log is a linear drift: bounded, so that the growth
      // stays a size one can read.
      problem.SetParameterLowerBound(b[2 + k], 1, 1.0);
      problem.SetParameterUpperBound(b[2 + k], 1, 10.0 * s.time_span);
    }
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.num_threads = 1;
  FitOut out;
  double last = std::numeric_limits<double>::infinity();
  for (int outer = 0; outer < 6; ++outer) {
    ceres::Solver::Summary sum;
    ceres::Solve(so, &problem, &sum);
    if (sum.termination_type == ceres::FAILURE) out.converged = false;
    out.residuals = Residuals(s, ext, st, rows);
    out.noise = MlCovariance(out.residuals);
    const double ld = LogDet(out.noise);
    *Linv = WhiteningOf(out.noise);
    if (std::abs(ld - last) < 1e-7) break;
    last = ld;
  }
  out.st = st;
  out.loglik = LogLik(out.residuals, out.noise);
  return out;
}

// Dense whitened Jacobian of every row of `rows` with respect to every parameter of every
// block (ambient), columns: base 6, tool ToolSize, then the extensions' blocks in order.
Eigen::MatrixXd DenseJacobian(const Setup& s, const std::vector<Extension>& ext, State st,
                              const std::vector<int>& rows, const Eigen::MatrixXd& Linv, Eigen::VectorXd* r) {
  std::vector<int> sizes{6, ToolSize(s)};
  for (const auto& e : ext) sizes.push_back(e.NumParameters());
  const int P = std::accumulate(sizes.begin(), sizes.end(), 0);
  Eigen::MatrixXd J(rows.size() * s.m, P);
  if (r) r->resize(rows.size() * s.m);
  std::vector<double*> b = Blocks(st);
  std::vector<std::vector<double>> jb(sizes.size());
  std::vector<double*> jp(sizes.size());
  for (size_t k = 0; k < sizes.size(); ++k) {
    jb[k].resize(sizes[k] * s.m);
    jp[k] = jb[k].data();
  }
  for (size_t i = 0; i < rows.size(); ++i) {
    ceres::DynamicAutoDiffCostFunction<RowResidual, 8> cost(new RowResidual{&s, &ext, &s.rows[rows[i]], &Linv});
    for (int sz : sizes) cost.AddParameterBlock(sz);
    cost.SetNumResiduals(s.m);
    double e[6];
    cost.Evaluate(b.data(), e, jp.data());
    int col = 0;
    for (size_t k = 0; k < sizes.size(); ++k) {
      for (int a = 0; a < s.m; ++a)
        for (int c = 0; c < sizes[k]; ++c) J(i * s.m + a, col + c) = jb[k][a * sizes[k] + c];
      col += sizes[k];
    }
    if (r)
      for (int a = 0; a < s.m; ++a) (*r)[i * s.m + a] = e[a];
  }
  return J;
}

// Free parameter columns of a state: base, tool, and the non-held extension parameters.
std::vector<int> FreeColumns(const Setup& s, const State& st) {
  std::vector<int> cols;
  for (int k = 0; k < 6 + ToolSize(s); ++k) cols.push_back(k);
  int col = 6 + ToolSize(s);
  for (size_t k = 0; k < st.ext.size(); ++k) {
    for (size_t j = 0; j < st.ext[k].size(); ++j)
      if (!st.held[k][j]) cols.push_back(col + static_cast<int>(j));
    col += static_cast<int>(st.ext[k].size());
  }
  return cols;
}

// Standard deviations of the extension parameters of a fitted state (0 for held ones).
std::vector<std::vector<double>> Sigmas(const Setup& s, const std::vector<Extension>& ext, const FitOut& f,
                                        const std::vector<int>& rows) {
  const Eigen::MatrixXd Linv = WhiteningOf(f.noise);
  const Eigen::MatrixXd J = DenseJacobian(s, ext, f.st, rows, Linv, nullptr);
  const std::vector<int> cols = FreeColumns(s, f.st);
  Eigen::MatrixXd Jf(J.rows(), cols.size());
  for (size_t c = 0; c < cols.size(); ++c) Jf.col(c) = J.col(cols[c]);
  // Columns scaled to unit norm first: the parameters differ by many orders of magnitude
  // (a growth of 1e-5 beside a time constant of 1e3 s).
  Eigen::VectorXd d = Jf.colwise().norm().transpose();
  for (int c = 0; c < d.size(); ++c)
    if (!(d[c] > 0)) d[c] = 1.0;
  const Eigen::MatrixXd Js = Jf * d.cwiseInverse().asDiagonal();
  const Eigen::MatrixXd Ns = Js.transpose() * Js;
  const Eigen::MatrixXd Cs = Ns.completeOrthogonalDecomposition().pseudoInverse();
  const Eigen::MatrixXd C = d.cwiseInverse().asDiagonal() * Cs * d.cwiseInverse().asDiagonal();
  std::vector<std::vector<double>> sig(ext.size());
  int free_at = 6 + ToolSize(s);
  for (size_t k = 0; k < ext.size(); ++k) {
    sig[k].assign(ext[k].NumParameters(), 0.0);
    for (int j = 0; j < ext[k].NumParameters(); ++j)
      if (!f.st.held[k][j]) {
        sig[k][j] = std::sqrt(std::max(0.0, C(free_at, free_at)));
        ++free_at;
      }
  }
  return sig;
}

double PositionRms(const Eigen::MatrixXd& R) {
  return R.rows() ? std::sqrt(R.leftCols(3).squaredNorm() / R.rows()) : 0.0;
}

// ---------------------------------------------------------------------------------
// Candidates


std::vector<Extension> Catalog(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o,
                               std::vector<std::string>* notes) {
  const auto wanted = [&](Effect e) {
    if (o.only.empty()) return true;
    return std::find(o.only.begin(), o.only.end(), Name(e)) != o.only.end();
  };
  std::vector<Extension> c;
  const int n = robot.NumJoints();
  for (int i = 0; i < n; ++i) {
    const bool rev = robot.Joints()[i].type == JointType::kRevolute;
    if (wanted(Effect::kJointOffset)) c.push_back({Effect::kJointOffset, i, 0});
    if (wanted(Effect::kJointScale)) c.push_back({Effect::kJointScale, i, 0});
    if (wanted(Effect::kGravityCompliance)) c.push_back({Effect::kGravityCompliance, i, 0});
    if (wanted(Effect::kBacklash)) c.push_back({Effect::kBacklash, i, 0});
    if (rev && wanted(Effect::kErrorMotion)) c.push_back({Effect::kErrorMotion, i, 1});
  }
  if (wanted(Effect::kLinkLength))
    for (int i = 0; i < n; ++i) {
      c.push_back({Effect::kLinkLength, i, 0});
      c.push_back({Effect::kLinkLength, i, 1});
    }
  if (wanted(Effect::kThermalDrift)) {
    const double span = log.rows.back().time_s - log.rows.front().time_s;
    if (!log.has_time) notes->push_back("thermal_drift in time not tested: the log has no time column");
    else if (span > 0) c.push_back({Effect::kThermalDrift, -1, 0});
    else notes->push_back("thermal_drift in time not tested: the log has no time span");
    if (log.has_temperature) c.push_back({Effect::kThermalDrift, -1, 1});
  }
  bool moving = false;
  for (const auto& r : log.rows) moving |= r.qdot.size() > 0 && r.qdot.norm() > 0;
  if (wanted(Effect::kClockOffset) && moving) c.push_back({Effect::kClockOffset, -1, 0});
  return c;
}

// The covariate an effect depends on, for plots.
std::string CovariateOf(const Extension& e, int n, bool has_temperature) {
  switch (e.effect) {
    case Effect::kGravityCompliance: return "joint " + std::to_string(e.index + 1) + " gravity torque";
    case Effect::kBacklash: return "joint " + std::to_string(e.index + 1) + " move direction";
    case Effect::kThermalDrift: return e.variant == 1 && has_temperature ? "temperature" : "time";
    case Effect::kLinkLength: return "joint " + std::to_string(std::min(e.index + 2, n)) + " angle";
    default: return "joint " + std::to_string(e.index + 1) + " angle";
  }
}

struct Covariate {
  std::string name;
  std::vector<double> v;
};

std::vector<Covariate> Covariates(const RobotModel& robot, const RobotLog& log, const Setup& s) {
  std::vector<Covariate> cv;
  const int n = robot.NumJoints();
  const size_t N = log.rows.size();
  Covariate t{"time", {}};
  for (const auto& r : log.rows) t.v.push_back(r.time_s);
  cv.push_back(t);
  for (int j = 0; j < n; ++j) {
    Covariate a{"joint " + std::to_string(j + 1) + " angle", {}};
    Covariate g{"joint " + std::to_string(j + 1) + " gravity torque", {}};
    Covariate d{"joint " + std::to_string(j + 1) + " move direction", {}};
    for (size_t i = 0; i < N; ++i) {
      a.v.push_back(log.rows[i].q[j]);
      g.v.push_back(s.rows[i].c.gravity_torque[j]);
      d.v.push_back(s.rows[i].c.move_direction[j]);
    }
    cv.push_back(a);
    cv.push_back(g);
    cv.push_back(d);
  }
  if (log.has_temperature) {
    Covariate c{"temperature", {}};
    for (const auto& r : log.rows) c.v.push_back(r.temperature_c);
    cv.push_back(c);
  }
  return cv;
}

// Groups of rows with the same joint values (repeats of a pose).
std::vector<std::vector<int>> RepeatGroups(const RobotLog& log, double tol) {
  const int N = log.rows.size();
  std::vector<int> order(N);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return log.rows[a].q[0] < log.rows[b].q[0]; });
  std::vector<int> group(N, -1);
  std::vector<std::vector<int>> groups;
  for (int ii = 0; ii < N; ++ii) {
    const int a = order[ii];
    if (group[a] >= 0) continue;
    group[a] = groups.size();
    groups.push_back({a});
    for (int jj = ii + 1; jj < N; ++jj) {
      const int b = order[jj];
      if (log.rows[b].q[0] - log.rows[a].q[0] > tol) break;
      if (group[b] < 0 && (log.rows[b].q - log.rows[a].q).cwiseAbs().maxCoeff() <= tol) {
        group[b] = group[a];
        groups.back().push_back(b);
      }
    }
  }
  return groups;
}

// Residual tests of the nominal fit.
// Returns the lack-of-fit statistic (chi-square per dof of the pose means against the
// scatter of the repeats), NaN without repeats.
double TestResiduals(const RobotLog& log, const Setup& s, const FitOut& nominal, const std::vector<Covariate>& cov,
                     double alpha, int num_params, double repeat_tolerance, AuditReport* rep) {
  double lack_of_fit = std::nan("");
  const int N = log.rows.size(), m = s.m;
  const Eigen::MatrixXd W = (WhiteningOf(nominal.noise) * nominal.residuals.transpose()).transpose();  // N x m
  std::vector<AuditTest> tests;
  // Lack of fit against the scatter of repeated poses.
  const auto groups = RepeatGroups(log, repeat_tolerance);
  const int G = groups.size();
  const int df_pe = N - G;
  if (df_pe >= 2 * m + 2 && m * G - num_params > 0) {
    Eigen::MatrixXd Spe = Eigen::MatrixXd::Zero(m, m);
    std::vector<Eigen::VectorXd> mean(G);
    for (int g = 0; g < G; ++g) {
      mean[g] = Eigen::VectorXd::Zero(m);
      for (int i : groups[g]) mean[g] += nominal.residuals.row(i).transpose();
      mean[g] /= groups[g].size();
      for (int i : groups[g]) {
        const Eigen::VectorXd d = nominal.residuals.row(i).transpose() - mean[g];
        Spe += d * d.transpose();
      }
    }
    Spe /= df_pe;
    Spe.diagonal().array() += 1e-12 * Spe.trace() / m + 1e-30;
    Eigen::LLT<Eigen::MatrixXd> llt(Spe);
    double chi2 = 0;
    for (int g = 0; g < G; ++g) chi2 += groups[g].size() * llt.matrixL().solve(mean[g]).squaredNorm();
    const double d1 = m * G - num_params, d2 = static_cast<double>(m) * df_pe;
    const double F = (chi2 / d1);
    lack_of_fit = F;
    const double p = boost::math::cdf(boost::math::complement(boost::math::fisher_f(d1, d2), F));
    tests.push_back({"lack of fit against repeated poses (F, " + std::to_string(G) + " poses)", F, p, false});
  } else {
    rep->notes.push_back("no repeated poses (or too few): the noise is estimated from the residuals with the model, "
                         "so the nominal model's chi-square cannot be tested on its own");
  }
  // Lag-1 autocorrelation in time and trends against every covariate, per component.
  const char* comp[6] = {"x", "y", "z", "rx", "ry", "rz"};
  for (int k = 0; k < m; ++k) {
    const std::vector<double> w(W.col(k).data(), W.col(k).data() + N);
    tests.push_back(AutocorrelationTest(std::string("autocorrelation in time (") + comp[k] + ")", w));
    for (const auto& c : cov)
      if (auto t = TrendTest("trend vs " + c.name + " (" + comp[k] + ")", c.v, w)) tests.push_back(*t);
  }
  const double per = alpha / std::max<size_t>(1, tests.size());
  for (auto& t : tests) t.failed = t.p_value < per;
  // Report the failed tests and the strongest few of the rest.
  std::vector<AuditTest> shown;
  for (const auto& t : tests)
    if (t.failed) shown.push_back(t);
  std::sort(shown.begin(), shown.end(), [](const AuditTest& a, const AuditTest& b) { return a.p_value < b.p_value; });
  std::vector<AuditTest> rest;
  for (const auto& t : tests)
    if (!t.failed) rest.push_back(t);
  std::sort(rest.begin(), rest.end(), [](const AuditTest& a, const AuditTest& b) { return a.p_value < b.p_value; });
  for (size_t i = 0; i < rest.size() && i < 3; ++i) shown.push_back(rest[i]);
  rep->tests = shown;
  char buf[160];
  std::snprintf(buf, sizeof buf, "%zu residual tests at a family-wise false-alarm rate of %.3g (each at %.3g)",
                tests.size(), alpha, per);
  rep->notes.push_back(buf);
  return lack_of_fit;
}

}  // namespace

RobotAuditResult AuditRobot(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) Throw("robot audit options: ", why);
  CheckRobotLog(log, robot);
  const auto say = [&](const std::string& s) {
    if (o.progress) o.progress(s);
  };
  RobotAuditResult result;
  AuditReport& rep = result.report;
  rep.mode = "robot";
  rep.rms_unit = "m";

  // Set-up: the rows with their covariates.
  Setup s;
  s.robot = &robot;
  s.six = log.six_dof();
  s.m = s.six ? 6 : 3;
  s.tool0 = robot.T_flange_tool();
  const int N = log.rows.size(), n = robot.NumJoints();
  const double t0 = log.rows.front().time_s;
  s.time_span = std::max(1.0, log.rows.back().time_s - t0);
  Eigen::VectorXd dir = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < N; ++i) {
    const RobotLogRow& lr = log.rows[i];
    RowData r;
    r.q = lr.q;
    r.p = lr.p_meas;
    if (lr.R_meas_tool) r.R = *lr.R_meas_tool;
    if (i > 0)
      for (int j = 0; j < n; ++j) {
        const double d = lr.q[j] - log.rows[i - 1].q[j];
        if (std::abs(d) > 1e-9) dir[j] = d > 0 ? 1.0 : -1.0;
      }
    r.c.time_s = lr.time_s - t0;
    r.c.temperature_c = lr.temperature_c;
    r.c.reference_temperature_c = o.reference_temperature_c;
    r.c.move_direction = dir;
    r.c.gravity_torque = GravityTorquePerKg(robot, lr.q) * (log.has_payload ? lr.payload_kg : 1.0);
    if (lr.qdot.size() == n) r.c.joint_velocity = lr.qdot;
    s.rows.push_back(r);
  }
  // Starting registration.
  if (o.base_guess) {
    s.base0 = *o.base_guess;
  } else if (s.six) {
    // Average of T_meas_tool T_base_tool^-1 over the rows (chordal mean of the rotations).
    Mat3 M = Mat3::Zero();
    Vec3 t = Vec3::Zero();
    for (int i = 0; i < N; ++i) {
      const Pose Tm{*log.rows[i].R_meas_tool, log.rows[i].p_meas};
      const Pose T = Tm * robot.T_base_tool(log.rows[i].q).Inverse();
      M += T.R;
      t += T.t;
    }
    Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Mat3 S = Mat3::Identity();
    if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) S(2, 2) = -1;
    s.base0.R = svd.matrixU() * S * svd.matrixV().transpose();
    s.base0.t = t / N;
  } else {
    std::vector<RobotMeasurement> ms(N);
    for (int i = 0; i < N; ++i) {
      ms[i].q = log.rows[i].q;
      ms[i].p_meas = log.rows[i].p_meas;
    }
    s.base0 = InitialBaseGuess(robot, ms);
  }
  std::vector<int> all(N);
  std::iota(all.begin(), all.end(), 0);
  // Time-blocked folds.
  const int K = std::min(o.folds, N / 4);
  std::vector<std::vector<int>> train(K), test(K);
  for (int i = 0; i < N; ++i) {
    const int f = TimeBlockFold(i, N, K);
    for (int k = 0; k < K; ++k) (k == f ? test : train)[k].push_back(i);
  }

  // 1. The nominal model. Error motion enters as one block per revolute joint (a first
  // harmonic) with every term held: a candidate frees one axis's sine/cosine pair (the
  // 12 terms of a whole harmonic rarely earn their place; one axis often does).
  say("nominal fit");
  std::vector<Extension> model;
  State st0;
  const auto wanted = [&](Effect e) {
    return o.only.empty() || std::find(o.only.begin(), o.only.end(), Name(e)) != o.only.end();
  };
  if (wanted(Effect::kErrorMotion))
    for (int j = 0; j < n; ++j)
      if (robot.Joints()[j].type == JointType::kRevolute) {
        const Extension e{Effect::kErrorMotion, j, 1};
        model.push_back(e);
        st0.ext.push_back(e.InitialParameters());
        st0.held.push_back(std::vector<bool>(e.NumParameters(), true));
      }
  Eigen::MatrixXd noise0 = Eigen::MatrixXd::Identity(s.m, s.m) * 1e-8;
  FitOut cur = Fit(s, model, st0, all, noise0);
  // Refit from the fitted state once: the first solve started from a rough noise guess.
  cur = Fit(s, model, cur.st, all, cur.noise);
  const FitOut nominal = cur;
  const std::vector<Extension> nominal_model = model;
  const int reg_params = 6 + ToolSize(s);
  rep.nominal_n = static_cast<long>(N) * s.m;
  const std::vector<Covariate> cov = Covariates(robot, log, s);
  const double alpha_tests = o.false_alarm / 2.0, alpha_effects = o.false_alarm / 2.0;
  // chi2/dof of the nominal fit against the pure-error noise of the repeats; without
  // repeats the noise comes from the residuals themselves and it is 1 by construction.
  const double lof = TestResiduals(log, s, nominal, cov, alpha_tests, reg_params, o.repeat_tolerance, &rep);
  rep.nominal_chi2_per_dof = std::isfinite(lof) ? lof : 1.0;

  // 2. Greedy forward selection.
  struct Option {  // a candidate: a new extension, or terms of a model block to free
    int block = -1;        // model block whose terms it frees; -1 = appends `ext`
    Extension ext;
    std::vector<int> terms;  // parameters it frees (empty for a new extension: all)
    std::string key;         // unique: label, and the axis for error motion
  };
  std::vector<Option> options;
  for (const Extension& e : Catalog(robot, log, o, &rep.notes)) {
    if (e.effect == Effect::kErrorMotion) {
      static const char* kAxis[6] = {"rx", "ry", "rz", "x", "y", "z"};
      for (size_t b = 0; b < model.size(); ++b)
        if (model[b].effect == Effect::kErrorMotion && model[b].index == e.index)
          for (int a = 0; a < 6; ++a)
            options.push_back({static_cast<int>(b), model[b], {a, 6 + a}, e.Label() + " (" + kAxis[a] + ")"});
    } else {
      options.push_back({-1, e, {}, e.Label()});
    }
  }
  const double logN = std::log(static_cast<double>(N));
  // Held-out log-likelihood and RMS of a model (extensions + starting state) by the folds.
  const auto CrossValidate = [&](const std::vector<Extension>& ext, const State& start, double* ll, double* rms) {
    double sum_ll = 0, sum_sq = 0;
    long cnt = 0;
    for (int k = 0; k < K; ++k) {
      const FitOut f = Fit(s, ext, start, train[k], cur.noise);
      const Eigen::MatrixXd R = Residuals(s, ext, f.st, test[k]);
      sum_ll += LogLik(R, f.noise);
      sum_sq += R.leftCols(3).squaredNorm();
      cnt += R.rows();
    }
    *ll = sum_ll;
    *rms = std::sqrt(sum_sq / std::max<long>(1, cnt));
  };
  struct Step {
    int block = 0;
    std::vector<int> terms;
    std::string key;
    double lr = 0, bic = 0, ll_gain = 0, rms_before = 0, rms_after = 0;
    bool undecided = false;
  };
  std::vector<Step> steps;
  std::set<std::string> taken;
  double cur_ll_cv = 0, cur_rms_cv = 0;
  bool cv_done = false;
  std::map<std::string, bool> not_identifiable;
  for (int step = 0; step < o.max_effects; ++step) {
    // Screening: the linearised chi-square each candidate removes, for all at once.
    std::vector<Extension> ext_all = model;
    State st_all = cur.st;
    std::vector<int> col_of(model.size());
    int col = 6 + ToolSize(s);
    for (size_t k = 0; k < model.size(); ++k) {
      col_of[k] = col;
      col += model[k].NumParameters();
    }
    std::vector<int> open;  // indices into options
    std::vector<int> open_col;
    for (size_t i = 0; i < options.size(); ++i) {
      if (taken.count(options[i].key)) continue;
      open.push_back(i);
      if (options[i].block >= 0) {
        open_col.push_back(col_of[options[i].block]);
      } else {
        open_col.push_back(col);
        col += options[i].ext.NumParameters();
        ext_all.push_back(options[i].ext);
        st_all.ext.push_back(options[i].ext.InitialParameters());
        st_all.held.push_back(std::vector<bool>(options[i].ext.NumParameters(), false));
      }
    }
    if (open.empty()) break;
    say("step " + std::to_string(step + 1) + ": screening " + std::to_string(open.size()) + " candidates");
    const Eigen::MatrixXd Linv = WhiteningOf(cur.noise);
    Eigen::VectorXd r;
    const Eigen::MatrixXd J = DenseJacobian(s, ext_all, st_all, all, Linv, &r);
    const std::vector<int> cur_cols = FreeColumns(s, cur.st);
    Eigen::MatrixXd J0(J.rows(), cur_cols.size());
    for (size_t c = 0; c < cur_cols.size(); ++c) J0.col(c) = J.col(cur_cols[c]);
    Eigen::HouseholderQR<Eigen::MatrixXd> qr0(J0);
    const Eigen::MatrixXd Q0 = qr0.householderQ() * Eigen::MatrixXd::Identity(J0.rows(), J0.cols());
    const Eigen::VectorXd rp = r - Q0 * (Q0.transpose() * r);
    struct Cand {
      int option = 0;
      std::vector<int> free;  // parameters of the block it frees (identifiable ones)
      int k = 0;
      double linear_gain = 0, linear_bic = 0;
    };
    std::vector<Cand> cands;
    for (size_t oi = 0; oi < open.size(); ++oi) {
      const Option& op = options[open[oi]];
      std::vector<int> terms = op.terms;
      if (terms.empty())
        for (int j = 0; j < op.ext.NumParameters(); ++j) terms.push_back(j);
      Eigen::MatrixXd Jc(J.rows(), 0);
      Cand c;
      c.option = open[oi];
      for (int j : terms) {
        const Eigen::VectorXd v = J.col(open_col[oi] + j);
        const double nv = v.norm();
        if (nv <= 0) continue;
        Eigen::VectorXd w = v - Q0 * (Q0.transpose() * v);
        for (int kk = 0; kk < Jc.cols(); ++kk) w -= Jc.col(kk) * Jc.col(kk).dot(w);
        if (w.norm() < 1e-5 * nv) continue;
        Jc.conservativeResize(Eigen::NoChange, Jc.cols() + 1);
        Jc.col(Jc.cols() - 1) = w / w.norm();
        c.free.push_back(j);
      }
      // The warm-up's time constant has no column at zero growth: free it with the growth.
      if (op.ext.effect == Effect::kThermalDrift && op.ext.variant == 0 && !c.free.empty() && c.free[0] == 0)
        c.free.push_back(1);
      c.k = c.free.size();
      if (c.k == 0) {
        not_identifiable[op.key] = true;
        continue;
      }
      c.linear_gain = (Jc.transpose() * rp).squaredNorm();
      c.linear_bic = c.linear_gain - c.k * logN;
      cands.push_back(c);
    }
    const int M = cands.size();
    if (M == 0) break;
    std::sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) { return a.linear_bic > b.linear_bic; });
    const auto Threshold = [&](int k) { return ChiSquareThreshold(k, alpha_effects / M); };
    // The model with candidate c added, in its starting state.
    const auto WithCandidate = [&](const Cand& c, const std::vector<double>& start, std::vector<Extension>* ext,
                                   State* st) {
      const Option& op = options[c.option];
      *ext = model;
      *st = cur.st;
      if (op.block >= 0) {
        for (int j : c.free) st->held[op.block][j] = false;
      } else {
        ext->push_back(op.ext);
        st->ext.push_back(start);
        std::vector<bool> held(op.ext.NumParameters(), true);
        for (int j : c.free) held[j] = false;
        st->held.push_back(held);
      }
    };
    // Full fits of the most promising.
    struct Tried {
      Cand c;
      std::vector<Extension> ext;
      FitOut fit;
      double lr = 0, bic = 0, ll_cv = 0, rms_cv = 0;
    };
    SelectionRule rule;
    rule.alpha = alpha_effects;
    rule.ln_n = logN;
    rule.close_bic = 10.0;
    rule.undecided_heldout = 1.0;
    rule.undecided_bic = 2.0;
    rule.undecided_bic_relative = 0.005;
    std::vector<Tried> tried;
    for (int i = 0; i < M && i < o.max_full_fits; ++i) {
      const Cand& c = cands[i];
      const Option& op = options[c.option];
      if (c.linear_gain < 0.3 * Threshold(c.k)) continue;
      say("step " + std::to_string(step + 1) + ": fitting " + op.key);
      Tried t;
      t.c = c;
      t.fit.loglik = -std::numeric_limits<double>::infinity();
      const bool warmup = op.ext.effect == Effect::kThermalDrift && op.ext.variant == 0;
      std::vector<std::vector<double>> starts{op.ext.InitialParameters()};
      if (warmup) {
        const double span = std::max(1.0, log.rows.back().time_s - t0);
        starts = {{0.0, span / 10}, {0.0, span / 3}, {0.0, span}};
      }
      for (const auto& p0 : starts) {
        State st;
        WithCandidate(c, p0, &t.ext, &st);
        FitOut f;
        if (warmup) {
          // First with the time constant held, then free.
          const std::vector<bool> free_held = st.held.back();
          st.held.back()[1] = true;
          f = Fit(s, t.ext, st, all, cur.noise);
          f.st.held.back() = free_held;
          f = Fit(s, t.ext, f.st, all, f.noise);
        } else {
          f = Fit(s, t.ext, st, all, cur.noise);
        }
        if (f.loglik > t.fit.loglik) t.fit = f;
      }
      t.lr = 2.0 * (t.fit.loglik - cur.loglik);
      t.bic = BicGain(t.lr, c.k, logN);
      char b[200];
      std::snprintf(b, sizeof b, "step %d: %s: likelihood ratio %.1f (threshold %.1f), BIC gain %.1f", step + 1,
                    op.key.c_str(), t.lr, Threshold(c.k), t.bic);
      say(b);
      tried.push_back(t);
    }
    // The decision (model/model_selection.h): every robot candidate explains the same
    // residual (one group); held-out gains by cross-validation when the rule asks.
    std::vector<SelectionCandidate> sel(tried.size());
    for (size_t i = 0; i < tried.size(); ++i) {
      sel[i].k = tried[i].c.k;
      sel[i].lr = tried[i].lr;
    }
    const StepDecision dec = DecideStep(sel, M, rule, [&](int i) {
      if (!cv_done) {
        CrossValidate(model, cur.st, &cur_ll_cv, &cur_rms_cv);
        cv_done = true;
      }
      Tried& t = tried[i];
      say("step " + std::to_string(step + 1) + ": cross-validating " + options[t.c.option].key);
      CrossValidate(t.ext, t.fit.st, &t.ll_cv, &t.rms_cv);
      return t.ll_cv - cur_ll_cv;
    });
    if (dec.outcome == StepOutcome::kNothingPasses) break;
    if (dec.outcome == StepOutcome::kNoHeldoutGain) {
      rep.notes.push_back(options[tried[dec.best].c.option].key +
                          " passed the likelihood-ratio test on all data but did not gain held-out log-likelihood (" +
                          std::to_string(sel[dec.best].heldout_gain) + "): not named");
      break;
    }
    Tried& best = tried[dec.best];
    std::vector<std::string> group;
    for (int i : dec.group) group.push_back(options[tried[i].c.option].key);
    const Option& op = options[best.c.option];
    Step sp;
    sp.block = op.block >= 0 ? op.block : static_cast<int>(model.size());
    sp.terms = best.c.free;
    sp.key = op.key;
    sp.lr = best.lr;
    sp.bic = best.bic;
    sp.ll_gain = best.ll_cv - cur_ll_cv;
    sp.rms_before = cur_rms_cv;
    sp.rms_after = best.rms_cv;
    sp.undecided = dec.outcome == StepOutcome::kUndecided;
    if (sp.undecided) rep.undecided.push_back(group);
    steps.push_back(sp);
    taken.insert(op.key);
    model = best.ext;
    cur = best.fit;
    cur_ll_cv = best.ll_cv;
    cur_rms_cv = best.rms_cv;
  }
  for (const auto& [label, b] : not_identifiable) {
    (void)b;
    rep.notes.push_back(label + ": not identifiable from these measurements with a free registration and tool");
  }

  // 3. The report.
  say("final fit");
  const std::vector<std::vector<double>> sig = Sigmas(s, model, cur, all);
  for (const Step& sp : steps) {
    if (sp.undecided) continue;
    const Extension& x = model[sp.block];
    AuditEffect e;
    e.name = Name(x.effect);
    e.where = x.Where();
    const auto names = x.ParameterNames();
    for (int j : sp.terms) {
      e.parameters.push_back({names[j], cur.st.ext[sp.block][j]});
      e.sigma.push_back({names[j], sig[sp.block][j]});
    }
    e.heldout_rms_before = sp.rms_before;
    e.heldout_rms_after = sp.rms_after;
    e.heldout_loglik_gain = sp.ll_gain;
    e.bic_gain = sp.bic;
    rep.effects.push_back(e);
  }
  bool failed = false;
  for (const auto& t : rep.tests) failed |= t.failed;
  rep.clean = !failed && steps.empty();
  if (failed && steps.empty())
    rep.notes.push_back("the nominal model fails a residual test but no effect of the catalog earns its place");

  // Fits and the extended robot.
  const auto ToFit = [&](const std::vector<Extension>& ext, const FitOut& f, const std::vector<std::vector<double>>& sg) {
    RobotAuditFit r;
    r.extensions = ext;
    r.parameters = f.st.ext;
    r.sigmas = sg;
    Mat3 Rb = ExpSO3(Vec3(f.st.base[0], f.st.base[1], f.st.base[2]));
    r.T_meas_base = Pose{Rb * s.base0.R, s.base0.t + Vec3(f.st.base[3], f.st.base[4], f.st.base[5])};
    Mat3 Rt = s.six ? ExpSO3(Vec3(f.st.tool[3], f.st.tool[4], f.st.tool[5])) : Mat3::Identity();
    r.T_flange_tool = Pose{Rt * s.tool0.R, s.tool0.t + Vec3(f.st.tool[0], f.st.tool[1], f.st.tool[2])};
    r.noise = f.noise;
    r.residuals = f.residuals;
    r.loglik = f.loglik;
    return r;
  };
  result.nominal = ToFit(nominal_model, nominal, {});
  result.extended = ToFit(model, cur, sig);
  std::vector<Joint> joints = robot.Joints();
  for (size_t k = 0; k < model.size(); ++k) {
    const Extension& e = model[k];
    const std::vector<double>& p = cur.st.ext[k];
    switch (e.effect) {
      case Effect::kJointOffset:
        if (joints[e.index].type == JointType::kRevolute) joints[e.index].theta_offset += p[0];
        else joints[e.index].d += p[0];
        break;
      case Effect::kLinkLength: (e.variant == 0 ? joints[e.index].a : joints[e.index].d) += p[0]; break;
      case Effect::kErrorMotion: {
        if (std::all_of(cur.st.held[k].begin(), cur.st.held[k].end(), [](bool h) { return h; })) break;
        Joint& j = joints[e.index];
        while (j.Harmonics() < e.variant) {
          j.error_motion_sin.push_back(Vec6::Zero());
          j.error_motion_cos.push_back(Vec6::Zero());
        }
        for (int h = 0; h < e.variant; ++h)
          for (int a = 0; a < 6; ++a) {
            j.error_motion_sin[h][a] += p[12 * h + a];
            j.error_motion_cos[h][a] += p[12 * h + 6 + a];
          }
        break;
      }
      default:
        rep.notes.push_back(e.Label() + " is not a term of the robot description file: robot.yaml holds the rest");
        break;
    }
  }
  result.extended_robot = RobotModel(robot.Name(), robot.Convention(), joints, result.extended.T_flange_tool);

  // Plots: the residual before each effect along the effect's direction, and the effect.
  for (const Step& sp : steps) {
    RobotAuditResult::EffectPlot pl;
    pl.effect = sp.key;
    pl.covariate = CovariateOf(model[sp.block], n, log.has_temperature);
    State st = cur.st;
    const std::vector<double> zero = model[sp.block].InitialParameters();
    for (int j : sp.terms) st.ext[sp.block][j] = zero[j];
    const Eigen::MatrixXd& Rwith = cur.residuals;
    const Eigen::MatrixXd Rwithout = Residuals(s, model, st, all);
    const Covariate* cv = nullptr;
    for (const auto& c : cov)
      if (c.name == pl.covariate) cv = &c;
    for (int i = 0; i < N; ++i) {
      const Vec3 d = (Rwithout.row(i).leftCols(3) - Rwith.row(i).leftCols(3)).transpose();  // the effect's change
      const double nd = d.norm();
      const Vec3 u = nd > 0 ? Vec3(d / nd) : Vec3::UnitX();
      pl.x.push_back(cv ? cv->v[i] : log.rows[i].time_s);
      pl.residual_before.push_back(Rwithout.row(i).leftCols(3).dot(u.transpose()));
      pl.effect_size.push_back(nd);
    }
    result.plots.push_back(pl);
  }
  return result;
}

std::string RunRobotAuditJob(const RobotAuditJob& job) {
  if (!job.output_dir.empty()) RequireReplaceableFolder(job.output_dir, {"report.json"}, "audit robot", "audit robot -o");
  if (!job.json.empty()) RequireWritableFile(job.json, "audit robot --json");
  const RobotModel robot = job.robot.empty() ? RobotModel::Default() : RobotModel::Read(job.robot);
  const RobotLog log = ReadRobotLog(job.log, robot);
  const RobotAuditResult r = AuditRobot(robot, log, job.options);
  std::ostringstream text;
  text << "robot log " << job.log.string() << ": " << log.rows.size() << " measurements ("
       << (log.six_dof() ? "6-D" : "3-D") << "), robot '" << robot.Name() << "'\n";
  const Eigen::MatrixXd& S = r.nominal.noise;
  char buf[256];
  std::snprintf(buf, sizeof buf, "nominal model: position residual RMS %.4f mm; noise sigma x y z %.4f %.4f %.4f mm (fitted)\n",
                PositionRms(r.nominal.residuals) * 1e3, std::sqrt(S(0, 0)) * 1e3, std::sqrt(S(1, 1)) * 1e3,
                std::sqrt(S(2, 2)) * 1e3);
  text << buf;
  text << r.report.Text();
  std::snprintf(buf, sizeof buf, "extended model: position residual RMS %.4f mm\n",
                PositionRms(r.extended.residuals) * 1e3);
  text << buf;
  const std::string report = text.str();
  if (!job.output_dir.empty()) {
    WriteFolderAtomically(job.output_dir, {"report.json"}, "audit robot", "audit robot -o",
                          [&](const std::filesystem::path& dir) {
                            WriteFileAtomically(dir / "report.txt", [&](std::ostream& os) { os << report; });
                            r.extended_robot.Write(dir / "robot.yaml");
                            WriteFileAtomically(dir / "residuals.csv", [&](std::ostream& os) {
                              os << "time_s,nominal_dx_mm,nominal_dy_mm,nominal_dz_mm,extended_dx_mm,extended_dy_mm,"
                                    "extended_dz_mm\n";
                              char b[256];
                              for (size_t i = 0; i < log.rows.size(); ++i) {
                                std::snprintf(b, sizeof b, "%.9g,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", log.rows[i].time_s,
                                              r.nominal.residuals(i, 0) * 1e3, r.nominal.residuals(i, 1) * 1e3,
                                              r.nominal.residuals(i, 2) * 1e3, r.extended.residuals(i, 0) * 1e3,
                                              r.extended.residuals(i, 1) * 1e3, r.extended.residuals(i, 2) * 1e3);
                                os << b;
                              }
                            });
                            std::filesystem::create_directories(dir / "plots");
                            int k = 0;
                            for (const auto& pl : r.plots) {
                              Plot p;
                              p.title = pl.effect + ": residual of the model without it, along its direction";
                              p.x_label = pl.covariate;
                              p.y_label = "mm";
                              PlotSeries a{"residual without the effect", pl.x, pl.residual_before, "#1f77b4", true};
                              PlotSeries b{"the fitted effect", pl.x, pl.effect_size, "#d62728", true};
                              for (auto& v : a.y) v *= 1e3;
                              for (auto& v : b.y) v *= 1e3;
                              p.series = {a, b};
                              p.WriteSvg(dir / "plots" / ("effect" + std::to_string(++k) + ".svg"));
                            }
                            r.report.WriteJson(dir / "report.json");
                          });
  }
  if (!job.json.empty()) r.report.WriteJson(job.json);
  return report;
}

}  // namespace mcms
