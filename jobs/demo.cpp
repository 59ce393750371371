#include "core/limits.h"
#include "jobs/demo.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <tuple>
#include <cstdarg>
#include <cstdio>

#include "core/error.h"
#include "core/format.h"
#include "core/io.h"
#include "core/parallel.h"
#include "core/random.h"
#include "core/svg_plot.h"
#include "core/output_folder.h"
#include "fusion/kalman.h"
#include "fusion/log_fusion.h"
#include "jobs/evaluation.h"
#include "synthetic/lab_scenario.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "tracking/sequence.h"

namespace mcms {

namespace {

namespace fs = std::filesystem;

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
    ParallelFor(f1 - f0, threads, [&](size_t i) { frames[i] = renderer.Render(f0 + i); });
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
          o << "," << 1e3 * e.error.tail<3>().norm() << "," << e.error.head<3>().norm() * 180 / std::numbers::pi;
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
      rs.y.push_back(e.error.head<3>().norm() * 180 / std::numbers::pi);
    }
    pos.series.push_back(ps);
    rot.series.push_back(rs);
  }
  pos.WriteSvg(out / "position_error_per_point.svg");
  rot.WriteSvg(out / "orientation_error_per_point.svg");
}

// The run beside the paper's lab result: a reduction is "within" when the paper's value
// lies within 2 bootstrap sd of the run's.
std::string FormatPaperComparison(const LabResult& r, const std::vector<double>& sd, const CameraErrorModel& model) {
  const auto find = [&](const std::string& name) -> int {
    for (size_t m = 0; m < r.summary.size(); ++m)
      if (r.summary[m].name == name) return static_cast<int>(m);
    return -1;
  };
  const int cam = find("camera"), rob = find("robot"), moifa = find("MOIFA"), kf = find("KF");
  if (cam < 0 || rob < 0 || moifa < 0 || kf < 0 || !(r.summary[cam].position_3sigma_m > 0)) return "";
  const double c3 = r.summary[cam].position_3sigma_m;
  std::string out = Format(
      "\nAgainst the paper's lab experiment (Tables 3-4; camera model %s; sd: bootstrap over the %d points):\n"
      "  three-sigma position error, mm: camera %.3f (paper %.3f), robot %.3f (paper %.3f)\n",
      model.name.c_str(), r.summary[cam].points, 1e3 * c3, 1e3 * PaperLabResult::camera_3sigma_m,
      1e3 * r.summary[rob].position_3sigma_m, 1e3 * PaperLabResult::robot_3sigma_m);
  // A bootstrap sd over a handful of points is no sd: below kMinComparisonPoints the
  // reductions are shown without a verdict.
  constexpr int kMinComparisonPoints = 10;
  if (r.summary[cam].points < kMinComparisonPoints) {
    for (const auto& [name, m, paper] : {std::tuple<const char*, int, double>{"MOIFA", moifa, PaperLabResult::moifa_reduction},
                                         {"KF", kf, PaperLabResult::kf_reduction}})
      out += Format("  %-5s reduction %5.1f %% (paper %.1f %%): no verdict from %d points (the comparison needs %d or "
                    "more; the paper measured 76)\n",
                    name, 100 * (1 - r.summary[m].position_3sigma_m / c3), 100 * paper, r.summary[cam].points,
                    kMinComparisonPoints);
    return out;
  }
  const auto line = [&](const char* name, int m, double paper) {
    const double red = 1 - r.summary[m].position_3sigma_m / c3;
    const bool within = std::abs(red - paper) <= 2 * sd[m];
    out += Format("  %-5s reduction %5.1f %% +- %.1f %% (paper %.1f %%): %s\n", name, 100 * red, 100 * sd[m], 100 * paper,
                  within ? "within 2 sd" : "NOT within 2 sd");
  };
  line("MOIFA", moifa, PaperLabResult::moifa_reduction);
  line("KF", kf, PaperLabResult::kf_reduction);
  return out;
}

}  // namespace

