// mcms fov-map: the rig's precision over its measuring volume (issue 12), predicted
// (Cramer-Rao of the tracker's estimators for the rig, target and pixel-noise model),
// simulated (Monte Carlo through the renderer and the tracker at a sample of grid points)
// and, with --measured, confronted with repeated measurements (the paper's Table 1 or a
// raw CSV) and line lengths (Table 2). The algorithms live in jobs/fov_map.h and
// audit/repeatability.h.
#include <numbers>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>

#include "core/limits.h"
#include "app/commands.h"
#include "core/error.h"
#include "jobs/html_report.h"
#include "core/io.h"
#include "jobs/fov_map_job.h"

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
  int threads = ThreadsToUse(0);
  int simulate = 0, repeats = 30;
  uint64_t seed = 1;
  bool quiet = false;
  bool html = false;  // also write DIR/report.html
  // Measured data.
  std::string measured, lines, json, reference;
  int measured_repeats = 5;
  std::string plane_distances = "2.0,1.0";
};

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

int RunFovMap(const FovArgs& a) {
  FovMapJob job;
  job.output = a.out;
  job.scenario = a.scenario;
  job.rig = a.rig;
  job.target = a.target;
  job.grid = a.grid;
  job.orientation_rad = ParseTriple(a.orientation_deg, "--orientation-deg") * (std::numbers::pi / 180.0);
  job.gain = a.gain;
  job.read_noise = a.read_noise;
  job.ball_dn = a.ball_dn;
  job.background_dn = a.background_dn;
  job.blur_px = a.blur_px;
  job.threshold_mm = a.threshold_mm;
  job.threads = a.threads;
  job.simulate = a.simulate;
  job.repeats = a.repeats;
  job.seed = a.seed;
  job.measured = a.measured;
  job.lines = a.lines;
  job.json = a.json;
  job.reference = a.reference;
  job.measured_repeats = a.measured_repeats;
  if (!a.measured.empty()) {
    std::stringstream ps(a.plane_distances);
    std::string c1, c2, extra;
    char* e1 = nullptr;
    char* e2 = nullptr;
    if (!std::getline(ps, c1, ',') || !std::getline(ps, c2, ',') || std::getline(ps, extra, ','))
      Throw("--plane-distances: expected FIRST,LAST in metres, found '", a.plane_distances, "'");
    job.plane_first_distance_m = std::strtod(c1.c_str(), &e1);
    job.plane_last_distance_m = std::strtod(c2.c_str(), &e2);
    if (*e1 || *e2 || c1.empty() || c2.empty() || !(job.plane_first_distance_m > 0) || !(job.plane_last_distance_m > 0))
      Throw("--plane-distances: expected two positive distances in metres, found '", a.plane_distances, "'");
  }
  job.quiet = a.quiet;
  RunFovMapJob(job, CommandOutput("fov-map", a.quiet));
  if (a.html) {
    const std::filesystem::path page = std::filesystem::path(a.out) / "report.html";
    const HtmlReportContents c = WriteHtmlReport({a.out}, page);
    std::printf("wrote %s: %zu figures, %zu tables\n", page.string().c_str(), c.figures, c.tables);
  }
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
  sub->add_flag("--html", a->html, "also write DIR/report.html, the run's self-contained HTML report (as `mcms report DIR`)");
  sub->add_option("--scenario", a->scenario, "scenario file: rig, target and image formation (default: the built-in one)")
      ->check(CLI::ExistingFile);
  sub->add_option("--rig", a->rig, "rig file (rig.yaml), replacing the scenario's")->check(CLI::ExistingFile);
  sub->add_option("--target", a->target, "target file (target.yaml), replacing the scenario's")->check(CLI::ExistingFile);
  sub->add_option("--grid", a->grid, std::string("grid in the rig frame, x0:x1:nx,y0:y1:ny,z0:z1:nz in metres (default ") +
                                         kDefaultFovGrid + ")");
  sub->add_option("--orientation-deg", a->orientation_deg,
                  "target orientation at every grid point: rotation vector rx,ry,rz in degrees (default 0,0,0)");
  sub->add_option("--gain", a->gain, "camera gain in electrons per DN (default: the scenario's)")->check(NonNegativeNumber());
  sub->add_option("--read-noise", a->read_noise,
                  "noise std of a background pixel in DN, as in mcms track (default: the scenario's read, photon and "
                  "quantization noise)")
      ->check(NonNegativeNumber() & CLI::Range(0.0, kMaxImageDn));
  sub->add_option("--ball-dn", a->ball_dn, "brightness of a ball image in DN (default: the scenario's)")->check(NonNegativeNumber());
  sub->add_option("--background-dn", a->background_dn, "background level in DN (default: the scenario's)")
      ->check(NonNegativeNumber());
  sub->add_option("--blur-px", a->blur_px, "optical blur sigma in px (default: the scenario's)")->check(NonNegativeNumber());
  sub->add_option("--threshold-mm", a->threshold_mm, "report the region where sigma_d is below this, mm (default 0.03)")
      ->check(PositiveNumber());
  sub->add_option("--threads", a->threads, "worker threads (default: all cores)")->check(CLI::Range(1, kMaxThreads));
  sub->add_option("--simulate", a->simulate, "Monte Carlo at N grid points (default 0: none)")->check(NonNegativeNumber());
  sub->add_option("--repeats", a->repeats, "rendered frames per Monte-Carlo point (default 30)")->check(CLI::Range(2, 100000));
  sub->add_option("--seed", a->seed, "random seed of the Monte Carlo (default 1)")->check(SeedValidator());
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
