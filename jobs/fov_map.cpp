#include "core/limits.h"
#include "jobs/fov_map.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include "core/error.h"
#include "core/io.h"
#include "core/parallel.h"
#include "core/svg_plot.h"
#include "core/statistics.h"
#include "synthetic/scenario.h"
#include "synthetic/recording.h"

namespace mcms {

namespace {
constexpr size_t kMaxFovGridPoints = 2000000;
}  // namespace

namespace fs = std::filesystem;

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Vec3 CameraCentre(const CameraModel& cam) { return cam.T_cam_rig().Inverse().t; }
}  // namespace

// ---------------------------------------------------------------------------------------
// Noise model and centre-covariance table

BlobDetectorOptions FovNoiseModel::Detector() const {
  BlobDetectorOptions d;
  d.polarity = Polarity::kBright;
  const double gain = detector_gain_e_per_dn >= 0 ? detector_gain_e_per_dn : render.gain_e_per_dn;
  d.gain_e_per_dn = gain;
  if (detector_read_noise_dn > 0) {
    d.read_noise_dn = detector_read_noise_dn;
  } else {
    const double shot = render.gain_e_per_dn > 0 ? render.exposure * render.background_dn / render.gain_e_per_dn : 0.0;
    d.read_noise_dn = std::sqrt(render.read_noise_dn * render.read_noise_dn + shot + 1.0 / 12.0);
  }
  return d;
}

bool FovNoiseModel::IsValid(std::string* why) const {
  if (!render.IsValid(why)) return false;
  if (!(std::isfinite(detector_read_noise_dn) && detector_read_noise_dn >= 0))
    return (*why = "the detector's read noise must be a number >= 0", false);
  if (!std::isfinite(detector_gain_e_per_dn)) return (*why = "the detector's gain must be a number", false);
  return Detector().IsValid(why);
}

CentroidCovarianceTable BuildCentroidCovarianceTable(const FovNoiseModel& noise, double b_min_px, double b_max_px,
                                                     double ratio_max, int threads) {
  std::string why;
  if (!noise.IsValid(&why)) Throw("noise model: ", why);
  MCMS_CHECK(b_min_px > 0 && b_max_px >= b_min_px && ratio_max >= 1, "BuildCentroidCovarianceTable: bad size range");
  std::vector<double> bs;
  const double lo = b_min_px / 1.1, hi = b_max_px * 1.1, step = 1.15;
  for (double b = lo; b < hi * step; b *= step) bs.push_back(b);
  std::vector<double> ratios{1.0};
  for (double r : {1.15, 1.3, 1.5, 1.8, 2.2})
    if (r <= ratio_max * 1.2) ratios.push_back(r);
  RenderOptions ro = noise.render;
  ro.noise_free = true;
  ro.background_gradient_dn = Vec2::Zero();
  ro.spurious_per_image = 0;
  ro.occlusion_probability = 0;
  ro.dropout_probability = 0;
  const BlobDetectorOptions det = noise.Detector();
  const double f = 1000.0, radius = 0.01;
  const Vec2 phases[4] = {Vec2(0, 0), Vec2(0.5, 0.25), Vec2(0.25, 0.5), Vec2(0.5, 0.5)};
  std::vector<double> vmaj(bs.size() * ratios.size()), vmin(vmaj.size());
  ParallelFor(
      vmaj.size(), threads,
      [&](size_t k) {
        const double b_target = bs[k / ratios.size()], ratio = ratios[k % ratios.size()];
        // A sphere at angle theta off the axis of a pinhole images as an ellipse elongated
        // radially by about 1 / cos(theta); its distance sets the size.
        const double theta = std::acos(1.0 / ratio);
        const Vec3 dir(std::sin(theta), 0.0, std::cos(theta));
        double D = f * radius / b_target / std::cos(theta);
        const int S = 2 * static_cast<int>(std::ceil(ratio * b_target + 4 * ro.blur_sigma_px + 40));
        // Size the distance so that the outline's minor semi-axis is b_target.
        for (int it = 0; it < 3; ++it) {
          const CameraModel probe("LENSMODEL_PINHOLE", {f, f, 0.0, 0.0}, S, S);
          const Ellipse e = EllipseFromOutline(SphereOutline(probe, D * dir, radius, 128));
          D *= e.b / b_target;
        }
        double sum_maj = 0, sum_min = 0;
        for (const Vec2& ph : phases) {
          const double cx = 0.5 * S + ph.x() - f * std::tan(theta), cy = 0.5 * S + ph.y();
          const CameraModel cam("LENSMODEL_PINHOLE", {f, f, cx, cy}, S, S);
          const cv::Mat img = RenderSpheres(cam, {D * dir}, radius, ro, nullptr);
          const std::vector<Blob> blobs = DetectBlobs(img, det);
          if (blobs.empty())
            Throw("noise model: the blob detector finds no ball image of minor semi-axis ", b_target,
                  " px (ball ", ro.ball_dn, " DN over background ", ro.background_dn, " DN)");
          // Elongated radially, i.e. along x: the major axis is x.
          sum_maj += blobs.front().cov(0, 0);
          sum_min += blobs.front().cov(1, 1);
        }
        vmaj[k] = sum_maj / 4;
        vmin[k] = sum_min / 4;
      },
      {});
  return CentroidCovarianceTable(bs, ratios, vmaj, vmin);
}

