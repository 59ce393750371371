// mcms fov-map: the rig's precision over its measuring volume (issue 12), predicted
// (Cramer-Rao of the tracker's estimators for the rig, target and pixel-noise model),
// simulated (Monte Carlo through the renderer and the tracker at a sample of grid points)
// and, with --measured, confronted with repeated measurements (the paper's Table 1 or a
// raw CSV) and line lengths (Table 2). The algorithms live in synthetic/fov_map.h and
// synthetic/fov_map_measured.h.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>

#include "app/commands.h"
#include "core/error.h"
#include "core/io.h"
#include "synthetic/fov_map.h"
#include "synthetic/fov_map_measured.h"
#include "synthetic/scenario.h"

namespace mcms::app {
namespace {

namespace fs = std::filesystem;

struct FovArgs {
  std::string out;
  std::string scenario, rig, target;
  std::string grid;
  std::string orientation_deg = "0,0,0";
  double gain = -1, read_noise = 0;
  double ball_dn = -1, background_dn = -1, blur_px = -1;
  double threshold_mm = 0.03;
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  int simulate = 0, repeats = 30;
  uint64_t seed = 1;
  bool quiet = false;
  // Measured data.
  std::string measured, lines, json, reference;
  int measured_repeats = 5;
  std::string plane_distances = "2.0,1.0";
};

const char* kDefaultGrid = "-0.5:0.5:11,-0.4:0.4:9,0:1:11";

Vec3 ParseTriple(const std::string& text, const std::string& option) {
  std::stringstream s(text);
  Vec3 v;
  std::string cell;
  for (int i = 0; i < 3; ++i) {
    if (!std::getline(s, cell, ','))
      Throw(option, ": expected three comma-separated numbers, found '", text, "'");
    char* end = nullptr;
    v[i] = std::strtod(cell.c_str(), &end);
    if (cell.empty() || end != cell.c_str() + cell.size() || !std::isfinite(v[i]))
      Throw(option, ": '", cell, "' is not a finite number (in '", text, "')");
  }
  if (std::getline(s, cell, ',')) Throw(option, ": expected three comma-separated numbers, found '", text, "'");
  return v;
}

// An output folder written as a whole: into a temporary folder beside it, renamed into
// place when complete. An existing folder is replaced only when it is empty or holds an
// earlier fov-map (map.csv or fov_measured.csv); anything else is refused.
void CheckReplaceable(const fs::path& out) {
  std::error_code ec;
  if (!fs::exists(out, ec)) return;
  if (!fs::is_directory(out, ec)) Throw("fov-map -o: ", out.string(), " exists and is not a folder");
  if (fs::is_empty(out, ec)) return;
  if (fs::exists(out / "map.csv") || fs::exists(out / "measured.csv")) return;
  Throw("fov-map -o: folder ", out.string(), " exists and does not hold an earlier fov-map; choose a new folder or remove it");
}

void WriteFolder(const fs::path& out_dir, const std::function<void(const fs::path&)>& write) {
  fs::path out = fs::absolute(out_dir).lexically_normal();
  if (!out.has_filename()) out = out.parent_path();
  CheckReplaceable(out);
  const std::string stem = "." + out.filename().string();
  const std::string pid = std::to_string(::getpid());
  const fs::path tmp = out.parent_path() / (stem + ".partial-" + pid);
  std::error_code ec;
  fs::remove_all(tmp, ec);
  try {
    fs::create_directories(tmp);
    write(tmp);
    CheckReplaceable(out);
    if (fs::exists(out)) {
      const fs::path old = out.parent_path() / (stem + ".old-" + pid);
      fs::remove_all(old, ec);
      fs::rename(out, old);
      fs::rename(tmp, out);
      fs::remove_all(old, ec);
    } else {
      fs::rename(tmp, out);
    }
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(tmp, ec);
    Throw("fov-map -o: cannot write ", out.string(), ": ", e.code().message());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
}

int RunFovMap(const FovArgs& a) {
  if (a.out.empty()) Throw("fov-map: give an output folder with -o DIR");
  const fs::path out = a.out;
  RequireWritableFolder(out, "fov-map -o");
  CheckReplaceable(fs::absolute(out).lexically_normal());
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
  mo.grid = FovGrid::Parse(a.grid.empty() ? std::string(kDefaultGrid) : a.grid, "--grid");
  mo.R_rig_target = ExpSO3(ParseTriple(a.orientation_deg, "--orientation-deg") * (M_PI / 180.0));
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
    if (!a.reference.empty()) ApplyReference(&*measured, a.reference);
    if (!a.lines.empty()) lines = ReadMeasuredLines(a.lines);
  }

  std::printf("mcms fov-map: %zu cameras, target '%s' (%zu balls, radius %.1f mm), grid %s (%zu points), %d threads\n",
              sc.rig.size(), sc.target.name.c_str(), sc.target.balls_target.size(), 1e3 * sc.target.ball_radius,
              mo.grid.ToString().c_str(), mo.grid.size(), mo.threads);
  const BlobDetectorOptions det = mo.noise.Detector();
  std::printf("pixel noise: balls %g DN over %g DN, blur %g px, gain %g e-/DN, background pixel noise %.3f DN\n",
              ro.ball_dn * ro.exposure, ro.background_dn * ro.exposure, ro.blur_sigma_px, det.gain_e_per_dn,
              det.read_noise_dn);
  std::fflush(stdout);

  Progress progress("fov-map predict", mo.grid.size(), a.quiet);
  const FovMap map = ComputeFovMap(sc.rig, sc.target, mo, [&](size_t d, size_t) { progress.Update(d); });
  progress.Finish();
  std::printf("%s", FovMapSummary(map).c_str());

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
    std::printf("Monte Carlo (%d rendered and tracked frames per point), sigma in mm, predicted / simulated:\n", a.repeats);
    int consistent = 0;
    for (const auto& s : sim) {
      const Vec3 pp = s.predicted_sigma_p * 1e3, ss = s.simulated_sigma_p * 1e3;
      std::printf("  (%6.3f, %6.3f, %6.3f) m  x %.4f / %.4f  y %.4f / %.4f  z %.4f / %.4f  d %.4f / %.4f  tracked %d/%d  %s\n",
                  s.p_rig.x(), s.p_rig.y(), s.p_rig.z(), pp.x(), ss.x(), pp.y(), ss.y(), pp.z(), ss.z(), pp.norm(), ss.norm(),
                  s.tracked, s.tracked + s.lost, s.AllConsistent() ? "consistent (99 % chi-square band, 6 axes)" : "OUTSIDE the 99 % band");
      consistent += s.AllConsistent();
    }
    std::printf("  %d of %zu points consistent on all six axes\n", consistent, sim.size());
  }

