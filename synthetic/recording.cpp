#include "synthetic/recording.h"

#include <numbers>
#include <cstdio>
#include <fstream>
#include <limits>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "core/limits.h"
#include "core/error.h"
#include "core/io.h"
#include "core/parallel.h"
#include "core/output_folder.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {
double AngleBetween(const Vec3& a, const Vec3& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }
}  // namespace

namespace {
// The truth of a frame and, per camera, which balls the occlusion option hid (the
// truth lists only balls in front of a camera; the renderer needs all).
FrameTruth ComputeTruth(const Scenario& s, size_t frame, std::vector<std::vector<char>>* hidden_per_camera) {
  if (frame >= s.times.size() || frame >= s.T_rig_target.size())
    throw std::out_of_range("FrameTruthOf: frame " + std::to_string(frame) + " of " + std::to_string(s.times.size()));
  const RenderOptions& o = s.render;
  const double r = s.target.ball_radius;
  FrameTruth t;
  if (hidden_per_camera) hidden_per_camera->assign(s.rig.size(), {});
  t.frame = frame;
  t.time_s = s.times[frame];
  t.T_rig_target = s.T_rig_target[frame];
  for (const Vec3& b : s.target.balls_target) t.balls_rig.push_back(t.T_rig_target * b);
  const size_t nb = t.balls_rig.size();
  // Keep spurious discs clear of the balls' blurred images and of each other.
  const double clearance = 3.0 + 3.0 * o.blur_sigma_px;

  for (size_t ci = 0; ci < s.rig.size(); ++ci) {
    const CameraModel& cam = s.rig.cameras[ci];
    const int cam_id = static_cast<int>(ci);
    // Every draw happens whatever the probabilities, so changing one option does
    // not reshuffle the other events.
    Rng events(StreamSeed(s.seed, frame, ci, 0));
    if (events.Uniform() < o.dropout_probability) {
      t.dropped_cameras.push_back(cam_id);
      continue;
    }
    std::vector<char> hidden(nb);
    for (size_t b = 0; b < nb; ++b) hidden[b] = events.Uniform() < o.occlusion_probability;
    if (hidden_per_camera) (*hidden_per_camera)[ci] = hidden;

    std::vector<Vec3> p(nb);
    std::vector<char> in_front(nb, 0);
    std::vector<BallTruth> obs(nb);
    for (size_t b = 0; b < nb; ++b) {
      p[b] = cam.T_cam_rig() * t.balls_rig[b];
      const double d = p[b].norm();
      if (!(d > r)) continue;
      const double off_axis = AngleBetween(p[b] / d, Vec3::UnitZ());
      if (!cam.CanProjectBehindCamera() && off_axis + std::asin(r / d) >= std::numbers::pi / 2 - 1e-6) continue;
      in_front[b] = 1;
      BallTruth& bt = obs[b];
      bt.camera = cam_id;
      bt.ball = static_cast<int>(b);
      bt.hidden = hidden[b];
      bt.centre_px = cam.Project(p[b]);
      bt.centroid_px = SphereImageCentroid(cam, p[b], r);
      const auto outline = SphereOutline(cam, p[b], r);
      bt.ellipse = EllipseFromOutline(outline);
      bool inside = !outline.empty();
      for (const Vec2& q : outline)
        inside = inside && q.allFinite() && q.x() >= -0.5 && q.y() >= -0.5 && q.x() <= cam.Width() - 0.5 &&
                 q.y() <= cam.Height() - 0.5;
      // A lens model folds back beyond its valid field: a ball far outside the view
      // can project into the image. The ray of its image point must lead back to it.
      if (inside) {
        const auto ray = cam.Unproject(bt.centre_px);
        inside = ray && AngleBetween(*ray, p[b]) < 1e-6;
      }
      bt.visible = inside;
    }
    // A nearer, not hidden ball whose image overlaps covers part of a farther one.
    for (size_t a = 0; a < nb; ++a)
      for (size_t b = 0; b < nb; ++b) {
        if (a == b || !in_front[a] || !in_front[b] || hidden[a]) continue;
        if (p[a].norm() >= p[b].norm()) continue;
        const double sep = AngleBetween(p[a], p[b]);
        if (sep < std::asin(r / p[a].norm()) + std::asin(r / p[b].norm())) obs[b].overlapped = true;
      }
    for (size_t b = 0; b < nb; ++b)
      if (in_front[b]) t.observations.push_back(obs[b]);

    const int n_spurious = static_cast<int>(events.Poisson(o.spurious_per_image));
    std::vector<SpuriousTruth> placed;
    for (int k = 0; k < n_spurious; ++k) {
      // Rejection sampling; a reflection that finds no free place in 100 tries is
      // dropped (only in images crowded far beyond any useful setting).
      for (int attempt = 0; attempt < 100; ++attempt) {
        const double rad = events.Uniform(o.spurious_radius_min_px, o.spurious_radius_max_px);
        const double u = events.Uniform(rad, cam.Width() - 1 - rad);
        const double v = events.Uniform(rad, cam.Height() - 1 - rad);
        const Vec2 q(u, v);
        if (u < rad || v < rad || u > cam.Width() - 1 - rad || v > cam.Height() - 1 - rad) continue;
        bool free = true;
        for (size_t b = 0; b < nb && free; ++b)
          if (in_front[b] && !hidden[b] && obs[b].centroid_px.allFinite())
            free = (q - obs[b].ellipse.centre).norm() > obs[b].ellipse.a + rad + clearance;
        for (const auto& sp : placed)
          if (free) free = (q - sp.centre_px).norm() > sp.radius_px + rad + clearance;
        if (free) {
          placed.push_back({cam_id, q, rad});
          break;
        }
      }
    }
    t.spurious.insert(t.spurious.end(), placed.begin(), placed.end());
  }
  return t;
}
}  // namespace

