#include "audit/robot_audit.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <numeric>
#include <set>
#include <sstream>

#include <ceres/ceres.h>
#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/rotation.h>

#include "audit/model_selection.h"
#include "calib/robot_calibration.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/random.h"
#include "core/svg_plot.h"

namespace mcms {
namespace {

// ---------------------------------------------------------------------------------
// Reading

std::string LineOf(const RobotLog& log, size_t i) {
  std::ostringstream o;
  o << log.source.string();
  if (log.rows[i].line > 0)
    o << " line " << log.rows[i].line;
  else
    o << " row " << i + 1;
  return o.str();
}

}  // namespace

void CheckRobotLog(const RobotLog& log, const RobotModel& robot) {
  const std::string src = log.source.empty() ? std::string("robot log") : log.source.string();
  if (static_cast<int>(log.rows.size()) < kMinRobotLogRows)
    Throw(src, ": ", log.rows.size(), log.rows.size() == 1 ? " measurement" : " measurements",
          "; the audit needs at least ", kMinRobotLogRows,
          " (the registration alone has 9 parameters; repeated poses over time show the noise)");
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
  if (max_geometric_terms < 0) return fail("max_geometric_terms must be >= 0");
  if (max_full_fits < 1) return fail("max_full_fits must be >= 1");
  if (!(repeat_tolerance >= 0)) return fail("repeat_tolerance must be >= 0");
  if (!(identifiability_tolerance > 0 && identifiability_tolerance < 1))
    return fail("identifiability_tolerance must be in (0, 1)");
  if (next_poses < 0) return fail("next_poses must be >= 0");
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
constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------------
// The problem: rows, one parameter vector for every candidate, exact residuals and one
// Jacobian at the nominal fit.

struct RowData {
  Eigen::VectorXd q;
  MeasurementContext c;
  Vec3 p = Vec3::Zero();
  Mat3 R = Mat3::Identity();
};

// theta = [registration (6: rotation vector, translation; meas frame), tool (3, or 6 with
// its rotation), the blocks of the extensions]; every block's zero is the nominal model
// (the warm-up's time constant aside, which only matters with a growth).
struct Problem {
  const RobotModel* robot = nullptr;
  Pose base0, tool0;
  bool six = false;
  int m = 3, N = 0, n = 0, ts = 3;
  double time_span = 1.0;
  // The payload of the last row (kg; 0 without a payload column) and the factor on the
  // tool point's lumped mass (the payload, or 1 kg without a payload column).
  double payload = 0.0, payload_factor = 1.0;
  std::vector<RowData> rows;
  std::vector<Extension> blocks;
  std::vector<int> offset;  // first parameter of each block
  int P = 0;
  std::vector<double> lower;                    // per parameter: -inf, or a physical bound
  int geometry = -1;                            // the geometry block
  int warmup = -1;                              // parameter index of the warm-up growth; -1 = none
  Eigen::VectorXd theta0;                       // the linearisation point (the nominal fit)
  std::vector<Eigen::MatrixXd> J;               // per residual component a: N x P at theta0
  Eigen::MatrixXd u;                            // N x m: residual change per unit uniform link growth
  int K = 0;                                    // folds: contiguous blocks of time
  std::vector<int> fold_begin;                  // K + 1 boundaries
  std::vector<std::vector<Eigen::MatrixXd>> G;  // [fold][a * m + b] = J_a^T J_b over the fold
  std::vector<Eigen::MatrixXd> Gall;
  int NumBase() const { return 6 + ts; }
};

// Predicted minus measured of one row for the registration b, the tool tl and the
// extensions' blocks (position, m; and for 6-D the rotation vector of R_pred R_meas^T).
template <typename T>
void PredictT(const Problem& pb, const RowData& row, const T* b, const T* tl, const std::vector<Extension>& ext,
              const T* const* blocks, T* e) {
  const PoseT<T> F = ExtendedFlangeT<T>(*pb.robot, ext, blocks, row.q, row.c);
  using V3 = Eigen::Matrix<T, 3, 1>;
  using M3 = Eigen::Matrix<T, 3, 3>;
  const V3 t_tool = pb.tool0.t.cast<T>() + V3(tl[0], tl[1], tl[2]);
  M3 Rb;
  ceres::AngleAxisToRotationMatrix(b, Rb.data());
  const M3 R_mb = Rb * pb.base0.R.cast<T>();
  const V3 t_mb = pb.base0.t.cast<T>() + V3(b[3], b[4], b[5]);
  const V3 p_pred = R_mb * (F.R * t_tool + F.t) + t_mb;
  for (int k = 0; k < 3; ++k) e[k] = p_pred[k] - T(row.p[k]);
  if (pb.six) {
    M3 Rt;
    ceres::AngleAxisToRotationMatrix(tl + 3, Rt.data());
    const M3 R_pred = R_mb * F.R * Rt * pb.tool0.R.cast<T>();
    const M3 E = R_pred * row.R.transpose().cast<T>();
    ceres::RotationMatrixToAngleAxis(E.data(), e + 3);
  }
}

// The same with every block of the layout, from theta.
template <typename T>
void RowResidualT(const Problem& pb, const RowData& row, const T* th, T* e) {
  std::vector<const T*> ptr(pb.blocks.size());
  for (size_t k = 0; k < pb.blocks.size(); ++k) ptr[k] = th + pb.offset[k];
  PredictT<T>(pb, row, th, th + 6, pb.blocks, ptr.data(), e);
}

struct AllParamsResidual {
  const Problem* pb;
  const RowData* row;
  template <typename T>
  bool operator()(T const* const* p, T* e) const {
    RowResidualT<T>(*pb, *row, p[0], e);
    return true;
  }
};

// Rows as contiguous ranges [begin, end): all rows, a fold's test block, or its training rows.
struct RowSet {
  std::vector<std::pair<int, int>> ranges;
  int fold = -1;       // -1: all rows
  bool train = false;  // with fold >= 0: every row but the fold's (else the fold's)
  int Count() const {
    int c = 0;
    for (const auto& [b, e] : ranges) c += e - b;
    return c;
  }
};
RowSet AllRows(const Problem& pb) {
  return RowSet{{{0, pb.N}}, -1, false};
}
RowSet TestRows(const Problem& pb, int f) {
  return RowSet{{{pb.fold_begin[f], pb.fold_begin[f + 1]}}, f, false};
}
RowSet TrainRows(const Problem& pb, int f) {
  RowSet s{{}, f, true};
  if (pb.fold_begin[f] > 0) s.ranges.push_back({0, pb.fold_begin[f]});
  if (pb.fold_begin[f + 1] < pb.N) s.ranges.push_back({pb.fold_begin[f + 1], pb.N});
  return s;
}

// Exact (nonlinear) residuals of the rows of `set` at theta into R (N x m).
void Exact(const Problem& pb, const Eigen::VectorXd& th, const RowSet& set, Eigen::MatrixXd* R) {
  if (R->rows() != pb.N || R->cols() != pb.m) R->setZero(pb.N, pb.m);
  double e[6];
  for (const auto& [b, en] : set.ranges)
    for (int i = b; i < en; ++i) {
      RowResidualT<double>(pb, pb.rows[i], th.data(), e);
      for (int a = 0; a < pb.m; ++a) (*R)(i, a) = e[a];
    }
}

// The uniform-growth direction (thermal drift: every a and d grows by the same relative
// amount) from the geometry block's columns, and the warm-up's column at time constant tau.
void UniformGrowth(Problem* pb) {
  pb->u.setZero(pb->N, pb->m);
  if (pb->geometry < 0) return;
  const int g0 = pb->offset[pb->geometry];
  for (int k = 0; k < pb->n; ++k) {
    const Joint& j = pb->robot->Joints()[k];
    for (int a = 0; a < pb->m; ++a)
      pb->u.col(a) +=
          pb->J[a].col(g0 + kDhParamsPerJoint * k + 1) * j.d + pb->J[a].col(g0 + kDhParamsPerJoint * k + 2) * j.a;
  }
}
Eigen::MatrixXd WarmupColumn(const Problem& pb, double tau) {
  Eigen::MatrixXd c = pb.u;
  for (int i = 0; i < pb.N; ++i) c.row(i) *= 1.0 - std::exp(-pb.rows[i].c.time_s / tau);
  return c;
}

// The Jacobian of every row with respect to every parameter at theta0, and the Gram
// matrices of each fold.
void Linearize(Problem* pb) {
  const int P = pb->P, m = pb->m;
  pb->J.assign(m, Eigen::MatrixXd(pb->N, P));
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Ji(m, P);
  double e[6];
  const double* params[1] = {pb->theta0.data()};
  double* jac[1] = {Ji.data()};
  for (int i = 0; i < pb->N; ++i) {
    ceres::DynamicAutoDiffCostFunction<AllParamsResidual, 16> cost(new AllParamsResidual{pb, &pb->rows[i]});
    cost.AddParameterBlock(P);
    cost.SetNumResiduals(m);
    cost.Evaluate(params, e, jac);
    for (int a = 0; a < m; ++a) pb->J[a].row(i) = Ji.row(a);
  }
  UniformGrowth(pb);
  pb->G.assign(pb->K, std::vector<Eigen::MatrixXd>(m * m));
  pb->Gall.assign(m * m, Eigen::MatrixXd::Zero(P, P));
  for (int f = 0; f < pb->K; ++f) {
    const int b = pb->fold_begin[f], len = pb->fold_begin[f + 1] - b;
    for (int a = 0; a < m; ++a)
      for (int c = a; c < m; ++c) {
        Eigen::MatrixXd g(P, P);
        g.noalias() = pb->J[a].middleRows(b, len).transpose() * pb->J[c].middleRows(b, len);
        pb->G[f][a * m + c] = g;
        if (c != a) pb->G[f][c * m + a] = g.transpose();
        pb->Gall[a * m + c] += g;
        if (c != a) pb->Gall[c * m + a] += g.transpose();
      }
  }
}

// ---------------------------------------------------------------------------------
// Fits: weighted least squares on the frozen Jacobian, the noise re-estimated, the exact
// residuals re-evaluated until they agree with the linear ones.

Eigen::MatrixXd MlCovariance(const Eigen::MatrixXd& R, const RowSet& set) {
  const int m = R.cols();
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(m, m);
  for (const auto& [b, e] : set.ranges) S.noalias() += R.middleRows(b, e - b).transpose() * R.middleRows(b, e - b);
  S /= std::max(1, set.Count());
  const double floor = 1e-12 * std::max(1e-30, S.trace() / m) + 1e-24;
  S.diagonal().array() += floor;
  return S;
}

double LogDet(const Eigen::MatrixXd& S) {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  return 2.0 * llt.matrixL().toDenseMatrix().diagonal().array().log().sum();
}

Eigen::MatrixXd WhiteningOf(const Eigen::MatrixXd& S) {
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  const Eigen::MatrixXd L = llt.matrixL();
  return L.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(S.rows(), S.cols()));
}

// Per-row log-likelihood of the rows of `set` under N(0, S) into ll (size N).
double RowLogLik(const Eigen::MatrixXd& R, const Eigen::MatrixXd& S, const RowSet& set, Eigen::VectorXd* ll) {
  const Eigen::MatrixXd Li = WhiteningOf(S);
  const double c = LogDet(S) + S.rows() * kLog2Pi;
  if (ll->size() != R.rows()) ll->setZero(R.rows());
  double sum = 0;
  for (const auto& [b, e] : set.ranges)
    for (int i = b; i < e; ++i) {
      const double v = -0.5 * ((Li * R.row(i).transpose()).squaredNorm() + c);
      (*ll)[i] = v;
      sum += v;
    }
  return sum;
}

// Solves H d = r for a symmetric positive semi-definite H, scaled to unit diagonal first
// (the parameters differ by orders of magnitude); the minimum-norm solution when singular.
Eigen::VectorXd SolveScaled(const Eigen::MatrixXd& H, const Eigen::VectorXd& r) {
  Eigen::VectorXd d = H.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (int i = 0; i < d.size(); ++i)
    if (!(d[i] > 0)) d[i] = 1.0;
  const Eigen::MatrixXd Hs = d.cwiseInverse().asDiagonal() * H * d.cwiseInverse().asDiagonal();
  const Eigen::VectorXd rs = d.cwiseInverse().asDiagonal() * r;
  Eigen::LDLT<Eigen::MatrixXd> ldlt(Hs);
  Eigen::VectorXd y;
  if (ldlt.info() == Eigen::Success && ldlt.isPositive() && ldlt.vectorD().minCoeff() > 1e-13) {
    y = ldlt.solve(rs);
  } else {
    y = Hs.completeOrthogonalDecomposition().solve(rs);
  }
  return d.cwiseInverse().asDiagonal() * y;
}

Eigen::MatrixXd InverseScaled(const Eigen::MatrixXd& H) {
  Eigen::VectorXd d = H.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (int i = 0; i < d.size(); ++i)
    if (!(d[i] > 0)) d[i] = 1.0;
  const Eigen::MatrixXd Hs = d.cwiseInverse().asDiagonal() * H * d.cwiseInverse().asDiagonal();
  const Eigen::MatrixXd C = Hs.completeOrthogonalDecomposition().pseudoInverse();
  return d.cwiseInverse().asDiagonal() * C * d.cwiseInverse().asDiagonal();
}

// min 1/2 d' H d + g' d subject to x + d >= lower (lower = -inf where unbounded): a primal
// active set (the bounded parameters are few). `at_bound` marks those held at the bound.
Eigen::VectorXd BoundedStep(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& x,
                            const Eigen::VectorXd& lower, std::vector<char>* at_bound) {
  const int n = H.rows();
  std::vector<char> active(n, 0);
  Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
  for (int iter = 0; iter < 4 * n + 10; ++iter) {
    std::vector<int> fr, ac;
    for (int i = 0; i < n; ++i) (active[i] ? ac : fr).push_back(i);
    d.setZero();
    for (int i : ac) d[i] = lower[i] - x[i];
    if (!fr.empty()) {
      Eigen::VectorXd rhs = -g(fr);
      if (!ac.empty()) rhs -= H(fr, ac) * d(ac);
      d(fr) = SolveScaled(H(fr, fr), rhs);
    }
    // Most violated bound among the free.
    int worst = -1;
    double wv = 0;
    for (int i : fr) {
      if (!std::isfinite(lower[i])) continue;
      const double scale = std::sqrt(std::max(H(i, i), 1e-300));
      const double v = (x[i] + d[i] - lower[i]) * scale;
      if (v < -1e-12 && v < wv) {
        wv = v;
        worst = i;
      }
    }
    if (worst >= 0) {
      active[worst] = 1;
      continue;
    }
    // A bound that the gradient pulls away from is released.
    const Eigen::VectorXd grad = H * d + g;
    int rel = -1;
    double rv = 0;
    for (int i : ac) {
      const double v = grad[i] / std::sqrt(std::max(H(i, i), 1e-300));
      if (v < -1e-12 && v < rv) {
        rv = v;
        rel = i;
      }
    }
    if (rel < 0) break;
    active[rel] = 0;
  }
  if (at_bound) *at_bound = active;
  return d;
}

struct FitResult {
  Eigen::VectorXd theta;
  std::vector<int> free;       // requested free parameters (base, tool, the model's terms)
  std::vector<char> at_bound;  // per free parameter: held at its physical bound
  Eigen::MatrixXd noise;       // m x m
  Eigen::MatrixXd R;           // N x m residuals (predicted - measured) of the fitted rows
  Eigen::VectorXd row_ll;      // N
  double loglik = -kInf;
  Eigen::MatrixXd cov;  // covariance of `free` (0 for those at a bound)
};

// Column values of parameter j at rows [b, e) for component a: the Jacobian, or the
// warm-up's column at the current time constant.
struct Columns {
  const Problem& pb;
  const std::vector<int>& F;
  std::vector<int> stat;      // positions in F of static columns
  std::vector<int> stat_idx;  // their parameter indices
  int dyn = -1;               // position in F of the warm-up growth
  Eigen::MatrixXd c;          // N x m warm-up column
  Columns(const Problem& p, const std::vector<int>& f, const Eigen::VectorXd& th) : pb(p), F(f) {
    for (size_t k = 0; k < F.size(); ++k) {
      if (F[k] == pb.warmup) {
        dyn = static_cast<int>(k);
        c = WarmupColumn(pb, th[pb.warmup + 1]);
      } else {
        stat.push_back(static_cast<int>(k));
        stat_idx.push_back(F[k]);
      }
    }
  }
  // H = sum_ab W_ab J_a(set, F)^T J_b(set, F).
  Eigen::MatrixXd Normal(const RowSet& set, const Eigen::MatrixXd& W) const {
    const int m = pb.m, nf = F.size();
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(nf, nf);
    Eigen::MatrixXd Hs = Eigen::MatrixXd::Zero(stat.size(), stat.size());
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b) {
        const double w = W(a, b);
        if (w == 0) continue;
        if (set.fold < 0) {
          Hs += w * pb.Gall[a * m + b](stat_idx, stat_idx);
        } else if (set.train) {
          Hs += w * (pb.Gall[a * m + b](stat_idx, stat_idx) - pb.G[set.fold][a * m + b](stat_idx, stat_idx));
        } else {
          Hs += w * pb.G[set.fold][a * m + b](stat_idx, stat_idx);
        }
      }
    H(stat, stat) = Hs;
    if (dyn >= 0) {
      Eigen::VectorXd hd = Eigen::VectorXd::Zero(nf);
      for (const auto& [b0, e0] : set.ranges) {
        const int len = e0 - b0;
        for (int a = 0; a < m; ++a) {
          // W c_a summed with J_b: rows of c times W.
          Eigen::VectorXd cw = Eigen::VectorXd::Zero(len);
          for (int b = 0; b < m; ++b) cw += W(a, b) * c.col(b).segment(b0, len);
          if (!stat.empty()) {
            const Eigen::VectorXd v = pb.J[a](Eigen::seqN(b0, len), stat_idx).transpose() * cw;
            for (size_t k = 0; k < stat.size(); ++k) hd[stat[k]] += v[k];
          }
          hd[dyn] += c.col(a).segment(b0, len).dot(cw);
        }
      }
      H.row(dyn) = hd.transpose();
      H.col(dyn) = hd;
    }
    return H;
  }
  // g = sum_a J_a(set, F)^T (R W)(set, a).
  Eigen::VectorXd Gradient(const RowSet& set, const Eigen::MatrixXd& W, const Eigen::MatrixXd& R) const {
    Eigen::VectorXd g = Eigen::VectorXd::Zero(F.size());
    for (const auto& [b0, e0] : set.ranges) {
      const int len = e0 - b0;
      const Eigen::MatrixXd RW = R.middleRows(b0, len) * W;
      for (int a = 0; a < pb.m; ++a) {
        if (!stat.empty()) {
          const Eigen::VectorXd v = pb.J[a](Eigen::seqN(b0, len), stat_idx).transpose() * RW.col(a);
          for (size_t k = 0; k < stat.size(); ++k) g[stat[k]] += v[k];
        }
        if (dyn >= 0) g[dyn] += c.col(a).segment(b0, len).dot(RW.col(a));
      }
    }
    return g;
  }
  // R(set) += J(set, F) d.
  void Apply(const RowSet& set, const Eigen::VectorXd& d, Eigen::MatrixXd* R) const {
    Eigen::VectorXd ds(stat.size());
    for (size_t k = 0; k < stat.size(); ++k) ds[k] = d[stat[k]];
    for (const auto& [b0, e0] : set.ranges) {
      const int len = e0 - b0;
      for (int a = 0; a < pb.m; ++a) {
        if (!stat.empty()) R->col(a).segment(b0, len).noalias() += pb.J[a](Eigen::seqN(b0, len), stat_idx) * ds;
        if (dyn >= 0) R->col(a).segment(b0, len) += d[dyn] * c.col(a).segment(b0, len);
      }
    }
  }
};

