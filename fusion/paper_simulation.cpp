#include "fusion/paper_simulation.h"

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "core/error.h"
#include "core/io.h"
#include "core/random.h"
#include "fusion/kalman.h"
#include "fusion/moifa.h"

namespace mcms {

bool PaperFusionOptions::IsValid(std::string* why) const {
  std::ostringstream s;
  if (num_points < 2) s << "num_points must be >= 2, is " << num_points;
  else if (!(cube_size > 0) || !std::isfinite(cube_size)) s << "cube_size must be positive, is " << cube_size;
  else if (!((camera_sigma.array() > 0).all() && camera_sigma.allFinite())) s << "camera_sigma must be positive";
  else if (!((robot_sigma.array() > 0).all() && robot_sigma.allFinite())) s << "robot_sigma must be positive";
  else if (repetitions < 2) s << "repetitions must be >= 2, is " << repetitions;
  if (s.tellp() == 0) return true;
  if (why) *why = "paper fusion simulation: " + s.str();
  return false;
}

double AnalyticMoifaRmsReduction(const Vec3& c, const Vec3& r) {
  double fused = 0.0, camera = 0.0;
  for (int k = 0; k < 3; ++k) {
    fused += 1.0 / (1.0 / (c[k] * c[k]) + 1.0 / (r[k] * r[k]));
    camera += c[k] * c[k];
  }
  return 1.0 - std::sqrt(fused / camera);
}

double RunningMeanRmsFactor(int n) {
  double h = 0.0;
  for (int k = 1; k <= n; ++k) h += 1.0 / k;
  return std::sqrt(h / n);
}

namespace {

// The paper's three-sigma rule on one axis: sigma of the values within 3 sigma of the mean.
double ThreeSigmaRuleSigma(const std::vector<Vec3>& e, int axis) {
  double mean = 0.0, var = 0.0;
  for (const Vec3& v : e) mean += v[axis];
  mean /= e.size();
  for (const Vec3& v : e) var += std::pow(v[axis] - mean, 2);
  const double sigma = std::sqrt(var / (e.size() - 1));
  double m2 = 0.0, s2 = 0.0;
  size_t kept = 0;
  for (const Vec3& v : e)
    if (std::abs(v[axis] - mean) <= 3.0 * sigma) {
      m2 += v[axis];
      ++kept;
    }
  m2 /= kept;
  for (const Vec3& v : e)
    if (std::abs(v[axis] - mean) <= 3.0 * sigma) s2 += std::pow(v[axis] - m2, 2);
  return std::sqrt(s2 / (kept - 1));
}

ErrorStats Stats(const std::vector<Vec3>& e) {
  ErrorStats s;
  Vec3 sum2 = Vec3::Zero();
  for (const Vec3& v : e) sum2 += v.cwiseProduct(v);
  s.rms_axis = (sum2 / e.size()).cwiseSqrt();
  s.rms = std::sqrt(sum2.sum() / e.size());
  double var = 0.0;
  for (int a = 0; a < 3; ++a) {
    const double sigma = ThreeSigmaRuleSigma(e, a);
    s.three_sigma_axis[a] = 3.0 * sigma;
    var += sigma * sigma;
  }
  s.three_sigma = 3.0 * std::sqrt(var);
  return s;
}

// Collects the errors of one estimator, pooled and per repetition.
struct Errors {
  std::vector<Vec3> all;
  std::vector<std::vector<Vec3>> per_rep;
  void Add(int rep, const Vec3& e) {
    all.push_back(e);
    if (static_cast<int>(per_rep.size()) <= rep) per_rep.resize(rep + 1);
    per_rep[rep].push_back(e);
  }
};

enum class Metric { kRms, kThreeSigma };

double Value(const ErrorStats& s, Metric m) { return m == Metric::kRms ? s.rms : s.three_sigma; }

Reduction Reduce(const Errors& est, const Errors& ref, Metric m) {
  Reduction r;
  r.pooled = 1.0 - Value(Stats(est.all), m) / Value(Stats(ref.all), m);
  const size_t n = est.per_rep.size();
  std::vector<double> per(n);
  double sum = 0.0;
  for (size_t i = 0; i < n; ++i) {
    per[i] = 1.0 - Value(Stats(est.per_rep[i]), m) / Value(Stats(ref.per_rep[i]), m);
    sum += per[i];
  }
  r.mean = sum / n;
  double var = 0.0;
  for (double p : per) var += (p - r.mean) * (p - r.mean);
  r.standard_error = std::sqrt(var / (n - 1) / n);
  return r;
}

}  // namespace

PaperFusionResult SimulatePaperFusion(const PaperFusionOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) Throw(why);
  PaperFusionResult res;
  res.options = o;
  const Mat3 Rc = o.camera_sigma.cwiseProduct(o.camera_sigma).asDiagonal();
  const Mat3 Rr = o.robot_sigma.cwiseProduct(o.robot_sigma).asDiagonal();
  const Mat3 Q_tracking = o.cube_size * o.cube_size * Mat3::Identity();

