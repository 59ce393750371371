// mcms audit cameras: track a recording, test every camera against the rest of the rig and
// name what the camera model gets wrong from the catalog of model/extensions.h
// (tracking/camera_audit.h); optionally write the report as JSON, the extended rig and the
// extended target.
#include <cmath>
#include <cstdio>

#include "app/audit_modes.h"
#include "app/tracking_options.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "tracking/audit.h"
#include "tracking/camera_audit.h"
#include "tracking/noise_estimate.h"
#include "tracking/sequence.h"

namespace mcms::app {
namespace {

struct AuditArgs {
  std::string dir, repaired, repaired_target, json, output;
  CameraAuditOptions audit;
  double rate = 10.0;
  bool quiet = false;
  TrackerCli tracker;
};

// report.txt, report.json, residuals.csv (every camera's whitened leave-one-out residuals
// with their covariates) and plots/<camera>.svg: the residuals against each covariate the
// audit tests, and as vectors over the image.
void WriteResidualOutput(const std::filesystem::path& out, const CameraRig& rig, const CameraAuditResult& audit) {
  WriteFileAtomically(out / "report.txt", [&](std::ostream& os) { os << audit.report.Text(); });
  WriteFileAtomically(out / "residuals.csv", [&](std::ostream& os) {
    os << "camera,ball,time_s,u_px,v_px,radius_px,range_m,w_u,w_v\n";
    char b[256];
    for (size_t c = 0; c < audit.residuals.size(); ++c)
      for (const auto& r : audit.residuals[c]) {
        std::snprintf(b, sizeof b, ",%d,%.9g,%.4f,%.4f,%.4f,%.6f,%.6f,%.6f\n", r.ball + 1, r.time_s, r.q.x(), r.q.y(),
                      r.radius_px, r.range_m, r.w.x(), r.w.y());
        os << rig.names[c] << b;
      }
  });
  std::filesystem::create_directories(out / "plots");
  for (size_t c = 0; c < audit.residuals.size(); ++c) {
    const auto& rs = audit.residuals[c];
    if (rs.empty()) continue;
    struct Axis {
      std::string label;
      std::function<double(const WhitenedResidual&)> of;
    };
    const std::vector<Axis> axes = {{"time (s)", [](const WhitenedResidual& r) { return r.time_s; }},
                                    {"distance from the image centre (px)", [](const WhitenedResidual& r) { return r.radius_px; }},
                                    {"distance to the camera (m)", [](const WhitenedResidual& r) { return r.range_m; }},
                                    {"image u (px)", [](const WhitenedResidual& r) { return r.q.x(); }},
                                    {"image v (px)", [](const WhitenedResidual& r) { return r.q.y(); }}};
    std::vector<Plot> plots;
    for (const auto& ax : axes) {
      Plot p;
      p.title = rig.names[c] + ": whitened residual vs " + ax.label.substr(0, ax.label.find(" ("));
      p.x_label = ax.label;
      p.y_label = "whitened residual (sigma)";
      PlotSeries u{"u", {}, {}, "#1f77b4", true}, v{"v", {}, {}, "#d62728", true};
      for (const auto& r : rs) {
        u.x.push_back(ax.of(r));
        u.y.push_back(r.w.x());
        v.x.push_back(ax.of(r));
        v.y.push_back(r.w.y());
      }
      p.series = {u, v};
      plots.push_back(p);
    }
    Plot img;
    // One sigma drawn as 1 % of the image width.
    const double per_sigma_px = 0.01 * rig.cameras[c].Width();
    char title[160];
    std::snprintf(title, sizeof title, "%s: whitened residuals over the image (%.3g px per sigma)", rig.names[c].c_str(),
                  per_sigma_px);
    img.title = title;
    img.x_label = "u (px)";
    img.y_label = "v (px)";
    img.y_down = img.equal_scale = true;
    img.x_range = std::make_pair(0.0, double(rig.cameras[c].Width()));
    img.y_range = std::make_pair(0.0, double(rig.cameras[c].Height()));
    PlotSeries vec{"residual", {}, {}, "#1f77b4", false};
    for (const auto& r : rs) {
      vec.x.push_back(r.q.x());
      vec.y.push_back(r.q.y());
      vec.dx.push_back(r.w.x());
      vec.dy.push_back(r.w.y());
    }
    vec.vector_scale = per_sigma_px;
    img.series = {vec};
    plots.push_back(img);
    WritePlotGridSvg(out / "plots" / (rig.names[c] + ".svg"), plots, 2);
  }
  audit.report.WriteJson(out / "report.json");
}

int RunAudit(const AuditArgs& a) {
  namespace fs = std::filesystem;
  const fs::path dir = a.dir;
  if (!a.repaired.empty()) RequireWritableFile(a.repaired, "audit --repaired-rig");
  if (!a.repaired_target.empty()) RequireWritableFile(a.repaired_target, "audit --repaired-target");
  if (!a.json.empty()) RequireWritableFile(a.json, "audit --json");
  if (!a.output.empty()) RequireReplaceableFolder(a.output, {"report.json"}, "audit cameras", "audit cameras -o");
  const CameraRig rig = CameraRig::Read(dir / "rig.yaml");
  const Target target = Target::Read(dir / "target.yaml");
  const ImageSequence seq = ScanImageSequence({dir / "images", dir / "frames.csv", a.rate}, rig);
  std::vector<std::string> notes;
  Tracker tracker(rig, target, a.tracker.Settings().Options(seq, rig, &notes));
  for (const auto& line : notes) std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  Progress progress("track", seq.frames.size(), a.quiet);
  const auto results = TrackImageSequence(
      seq, tracker, [&](size_t d, size_t) { progress.Update(d); }, a.tracker.Threads());
  progress.Finish();
  std::printf("%s\n", CheckPoseResiduals(results).Describe().c_str());
  const CameraAuditResult audit = AuditCameraModel(rig, target, results, a.audit, [&](const std::string& line) {
    if (!a.quiet) std::fprintf(stderr, "audit: %s\n", line.c_str());
  });
  std::printf("%s", audit.report.Text().c_str());
  if (audit.report.effects.empty() && audit.report.undecided.empty())
    std::printf("every camera is consistent with the rest of the rig\n");
  if (!a.json.empty()) {
    audit.report.WriteJson(a.json);
    std::printf("wrote the audit report to %s\n", a.json.c_str());
  }
  if (!a.output.empty()) {
    WriteFolderAtomically(a.output, {"report.json"}, "audit cameras", "audit cameras -o",
                          [&](const fs::path& out) { WriteResidualOutput(out, rig, audit); });
    std::printf("wrote the report, the whitened residuals and their plots to %s\n", a.output.c_str());
  }
  bool noise = false, target_changes = false;
  for (const auto& t : audit.terms) {
    noise = noise || t.extension.effect == Effect::kPixelNoiseScale;
    target_changes = target_changes || (t.extension.effect == Effect::kTargetGeometry && !t.undecided);
  }
  // Every repaired file asked for is checked before any is written.
  if (!a.repaired.empty() && !audit.report.effects.empty()) {
    if (!audit.ChangesRig()) {
      if (noise)
        Throw("the residuals are larger than the pixel noise model predicts (pixel_noise_scale) and no change of the "
              "rig explains them: check --gain and --read-noise (or leave them out to measure the noise); no "
              "repaired rig written");
      Throw("the effects found (time offset, target geometry) cannot be written into a rig; no repaired rig written");
    }
  }
  if (!a.repaired_target.empty() && !audit.report.effects.empty() && !target_changes)
    Throw("--repaired-target: no target_geometry effect was named (the effects found belong to the cameras or the "
          "noise model); no repaired target written");
  if (!a.repaired_target.empty() && target_changes) {
    audit.ExtendedTarget(target).Write(a.repaired_target);
    std::printf("wrote the target with the ball positions found to %s\n", a.repaired_target.c_str());
  }
  if (!a.repaired_target.empty() && audit.report.effects.empty())
    std::printf("no effect named: no repaired target written (%s)\n", a.repaired_target.c_str());
  if (!a.repaired.empty() && audit.ChangesRig()) {
    audit.ExtendedRig(rig).Write(a.repaired);
    std::printf("wrote the rig extended by the effects found to %s\n", a.repaired.c_str());
    for (const auto& t : audit.terms) {
      const Effect e = t.extension.effect;
      if (e == Effect::kCameraTimeOffset || e == Effect::kPixelNoiseScale || e == Effect::kTargetGeometry)
        std::printf("  not in the rig file: %s\n", t.extension.Label(rig.names).c_str());
      if (e == Effect::kCameraMoved && std::isfinite(t.from_time_s))
        std::printf("  %s: the rig has its pose after the move (from t = %.3f s)\n", rig.names[t.extension.index].c_str(),
                    t.from_time_s);
    }
  }
  return 0;
}

}  // namespace

std::pair<CLI::App*, Runner> AddAuditCameras(CLI::App& audit) {
  auto args = std::make_shared<AuditArgs>();
  CLI::App* cmd = audit.add_subcommand(
      "cameras",
      "Track a recording (as `mcms track`) and audit the camera model: every camera is tested against the rest of the "
      "rig (leave-one-camera-out residuals, chi-square), then the catalog of model extensions is fitted camera by "
      "camera and ball by ball (pixel_noise_scale first, camera_moved, also from a change time on, focal_length, "
      "principal_point, radial_distortion, camera_time_offset, target_geometry), scored on held-out blocks of time "
      "and by BIC; greedy forward selection names the effects that earn their place, with size, sigma and held-out "
      "gain, and says when two candidates explain the residuals equally. The pixel noise model is measured from the "
      "images unless --gain is given (as in `mcms track`).");
  cmd->add_option("DIR", args->dir, "recording folder (images/, rig.yaml, target.yaml, optional frames.csv)")->required();
  cmd->add_option("--repaired-rig", args->repaired,
                  "write the rig extended by the effects found here (moved poses, focal length, principal point, k1)");
  cmd->add_option("--repaired-target", args->repaired_target,
                  "write the target with the ball positions found (target_geometry) here");
  cmd->add_option("-o,--output", args->output,
                  "output folder: report.txt, report.json, residuals.csv (whitened residuals with their covariates), "
                  "plots/<camera>.svg (residuals against time, distance from the image centre, distance to the camera, "
                  "image u and v, and as vectors over the image)");
  cmd->add_option("--json", args->json, "write the audit report as JSON here (mode, nominal, clean, effects, undecided)");
  cmd->add_option("--false-alarm", args->audit.false_alarm,
                  "designed probability of naming an effect on a recording without one")
      ->check(CLI::Range(1e-6, 0.5))
      ->capture_default_str();
  cmd->add_option("--noise-tolerance", args->audit.noise_tolerance,
                  "relative error of the pixel noise sigma accepted before pixel_noise_scale is named")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  cmd->add_option("--folds", args->audit.folds, "k of the k-fold cross-validation (blocks of time)")
      ->check(CLI::Range(2, 50))
      ->capture_default_str();
  cmd->add_option("--rate", args->rate, "frame rate in Hz when there is no frames.csv")->check(CLI::PositiveNumber);
  args->tracker.Add(cmd);
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunAudit(*args); }));
}

}  // namespace mcms::app
