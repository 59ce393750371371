// mcms demo: the main job, on the embedded default (the paper's lab experiment,
// section 3.4). Renders the 4-camera rig watching the five-ball target on a KUKA KR 5 arc
// that visits 76 points on a 200 mm sphere with 7 s dwells, tracks every rendered frame,
// reads the robot's joints and the inclinometer, fuses them with MOIFA and with the
// multi-sensor KF, and reports each sensor alone and each fused result against the truth
// by the paper's three-sigma rule, with plots like its Figures 7 and 8.
#include <cmath>
#include <cstdio>
#include <thread>

#include "app/commands.h"
#include "core/error.h"
#include "core/io.h"
#include "core/svg_plot.h"
#include "synthetic/evaluation.h"
#include "synthetic/iso9283_experiment.h"
#include "synthetic/lab_experiment.h"
#include "synthetic/lab_scenario.h"
#include "synthetic/renderer.h"
#include "tracking/sequence.h"

namespace mcms::app {
namespace {

struct DemoArgs {
  std::string out = "mcms-demo";
  int points = 76;
  double camera_rate = 1.0;
  bool save_images = false;
  LabExperimentOptions experiment;
  bool quiet = false;
};

int RunDemo(const DemoArgs& a) {
  namespace fs = std::filesystem;
  LabOptions lo;
  lo.points = a.points;
  lo.camera_rate_hz = a.camera_rate;
  const LabScenario lab = MakeLabScenario(lo);
  const Scenario& sc = lab.vision;
  const fs::path out = a.out;
  RequireWritableFolder(out, "demo -o");  // before minutes of simulation, not after
  std::printf("mcms demo: the paper's lab experiment: %d points on a %.0f mm sphere, %.0f s dwell, %zu cameras at "
              "%.1f Hz (%zu frames), robot at %.0f Hz, inclinometer every %.0f ms -> %s\n",
              lo.points, 1e3 * lo.sphere_radius_m, lo.dwell_s, sc.rig.size(), lo.camera_rate_hz, sc.NumFrames(),
              lo.robot_rate_hz, 1e3 * lo.inclinometer.period, out.string().c_str());
  std::fflush(stdout);
  fs::create_directories(out);
  const int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (a.save_images) RenderSequence(sc, out / "recording", a.quiet, threads);

  // Render (in parallel, in chunks) and track (in order).
  ScenarioRenderer renderer(sc, threads);
  TrackerOptions topts;
  topts.detector.gain_e_per_dn = sc.render.gain_e_per_dn;
  Tracker tracker(sc.rig, sc.target, topts);
  std::vector<FrameResult> tracked;
  Progress progress("render + track", sc.NumFrames(), a.quiet);
  const size_t chunk = 4 * threads;
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
  WritePoseCsv(out / "tracker_poses.csv", tracked);
  const PoseErrorSummary ts = EvaluatePoses(tracked, sc.T_rig_target);

  const LabResult r = RunLabExperiment(lab, tracked, a.experiment);
  std::string report = "Tracker (rig frame, every frame):\n" + FormatSummary(ts) +
                       "\nFlange pose at the 76 points (robot base frame), each sensor alone and fused:\n" +
                       FormatLabTable(r);
  std::printf("\n%s", report.c_str());
  WriteFileAtomically(out / "summary.txt", [&](std::ostream& o) { o << report; });

  // Per-point errors (CSV) and the figures.
  WriteFileAtomically(out / "point_errors.csv", [&](std::ostream& o) {
    o << "point";
    for (const auto& m : r.methods) o << "," << m << "_pos_err_mm," << m << "_rot_err_deg";
    o << "\n";
    for (int i = 0; i < lo.points; ++i) {
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
    PlotSeries ps{r.methods[m], {}, {}, colors[m], false}, rs{r.methods[m], {}, {}, colors[m], false};
    for (int i = 0; i < lo.points; ++i) {
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
  std::printf("wrote %s/{summary.txt, point_errors.csv, tracker_poses.csv, position_error_per_point.svg, "
              "orientation_error_per_point.svg}\n",
              out.string().c_str());

  // ISO 9283 (issue 4) on the forward model: AP/RP, AD/RD, AT/RT before and after
  // calibration and before and after a fused correction (synthetic/iso9283_experiment.h).
  const Iso9283Experiment iso = RunIso9283Experiment();
  const std::string iso_report = FormatIso9283Experiment(iso);
  std::printf("\n%s", iso_report.c_str());
  WriteFileAtomically(out / "iso9283_summary.txt", [&](std::ostream& o) { o << iso_report; });
  WriteIso9283ExperimentCsv(out / "iso9283_characteristics.csv", iso);
  for (int k = 0; k < static_cast<int>(iso.conditions.size()); ++k) {
    WriteIso9283AttainedCsv(out / ("iso9283_attained_" + std::to_string(k + 1) + ".csv"), iso, k);
    WriteIso9283PathCsv(out / ("iso9283_path_" + std::to_string(k + 1) + ".csv"), iso, k);
  }
  WriteIso9283ExperimentSvg(out / "iso9283_ap.svg", out / "iso9283_rp.svg", iso);
  std::printf("wrote %s/{iso9283_summary.txt, iso9283_characteristics.csv, iso9283_attained_1..%zu.csv, "
              "iso9283_path_1..4.csv (input of `mcms iso9283 POSES --path PATH`; 1 = before calibration, "
              "2 = after, 3 = camera correction, 4 = MOIFA correction), iso9283_ap.svg, iso9283_rp.svg}\n",
              out.string().c_str(), iso.conditions.size());
  return 0;
}

McmsCommand demo_command([](CLI::App& app) {
  auto args = std::make_shared<DemoArgs>();
  CLI::App* cmd = app.add_subcommand(
      "demo",
      "The main job on the embedded default: the paper's lab experiment (section 3.4). A KR 5 arc carries the "
      "five-ball target and an inclinometer to 76 points on a 200 mm sphere (7 s dwell each); the 4-camera rig is "
      "rendered and tracked, the robot's joints and the inclinometer are read, and MOIFA and the KF fuse them. "
      "Prints each sensor's and each fused result's error by the three-sigma rule with the reduction, and writes "
      "tables and plots.");
  cmd->add_option("-o,--output", args->out, "output folder (default mcms-demo)");
  cmd->add_option("--points", args->points, "number of points on the sphere (paper: 76)")->check(CLI::Range(1, 1000));
  cmd->add_option("--camera-rate", args->camera_rate, "rendered camera frames per second (default 1)")
      ->check(CLI::Range(0.01, 100.0));
  cmd->add_option("--kf-angular-psd", args->experiment.kf_angular_psd,
                  "KF process noise: angular acceleration spectral density, rad^2/s^3")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--kf-linear-psd", args->experiment.kf_linear_psd,
                  "KF process noise: linear acceleration spectral density, m^2/s^3")
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--save-images", args->save_images, "also write the rendered recording (PNG, ~0.6 MB per image)");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunDemo(*args); }));
});

}  // namespace
}  // namespace mcms::app
