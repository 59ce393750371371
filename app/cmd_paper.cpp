// mcms paper fusion: the simulation of section 3.3 of Liu, Zhang, Qu (2015), Table 3
// reproduced by MOIFA and by the paper's KF scheme, with the analytic figures, the paper's
// published numbers beside ours, and what the paper's 78.2 % "KF" figure measures.
// The simulation itself lives in fusion/paper_simulation.h.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include "app/commands.h"
#include "core/error.h"
#include "core/io.h"
#include "fusion/paper_simulation.h"

namespace mcms::app {
namespace {

namespace fs = std::filesystem;

struct PaperFusionArgs {
  uint64_t seed = 1;
  int repetitions = 200;
  int points = 100;
  double cube_mm = 100.0;
  std::string paper_results;  // fusion_results.csv; empty: look in the usual places
};

int RunPaperFusion(const PaperFusionArgs& a) {
  PaperFusionOptions o;
  o.seed = a.seed;
  o.repetitions = a.repetitions;
  o.num_points = a.points;
  o.cube_size = a.cube_mm * 1e-3;
  // The simulation keeps every point of every repetition: bounded in all (some 0.5 kB each).
  if (static_cast<double>(a.repetitions) * a.points > 1e7)
    Throw("paper fusion: --repetitions ", a.repetitions, " x --points ", a.points,
          " simulated points, more than the 1e7 this simulation holds in memory; the paper's figures need 200 x 100");
  // A cube a robot's workspace holds (the paper's 100 mm).
  if (!(a.cube_mm <= 1e4)) Throw("paper fusion: --cube-mm ", a.cube_mm, ": expected up to 10000 mm (a robot's workspace)");
  std::string why;
  if (!o.IsValid(&why)) Throw(why);
  // Resolve (and check) every input before printing anything.
  std::string looked;
  const std::optional<fs::path> paper_file = FindPaperResults(a.paper_results, &looked);
  std::optional<CsvTable> paper_table;
  if (paper_file) paper_table = ReadCsv(*paper_file);
  const PaperFusionResult r = SimulatePaperFusion(o);
  std::fputs(FormatPaperFusionReport(o, r, paper_table ? &*paper_table : nullptr, looked).c_str(), stdout);
  return 0;
}

McmsCommand paper_command([](CLI::App& app) {
  CLI::App* paper = app.add_subcommand("paper", "Reproduce figures of Liu, Zhang, Qu (2015), Sensors 15:7933.");
  paper->require_subcommand(1);
  auto fa = std::make_shared<PaperFusionArgs>();
  CLI::App* fusion = paper->add_subcommand(
      "fusion",
      "Section 3.3: 100 random points in a 100 mm cube measured by camera and robot, fused by MOIFA and by the "
      "paper's KF scheme; Table 3 by the three-sigma rule and as RMS, with the analytic figures and the paper's.");
  fusion->add_option("--seed", fa->seed, "random seed (default 1)")->check(SeedValidator());
  fusion->add_option("--repetitions", fa->repetitions, "Monte-Carlo repetitions (default 200)")
      ->check(CLI::Range(2, 1000000));
  fusion->add_option("--points", fa->points, "points per repetition (default 100)")->check(CLI::Range(2, 1000000));
  fusion->add_option("--cube-mm", fa->cube_mm, "edge of the cube of random points, mm (default 100)")
      ->check(PositiveNumber());
  fusion->add_option("--paper-results", fa->paper_results,
                     "the paper's figures (default: $MCMS_DATA_DIR/paper/fusion_results.csv or "
                     "../shared/data/paper/fusion_results.csv)");
  return std::make_pair(paper, Runner([fusion, fa]() -> int {
                          if (fusion->parsed()) return RunPaperFusion(*fa);
                          return 1;
                        }));
});

}  // namespace
}  // namespace mcms::app
