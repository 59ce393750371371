// The plausibility checks of a robot log (CheckRobotLogPlausible, CheckPositionsMove: a
// mistyped row, duplicated rows, positions in another unit, a body that is not rigid, rows the
// robot cannot reach) and the rigid body its measured points form (FitRigidBody,
// RigidBodyPoses), declared in model/robot_measurements.h; the readers are
// robot_measurements.cpp.
#include "model/robot_measurements.h"
#include "model/robot_measurements_internal.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <numeric>
#include <set>
#include <sstream>

#include <Eigen/Dense>
#include <yaml-cpp/yaml.h>

#include "core/format.h"
#include "core/limits.h"
#include "core/error.h"
#include "core/io.h"
#include "core/statistics.h"
#include "core/yaml.h"
#include "model/tilt_sensor.h"
#include "model/urdf.h"

namespace mcms {

using robot_log_internal::JointName;

// ---- plausibility ------------------------------------------------------------------

namespace {

// A mistyped row: a measured position far outside where the others lie (a coordinate of
// 1e308, one row in millimetres). Robust: distances from the componentwise median,
// against their median; a row beyond 100 times that (and 10 m) is named.
void CheckOutlyingRow(const RobotLog& log) {
  const int N = log.rows.size();
  Vec3 med;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> c(N);
    for (int i = 0; i < N; ++i) c[i] = log.rows[i].p_meas[k];
    med[k] = SelectedMedian(c);
  }
  std::vector<double> d(N);
  for (int i = 0; i < N; ++i) d[i] = (log.rows[i].p_meas - med).norm();
  std::vector<double> sorted = d;
  const double typical = SelectedMedian(sorted);
  for (int i = 0; i < N; ++i)
    if (d[i] > std::max(100.0 * typical, 10.0))
      Throw(log.Where(i), ": the measured position (", Num4(log.rows[i].p_meas.x()), ", ", Num4(log.rows[i].p_meas.y()),
            ", ", Num4(log.rows[i].p_meas.z()), ") m lies ",
            std::isfinite(d[i]) ? Num4(d[i]) + " m" : std::string("absurdly far"),
            " from the log's median position, where the other rows lie within about ", Num4(typical),
            " m: a mistyped row, or another unit than metres?");
}

// The same measurement twice (identical joints and position to the last digit, which two
// real measurements never are) would count it twice and halve its variance.
void CheckDuplicateRows(const RobotLog& log) {
  std::vector<size_t> order(log.rows.size());
  std::iota(order.begin(), order.end(), 0);
  const auto key = [&](size_t i) {
    const RobotMeasurement& r = log.rows[i];
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
    const std::string first = log.Where(a);
    const std::string prefix = log.source.empty() ? std::string("robot log") : log.source.string();
    const bool same_file = first.rfind(prefix + " ", 0) == 0;
    Throw(log.Where(b), " repeats ", same_file ? first.substr(prefix.size() + 1) : first,
          " exactly (the same joints and measured position): a duplicated row would count one measurement "
          "twice; remove the duplicates (repeated visits of a pose measure a new position each time)");
  }
}

// The best similarity from the model's tool positions src to the measured ones dst (3 x N):
// its scale with a rotation, with a rotation or reflection, whether the best is a
// reflection, and (optional) the RMS residual of the rotation's fit relative to the
// measured positions' spread.
void SimilarityScale(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, double* scale, double* scale_any,
                     bool* mirrored, double* relative_rms) {
  const int N = src.cols();
  const Eigen::Matrix3Xd a = src.colwise() - src.rowwise().mean(), b = dst.colwise() - dst.rowwise().mean();
  const double var_src = std::max(a.squaredNorm() / N, 1e-300), var_dst = b.squaredNorm() / N;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(b * a.transpose() / N, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d d(1, 1, 1);
  *mirrored = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0;
  if (*mirrored) d[2] = -1;
  *scale = svd.singularValues().dot(d) / var_src;
  *scale_any = svd.singularValues().sum() / var_src;  // rotation or reflection
  if (relative_rms) {
    // Umeyama: residual variance var_dst - (sum d_k s_k)^2 / var_src.
    const double sd = svd.singularValues().dot(d);
    *relative_rms = std::sqrt(std::max(0.0, var_dst - sd * sd / var_src) / std::max(var_dst, 1e-300));
  }
}

// Measured positions in another unit than metres, a robot description of another size,
// swapped axes, or joints that do not move the tool: the best similarity between the tool
// positions the robot's model gives for the logged joints and the measured ones has a
// scale far from 1 or needs a reflection.
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
            Num4(std::sqrt(var_dst)), " m (RMS): are the joint columns filled, and in the unit their headers give?");
    Throw(src_name,
          ": neither the logged joints nor the measured positions move (every row measures the same "
          "place): measurements spread over the workspace are needed");
  }
  double scale = 0, scale_any = 0;
  bool mirrored = false;
  SimilarityScale(src, dst, &scale, &scale_any, &mirrored, nullptr);
  if (scale > 0.8 && scale < 1.25) return;
  if (mirrored && scale_any > 0.8 && scale_any < 1.25)
    Throw(src_name, ": the measured positions are a mirror image of where robot '", robot.Name(),
          "' puts its tool at the logged joints (a rotation fits them only at scale ", Num4(scale),
          ", a reflection at ", Num4(scale_any),
          "): two of the x, y, z columns swapped, or one axis's sign flipped?");
  // One joint in another unit than its header says (a prismatic joint in mm, radians under
  // a _deg header): the positions fit once that joint's values are rescaled.
  const int n = robot.NumJoints();
  const struct {
    double factor;
    const char* hint;
  } kUnits[] = {{1e-3, "millimetres where metres are read?"},
                {1e3, "metres where millimetres are read?"},
                {180.0 / std::numbers::pi, "radians under a _deg header?"},
                {std::numbers::pi / 180.0, "degrees where radians are read?"}};
  for (int j = 0; j < n; ++j)
    for (const auto& u : kUnits) {
      Eigen::Matrix3Xd s2(3, N);
      bool inside = true;  // a reading rescaled beyond the joint's range is not what was meant
      for (int i = 0; i < N && inside; ++i) {
        Eigen::VectorXd q = log.rows[i].q;
        q[j] *= u.factor;
        inside = robot.WithinLimits(q, nullptr);  // the forward kinematics' own (strict) test
        if (inside) s2.col(i) = robot.T_base_tool(q).t;
      }
      if (!inside) continue;
      double sc = 0, sc_any = 0, rel = 1;
      bool mir = false;
      SimilarityScale(s2, dst, &sc, &sc_any, &mir, &rel);
      if (sc > 0.8 && sc < 1.25 && rel < 0.05)
        Throw(src_name, ": the measured positions fit robot '", robot.Name(), "' once joint ", JointName(robot, j),
              "'s logged values are taken ", Num4(u.factor), " times as large (", u.hint,
              "); give each joint in the unit its column's header says");
    }
  const std::string unit = LengthUnitHint(scale);
  Throw(src_name, ": the measured positions are ", Num4(scale), " times as far apart as robot '", robot.Name(),
        "' puts its tool at the logged joints", unit,
        "; give the positions in metres, and the robot description the log was measured with (--robot)");
}