// ---------------------------------------------------------------------------------------
// Grid

FovGrid FovGrid::Parse(const std::string& text, const std::string& source) {
  auto fail = [&](const std::string& detail) -> FovGrid {
    Throw(source, ": expected x0:x1:nx,y0:y1:ny,z0:z1:nz (metres in the rig frame, n >= 1 points per axis), found '",
          text, "'", detail.empty() ? "" : ": ", detail);
  };
  std::vector<std::string> parts;
  std::stringstream ss(text);
  for (std::string p; std::getline(ss, p, ',');) parts.push_back(p);
  if (parts.size() != 3) return fail("three axes separated by commas");
  FovGrid g;
  const char* axis = "xyz";
  for (int a = 0; a < 3; ++a) {
    std::vector<std::string> f;
    std::stringstream s2(parts[a]);
    for (std::string p; std::getline(s2, p, ':');) f.push_back(p);
    if (f.size() != 3) return fail(std::string("axis ") + axis[a] + " needs start:end:count");
    double v[3];
    for (int i = 0; i < 3; ++i) {
      char* end = nullptr;
      v[i] = std::strtod(f[i].c_str(), &end);
      if (f[i].empty() || end != f[i].c_str() + f[i].size() || !std::isfinite(v[i]))
        return fail(std::string("axis ") + axis[a] + ": '" + f[i] + "' is not a finite number");
    }
    if (v[2] < 1 || v[2] != std::floor(v[2]) || v[2] > 100000)
      return fail(std::string("axis ") + axis[a] + ": the count must be an integer >= 1");
    g.n[a] = static_cast<int>(v[2]);
    if (g.n[a] > 1 && !(v[1] > v[0])) return fail(std::string("axis ") + axis[a] + ": the end must exceed the start");
    // A camera rig's working volume is metres across; 1 km is beyond any (and keeps the
    // grid's arithmetic finite: -1e308:1e308 would overflow the spacing).
    if (std::abs(v[0]) > 1000 || std::abs(v[1]) > 1000)
      return fail(std::string("axis ") + axis[a] + ": positions beyond 1000 m (metres are expected)");
    g.lo[a] = v[0];
    g.hi[a] = g.n[a] > 1 ? v[1] : v[0];
  }
  // Each point's prediction holds about 0.9 kB until the map is written and takes about
  // 0.25 ms: 2e6 points are 2 GB and 8 minutes on two cores; more is not a map anyone waits for.
  if (g.size() > kMaxFovGridPoints)
    Throw(source, ": ", g.size(), " grid points, more than ", kMaxFovGridPoints, " (each needs about 0.9 kB of memory: ",
          0.9e-6 * double(g.size()), " GB, and 0.25 ms); give fewer points per axis");
  return g;
}

Vec3 FovGrid::Point(size_t index) const {
  const int ix = static_cast<int>(index % n[0]);
  const int iy = static_cast<int>((index / n[0]) % n[1]);
  const int iz = static_cast<int>(index / (static_cast<size_t>(n[0]) * n[1]));
  return {Coord(0, ix), Coord(1, iy), Coord(2, iz)};
}

