#include "synthetic/demo.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <thread>

#include "core/error.h"
#include "core/io.h"
#include "core/svg_plot.h"
#include "fusion/log_fusion.h"
#include "synthetic/evaluation.h"
#include "synthetic/lab_scenario.h"
#include "synthetic/renderer.h"
#include "tracking/sequence.h"

namespace mcms {

namespace {

namespace fs = std::filesystem;

std::string Format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string Format(const char* fmt, ...) {
  char buf[4096];
  va_list ap;
  va_start(ap, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  return buf;
}

// Renders (in parallel, in chunks) and tracks (in order) every frame of the scenario.
std::vector<FrameResult> RenderAndTrack(const Scenario& sc, int threads, bool quiet) {
  ScenarioRenderer renderer(sc, threads);
  TrackerOptions topts;
  topts.detector.gain_e_per_dn = sc.render.gain_e_per_dn;
  Tracker tracker(sc.rig, sc.target, topts);
  std::vector<FrameResult> tracked;
  Progress progress("render + track", sc.NumFrames(), quiet);
  const size_t chunk = 4 * static_cast<size_t>(threads);
  for (size_t f0 = 0; f0 < sc.NumFrames(); f0 += chunk) {
    const size_t f1 = std::min(sc.NumFrames(), f0 + chunk);
    std::vector<RenderedFrame> frames(f1 - f0);
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        for (size_t f = f0 + t; f < f1; f += threads) frames[f - f0] = renderer.Render(f);
      });
    for (auto& th : pool) th.join();
    for (size_t f = f0; f < f1; ++f) {
      tracked.push_back(tracker.ProcessFrame(f, sc.times[f], frames[f - f0].images));
      progress.Update(f + 1);
    }
  }
  progress.Finish();
  return tracked;
}

void WritePointErrors(const fs::path& out, const LabResult& r, int points) {
  WriteFileAtomically(out / "point_errors.csv", [&](std::ostream& o) {
    o << "point";
    for (const auto& m : r.methods) o << "," << m << "_pos_err_mm," << m << "_rot_err_deg";
    o << "\n";
    for (int i = 0; i < points; ++i) {
      o << i;
      for (size_t m = 0; m < r.methods.size(); ++m) {
        const auto& e = r.estimates[m][i];
        if (e.valid)
          o << "," << 1e3 * e.error.tail<3>().norm() << "," << e.error.head<3>().norm() * 180 / M_PI;
        else
          o << ",,";
      }
      o << "\n";
    }
  });
  const char* colors[4] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"};
  Plot pos{"Position error per point (cf. the paper's Figures 7-8)", "point", "position error (mm)", {}};
  Plot rot{"Orientation error per point", "point", "orientation error (deg)", {}};
  for (size_t m = 0; m < r.methods.size(); ++m) {
    PlotSeries ps{r.methods[m], {}, {}, colors[m % 4], false}, rs{r.methods[m], {}, {}, colors[m % 4], false};
    for (int i = 0; i < points; ++i) {
      const auto& e = r.estimates[m][i];
      if (!e.valid) continue;
      ps.x.push_back(i);
      ps.y.push_back(1e3 * e.error.tail<3>().norm());
      rs.x.push_back(i);
      rs.y.push_back(e.error.head<3>().norm() * 180 / M_PI);
    }
    pos.series.push_back(ps);
    rot.series.push_back(rs);
  }
  pos.WriteSvg(out / "position_error_per_point.svg");
  rot.WriteSvg(out / "orientation_error_per_point.svg");
}

}  // namespace

bool DemoOptions::IsValid(std::string* why) const {
  const auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (points < 1) return fail("points must be >= 1, got " + std::to_string(points));
  if (!(camera_rate_hz > 0) || !std::isfinite(camera_rate_hz)) return fail("camera_rate_hz must be positive");
  if (threads < 0) return fail("threads must be >= 0 (0: the hardware's), got " + std::to_string(threads));
  if (!(experiment.kf_angular_psd > 0) || !(experiment.kf_linear_psd > 0))
    return fail("the KF's process noise densities must be positive");
  return true;
}