// Iterated generalized least squares on the rows of `set`: theta(F) and the noise
// covariance S, with R (N x m) the current residuals of those rows, kept up to date.
void SolveLinear(const Problem& pb, const RowSet& set, const std::vector<int>& F, Eigen::VectorXd* theta,
                 Eigen::MatrixXd* R, Eigen::MatrixXd* S, std::vector<char>* at_bound) {
  const Columns cols(pb, F, *theta);
  Eigen::VectorXd lower(F.size());
  for (size_t k = 0; k < F.size(); ++k) lower[k] = pb.lower[F[k]];
  double last = LogDet(*S);
  for (int it = 0; it < 60; ++it) {
    const Eigen::MatrixXd W = S->inverse();
    const Eigen::MatrixXd H = cols.Normal(set, W);
    const Eigen::VectorXd g = cols.Gradient(set, W, *R);
    const Eigen::VectorXd x = (*theta)(F);
    const Eigen::VectorXd d = BoundedStep(H, g, x, lower, at_bound);
    for (size_t k = 0; k < F.size(); ++k) (*theta)[F[k]] += d[k];
    cols.Apply(set, d, R);
    *S = MlCovariance(*R, set);
    const double ld = LogDet(*S);
    const double step = d.dot(H * d);
    if (std::abs(ld - last) < 1e-10 && step < 1e-10) break;
    last = ld;
  }
}

// The fit of the model whose free parameters are F, on all rows, from `start`.
FitResult FitModel(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start,
                   const Eigen::MatrixXd& noise_start) {
  FitResult f;
  f.free = F;
  f.theta = start;
  const RowSet all = AllRows(pb);
  Exact(pb, f.theta, all, &f.R);
  Eigen::MatrixXd S = noise_start;
  for (int pass = 0; pass < 6; ++pass) {
    SolveLinear(pb, all, F, &f.theta, &f.R, &S, &f.at_bound);
    Eigen::MatrixXd Rex;
    Exact(pb, f.theta, all, &Rex);
    const Eigen::MatrixXd Li = WhiteningOf(S);
    const double change = ((Rex - f.R) * Li.transpose()).cwiseAbs().maxCoeff();
    f.R = Rex;
    S = MlCovariance(f.R, all);
    if (change < 1e-4) break;
  }
  f.noise = S;
  f.loglik = RowLogLik(f.R, S, all, &f.row_ll);
  // Covariance of the parameters not at a bound.
  const Columns cols(pb, F, f.theta);
  const Eigen::MatrixXd H = cols.Normal(all, S.inverse());
  std::vector<int> in;
  for (size_t k = 0; k < F.size(); ++k)
    if (f.at_bound.empty() || !f.at_bound[k]) in.push_back(static_cast<int>(k));
  f.cov = Eigen::MatrixXd::Zero(F.size(), F.size());
  if (!in.empty()) f.cov(in, in) = InverseScaled(H(in, in));
  return f;
}

double SigmaOf(const FitResult& f, int param) {
  for (size_t k = 0; k < f.free.size(); ++k)
    if (f.free[k] == param) return std::sqrt(std::max(0.0, f.cov(k, k)));
  return 0.0;
}
bool AtBound(const FitResult& f, int param) {
  for (size_t k = 0; k < f.free.size(); ++k)
    if (f.free[k] == param) return !f.at_bound.empty() && f.at_bound[k];
  return false;
}