bool DemoOptions::IsValid(std::string* why) const {
  const auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (points < 1) return fail("points must be >= 1, got " + std::to_string(points));
  if (!(camera_rate_hz > 0) || !std::isfinite(camera_rate_hz)) return fail("camera_rate_hz must be positive");
  // Every point is measured while the robot dwells there: a slower camera misses points.
  if (const double dwell_s = LabOptions{}.dwell_s; camera_rate_hz * dwell_s < 1)
    return fail(Format("the camera rate (--camera-rate) %g Hz takes no frame in some of the %g s dwells at the points; "
                       "give at least %.3g Hz",
                       camera_rate_hz, dwell_s, 1.0 / dwell_s));
  if (threads < 0 || threads > kMaxThreads)
    return fail("threads must be 0 (the hardware's) to " + std::to_string(kMaxThreads) + ", got " + std::to_string(threads));
  std::string model_why;
  if (!camera_model.IsValid(&model_why)) return fail("camera model " + camera_model.name + ": " + model_why);
  // The KF's own check (fusion/kalman.h), named by the demo's options.
  PoseKalmanOptions kalman;
  kalman.angular_acceleration_psd = experiment.kf_angular_psd;
  kalman.linear_acceleration_psd = experiment.kf_linear_psd;
  if (std::string kf_why; !kalman.IsValid(&kf_why))
    return fail("--kf-angular-psd " + Format("%g", experiment.kf_angular_psd) + ", --kf-linear-psd " +
                Format("%g", experiment.kf_linear_psd) + ": " + kf_why);
  return true;
}