FrameTruth FrameTruthOf(const Scenario& scenario, size_t frame) { return ComputeTruth(scenario, frame, nullptr); }

ScenarioRenderer::ScenarioRenderer(const Scenario& scenario, int threads)
    : scenario_(std::make_unique<const Scenario>(scenario)) {
  std::string why;
  if (!scenario_->IsValid(&why)) Throw("scenario: ", why);
  const double pad = RenderPadPx(scenario_->render) + 2.0;
  std::vector<std::optional<RayTable>> tables(scenario_->rig.size());
  ParallelFor(tables.size(), threads, [&](size_t c) { tables[c].emplace(scenario_->rig.cameras[c], pad); });
  for (auto& t : tables) tables_.push_back(std::move(*t));
}

ScenarioRenderer::~ScenarioRenderer() = default;

RenderedFrame ScenarioRenderer::Render(size_t frame) const {
  const Scenario& s = *scenario_;
  RenderedFrame out;
  std::vector<std::vector<char>> hidden;
  out.truth = ComputeTruth(s, frame, &hidden);
  out.images.resize(s.rig.size());
  for (size_t ci = 0; ci < s.rig.size(); ++ci) {
    const int cam_id = static_cast<int>(ci);
    if (std::find(out.truth.dropped_cameras.begin(), out.truth.dropped_cameras.end(), cam_id) !=
        out.truth.dropped_cameras.end())
      continue;
    const CameraModel& cam = s.rig.cameras[ci];
    std::vector<Vec3> centres;
    for (size_t b = 0; b < out.truth.balls_rig.size(); ++b)
      if (!hidden[ci][b]) centres.push_back(cam.T_cam_rig() * out.truth.balls_rig[b]);
    std::vector<ImageDisc> discs;
    for (const SpuriousTruth& sp : out.truth.spurious)
      if (sp.camera == cam_id) discs.push_back({sp.centre_px, sp.radius_px, s.render.spurious_dn});
    Rng noise(StreamSeed(s.seed, frame, ci, 1));
    out.images[ci] = RenderSpheres(tables_[ci], centres, s.target.ball_radius, s.render, &noise, discs);
  }
  return out;
}

RenderedFrame RenderFrame(const Scenario& scenario, size_t frame) {
  return ScenarioRenderer(scenario).Render(frame);
}

// ---------------------------------------------------------------------------------
// Output folder

namespace {

std::string Fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  out.flush();
  if (!out) Throw("cannot write output file ", path.string());
}