std::string FovGrid::ToString() const {
  std::ostringstream o;
  for (int a = 0; a < 3; ++a) o << (a ? "," : "") << lo[a] << ":" << hi[a] << ":" << n[a];
  return o.str();
}

bool FovMapOptions::IsValid(std::string* why) const {
  if (!noise.IsValid(why)) return false;
  if (!prediction.IsValid(why)) return false;
  if (threads < 1 || threads > kMaxThreads)
    return (*why = "threads must be 1 to " + std::to_string(kMaxThreads) + ", got " + std::to_string(threads), false);
  if (!(threshold_mm > 0 && std::isfinite(threshold_mm))) return (*why = "the threshold must be a positive number of mm", false);
  if (!(std::abs(R_rig_target.determinant() - 1) < 1e-6)) return (*why = "the orientation is not a rotation", false);
  return true;
}

// ---------------------------------------------------------------------------------------
// The map

Vec3 FovMapPoint::sigma_p() const {
  if (!prediction.trackable) return Vec3::Constant(kNaN);
  return prediction.cov.diagonal().tail<3>().cwiseSqrt();
}
Vec3 FovMapPoint::sigma_r() const {
  if (!prediction.trackable) return Vec3::Constant(kNaN);
  return prediction.cov.diagonal().head<3>().cwiseSqrt();
}
double FovMapPoint::mean_ball_sigma_d() const {
  double s = 0;
  int n = 0;
  for (const auto& b : prediction.balls)
    if (b.triangulated) s += std::sqrt(b.cov.trace()), ++n;
  return n ? s / n : kNaN;
}

