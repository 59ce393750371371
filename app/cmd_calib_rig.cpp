// mcms calib-rig: calibrates a camera rig from calibration-board images (the job:
// jobs/rig_calibration_job.h); this file only parses the options and prints.
#include <cstdio>

#include "app/commands.h"
#include "jobs/rig_calibration_job.h"

namespace mcms::app {
namespace {

struct CalibRigArgs {
  std::string board;
  std::vector<std::string> folders;
  std::string lensmodel = "auto";
  int max_iterations = 200;
  std::string output = "calib-rig";
  double outlier_k = 4.0;
  double range_m = 10.0;
  bool board_warp = false;
  bool quiet = false;
  CalibrationQualityLimits limits;
  bool allow_poor_fit = false;
};

int RunCalibRig(const CalibRigArgs& a) {
  RigCalibrationJob job;
  job.board = a.board;
  for (const auto& f : a.folders) job.folders.push_back(f);
  job.output = a.output;
  job.lensmodel = a.lensmodel;
  job.max_iterations = a.max_iterations;
  job.outlier_k = a.outlier_k;
  job.range_m = a.range_m;
  job.board_warp = a.board_warp;
  job.quiet = a.quiet;
  job.limits = a.limits;
  job.allow_poor_fit = a.allow_poor_fit;
  RunRigCalibrationJob(job, CommandOutput("calib-rig", a.quiet));
  return 0;
}

McmsCommand calib_rig_command([](CLI::App& app) {
  auto args = std::make_shared<CalibRigArgs>();
  CLI::App* cmd = app.add_subcommand(
      "calib-rig",
      "Calibrate a camera rig from calibration-board images: every camera's intrinsics (mrcal lens model) and pose "
      "in the rig (the first camera defines the rig frame), by bundle adjustment with outlier rejection. Give one "
      "image folder per camera (images of the same moment share a file name) or a single folder for one camera. "
      "Writes <camera>.cameramodel (mrcal; with optimization_inputs for chessboards, so mrcal's uncertainty and diff "
      "tools read it), <camera>.yml (OpenCV), rig.yaml and residuals-<camera>.svg to the "
      "output folder, and prints residuals, parameter standard deviations and the projection uncertainty.");
  cmd->add_option("BOARD", args->board,
                  "board description (Kalibr YAML: target_type aprilgrid with tagCols, tagRows, tagSize, tagSpacing; "
                  "or checkerboard with targetCols, targetRows (inner corners), rowSpacingMeters, colSpacingMeters)")
      ->required();
  cmd->add_option("FOLDERS", args->folders, "image folder per camera (its name names the camera)")->required();
  cmd->add_option("-m,--lensmodel", args->lensmodel,
                  "auto (default: solves LENSMODEL_OPENCV4, _OPENCV5 and _OPENCV8 and keeps the converged one with "
                  "every distortion coefficient determined and the lowest BIC; prints why), or one of "
                  "LENSMODEL_OPENCV4, _OPENCV5, _OPENCV8, _OPENCV12, LENSMODEL_PINHOLE");
  cmd->add_option("--max-iterations", args->max_iterations,
                  "iteration limit of each bundle-adjustment solve (default 200); a solve that reaches it has not "
                  "converged and nothing is written")
      ->check(PositiveNumber());
  cmd->add_option("-o,--output", args->output, "output folder (created; default ./calib-rig)");
  cmd->add_option("--outlier-k", args->outlier_k,
                  "reject points with a coordinate beyond k sigma and re-solve, in rounds where one exceeds "
                  "k + 1 sigma (0 = keep all)")
      ->check(NonNegativeNumber());
  cmd->add_option("--range", args->range_m, "range in metres for the projection-uncertainty report")
      ->check(PositiveNumber());
  cmd->add_flag("--board-warp", args->board_warp, "also solve the board's out-of-plane warp (mrcal's calobject_warp)");
  cmd->add_option("--max-rms", args->limits.max_rms_px,
                  "refuse a solution whose residual RMS exceeds this (px per coordinate; default 1)")
      ->check(PositiveNumber());
  cmd->add_option("--max-noise-ratio", args->limits.max_noise_ratio,
                  "refuse a solution whose residual exceeds the views' own noise floor (each view's board pose "
                  "fitted alone with the solved lens) by more than this factor (default 1.5): the views then do "
                  "not agree with one rig")
      ->check(CLI::Range(1.0, 1e9));
  cmd->add_option("--max-outlier-fraction", args->limits.max_outlier_fraction,
                  "refuse a solution that rejected more than this fraction of the points (default 0.1; and, always, "
                  "one where a view lost more than half of its points: that view disagrees with the others)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_flag("--allow-poor-fit", args->allow_poor_fit,
                "write a solution that fails these checks (or has a singular covariance) anyway, with a warning on "
                "stderr and stdout");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress on stderr");
  return std::make_pair(cmd, Runner([args] { return RunCalibRig(*args); }));
});

}  // namespace
}  // namespace mcms::app