  std::optional<MeasuredReport> report;
  if (measured) {
    MeasuredAnalysisOptions mao;
    {
      std::stringstream ps(a.plane_distances);
      std::string c1, c2, extra;
      char* e1 = nullptr;
      char* e2 = nullptr;
      if (!std::getline(ps, c1, ',') || !std::getline(ps, c2, ',') || std::getline(ps, extra, ','))
        Throw("--plane-distances: expected FIRST,LAST in metres, found '", a.plane_distances, "'");
      mao.plane_first_distance_m = std::strtod(c1.c_str(), &e1);
      mao.plane_last_distance_m = std::strtod(c2.c_str(), &e2);
      if (*e1 || *e2 || c1.empty() || c2.empty() || !(mao.plane_first_distance_m > 0) || !(mao.plane_last_distance_m > 0))
        Throw("--plane-distances: expected two positive distances in metres, found '", a.plane_distances, "'");
    }
    if (!a.quiet) std::fprintf(stderr, "fov-map: fitting the measured data (with leave-one-out and layout variants)\n");
    report = AnalyseMeasured(*measured, lines ? &*lines : nullptr, sc.rig, sc.target, mo, mao);
    std::printf("%s", report->text.c_str());
  }

  WriteFolder(out, [&](const fs::path& dir) {
    WriteFovMap(map, dir, sim);
    if (report) WriteMeasuredReport(*report, dir);
  });
  if (report && !a.json.empty()) WriteMeasuredJson(*report, a.json);
  std::printf("wrote %s/map.csv, heat maps per z plane, sigma_vs_distance.svg, region.txt%s%s\n", out.string().c_str(),
              sim.empty() ? "" : ", simulated.csv", report ? ", measured.csv, measured_fit.txt" : "");
  return 0;
}

const McmsCommand kFovMap([](CLI::App& app) {
  auto a = std::make_shared<FovArgs>();
  CLI::App* sub = app.add_subcommand("fov-map", "Map the rig's precision over its measuring volume (predicted, simulated, measured)");
  sub->description(
      "Map the camera rig's precision over a grid of target positions (issue 12; the paper's section 3.1).\n"
      "Predicted: at every grid point the Cramer-Rao covariance of each triangulated ball and of the\n"
      "target's pose (the tracker's own estimators at the true image points, with the blob detector's\n"
      "centre covariance for the rendered image formation), and which camera sees which ball.\n"
      "With no other input it maps the default (demo) rig over its 1 x 0.8 x 1 m working volume.\n"
      "--simulate N: Monte Carlo through the renderer and the tracker at N grid points.\n"
      "--measured FILE: repeated measurements (the paper's Table 1 CSV plane,point,sigma_x_mm,...\n"
      "or a raw CSV point,repeat,x_m,y_m,z_m) against the nominal model; candidate causes of the\n"
      "disagreement fitted by maximum likelihood and selected by BIC; --lines: Table 2 predicted.\n"
      "DIR receives map.csv, heatmap_z<k>.svg, sigma_vs_distance.svg, region.txt (and simulated.*,\n"
      "measured.*); it is written to a temporary folder and renamed into place when complete.");
  sub->add_option("-o,--output", a->out, "output folder (required)")->type_name("DIR");
  sub->add_option("--scenario", a->scenario, "scenario file: rig, target and image formation (default: the built-in one)")
      ->check(CLI::ExistingFile);
  sub->add_option("--rig", a->rig, "rig file (rig.yaml), replacing the scenario's")->check(CLI::ExistingFile);
  sub->add_option("--target", a->target, "target file (target.yaml), replacing the scenario's")->check(CLI::ExistingFile);
  sub->add_option("--grid", a->grid, std::string("grid in the rig frame, x0:x1:nx,y0:y1:ny,z0:z1:nz in metres (default ") +
                                         kDefaultGrid + ")");
  sub->add_option("--orientation-deg", a->orientation_deg,
                  "target orientation at every grid point: rotation vector rx,ry,rz in degrees (default 0,0,0)");
  sub->add_option("--gain", a->gain, "camera gain in electrons per DN (default: the scenario's)")->check(CLI::NonNegativeNumber);
  sub->add_option("--read-noise", a->read_noise,
                  "noise std of a background pixel in DN, as in mcms track (default: the scenario's read, photon and "
                  "quantization noise)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--ball-dn", a->ball_dn, "brightness of a ball image in DN (default: the scenario's)")->check(CLI::NonNegativeNumber);
  sub->add_option("--background-dn", a->background_dn, "background level in DN (default: the scenario's)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--blur-px", a->blur_px, "optical blur sigma in px (default: the scenario's)")->check(CLI::NonNegativeNumber);
  sub->add_option("--threshold-mm", a->threshold_mm, "report the region where sigma_d is below this, mm (default 0.03)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--threads", a->threads, "worker threads (default: all cores)")->check(CLI::PositiveNumber);
  sub->add_option("--simulate", a->simulate, "Monte Carlo at N grid points (default 0: none)")->check(CLI::NonNegativeNumber);
  sub->add_option("--repeats", a->repeats, "rendered frames per Monte-Carlo point (default 30)")->check(CLI::Range(2, 100000));
  sub->add_option("--seed", a->seed, "random seed of the Monte Carlo (default 1)");
  sub->add_option("--measured", a->measured,
                  "repeated measurements: Table 1 CSV (plane,point,sigma_x_mm,sigma_y_mm,sigma_z_mm[,sigma_d_mm]) or raw "
                  "CSV (point,repeat,x_m,y_m,z_m[,plane]) or an mcms track poses.csv with a point column")
      ->check(CLI::ExistingFile);
  sub->add_option("--measured-repeats", a->measured_repeats,
                  "repeats behind each sigma of a Table 1 CSV (default 5, the paper's)")
      ->check(CLI::Range(2, 1000000));
  sub->add_option("--reference", a->reference, "reference coordinates of the measured points (point,x_m,y_m,z_m)")
      ->check(CLI::ExistingFile);
  sub->add_option("--lines", a->lines, "line lengths (Table 2 CSV: plane,line,d_laser_mm,d_camera_mm[,delta_mm])")
      ->check(CLI::ExistingFile);
  sub->add_option("--json", a->json, "write the measured fit as JSON (effects, held-out gain, Table 2 prediction)");
  sub->add_option("--plane-distances", a->plane_distances,
                  "Table 1 layout: distances of the first and last plane below the cameras, m (default 2.0,1.0)");
  sub->add_flag("--quiet", a->quiet, "no progress on stderr");
  return std::make_pair(sub, Runner([a] { return RunFovMap(*a); }));
});

}  // namespace
}  // namespace mcms::app
