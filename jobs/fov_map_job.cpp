#include "jobs/fov_map_job.h"

#include <cmath>
#include <optional>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "jobs/fov_map_lab.h"
#include "synthetic/scenario.h"

namespace mcms {

namespace {
namespace fs = std::filesystem;
// Files that mark a folder as an earlier fov-map, which -o may replace.
const std::vector<std::string> kFovMapMarkers = {"map.csv"};
}  // namespace

MeasuredReport AnalyseMeasuredAgainstRig(const MeasuredPoints& measured, const MeasuredLines* lines,
                                         const CameraRig& rig, const Target& target, const FovMapOptions& map_options,
                                         const MeasuredAnalysisOptions& options) {
  const PredictPoints predict = [&](const std::vector<Vec3>& positions) {
    std::vector<PointPrediction> out;
    for (const FovMapPoint& p : PredictFovPoints(rig, target, map_options, positions))
      out.push_back({p.prediction.trackable, p.prediction.cov, p.prediction.min_border_px});
    return out;
  };
  const PredictLab lab = [](const CameraErrorModel& model, const Mat6& centre_cov, int seeds) {
    return PredictLabReductions(model, centre_cov, seeds);
  };
  return AnalyseMeasured(measured, lines, rig, predict, lab, options);
}

void RunFovMapJob(const FovMapJob& a, const JobOutput& sink) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  if (a.output.empty()) Throw("fov-map: give an output folder with -o DIR");
  const fs::path out = a.output;
  RequireOutputsSpareInputs({{out, "fov-map -o", true}, {a.json, "fov-map --json"}},
                            {a.measured, a.lines, a.reference, a.scenario, a.rig, a.target});
  RequireWritableFolder(out, "fov-map -o");
  RequireReplaceableFolder(fs::absolute(out).lexically_normal(), kFovMapMarkers, "fov-map", "fov-map -o");
  if (!a.json.empty()) RequireWritableFile(a.json, "fov-map --json");
  if (!a.json.empty() && a.measured.empty()) Throw("fov-map --json: needs --measured (the JSON reports the measured fit)");
  if (!a.lines.empty() && a.measured.empty()) Throw("fov-map --lines: needs --measured (Table 2 is predicted from Table 1's fit)");
  if (!a.reference.empty() && a.measured.empty()) Throw("fov-map --reference: needs --measured");

  // What is mapped: the scenario's (default: the demo's) rig, target and image formation,
  // with --rig, --target and the noise options overriding.
  Scenario sc = a.scenario.empty() ? Scenario::Default() : Scenario::Read(a.scenario);
  if (!a.rig.empty()) sc.rig = CameraRig::Read(a.rig);
  if (!a.target.empty()) sc.target = Target::Read(a.target);
  FovMapOptions mo;
  mo.grid = FovGrid::Parse(a.grid.empty() ? std::string(kDefaultFovGrid) : a.grid, "--grid");
  mo.R_rig_target = ExpSO3(a.orientation_rad);
  mo.threads = a.threads;
  mo.threshold_mm = a.threshold_mm;
  mo.noise.render = sc.render;
  RenderOptions& ro = mo.noise.render;
  if (a.ball_dn >= 0) ro.ball_dn = a.ball_dn;
  if (a.background_dn >= 0) ro.background_dn = a.background_dn;
  if (a.blur_px >= 0) ro.blur_sigma_px = a.blur_px;
  if (a.gain >= 0) ro.gain_e_per_dn = a.gain;
  if (a.read_noise > 0) {
    // --read-noise is the detector's noise of a background pixel (as in mcms track); the
    // images of the Monte Carlo get the read noise that makes it so.
    const double shot = ro.gain_e_per_dn > 0 ? ro.exposure * ro.background_dn / ro.gain_e_per_dn : 0.0;
    const double r2 = a.read_noise * a.read_noise - shot - 1.0 / 12.0;
    if (!(r2 >= 0))
      Throw("--read-noise ", a.read_noise, " DN: below the background's own photon and quantization noise (",
            std::sqrt(shot + 1.0 / 12.0), " DN at ", ro.background_dn, " DN and gain ", ro.gain_e_per_dn, " e-/DN)");
    ro.read_noise_dn = std::sqrt(r2);
    mo.noise.detector_read_noise_dn = a.read_noise;
  }
  std::string why;
  if (!mo.IsValid(&why)) Throw("fov-map: ", why);

