// mcms demo: the main job on the embedded default scenario. Renders the paper's rig
// (4 cameras over a 1 x 0.8 x 1 m volume) watching the five-ball target, tracks the
// rendered images from disk exactly as `mcms track` would, and audits the poses
// against the ground truth: errors, the covariance's honesty (NEES), plots.
#include <cmath>
#include <cstdio>
#include <thread>

#include "app/commands.h"
#include "app/tracking_options.h"
#include "core/error.h"
#include "core/io.h"
#include "core/svg_plot.h"
#include "synthetic/evaluation.h"
#include "synthetic/renderer.h"
#include "synthetic/scenario.h"
#include "tracking/sequence.h"

namespace mcms::app {
namespace {

struct DemoArgs {
  std::string out = "mcms-demo";
  std::string scenario;
  int frames = 0;
  bool quiet = false;
};

int RunDemo(const DemoArgs& a) {
  namespace fs = std::filesystem;
  Scenario sc = a.scenario.empty() ? Scenario::Default() : Scenario::Read(a.scenario);
  if (a.frames > 0 && static_cast<size_t>(a.frames) < sc.NumFrames()) {
    sc.times.resize(a.frames);
    sc.T_rig_target.resize(a.frames);
  }
  const fs::path out = a.out;
  const fs::path rec = out / "recording";
  std::printf("mcms demo: %zu cameras, %zu frames, target '%s' -> %s\n", sc.rig.size(), sc.NumFrames(),
              sc.target.name.c_str(), out.string().c_str());
  std::fflush(stdout);
  fs::create_directories(out);
  RenderSequence(sc, rec, a.quiet, static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));

  // Track from the files on disk, as a user's recording would be.
  CameraRig rig = CameraRig::Read(rec / "rig.yaml");
  Target target = Target::Read(rec / "target.yaml");
  const ImageSequence seq = ScanImageSequence({rec / "images", rec / "frames.csv", 10.0}, rig);
  TrackerOptions opts;
  opts.detector.gain_e_per_dn = sc.render.noise_free ? 0.0 : sc.render.gain_e_per_dn;
  Tracker tracker(rig, target, opts);
  Progress progress("track", seq.frames.size(), a.quiet);
  const auto results = TrackImageSequence(seq, tracker, [&](size_t d, size_t) { progress.Update(d); });
  progress.Finish();
  WritePoseCsv(out / "poses.csv", results);

  std::vector<Pose> truth;
  for (size_t f : seq.frames) truth.push_back(sc.T_rig_target.at(f));
  const PoseErrorSummary s = EvaluatePoses(results, truth);
  const std::string report = FormatSummary(s);
  std::printf("%s", report.c_str());
  WriteFileAtomically(out / "summary.txt", [&](std::ostream& o) { o << report; });

  Plot perr{"Tracked target position error per frame", "frame", "error (mm)", {}};
  Plot rerr{"Tracked target rotation error per frame", "frame", "error (deg)", {}};
  PlotSeries pe{"|p - p_true|", {}, {}, "#1f77b4", true}, pb{"3-sigma predicted (from the 6x6 covariance)", {}, {}, "#d62728"};
  PlotSeries re{"rotation error angle", {}, {}, "#2ca02c", true}, rb{"3-sigma predicted", {}, {}, "#d62728"};
  for (size_t i = 0; i < results.size(); ++i) {
    if (!results[i].T_rig_target) continue;
    const Vec6 e = BoxMinus(*results[i].T_rig_target, truth[i]);
    const double x = static_cast<double>(results[i].frame);
    pe.x.push_back(x);
    pe.y.push_back(1e3 * e.tail<3>().norm());
    pb.x.push_back(x);
    pb.y.push_back(3e3 * std::sqrt(results[i].cov.bottomRightCorner<3, 3>().trace()));
    re.x.push_back(x);
    re.y.push_back(e.head<3>().norm() * 180 / M_PI);
    rb.x.push_back(x);
    rb.y.push_back(3 * std::sqrt(results[i].cov.topLeftCorner<3, 3>().trace()) * 180 / M_PI);
  }
  perr.series = {pe, pb};
  rerr.series = {re, rb};
  perr.WriteSvg(out / "position_error.svg");
  rerr.WriteSvg(out / "rotation_error.svg");
  std::printf("wrote %s/{poses.csv, summary.txt, position_error.svg, rotation_error.svg} and the recording in %s\n",
              out.string().c_str(), rec.string().c_str());
  return 0;
}

McmsCommand demo_command([](CLI::App& app) {
  auto args = std::make_shared<DemoArgs>();
  CLI::App* cmd = app.add_subcommand(
      "demo",
      "The main job on the embedded default scenario: render the paper's 4-camera rig watching the five-ball "
      "target, track the images, and report the pose errors against the ground truth and whether the reported "
      "covariance is honest (NEES), with plots.");
  cmd->add_option("-o,--output", args->out, "output folder (default mcms-demo)");
  cmd->add_option("--scenario", args->scenario, "a scenario file instead of the embedded default");
  cmd->add_option("--frames", args->frames, "use only the first N frames")->check(CLI::PositiveNumber);
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunDemo(*args); }));
});

}  // namespace
}  // namespace mcms::app
