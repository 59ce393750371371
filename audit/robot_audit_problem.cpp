// Long file: the robot audit's forward model is templated over Ceres' Jet, and every autodiff
// functor over it (registration, all parameters, the free parameters, the nominal fit) and
// the fits that run them stay in this one translation unit: autodiff compiles slowly, and
// a second unit would instantiate the templates again (docs/performance.md).
#include "audit/robot_audit_problem.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <numeric>

#include <ceres/ceres.h>
#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/rotation.h>

#include "audit/model_selection.h"
#include "model/robot_validation.h"
#include "core/error.h"

namespace mcms::robot_audit {

namespace {

constexpr double kLog2Pi = 1.8378770664093453;

// The residuals' Jacobian with respect to the parameters F at theta, on the rows of `set`
// (the exact model; below).
std::vector<Eigen::MatrixXd> FreeJacobian(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& theta,
                                          const RowSet& set);


// The tool's pose in the robot's base frame for the tool tl and the extensions' blocks (the
// tool's rotation only for 6-D problems), before the registration.
template <typename T>
PoseT<T> ToolInBaseT(const Problem& pb, const RowData& row, const T* tl, const std::vector<Extension>& ext,
                     const T* const* blocks) {
  const PoseT<T> F = ExtendedFlangeT<T>(*pb.robot, ext, blocks, row.q, row.c);
  using V3 = Eigen::Matrix<T, 3, 1>;
  using M3 = Eigen::Matrix<T, 3, 3>;
  const V3 t_tool = pb.tool0.t.cast<T>() + V3(tl[0], tl[1], tl[2]);
  PoseT<T> out;
  const M3 C = row.tilt.R.cast<T>();
  out.t = C * (F.R * t_tool + F.t) + row.tilt.t.cast<T>();
  if (pb.six) {
    M3 Rt;
    ceres::AngleAxisToRotationMatrix(tl + 3, Rt.data());
    out.R = C * F.R * Rt * pb.tool0.R.cast<T>();
  } else {
    out.R = C * F.R * pb.tool0.R.cast<T>();
  }
  return out;
}

// T_meas_tool: the tool's pose X in the base frame placed by the row's station's
// registration b (rotation vector applied before its start placement, translation after).
template <typename T, typename U>
PoseT<T> RegisterT(const Problem& pb, const RowData& row, const T* b, const PoseT<U>& X) {
  using V3 = Eigen::Matrix<T, 3, 1>;
  using M3 = Eigen::Matrix<T, 3, 3>;
  M3 Rb;
  ceres::AngleAxisToRotationMatrix(b, Rb.data());
  const Pose& base0 = pb.station0[row.station];
  const M3 R_mb = Rb * base0.R.cast<T>();
  const V3 t_mb = base0.t.cast<T>() + V3(b[3], b[4], b[5]);
  PoseT<T> out;
  out.t = R_mb * X.t.template cast<T>() + t_mb;
  out.R = R_mb * X.R.template cast<T>();
  return out;
}

// The predicted tool pose T_meas_tool of one row for the registration b, the tool tl and
// the extensions' blocks.
template <typename T>
PoseT<T> PredictPoseT(const Problem& pb, const RowData& row, const T* b, const T* tl,
                      const std::vector<Extension>& ext, const T* const* blocks) {
  return RegisterT<T, T>(pb, row, b, ToolInBaseT<T>(pb, row, tl, ext, blocks));
}

// Measured minus nothing: the residual of a predicted pose X (position, m; and for 6-D the
// rotation vector of R_pred R_meas^T).
template <typename T>
void PoseResidualT(const Problem& pb, const RowData& row, const PoseT<T>& X, T* e) {
  for (int k = 0; k < 3; ++k) e[k] = X.t[k] - T(row.p[k]);
  if (pb.six) {
    const Eigen::Matrix<T, 3, 3> E = X.R * row.R.transpose().cast<T>();
    ceres::RotationMatrixToAngleAxis(E.data(), e + 3);
  }
}

// The residual of a row as a function of its station's registration alone, the tool's
// pose in the base frame held (the Jacobian of the other stations' registrations).
struct RegistrationResidual {
  const Problem* pb;
  const RowData* row;
  PoseT<double> X;
  template <typename T>
  bool operator()(T const* const* b, T* e) const {
    PoseResidualT<T>(*pb, *row, RegisterT<T, double>(*pb, *row, b[0], X), e);
    return true;
  }
};

// Predicted minus measured of one row (position, m; and for 6-D the rotation vector of
// R_pred R_meas^T).
template <typename T>
void PredictT(const Problem& pb, const RowData& row, const T* b, const T* tl, const std::vector<Extension>& ext,
              const T* const* blocks, T* e) {
  PoseResidualT<T>(pb, row, PredictPoseT<T>(pb, row, b, tl, ext, blocks), e);
}

// The same with the blocks of the layout from theta: every block, or (with `active`) only
// those marked; a block left out is at its nominal zero, where it changes nothing.
template <typename T>
void RowResidualT(const Problem& pb, const RowData& row, const T* th, T* e, const std::vector<char>* active = nullptr) {
  if (!active) {
    std::vector<const T*> ptr(pb.blocks.size());
    for (size_t k = 0; k < pb.blocks.size(); ++k) ptr[k] = th + pb.offset[k];
    PredictT<T>(pb, row, th + pb.RegOffset(row.station), th + 6, pb.blocks, ptr.data(), e);
    return;
  }
  std::vector<Extension> ext;
  std::vector<const T*> ptr;
  for (size_t k = 0; k < pb.blocks.size(); ++k)
    if ((*active)[k]) {
      ext.push_back(pb.blocks[k]);
      ptr.push_back(th + pb.offset[k]);
    }
  PredictT<T>(pb, row, th + pb.RegOffset(row.station), th + 6, ext, ptr.data(), e);
}

// The blocks whose parameters are off their nominal zero at theta or free in F (may be null).
std::vector<char> ActiveBlocks(const Problem& pb, const Eigen::VectorXd& theta, const std::vector<int>* F) {
  std::vector<char> a(pb.blocks.size(), 0);
  for (size_t k = 0; k < pb.blocks.size(); ++k) {
    const int np = pb.blocks[k].NumParameters();
    for (int j = 0; j < np && !a[k]; ++j) a[k] = theta[pb.offset[k] + j] != pb.theta0[pb.offset[k] + j];
  }
  if (F)
    for (int p : *F) {
      const int k = static_cast<int>(std::upper_bound(pb.offset.begin(), pb.offset.end(), p) - pb.offset.begin()) - 1;
      if (k >= 0 && pb.IsBlockParam(p)) a[k] = 1;
    }
  return a;
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

// The uniform-growth direction (thermal drift: every link length grows by the same relative
// amount; model/robot_model.h UniformGrowth) from the geometry block's columns, and the
// warm-up's column at time constant tau.
void GrowthDirection(Problem* pb) {
  pb->u.setZero(pb->N, pb->m);
  if (pb->geometry < 0) return;
  const int g0 = pb->offset[pb->geometry];
  const Eigen::VectorXd g = UniformGrowth(*pb->robot);
  for (int k = 0; k < g.size(); ++k)
    if (g[k] != 0.0)
      for (int a = 0; a < pb->m; ++a) pb->u.col(a) += pb->J[a].col(g0 + k) * g[k];
}
Eigen::MatrixXd WarmupColumn(const Problem& pb, double tau) {
  Eigen::MatrixXd c = pb.u;
  for (int i = 0; i < pb.N; ++i) c.row(i) *= 1.0 - std::exp(-pb.rows[i].c.time_s / tau);
  return c;
}

// min 1/2 d' H d + g' d subject to x + d >= lower (lower = -inf where unbounded): a primal
// active set (the bounded parameters are few). `at_bound` marks those held at the bound.
Eigen::VectorXd BoundedStep(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& x,
                            const Eigen::VectorXd& lower, const Eigen::VectorXd& upper, std::vector<char>* at_bound) {
  const int n = H.rows();
  std::vector<char> active(n, 0);  // 1: held at its lower bound, 2: at its upper bound
  Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
  for (int iter = 0; iter < 4 * n + 10; ++iter) {
    std::vector<int> fr, ac;
    for (int i = 0; i < n; ++i) (active[i] ? ac : fr).push_back(i);
    d.setZero();
    for (int i : ac) d[i] = (active[i] == 1 ? lower[i] : upper[i]) - x[i];
    if (!fr.empty()) {
      Eigen::VectorXd rhs = -g(fr);
      if (!ac.empty()) rhs -= H(fr, ac) * d(ac);
      d(fr) = SolveScaled(H(fr, fr), rhs);
    }
    // Most violated bound among the free.
    int worst = -1, side = 0;
    double wv = 0;
    for (int i : fr) {
      const double scale = std::sqrt(std::max(H(i, i), 1e-300));
      if (std::isfinite(lower[i])) {
        const double v = (x[i] + d[i] - lower[i]) * scale;
        if (v < -1e-12 && v < wv) wv = v, worst = i, side = 1;
      }
      if (std::isfinite(upper[i])) {
        const double v = (upper[i] - x[i] - d[i]) * scale;
        if (v < -1e-12 && v < wv) wv = v, worst = i, side = 2;
      }
    }
    if (worst >= 0) {
      active[worst] = static_cast<char>(side);
      continue;
    }
    // A bound that the gradient pulls away from is released.
    const Eigen::VectorXd grad = H * d + g;
    int rel = -1;
    double rv = 0;
    for (int i : ac) {
      const double v = (active[i] == 1 ? 1.0 : -1.0) * grad[i] / std::sqrt(std::max(H(i, i), 1e-300));
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

}  // namespace

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

namespace {

// Per fold, its rows as ranges [begin, end) in order.
std::vector<std::vector<std::pair<int, int>>> RangesOf(const std::vector<int>& fold, int K) {
  std::vector<std::vector<std::pair<int, int>>> out(K);
  for (int i = 0; i < static_cast<int>(fold.size()); ++i) {
    auto& r = out[fold[i]];
    if (!r.empty() && r.back().second == i)
      r.back().second = i + 1;
    else
      r.push_back({i, i + 1});
  }
  return out;
}

}  // namespace

// Rows with their covariates, the starting registration and tool, the folds.
Problem MakeProblem(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o, const Problem* frozen) {
  Problem pb;
  pb.robot = &robot;
  const int K = log.NumPoints();
  pb.six = log.six_dof() || K >= 3;
  pb.m = pb.six ? 6 : 3;
  pb.ts = pb.six ? 6 : 3;
  pb.tool0 = robot.T_flange_tool();
  pb.N = log.rows.size();
  pb.n = robot.NumJoints();
  const int N = pb.N, n = pb.n;
  const double t0 = log.rows.front().time_s;
  pb.time_span = std::max(1.0, log.rows.back().time_s - t0);
  // K >= 3 points of a rigid body: each row measures the body's pose; the body's frame is
  // the tool (its shape from the fitted log when frozen).
  std::vector<Pose> body_pose;
  if (K >= 3) {
    if (frozen) {
      pb.body_points = frozen->body_points;
      if (static_cast<int>(pb.body_points.size()) != K)
        Throw(log.source.string(), ": ", K, " points per row, but the fitted log's body has ", pb.body_points.size());
      body_pose = RigidBodyPoses(log, pb.body_points).T_meas_body;
    } else {
      const RigidBody body = FitRigidBody(log);
      pb.body_points = body.points_body;
      body_pose = body.T_meas_body;
    }
  }
  Eigen::VectorXd dir = Eigen::VectorXd::Zero(n);
  const bool masses = robot.HasMasses();
  // A move is a change beyond the encoders' jitter, measured from where the joint last
  // stood (jitter never flips the direction of the last move).
  const Eigen::VectorXd jitter = JitterTolerance(robot, o.repeat_tolerance);
  Eigen::VectorXd at = log.rows.front().q;
  const std::vector<Pose> tilt = MeasuredTiltCorrections(robot, log);
  for (int i = 0; i < N; ++i) {
    const RobotMeasurement& lr = log.rows[i];
    RowData r;
    r.q = lr.q;
    if (!tilt.empty()) r.tilt = tilt[i];
    r.p = lr.p_meas;
    if (lr.R_meas_tool) r.R = *lr.R_meas_tool;
    if (K >= 3) r.p = body_pose[i].t, r.R = body_pose[i].R;
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
    const double payload = log.has_payload ? lr.payload_kg.value_or(0.0) : 0.0;
    r.c.gravity_torque = masses ? GravityTorque(robot, lr.q, payload)
                                : Eigen::VectorXd(GravityTorquePerKg(robot, lr.q) * (log.has_payload ? payload : 1.0));
    r.c.gravity_lever = GravityLever(robot, lr.q);
    if (log.has_payload) r.c.gravity_lever.col(2 * n) *= payload;
    if (lr.qdot.size() == n) r.c.joint_velocity = lr.qdot;
    pb.rows.push_back(r);
    pb.payload = payload;
    pb.payload_factor = log.has_payload ? payload : 1.0;
  }
  // Starting registration and tool.
  const auto ChordalMean = [](const std::vector<Pose>& T) {
    Mat3 M = Mat3::Zero();
    Vec3 t = Vec3::Zero();
    for (const Pose& p : T) M += p.R, t += p.t;
    Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Mat3 S = Mat3::Identity();
    if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) S(2, 2) = -1;
    return Pose{svd.matrixU() * S * svd.matrixV().transpose(), t / static_cast<double>(T.size())};
  };
  // Stations: the rows' placements (a frozen model is scored with the fitted log's first;
  // model/robot_validation.h places another session's stations anew).
  if (!frozen && log.has_stations) {
    pb.station_names = log.Stations();
    pb.S = static_cast<int>(pb.station_names.size());
    for (int i = 0; i < N; ++i)
      pb.rows[i].station = static_cast<int>(
          std::find(pb.station_names.begin(), pb.station_names.end(), log.rows[i].station) - pb.station_names.begin());
  } else {
    pb.station_names = {""};
  }
  // Starting registration per station, and the tool.
  const auto StationStart = [&](int st) -> Pose {
    std::vector<int> rows;
    for (int i = 0; i < N; ++i)
      if (pb.rows[i].station == st) rows.push_back(i);
    if (pb.six && K < 3) {
      // Average of T_meas_tool T_base_tool^-1 over the rows (chordal mean of the rotations).
      std::vector<Pose> T;
      for (int i : rows)
        T.push_back(Pose{*log.rows[i].R_meas_tool, log.rows[i].p_meas} * robot.T_base_tool(log.rows[i].q).Inverse());
      return ChordalMean(T);
    }
    std::vector<RobotMeasurement> ms(rows.size());
    for (size_t k = 0; k < rows.size(); ++k) {
      ms[k].q = log.rows[rows[k]].q;
      ms[k].p_meas = pb.rows[rows[k]].p;
    }
    try {
      return InitialBaseGuess(robot, ms);
    } catch (const InputError& e) {
      if (pb.S == 1) throw;
      Throw(log.source.string(), ": station '", pb.station_names[st], "' (", rows.size(),
            " rows) cannot be placed in the instrument's frame: ", e.what());
    }
  };
  if (frozen) {
    pb.base0 = frozen->base0;
    pb.tool0 = frozen->tool0;
    pb.station0 = {pb.base0};
  } else {
    for (int st = 0; st < pb.S; ++st)
      pb.station0.push_back(st == 0 && o.base_guess ? *o.base_guess : StationStart(st));
    pb.base0 = pb.station0[0];
  }
  if (K >= 3 && !frozen) {
    // The body's pose on the flange: the mean of (T_meas_base T_base_flange)^-1 T_meas_body.
    std::vector<Pose> T;
    for (int i = 0; i < N; ++i)
      T.push_back((pb.station0[pb.rows[i].station] * robot.T_base_flange(log.rows[i].q)).Inverse() * body_pose[i]);
    pb.tool0 = ChordalMean(T);
  }
  // Folds: contiguous blocks of time within each station (a station's registration is
  // fitted on its other blocks).
  pb.K = std::max(2, std::min(o.folds, N / 4));
  {
    std::vector<int> count(pb.S, 0), seen(pb.S, 0), fold(N);
    for (const RowData& r : pb.rows) ++count[r.station];
    for (int i = 0; i < N; ++i) {
      const int st = pb.rows[i].station;
      fold[i] = TimeBlockFold(seen[st]++, count[st], pb.K);
    }
    pb.fold_rows = RangesOf(fold, pb.K);
  }
  // Blocks of joint space: per station, K clusters of its postures (k-means, the joints
  // scaled by their spread over the log; seeded by farthest-first from the station's first
  // row; deterministic), ordered by their first row.
  {
    Eigen::VectorXd scale = Eigen::VectorXd::Ones(n);
    for (int j = 0; j < n; ++j) {
      double s1 = 0, s2 = 0;
      for (const RowData& r : pb.rows) s1 += r.q[j], s2 += r.q[j] * r.q[j];
      const double var = s2 / N - (s1 / N) * (s1 / N);
      scale[j] = var > 1e-18 ? 1.0 / std::sqrt(var) : 0.0;
    }
    std::vector<int> fold(N, 0);
    for (int st = 0; st < pb.S; ++st) {
      std::vector<int> rows;
      for (int i = 0; i < N; ++i)
        if (pb.rows[i].station == st) rows.push_back(i);
      const int k = std::min<int>(pb.K, rows.size());
      const auto X = [&](int i) { return Eigen::VectorXd(pb.rows[i].q.cwiseProduct(scale)); };
      std::vector<Eigen::VectorXd> c{X(rows.front())};
      while (static_cast<int>(c.size()) < k) {
        int far = rows.front();
        double fd = -1;
        for (int i : rows) {
          double d = kInf;
          for (const auto& ci : c) d = std::min(d, (X(i) - ci).squaredNorm());
          if (d > fd) fd = d, far = i;
        }
        c.push_back(X(far));
      }
      std::vector<int> label(rows.size(), 0);
      for (int it = 0; it < 30; ++it) {
        for (size_t r = 0; r < rows.size(); ++r) {
          double best = kInf;
          for (int ci = 0; ci < k; ++ci) {
            const double d = (X(rows[r]) - c[ci]).squaredNorm();
            if (d < best) best = d, label[r] = ci;
          }
        }
        std::vector<Eigen::VectorXd> sum(k, Eigen::VectorXd::Zero(n));
        std::vector<int> cnt(k, 0);
        for (size_t r = 0; r < rows.size(); ++r) sum[label[r]] += X(rows[r]), ++cnt[label[r]];
        for (int ci = 0; ci < k; ++ci)
          if (cnt[ci]) c[ci] = sum[ci] / cnt[ci];
      }
      // Fold of each cluster: in order of its first row.
      std::vector<int> order(k, -1);
      int next = 0;
      for (size_t r = 0; r < rows.size(); ++r)
        if (order[label[r]] < 0) order[label[r]] = next++;
      for (size_t r = 0; r < rows.size(); ++r) fold[rows[r]] = order[label[r]];
    }
    pb.posture_rows = RangesOf(fold, pb.K);
  }
  if (frozen) {
    pb.blocks = frozen->blocks;
    pb.offset = frozen->offset;
    pb.P = frozen->P;
    pb.lower = frozen->lower;
    pb.upper = frozen->upper;
    pb.geometry = frozen->geometry;
    pb.warmup = frozen->warmup;
    pb.theta0 = frozen->theta0;
    pb.reg_extra = frozen->reg_extra;
  }
  return pb;
}

void RowResidual(const Problem& pb, const RowData& row, const double* theta, double* e) {
  RowResidualT<double>(pb, row, theta, e);
}

Pose PredictedTool(const Problem& pb, const RowData& row, const Eigen::VectorXd& theta) {
  std::vector<const double*> ptr(pb.blocks.size());
  for (size_t k = 0; k < pb.blocks.size(); ++k) ptr[k] = theta.data() + pb.offset[k];
  const PoseT<double> X = PredictPoseT<double>(pb, row, theta.data() + pb.RegOffset(row.station),
                                               theta.data() + 6, pb.blocks, ptr.data());
  return Pose{X.R, X.t};
}

RowSet AllRows(const Problem& pb) {
  return RowSet{{{0, pb.N}}, -1, false};
}
RowSet TestRows(const Problem& pb, int f, bool posture) {
  return RowSet{posture ? pb.posture_rows[f] : pb.fold_rows[f], f, false, posture};
}
RowSet TrainRows(const Problem& pb, int f, bool posture) {
  RowSet s{{}, f, true, posture};
  int at = 0;
  for (const auto& [b, e] : posture ? pb.posture_rows[f] : pb.fold_rows[f]) {
    if (b > at) s.ranges.push_back({at, b});
    at = e;
  }
  if (at < pb.N) s.ranges.push_back({at, pb.N});
  return s;
}

std::vector<int> Problem::BaseParams() const {
  std::vector<int> b(NumBase());
  std::iota(b.begin(), b.end(), 0);
  for (int s = 1; s < S; ++s)
    for (int k = 0; k < 6; ++k) b.push_back(RegOffset(s) + k);
  return b;
}

// Exact (nonlinear) residuals of the rows of `set` at theta into R (N x m).
void Exact(const Problem& pb, const Eigen::VectorXd& th, const RowSet& set, Eigen::MatrixXd* R) {
  if (R->rows() != pb.N || R->cols() != pb.m) R->setZero(pb.N, pb.m);
  double e[6];
  const std::vector<char> active = ActiveBlocks(pb, th, nullptr);
  for (const auto& [b, en] : set.ranges)
    for (int i = b; i < en; ++i) {
      RowResidualT<double>(pb, pb.rows[i], th.data(), e, &active);
      for (int a = 0; a < pb.m; ++a) (*R)(i, a) = e[a];
    }
}

// The Jacobian of every row with respect to every parameter at theta0, and the Gram
// matrices of each fold.
void Linearize(Problem* pb, const Eigen::VectorXd* at) {
  const int P = pb->P, m = pb->m;
  const Eigen::VectorXd& point = at ? *at : pb->theta0;
  if (pb->S > 1) {
    // Stations: each row's own registration by its 6 jets, the chain's parameters by jets.
    std::vector<int> all(P);
    std::iota(all.begin(), all.end(), 0);
    pb->J = FreeJacobian(*pb, all, point, AllRows(*pb));
  } else {
    pb->J.assign(m, Eigen::MatrixXd(pb->N, P));
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Ji(m, P);
    double e[6];
    const double* params[1] = {point.data()};
    double* jac[1] = {Ji.data()};
    for (int i = 0; i < pb->N; ++i) {
      ceres::DynamicAutoDiffCostFunction<AllParamsResidual, 16> cost(new AllParamsResidual{pb, &pb->rows[i]});
      cost.AddParameterBlock(P);
      cost.SetNumResiduals(m);
      cost.Evaluate(params, e, jac);
      for (int a = 0; a < m; ++a) pb->J[a].row(i) = Ji.row(a);
    }
  }
  GrowthDirection(pb);
  pb->Gall.assign(m * m, Eigen::MatrixXd::Zero(P, P));
  const auto Grams = [&](const std::vector<std::vector<std::pair<int, int>>>& folds,
                         std::vector<std::vector<Eigen::MatrixXd>>* out, bool sum) {
    out->assign(folds.size(), std::vector<Eigen::MatrixXd>(m * m));
    for (size_t f = 0; f < folds.size(); ++f)
      for (int a = 0; a < m; ++a)
        for (int c = a; c < m; ++c) {
          Eigen::MatrixXd g = Eigen::MatrixXd::Zero(P, P);
          for (const auto& [b, e] : folds[f])
            g.noalias() += pb->J[a].middleRows(b, e - b).transpose() * pb->J[c].middleRows(b, e - b);
          (*out)[f][a * m + c] = g;
          if (c != a) (*out)[f][c * m + a] = g.transpose();
          if (sum) {
            pb->Gall[a * m + c] += g;
            if (c != a) pb->Gall[c * m + a] += g.transpose();
          }
        }
  };
  Grams(pb->fold_rows, &pb->G, true);
  Grams(pb->posture_rows, &pb->posture_G, false);
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

Columns::Columns(const Problem& p, const std::vector<int>& f, const Eigen::VectorXd& th) : pb(p), F(f) {
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
Eigen::MatrixXd Columns::Normal(const RowSet& set, const Eigen::MatrixXd& W) const {
    const int m = pb.m, nf = F.size();
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(nf, nf);
    Eigen::MatrixXd Hs = Eigen::MatrixXd::Zero(stat.size(), stat.size());
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b) {
        const double w = W(a, b);
        if (w == 0) continue;
        const auto& G = set.posture ? pb.posture_G : pb.G;
        if (set.fold < 0) {
          Hs += w * pb.Gall[a * m + b](stat_idx, stat_idx);
        } else if (set.train) {
          Hs += w * (pb.Gall[a * m + b](stat_idx, stat_idx) - G[set.fold][a * m + b](stat_idx, stat_idx));
        } else {
          Hs += w * G[set.fold][a * m + b](stat_idx, stat_idx);
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
Eigen::VectorXd Columns::Gradient(const RowSet& set, const Eigen::MatrixXd& W, const Eigen::MatrixXd& R) const {
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
void Columns::Apply(const RowSet& set, const Eigen::VectorXd& d, Eigen::MatrixXd* R) const {
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


namespace {

// Iterated generalized least squares on the rows of `set`: theta(F) and the noise
// covariance S, with R (N x m) the current residuals of those rows, kept up to date.
void SolveLinear(const Problem& pb, const RowSet& set, const std::vector<int>& F, Eigen::VectorXd* theta,
                 Eigen::MatrixXd* R, Eigen::MatrixXd* S, std::vector<char>* at_bound) {
  const Columns cols(pb, F, *theta);
  Eigen::VectorXd lower(F.size());
  Eigen::VectorXd upper(F.size());
  for (size_t k = 0; k < F.size(); ++k) lower[k] = pb.lower[F[k]], upper[k] = pb.upper[F[k]];
  double last = LogDet(*S);
  for (int it = 0; it < 60; ++it) {
    const Eigen::MatrixXd W = S->inverse();
    const Eigen::MatrixXd H = cols.Normal(set, W);
    const Eigen::VectorXd g = cols.Gradient(set, W, *R);
    const Eigen::VectorXd x = (*theta)(F);
    const Eigen::VectorXd d = BoundedStep(H, g, x, lower, upper, at_bound);
    for (size_t k = 0; k < F.size(); ++k) (*theta)[F[k]] += d[k];
    cols.Apply(set, d, R);
    *S = MlCovariance(*R, set);
    const double ld = LogDet(*S);
    const double step = d.dot(H * d);
    if (std::abs(ld - last) < 1e-10 && step < 1e-10) break;
    last = ld;
  }
}

}  // namespace

namespace {

// The residuals' Jacobian with respect to the free parameters F at theta (Ceres jets, the
// exact model): per residual component a, N x |F|.
struct FreeParamsResidual {
  const Problem* pb;
  const RowData* row;
  const Eigen::VectorXd* theta;
  const std::vector<int>* F;
  const std::vector<char>* active;
  template <typename T>
  bool operator()(T const* const* p, T* e) const {
    std::vector<T> th(pb->P);
    for (int k = 0; k < pb->P; ++k) th[k] = T((*theta)[k]);
    for (size_t k = 0; k < F->size(); ++k) th[(*F)[k]] = p[0][k];
    RowResidualT<T>(*pb, *row, th.data(), e, active);
    return true;
  }
};

std::vector<Eigen::MatrixXd> FreeJacobian(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& theta,
                                          const RowSet& set) {
  const int nf = static_cast<int>(F.size()), m = pb.m;
  std::vector<Eigen::MatrixXd> J(m, Eigen::MatrixXd::Zero(pb.N, nf));
  // The other stations' registrations act after the chain: their columns from the row's
  // own registration alone (a pass of 6 jets), the rest by jets over the chain.
  std::vector<int> chain, chain_pos;
  std::vector<std::array<int, 6>> reg_pos(pb.S);
  for (auto& r : reg_pos) r.fill(-1);
  for (int k = 0; k < nf; ++k) {
    if (pb.S > 1 && F[k] >= pb.reg_extra) {
      const int st = 1 + (F[k] - pb.reg_extra) / 6;
      reg_pos[st][(F[k] - pb.reg_extra) % 6] = k;
    } else {
      chain.push_back(F[k]);
      chain_pos.push_back(k);
    }
  }
  const int nc = static_cast<int>(chain.size());
  Eigen::VectorXd x = theta(chain);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Ji(m, std::max(1, nc)), Jr(m, 6);
  double e[6];
  const double* params[1] = {x.data()};
  double* jac[1] = {Ji.data()};
  const std::vector<char> active = ActiveBlocks(pb, theta, &F);
  std::vector<const double*> ptr(pb.blocks.size());
  for (const auto& [b, en] : set.ranges)
    for (int i = b; i < en; ++i) {
      const RowData& row = pb.rows[i];
      if (nc > 0) {
        ceres::DynamicAutoDiffCostFunction<FreeParamsResidual, 16> cost(
            new FreeParamsResidual{&pb, &row, &theta, &chain, &active});
        cost.AddParameterBlock(nc);
        cost.SetNumResiduals(m);
        cost.Evaluate(params, e, jac);
        for (int k = 0; k < nc; ++k)
          for (int a = 0; a < m; ++a) J[a](i, chain_pos[k]) = Ji(a, k);
      }
      if (row.station > 0 && reg_pos[row.station][0] + reg_pos[row.station][5] > -2) {
        std::vector<Extension> ext;
        std::vector<const double*> bp;
        for (size_t k = 0; k < pb.blocks.size(); ++k)
          if (active[k]) ext.push_back(pb.blocks[k]), bp.push_back(theta.data() + pb.offset[k]);
        auto* f = new RegistrationResidual{&pb, &row, ToolInBaseT<double>(pb, row, theta.data() + 6, ext, bp.data())};
        ceres::DynamicAutoDiffCostFunction<RegistrationResidual, 6> cost(f);
        cost.AddParameterBlock(6);
        cost.SetNumResiduals(m);
        const double* b6[1] = {theta.data() + pb.RegOffset(row.station)};
        double* j6[1] = {Jr.data()};
        cost.Evaluate(b6, e, j6);
        for (int c = 0; c < 6; ++c)
          if (reg_pos[row.station][c] >= 0)
            for (int a = 0; a < m; ++a) J[a](i, reg_pos[row.station][c]) = Jr(a, c);
      }
    }
  return J;
}

// The normal matrix sum_ab W_ab J_a^T J_b of the rows of `set` (J zero elsewhere).
Eigen::MatrixXd NormalOf(const std::vector<Eigen::MatrixXd>& J, const Eigen::MatrixXd& W) {
  const int nf = J.empty() ? 0 : static_cast<int>(J[0].cols());
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(nf, nf);
  for (size_t a = 0; a < J.size(); ++a)
    for (size_t b = 0; b < J.size(); ++b)
      if (W(a, b) != 0) H.noalias() += W(a, b) * J[a].transpose() * J[b];
  return H;
}

// The profiled log-likelihood of the exact residuals of the rows of `set` at theta: R, the
// noise's ML estimate S and the per-row values.
double ExactProfiled(const Problem& pb, const Eigen::VectorXd& theta, const RowSet& set, Eigen::MatrixXd* R,
                     Eigen::MatrixXd* S, Eigen::VectorXd* row_ll) {
  Exact(pb, theta, set, R);
  *S = MlCovariance(*R, set);
  return RowLogLik(*R, *S, set, row_ll);
}

// Levenberg-Marquardt on the exact model over the rows of `set`, its Jacobian taken anew at
// every iterate, a step taken only where the profiled log-likelihood rises (so never below
// where it starts), within the physical bounds; the noise re-estimated after every step.
// Used where the one Jacobian of the nominal fit does not carry a fit to convergence (a
// geometry far from the nominal's, nearly dependent parameters, a long lever that makes
// the curvature matter).
FitResult NonlinearFit(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start, const RowSet& set) {
  FitResult f;
  f.free = F;
  f.theta = start;
  f.nonlinear = true;
  Eigen::MatrixXd S;
  f.loglik = ExactProfiled(pb, f.theta, set, &f.R, &S, &f.row_ll);
  const int nf = static_cast<int>(F.size());
  Eigen::VectorXd lower(nf), upper(nf);
  for (int k = 0; k < nf; ++k) lower[k] = pb.lower[F[k]], upper[k] = pb.upper[F[k]];
  // The Jacobian is taken anew only when a step with the one in hand fails (a stale one
  // still points uphill near the solution; each new one costs a pass of jets over the rows).
  double lambda = 1e-6;
  // The first Jacobian is the problem's one (its columns F; the warm-up's at the current
  // time constant): no pass of jets until a step with it fails.
  std::vector<Eigen::MatrixXd> J(pb.m, Eigen::MatrixXd::Zero(pb.N, nf));
  {
    const Columns cols(pb, F, f.theta);
    for (const auto& [b, e] : set.ranges)
      for (int a = 0; a < pb.m; ++a) {
        for (size_t k = 0; k < cols.stat.size(); ++k)
          J[a].col(cols.stat[k]).segment(b, e - b) = pb.J[a].col(cols.stat_idx[k]).segment(b, e - b);
        if (cols.dyn >= 0) J[a].col(cols.dyn).segment(b, e - b) = cols.c.col(a).segment(b, e - b);
      }
  }
  bool need = false, at_current = false;
  for (int it = 0; it < 200 && lambda < 1e12; ++it) {
    if (need) J = FreeJacobian(pb, F, f.theta, set), at_current = true, need = false;
    const Eigen::MatrixXd W = S.inverse();
    const Eigen::MatrixXd H = NormalOf(J, W);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(nf);
    const Eigen::MatrixXd RW = f.R * W;
    for (int a = 0; a < pb.m; ++a) g.noalias() += J[a].transpose() * RW.col(a);
    const Eigen::VectorXd x = f.theta(F);
    Eigen::MatrixXd Hd = H;
    Hd.diagonal() += lambda * H.diagonal().cwiseMax(1e-300);
    std::vector<char> ab;
    const Eigen::VectorXd d = BoundedStep(Hd, g, x, lower, upper, &ab);
    Eigen::VectorXd th = f.theta;
    for (int k = 0; k < nf; ++k) th[F[k]] = std::clamp(x[k] + d[k], lower[k], upper[k]);
    Eigen::MatrixXd R2, S2;
    Eigen::VectorXd ll2;
    const double l = ExactProfiled(pb, th, set, &R2, &S2, &ll2);
    if (l > f.loglik) {
      const double gain = l - f.loglik;
      f.theta = th, f.R = R2, S = S2, f.row_ll = ll2, f.loglik = l, f.at_bound = ab;
      lambda = std::max(1e-9, lambda / 10);
      const bool was_current = at_current;
      at_current = false;
      if (gain < 1e-8 * std::max(1.0, std::abs(f.loglik))) {
        if (was_current) break;  // converged on a Jacobian taken where the step began
        need = true;
      }
    } else if (!at_current && lambda >= 1e-2) {
      need = true;  // a stale Jacobian failed even damped: take it anew
      lambda = 1e-6;
    } else {
      lambda *= 10;
    }
  }
  f.noise = S;
  // Covariance of the parameters not at a bound, from the Jacobian at the solution.
  const Eigen::MatrixXd H = NormalOf(FreeJacobian(pb, F, f.theta, set), S.inverse());
  std::vector<int> in;
  for (int k = 0; k < nf; ++k)
    if (f.at_bound.empty() || !f.at_bound[k]) in.push_back(k);
  f.cov = Eigen::MatrixXd::Zero(nf, nf);
  if (!in.empty()) f.cov(in, in) = InverseScaled(H(in, in));
  return f;
}

}  // namespace

// The fit of the model whose free parameters are F, on the rows of `set` (all rows by
// default), from `start`: iterated generalized least squares on the one Jacobian of the
// nominal fit, the exact residuals re-evaluated until they agree; where that does not
// converge, or ends below the start (a model with more free parameters never fits worse
// than the one it extends, and `start` is that model's solution), Levenberg-Marquardt on
// the exact model from the better of the two (NonlinearFit).
FitResult FitModel(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start,
                   const Eigen::MatrixXd& noise_start, const RowSet* rows) {
  const RowSet set = rows ? *rows : AllRows(pb);
  FitResult f;
  f.free = F;
  f.theta = start;
  Eigen::MatrixXd S0;
  Eigen::VectorXd ll0;
  const double start_loglik = ExactProfiled(pb, start, set, &f.R, &S0, &ll0);
  Eigen::MatrixXd S = noise_start;
  bool converged = false;
  // The chord iterations: each pass a linear solve on the one Jacobian from the exact
  // residuals; on while each pass raises the exact log-likelihood (they converge linearly,
  // at a rate that the Jacobian's change over the step sets).
  double last = start_loglik;
  for (int pass = 0; pass < 30; ++pass) {
    const Eigen::VectorXd before = f.theta;
    const Eigen::MatrixXd R_before = f.R, S_before = S;
    const std::vector<char> ab_before = f.at_bound;
    SolveLinear(pb, set, F, &f.theta, &f.R, &S, &f.at_bound);
    Eigen::MatrixXd Rex = f.R;
    Exact(pb, f.theta, set, &Rex);
    const Eigen::MatrixXd Li = WhiteningOf(S);
    double change = 0.0;
    for (const auto& [b, e] : set.ranges)
      if (e > b)
        change = std::max(change, ((Rex.middleRows(b, e - b) - f.R.middleRows(b, e - b)) * Li.transpose())
                                      .cwiseAbs()
                                      .maxCoeff());
    f.R = Rex;
    S = MlCovariance(f.R, set);
    const double ll = RowLogLik(f.R, S, set, &f.row_ll);
    if (!(ll >= last - 1e-9 * std::max(1.0, std::abs(last)))) {
      // Diverging: back to the pass before, for the exact solver to carry on from.
      f.theta = before, f.R = R_before, S = S_before, f.at_bound = ab_before;
      break;
    }
    last = ll;
    if (change < 1e-4) {
      converged = true;
      break;
    }
  }
  f.noise = S;
  f.loglik = RowLogLik(f.R, S, set, &f.row_ll);
  const double tol = 1e-9 * std::max(1.0, std::abs(start_loglik));
  if (!converged || !(f.loglik >= start_loglik - tol)) {
    const bool from_chord = f.loglik > start_loglik && f.R.allFinite();
    return NonlinearFit(pb, F, from_chord ? f.theta : start, set);
  }
  // Covariance of the parameters not at a bound.
  const Columns cols(pb, F, f.theta);
  const Eigen::MatrixXd H = cols.Normal(set, S.inverse());
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
HeldOut CrossValidate(const Problem& pb, const FitResult& all_fit, const Eigen::MatrixXd& metric, bool posture) {
  HeldOut h;
  h.row_ll.setZero(pb.N);
  double sum_sq = 0;
  const int K = static_cast<int>(posture ? pb.posture_rows.size() : pb.fold_rows.size());
  for (int f = 0; f < K; ++f) {
    const RowSet train = TrainRows(pb, f, posture), test = TestRows(pb, f, posture);
    const FitResult fold = FitModel(pb, all_fit.free, all_fit.theta, all_fit.noise, &train);
    Eigen::MatrixXd Rt;
    Exact(pb, fold.theta, test, &Rt);
    h.loglik += RowLogLik(Rt, metric, test, &h.row_ll);
    for (const auto& [b, e] : test.ranges) sum_sq += Rt.middleRows(b, e - b).leftCols(3).squaredNorm();
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

// The fit of the model whose free parameters are F, from `start`; with the warm-up's
// growth free, its time constant by the profile likelihood (a grid in log time, refined by
// a parabola through the best and its neighbours), with its standard deviation in
// *tau_sigma.
FitResult FitProfiled(const Problem& pb, const std::vector<int>& F, const Eigen::VectorXd& start,
                      const Eigen::MatrixXd& noise, double* tau_sigma) {
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
  std::vector<std::vector<double>> b(pb->S, std::vector<double>(6, 0.0));
  std::vector<double> tl(pb->ts, 0.0);
  auto Linv = std::make_shared<Eigen::MatrixXd>(Eigen::MatrixXd::Identity(pb->m, pb->m) * 1e4);
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  for (const RowData& r : pb->rows) {
    auto* cost = new ceres::DynamicAutoDiffCostFunction<NominalResidual, 16>(new NominalResidual{pb, &r, Linv.get()});
    cost->AddParameterBlock(6);
    cost->AddParameterBlock(pb->ts);
    cost->SetNumResiduals(pb->m);
    problem.AddResidualBlock(cost, nullptr, b[r.station].data(), tl.data());
  }
  ceres::Solver::Options so;
  so.linear_solver_type = pb->S > 4 ? ceres::SPARSE_SCHUR : ceres::DENSE_QR;
  if (!ceres::IsSparseLinearAlgebraLibraryTypeAvailable(so.sparse_linear_algebra_library_type))
    so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.num_threads = 1;
  Eigen::MatrixXd S = Eigen::MatrixXd::Identity(pb->m, pb->m) * 1e-8;
  double last = kInf;
  for (int outer = 0; outer < 8; ++outer) {
    ceres::Solver::Summary sum;
    ceres::Solve(so, &problem, &sum);
    Eigen::MatrixXd R(pb->N, pb->m);
    double e[6];
    for (int i = 0; i < pb->N; ++i) {
      PredictT<double>(*pb, pb->rows[i], b[pb->rows[i].station].data(), tl.data(), {}, nullptr, e);
      for (int a = 0; a < pb->m; ++a) R(i, a) = e[a];
    }
    S = MlCovariance(R, AllRows(*pb));
    *Linv = WhiteningOf(S);
    const double ld = LogDet(S);
    if (std::abs(ld - last) < 1e-7) break;
    last = ld;
  }
  for (int st = 0; st < pb->S; ++st)
    for (int k = 0; k < 6; ++k) pb->theta0[pb->RegOffset(st) + k] = b[st][k];
  for (int k = 0; k < pb->ts; ++k) pb->theta0[6 + k] = tl[k];
  return S;
}

// The DH parameters these poses identify with the registration and the tool free
// (calib-robot's analysis: base and tool first, then the joints from the base out), and

}  // namespace mcms::robot_audit