  // Measured data are read (and refused) before any long computation.
  std::optional<MeasuredPoints> measured;
  std::optional<MeasuredLines> lines;
  if (!a.measured.empty()) {
    measured = ReadMeasuredPoints(a.measured, a.measured_repeats);
    // Raw repeats give positions: each must lie where the rig measures (seen by 2 cameras).
    for (const MeasuredPoint& p : measured->points) {
      if (!p.mean_rig) continue;
      int seen = 0;
      for (const CameraModel& cam : sc.rig.cameras) seen += cam.Sees(cam.T_cam_rig() * *p.mean_rig) ? 1 : 0;
      if (seen < 2)
        Throw(a.measured.string(), ": point ", p.id, " at (", p.mean_rig->x(), ", ", p.mean_rig->y(), ", ",
              p.mean_rig->z(), ") m (mean of its repeats) is outside the rig's field of view: ", seen, " of ",
              sc.rig.size(),
              " cameras see it, a measured point needs 2; expected positions in the rig frame, in metres");
    }
    if (!a.reference.empty()) ApplyReference(&*measured, a.reference);
    if (!a.lines.empty()) {
      lines = ReadMeasuredLines(a.lines);
      CheckLinesAgainstPoints(*lines, *measured);
    }
  }

  sink.Print(Format("mcms fov-map: %zu cameras, target '%s' (%zu balls, radius %.1f mm), grid %s (%zu points), %d threads\n",
              sc.rig.size(), sc.target.name.c_str(), sc.target.balls_target.size(), 1e3 * sc.target.ball_radius,
              mo.grid.ToString().c_str(), mo.grid.size(), mo.threads));
  const BlobDetectorOptions det = mo.noise.Detector();
  sink.Print(Format("pixel noise: balls %g DN over %g DN, blur %g px, gain %g e-/DN, background pixel noise %.3f DN\n",
              ro.ball_dn * ro.exposure, ro.background_dn * ro.exposure, ro.blur_sigma_px, det.gain_e_per_dn,
              det.read_noise_dn));

  Progress progress("fov-map predict", mo.grid.size(), a.quiet);
  const FovMap map = ComputeFovMap(sc.rig, sc.target, mo, [&](size_t d, size_t) { progress.Update(d); });
  progress.Finish();
  sink.Print(FovMapSummary(map));

  std::vector<FovSimulatedPoint> sim;
  if (a.simulate > 0) {
    FovSimulationOptions so;
    so.points = a.simulate;
    so.repeats = a.repeats;
    so.seed = a.seed;
    so.threads = a.threads;
    const std::vector<size_t> pick = PickSimulationPoints(map, a.simulate);
    Progress sp("fov-map simulate", pick.size() * a.repeats, a.quiet);
    sim = SimulateFovPoints(map, pick, so, [&](size_t d, size_t) { sp.Update(d); });
    sp.Finish();
    sink.Print(Format("Monte Carlo (%d rendered and tracked frames per point), sigma in mm, predicted / simulated:\n", a.repeats));
    int consistent = 0;
    for (const auto& s : sim) {
      const Vec3 pp = s.predicted_sigma_p * 1e3, ss = s.simulated_sigma_p * 1e3;
      sink.Print(Format("  (%6.3f, %6.3f, %6.3f) m  x %.4f / %.4f  y %.4f / %.4f  z %.4f / %.4f  d %.4f / %.4f  tracked %d/%d  %s\n",
                  s.p_rig.x(), s.p_rig.y(), s.p_rig.z(), pp.x(), ss.x(), pp.y(), ss.y(), pp.z(), ss.z(), pp.norm(), ss.norm(),
                  s.tracked, s.tracked + s.lost, s.AllConsistent() ? "consistent (99 % chi-square band, 6 axes)" : "OUTSIDE the 99 % band"));
      consistent += s.AllConsistent();
    }
    sink.Print(Format("  %d of %zu points consistent on all six axes\n", consistent, sim.size()));
  }

  std::optional<MeasuredReport> report;
  if (measured) {
    MeasuredAnalysisOptions mao;
    mao.plane_first_distance_m = a.plane_first_distance_m;
    mao.plane_last_distance_m = a.plane_last_distance_m;
    if (!a.quiet) std::fprintf(stderr, "fov-map: fitting the measured data (with leave-one-out and layout variants)\n");
    report = AnalyseMeasuredAgainstRig(*measured, lines ? &*lines : nullptr, sc.rig, sc.target, mo, mao);
    sink.Print(report->text);
  }

  WriteFolderAtomically(out, kFovMapMarkers, "fov-map", "fov-map -o", [&](const fs::path& dir) {
    WriteFovMap(map, dir, sim);
    if (report) WriteMeasuredReport(*report, dir);
  });
  if (report && !a.json.empty()) WriteMeasuredJson(*report, a.json);
  sink.Print(Format("wrote %s/map.csv, heat maps per z plane, sigma_vs_distance.svg, region.txt%s%s\n", out.string().c_str(),
              sim.empty() ? "" : ", simulated.csv", report ? ", measured.csv, measured_fit.txt" : ""));
}

}  // namespace mcms