  Errors camera, robot, moifa, ks_c, ks_r, ks_f, kt_c, kt_r, kt_f;
  Rng rng(o.seed);
  for (int rep = 0; rep < o.repetitions; ++rep) {
    PerSensorKalmanFusion kf_static(2, Mat3::Zero());
    PerSensorKalmanFusion kf_tracking(2, Q_tracking);
    Vec3 previous = Vec3::Zero();
    for (int k = 0; k < o.num_points; ++k) {
      Vec3 p, yc, yr;
      for (int a = 0; a < 3; ++a) p[a] = rng.Uniform(0.0, o.cube_size);
      for (int a = 0; a < 3; ++a) yc[a] = p[a] + o.camera_sigma[a] * rng.Normal();
      for (int a = 0; a < 3; ++a) yr[a] = p[a] + o.robot_sigma[a] * rng.Normal();
      camera.Add(rep, yc - p);
      robot.Add(rep, yr - p);

      const FusedPosition f = FusePositions(
          {PositionMeasurement::FromCovariance("camera", yc, Rc), PositionMeasurement::FromCovariance("robot", yr, Rr)});
      moifa.Add(rep, f.p - p);

      // Static KF: no process noise, told the commanded displacement.
      const Vec3 u = k == 0 ? Vec3::Zero() : Vec3(p - previous);
      const auto s = kf_static.Step({yc, yr}, {Rc, Rr}, u);
      ks_c.Add(rep, kf_static.Filter(0).State() - p);
      ks_r.Add(rep, kf_static.Filter(1).State() - p);
      ks_f.Add(rep, s.fused.p - p);

      // Tracking KF: process noise >> R, no knowledge of the motion.
      const auto t = kf_tracking.Step({yc, yr}, {Rc, Rr});
      kt_c.Add(rep, kf_tracking.Filter(0).State() - p);
      kt_r.Add(rep, kf_tracking.Filter(1).State() - p);
      kt_f.Add(rep, t.fused.p - p);
      previous = p;
    }
  }
  res.camera = Stats(camera.all);
  res.robot = Stats(robot.all);
  res.moifa = Stats(moifa.all);
  res.kf_static_camera = Stats(ks_c.all);
  res.kf_static_robot = Stats(ks_r.all);
  res.kf_static_fused = Stats(ks_f.all);
  res.kf_tracking_camera = Stats(kt_c.all);
  res.kf_tracking_robot = Stats(kt_r.all);
  res.kf_tracking_fused = Stats(kt_f.all);

  res.moifa_rms = Reduce(moifa, camera, Metric::kRms);
  res.moifa_three_sigma = Reduce(moifa, camera, Metric::kThreeSigma);
  res.kf_static_rms = Reduce(ks_f, camera, Metric::kRms);
  res.kf_static_three_sigma = Reduce(ks_f, camera, Metric::kThreeSigma);
  res.kf_static_filter_rms = Reduce(ks_c, camera, Metric::kRms);
  res.kf_tracking_rms = Reduce(kt_f, camera, Metric::kRms);
  res.kf_tracking_three_sigma = Reduce(kt_f, camera, Metric::kThreeSigma);
  res.kf_static_vs_filtered_camera_rms = Reduce(ks_f, ks_c, Metric::kRms);
  res.kf_static_vs_filtered_camera_three_sigma = Reduce(ks_f, ks_c, Metric::kThreeSigma);