// Held-out log-likelihood (summed), position RMS and per-row values of a model by the
// time-blocked folds, each fold's fit starting from the fit on all rows.
struct HeldOut {
  double loglik = 0.0, rms = 0.0;
  Eigen::VectorXd row_ll;
};
HeldOut CrossValidate(const Problem& pb, const FitResult& all_fit) {
  HeldOut h;
  h.row_ll.setZero(pb.N);
  double sum_sq = 0;
  for (int f = 0; f < pb.K; ++f) {
    const RowSet train = TrainRows(pb, f), test = TestRows(pb, f);
    Eigen::VectorXd theta = all_fit.theta;
    Eigen::MatrixXd R = all_fit.R, S = all_fit.noise;
    std::vector<char> ab;
    SolveLinear(pb, train, all_fit.free, &theta, &R, &S, &ab);
    Eigen::MatrixXd Rt;
    Exact(pb, theta, test, &Rt);
    h.loglik += RowLogLik(Rt, S, test, &h.row_ll);
    sum_sq += Rt.middleRows(pb.fold_begin[f], pb.fold_begin[f + 1] - pb.fold_begin[f]).leftCols(3).squaredNorm();
  }
  h.rms = std::sqrt(sum_sq / std::max(1, pb.N));
  return h;
}

// Whether a model with `params` free parameters can be cross-validated: every training
// set has at least twice as many residuals.
bool EnoughData(const Problem& pb, int params) {
  for (int f = 0; f < pb.K; ++f)
    if (TrainRows(pb, f).Count() * pb.m < 2 * params) return false;
  return true;
}

std::string Fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

double PositionRms(const Eigen::MatrixXd& R) {
  return R.rows() ? std::sqrt(R.leftCols(3).squaredNorm() / R.rows()) : 0.0;
}

std::vector<int> Union(std::vector<int> a, const std::vector<int>& b);

// Parameters a candidate adds: its terms, and the warm-up's profiled time constant.
int ParamCount(const Problem& pb, const std::vector<int>& terms) {
  int k = static_cast<int>(terms.size());
  if (pb.warmup >= 0 && std::find(terms.begin(), terms.end(), pb.warmup) != terms.end()) ++k;
  return k;
}

std::vector<int> Union(std::vector<int> a, const std::vector<int>& b) {
  for (int x : b)
    if (std::find(a.begin(), a.end(), x) == a.end()) a.push_back(x);
  return a;
}

// ---------------------------------------------------------------------------------
// Residual tests of the nominal fit

// The covariate an effect depends on, for plots.
std::string CovariateOf(const Extension& e, int n, bool has_temperature) {
  switch (e.effect) {
    case Effect::kGravityCompliance:
      return "joint " + std::to_string(e.index + 1) + " gravity torque";
    case Effect::kBacklash:
      return "joint " + std::to_string(e.index + 1) + " move direction";
    case Effect::kThermalDrift:
      return e.variant == 1 && has_temperature ? "temperature" : "time";
    case Effect::kGeometry:
    case Effect::kClockOffset:
      return "time";
    case Effect::kLinkLength:
    case Effect::kLinkTwist:
      return "joint " + std::to_string(std::min(e.index + 2, n)) + " angle";
    default:
      return "joint " + std::to_string(e.index + 1) + " angle";
  }
}

struct Covariate {
  std::string name;
  std::vector<double> v;
};

std::vector<Covariate> Covariates(const RobotModel& robot, const RobotLog& log, const Problem& s) {
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
std::vector<std::vector<int>> RepeatGroups(const RobotLog& log, const Eigen::VectorXd& tol) {
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
      if (log.rows[b].q[0] - log.rows[a].q[0] > tol[0]) break;
      if (group[b] < 0 && ((log.rows[b].q - log.rows[a].q).cwiseAbs().array() <= tol.array()).all()) {
        group[b] = group[a];
        groups.back().push_back(b);
      }
    }
  }
  return groups;
}

// Per joint: changes of a joint value no larger than this are the encoders' jitter, not a
// move (a repeat of the pose; no new move direction for backlash): the options'
// repeat_tolerance, or 6 sqrt(2) encoder sigmas of the robot file (two readings' jitter at
// six sigma), whichever is larger.
Eigen::VectorXd JitterTolerance(const RobotModel& robot, double repeat_tolerance) {
  Eigen::VectorXd t(robot.NumJoints());
  for (int j = 0; j < robot.NumJoints(); ++j)
    t[j] = std::max(repeat_tolerance, 6.0 * std::sqrt(2.0) * robot.Joints()[j].encoder_sigma);
  return t;
}