// Points of one rigid body keep their mutual distances: per pair, each row's distance
// against the median over the rows; a row off by more than 1 mm and 10 times the pairs'
// robust scatter is named.
void CheckRigid(const RobotLog& log) {
  const int K = log.NumPoints(), N = log.rows.size();
  if (K < 2) return;
  std::vector<std::string> bad;
  double worst = 0;
  std::vector<double> dev_row(N, 0.0);
  std::vector<double> all_dev;
  for (int a = 0; a < K; ++a)
    for (int b = a + 1; b < K; ++b) {
      std::vector<double> d(N);
      for (int i = 0; i < N; ++i) d[i] = (log.rows[i].Point(a) - log.rows[i].Point(b)).norm();
      std::vector<double> s = d;
      const double med = SelectedMedian(s);
      for (int i = 0; i < N; ++i) {
        dev_row[i] = std::max(dev_row[i], std::abs(d[i] - med));
        all_dev.push_back(std::abs(d[i] - med));
      }
    }
  const double mad = SelectedMedian(all_dev);
  const double limit = std::max(1e-3, 10.0 * 1.4826 * mad);
  for (int i = 0; i < N; ++i)
    if (dev_row[i] > limit) {
      if (bad.size() < 8) bad.push_back(std::to_string(log.rows[i].line > 0 ? log.rows[i].line : i + 1));
      worst = std::max(worst, dev_row[i]);
    }
  if (bad.empty()) return;
  std::string rows;
  for (size_t k = 0; k < bad.size(); ++k) rows += (k ? ", " : "") + bad[k];
  Throw(log.source.empty() ? std::string("robot log") : log.source.string(), ": the ", K,
        " points are not one rigid body: their mutual distances change by up to ", Num4(worst * 1e3), " mm on ",
        log.rows.front().line > 0 ? "line" : "row", bad.size() > 1 ? "s " : " ", rows,
        " (elsewhere within ", Num4(limit * 1e3), " mm); a marker lost or swapped, or points of different bodies?");
}