DemoResult RunDemo(const DemoOptions& o, const std::function<void(const std::string&)>& print) {
  std::string why;
  if (!o.IsValid(&why)) Throw("demo: ", why);
  LabOptions lo;
  lo.points = o.points;
  lo.camera_rate_hz = o.camera_rate_hz;
  const LabScenario lab = MakeLabScenario(lo);
  const Scenario& sc = lab.vision;
  const fs::path& out = o.out;
  RequireWritableFolder(out, "demo -o");  // before minutes of simulation, not after
  const int threads = o.threads > 0 ? o.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  print(Format("mcms demo: the paper's lab experiment: %d points on a %.0f mm sphere, %.0f s dwell, %zu cameras at "
               "%.1f Hz (%zu frames), robot at %.0f Hz, inclinometer every %.0f ms, %d threads -> %s\n",
               lo.points, 1e3 * lo.sphere_radius_m, lo.dwell_s, sc.rig.size(), lo.camera_rate_hz, sc.NumFrames(),
               lo.robot_rate_hz, 1e3 * lo.inclinometer.period, threads, out.string().c_str()));
  fs::create_directories(out);
  if (o.save_images) RenderSequence(sc, out / "recording", o.quiet, threads);
  const std::vector<FrameResult> tracked = RenderAndTrack(sc, threads, o.quiet);

  // The logs the fusion reads, written and then fused from the files, as `mcms fuse` does.
  WritePoseCsv(out / "tracker_poses.csv", tracked);
  const SensorLogs logs = LabSensorLogs(lab, tracked);
  const FusionSetup setup = LabFusionSetup(lab, o.experiment);
  WriteJointLog(out / "robot_joints.csv", *logs.robot, setup.robot);
  WriteInclinometerLog(out / "inclinometer.csv", *logs.inclinometer);
  WriteFusionSetup(out / "fusion_setup.yaml", setup);  // the default robot: lab.nominal is RobotModel::Default()
  WriteFusionWindows(out / "dwells.csv", LabWindows(lab));
  FuseFilesRequest req;
  req.tracker = out / "tracker_poses.csv";
  req.robot = out / "robot_joints.csv";
  req.inclinometer = out / "inclinometer.csv";
  req.setup = out / "fusion_setup.yaml";
  req.windows = out / "dwells.csv";
  req.output = out / "fused_poses.csv";
  const FuseFilesResult fused = FuseLogFiles(req);

  DemoResult res;
  const PoseErrorSummary ts = EvaluatePoses(tracked, sc.T_rig_target);
  res.lab = EvaluateLabExperiment(lab, fused.logs, fused.setup, fused.rows);
  res.lab_report = "Tracker (rig frame, every frame):\n" + FormatSummary(ts) + "\nFlange pose at the " +
                   std::to_string(lo.points) + " points (robot base frame), each sensor alone and fused:\n" +
                   FormatLabTable(res.lab);
  print("\n" + res.lab_report);
  WriteFileAtomically(out / "summary.txt", [&](std::ostream& s) { s << res.lab_report; });
  WritePointErrors(out, res.lab, lo.points);
  print(Format("wrote %s/{summary.txt, point_errors.csv, position_error_per_point.svg, "
               "orientation_error_per_point.svg}\n"
               "fused the logs it wrote: %s/{tracker_poses.csv, robot_joints.csv, inclinometer.csv, "
               "fusion_setup.yaml, dwells.csv} -> fused_poses.csv; to re-fuse them:\n"
               "  mcms fuse --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer inclinometer.csv "
               "--setup fusion_setup.yaml --windows dwells.csv -o fused_poses.csv\n",
               out.string().c_str(), out.string().c_str()));
  if (!o.iso9283) return res;

  // ISO 9283 (issue 4) on the forward model: AP/RP, AD/RD, AT/RT before and after
  // calibration and before and after a fused correction (synthetic/iso9283_experiment.h).
  const Iso9283Experiment iso = RunIso9283Experiment();
  res.iso_report = FormatIso9283Experiment(iso);
  print("\n" + res.iso_report);
  WriteFileAtomically(out / "iso9283_summary.txt", [&](std::ostream& s) { s << res.iso_report; });
  WriteIso9283ExperimentCsv(out / "iso9283_characteristics.csv", iso);
  WriteIso9283Measurements(out, "iso9283_", iso);
  WriteIso9283ExperimentSvg(out / "iso9283_ap.svg", out / "iso9283_rp.svg", iso);
  print(Format("wrote %s/{iso9283_summary.txt, iso9283_characteristics.csv, iso9283_attained_1..%zu.csv, "
               "iso9283_path_1..4.csv (input of `mcms iso9283 POSES --path PATH`; 1 = before calibration, "
               "2 = after, 3 = camera correction, 4 = MOIFA correction), iso9283_ap.svg, iso9283_rp.svg}\n",
               out.string().c_str(), iso.conditions.size()));
  return res;
}

}  // namespace mcms
