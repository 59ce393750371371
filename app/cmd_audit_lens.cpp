// mcms audit lens MODEL.cameramodel: the lens mode of the model audit (audit/lens_audit.h):
// refits the chessboard observations stored in a mrcal .cameramodel with its own lens
// model and with richer ones (OpenCV8/12, mrcal's splined model), scores each on held-out
// boards, and names the richer model only when it earns its parameters.
#include <cstdio>
#include <memory>

#include "app/audit_modes.h"
#include "jobs/lens_audit_job.h"
#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/output_folder.h"

namespace mcms::app {
namespace {

struct AuditLensArgs {
  std::string model, output, json;
  std::vector<std::string> candidates;
  double false_alarm = 0.01;
  int folds = 5, spline_nx = 30, spline_ny = 0, threads = 0;
  bool quiet = false, contiguous = false;
};

int RunAuditLens(const AuditLensArgs& a) {
  LensAuditJob job;
  job.model = a.model;
  job.output = a.output;
  job.json = a.json;
  job.options.false_alarm = a.false_alarm;
  job.options.folds = a.folds;
  job.options.contiguous_folds = a.contiguous;
  job.options.candidates = a.candidates;
  job.options.spline_nx = a.spline_nx;
  job.options.spline_ny = a.spline_ny;
  job.options.threads = a.threads;
  RunLensAuditJob(job, CommandOutput("audit lens", a.quiet));
  return 0;
}

}  // namespace

std::pair<CLI::App*, Runner> AddAuditLens(CLI::App& audit) {
  auto args = std::make_shared<AuditLensArgs>();
  CLI::App* cmd = audit.add_subcommand(
      "lens",
      "Audit a camera's lens model against the chessboard observations stored in a mrcal .cameramodel "
      "(its optimization_inputs): refit them with the file's own lens model and with richer ones (default: "
      "LENSMODEL_OPENCV8 and LENSMODEL_OPENCV12 where richer, and mrcal's splined stereographic model), score each "
      "on held-out boards (interleaved folds) and by BIC, and name the richer model (effect "
      "lens_model) only when it earns its parameters.");
  cmd->add_option("MODEL", args->model, "a mrcal .cameramodel with optimization_inputs")->required();
  cmd->add_option("-o,--output", args->output,
                  "output folder: report.txt, report.json, residuals.csv, plots/<camera>.svg (residuals binned over the image "
                  "and against the distance from the centre) and the named model as <camera>.cameramodel");
  cmd->add_option("--json", args->json, "write the machine-readable report here");
  cmd->add_option("--candidates", args->candidates,
                  "richer lens models to try (mrcal names; 'splined' = the default splined model)");
  cmd->add_option("--spline-nx", args->spline_nx, "knots across the splined model (default 30)");
  cmd->add_option("--spline-ny", args->spline_ny, "knots down (default: square cells)");
  cmd->add_option("--false-alarm", args->false_alarm,
                  "designed probability that a richer model is named on data the nominal explains (default 0.01)");
  cmd->add_option("--folds", args->folds, "held-out folds of board observations (default 5)");
  cmd->add_flag("--contiguous-folds", args->contiguous,
                "folds of contiguous capture order (tests extrapolation to regions of the view a block alone "
                "covered) instead of interleaved boards");
  cmd->add_option("--threads", args->threads, "threads solving the held-out folds side by side (0 = all cores); the result does not depend on it")
      ->check(CLI::Range(0, kMaxThreads));
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunAuditLens(*args); }));
}

}  // namespace mcms::app