DemoResult RunDemo(const DemoOptions& o, const JobOutput& job_out) {
  const std::function<void(const std::string&)> print = [&job_out](const std::string& s) { job_out.Print(s); };
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  std::string why;
  if (!o.IsValid(&why)) Throw("demo: ", why);
  LabOptions lo;
  lo.points = o.points;
  lo.camera_rate_hz = o.camera_rate_hz;
  const LabScenario lab = MakeLabScenario(lo);
  const Scenario& sc = lab.vision;
  const fs::path& out = o.out;
  std::error_code ec;
  const bool model_file = std::filesystem::is_regular_file(o.camera_model.name, ec);
  RequireOutputsSpareInputs({{out, "demo -o", true}}, {model_file ? fs::path(o.camera_model.name) : fs::path()});
  // Before minutes of simulation, not after: an earlier demo is replaced, a folder holding
  // anything else (the user's own logs named like the demo's) is refused untouched.
  RequireWritableFolder(out, "demo -o");
  RequireReplaceableFolder(out, {"summary.txt"}, "demo", "demo -o");
  const int threads = ThreadsToUse(o.threads);
  print(Format("mcms demo: the paper's lab experiment: %d points on a %.0f mm sphere, %.0f s dwell, %zu cameras at "
               "%.1f Hz (%zu frames), robot at %.0f Hz, inclinometer every %.0f ms, %d threads -> %s\n",
               lo.points, 1e3 * lo.sphere_radius_m, lo.dwell_s, sc.rig.size(), lo.camera_rate_hz, sc.NumFrames(),
               lo.robot_rate_hz, 1e3 * lo.inclinometer.period, threads, out.string().c_str()));
  // Written in a temporary folder beside `out`, which replaces it only when complete: an
  // interrupted or failed demo leaves nothing (core/output_folder.h). Messages name `out`.
  CreateOutputFolder(out.has_parent_path() ? out.parent_path() : fs::path("."), "demo -o");
  DemoResult res;
  WriteFolderAtomically(out, {"summary.txt"}, "demo", "demo -o", [&](const fs::path& dir) {
    // What the cameras see: the truth moved by each visit's rigid error (synthetic/
    // camera_error_model.h). The truth (sc) is what is scored against.
    const CameraErrorModel& model = o.camera_model;
    Scenario seen = sc;
    std::vector<int> frames_of_point(lo.points, 0);
    for (int p : lab.point_of_frame)
      if (p >= 0) ++frames_of_point[p];
    Rng rng(lo.seed * 7919 + 13);
    {
      std::vector<Vec3> visit(lo.points);
      for (auto& v : visit) v = model.DrawVisit(&rng);
      for (size_t k = 0; k < seen.NumFrames(); ++k) {
        const int p = lab.point_of_frame[k];
        seen.T_rig_target[k].t += p >= 0 ? visit[p] : model.DrawVisit(&rng);
      }
    }
    print("camera model: " + model.Describe() + "\n");
    WriteFileAtomically(dir / "camera_model.txt", [&](std::ostream& s) { s << model.Describe() << "\n"; });
    if (o.save_images) RenderSequence(seen, dir / "recording", o.quiet, threads);
    std::vector<FrameResult> tracked = RenderAndTrack(seen, threads, o.quiet);
    // The pixel-noise excess on the tracked poses, and the per-visit error in the tracker's
    // reported covariance (the visit covariance times the visit's frame count).
    for (size_t k = 0; k < tracked.size(); ++k) {
      if (!tracked[k].T_rig_target) continue;
      model.ScalePixelNoise(&*tracked[k].T_rig_target, &tracked[k].cov, &rng);
      const int p = lab.point_of_frame[k];
      model.AddVisitCovariance(&tracked[k].cov, p >= 0 ? frames_of_point[p] : 1);
    }

    // The logs the fusion reads, written and then fused from the files, as `mcms fuse` does.
    WritePoseCsv(dir / "tracker_poses.csv", tracked);
    const SensorLogs logs = LabSensorLogs(lab, tracked);
    const FusionSetup setup = LabFusionSetup(lab, o.experiment);
    WriteJointLog(dir / "robot_joints.csv", *logs.robot, setup.robot);
    WriteInclinometerLog(dir / "inclinometer.csv", *logs.inclinometer);
    WriteFusionSetup(dir / "fusion_setup.yaml", setup);  // the default robot: lab.nominal is RobotModel::Default()
    WriteFusionWindows(dir / "dwells.csv", LabWindows(lab));
    FuseFilesRequest req;
    req.tracker = dir / "tracker_poses.csv";
    req.robot = dir / "robot_joints.csv";
    req.inclinometer = dir / "inclinometer.csv";
    req.setup = dir / "fusion_setup.yaml";
    req.windows = dir / "dwells.csv";
    req.output = dir / "fused_poses.csv";
    const FuseFilesResult fused = FuseLogFiles(req);

    const PoseErrorSummary ts = EvaluatePoses(tracked, sc.T_rig_target);
    res.lab = EvaluateLabExperiment(lab, fused.logs, fused.setup, fused.rows);
    res.lab_report = "Tracker (rig frame, every frame):\n" + FormatSummary(ts) + "\nFlange pose at the " +
                     std::to_string(lo.points) + " points (robot base frame), each sensor alone and fused:\n" +
                     FormatLabTable(res.lab);
    res.reduction_sd = BootstrapReductionSd(res.lab);
    res.paper_report = FormatPaperComparison(res.lab, res.reduction_sd, model);
    std::string model_text = "Camera model: " + model.Describe() + "\n";
    if (!model.VisitSigma().isZero())
      model_text +=
          "  (every frame of a visit reports the visit's covariance times the visit's frame count, so the tracker's\n"
          "  'predicted' per-frame position error below is inflated by that; the fused camera estimate of a dwell\n"
          "  reports the visit's covariance, which the camera's NEES in the table checks)\n";
    res.lab_report = model_text + res.lab_report + res.paper_report;
    print("\n" + res.lab_report);
    WriteFileAtomically(dir / "summary.txt", [&](std::ostream& s) { s << res.lab_report; });
    WritePointErrors(dir, res.lab, lo.points);
    print(Format("wrote %s/{summary.txt, point_errors.csv, position_error_per_point.svg, "
                 "orientation_error_per_point.svg}\n"
                 "fused the logs it wrote: %s/{tracker_poses.csv, robot_joints.csv, inclinometer.csv, "
                 "fusion_setup.yaml, dwells.csv} -> fused_poses.csv; to re-fuse them:\n"
                 "  mcms fuse --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer inclinometer.csv "
                 "--setup fusion_setup.yaml --windows dwells.csv -o fused_poses.csv\n",
                 out.string().c_str(), out.string().c_str()));
    if (!o.iso9283) return;

    // ISO 9283 (issue 4) on the forward model: AP/RP, AD/RD, AT/RT before and after
    // calibration and before and after a fused correction (jobs/iso9283_experiment.h).
    const Iso9283Experiment iso = RunIso9283Experiment();
    res.iso_report = FormatIso9283Experiment(iso);
    print("\n" + res.iso_report);
    WriteFileAtomically(dir / "iso9283_summary.txt", [&](std::ostream& s) { s << res.iso_report; });
    WriteIso9283ExperimentCsv(dir / "iso9283_characteristics.csv", iso);
    WriteIso9283Measurements(dir, "iso9283_", iso);
    WriteIso9283ExperimentSvg(dir / "iso9283_ap.svg", dir / "iso9283_rp.svg", iso);
    print(Format("wrote %s/{iso9283_summary.txt, iso9283_characteristics.csv, iso9283_attained_1..%zu.csv, "
                 "iso9283_path_1..4.csv (input of `mcms iso9283 POSES --path PATH`; 1 = before calibration, "
                 "2 = after, 3 = camera correction, 4 = MOIFA correction), iso9283_ap.svg, iso9283_rp.svg}\n",
                 out.string().c_str(), iso.conditions.size()));
  });
  return res;
}

}  // namespace mcms
