#include "jobs/camera_audit_job.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "tracking/sequence.h"

namespace mcms {

void WriteCameraAuditFolder(const std::filesystem::path& out, const CameraRig& rig, const CameraAuditResult& audit) {
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

void RunCameraAuditJob(const CameraAuditJob& a, const JobOutput& out) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  namespace fs = std::filesystem;
  const fs::path dir = a.recording;
  // (the rig's camera model files are inputs too)
  const CameraRig rig = CameraRig::Read(dir / "rig.yaml");
  const Target target = Target::Read(dir / "target.yaml");
  RequireOutputsSpareInputs({{a.json, "audit cameras --json"},
                             {a.output, "audit cameras -o", true},
                             {a.repaired_rig, "audit cameras --repaired-rig"},
                             {a.repaired_target, "audit cameras --repaired-target"}},
                            {dir / "rig.yaml", dir / "target.yaml", dir / "frames.csv", dir / "images"});
  if (!a.repaired_rig.empty()) RequireWritableFile(a.repaired_rig, "audit --repaired-rig");
  if (!a.repaired_target.empty()) RequireWritableFile(a.repaired_target, "audit --repaired-target");
  if (!a.json.empty()) RequireWritableFile(a.json, "audit --json");
  if (!a.output.empty()) RequireReplaceableFolder(a.output, {"report.json"}, "audit cameras", "audit cameras -o");
  const ImageSequence seq = ScanImageSequence({dir / "images", dir / "frames.csv", a.rate_hz}, rig);
  std::vector<std::string> notes;
  Tracker tracker(rig, target, a.tracker.Options(seq, rig, &notes));
  for (const auto& line : notes) out.Print(line + "\n");
  Progress progress("track", seq.frames.size(), a.quiet);
  const auto results = TrackImageSequence(
      seq, tracker, [&](size_t d, size_t) { progress.Update(d); }, a.tracker.threads);
  progress.Finish();
  // Frames whose image files could not be read: named with the file and the reason (they
  // are degraded or lost and the audit goes on without those images).
  {
    const std::string images = (dir / "images").string();
    size_t named = 0, more = 0;
    for (const auto& r : results) {
      if (r.status == FrameStatus::kOk || r.reason.find(images) == std::string::npos) continue;
      if (named++ < 20)
        out.Print("frame " + std::to_string(r.frame) + " " + ToString(r.status) + ": " + r.reason + "\n");
      else
        ++more;
    }
    if (more > 0) out.Print("... and " + std::to_string(more) + " more frames with unreadable images\n");
  }
  // No pose at all: the rig does not describe these images (camera folders swapped, the
  // wrong rig or target); say so, as `mcms track` does, not "too few frames".
  if (std::none_of(results.begin(), results.end(), [](const FrameResult& r) { return r.T_rig_target.has_value(); }))
    Throw("audit cameras: the target was never found in any of the ", results.size(), " frames of ",
          (dir / "images").string(), results.empty() ? std::string() : " (first frame: " + results.front().reason + ")",
          "; check that the image folders are those of ", (dir / "rig.yaml").string(),
          "'s cameras (two folders swapped?) and that target.yaml is the target seen");
  out.Print(CheckPoseResiduals(results).Describe() + "\n");
  const CameraAuditResult audit = AuditCameraModel(rig, target, results, a.audit, [&](const std::string& line) {
    if (!a.quiet) std::fprintf(stderr, "audit: %s\n", line.c_str());
  });
  out.Print(audit.report.Text());
  if (audit.report.effects.empty() && audit.report.undecided.empty())
    out.Print("every camera is consistent with the rest of the rig\n");
  if (!a.json.empty()) {
    audit.report.WriteJson(a.json);
    out.Print("wrote the audit report to " + a.json.string() + "\n");
  }
  if (!a.output.empty()) {
    WriteFolderAtomically(a.output, {"report.json"}, "audit cameras", "audit cameras -o",
                          [&](const fs::path& out) { WriteCameraAuditFolder(out, rig, audit); });
    out.Print("wrote the report, the whitened residuals and their plots to " + a.output.string() + "\n");
  }
  bool noise = false, target_changes = false;
  for (const auto& t : audit.terms) {
    noise = noise || t.extension.effect == Effect::kPixelNoiseScale;
    target_changes = target_changes || (t.extension.effect == Effect::kTargetGeometry && !t.undecided);
  }
  // Every repaired file asked for is checked before any is written.
  if (!a.repaired_rig.empty() && !audit.report.effects.empty()) {
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
    out.Print("wrote the target with the ball positions found to " + a.repaired_target.string() + "\n");
  }
  if (!a.repaired_target.empty() && audit.report.effects.empty())
    out.Print("no effect named: no repaired target written (" + a.repaired_target.string() + ")\n");
  if (!a.repaired_rig.empty() && audit.ChangesRig()) {
    audit.ExtendedRig(rig).Write(a.repaired_rig);
    out.Print("wrote the rig extended by the effects found to " + a.repaired_rig.string() + "\n");
    for (const auto& t : audit.terms) {
      const Effect e = t.extension.effect;
      if (e == Effect::kCameraTimeOffset || e == Effect::kPixelNoiseScale || e == Effect::kTargetGeometry)
        out.Print("  not in the rig file: " + t.extension.Label(rig.names) + "\n");
      if (e == Effect::kCameraMoved && std::isfinite(t.from_time_s)) {
        char b[200];
        std::snprintf(b, sizeof b, "  %s: the rig has its pose after the move (from t = %.3f s)\n",
                      rig.names[t.extension.index].c_str(), t.from_time_s);
        out.Print(b);
      }
    }
  }
}


}  // namespace mcms