// Residual tests of the nominal fit.
// Returns the lack-of-fit statistic (chi-square per dof of the pose means against the
// scatter of the repeats), NaN without repeats.
double TestResiduals(const RobotLog& log, const Problem& s, const FitResult& nominal, const std::vector<Covariate>& cov,
                     double alpha, int num_params, const Eigen::VectorXd& repeat_tolerance, AuditReport* rep) {
  double lack_of_fit = std::nan("");
  const int N = log.rows.size(), m = s.m;
  const Eigen::MatrixXd W = (WhiteningOf(nominal.noise) * nominal.R.transpose()).transpose();  // N x m
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
      for (int i : groups[g]) mean[g] += nominal.R.row(i).transpose();
      mean[g] /= groups[g].size();
      for (int i : groups[g]) {
        const Eigen::VectorXd d = nominal.R.row(i).transpose() - mean[g];
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
    const double p = FisherSurvival(F, d1, d2);
    tests.push_back({"lack of fit against repeated poses (F, " + std::to_string(G) + " poses)", F, p, false});
  } else {
    rep->notes.push_back(
        "no repeated poses (or too few): the noise is estimated from the residuals with the model, "
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
  int failed = 0;
  for (const auto& t : tests)
    if (t.failed) shown.push_back(t), ++failed;
  std::sort(shown.begin(), shown.end(), [](const AuditTest& a, const AuditTest& b) { return a.p_value < b.p_value; });
  // The ten strongest failures are shown; the rest are counted.
  if (shown.size() > 10) {
    shown.resize(10);
    rep->notes.push_back(std::to_string(failed - 10) + " more residual tests failed (the ten strongest are shown)");
  }
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

// ---------------------------------------------------------------------------------
// The problem's rows, the layout of every candidate's parameters, the nominal fit

// A candidate of a greedy step: the terms of theta it frees, and what it names.
struct Option {
  std::string key;         // unique label: "joint_offset at joint 3", "error_motion at joint 2 (rx)"
  Extension ext;           // the catalog effect and where it acts
  std::vector<int> terms;  // parameter indices it frees
  // Preference in ties (model_selection rule 5): 0 a single physical cause, 1 the whole
  // geometry (broad), 2 error motion (a flexible harmonic family).
  int tier = 0;
  bool geometric = false;  // a DH term (or all of them)
};

bool Wanted(const RobotAuditOptions& o, Effect e) {
  return o.only.empty() || std::find(o.only.begin(), o.only.end(), Name(e)) != o.only.end();
}
bool GeometryWanted(const RobotAuditOptions& o) {
  for (Effect e : {Effect::kGeometry, Effect::kJointOffset, Effect::kLinkLength, Effect::kLinkTwist})
    if (Wanted(o, e)) return true;
  return false;
}
// A single geometric kind is offered when asked for by name, or with the whole geometry.
bool GeometricKindWanted(const RobotAuditOptions& o, Effect e) {
  return Wanted(o, e) || Wanted(o, Effect::kGeometry);
}

// Rows with their covariates, the starting registration and tool, the folds.
Problem MakeProblem(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o) {
  Problem pb;
  pb.robot = &robot;
  pb.six = log.six_dof();
  pb.m = pb.six ? 6 : 3;
  pb.ts = pb.six ? 6 : 3;
  pb.tool0 = robot.T_flange_tool();
  pb.N = log.rows.size();
  pb.n = robot.NumJoints();
  const int N = pb.N, n = pb.n;
  const double t0 = log.rows.front().time_s;
  pb.time_span = std::max(1.0, log.rows.back().time_s - t0);
  Eigen::VectorXd dir = Eigen::VectorXd::Zero(n);
  const bool masses = robot.HasMasses();
  // A move is a change beyond the encoders' jitter, measured from where the joint last
  // stood (jitter never flips the direction of the last move).
  const Eigen::VectorXd jitter = JitterTolerance(robot, o.repeat_tolerance);
  Eigen::VectorXd at = log.rows.front().q;
  for (int i = 0; i < N; ++i) {
    const RobotLogRow& lr = log.rows[i];
    RowData r;
    r.q = lr.q;
    r.p = lr.p_meas;
    if (lr.R_meas_tool) r.R = *lr.R_meas_tool;
    for (int j = 0; j < n; ++j) {
      const double d = lr.q[j] - at[j];
      if (std::abs(d) > std::max(jitter[j], 1e-9)) {
        dir[j] = d > 0 ? 1.0 : -1.0;
        at[j] = lr.q[j];
      }
    }
    r.c.time_s = lr.time_s - t0;
    r.c.temperature_c = lr.temperature_c;
    r.c.reference_temperature_c = o.reference_temperature_c;
    r.c.move_direction = dir;
    // The arm's own weight acts whether or not the log has a payload column.
    const double payload = log.has_payload ? lr.payload_kg : 0.0;
    r.c.gravity_torque = masses ? GravityTorque(robot, lr.q, payload)
                                : Eigen::VectorXd(GravityTorquePerKg(robot, lr.q) * (log.has_payload ? payload : 1.0));
    r.c.gravity_lever = GravityLever(robot, lr.q);
    if (log.has_payload) r.c.gravity_lever.col(2 * n) *= payload;
    if (lr.qdot.size() == n) r.c.joint_velocity = lr.qdot;
    pb.rows.push_back(r);
    pb.payload = payload;
    pb.payload_factor = log.has_payload ? payload : 1.0;
  }
  // Starting registration.
  if (o.base_guess) {
    pb.base0 = *o.base_guess;
  } else if (pb.six) {
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
    pb.base0.R = svd.matrixU() * S * svd.matrixV().transpose();
    pb.base0.t = t / N;
  } else {
    std::vector<RobotMeasurement> ms(N);
    for (int i = 0; i < N; ++i) {
      ms[i].q = log.rows[i].q;
      ms[i].p_meas = log.rows[i].p_meas;
    }
    pb.base0 = InitialBaseGuess(robot, ms);
  }
  // Time-blocked folds.
  pb.K = std::max(2, std::min(o.folds, N / 4));
  pb.fold_begin.assign(pb.K + 1, N);
  for (int i = N - 1; i >= 0; --i) pb.fold_begin[TimeBlockFold(i, N, pb.K)] = i;
  for (int f = pb.K - 1; f >= 0; --f) pb.fold_begin[f] = std::min(pb.fold_begin[f], pb.fold_begin[f + 1]);
  return pb;
}

// The blocks of theta and the candidates that free them: the geometric terms (stage 2)
// and the rest of the catalog (stage 3).
void MakeLayout(Problem* pb, const RobotLog& log, const RobotAuditOptions& o, std::vector<Option>* geometric,
                std::vector<Option>* others, std::vector<std::string>* notes) {
  const RobotModel& robot = *pb->robot;
  const int n = pb->n;
  std::vector<Extension>& B = pb->blocks;
  B.push_back({Effect::kGeometry, -1, n});
  pb->geometry = 0;
  const bool masses = robot.HasMasses();
  bool moves_both_ways = false;
  for (int j = 0; j < n && !moves_both_ways; ++j) {
    bool up = false, down = false;
    for (const RowData& r : pb->rows) {
      up |= r.c.move_direction[j] > 0;
      down |= r.c.move_direction[j] < 0;
    }
    moves_both_ways = up && down;
  }
  for (int j = 0; j < n; ++j) {
    if (robot.Joints()[j].type == JointType::kRevolute && Wanted(o, Effect::kErrorMotion))
      B.push_back({Effect::kErrorMotion, j, 1});
    if (Wanted(o, Effect::kJointScale)) B.push_back({Effect::kJointScale, j, 0});
    if (Wanted(o, Effect::kGravityCompliance)) B.push_back({Effect::kGravityCompliance, j, masses ? 0 : 2 * n + 1});
    if (Wanted(o, Effect::kBacklash) && moves_both_ways) B.push_back({Effect::kBacklash, j, 0});
  }
  if (Wanted(o, Effect::kBacklash) && !moves_both_ways)
    notes->push_back("backlash not tested: no joint moves both ways in the log");
  if (Wanted(o, Effect::kThermalDrift)) {
    const double span = log.rows.back().time_s - log.rows.front().time_s;
    if (!log.has_time)
      notes->push_back("thermal_drift in time not tested: the log has no time column");
    else if (span > 0)
      B.push_back({Effect::kThermalDrift, -1, 0});
    else
      notes->push_back("thermal_drift in time not tested: the log has no time span");
    if (log.has_temperature) B.push_back({Effect::kThermalDrift, -1, 1});
  }
  bool moving = false;
  for (const auto& r : log.rows) moving |= r.qdot.size() > 0 && r.qdot.norm() > 0;
  if (Wanted(o, Effect::kClockOffset) && moving) B.push_back({Effect::kClockOffset, -1, 0});

  // Parameters.
  pb->P = pb->NumBase();
  for (const Extension& e : B) {
    pb->offset.push_back(pb->P);
    pb->P += e.NumParameters();
  }
  pb->theta0 = Eigen::VectorXd::Zero(pb->P);
  pb->lower.assign(pb->P, -kInf);
  for (size_t k = 0; k < B.size(); ++k) {
    const std::vector<double> p0 = B[k].InitialParameters();
    for (size_t j = 0; j < p0.size(); ++j) pb->theta0[pb->offset[k] + j] = p0[j];
    // Physical bounds: no joint has a negative compliance or mass, nor a negative backlash.
    if (B[k].effect == Effect::kGravityCompliance || B[k].effect == Effect::kBacklash)
      for (int j = 0; j < B[k].NumParameters(); ++j) pb->lower[pb->offset[k] + j] = 0.0;
    if (B[k].effect == Effect::kThermalDrift && B[k].variant == 0) pb->warmup = pb->offset[k];
  }

  // Geometric candidates: one DH term each (the geometry block's parameters).
  const int g0 = pb->offset[pb->geometry];
  for (int j = 0; j < n; ++j) {
    const bool rev = robot.Joints()[j].type == JointType::kRevolute;
    const auto Add = [&](Extension e, int term) {
      if (!GeometricKindWanted(o, e.effect)) return;
      geometric->push_back({e.Label(), e, {g0 + kDhParamsPerJoint * j + term}, 0, true});
    };
    if (rev) {
      Add({Effect::kJointOffset, j, 0}, 0);
      Add({Effect::kLinkLength, j, 1}, 1);
    } else {
      Add({Effect::kJointOffset, j, 0}, 1);
    }
    Add({Effect::kLinkLength, j, 0}, 2);
    Add({Effect::kLinkTwist, j, 0}, 3);
  }
  // The rest: a block each, error motion one axis's sine/cosine pair at a time.
  for (size_t k = 1; k < B.size(); ++k) {
    const Extension& e = B[k];
    if (e.effect == Effect::kErrorMotion) {
      // One kind of error motion at a time (ISO 230-7): tilt, angular, radial, axial, each
      // a first-harmonic sine/cosine pair. A radial (or tilt) motion along x and one along
      // y differ only by a part that turns with the joint, which is a DH change: the
      // geometry holds it, so x (rx) stands for both.
      static const std::pair<int, const char*> kKinds[4] = {{0, "tilt"}, {2, "angular"}, {3, "radial"}, {5, "axial"}};
      for (const auto& [a, kind] : kKinds)
        others->push_back({e.Label() + " (" + kind + ")", e, {pb->offset[k] + a, pb->offset[k] + 6 + a}, 2, false});
    } else if (e.effect == Effect::kThermalDrift && e.variant == 0) {
      others->push_back({e.Label() + " (warm-up)", e, {pb->offset[k]}, 0, false});  // the time constant is profiled
    } else {
      std::vector<int> t(e.NumParameters());
      std::iota(t.begin(), t.end(), pb->offset[k]);
      // Lumped masses: the tool point (the payload) first, then the link frames from the
      // flange inward, so that of two points the data cannot tell apart the outer is kept.
      if (e.effect == Effect::kGravityCompliance && e.variant > 0) std::reverse(t.begin(), t.end());
      std::string key = e.Label();
      if (e.effect == Effect::kThermalDrift) key += " (temperature)";
      others->push_back({key, e, t, 0, false});
    }
  }
}

// The registration and the tool of the nominal model by maximum likelihood (Ceres; the
// noise re-estimated between solves); sets theta0.
struct NominalResidual {
  const Problem* pb;
  const RowData* row;
  const Eigen::MatrixXd* Linv;
  template <typename T>
  bool operator()(T const* const* p, T* res) const {
    T e[6];
    PredictT<T>(*pb, *row, p[0], p[1], {}, nullptr, e);
    for (int i = 0; i < pb->m; ++i) {
      T acc(0);
      for (int k = 0; k <= i; ++k) acc += (*Linv)(i, k) * e[k];
      res[i] = acc;
    }
    return true;
  }
};

Eigen::MatrixXd FitNominal(Problem* pb) {
  std::vector<double> b(6, 0.0), tl(pb->ts, 0.0);
  auto Linv = std::make_shared<Eigen::MatrixXd>(Eigen::MatrixXd::Identity(pb->m, pb->m) * 1e4);
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  for (const RowData& r : pb->rows) {
    auto* cost = new ceres::DynamicAutoDiffCostFunction<NominalResidual, 12>(new NominalResidual{pb, &r, Linv.get()});
    cost->AddParameterBlock(6);
    cost->AddParameterBlock(pb->ts);
    cost->SetNumResiduals(pb->m);
    problem.AddResidualBlock(cost, nullptr, b.data(), tl.data());
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.num_threads = 1;
  Eigen::MatrixXd S = Eigen::MatrixXd::Identity(pb->m, pb->m) * 1e-8;
  double last = kInf;
  Eigen::VectorXd th(pb->NumBase());
  for (int outer = 0; outer < 8; ++outer) {
    ceres::Solver::Summary sum;
    ceres::Solve(so, &problem, &sum);
    for (int k = 0; k < 6; ++k) th[k] = b[k];
    for (int k = 0; k < pb->ts; ++k) th[6 + k] = tl[k];
    Eigen::MatrixXd R(pb->N, pb->m);
    double e[6];
    for (int i = 0; i < pb->N; ++i) {
      PredictT<double>(*pb, pb->rows[i], b.data(), tl.data(), {}, nullptr, e);
      for (int a = 0; a < pb->m; ++a) R(i, a) = e[a];
    }
    S = MlCovariance(R, AllRows(*pb));
    *Linv = WhiteningOf(S);
    const double ld = LogDet(S);
    if (std::abs(ld - last) < 1e-7) break;
    last = ld;
  }
  pb->theta0.head(pb->NumBase()) = th;
  return S;
}

// The DH parameters these poses identify with the registration and the tool free
// (calib-robot's analysis: base and tool first, then the joints from the base out), and
// the reason for each that is held.
struct Identifiable {
  std::vector<int> params;                                // geometry parameters of theta
  std::vector<std::pair<std::string, std::string>> held;  // name, reason
};

std::string DhName(const RobotModel& robot, int j, int term) {
  static const char* kTerm[4] = {"theta_offset", "d", "a", "alpha"};
  const std::string& name = robot.Joints()[j].name;
  return (name.empty() ? "J" + std::to_string(j + 1) : name) + "." + kTerm[term];
}

Identifiable GeometryIdentifiability(const Problem& pb, const Eigen::MatrixXd& noise, double tol) {
  const int nb = pb.NumBase(), g0 = pb.offset[pb.geometry], ng = kDhParamsPerJoint * pb.n;
  std::vector<int> cols;
  std::vector<std::string> names;
  static const char* kBase[6] = {"base.rx", "base.ry", "base.rz", "base.x", "base.y", "base.z"};
  static const char* kTool[6] = {"tool.x", "tool.y", "tool.z", "tool.rx", "tool.ry", "tool.rz"};
  for (int k = 0; k < 6; ++k) cols.push_back(k), names.push_back(kBase[k]);
  for (int k = 0; k < pb.ts; ++k) cols.push_back(6 + k), names.push_back(kTool[k]);
  for (int k = 0; k < ng; ++k)
    cols.push_back(g0 + k), names.push_back(DhName(*pb.robot, k / kDhParamsPerJoint, k % kDhParamsPerJoint));
  const Eigen::MatrixXd Li = WhiteningOf(noise);
  Eigen::MatrixXd Jw(static_cast<Eigen::Index>(pb.N) * pb.m, cols.size());
  for (size_t c = 0; c < cols.size(); ++c)
    for (int i = 0; i < pb.N; ++i)
      for (int a = 0; a < pb.m; ++a) {
        double v = 0;
        for (int b = 0; b <= a; ++b) v += Li(a, b) * pb.J[b](i, cols[c]);
        Jw(static_cast<Eigen::Index>(i) * pb.m + a, c) = v;
      }
  std::vector<CalibrationParameter> params(cols.size());
  for (size_t c = 0; c < cols.size(); ++c) params[c].name = names[c];
  AnalyzeIdentifiability(Jw, names, tol, &params);
  Identifiable id;
  for (int k = 0; k < ng; ++k) {
    const CalibrationParameter& p = params[nb + k];
    if (p.fixed)
      id.held.push_back({p.name, p.reason});
    else
      id.params.push_back(g0 + k);
  }
  return id;
}

// ---------------------------------------------------------------------------------
// Greedy selection: screening, full fits, the selection rule

// A candidate's identifiable terms on top of the current model and the chi-square its
// linearised (unconstrained) fit removes, with the unconstrained estimates.
struct Screened {
  int option = -1;
  std::vector<int> terms;
  double gain = 0.0;
  Eigen::VectorXd estimate, sigma;
};

std::vector<Screened> Screen(const Problem& pb, const FitResult& cur, const std::vector<Option>& opts,
                             const std::vector<int>& open, double tol, std::vector<std::string>* not_identifiable) {
  std::vector<int> C;
  for (int oi : open)
    for (int t : opts[oi].terms)
      if (std::find(cur.free.begin(), cur.free.end(), t) == cur.free.end() &&
          std::find(C.begin(), C.end(), t) == C.end())
        C.push_back(t);
  std::vector<Screened> out;
  if (C.empty()) return out;
  const std::vector<int> FC = Union(cur.free, C);
  Eigen::VectorXd th = cur.theta;
  if (pb.warmup >= 0 && std::find(C.begin(), C.end(), pb.warmup) != C.end() && th[pb.warmup] == 0.0)
    th[pb.warmup + 1] = pb.time_span / 3.0;  // a representative warm-up for screening
  const Columns cols(pb, FC, th);
  const RowSet all = AllRows(pb);
  const Eigen::MatrixXd W = cur.noise.inverse();
  const Eigen::MatrixXd H = cols.Normal(all, W);
  const Eigen::VectorXd g = cols.Gradient(all, W, cur.R);
  const int nf = cur.free.size();
  const Eigen::MatrixXd HffInv = InverseScaled(H.topLeftCorner(nf, nf));
  const auto Pos = [&](int param) { return static_cast<int>(std::find(FC.begin(), FC.end(), param) - FC.begin()); };
  for (int oi : open) {
    std::vector<int> pos;
    for (int t : opts[oi].terms)
      if (std::find(cur.free.begin(), cur.free.end(), t) == cur.free.end()) pos.push_back(Pos(t));
    if (pos.empty()) continue;
    const Eigen::MatrixXd Hcf = H(pos, Eigen::seqN(0, nf));
    const Eigen::MatrixXd S = H(pos, pos) - Hcf * HffInv * Hcf.transpose();
    const Eigen::VectorXd h = g(pos) - Hcf * HffInv * g.head(nf);
    // Identifiable terms: greedy, each against the model and the terms kept before it.
    std::vector<int> keep;
    for (size_t t = 0; t < pos.size(); ++t) {
      double d = S(t, t);
      if (!keep.empty()) {
        const Eigen::MatrixXd Skk = S(keep, keep);
        const Eigen::VectorXd skt = S(keep, Eigen::seqN(static_cast<int>(t), 1));
        d -= skt.dot(SolveScaled(Skk, skt));
      }
      const double hn = H(pos[t], pos[t]);
      if (hn > 0 && d > 0 && std::sqrt(d / hn) >= tol) keep.push_back(static_cast<int>(t));
    }
    if (keep.empty()) {
      not_identifiable->push_back(opts[oi].key);
      continue;
    }
    Screened s;
    s.option = oi;
    for (int k : keep) s.terms.push_back(FC[pos[k]]);
    const Eigen::MatrixXd Sk = S(keep, keep);
    const Eigen::MatrixXd Ski = InverseScaled(Sk);
    const Eigen::VectorXd hk = h(keep);
    s.gain = hk.dot(Ski * hk);
    s.estimate = -Ski * hk;
    s.sigma = Ski.diagonal().cwiseMax(0.0).cwiseSqrt();
    out.push_back(s);
  }
  return out;
}

struct Tried {
  int option = -1;
  std::vector<int> terms;
  FitResult fit;
  double lr = 0.0, bic = 0.0, tau_sigma = 0.0;
  bool cv_done = false;
  HeldOut cv;
};

// The fit of the model whose free parameters are F, from `start`; with the warm-up's
// growth free, its time constant by the profile likelihood (a grid in log time, refined by
// a parabola through the best and its neighbours), with its standard deviation in
// *tau_sigma.
FitResult FitProfiled(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start,
                      const Eigen::MatrixXd& noise, double* tau_sigma = nullptr) {
  const bool warmup = pb.warmup >= 0 && std::find(F.begin(), F.end(), pb.warmup) != F.end();
  if (!warmup) return FitModel(pb, F, start, noise);
  const int G = 16;
  std::vector<double> x(G), ll(G);
  std::vector<FitResult> fits(G);
  int best = 0;
  for (int k = 0; k < G; ++k) {
    x[k] = std::log(pb.time_span) + std::log(10.0) * (-1.5 + 2.5 * k / (G - 1));
    Eigen::VectorXd th = start;
    th[pb.warmup] = 0.0;
    th[pb.warmup + 1] = std::exp(x[k]);
    fits[k] = FitModel(pb, F, th, noise);
    ll[k] = fits[k].loglik;
    if (ll[k] > ll[best]) best = k;
  }
  FitResult out = fits[best];
  double sig = out.theta[pb.warmup + 1];  // at the end of the grid: known to its order only
  if (best > 0 && best < G - 1) {
    const double h = x[1] - x[0];
    const double a = (ll[best + 1] - 2 * ll[best] + ll[best - 1]) / (2 * h * h);
    const double b = (ll[best + 1] - ll[best - 1]) / (2 * h);
    if (a < 0) {
      const double dx = std::clamp(-b / (2 * a), -h, h);
      Eigen::VectorXd th = fits[best].theta;
      th[pb.warmup + 1] = std::exp(x[best] + dx);
      FitResult f = FitModel(pb, F, th, fits[best].noise);
      if (f.loglik >= out.loglik) out = f;
      sig = out.theta[pb.warmup + 1] * std::sqrt(-1.0 / (2 * a));
    }
  }
  // The covariance with the time constant free too (growth and time constant correlate
  // strongly over a log shorter than a few time constants): the normal matrix with the
  // column of tau, d r / d tau = growth (-t / tau^2) exp(-t / tau) u.
  const double growth = out.theta[pb.warmup], tau = out.theta[pb.warmup + 1];
  Eigen::MatrixXd ct = pb.u;
  for (int i = 0; i < pb.N; ++i) {
    const double t = pb.rows[i].c.time_s;
    ct.row(i) *= growth * (-t / (tau * tau)) * std::exp(-t / tau);
  }
  const RowSet all = AllRows(pb);
  const Eigen::MatrixXd W = out.noise.inverse();
  const Columns cols(pb, F, out.theta);
  const int nf = F.size();
  Eigen::MatrixXd H(nf + 1, nf + 1);
  H.topLeftCorner(nf, nf) = cols.Normal(all, W);
  const Eigen::VectorXd h = cols.Gradient(all, W, ct);
  H.block(0, nf, nf, 1) = h;
  H.block(nf, 0, 1, nf) = h.transpose();
  H(nf, nf) = (ct * W).cwiseProduct(ct).sum();
  std::vector<int> in;
  for (int k = 0; k < nf; ++k)
    if (out.at_bound.empty() || !out.at_bound[k]) in.push_back(k);
  in.push_back(nf);
  if (std::abs(growth) > 0) {
    const Eigen::MatrixXd C = InverseScaled(H(in, in));
    // `in` is the free parameters not at a bound, then tau: back to F's order.
    Eigen::MatrixXd full = Eigen::MatrixXd::Zero(nf, nf);
    for (size_t a = 0; a + 1 < in.size(); ++a)
      for (size_t b = 0; b + 1 < in.size(); ++b) full(in[a], in[b]) = C(a, b);
    out.cov = full;
    sig = std::sqrt(std::max(0.0, C(in.size() - 1, in.size() - 1)));
  }
  if (tau_sigma) *tau_sigma = sig;
  return out;
}

// The full fit of a candidate on top of `cur`.
Tried FitCandidate(const Problem& pb, const FitResult& cur, int option, const std::vector<int>& terms) {
  Tried t;
  t.option = option;
  t.terms = terms;
  t.fit = FitProfiled(pb, Union(cur.free, terms), cur.theta, cur.noise, &t.tau_sigma);
  return t;
}

struct Finding {
  int option = -1;  // the stage's option; -1 = the whole geometry
  std::vector<int> terms;
  double lr = 0.0, bic = 0.0, ll_gain = 0.0, rms_before = 0.0, rms_after = 0.0, tau_sigma = 0.0;
  double base_cv_loglik = 0.0;  // held-out log-likelihood of the model before this step
  bool undecided = false;
  std::vector<Tried> group;  // undecided: every member, best first
  bool dropped = false;      // pruned at the end
};

struct SelectionResult {
  std::vector<Finding> findings;
  FitResult cur;
  bool cv_known = false;
  HeldOut cur_cv;
};

// Greedy forward selection over every candidate, from `start`: single geometric terms,
// the whole identifiable geometry (`geometry_terms`, offered as one candidate while the
// data can hold it), and the non-geometric catalog. A non-geometric candidate must also
// pass on top of the whole geometry (at the step's rate, without the Bonferroni factor):
// an effect that only explains what some DH parameter would is not named (it would soak
// up a geometric error). At most `max_singles` single geometric terms are named; beyond
// them, only the whole geometry.
SelectionResult RunSelection(const Problem& pb, const std::vector<Option>& opts, const std::vector<int>& geometry_terms,
                             const FitResult& start, const RobotAuditOptions& o, double alpha,
                             std::set<std::string>* not_identifiable, std::vector<std::string>* notes,
                             const std::function<void(const std::string&)>& say) {
  SelectionResult res;
  res.cur = start;
  const double logN = std::log(static_cast<double>(pb.N));
  std::set<int> taken;
  int singles = 0, effects = 0;
  const auto FreeAll = [&](const FitResult& f, const std::vector<int>& terms) {
    for (int t : terms)
      if (std::find(f.free.begin(), f.free.end(), t) == f.free.end()) return false;
    return true;
  };
  for (int step = 0; step < o.max_geometric_terms + o.max_effects + 1; ++step) {
    const bool geometry_free = FreeAll(res.cur, geometry_terms);
    std::vector<int> open;
    for (size_t i = 0; i < opts.size(); ++i) {
      const Option& op = opts[i];
      if (taken.count(static_cast<int>(i))) continue;
      if (op.geometric && op.tier == 0 && singles >= o.max_geometric_terms) continue;
      if (!op.geometric && effects >= o.max_effects) continue;
      if (op.geometric && geometry_free) continue;
      open.push_back(static_cast<int>(i));
    }
    if (open.empty()) break;
    say("step " + std::to_string(step + 1) + ": screening " + std::to_string(open.size()) + " candidates");
    std::vector<std::string> ni;
    std::vector<Screened> sc = Screen(pb, res.cur, opts, open, o.identifiability_tolerance, &ni);
    if (step == 0)
      for (const auto& k : ni) not_identifiable->insert(k);
    const int M = static_cast<int>(sc.size());
    if (sc.empty()) break;
    std::sort(sc.begin(), sc.end(), [&](const Screened& a, const Screened& b) {
      return a.gain - ParamCount(pb, a.terms) * logN > b.gain - ParamCount(pb, b.terms) * logN;
    });
    const auto Threshold = [&](int k) { return ChiSquareThreshold(k, alpha / M); };
    // The whole geometry on top of the current model: the base of the confirmations.
    std::optional<FitResult> with_geometry;
    std::vector<Tried> tried;
    std::vector<std::pair<double, std::string>> unconfirmed;  // BIC gain, note
    for (size_t i = 0; i < sc.size() && static_cast<int>(tried.size()) < o.max_full_fits; ++i) {
      const int k = ParamCount(pb, sc[i].terms);
      const Option& op = opts[sc[i].option];
      if (sc[i].gain < 0.3 * Threshold(k)) continue;
      if (op.geometric && op.tier == 1 && !EnoughData(pb, static_cast<int>(res.cur.free.size()) + k)) continue;
      Tried t = FitCandidate(pb, res.cur, sc[i].option, sc[i].terms);
      t.lr = 2.0 * (t.fit.loglik - res.cur.loglik);
      t.bic = BicGain(t.lr, k, logN);
      char b[240];
      std::snprintf(b, sizeof b, "step %d: %s: likelihood ratio %.1f (threshold %.1f), BIC gain %.1f", step + 1,
                    op.key.c_str(), t.lr, Threshold(k), t.bic);
      say(b);
      // Confirmation on top of the whole geometry.
      if (!op.geometric && !geometry_free && !geometry_terms.empty() && t.lr >= Threshold(k)) {
        const std::vector<int> Fg = Union(res.cur.free, geometry_terms);
        if (EnoughData(pb, static_cast<int>(Fg.size()) + k)) {
          if (!with_geometry) with_geometry = FitModel(pb, Fg, res.cur.theta, res.cur.noise);
          const Tried c = FitCandidate(pb, *with_geometry, sc[i].option, sc[i].terms);
          const double lr = 2.0 * (c.fit.loglik - with_geometry->loglik);
          if (ChiSquareSurvival(lr, k) >= alpha) {
            std::snprintf(b, sizeof b,
                          "%s: likelihood ratio %.1f on the model, but only %.1f on top of every identifiable DH "
                          "parameter: what it explains, the geometry explains too; not named",
                          op.key.c_str(), t.lr, lr);
            say(b);
            unconfirmed.push_back({t.bic, b});
            continue;
          }
        }
      }
      tried.push_back(std::move(t));
    }
    // An unconfirmed candidate is worth a note only where it would have led the step.
    const auto NoteUnconfirmed = [&](double named_bic) {
      const auto top = std::max_element(unconfirmed.begin(), unconfirmed.end());
      if (top != unconfirmed.end() && top->first > named_bic) notes->push_back(top->second);
    };
    if (tried.empty()) {
      NoteUnconfirmed(-kInf);
      break;
    }
    std::vector<SelectionCandidate> sel(tried.size());
    for (size_t i = 0; i < tried.size(); ++i) {
      sel[i].k = ParamCount(pb, tried[i].terms);
      sel[i].lr = tried[i].lr;
      sel[i].tier = opts[tried[i].option].tier;
      sel[i].row_loglik.assign(tried[i].fit.row_ll.data(), tried[i].fit.row_ll.data() + pb.N);
    }
    SelectionRule rule;
    rule.alpha = alpha;
    rule.ln_n = logN;
    rule.close_bic = 10.0;
    const StepDecision dec = DecideStep(sel, M, rule, [&](int i) {
      if (!res.cv_known) {
        res.cur_cv = CrossValidate(pb, res.cur);
        res.cv_known = true;
      }
      Tried& t = tried[i];
      if (!t.cv_done) {
        say("step " + std::to_string(step + 1) + ": cross-validating " + opts[t.option].key);
        t.cv = CrossValidate(pb, t.fit);
        t.cv_done = true;
      }
      sel[i].heldout_row_loglik.assign(t.cv.row_ll.data(), t.cv.row_ll.data() + pb.N);
      return t.cv.loglik - res.cur_cv.loglik;
    });
    NoteUnconfirmed(dec.best >= 0 && dec.outcome != StepOutcome::kNoHeldoutGain ? sel[dec.best].bic_gain : -kInf);
    if (dec.outcome == StepOutcome::kNothingPasses) break;
    if (dec.outcome == StepOutcome::kNoHeldoutGain) {
      char b[200];
      std::snprintf(b, sizeof b,
                    "%s passed the likelihood-ratio test on all data but did not gain held-out log-likelihood "
                    "(%.1f): not named",
                    opts[tried[dec.best].option].key.c_str(), sel[dec.best].heldout_gain);
      notes->push_back(b);
      break;
    }
    Tried& best = tried[dec.best];
    Finding f;
    f.option = best.option;
    f.terms = best.terms;
    f.lr = best.lr;
    f.bic = best.bic;
    f.ll_gain = best.cv.loglik - res.cur_cv.loglik;
    f.rms_before = res.cur_cv.rms;
    f.base_cv_loglik = res.cur_cv.loglik;
    f.rms_after = best.cv.rms;
    f.tau_sigma = best.tau_sigma;
    f.undecided = dec.outcome == StepOutcome::kUndecided;
    // The best is in the model; the others of an undecided group stay candidates: if one
    // still earns its place on top of the best, it was not an alternative but a second
    // effect (both then named, below).
    taken.insert(best.option);
    if (f.undecided)
      for (int i : dec.group) f.group.push_back(tried[i]);
    const Option& bo = opts[best.option];
    if (bo.geometric && bo.tier == 0) ++singles;
    if (!bo.geometric) ++effects;
    // A candidate named now that stood in an earlier undecided group beside that group's
    // best: both earn their places, so that group is decided.
    if (!f.undecided)
      for (Finding& g : res.findings)
        if (g.undecided)
          for (size_t m = 1; m < g.group.size(); ++m)
            if (g.group[m].option == f.option) g.undecided = false;
    res.findings.push_back(f);
    res.cur = best.fit;
    res.cur_cv = best.cv;
  }
  return res;
}

// ---------------------------------------------------------------------------------
// Reporting

// The effect of a finding with its sizes from `fit`.
AuditEffect EffectOf(const Problem& pb, const Option& op, const std::vector<int>& terms, const FitResult& fit,
                     double tau_sigma, const Identifiable& ident) {
  AuditEffect e;
  e.name = Name(op.ext.effect);
  e.where = op.ext.Where();
  if (op.ext.effect == Effect::kGeometry) {
    // Every identifiable DH parameter by its calib-robot name, and the held ones.
    for (int p : ident.params) {
      const int k = p - pb.offset[pb.geometry];
      const std::string nm = DhName(*pb.robot, k / kDhParamsPerJoint, k % kDhParamsPerJoint);
      e.parameters.push_back({nm, fit.theta[p]});
      e.sigma.push_back({nm, SigmaOf(fit, p)});
    }
    e.held = ident.held;
    return e;
  }
  const auto names = op.ext.ParameterNames();
  const int k = std::upper_bound(pb.offset.begin(), pb.offset.end(), terms.front()) - pb.offset.begin() - 1;
  const bool geometric = k == pb.geometry;
  for (int p : terms) {
    const std::string name = geometric ? names.front() : names[p - pb.offset[k]];
    if (AtBound(fit, p)) {
      e.held.push_back({name, "at its physical bound 0 (no negative mass, compliance or backlash)"});
      continue;
    }
    e.parameters.push_back({name, fit.theta[p]});
    e.sigma.push_back({name, SigmaOf(fit, p)});
  }
  if (pb.warmup >= 0 && terms.front() == pb.warmup) {
    e.parameters.push_back({names[1], fit.theta[pb.warmup + 1]});
    e.sigma.push_back({names[1], tau_sigma});
  }
  return e;
}

RobotAuditFit ToFit(const Problem& pb, const FitResult& f) {
  RobotAuditFit r;
  for (size_t k = 0; k < pb.blocks.size(); ++k) {
    const int np = pb.blocks[k].NumParameters();
    bool any = false;
    for (int j = 0; j < np; ++j) any |= std::find(f.free.begin(), f.free.end(), pb.offset[k] + j) != f.free.end();
    if (!any) continue;
    r.extensions.push_back(pb.blocks[k]);
    std::vector<double> p(np), s(np);
    for (int j = 0; j < np; ++j) {
      p[j] = f.theta[pb.offset[k] + j];
      s[j] = SigmaOf(f, pb.offset[k] + j);
    }
    r.parameters.push_back(p);
    r.sigmas.push_back(s);
  }
  const Mat3 Rb = ExpSO3(Vec3(f.theta[0], f.theta[1], f.theta[2]));
  r.T_meas_base = Pose{Rb * pb.base0.R, pb.base0.t + Vec3(f.theta[3], f.theta[4], f.theta[5])};
  const Mat3 Rt = pb.six ? ExpSO3(Vec3(f.theta[9], f.theta[10], f.theta[11])) : Mat3::Identity();
  r.T_flange_tool = Pose{Rt * pb.tool0.R, pb.tool0.t + Vec3(f.theta[6], f.theta[7], f.theta[8])};
  r.noise = f.noise;
  r.residuals = f.R;
  r.loglik = f.loglik;
  return r;
}

// The robot description with what it can hold of the fit: the DH table's corrections
// and error motion; the tool as fitted.
RobotModel ExtendedRobot(const Problem& pb, const FitResult& f, std::vector<std::string>* notes,
                         const std::vector<Extension>& named) {
  const RobotModel& robot = *pb.robot;
  std::vector<Joint> joints = robot.Joints();
  const int g0 = pb.offset[pb.geometry];
  for (int j = 0; j < pb.n; ++j) {
    joints[j].theta_offset += f.theta[g0 + kDhParamsPerJoint * j];
    joints[j].d += f.theta[g0 + kDhParamsPerJoint * j + 1];
    joints[j].a += f.theta[g0 + kDhParamsPerJoint * j + 2];
    joints[j].alpha += f.theta[g0 + kDhParamsPerJoint * j + 3];
  }
  for (size_t k = 0; k < pb.blocks.size(); ++k) {
    const Extension& e = pb.blocks[k];
    if (e.effect != Effect::kErrorMotion) continue;
    bool any = false;
    for (int a = 0; a < 12; ++a) any |= f.theta[pb.offset[k] + a] != 0.0;
    if (!any) continue;
    Joint& j = joints[e.index];
    if (j.Harmonics() < 1) {
      j.error_motion_sin.push_back(Vec6::Zero());
      j.error_motion_cos.push_back(Vec6::Zero());
    }
    for (int a = 0; a < 6; ++a) {
      j.error_motion_sin[0][a] += f.theta[pb.offset[k] + a];
      j.error_motion_cos[0][a] += f.theta[pb.offset[k] + 6 + a];
    }
  }
  for (const Extension& e : named)
    if (e.effect != Effect::kErrorMotion && e.effect != Effect::kGeometry && e.effect != Effect::kJointOffset &&
        e.effect != Effect::kLinkLength && e.effect != Effect::kLinkTwist)
      notes->push_back(e.Label() + " is not a term of the robot description file: robot.yaml holds the rest");
  RobotModel m = robot.WithJoints(joints);
  m.SetT_flange_tool(ToFit(pb, f).T_flange_tool);
  return m;
}

// Poses that best separate two fitted models: their predicted tool difference against
// the noise, over poses drawn within the joint limits and near the logged ones.
RobotAuditResult::NextPoses SeparatingPoses(const Problem& pb, const RobotLog& log, const Tried& A, const Tried& B,
                                            const std::string& la, const std::string& lb, int count) {
  RobotAuditResult::NextPoses np;
  np.a = la;
  np.b = lb;
  if (count <= 0) return np;
  const RobotModel& robot = *pb.robot;
  Rng rng(20261204);
  const Eigen::MatrixXd Li = WhiteningOf(A.fit.noise);
  const RowData& last = pb.rows.back();
  struct Cand {
    Eigen::VectorXd q;
    double score;
    Vec3 pa, pb;
  };
  std::vector<Cand> cands;
  for (int k = 0; k < 4000; ++k) {
    Eigen::VectorXd q = k % 2 ? log.rows[static_cast<int>(rng.Uniform() * pb.N) % pb.N].q : Eigen::VectorXd::Zero(pb.n);
    const int redraw = k % 2 ? 1 + static_cast<int>(rng.Uniform() * 2) : pb.n;
    for (int r = 0; r < redraw; ++r) {
      const int j = k % 2 ? static_cast<int>(rng.Uniform() * pb.n) % pb.n : r;
      const Joint& jt = robot.Joints()[j];
      const double wide = jt.type == JointType::kRevolute ? std::numbers::pi : 1.0;
      q[j] = rng.Uniform(std::max(jt.lower, -wide), std::min(jt.upper, wide));
    }
    RowData row;
    row.q = q;
    row.c = last.c;
    row.c.move_direction = Eigen::VectorXd::Zero(pb.n);
    row.c.joint_velocity.resize(0);
    row.c.gravity_lever = GravityLever(robot, q);
    row.c.gravity_lever.col(2 * pb.n) *= pb.payload_factor;
    row.c.gravity_torque = robot.HasMasses() ? GravityTorque(robot, q, pb.payload)
                                             : Eigen::VectorXd(GravityTorquePerKg(robot, q) * pb.payload_factor);
    // B's prediction is the "measurement": A's residual is then the difference.
    double e[6];
    row.p.setZero();
    row.R.setIdentity();
    RowResidualT<double>(pb, row, B.fit.theta.data(), e);
    const Vec3 pbv(e[0], e[1], e[2]);
    row.p = pbv;
    if (pb.six) {
      // R_meas = R_pred_B: with R_meas = I the residual's rotation is Log(R_pred_B).
      row.R = ExpSO3(Vec3(e[3], e[4], e[5]));
    }
    RowResidualT<double>(pb, row, A.fit.theta.data(), e);
    Eigen::VectorXd d(pb.m);
    for (int a = 0; a < pb.m; ++a) d[a] = e[a];
    cands.push_back({q, (Li * d).squaredNorm(), pbv + Vec3(e[0], e[1], e[2]), pbv});
  }
  std::sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) { return a.score > b.score; });
  for (const Cand& c : cands) {
    bool far = true;
    for (const auto& s : np.poses) far &= (s.q - c.q).cwiseAbs().maxCoeff() > 0.2;
    if (!far) continue;
    np.poses.push_back({c.q, c.pa, c.pb, std::sqrt(c.score)});
    if (static_cast<int>(np.poses.size()) >= count) break;
  }
  return np;
}

// A physical bound the data push against (a negative compliance or backlash wanted on top
// of the final model and the whole geometry): said in a note, not named.
void NoteViolatedBounds(const Problem& pb, const std::vector<Option>& opts, const Identifiable& ident,
                        const FitResult& fin, double alpha_selection, const RobotAuditOptions& o,
                        AuditReport* rep_out) {
  AuditReport& rep = *rep_out;
  const bool has_geometry = Union(fin.free, ident.params).size() == fin.free.size();
  const FitResult base = has_geometry ? fin : FitProfiled(pb, Union(fin.free, ident.params), fin.theta, fin.noise);
  std::vector<int> bounded;
  for (size_t i = 0; i < opts.size(); ++i) {
    bool b = false, all_free = true;
    for (int t : opts[i].terms) {
      b |= std::isfinite(pb.lower[t]);
      all_free &= std::find(base.free.begin(), base.free.end(), t) != base.free.end();
    }
    if (b && !all_free) bounded.push_back(static_cast<int>(i));
  }
  std::vector<std::string> ignored;
  for (const Screened& sc : Screen(pb, base, opts, bounded, o.identifiability_tolerance, &ignored)) {
    const int k = ParamCount(pb, sc.terms);
    if (sc.gain < ChiSquareThreshold(k, alpha_selection / std::max<size_t>(1, opts.size()))) continue;
    int worst = 0;
    for (int j = 1; j < sc.estimate.size(); ++j)
      if (sc.estimate[j] / std::max(1e-300, sc.sigma[j]) < sc.estimate[worst] / std::max(1e-300, sc.sigma[worst]))
        worst = j;
    if (!(sc.estimate[worst] < -3.0 * sc.sigma[worst])) continue;
    const Option& op = opts[sc.option];
    const auto names = op.ext.ParameterNames();
    const int blk = std::upper_bound(pb.offset.begin(), pb.offset.end(), sc.terms[worst]) - pb.offset.begin() - 1;
    const int pidx = std::min<int>(sc.terms[worst] - pb.offset[blk], names.size() - 1);
    char nb[600];
    std::snprintf(nb, sizeof nb,
                  "%s: the data ask for a sign no joint can have (%s = %.3g +- %.2g without its bound at 0, "
                  "likelihood ratio %.1f): held at 0 and not named; a counterbalance spring, masses in the robot "
                  "file that are too large, or an effect the catalog lacks would do this",
                  op.key.c_str(), names[pidx].c_str(), sc.estimate[worst], sc.sigma[worst], sc.gain);
    rep.notes.push_back(nb);
  }
}

// The residual without a named finding along its direction, and the finding itself, per
// measurement against the covariate the effect depends on.
RobotAuditResult::EffectPlot EffectPlotOf(const Problem& pb, const RobotLog& log, const std::vector<Covariate>& cov,
                                          const FitResult& fin, const std::string& label, const std::vector<int>& terms,
                                          const Extension& ext) {
  RobotAuditResult::EffectPlot pl;
  pl.effect = label;
  pl.covariate = CovariateOf(ext, pb.n, log.has_temperature);
  Eigen::VectorXd th = fin.theta;
  for (int p : terms) th[p] = pb.theta0[p];
  Eigen::MatrixXd Rwithout;
  Exact(pb, th, AllRows(pb), &Rwithout);
  const Covariate* cv = nullptr;
  for (const auto& c : cov)
    if (c.name == pl.covariate) cv = &c;
  for (int i = 0; i < pb.N; ++i) {
    const Vec3 d = (Rwithout.row(i).leftCols(3) - fin.R.row(i).leftCols(3)).transpose();
    const double nd = d.norm();
    const Vec3 u = nd > 0 ? Vec3(d / nd) : Vec3::UnitX();
    pl.x.push_back(cv ? cv->v[i] : log.rows[i].time_s);
    pl.residual_before.push_back(Rwithout.row(i).leftCols(3).dot(u.transpose()));
    pl.effect_size.push_back(nd);
  }
  return pl;
}

}  // namespace

std::string Num4(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.4g", v);
  return b;
}

// A mistyped row: a measured position far outside where the others lie (a coordinate of
// 1e308, one row in millimetres). Robust: distances from the componentwise median,
// against their median; a row beyond 100 times that (and 10 m) is named.
void CheckOutlyingRow(const RobotLog& log) {
  const int N = log.rows.size();
  Vec3 med;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> c(N);
    for (int i = 0; i < N; ++i) c[i] = log.rows[i].p_meas[k];
    std::nth_element(c.begin(), c.begin() + N / 2, c.end());
    med[k] = c[N / 2];
  }
  std::vector<double> d(N);
  for (int i = 0; i < N; ++i) d[i] = (log.rows[i].p_meas - med).norm();
  std::vector<double> sorted = d;
  std::nth_element(sorted.begin(), sorted.begin() + N / 2, sorted.end());
  const double typical = sorted[N / 2];
  for (int i = 0; i < N; ++i)
    if (d[i] > std::max(100.0 * typical, 10.0))
      Throw(LineOf(log, i), ": the measured position (", Num4(log.rows[i].p_meas.x()), ", ",
            Num4(log.rows[i].p_meas.y()), ", ", Num4(log.rows[i].p_meas.z()), ") m lies ",
            std::isfinite(d[i]) ? Num4(d[i]) + " m" : std::string("absurdly far"),
            " from the log's median position, where the other rows lie within about ", Num4(typical),
            " m: a mistyped row, or another unit than metres?");
}

