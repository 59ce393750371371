// The plots `mcms report` draws of the tables the commands write.
#include "jobs/html_report_internal.h"

#include <Eigen/Cholesky>
#include <numbers>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <system_error>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/output_folder.h"
#include "core/pose_math.h"
#include "core/statistics.h"
#include "core/svg_plot.h"

namespace mcms::html_report_internal {

namespace fs = std::filesystem;
bool IsTrackerPoses(const Table& t) {
  return t.Column("frame") >= 0 && t.Column("time_s") >= 0 && t.Column("status") >= 0 && t.Column("x_m") >= 0;
}

// 95 % two-sided band of a chi-square variable with k degrees of freedom.
std::pair<double, double> ChiSquareBand95(int k) {
  return ChiSquareBand(k, 0.95);
}

// Adds err_x_mm, err_y_mm, err_z_mm, err_rot_mdeg and nees columns to a tracker pose table
// from a truth pose table (frame,x_m,y_m,z_m,qw,qx,qy,qz: T_rig_target, what `mcms render`
// writes to truth/poses.csv), matched by frame. The error is the estimate's against the
// truth (core/statistics.h PoseError: BoxMinus(T_est, T_true), the [dtheta; dp] layout of
// the covariance), NEES = e^T Cov^-1 e (PoseNees). Returns a summary line,
// or the reason nothing was added.
std::string AddTruthColumns(Table& t, const Table& truth) {
  const char* pose_cols[] = {"x_m", "y_m", "z_m", "qw", "qx", "qy", "qz"};
  int tc[7], ec[7];
  for (int i = 0; i < 7; ++i) {
    tc[i] = truth.Column(pose_cols[i]);
    ec[i] = t.Column(pose_cols[i]);
    if (tc[i] < 0) return std::string("the truth file has no ") + pose_cols[i] + " column";
  }
  const int tf = truth.Column("frame"), ef = t.Column("frame");
  if (tf < 0) return "the truth file has no frame column";
  const char* axes[] = {"rx", "ry", "rz", "px", "py", "pz"};
  int cov[6][6];
  bool have_cov = true;
  for (int a = 0; a < 6; ++a)
    for (int b = 0; b < 6; ++b) {
      cov[a][b] = t.Column(std::string("cov_") + axes[a] + "_" + axes[b]);
      have_cov = have_cov && cov[a][b] >= 0;
    }
  // A pose: seven finite values whose quaternion is a unit one (within 1e-3: a pose file
  // rounds, it does not invent a norm of 5).
  auto pose_of = [](const Table& tab, size_t r, const int* c) -> std::optional<Pose> {
    double v[7];
    for (int i = 0; i < 7; ++i) {
      const auto x = tab.Value(r, c[i]);
      if (!x || !std::isfinite(*x)) return std::nullopt;
      v[i] = *x;
    }
    const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
    if (!(std::abs(q.norm() - 1.0) <= 1e-3)) return std::nullopt;
    return Pose::FromQuaternion(q.normalized(), Vec3(v[0], v[1], v[2]));
  };
  std::map<long long, Pose> truth_by_frame;
  for (size_t r = 0; r < truth.rows.size(); ++r)
    if (const auto f = truth.Value(r, tf))
      if (const auto T = pose_of(truth, r, tc)) truth_by_frame[std::llround(*f)] = *T;
  for (const char* h : {"err_x_mm", "err_y_mm", "err_z_mm", "err_rot_mdeg", "nees"}) t.header.push_back(h);
  size_t matched = 0, with_nees = 0, inside = 0, bad_pose = 0, bad_cov = 0;
  double sum_nees = 0, sum_sq_mm = 0;
  const auto [lo, hi] = ChiSquareBand95(6);
  for (size_t r = 0; r < t.rows.size(); ++r) {
    std::string cells[5];
    const auto f = t.Value(r, ef);
    const auto est = pose_of(t, r, ec);
    const auto tr = f ? truth_by_frame.find(std::llround(*f)) : truth_by_frame.end();
    bool given = f.has_value();  // a pose written (a lost frame's cells are empty)
    for (int i = 0; i < 7; ++i)
      given = given && ec[i] >= 0 && static_cast<size_t>(ec[i]) < t.rows[r].size() && !t.rows[r][ec[i]].empty();
    bad_pose += !est && given;
    if (est && tr != truth_by_frame.end()) {
      const Vec6 e = PoseErrorVector(*est, tr->second);
      ++matched;
      sum_sq_mm += 1e6 * e.tail<3>().squaredNorm();
      for (int a = 0; a < 3; ++a) cells[a] = Num(1e3 * e[3 + a]);
      cells[3] = Num(e.head<3>().norm() * 180.0 / std::numbers::pi * 1e3);
      if (have_cov) {
        Mat6 C;
        bool ok = true;
        for (int a = 0; a < 6; ++a)
          for (int b = 0; b < 6; ++b) {
            const auto v = t.Value(r, cov[a][b]);
            ok = ok && v.has_value();
            C(a, b) = v.value_or(0.0);
          }
        // A covariance: finite, symmetric, positive definite, no standard deviation above
        // 100 (m or rad): anything else is not an estimate's uncertainty.
        ok = ok && C.allFinite() && (C - C.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * C.cwiseAbs().maxCoeff() &&
             C.diagonal().maxCoeff() <= 1e4;
        Eigen::LDLT<Mat6> ldlt(C);
        ok = ok && ldlt.info() == Eigen::Success && ldlt.isPositive() && (ldlt.vectorD().array() > 0).all();
        bad_cov += !ok;
        if (ok) {
          const double nees = PoseNees(*est, tr->second, C);
          cells[4] = Num(nees);
          ++with_nees;
          sum_nees += nees;
          inside += nees >= lo && nees <= hi;
        }
      }
    }
    for (auto& c : cells) t.rows[r].push_back(c);
  }
  std::ostringstream o;
  o << "against the truth (matched by frame): " << matched << " of " << t.rows.size() << " frames";
  if (matched) o << ", position error RMS " << Num(std::sqrt(sum_sq_mm / static_cast<double>(matched))) << " mm";
  if (with_nees)
    o << ", mean NEES " << Num(sum_nees / static_cast<double>(with_nees)) << " (6 for a consistent covariance), "
      << inside << " of " << with_nees << " frames inside the 95 % band [" << lo << ", " << hi << "]";
  if (bad_pose)
    o << "; " << bad_pose << " frame(s) left out: their pose is not seven finite numbers with a unit quaternion";
  if (bad_cov)
    o << "; " << bad_cov << " frame(s) without a NEES: their covariance is not finite, symmetric and positive "
      << "definite with standard deviations below 100";
  return o.str();
}

// Per-frame plots of a tracker pose CSV; figures appended to `out`, count returned.
size_t TrackerPlots(const Table& t, const std::string& name, std::ostringstream& out) {
  const char* colors[] = {"#2ca02c", "#ff7f0e", "#d62728", "#9467bd", "#8c564b", "#1f77b4"};
  const int ct = t.Column("time_s"), cs = t.Column("status"), cb = t.Column("balls");
  const size_t n = t.rows.size();
  std::vector<double> time(n);
  for (size_t r = 0; r < n; ++r) time[r] = t.Value(r, ct).value_or(NAN);
  size_t figures = 0;
  auto emit = [&](const Plot& p, const std::string& caption) {
    out << FigureHtml(p.ToSvg(900, 360), name + ": " + caption);
    ++figures;
  };
  // Status and balls per frame.
  {
    Plot p{"Per-frame status: balls identified in each frame", "time (s)", "balls identified", {}};
    std::map<std::string, size_t> index;
    for (size_t r = 0; r < n; ++r) {
      const std::string& s = t.rows[r][cs];
      if (!index.count(s)) {
        index[s] = p.series.size();
        p.series.push_back(PlotSeries{s, {}, {}, colors[p.series.size() % 6], true});
      }
      auto& ser = p.series[index[s]];
      ser.x.push_back(time[r]);
      ser.y.push_back(cb >= 0 ? t.Value(r, cb).value_or(0.0) : 0.0);
    }
    for (auto& s : p.series) s.label += " (" + std::to_string(s.x.size()) + " frames)";
    emit(p, "status per frame");
  }
  // Position.
  {
    Plot p{"Tracked position of the target (rig frame)", "time (s)", "position (mm)", {}};
    const char* axes[] = {"x_m", "y_m", "z_m"};
    for (int a = 0; a < 3; ++a) {
      PlotSeries s{std::string(1, "xyz"[a]), {}, {}, colors[(a + 3) % 6], false};
      const int c = t.Column(axes[a]);
      for (size_t r = 0; r < n; ++r) s.x.push_back(time[r]), s.y.push_back(t.Value(r, c).value_or(NAN) * 1e3);
      p.series.push_back(s);
    }
    emit(p, "position per frame");
  }
  // Predicted sigma of the position, and the reprojection RMS.
  const int cxx = t.Column("cov_px_px"), cyy = t.Column("cov_py_py"), czz = t.Column("cov_pz_pz");
  if (cxx >= 0 && cyy >= 0 && czz >= 0) {
    Plot p{"Predicted position sigma per frame (from the 6x6 covariance)", "time (s)", "sigma (mm)", {}};
    const int cols[] = {cxx, cyy, czz};
    for (int a = 0; a < 3; ++a) {
      PlotSeries s{std::string("sigma_") + "xyz" [a], {}, {}, colors[(a + 3) % 6], false};
      for (size_t r = 0; r < n; ++r) {
        const auto v = t.Value(r, cols[a]);
        s.x.push_back(time[r]);
        s.y.push_back(v && *v >= 0 ? std::sqrt(*v) * 1e3 : NAN);
      }
      p.series.push_back(s);
    }
    emit(p, "predicted sigma per frame");
  }
  if (const int c = t.Column("rms_px"); c >= 0) {
    Plot p{"Reprojection RMS per frame", "time (s)", "RMS (px)", {}};
    PlotSeries s{"rms_px", {}, {}, colors[5], true};
    for (size_t r = 0; r < n; ++r) s.x.push_back(time[r]), s.y.push_back(t.Value(r, c).value_or(NAN));
    p.series.push_back(s);
    emit(p, "reprojection RMS per frame");
  }
  // Errors against a truth file, one axis per plot, each with its predicted 3-sigma band.
  {
    const std::string axes = "xyz";
    const int cov[] = {cxx, cyy, czz};
    for (int a = 0; a < 3; ++a) {
      const std::string h = std::string("err_") + axes[a] + "_mm";
      const int c = t.Column(h);
      if (c < 0) continue;
      Plot p{std::string("Error in ") + axes[a] + " against the truth per frame" +
                 (cov[a] >= 0 ? " (band: predicted +-3 sigma)" : ""),
             "time (s)",
             std::string(1, axes[a]) + " error (mm)",
             {}};
      PlotSeries s{"measured error", {}, {}, colors[(a + 3) % 6], true};
      for (size_t r = 0; r < n; ++r) {
        s.x.push_back(time[r]);
        s.y.push_back(t.Value(r, c).value_or(NAN));
        if (cov[a] >= 0) {
          const auto v = t.Value(r, cov[a]);
          const double b = v && *v >= 0 ? 3e3 * std::sqrt(*v) : NAN;
          s.y_low.push_back(-b);
          s.y_high.push_back(b);
        }
      }
      if (cov[a] >= 0) s.label += " (band: predicted +-3 sigma)";
      p.series.push_back(s);
      emit(p, h + " per frame");
    }
    for (size_t c = 0; c < t.header.size(); ++c) {
      const std::string& h = t.header[c];
      const bool axis_error = h == "err_x_mm" || h == "err_y_mm" || h == "err_z_mm";  // plotted above
      if (!StartsWith(h, "err") || axis_error) continue;
      Plot q{"Per-frame " + h, "time (s)", h, {}};
      PlotSeries s{h, {}, {}, colors[2], true};
      for (size_t r = 0; r < n; ++r)
        s.x.push_back(time[r]), s.y.push_back(t.Value(r, static_cast<int>(c)).value_or(NAN));
      q.series.push_back(s);
      emit(q, h + " per frame");
    }
  }
  for (size_t c = 0; c < t.header.size(); ++c) {
    const std::string h = Lower(t.header[c]);
    if (!StartsWith(h, "nees")) continue;
    const int k = h.find("pos") != std::string::npos || h.find("_p") != std::string::npos ? 3 : 6;
    const auto [lo, hi] = ChiSquareBand95(k);
    Plot p{"NEES per frame against the truth (band: 95 % of chi-square, " + std::to_string(k) + " dof)",
           "time (s)",
           t.header[c],
           {}};
    PlotSeries s{t.header[c], {}, {}, colors[3], true};
    for (size_t r = 0; r < n; ++r) {
      s.x.push_back(time[r]);
      s.y.push_back(t.Value(r, static_cast<int>(c)).value_or(NAN));
      s.y_low.push_back(lo);
      s.y_high.push_back(hi);
    }
    p.series.push_back(s);
    p.log_y = true;
    emit(p, t.header[c] + " per frame");
  }
  return figures;
}

// `mcms fuse`'s output: one fused pose per row, with the method and the sensors it fused.
bool IsFusedPoses(const Table& t) {
  return t.Column("method") >= 0 && t.Column("sensors") >= 0 && t.Column("x_m") >= 0 && t.Column("flagged") >= 0;
}

bool IsIso9283Characteristics(const Table& t) {
  return t.Column("pose") >= 0 && t.Column("AP_mm") >= 0 && t.Column("RP_mm") >= 0;
}

// Plots of an ISO 9283 characteristics table (`mcms iso9283 -o`, the demo's
// iso9283_characteristics.csv): AP per pose on a log axis in mm, and RP measured (markers)
// next to RP predicted from the covariances (lines) when the table has RP_pred_mm; one
// colour per condition.
size_t Iso9283Plots(const Table& t, const std::string& name, std::ostringstream& out) {
  const char* colors[] = {"#d62728", "#ff7f0e", "#1f77b4", "#2ca02c", "#9467bd", "#8c564b"};
  const int cp = t.Column("pose"), cc = t.Column("condition"), ca = t.Column("AP_mm"), cr = t.Column("RP_mm"),
            cq = t.Column("RP_pred_mm");
  std::vector<std::string> conditions;
  std::map<std::string, size_t> index;
  for (const auto& row : t.rows) {
    const std::string c = cc >= 0 ? row[cc] : std::string("measured");
    if (!index.count(c)) index[c] = conditions.size(), conditions.push_back(c);
  }
  Plot ap{"ISO 9283 pose accuracy AP per pose", "pose (P1..P5)", "AP (mm)", {}};
  ap.log_y = true;
  Plot rp{std::string("ISO 9283 pose repeatability RP per pose") +
              (cq >= 0 ? " (markers: measured, lines: predicted)" : ""),
          "pose (P1..P5)",
          "RP (mm)",
          {}};
  for (size_t k = 0; k < conditions.size(); ++k) {
    PlotSeries a{conditions[k], {}, {}, colors[k % 6], true},
        r = a, q{conditions[k] + " (predicted)", {}, {}, colors[k % 6], false};
    for (size_t i = 0; i < t.rows.size(); ++i) {
      if ((cc >= 0 ? t.rows[i][cc] : std::string("measured")) != conditions[k]) continue;
      // Pose "P3" -> 3; a plain number is used as it is.
      const std::string& pose = t.rows[i][cp];
      const double x =
          std::strtod(pose.c_str() + (pose.size() > 1 && (pose[0] == 'P' || pose[0] == 'p') ? 1 : 0), nullptr);
      a.x.push_back(x), a.y.push_back(t.Value(i, ca).value_or(NAN));
      r.x.push_back(x), r.y.push_back(t.Value(i, cr).value_or(NAN));
      if (cq >= 0) q.x.push_back(x), q.y.push_back(t.Value(i, cq).value_or(NAN));
    }
    ap.series.push_back(a);
    rp.series.push_back(r);
    if (cq >= 0) rp.series.push_back(q);
  }
  out << FigureHtml(ap.ToSvg(900, 420), name + ": AP per pose");
  out << FigureHtml(rp.ToSvg(900, 420), name + ": RP per pose, measured and predicted");
  return 2;
}

// The demo's answer, for the page's first screen: the flange error of each sensor and each
// fused result by the paper's three-sigma rule with the reduction, from summary.txt's table
// (rows "method points posRMS pos3sig reduction tiltRMS yawRMS NEES [band]") and its lines
// against the paper. Empty when the summary does not hold them.
}  // namespace mcms::html_report_internal