void CheckRowsFitTheRobot(const RobotModel& robot, const RobotLog& log);  // below

}  // namespace

// Measured positions that never move while the joints move the tool (a position column
// filled once and copied down): named before the rows are compared with each other.
void CheckPositionsMove(const RobotModel& robot, const RobotLog& log) {
  for (const std::string& st : log.Stations()) {
    std::vector<Vec3> tool, meas;
    for (const auto& r : log.rows)
      if (r.station == st) tool.push_back(robot.T_base_tool(r.q).t), meas.push_back(r.p_meas);
    if (meas.size() < 2) continue;
    double spread_meas = 0, spread_tool = 0;
    for (size_t i = 1; i < meas.size(); ++i) {
      spread_meas = std::max(spread_meas, (meas[i] - meas[0]).norm());
      spread_tool = std::max(spread_tool, (tool[i] - tool[0]).norm());
    }
    if (spread_meas < 1e-6 && spread_tool > 1e-4)
      Throw(log.source.empty() ? std::string("robot log") : log.source.string(),
            st.empty() ? std::string() : std::string(" station ").append(st),
            ": the measured positions do not move (every row measures the same point within 1 um) while the "
            "logged joints move the tool over ",
            Num4(spread_tool), " m: are the position columns filled per row?");
  }
}

void CheckRobotLogPlausible(const RobotLog& log, const RobotModel& robot) {
  CheckRobotLog(log, robot);
  CheckPositionsMove(robot, log);
  CheckDuplicateRows(log);
  CheckRigid(log);
  // The checks against one placement of the instrument: per station where the log has them.
  const std::vector<std::string> stations = log.Stations();
  for (const std::string& st : stations) {
    RobotLog part;
    const RobotLog* one = &log;
    if (stations.size() > 1) {
      part = log;
      part.rows.clear();
      for (const auto& r : log.rows)
        if (r.station == st) part.rows.push_back(r);
      if (part.rows.size() < 4) continue;  // too few to test; placing it names it
      one = &part;
    }
    CheckOutlyingRow(*one);
    CheckScale(robot, *one);
    CheckRowsFitTheRobot(robot, *one);
  }
}