// The same measurement twice (identical joints and position to the last digit, which two
// real measurements never are) would count it twice and halve its variance.
void CheckDuplicateRows(const RobotLog& log) {
  std::vector<size_t> order(log.rows.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  const auto key = [&](size_t i) {
    const RobotLogRow& r = log.rows[i];
    std::vector<double> k(r.q.data(), r.q.data() + r.q.size());
    k.insert(k.end(), {r.p_meas.x(), r.p_meas.y(), r.p_meas.z()});
    return k;
  };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key(a) < key(b); });
  size_t a = 0, b = order.size();  // the duplicate pair whose later row comes first
  for (size_t k = 1; k < order.size(); ++k)
    if (key(order[k - 1]) == key(order[k]) && std::max(order[k - 1], order[k]) < b)
      a = std::min(order[k - 1], order[k]), b = std::max(order[k - 1], order[k]);
  if (b < order.size()) {
    Throw(LineOf(log, b), " repeats ", LineOf(log, a).substr(log.source.string().size() + 1),
          " exactly (the same joints and measured position): a duplicated row would count one measurement "
          "twice; remove the duplicates (repeated visits of a pose measure a new position each time)");
  }
}

// Measured positions in another unit than metres (millimetres under x_m headers, say), a
// robot description of another size, swapped axes, or joints that do not move the tool:
// the best similarity between the tool positions the robot's model gives for the logged
// joints and the measured ones has a scale far from 1 (no DH error scales a robot by a
// fifth) or needs a reflection. Refused with the likely cause named, before any fit (the
// audit of such a log would only measure the wrong unit or axis).
void CheckScale(const RobotModel& robot, const RobotLog& log) {
  const int N = log.rows.size();
  Eigen::Matrix3Xd src(3, N), dst(3, N);
  for (int i = 0; i < N; ++i) {
    src.col(i) = robot.T_base_tool(log.rows[i].q).t;
    dst.col(i) = log.rows[i].p_meas;
  }
  const Eigen::Matrix3Xd a = src.colwise() - src.rowwise().mean(), b = dst.colwise() - dst.rowwise().mean();
  const double var_src = a.squaredNorm() / N, var_dst = b.squaredNorm() / N;
  const std::string src_name = log.source.empty() ? std::string("robot log") : log.source.string();
  if (!(var_src > 1e-8)) {
    if (var_dst > 1e-6)
      Throw(src_name,
            ": the logged joints put the tool at the same place in every row (within 0.1 mm), but the "
            "measured positions spread over ",
            Num4(std::sqrt(var_dst)),
            " m (RMS): are the joint columns filled, "
            "and in the unit their headers give?");
    Throw(src_name,
          ": neither the logged joints nor the measured positions move (every row measures the same "
          "place): the audit needs measurements spread over the workspace");
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(b * a.transpose() / N, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d d(1, 1, 1);
  const bool mirrored = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0;
  if (mirrored) d[2] = -1;
  const double scale = svd.singularValues().dot(d) / var_src;
  const double scale_any = svd.singularValues().sum() / var_src;  // rotation or reflection
  if (scale > 0.8 && scale < 1.25) return;
  if (mirrored && scale_any > 0.8 && scale_any < 1.25)
    Throw(src_name, ": the measured positions are a mirror image of where robot '", robot.Name(),
          "' puts its tool at the logged joints (a rotation fits them only at scale ", Num4(scale),
          ", a reflection at ", Num4(scale_any),
          "): two of the x_m, y_m, z_m columns swapped, or one axis's sign flipped?");
  std::string unit;
  if (std::abs(std::log10(scale) - 3.0) < 0.05)
    unit = " (millimetres under x_m, y_m, z_m headers?)";
  else if (std::abs(std::log10(scale) - 2.0) < 0.05)
    unit = " (centimetres?)";
  else if (std::abs(scale / 39.37 - 1.0) < 0.05)
    unit = " (inches?)";
  else if (std::abs(std::log10(scale) + 3.0) < 0.05)
    unit = " (kilometres?)";
  Throw(src_name, ": the measured positions are ", Num4(scale), " times as far apart as robot '", robot.Name(),
        "' puts its tool at the logged joints", unit,
        "; give the positions in metres, and the robot description the log was measured with (--robot)");
}

RobotAuditResult AuditRobot(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) Throw("robot audit options: ", why);
  CheckRobotLog(log, robot);
  CheckDuplicateRows(log);
  CheckOutlyingRow(log);
  CheckScale(robot, log);
  const int max_folds = std::max(RobotAuditOptions{}.folds, static_cast<int>(log.rows.size()) / 4);
  if (o.folds > max_folds)
    Throw("--folds ", o.folds, ": ", log.source.empty() ? std::string("the robot log") : log.source.string(), " has ",
          log.rows.size(), " measurements, enough for at most ", max_folds,
          " folds of the time-blocked cross-validation (each needs at least 4 measurements)");
  const auto say = [&](const std::string& s) {
    if (o.progress) o.progress(s);
  };
  RobotAuditResult result;
  AuditReport& rep = result.report;
  rep.mode = "robot";
  rep.rms_unit = "m";

  // 1. The problem, the nominal fit, one Jacobian, the residual tests.
  Problem pb = MakeProblem(robot, log, o);
  std::vector<Option> geo_opts, other_opts;
  MakeLayout(&pb, log, o, &geo_opts, &other_opts, &rep.notes);
  say("nominal fit");
  const Eigen::MatrixXd noise0 = FitNominal(&pb);
  say("linearising " + std::to_string(pb.P) + " parameters over " + std::to_string(pb.N) + " measurements");
  Linearize(&pb);
  const std::vector<int> base_free = [&] {
    std::vector<int> b(pb.NumBase());
    std::iota(b.begin(), b.end(), 0);
    return b;
  }();
  const FitResult nominal = FitModel(pb, base_free, pb.theta0, noise0);
  const int N = pb.N;
  const double logN = std::log(static_cast<double>(N));
  rep.nominal_n = static_cast<long>(N) * pb.m;
  const std::vector<Covariate> cov = Covariates(robot, log, pb);
  const double alpha_tests = o.false_alarm / 2.0;
  const double lof =
      TestResiduals(log, pb, nominal, cov, alpha_tests, pb.NumBase(), JitterTolerance(robot, o.repeat_tolerance), &rep);
  rep.nominal_chi2_per_dof = std::isfinite(lof) ? lof : 1.0;

  // 2. Greedy selection over the catalog: the DH parameters these poses identify one by
  //    one and all at once ("geometry first": a real robot has all of them a little off),
  //    the other effects confirmed on top of the whole geometry.
  std::set<std::string> not_identifiable;
  const Identifiable ident = GeometryIdentifiability(pb, nominal.noise, o.identifiability_tolerance);
  std::vector<Option> opts;
  for (const Option& op : geo_opts)
    if (std::find(ident.params.begin(), ident.params.end(), op.terms.front()) != ident.params.end()) opts.push_back(op);
  if (Wanted(o, Effect::kGeometry) && ident.params.size() > 1) {
    Option g{"geometry at DH table", pb.blocks[pb.geometry], ident.params, 1, true};
    opts.push_back(g);
  }
  opts.insert(opts.end(), other_opts.begin(), other_opts.end());
  const double alpha_selection = o.false_alarm / 2.0;
  const std::vector<int> geometry_terms = GeometryWanted(o) ? ident.params : std::vector<int>{};
  SelectionResult sel =
      RunSelection(pb, opts, geometry_terms, nominal, o, alpha_selection, &not_identifiable, &rep.notes, say);
  const auto IsWhole = [&](const Finding& f) { return opts[f.option].geometric && opts[f.option].tier == 1; };
  const auto IsSingle = [&](const Finding& f) { return opts[f.option].geometric && opts[f.option].tier == 0; };

  // 3. Backward pruning: geometric findings that the later effects make unnecessary.
  say("final fit");
  FitResult fin = sel.cur;
  const auto TermsOf = [&](const std::function<bool(const Finding&)>& keep) {
    std::vector<int> t = base_free;
    for (const Finding& f : sel.findings)
      if (!f.dropped && keep(f)) t = Union(t, f.terms);
    return t;
  };
  const auto Refit = [&](const std::vector<int>& F) {
    Eigen::VectorXd th = sel.cur.theta;
    for (int p = pb.NumBase(); p < pb.P; ++p)
      if (std::find(F.begin(), F.end(), p) == F.end()) th[p] = pb.theta0[p];
    return FitProfiled(pb, F, th, sel.cur.noise);
  };
  std::string effects;
  for (const Finding& f : sel.findings)
    if (!opts[f.option].geometric) effects += (effects.empty() ? "" : ", ") + opts[f.option].key;
  if (!effects.empty()) {
    const double bar = alpha_selection / std::max<size_t>(1, opts.size());
    while (true) {
      int weakest = -1;
      double wlr = kInf;
      FitResult wfit;
      for (size_t i = 0; i < sel.findings.size(); ++i) {
        const Finding& fi = sel.findings[i];
        if (fi.dropped || !opts[fi.option].geometric) continue;
        // Without it; the whole geometry gives way to the single terms named before it.
        const FitResult f = Refit(TermsOf([&](const Finding& x) { return &x != &fi; }));
        const double lr = 2.0 * (fin.loglik - f.loglik);
        const double k = static_cast<double>(Union(f.free, fi.terms).size() - f.free.size());
        if (EarnsPlace(lr, std::max(1.0, k), bar, logN)) continue;
        if (lr < wlr) wlr = lr, weakest = static_cast<int>(i), wfit = f;
      }
      if (weakest < 0) break;
      sel.findings[weakest].dropped = true;
      fin = wfit;
      rep.notes.push_back(opts[sel.findings[weakest].option].key + " was named at first, but once " + effects +
                          " is in the model it no longer earns its place (likelihood ratio " + Fixed(wlr, 1) +
                          "): not named");
    }
  }
  fin = Refit(TermsOf([](const Finding&) { return true; }));
  NoteViolatedBounds(pb, opts, ident, fin, alpha_selection, o, &rep);

  // 4. The report.
  std::vector<Extension> named;
  bool geometry_named = false;
  HeldOut nominal_cv, fin_cv;
  for (const Finding& f : sel.findings) {
    if (f.dropped) continue;
    const Option& op = opts[f.option];
    if (f.undecided) {
      std::vector<std::string> labels;
      std::vector<AuditEffect> sizes;
      for (const Tried& t : f.group) {
        labels.push_back(opts[t.option].key);
        AuditEffect e = EffectOf(pb, opts[t.option], t.terms, t.fit, t.tau_sigma, ident);
        e.heldout_rms_before = f.rms_before;
        e.heldout_rms_after = t.cv_done ? t.cv.rms : std::nan("");
        e.heldout_loglik_gain = t.cv_done ? t.cv.loglik - f.base_cv_loglik : std::nan("");
        e.bic_gain = t.bic;
        sizes.push_back(e);
      }
      rep.undecided.push_back(labels);
      rep.undecided_effects.push_back(sizes);
      if (f.group.size() >= 2)
        result.next_poses.push_back(
            SeparatingPoses(pb, log, f.group[0], f.group[1], labels[0], labels[1], o.next_poses));
      continue;
    }
    AuditEffect e = EffectOf(pb, op, f.terms, fin, f.tau_sigma, ident);
    e.heldout_rms_before = f.rms_before;
    e.heldout_rms_after = f.rms_after;
    e.heldout_loglik_gain = f.ll_gain;
    e.bic_gain = f.bic;
    if (IsWhole(f)) {
      // The whole geometry's gain over the nominal, with the single terms named before it.
      geometry_named = true;
      if (nominal_cv.row_ll.size() == 0) nominal_cv = CrossValidate(pb, nominal);
      const FitResult g = Refit(TermsOf(IsSingle));
      const FitResult gw = Refit(Union(TermsOf(IsSingle), ident.params));
      const HeldOut gcv = CrossValidate(pb, gw);
      e.heldout_rms_before = nominal_cv.rms;
      e.heldout_rms_after = gcv.rms;
      e.heldout_loglik_gain = gcv.loglik - nominal_cv.loglik;
      e.bic_gain = BicGain(2.0 * (gw.loglik - nominal.loglik), static_cast<double>(ident.params.size()), logN);
      (void)g;
    }
    rep.effects.push_back(e);
    named.push_back(op.ext);
  }
  // The single geometric terms named before the whole geometry are in it.
  if (geometry_named) {
    std::vector<AuditEffect> kept;
    for (const AuditEffect& e : rep.effects) {
      bool single = false;
      for (const Finding& f : sel.findings)
        if (!f.dropped && !f.undecided && IsSingle(f) && Name(opts[f.option].ext.effect) == e.name &&
            opts[f.option].ext.Where() == e.where)
          single = true;
      if (!single) kept.push_back(e);
    }
    rep.effects = kept;
  } else if (!ident.held.empty()) {
    bool any_geometric = false;
    for (const Finding& f : sel.findings) any_geometric |= !f.dropped && opts[f.option].geometric;
    if (any_geometric) {
      std::string h;
      for (const auto& [name, reason] : ident.held) h += (h.empty() ? "" : ", ") + name;
      rep.notes.push_back("DH parameters not identifiable from these poses with a free registration and tool: " + h);
    }
  }
  for (const auto& label : not_identifiable)
    rep.notes.push_back(label + ": not identifiable from these measurements with a free registration and tool");
  bool failed = false;
  for (const auto& t : rep.tests) failed |= t.failed;
  rep.clean = !failed && rep.effects.empty() && rep.undecided.empty();
  if (failed && rep.effects.empty() && rep.undecided.empty())
    rep.notes.push_back("the nominal model fails a residual test but no effect of the catalog earns its place");

  result.nominal = ToFit(pb, nominal);
  result.extended = ToFit(pb, fin);
  result.extended_robot = ExtendedRobot(pb, fin, &rep.notes, named);

  for (const Finding& f : sel.findings) {
    if (f.dropped || f.undecided || (geometry_named && IsSingle(f))) continue;
    result.plots.push_back(
        EffectPlotOf(pb, log, cov, fin, opts[f.option].key, IsWhole(f) ? ident.params : f.terms, opts[f.option].ext));
  }
  return result;
}

void WriteNextPoses(const std::filesystem::path& path, const RobotAuditResult& result, int num_joints) {
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "pair";
    for (int j = 1; j <= num_joints; ++j) os << ",q" << j << "_rad";
    os << ",x_a_m,y_a_m,z_a_m,x_b_m,y_b_m,z_b_m,difference_mm,separation_sigma\n";
    char b[64];
    for (const auto& np : result.next_poses)
      for (const auto& p : np.poses) {
        os << '"' << np.a << " | " << np.b << '"';
        for (int j = 0; j < p.q.size(); ++j) {
          std::snprintf(b, sizeof b, ",%.9g", p.q[j]);
          os << b;
        }
        for (const Vec3* v : {&p.p_meas_a, &p.p_meas_b})
          for (int k = 0; k < 3; ++k) {
            std::snprintf(b, sizeof b, ",%.9g", (*v)[k]);
            os << b;
          }
        std::snprintf(b, sizeof b, ",%.6f,%.3f\n", (p.p_meas_a - p.p_meas_b).norm() * 1e3, p.separation_sigma);
        os << b;
      }
  });
}
std::string RunRobotAuditJob(const RobotAuditJob& job) {
  RequireOutputsSpareInputs({{job.output_dir, "audit robot -o", true}, {job.json, "audit robot --json"}},
                            {job.log, job.robot});
  if (!job.output_dir.empty())
    RequireReplaceableFolder(job.output_dir, {"report.json"}, "audit robot", "audit robot -o");
  if (!job.json.empty()) RequireWritableFile(job.json, "audit robot --json");
  const RobotModel robot = job.robot.empty() ? RobotModel::Default() : RobotModel::Read(job.robot);
  const RobotLog log = ReadRobotLog(job.log, robot);
  const RobotAuditResult r = AuditRobot(robot, log, job.options);
  std::ostringstream text;
  text << "robot log " << job.log.string() << ": " << log.rows.size() << " measurements ("
       << (log.six_dof() ? "6-D" : "3-D") << "), robot '" << robot.Name() << "'\n";
  const Eigen::MatrixXd& S = r.nominal.noise;
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "nominal model: position residual RMS %.4f mm; noise sigma x y z %.4f %.4f %.4f mm (fitted)\n",
                PositionRms(r.nominal.residuals) * 1e3, std::sqrt(S(0, 0)) * 1e3, std::sqrt(S(1, 1)) * 1e3,
                std::sqrt(S(2, 2)) * 1e3);
  text << buf;
  text << r.report.Text();
  std::snprintf(buf, sizeof buf, "extended model: position residual RMS %.4f mm\n",
                PositionRms(r.extended.residuals) * 1e3);
  text << buf;
  for (const auto& np : r.next_poses)
    if (!np.poses.empty()) {
      std::snprintf(buf, sizeof buf,
                    "to tell [%s] from [%s]: measure the %zu poses of next_poses.csv (-o); the best "
                    "separates them by %.1f sigma of the noise\n",
                    np.a.c_str(), np.b.c_str(), np.poses.size(), np.poses.front().separation_sigma);
      text << buf;
    }
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
                            if (!r.next_poses.empty()) WriteNextPoses(dir / "next_poses.csv", r, robot.NumJoints());
                            r.report.WriteJson(dir / "report.json");
                          });
  }
  if (!job.json.empty()) r.report.WriteJson(job.json);
  return report;
}

}  // namespace mcms
