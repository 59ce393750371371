// mcms render: synthetic camera images of the five-ball target with their ground
// truth (synthetic/renderer.h, synthetic/scenario.h).
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "core/limits.h"
#include "app/commands.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "synthetic/scenario.h"
#include "vision/image_file.h"

namespace mcms::app {
namespace {

struct RenderArgs {
  std::string scenario;
  std::string out;
  long long frames = -1;
  std::optional<uint64_t> seed;
  bool quiet = false;
  bool print_default = false;
  int threads = 0;  // 0 = all cores
  std::string format = "png";
};

int RunRender(const RenderArgs& a) {
  if (a.print_default) {
    std::fputs(Scenario::DefaultText().c_str(), stdout);
    return 0;
  }
  if (a.out.empty()) Throw("render: the output folder is missing; give -o DIR");
  RequireOutputsSpareInputs({{a.out, "render -o", true}}, {a.scenario});
  RequireWritableFolder(a.out, "render -o");
  Scenario s = a.scenario.empty() ? Scenario::Default() : Scenario::Read(a.scenario);
  const std::string source = a.scenario.empty() ? std::string("the default scenario") : a.scenario;
  if (a.frames >= 0) {
    if (a.frames == 0 || static_cast<size_t>(a.frames) > s.NumFrames())
      Throw("render: --frames ", a.frames, " must be between 1 and the ", s.NumFrames(), " frames of ", source);
    s.times.resize(static_cast<size_t>(a.frames));
    s.T_rig_target.resize(static_cast<size_t>(a.frames));
  }
  if (a.seed) s.seed = *a.seed;
  const int threads = ThreadsToUse(a.threads);
  const ImageFileFormat format = ParseImageFileFormat(a.format, "render --format");
  RenderSequence(s, a.out, a.quiet, threads, format);
  if (!a.quiet)
    std::fprintf(stderr, "render: %zu frames x %zu cameras (%s) written to %s\n", s.NumFrames(), s.rig.size(),
                 ToString(format), a.out.c_str());
  return 0;
}

const McmsCommand kRender([](CLI::App& app) {
  auto args = std::make_shared<RenderArgs>();
  CLI::App* sub = app.add_subcommand("render", "Render synthetic camera images of the target with ground truth");
  sub->description(
      "Render synthetic camera images of the five-ball target and their ground truth.\n"
      "SCENARIO is a YAML or JSON scenario file (rig, target, motion, render options, seed; format in\n"
      "synthetic/scenario.h); without it the built-in default is rendered: the paper's 4 cameras above\n"
      "a 1 x 0.8 x 1 m working volume, 120 frames at 10 Hz. `mcms render --print-default` prints that\n"
      "scenario as a starting point for your own.\n"
      "DIR receives: scenario.yaml (effective), rig.yaml, cameras/<name>.cameramodel, target.yaml,\n"
      "frames.csv, images/<camera>/<frame %06d>.png (.pgm, .tif with --format), truth/{poses,balls,\n"
      "observations,spurious,dropouts}.csv. It is written to a temporary folder and moved into place when complete; an\n"
      "earlier render in DIR is replaced, any other non-empty DIR is refused. The same scenario and\n"
      "seed give byte-identical output. Progress goes to stderr.");
  sub->add_option("SCENARIO", args->scenario, "Scenario file (YAML or JSON); default: the built-in scenario")
      ->check(CLI::ExistingFile)
      ->type_name("FILE");
  sub->add_option("-o,--output", args->out, "Output folder (required unless --print-default)")->type_name("DIR");
  sub->add_option("--frames", args->frames, "Render only the first N frames of the scenario")
      ->check(PositiveNumber())
      ->type_name("N");
  sub->add_option("--seed", args->seed, "Random seed, overriding the scenario's")->check(SeedValidator())->type_name("S");
  sub->add_option("--threads", args->threads, "Threads rendering frames (0 = all cores); the output does not depend on it")
      ->check(CLI::Range(0, kMaxThreads))
      ->type_name("N");
  sub->add_option("--format", args->format,
                  "Image files: png (compressed, the default), pgm (binary PGM) or tiff (uncompressed TIFF); "
                  "`mcms track` reads all three, the uncompressed ones memory-mapped (several times faster, "
                  "about 2x the disk space)")
      ->check(CLI::IsMember({"png", "pgm", "tiff"}))
      ->type_name("FORMAT");
  sub->add_flag("-q,--quiet", args->quiet, "No progress on stderr");
  sub->add_flag("--print-default", args->print_default, "Print the default scenario file and exit");
  return std::make_pair(sub, Runner([args] { return RunRender(*args); }));
});

}  // namespace
}  // namespace mcms::app