  res.analytic_moifa_rms_reduction = AnalyticMoifaRmsReduction(o.camera_sigma, o.robot_sigma);
  res.analytic_static_kf_factor = RunningMeanRmsFactor(o.num_points);
  res.analytic_kf_static_rms_reduction =
      1.0 - res.analytic_static_kf_factor * (1.0 - res.analytic_moifa_rms_reduction);
  res.analytic_kf_static_filter_reduction = 1.0 - res.analytic_static_kf_factor;
  return res;
}

namespace {

// printf into the report.
void Append(std::string* out, const char* fmt, ...) __attribute__((format(printf, 2, 3)));
void Append(std::string* out, const char* fmt, ...) {
  va_list ap, copy;
  va_start(ap, fmt);
  va_copy(copy, ap);
  const int n = std::vsnprintf(nullptr, 0, fmt, copy);
  va_end(copy);
  std::string s(n > 0 ? n : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), s.size() + 1, fmt, ap);
  va_end(ap);
  *out += s;
}

std::string Pct(const Reduction& r) {
  char b[64];
  std::snprintf(b, sizeof b, "%5.1f +- %.1f", 100 * r.pooled, 100 * r.standard_error);
  return b;
}

void Row(std::string* out, const char* label, double camera, double robot, double fused, const std::string& vs_camera,
         const std::string& vs_own) {
  Append(out, "  %-36s %9.3f %9.3f %9.3f   %-13s %s\n", label, 1e3 * camera, 1e3 * robot, 1e3 * fused,
              vs_camera.c_str(), vs_own.c_str());
}

}  // namespace

namespace fs = std::filesystem;

std::optional<fs::path> FindPaperResults(const std::string& given, std::string* looked) {
  if (!given.empty()) {
    if (!fs::exists(given)) Throw("--paper-results: file ", given, " does not exist");
    return fs::path(given);
  }
  std::vector<fs::path> candidates;
  if (const char* env = std::getenv("MCMS_DATA_DIR")) candidates.push_back(fs::path(env) / "paper/fusion_results.csv");
  candidates.push_back(fs::path("..") / "shared/data/paper/fusion_results.csv");
  for (const auto& c : candidates) {
    if (fs::exists(c)) return c;
    *looked += (looked->empty() ? "" : ", ") + c.string();
  }
  return std::nullopt;
}

