// mcms iso9283: ISO 9283 pose, distance and path characteristics from measured poses
// (formats and evaluation in calib/iso9283_report.h), or --simulate: the forward-model
// experiment (jobs/iso9283_experiment.h). This file parses and prints.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "app/commands.h"
#include "calib/iso9283_report.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "jobs/iso9283_experiment.h"

namespace mcms::app {
namespace {

struct IsoArgs {
  std::string poses, path, output;
  // --simulate: the experiment on the forward model (jobs/iso9283_experiment.h)
  // instead of measured input.
  bool simulate = false;
  int cycles = 30;
  uint64_t seed = Iso9283ExperimentOptions{}.seed;
  std::string simulate_dir;
};

// The four conditions of the forward-model experiment: tables on stdout, -o the
// characteristics CSV, --write-measurements the attained poses and paths per condition
// (this command's own input layout, so each can be re-evaluated from its file).
int RunIso9283Simulation(const IsoArgs& a) {
  if (!a.poses.empty() || !a.path.empty())
    Throw("iso9283 --simulate: makes its own measurements; give no POSES file and no --path");
  if (!a.output.empty()) RequireWritableFile(a.output, "iso9283 -o");
  // The folder is the command's own output: written whole, replacing only an earlier one
  // (never a folder holding the user's files).
  const std::vector<std::string> markers = {"attained_1.csv", "path_1.csv"};
  if (!a.simulate_dir.empty()) {
    RequireWritableFolder(a.simulate_dir, "iso9283 --write-measurements");
    RequireReplaceableFolder(a.simulate_dir, markers, "iso9283", "iso9283 --write-measurements");
  }
  Iso9283ExperimentOptions o;
  o.cycles = a.cycles;
  o.seed = a.seed;
  const Iso9283Experiment e = RunIso9283Experiment(o);
  if (!a.output.empty()) WriteIso9283ExperimentCsv(a.output, e);
  if (!a.simulate_dir.empty())
    WriteFolderAtomically(a.simulate_dir, markers, "iso9283", "iso9283 --write-measurements",
                          [&](const std::filesystem::path& dir) { WriteIso9283Measurements(dir, "", e); });
  std::fputs(FormatIso9283Experiment(e).c_str(), stdout);
  return 0;
}

int RunIso9283(const IsoArgs& a) {
  if (a.simulate) return RunIso9283Simulation(a);
  if (!a.simulate_dir.empty())
    Throw("iso9283 --write-measurements writes the measurements of the simulated experiment; give it with "
          "--simulate (measured POSES are the input, not an output)");
  if (a.poses.empty()) Throw("iso9283: POSES (a pose CSV) is required, or --simulate");
  RequireOutputsSpareInputs({{a.output, "iso9283 -o"}}, {a.poses, a.path});
  if (!a.output.empty()) RequireWritableFile(a.output, "iso9283 -o");
  const Iso9283Report r = EvaluateIso9283Files(a.poses, a.path);
  if (!a.output.empty()) WriteFileAtomically(a.output, [&](std::ostream& o) { o << r.csv; });
  std::fputs(r.table.c_str(), stdout);
  return 0;
}

const McmsCommand kIso9283([](CLI::App& app) {
  auto args = std::make_shared<IsoArgs>();
  CLI::App* sub = app.add_subcommand("iso9283", "ISO 9283 pose, distance and path accuracy and repeatability");
  sub->description(
      "ISO 9283 accuracy and repeatability from repeated measurements of commanded poses.\n"
      "POSES.csv: header and one row per attained pose:\n"
      "  pose,cycle,cmd_x_m,cmd_y_m,cmd_z_m,cmd_qw,cmd_qx,cmd_qy,cmd_qz,x_m,y_m,z_m,qw,qx,qy,qz\n"
      "  (pose = commanded pose name, cycle = repetition; quaternions w,x,y,z; metres).\n"
      "Reports per pose AP, RP (with AP_a/b/c, RP_a/b/c: rotation deviations about x, y, z), per\n"
      "consecutive pose pair AD, RD (cycles matched by name), and with --path AT, RT from a CSV\n"
      "run,x_m,y_m,z_m where run = commanded marks the commanded path (calculation points).\n"
      "Table on stdout (mm, deg); -o writes it as CSV.\n"
      "--simulate: no input; runs the experiment on the forward model (KR 5 arc with DH, base, tool and gear\n"
      "errors, the 4-camera rig, the inclinometer) before and after calibration and before and after a\n"
      "camera-only and a MOIFA correction, and prints the four conditions' tables.");
  sub->add_option("POSES", args->poses, "Pose CSV (required unless --simulate)")->check(CLI::ExistingFile);
  sub->add_flag("--simulate", args->simulate, "Run the forward-model experiment instead of reading POSES");
  sub->add_option("--cycles", args->cycles, "--simulate: cycles P1..P5 (ISO 9283: 30; 2 to 100000)")
      ->check(CLI::Range(2, 100000));
  sub->add_option("--seed", args->seed, "--simulate: random seed")->check(SeedValidator());
  sub->add_option("--write-measurements", args->simulate_dir,
                  "--simulate: folder for attained_<k>.csv and path_<k>.csv per condition k = 1..4")
      ->type_name("DIR");
  sub->add_option("--path", args->path, "Path CSV (run,x_m,y_m,z_m)")->check(CLI::ExistingFile);
  sub->add_option("-o,--output", args->output, "Also write the table as CSV")->type_name("FILE");
  return std::make_pair(sub, Runner([args] { return RunIso9283(*args); }));
});

}  // namespace
}  // namespace mcms::app