namespace {
// The centre-noise table for the ball-image sizes that occur in the box [lo, hi].
CentroidCovarianceTable TableForBox(const CameraRig& rig, const Target& target, const FovMapOptions& options,
                                    const Vec3& lo, const Vec3& hi) {
  // The range of ball-image sizes over the box: from the nearest and farthest depth of
  // the box's corners (the volume is convex), padded, for every camera.
  double b_min = INFINITY, b_max = 0;
  const double reach = target.balls_target.empty() ? 0.0 : [&] {
    double r = 0;
    for (const Vec3& b : target.balls_target) r = std::max(r, b.norm());
    return r;
  }();
  for (const CameraModel& cam : rig.cameras) {
    const double fmax = cam.FocalLengths().maxCoeff(), fmin = cam.FocalLengths().minCoeff();
    double dmin = INFINITY, dmax = 0;
    for (int c = 0; c < 8; ++c) {
      const Vec3 p((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
      const double d = (cam.T_cam_rig() * p).norm();
      dmin = std::min(dmin, d);
      dmax = std::max(dmax, d);
    }
    dmin = std::max(dmin - reach, 0.05);
    dmax += reach;
    b_min = std::min(b_min, fmin * target.ball_radius / dmax);
    b_max = std::max(b_max, 1.6 * fmax * target.ball_radius / dmin);
  }
  b_min = std::max(b_min, 0.5);
  b_max = std::min(std::max(b_max, b_min), 400.0);
  return BuildCentroidCovarianceTable(options.noise, b_min, b_max, 1.8, options.threads);
}

void FillDistance(const CameraRig& rig, FovMapPoint* pt) {
  double s = 0;
  int n = 0;
  for (size_t c = 0; c < rig.size(); ++c)
    if (pt->prediction.balls_in_camera[c] > 0) s += (CameraCentre(rig.cameras[c]) - pt->p_rig).norm(), ++n;
  pt->mean_distance_m = n ? s / n : kNaN;
}
}  // namespace

FovMap ComputeFovMap(const CameraRig& rig, const Target& target, const FovMapOptions& options,
                     const std::function<void(size_t, size_t)>& progress) {
  std::string why;
  if (!options.IsValid(&why)) Throw("fov-map options: ", why);
  if (rig.size() < 2) Throw("the rig needs at least 2 cameras to triangulate, it has ", rig.size());
  target.MinDistanceGap();
  FovMap map;
  map.rig = rig;
  map.target = target;
  map.options = options;

  // A grid no two cameras see (outside the view, behind the rig, in mm): said here, not as
  // ball images too small for the detector.
  {
    const auto Seen = [&](const Vec3& p, const CameraModel& cam) {
      const Vec3 pc = cam.T_cam_rig() * p;
      if (!(pc.z() > 0.05)) return false;
      const Vec2 q = cam.Project(pc);
      return std::isfinite(q.x()) && std::isfinite(q.y()) && q.x() >= 0 && q.y() >= 0 && q.x() < cam.Width() &&
             q.y() < cam.Height();
    };
    bool any = false;
    for (size_t i = 0; i < options.grid.size() && !any; ++i) {
      const Vec3 p = options.grid.Point(i);
      int n = 0;
      for (const CameraModel& cam : rig.cameras) n += Seen(p, cam);
      any = n >= 2;
    }
    if (!any)
      Throw("fov-map --grid ", options.grid.ToString(), ": none of its ", options.grid.size(),
            " points is in the view of two cameras (points in the rig frame, metres; the rig's cameras look at ",
            "their common view, e.g. the scenario's look_at_m); give a grid inside the cameras' common view");
  }
  map.centre_table = TableForBox(rig, target, options, options.grid.lo, options.grid.hi);
  const CentroidCovarianceTable& table = map.centre_table;
  const CentroidCovarianceFn centre_cov = [&table](const Ellipse& e) { return table(e); };

  map.points.resize(options.grid.size());
  ParallelFor(
      map.points.size(), options.threads,
      [&](size_t i) {
        FovMapPoint& pt = map.points[i];
        pt.p_rig = options.grid.Point(i);
        Pose T;
        T.R = options.R_rig_target;
        T.t = pt.p_rig;
        pt.prediction = PredictFovPoint(rig, target, T, centre_cov, options.prediction);
        FillDistance(rig, &pt);
      },
      progress);
  return map;
}

std::vector<FovMapPoint> PredictFovPoints(const CameraRig& rig, const Target& target, const FovMapOptions& options,
                                          const std::vector<Vec3>& positions) {
  std::string why;
  if (!options.IsValid(&why)) Throw("fov-map options: ", why);
  if (rig.size() < 2) Throw("the rig needs at least 2 cameras to triangulate, it has ", rig.size());
  std::vector<FovMapPoint> out(positions.size());
  if (positions.empty()) return out;
  Vec3 lo = positions.front(), hi = positions.front();
  for (const Vec3& p : positions) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const CentroidCovarianceTable table = TableForBox(rig, target, options, lo, hi);
  const CentroidCovarianceFn centre_cov = [&table](const Ellipse& e) { return table(e); };
  ParallelFor(
      positions.size(), options.threads,
      [&](size_t i) {
        FovMapPoint& pt = out[i];
        pt.p_rig = positions[i];
        Pose T;
        T.R = options.R_rig_target;
        T.t = pt.p_rig;
        pt.prediction = PredictFovPoint(rig, target, T, centre_cov, options.prediction);
        FillDistance(rig, &pt);
      },
      {});
  return out;
}

// ---------------------------------------------------------------------------------------
// Monte Carlo

bool FovSimulatedPoint::AllConsistent() const {
  for (bool c : consistent)
    if (!c) return false;
  return true;
}

std::vector<size_t> PickSimulationPoints(const FovMap& map, int points) {
  std::vector<size_t> trackable;
  for (size_t i = 0; i < map.points.size(); ++i)
    if (map.points[i].prediction.trackable) trackable.push_back(i);
  std::vector<size_t> out;
  if (trackable.empty() || points <= 0) return out;
  const size_t n = std::min(trackable.size(), static_cast<size_t>(points));
  for (size_t k = 0; k < n; ++k) {
    // Evenly spread, the ends excluded unless one point only (the middle then).
    const double f = (k + 1.0) / (n + 1.0);
    out.push_back(trackable[static_cast<size_t>(std::floor(f * (trackable.size() - 1) + 0.5))]);
  }
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

bool FovSimulationOptions::IsValid(std::string* why) const {
  std::string w;
  if (repeats < 2)
    w = "--repeats: the Monte Carlo needs at least 2 repeats per point, got " + std::to_string(repeats);
  else if (points < 1)
    w = "--points: at least 1 point, got " + std::to_string(points);
  else if (threads < 0 || threads > kMaxThreads)
    w = "threads must be 0 to " + std::to_string(kMaxThreads) + ", got " + std::to_string(threads);
  else if (std::string t; !tracker.IsValid(&t))
    w = "tracker options: " + t;
  if (why) *why = w;
  return w.empty();
}

std::vector<FovSimulatedPoint> SimulateFovPoints(const FovMap& map, const std::vector<size_t>& grid_indices,
                                                 const FovSimulationOptions& options,
                                                 const std::function<void(size_t, size_t)>& progress) {
  if (std::string why; !options.IsValid(&why)) Throw(why);
  for (size_t i : grid_indices)
    MCMS_CHECK(i < map.points.size(), "SimulateFovPoints: grid index out of range");
  std::vector<FovSimulatedPoint> out(grid_indices.size());
  if (grid_indices.empty()) return out;
  Scenario sc;
  sc.rig = map.rig;
  sc.target = map.target;
  sc.render = map.options.noise.render;
  sc.seed = options.seed;
  const size_t R = static_cast<size_t>(options.repeats);
  for (size_t k = 0; k < grid_indices.size(); ++k)
    for (size_t r = 0; r < R; ++r) {
      sc.times.push_back(10.0 * static_cast<double>(sc.times.size()));
      sc.T_rig_target.push_back(map.points[grid_indices[k]].prediction.T_rig_target);
    }
  TrackerOptions topts = options.tracker;
  if (topts.detector.gain_e_per_dn == 0) topts.detector.gain_e_per_dn = map.options.noise.Detector().gain_e_per_dn;
  const ScenarioRenderer renderer(sc, options.threads);
  std::vector<std::optional<Vec6>> errors(sc.NumFrames());
  ParallelFor(
      sc.NumFrames(), options.threads,
      [&](size_t f) {
        const RenderedFrame fr = renderer.Render(f);
        Tracker tracker(map.rig, map.target, topts);
        const FrameResult res = tracker.ProcessFrame(f, sc.times[f], fr.images);
        if (res.status != FrameStatus::kLost && res.T_rig_target) errors[f] = BoxMinus(*res.T_rig_target, sc.T_rig_target[f]);
      },
      progress);
  for (size_t k = 0; k < grid_indices.size(); ++k) {
    FovSimulatedPoint& s = out[k];
    const FovMapPoint& mp = map.points[grid_indices[k]];
    s.grid_index = grid_indices[k];
    s.p_rig = mp.p_rig;
    s.predicted_sigma_p = mp.sigma_p();
    s.predicted_sigma_r = mp.sigma_r();
    std::vector<Vec6> e;
    for (size_t r = 0; r < R; ++r)
      if (errors[k * R + r]) e.push_back(*errors[k * R + r]);
    s.tracked = static_cast<int>(e.size());
    s.lost = static_cast<int>(R) - s.tracked;
    if (e.size() < 2) {
      s.simulated_sigma_p = s.simulated_sigma_r = Vec3::Constant(kNaN);
      continue;
    }
    Vec6 mean = Vec6::Zero();
    for (const Vec6& v : e) mean += v;
    mean /= static_cast<double>(e.size());
    Vec6 var = Vec6::Zero();
    for (const Vec6& v : e) var += (v - mean).cwiseAbs2();
    var /= static_cast<double>(e.size() - 1);
    s.simulated_sigma_r = var.head<3>().cwiseSqrt();
    s.simulated_sigma_p = var.tail<3>().cwiseSqrt();
    s.mean_error_p = mean.tail<3>();
    const double dof = static_cast<double>(e.size() - 1);
    const double lo = ChiSquareQuantile(0.005, dof), hi = ChiSquareQuantile(0.995, dof);
    const Vec6 pred = mp.prediction.cov.diagonal();
    for (int a = 0; a < 6; ++a) {
      // Position axes first in the report (x, y, z, rx, ry, rz); the covariance is [r; p].
      const int c = a < 3 ? a + 3 : a - 3;
      const double stat = dof * var[c] / pred[c];
      s.consistent[a] = std::isfinite(stat) && stat >= lo && stat <= hi;
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------
// Output

namespace {
std::string Fmt(double v, int prec = 5) {
  if (!std::isfinite(v)) return "";
  char b[64];
  std::snprintf(b, sizeof(b), "%.*g", prec, v);
  return b;
}
constexpr double kMdegPerRad = 180e3 / std::numbers::pi;
}  // namespace

std::string FovMapSummary(const FovMap& map) {
  std::ostringstream o;
  const double thr = map.options.threshold_mm * 1e-3;
  size_t trackable = 0, below = 0;
  Vec3 lo = Vec3::Constant(INFINITY), hi = Vec3::Constant(-INFINITY);
  const FovMapPoint* best = nullptr;
  const FovMapPoint* worst = nullptr;
  for (const auto& p : map.points) {
    if (!p.prediction.trackable) continue;
    ++trackable;
    if (!best || p.sigma_d() < best->sigma_d()) best = &p;
    if (!worst || p.sigma_d() > worst->sigma_d()) worst = &p;
    if (p.sigma_d() < thr) {
      ++below;
      lo = lo.cwiseMin(p.p_rig);
      hi = hi.cwiseMax(p.p_rig);
    }
  }
  char b[512];
  std::snprintf(b, sizeof(b), "grid %s (rig frame, m): %zu points, %zu trackable (%.1f %%)\n",
                map.options.grid.ToString().c_str(), map.points.size(), trackable,
                map.points.empty() ? 0.0 : 100.0 * trackable / map.points.size());
  o << b;
  if (best) {
    const Vec3 sb = best->sigma_p() * 1e3, sw = worst->sigma_p() * 1e3;
    std::snprintf(b, sizeof(b), "best  sigma_d %.4f mm at (%.3f, %.3f, %.3f) m: sigma_x,y,z %.4f %.4f %.4f mm\n",
                  best->sigma_d() * 1e3, best->p_rig.x(), best->p_rig.y(), best->p_rig.z(), sb.x(), sb.y(), sb.z());
    o << b;
    std::snprintf(b, sizeof(b), "worst sigma_d %.4f mm at (%.3f, %.3f, %.3f) m: sigma_x,y,z %.4f %.4f %.4f mm\n",
                  worst->sigma_d() * 1e3, worst->p_rig.x(), worst->p_rig.y(), worst->p_rig.z(), sw.x(), sw.y(), sw.z());
    o << b;
  }
  if (below > 0) {
    std::snprintf(b, sizeof(b),
                  "sigma_d < %g mm at %zu of %zu grid points (%.1f %%), within x [%.3f, %.3f], y [%.3f, %.3f], z [%.3f, %.3f] m\n",
                  map.options.threshold_mm, below, map.points.size(), 100.0 * below / map.points.size(), lo.x(), hi.x(),
                  lo.y(), hi.y(), lo.z(), hi.z());
  } else {
    std::snprintf(b, sizeof(b), "sigma_d < %g mm nowhere on the grid\n", map.options.threshold_mm);
  }
  o << b;
  return o.str();
}

void WriteFovMap(const FovMap& map, const fs::path& dir, const std::vector<FovSimulatedPoint>& simulated) {
  fs::create_directories(dir);
  const size_t nc = map.rig.size();
  const double thr = map.options.threshold_mm * 1e-3;
  WriteFileAtomically(dir / "map.csv", [&](std::ostream& o) {
    o << "x_m,y_m,z_m,sigma_x_mm,sigma_y_mm,sigma_z_mm,sigma_d_mm,sigma_rx_mdeg,sigma_ry_mdeg,sigma_rz_mdeg,"
         "ball_sigma_d_mm,trackable,below_threshold,cameras,observations,balls_triangulated";
    for (size_t c = 0; c < nc; ++c) o << ",balls_" << map.rig.names[c];
    o << ",centre_sigma_px,ball_minor_axis_px,min_border_px,mean_distance_m\n";
    for (const auto& p : map.points) {
      const Vec3 sp = p.sigma_p() * 1e3, sr = p.sigma_r() * kMdegPerRad;
      int tri = 0;
      for (const auto& b : p.prediction.balls) tri += b.triangulated;
      o << Fmt(p.p_rig.x(), 9) << "," << Fmt(p.p_rig.y(), 9) << "," << Fmt(p.p_rig.z(), 9) << "," << Fmt(sp.x()) << ","
        << Fmt(sp.y()) << "," << Fmt(sp.z()) << "," << Fmt(p.sigma_d() * 1e3) << "," << Fmt(sr.x()) << "," << Fmt(sr.y())
        << "," << Fmt(sr.z()) << "," << Fmt(p.mean_ball_sigma_d() * 1e3) << "," << (p.prediction.trackable ? 1 : 0) << ","
        << (p.prediction.trackable && p.sigma_d() < thr ? 1 : 0) << "," << p.prediction.CamerasSeeing() << ","
        << p.prediction.observations << "," << tri;
      for (size_t c = 0; c < nc; ++c) o << "," << p.prediction.balls_in_camera[c];
      o << "," << Fmt(p.prediction.mean_centre_sigma_px) << "," << Fmt(p.prediction.mean_ball_px) << ","
        << Fmt(p.prediction.min_border_px, 4) << "," << Fmt(p.mean_distance_m) << "\n";
    }
  });

  // One heat map per z plane of the grid, and one x and one y slice through the middle of
  // the grid (vertical sections: z against y, z against x), all on one colour scale.
  const FovGrid& g = map.options.grid;
  double vmin = INFINITY, vmax = -INFINITY;
  for (const auto& p : map.points)
    if (p.prediction.trackable) vmin = std::min(vmin, p.sigma_d() * 1e3), vmax = std::max(vmax, p.sigma_d() * 1e3);
  const char* axis_name[3] = {"x", "y", "z"};
  // The slice where axis `fixed` is at grid index `at`; its horizontal axis is the first
  // of the other two, its vertical the second.
  const auto slice = [&](int fixed, int at, const fs::path& file) {
    const int u = fixed == 0 ? 1 : 0, v = fixed == 2 ? 1 : 2;
    HeatMap h;
    char title[200];
    std::snprintf(title, sizeof(title), "Predicted sigma_d of the target position, plane %s = %.3f m", axis_name[fixed],
                  g.Coord(fixed, at));
    h.title = title;
    h.x_label = std::string(axis_name[u]).append(" (m, rig frame)");
    h.y_label = std::string(axis_name[v]).append(" (m, rig frame)");
    h.value_label = "sigma_d (mm)";
    for (int i = 0; i < g.n[u]; ++i) h.x.push_back(g.Coord(u, i));
    for (int i = 0; i < g.n[v]; ++i) h.y.push_back(g.Coord(v, i));
    int idx[3];
    idx[fixed] = at;
    for (int iv = 0; iv < g.n[v]; ++iv)
      for (int iu = 0; iu < g.n[u]; ++iu) {
        idx[u] = iu, idx[v] = iv;
        const auto& p = map.points[(static_cast<size_t>(idx[2]) * g.n[1] + idx[1]) * g.n[0] + idx[0]];
        h.values.push_back(p.prediction.trackable ? p.sigma_d() * 1e3 : kNaN);
      }
    if (std::isfinite(vmin)) {
      h.vmin = vmin;
      h.vmax = vmax;
      h.log_scale = vmax > 5 * vmin;
    }
    h.threshold = map.options.threshold_mm;
    h.WriteSvg(file);
  };
  for (int iz = 0; iz < g.n[2]; ++iz) {
    char name[64];
    std::snprintf(name, sizeof(name), "heatmap_z%02d.svg", iz);
    slice(2, iz, dir / name);
  }
  slice(0, (g.n[0] - 1) / 2, dir / "heatmap_x_centre.svg");
  slice(1, (g.n[1] - 1) / 2, dir / "heatmap_y_centre.svg");

  Plot plot;
  plot.title = "Predicted precision against the mean distance to the cameras that see the target";
  plot.x_label = "mean distance from the cameras (m)";
  plot.y_label = "sigma (mm)";
  PlotSeries sd{"sigma_d", {}, {}, "#1f77b4", true}, sz{"sigma_z", {}, {}, "#ff7f0e", true},
      sx{"sigma_x", {}, {}, "#2ca02c", true};
  for (const auto& p : map.points) {
    if (!p.prediction.trackable) continue;
    const Vec3 s = p.sigma_p() * 1e3;
    sd.x.push_back(p.mean_distance_m), sd.y.push_back(p.sigma_d() * 1e3);
    sz.x.push_back(p.mean_distance_m), sz.y.push_back(s.z());
    sx.x.push_back(p.mean_distance_m), sx.y.push_back(s.x());
  }
  plot.series = {sd, sz, sx};
  plot.WriteSvg(dir / "sigma_vs_distance.svg");

  const std::string summary = FovMapSummary(map);
  WriteFileAtomically(dir / "region.txt", [&](std::ostream& o) {
    o << "# Predicted precision of " << map.rig.size() << " cameras tracking target '" << map.target.name << "'\n";
    o << summary;
    o << "# grid points below the threshold (x_m,y_m,z_m,sigma_d_mm):\n";
    for (const auto& p : map.points)
      if (p.prediction.trackable && p.sigma_d() < thr)
        o << Fmt(p.p_rig.x(), 9) << "," << Fmt(p.p_rig.y(), 9) << "," << Fmt(p.p_rig.z(), 9) << "," << Fmt(p.sigma_d() * 1e3)
          << "\n";
  });

  if (simulated.empty()) return;
  WriteFileAtomically(dir / "simulated.csv", [&](std::ostream& o) {
    o << "x_m,y_m,z_m,tracked,lost,pred_sigma_x_mm,pred_sigma_y_mm,pred_sigma_z_mm,pred_sigma_d_mm,"
         "sim_sigma_x_mm,sim_sigma_y_mm,sim_sigma_z_mm,sim_sigma_d_mm,pred_sigma_rx_mdeg,pred_sigma_ry_mdeg,"
         "pred_sigma_rz_mdeg,sim_sigma_rx_mdeg,sim_sigma_ry_mdeg,sim_sigma_rz_mdeg,mean_err_x_mm,mean_err_y_mm,"
         "mean_err_z_mm,consistent_99pct\n";
    for (const auto& s : simulated) {
      const Vec3 pp = s.predicted_sigma_p * 1e3, sp = s.simulated_sigma_p * 1e3;
      const Vec3 pr = s.predicted_sigma_r * kMdegPerRad, sr = s.simulated_sigma_r * kMdegPerRad;
      o << Fmt(s.p_rig.x(), 9) << "," << Fmt(s.p_rig.y(), 9) << "," << Fmt(s.p_rig.z(), 9) << "," << s.tracked << ","
        << s.lost;
      for (double v : {pp.x(), pp.y(), pp.z(), pp.norm(), sp.x(), sp.y(), sp.z(), sp.norm(), pr.x(), pr.y(), pr.z(), sr.x(),
                       sr.y(), sr.z(), s.mean_error_p.x() * 1e3, s.mean_error_p.y() * 1e3, s.mean_error_p.z() * 1e3})
        o << "," << Fmt(v);
      o << "," << (s.AllConsistent() ? 1 : 0) << "\n";
    }
  });
  Plot sp;
  sp.title = "Predicted (Cramer-Rao) against Monte-Carlo sigma of the tracked position";
  sp.x_label = "predicted sigma (mm)";
  sp.y_label = "simulated sigma (mm)";
  PlotSeries px{"x", {}, {}, "#2ca02c", true}, py{"y", {}, {}, "#1f77b4", true}, pz{"z", {}, {}, "#ff7f0e", true},
      diag{"simulated = predicted", {}, {}, "#888888", false};
  double top = 0;
  for (const auto& s : simulated) {
    for (int a = 0; a < 3; ++a) {
      PlotSeries& ser = a == 0 ? px : a == 1 ? py : pz;
      ser.x.push_back(s.predicted_sigma_p[a] * 1e3);
      ser.y.push_back(s.simulated_sigma_p[a] * 1e3);
      if (std::isfinite(s.simulated_sigma_p[a])) top = std::max(top, 1e3 * std::max(s.predicted_sigma_p[a], s.simulated_sigma_p[a]));
    }
  }
  diag.x = {0, top};
  diag.y = {0, top};
  sp.series = {diag, px, py, pz};
  sp.WriteSvg(dir / "simulated.svg", 640, 520);
}

}  // namespace mcms