namespace {

Eigen::Matrix3Xd PointsOfRow(const RobotLog& log, int i) {
  const int K = log.rows[i].NumPoints();
  Eigen::Matrix3Xd P(3, K);
  for (int k = 0; k < K; ++k) P.col(k) = log.rows[i].Point(k);
  return P;
}

// Kabsch: the pose mapping `ref` (body frame) onto `P` (meas frame), least squares.
Pose Align(const Eigen::Matrix3Xd& ref, const Eigen::Matrix3Xd& P) { return RigidFit(ref, P); }

// Measured orientations (qw, qx, qy, qz) against the robot, once the positions fit: the
// tool's rotation on the flange, (R_meas_base R_base_flange)^T R_meas_tool, is one rotation
// in every row, to a fraction of a degree for any robot its description fits. Spread over
// tens of degrees, they are not the robot's tool orientations: read scalar-last (the same
// four numbers as x, y, z, w), the usual mix-up, is said when that makes them agree.
// The median angle of each row's rotation from their chordal mean is compared with 10 deg.
double MedianSpreadDeg(const std::vector<Mat3>& R) {
  Mat3 sum = Mat3::Zero();
  for (const Mat3& r : R) sum += r;
  Eigen::JacobiSVD<Mat3> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) D(2, 2) = -1;
  const Mat3 mean = svd.matrixU() * D * svd.matrixV().transpose();
  std::vector<double> a;
  for (const Mat3& r : R) a.push_back(Eigen::AngleAxisd(mean.transpose() * r).angle());
  return SelectedMedian(a) * 180 / std::numbers::pi;
}

void CheckOrientationsFitTheRobot(const RobotModel& robot, const RobotLog& log, const std::vector<Pose>& flange,
                                  const Pose& T) {
  std::vector<Mat3> tool, tool_xyzw;
  for (size_t i = 0; i < log.rows.size(); ++i) {
    if (!log.rows[i].R_meas_tool) return;
    const Mat3 to_flange = (T.R * flange[i].R).transpose();
    tool.push_back(to_flange * *log.rows[i].R_meas_tool);
    tool_xyzw.push_back(to_flange * RotationReadScalarLast(Eigen::Quaterniond(*log.rows[i].R_meas_tool)));
  }
  if (tool.size() < 4) return;
  const double spread = MedianSpreadDeg(tool);
  if (!(spread > 10)) return;
  const double spread_xyzw = MedianSpreadDeg(tool_xyzw);
  Throw(log.source.empty() ? std::string("robot log") : log.source.string(), ": the measured orientations (qw, qx, ",
        "qy, qz) do not follow robot '", robot.Name(), "': the tool's rotation on the flange they imply varies by ",
        Num4(spread), " deg (median from its mean) where a robot its description fits keeps it within a degree",
        spread_xyzw < 2 ? "; read scalar-last they agree to " + Num4(spread_xyzw) +
                              " deg: quaternions x, y, z, w under qw, qx, qy, qz? expected qw, qx, qy, qz (scalar first)"
                        : std::string("; are the orientations those of the tool whose positions the log gives?"));
}

// Rows of another layout among the others (x and y exchanged in some rows, a row in
// another unit): once the scale is right, the best rigid registration and tool position
// leave residuals of the size of the motion itself, where any robot the description
// fits (every DH term off, sag, backlash) leaves a few mm. Named when the RMS is beyond
// 10 % of the positions' spread and 20 mm, with the row farthest off.
void CheckRowsFitTheRobot(const RobotModel& robot, const RobotLog& log) {
  const int N = log.rows.size();
  if (N < 4) return;
  // A robot measured while it moves (joint velocities known): a clock offset between the
  // logs, an effect the audit names, misplaces rows by the speed times the offset.
  for (const RobotMeasurement& r : log.rows)
    if (r.qdot.size() > 0) return;
  std::vector<Pose> flange(N);
  Eigen::Matrix3Xd dst(3, N), src(3, N);
  for (int i = 0; i < N; ++i) flange[i] = robot.T_base_flange(log.rows[i].q), dst.col(i) = log.rows[i].p_meas;
  Vec3 tool = robot.T_flange_tool().t;
  Pose T;  // T_meas_base
  for (int round = 0; round < 20; ++round) {  // registration and tool point in turn
    for (int i = 0; i < N; ++i) src.col(i) = flange[i] * tool;
    T = Align(src, dst);
    Vec3 sum = Vec3::Zero();
    for (int i = 0; i < N; ++i) sum += flange[i].R.transpose() * (T.R.transpose() * (dst.col(i) - T.t) - flange[i].t);
    tool = sum / N;
  }
  for (int i = 0; i < N; ++i) src.col(i) = flange[i] * tool;
  T = Align(src, dst);
  double ss = 0, worst = -1;
  int far = 0;
  for (int i = 0; i < N; ++i) {
    const double e = (T * Vec3(src.col(i)) - dst.col(i)).norm();
    ss += e * e;
    if (e > worst) worst = e, far = i;
  }
  const double rms = std::sqrt(ss / N);
  const double spread = std::sqrt((dst.colwise() - dst.rowwise().mean()).squaredNorm() / N);
  if (!(rms > std::max(0.1 * spread, 0.02))) {
    CheckOrientationsFitTheRobot(robot, log, flange, T);
    return;
  }
  Throw(log.source.empty() ? std::string("robot log") : log.source.string(),
        ": with the best registration and tool position, robot '", robot.Name(),
        "' explains the measured positions only to ", Num4(1e3 * rms), " mm RMS while they spread over ",
        Num4(1e3 * spread), " mm (the row farthest off, ", log.Where(far), ", by ", Num4(1e3 * worst),
        " mm); a robot its description fits leaves a few mm: check the rows' columns (x and y swapped in some?) and "
        "units, and --robot");
}

}  // namespace

