// mcms demo: the main job, on the embedded default (the paper's lab experiment, section
// 3.4): jobs/demo.h RunDemo renders, tracks, writes the sensor logs, fuses them by the
// path `mcms fuse` runs, and reports against the truth. This file parses and prints.
#include <cstdio>
#include <memory>

#include "app/commands.h"
#include "core/limits.h"
#include "core/output_folder.h"
#include "jobs/html_report.h"
#include "jobs/demo.h"

namespace mcms::app {
namespace {

McmsCommand demo_command([](CLI::App& app) {
  auto args = std::make_shared<DemoOptions>();
  auto out = std::make_shared<std::string>("mcms-demo");
  auto no_iso = std::make_shared<bool>(false);
  auto html = std::make_shared<bool>(true);
  auto camera_model = std::make_shared<std::string>("ideal");
  CLI::App* cmd = app.add_subcommand(
      "demo",
      "The main job on the embedded default: the paper's lab experiment (section 3.4). A KR 5 arc carries the "
      "five-ball target and an inclinometer to 76 points on a 200 mm sphere (7 s dwell each); the 4-camera rig is "
      "rendered and tracked, the robot's joints and the inclinometer are read and written as logs, and MOIFA and "
      "the KF fuse those logs as `mcms fuse --windows` does. Prints each sensor's and each fused result's error by "
      "the three-sigma rule with the reduction, and writes tables and plots.");
  cmd->add_option("-o,--output", *out, "output folder (default mcms-demo)");
  cmd->add_option("--points", args->points, "number of points on the sphere (paper: 76)")->check(CLI::Range(1, 1000));
  cmd->add_option("--camera-rate", args->camera_rate_hz, "rendered camera frames per second (default 1)")
      ->check(CLI::Range(0.01, 100.0));
  cmd->add_option("--kf-angular-psd", args->experiment.kf_angular_psd,
                  "KF process noise: angular acceleration spectral density, rad^2/s^3")
      ->check(PositiveNumber());
  cmd->add_option("--kf-linear-psd", args->experiment.kf_linear_psd,
                  "KF process noise: linear acceleration spectral density, m^2/s^3")
      ->check(PositiveNumber());
  cmd->add_option("--camera-model", *camera_model,
                  "the camera's error model: ideal (the nominal rig, default), paper (the model `mcms fov-map --measured` "
                  "fits to the paper's Table 1: blob-centre noise x11, per-visit rigid error 0.98 mm in y and 0.25 mm in z), or "
                  "FILE, the JSON of `mcms fov-map --measured --json FILE`");
  cmd->add_flag("--save-images", args->save_images, "also write the rendered recording (PNG, ~0.6 MB per image)");
  cmd->add_flag("--no-iso9283", *no_iso, "skip the ISO 9283 experiment");
  cmd->add_flag("--html,!--no-html", *html,
                "write OUT/report.html, the run's self-contained HTML report (as `mcms report OUT`; the default), "
                "or not (--no-html)");
  cmd->add_option("--threads", args->threads, "render threads (default: the hardware's)")->check(CLI::Range(1, kMaxThreads));
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args, out, no_iso, html, camera_model] {
                          args->out = *out;
                          args->camera_model = ReadCameraErrorModel(*camera_model);
                          args->iso9283 = !*no_iso;
                          RunDemo(*args, CommandOutput("demo", true));
                          if (*html) {
                            const auto page = std::filesystem::path(*out) / "report.html";
                            const HtmlReportContents c = WriteHtmlReport({*out}, page);
                            std::printf("report: %s (%zu figures, %zu tables; open it in a browser)\n", page.string().c_str(),
                                        c.figures, c.tables);
                          }
                          RecordOutputFolder(*out, "demo");
                          return 0;
                        }));
});

}  // namespace
}  // namespace mcms::app