std::string FormatPaperFusionReport(const PaperFusionOptions& o, const PaperFusionResult& r,
                                    const CsvTable* paper_table, const std::string& looked) {
  std::string out;
  Append(&out, "Liu, Zhang, Qu (2015), section 3.3: fusion of photogrammetry and robot positions\n");
  Append(&out, "%d random points in a %.0f mm cube, %d Monte-Carlo repetitions, seed %llu\n", o.num_points, 1e3 * o.cube_size,
              o.repetitions, static_cast<unsigned long long>(o.seed));
  Append(&out, "sigma per axis (x, y, z): camera %.3f %.3f %.3f mm, robot %.3f %.3f %.3f mm\n\n",
              1e3 * o.camera_sigma.x(), 1e3 * o.camera_sigma.y(), 1e3 * o.camera_sigma.z(), 1e3 * o.robot_sigma.x(),
              1e3 * o.robot_sigma.y(), 1e3 * o.robot_sigma.z());

  Append(&out, "Table 3, ours: composite 3-D error over all points and repetitions (mm); reduction in %%\n");
  Append(&out, "(+- one Monte-Carlo standard error over repetitions); 'vs own camera' = the paper's (dx1 - dxf) / dx1\n");
  Append(&out, "  %-36s %9s %9s %9s   %-13s %s\n", "", "camera_mm", "robot_mm", "fused_mm", "vs_camera_pct",
              "vs_own_camera_pct");
  const std::string same = "(same)";
  Append(&out, " three-sigma rule (3 sigma after rejecting errors beyond 3 sigma)\n");
  Row(&out, "MOIFA (D_CM, D_RB, D_f)", r.camera.three_sigma, r.robot.three_sigma, r.moifa.three_sigma,
      Pct(r.moifa_three_sigma), same);
  Row(&out, "KF static, Q = 0 (dx1, dx2, dxf)", r.kf_static_camera.three_sigma, r.kf_static_robot.three_sigma,
      r.kf_static_fused.three_sigma, Pct(r.kf_static_three_sigma), Pct(r.kf_static_vs_filtered_camera_three_sigma));
  Row(&out, "KF tracking, Q >> R (dx1, dx2, dxf)", r.kf_tracking_camera.three_sigma, r.kf_tracking_robot.three_sigma,
      r.kf_tracking_fused.three_sigma, Pct(r.kf_tracking_three_sigma), same);
  Append(&out, " RMS\n");
  Row(&out, "MOIFA", r.camera.rms, r.robot.rms, r.moifa.rms, Pct(r.moifa_rms), same);
  Row(&out, "KF static, Q = 0", r.kf_static_camera.rms, r.kf_static_robot.rms, r.kf_static_fused.rms, Pct(r.kf_static_rms),
      Pct(r.kf_static_vs_filtered_camera_rms));
  Row(&out, "KF tracking, Q >> R", r.kf_tracking_camera.rms, r.kf_tracking_robot.rms, r.kf_tracking_fused.rms,
      Pct(r.kf_tracking_rms), same);

  // Analytic: MOIFA per axis 1/(1/c^2 + 1/r^2); static KF RMS = sqrt(H_N/N) x the single-measurement figure.
  const double cam_rms = o.camera_sigma.norm(), rob_rms = o.robot_sigma.norm();
  const double fused_rms = cam_rms * (1.0 - r.analytic_moifa_rms_reduction);
  const double f = r.analytic_static_kf_factor;
  char moifa_pct[32], static_pct[32], own_pct[32];
  std::snprintf(moifa_pct, sizeof moifa_pct, "%5.1f", 100 * r.analytic_moifa_rms_reduction);
  std::snprintf(static_pct, sizeof static_pct, "%5.1f", 100 * r.analytic_kf_static_rms_reduction);
  std::snprintf(own_pct, sizeof own_pct, "%5.1f", 100 * r.analytic_moifa_rms_reduction);
  Append(&out, " analytic (RMS; for Gaussian errors, as MOIFA's, the three-sigma figures are 3x these)\n");
  Row(&out, "MOIFA, eq. 19", cam_rms, rob_rms, fused_rms, moifa_pct, same);
  Row(&out, "KF static: running mean", f * cam_rms, f * rob_rms, f * fused_rms, static_pct, own_pct);
  Append(&out, "  (static KF: the camera filter alone is %.1f %% below the raw camera, sqrt(H_N / N) = %.3f, N = %d)\n\n",
              100 * r.analytic_kf_static_filter_reduction, f, o.num_points);

  if (paper_table) {
    const CsvTable& t = *paper_table;
    const auto* file = &paper_table->source;
    const int ex = t.Column("experiment"), me = t.Column("method"), c = t.Column("dx_camera_mm"),
              rb = t.Column("dx_robot_mm"), fu = t.Column("dx_fused_mm"), red = t.Column("reduction_pct");
    Append(&out, "The paper's figures (%s; signed single values, mm):\n", file->string().c_str());
    Append(&out, "  %-12s %-6s %9s %9s %9s %14s\n", "experiment", "method", "camera_mm", "robot_mm", "fused_mm",
                "reduction_pct");
    const auto cell = [&](size_t i, int col) {
      return t.rows[i][col].empty() ? std::string("-") : t.rows[i][col];
    };
    std::optional<std::pair<double, double>> kf_sim;
    for (size_t i = 0; i < t.rows.size(); ++i) {
      Append(&out, "  %-12s %-6s %9s %9s %9s %14s\n", t.rows[i][ex].c_str(), t.rows[i][me].c_str(), cell(i, c).c_str(),
                  cell(i, rb).c_str(), cell(i, fu).c_str(), cell(i, red).c_str());
      if (t.rows[i][ex] == "simulation" && t.rows[i][me] == "KF" && !t.rows[i][c].empty() && !t.rows[i][rb].empty())
        kf_sim = std::make_pair(t.Number(i, c), t.Number(i, rb));
    }
    Append(&out, "  ours, simulation: MOIFA %.1f %% (analytic %.1f %%); static KF %.1f %% per filter, %.1f %% fused\n",
                100 * r.moifa_rms.pooled, 100 * r.analytic_moifa_rms_reduction, 100 * r.kf_static_filter_rms.pooled,
                100 * r.kf_static_rms.pooled);
    if (kf_sim) {
      // Eq. 14 on the x axis (weights c^-2 / (c^-2 + r^-2)) applied to the paper's own two
      // signed numbers: opposite signs cancel in any weighted mean.
      const double wc = 1.0 / std::pow(o.camera_sigma.x(), 2), wr = 1.0 / std::pow(o.robot_sigma.x(), 2);
      const double fused = (wc * kf_sim->first + wr * kf_sim->second) / (wc + wr);
      Append(&out, "  note: the printed KF errors are single signed values of opposite sign; eq. 14 with the x-axis\n"
                  "  weights (%.2f, %.2f) turns dx1 = %.3f and dx2 = %.3f into %.3f mm, %.0f %% below |dx1|, so one\n"
                  "  such sample says little about either method.\n",
                  wc / (wc + wr), wr / (wc + wr), kf_sim->first, kf_sim->second, fused,
                  100 * (1 - std::abs(fused) / std::abs(kf_sim->first)));
    }
    Append(&out, "\n");
  } else {
    Append(&out, "The paper's figures: not shown, fusion_results.csv not found (looked in: %s; use --paper-results)\n\n",
                looked.c_str());
  }

  // The explanations, computed for these options.
  const auto printed = PrintedEquation13Weights(
      {Mat3(o.camera_sigma.cwiseAbs2().asDiagonal()) * 1e6, Mat3(o.robot_sigma.cwiseAbs2().asDiagonal()) * 1e6});
  const Mat3 printed_sum = printed[0] + printed[1];
  Append(&out,
      "Notes\n"
      "- MOIFA fuses the two measurements of each point with W_i = (sum_j P_j^-1)^-1 P_i^-1 (sum W_i = I).\n"
      "  The paper prints eq. 13/16 as W_i = (sum_j P_j)^-1 P_i^-1, whose weights here sum to\n"
      "  diag(%.0f, %.0f, %.0f) mm^-4, not I (and are not dimensionless); its eq. 19 and its 46.1 %% match the\n"
      "  correct form (analytic %.1f %%).\n"
      "- The paper's KF figure (78.2 %%) is the size of what a static KF gives: with process noise Q = 0 and the\n"
      "  commanded displacement between points, each per-sensor filter believes it sees one unchanging offset\n"
      "  and averages the errors of all points so far (error sigma / sqrt(k) at point k; %.1f %% lower RMS over\n"
      "  %d points, %.1f %% after fusing the two filters). That gain comes from averaging over time, not from\n"
      "  fusion, and is valid only if the errors really were one constant offset; with independent errors per\n"
      "  point, as simulated here and in the paper, it borrows measurements of other points. Comparing it with\n"
      "  MOIFA, which fuses two single measurements of one point, is not like for like.\n"
      "- Like for like, a KF whose process noise matches a state that really moves between independent points\n"
      "  (Q >> R) keeps gain ~1 and reduces to MOIFA: %.1f %% here.\n",
      printed_sum(0, 0), printed_sum(1, 1), printed_sum(2, 2), 100 * r.analytic_moifa_rms_reduction,
      100 * r.analytic_kf_static_filter_reduction, o.num_points, 100 * r.analytic_kf_static_rms_reduction,
      100 * r.kf_tracking_rms.pooled);
  return out;
}

}  // namespace mcms
