#include "fusion/paper_simulation.h"

#include <cmath>
#include <sstream>

#include "core/error.h"
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

}  // namespace mcms