RigidBody FitRigidBody(const RobotLog& log) {
  const int K = log.NumPoints(), N = log.rows.size();
  if (K < 3) Throw("FitRigidBody: ", K, " points per row; a rigid body's pose needs at least 3");
  // The mean shape over the rows, in the first row's orientation, centred.
  Eigen::Matrix3Xd ref = PointsOfRow(log, 0);
  ref = ref.colwise() - ref.rowwise().mean().eval();
  for (int pass = 0; pass < 3; ++pass) {
    Eigen::Matrix3Xd mean = Eigen::Matrix3Xd::Zero(3, K);
    for (int i = 0; i < N; ++i) {
      const Pose Ti = Align(ref, PointsOfRow(log, i)).Inverse();
      mean += (Ti.R * PointsOfRow(log, i)).colwise() + Ti.t;
    }
    mean /= N;
    const Pose T0 = Align(mean, PointsOfRow(log, 0));
    const Vec3 c0 = PointsOfRow(log, 0).rowwise().mean();
    ref = (T0.R * mean).colwise() + (T0.t - c0);
  }
  std::vector<Vec3> shape;
  for (int k = 0; k < K; ++k) shape.push_back(ref.col(k));
  // Points on one line fix no rotation about it: not a pose.
  Eigen::JacobiSVD<Mat3> svd(Mat3(ref * ref.transpose()));
  if (!(svd.singularValues()[1] > 1e-6 * svd.singularValues()[0]) || !(std::sqrt(svd.singularValues()[1]) > 1e-4))
    Throw(log.source.empty() ? std::string("robot log") : log.source.string(), ": the ", K,
          " points of the rigid body lie on one line (spread ", std::sqrt(std::max(0.0, svd.singularValues()[1])) * 1e3,
          " mm across it); a body's pose needs points spread in two directions (give one point, or points not in a "
          "line)");
  return RigidBodyPoses(log, shape);
}

RigidBody RigidBodyPoses(const RobotLog& log, const std::vector<Vec3>& points_body) {
  const int K = points_body.size();
  Eigen::Matrix3Xd ref(3, K);
  for (int k = 0; k < K; ++k) ref.col(k) = points_body[k];
  RigidBody body;
  body.points_body = points_body;
  for (size_t i = 0; i < log.rows.size(); ++i) {
    if (log.rows[i].NumPoints() != K)
      Throw(log.Where(i), ": ", log.rows[i].NumPoints(), " points, but the rigid body has ", K);
    const Eigen::Matrix3Xd P = PointsOfRow(log, i);
    const Pose T = Align(ref, P);
    body.T_meas_body.push_back(T);
    const Eigen::Matrix3Xd pred = (T.R * ref).colwise() + T.t;
    body.fit_rms_m.push_back(std::sqrt((pred - P).squaredNorm() / K));
  }
  return body;
}

}  // namespace mcms