void WriteTruth(const Scenario& s, const std::vector<FrameTruth>& truths, const fs::path& dir) {
  std::ostringstream frames, poses, balls, obs, spurious, drops;
  frames << "frame,time_s\n";
  poses << "frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz\n";
  balls << "frame,ball,x_m,y_m,z_m\n";
  obs << "frame,camera,ball,visible,occluded,u_centre_px,v_centre_px,u_centroid_px,v_centroid_px,"
         "ellipse_a_px,ellipse_b_px,ellipse_angle_rad\n";
  spurious << "frame,camera,u_px,v_px,radius_px\n";
  drops << "frame,camera\n";
  for (const FrameTruth& t : truths) {
    const std::string f = std::to_string(t.frame) + ",";
    frames << f << Fmt("%.9f", t.time_s) << "\n";
    const Eigen::Quaterniond q = t.T_rig_target.Quaternion();
    poses << f << Fmt("%.9f", t.time_s);
    for (double v : {t.T_rig_target.t.x(), t.T_rig_target.t.y(), t.T_rig_target.t.z()}) poses << Fmt(",%.9f", v);
    for (double v : {q.w(), q.x(), q.y(), q.z()}) poses << Fmt(",%.12f", v);
    poses << "\n";
    for (size_t b = 0; b < t.balls_rig.size(); ++b) {
      balls << f << b;
      for (int k = 0; k < 3; ++k) balls << Fmt(",%.9f", t.balls_rig[b][k]);
      balls << "\n";
    }
    for (const BallTruth& o : t.observations) {
      obs << f << s.rig.names[o.camera] << "," << o.ball << "," << int(o.visible) << "," << int(o.occluded());
      for (double v : {o.centre_px.x(), o.centre_px.y(), o.centroid_px.x(), o.centroid_px.y(), o.ellipse.a,
                       o.ellipse.b})
        obs << Fmt(",%.6f", v);
      obs << Fmt(",%.9f", o.ellipse.angle) << "\n";
    }
    for (const SpuriousTruth& sp : t.spurious)
      spurious << f << s.rig.names[sp.camera] << Fmt(",%.6f", sp.centre_px.x()) << Fmt(",%.6f", sp.centre_px.y())
               << Fmt(",%.6f", sp.radius_px) << "\n";
    for (int c : t.dropped_cameras) drops << f << s.rig.names[c] << "\n";
  }
  WriteText(dir / "frames.csv", frames.str());
  WriteText(dir / "truth" / "poses.csv", poses.str());
  WriteText(dir / "truth" / "balls.csv", balls.str());
  WriteText(dir / "truth" / "observations.csv", obs.str());
  WriteText(dir / "truth" / "spurious.csv", spurious.str());
  WriteText(dir / "truth" / "dropouts.csv", drops.str());
}

}  // namespace

void RenderSequence(const Scenario& scenario, const fs::path& out_dir, bool quiet, int threads, ImageFileFormat format) {
  std::string why;
  if (!scenario.IsValid(&why)) Throw("scenario: ", why);
  if (out_dir.empty()) Throw("render: no output folder given");
  for (size_t c = 0; c < scenario.rig.size(); ++c) {
    const CameraModel& cam = scenario.rig.cameras[c];
    const double px = static_cast<double>(cam.Width()) * cam.Height();
    if (px > kMaxRenderPixels)
      Throw("render: camera ", scenario.rig.names[c], "'s image is ", cam.Width(), " x ", cam.Height(), " px (", px,
            " px); at most ", kMaxRenderPixels, " px per image are rendered (the scenario's imagersize)");
  }
  // An earlier render (absent, empty, or holding these) may be replaced.
  const std::vector<std::string> markers = {"scenario.yaml", "truth", "images"};
  WriteFolderAtomically(out_dir, markers, "render", "render output", [&](const fs::path& tmp) {
    fs::create_directories(tmp / "truth");
    fs::create_directories(tmp / "cameras");
    for (const auto& name : scenario.rig.names) fs::create_directories(tmp / "images" / name);
    scenario.Write(tmp / "scenario.yaml");
    scenario.rig.Write(tmp / "rig.yaml");
    for (size_t c = 0; c < scenario.rig.size(); ++c)
      scenario.rig.cameras[c].WriteCameramodel(tmp / "cameras" / (scenario.rig.names[c] + ".cameramodel"));
    scenario.target.Write(tmp / "target.yaml");

    threads = std::max(threads, 1);
    const ScenarioRenderer renderer(scenario, threads);
    const size_t n = scenario.times.size();
    std::vector<FrameTruth> truths(n);
    Progress progress("render", n, quiet);
    std::mutex m;
    size_t done = 0;
    ParallelFor(n, threads, [&](size_t f) {
      RenderedFrame r = renderer.Render(f);
      char name[32];
      std::snprintf(name, sizeof(name), "%06zu%s", f, ExtensionOf(format));
      for (size_t c = 0; c < r.images.size(); ++c)
        if (!r.images[c].empty()) WriteImageFile(tmp / "images" / scenario.rig.names[c] / name, r.images[c], format);
      std::lock_guard<std::mutex> lock(m);
      truths[f] = std::move(r.truth);
      progress.Update(++done);
    });
    progress.Finish();
    WriteTruth(scenario, truths, tmp);
  });
}

}  // namespace mcms
