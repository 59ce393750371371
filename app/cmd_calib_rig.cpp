// mcms calib-rig: calibration-board images per camera -> every camera's intrinsics
// and pose in the rig (camera 0 = rig frame), as mrcal .cameramodel (with mrcal's
// optimization_inputs for chessboards), OpenCV YAML and rig.yaml, with a residual
// summary and per-camera residual plots. The lens model is chosen by the data unless
// given; a solve that did not converge writes nothing, nor (without --allow-poor-fit)
// one that CalibrationProblems finds untrustworthy. Symmetric chessboards are
// renumbered per frame to agree across the cameras, and every renumbering is printed.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "app/commands.h"
#include "calib/calibration_board.h"
#include "calib/camera_calibration.h"
#include "calib/mrcal_optimization_inputs.h"
#include "core/error.h"
#include "core/io.h"

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

// Projection uncertainties that cannot come from a sound covariance: exactly zero, or
// beyond this (px; larger than any image: the lens is not determined there).
constexpr double kMaxMeaningfulUncertaintyPx = 1000.0;

bool IsImage(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  static const std::set<std::string> kExt = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"};
  return kExt.count(e) > 0;
}

int RunCalibRig(const CalibRigArgs& a) {
  namespace fs = std::filesystem;
  const CalibrationBoard board = CalibrationBoard::Read(a.board);
  CameraCalibrationOptions options;
  options.lensmodel = a.lensmodel;
  options.max_iterations = a.max_iterations;
  options.outlier_k = a.outlier_k;
  options.solve_board_warp = a.board_warp;
  if (!a.quiet) options.log = [](const std::string& s) { std::fprintf(stderr, "calib-rig: %s\n", s.c_str()); };
  std::string why;
  if (!options.IsValid(&why)) Throw("calib-rig options: ", why);
  // Refuse an unusable output folder before detection, not after the solve.
  RequireWritableFolder(a.output, "calib-rig -o");

  // Images per camera; a frame is one file name (stem) shared across the folders.
  std::vector<std::vector<fs::path>> images(a.folders.size());
  std::set<std::string> stems;
  CameraCalibrationInput input;
  for (size_t c = 0; c < a.folders.size(); ++c) {
    const fs::path dir = a.folders[c];
    if (!fs::is_directory(dir)) Throw("image folder ", dir.string(), " does not exist or is not a folder");
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file() && IsImage(e.path())) images[c].push_back(e.path());
    std::sort(images[c].begin(), images[c].end());
    if (images[c].empty())
      Throw("image folder ", dir.string(), " holds no images (.png, .jpg, .bmp, .tif, .pgm)");
    for (const auto& p : images[c]) stems.insert(p.stem().string());
    std::string name = fs::path(dir).lexically_normal().filename().string();
    if (name.empty() || name == ".") name = "cam" + std::to_string(c);
    input.camera_names.push_back(name);
  }
  const std::vector<std::string> frame_names(stems.begin(), stems.end());
  size_t total = 0;
  for (const auto& v : images) total += v.size();
  Progress progress("detect", total, a.quiet);
  size_t done = 0;
  for (size_t c = 0; c < a.folders.size(); ++c) {
    int width = 0, height = 0, found = 0;
    for (const fs::path& p : images[c]) {
      cv::Mat img;
      try {
        img = cv::imread(p.string(), cv::IMREAD_GRAYSCALE);
      } catch (const cv::Exception& e) {
        Throw("image ", p.string(), ": cannot be read as an image (", e.err, ")");
      }
      if (img.empty()) Throw("image ", p.string(), ": cannot be read as an image");
      if (width == 0) width = img.cols, height = img.rows;
      else if (img.cols != width || img.rows != height)
        Throw("image ", p.string(), " is ", img.cols, "x", img.rows, " but the other images of camera ",
              input.camera_names[c], " are ", width, "x", height);
      const BoardDetection det = DetectBoard(board, img);
      progress.Update(++done);
      if (det.size() == 0) continue;
      ++found;
      BoardObservation o;
      o.camera = static_cast<int>(c);
      o.frame = static_cast<int>(std::lower_bound(frame_names.begin(), frame_names.end(), p.stem().string()) -
                                 frame_names.begin());
      o.pixels = det.pixels;
      for (int id : det.ids) o.points_board.push_back(board.Point(id));
      input.observations.push_back(std::move(o));
    }
    if (found == 0)
      Throw("the board (", board.Describe(), ", from ", a.board, ") was not found in any of the ", images[c].size(),
            " images of camera ", input.camera_names[c], " (", a.folders[c],
            "); check the board file (chessboards count inner corners) and that the images show the whole board; "
            "no output written");
    input.widths.push_back(width);
    input.heights.push_back(height);
    if (!a.quiet)
      std::fprintf(stderr, "calib-rig: %s: board found in %d of %zu images\n", input.camera_names[c].c_str(), found,
                   images[c].size());
  }
  progress.Finish();
  // A symmetric chessboard may be numbered differently by two cameras in one frame:
  // the calibration renumbers such views to agree (and says so below).
  input.board_symmetries = board.NumberingSymmetries();

  const CameraCalibrationResult r = CalibrateCameras(input, options);
  if (!r.lens_model_trials.empty()) {
    std::printf("lens model (auto): BIC = n ln(RSS/n) + k ln(n) over the %d residuals every candidate kept\n",
                r.lens_model_trials[0].num_residuals);
    for (const LensModelTrial& t : r.lens_model_trials)
      std::printf("  %-18s %s %4d iterations, RMS %.4f px, %d parameters, BIC %.1f, largest distortion 1-sigma %.3g%s\n",
                  t.lensmodel.c_str(), t.converged ? "converged    " : "NOT CONVERGED", t.iterations, t.rms_px,
                  t.num_parameters, t.bic, t.largest_distortion_std, t.chosen ? "  <- chosen" : "");
    std::printf("%s\n", r.lens_model_choice.c_str());
  }
  if (!r.converged)
    Throw("calib-rig: the bundle adjustment with ", r.lensmodel, " did not converge in ", r.iterations,
          " iterations (Ceres: ", r.solver_message, "); its parameters are not a solution. Raise --max-iterations "
          "(now ", a.max_iterations, ") or choose a simpler --lensmodel (or auto); no output written");
  if (!r.renumbered.empty() || !r.dropped.empty())
    std::printf("the board's numbering is symmetric (%s: the detector may number it turned by %s); each frame's "
                "views were matched across the cameras:\n",
                board.Describe().c_str(), board.cols == board.rows ? "90, 180 or 270 deg" : "180 deg");
  for (const BoardRenumbering& n : r.renumbered)
    std::printf("  frame %s: %s renumbered (its numbering was turned by %.0f deg against the other cameras'; "
                "reprojection %.2f px renumbered, %.2f px under the next best numbering)\n",
                frame_names[n.frame].c_str(), input.camera_names[n.camera].c_str(), 360.0 - n.angle_deg, n.rms_px,
                n.next_rms_px);
  for (const DroppedObservation& d : r.dropped)
    std::printf("  frame %s: %s left out: %s\n", frame_names[d.frame].c_str(), input.camera_names[d.camera].c_str(),
                d.reason.c_str());
  // Is the solution trustworthy? Residual against its noise, outliers, covariance,
  // projection uncertainty; all computed before anything is written.
  std::vector<std::string> problems = CalibrationProblems(r, a.limits, frame_names);
  std::vector<UncertaintyGrid> grids;
  for (size_t c = 0; c < r.rig.size(); ++c) {
    grids.push_back(ProjectionUncertaintyGrid(r, static_cast<int>(c), a.range_m));
    int bad = 0;
    for (double s : grids.back().sigma_px) bad += std::isfinite(s) && !(s > 0.0 && s < kMaxMeaningfulUncertaintyPx);
    if (bad > 0)
      problems.push_back(r.rig.names[c] + ": " + std::to_string(bad) + " of " +
                         std::to_string(grids.back().sigma_px.size()) +
                         " projection uncertainties are 0 px or above " +
                         std::to_string(static_cast<int>(kMaxMeaningfulUncertaintyPx)) +
                         " px, which no sound covariance gives");
  }
  if (!problems.empty()) {
    std::string list;
    for (const std::string& p : problems) list += "\n  - " + p;
    if (!a.allow_poor_fit)
      Throw("calib-rig: the calibration is not trustworthy:", list,
            "\nno output written (--allow-poor-fit writes it anyway, with this warning; the limits are "
            "--max-rms, --max-noise-ratio and --max-outlier-fraction)");
    std::fprintf(stderr, "calib-rig: WARNING: the calibration is not trustworthy (written because of --allow-poor-fit):%s\n",
                 list.c_str());
    std::printf("WARNING: the calibration is not trustworthy (written because of --allow-poor-fit):%s\n", list.c_str());
  }
  // mrcal's optimization_inputs need the board as a regular grid: chessboards only.
  std::string optimization_inputs, no_inputs_why;
  if (board.type == CalibrationBoard::Type::kChessboard)
    optimization_inputs = MrcalOptimizationInputs(r, MrcalBoardGrid{board.cols, board.rows, board.square_m});
  else
    no_inputs_why = "the models carry no optimization_inputs: mrcal describes a board as a regular grid of points, "
                    "and an AprilTag grid's corners are not one (mrcal's uncertainty tools need a chessboard)";

  // Everything is computed; only now write the outputs (each atomically): plots first,
  // then the models, rig.yaml last, so a failure part-way leaves no rig.yaml.
  const fs::path out = a.output;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) Throw("calib-rig -o ", out.string(), ": cannot create the output folder: ", ec.message());
  for (size_t c = 0; c < r.rig.size(); ++c)
    WriteResidualPlot(r, static_cast<int>(c), out / ("residuals-" + r.rig.names[c] + ".svg"));
  for (size_t c = 0; c < r.rig.size(); ++c) {
    const std::string& name = r.rig.names[c];
    if (optimization_inputs.empty())
      r.rig.cameras[c].WriteCameramodel(out / (name + ".cameramodel"));
    else
      WriteCameramodelWithOptimizationInputs(r, static_cast<int>(c), optimization_inputs, out / (name + ".cameramodel"));
    r.rig.cameras[c].WriteOpenCvYaml(out / (name + ".yml"));
  }
  r.rig.Write(out / "rig.yaml");

  std::printf("%s", SummarizeCalibration(r).c_str());
  if (a.board_warp)
    std::printf("board warp: %.3f +- %.3f mm (x), %.3f +- %.3f mm (y)\n", r.board_warp_m[0] * 1e3,
                r.board_warp_std_m[0] * 1e3, r.board_warp_m[1] * 1e3, r.board_warp_std_m[1] * 1e3);
  std::printf("residual against the views' own noise floor (each view's board pose fitted alone): %.4f / %.4f px "
              "per coordinate = %.2f\n",
              std::sqrt(r.residual_variance_px2), std::sqrt(r.views_alone_variance_px2),
              std::sqrt(r.residual_variance_px2 / r.views_alone_variance_px2));
  for (size_t c = 0; c < r.rig.size(); ++c) {
    const UncertaintyGrid& g = grids[c];
    std::printf("%s: projection uncertainty (worst direction, 1 sigma, px; mrcal's mean-frames method) at %.2f m, "
                "%dx%d grid over the image:\n",
                r.rig.names[c].c_str(), a.range_m, g.nx, g.ny);
    for (int j = 0; j < g.ny; ++j) {
      std::printf("  ");
      for (int i = 0; i < g.nx; ++i) std::printf(" %7.3f", g.sigma_px[j * g.nx + i]);
      std::printf("\n");
    }
  }
  std::printf("wrote %zu camera models (.cameramodel%s, .yml), residual plots and rig.yaml to %s\n", r.rig.size(),
              optimization_inputs.empty() ? "" : " with mrcal's optimization_inputs", out.string().c_str());
  if (!no_inputs_why.empty()) std::printf("note: %s\n", no_inputs_why.c_str());
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
      ->check(CLI::PositiveNumber);
  cmd->add_option("-o,--output", args->output, "output folder (created; default ./calib-rig)");
  cmd->add_option("--outlier-k", args->outlier_k,
                  "reject points with a coordinate beyond k sigma and re-solve, in rounds where one exceeds "
                  "k + 1 sigma (0 = keep all)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--range", args->range_m, "range in metres for the projection-uncertainty report")
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--board-warp", args->board_warp, "also solve the board's out-of-plane warp (mrcal's calobject_warp)");
  cmd->add_option("--max-rms", args->limits.max_rms_px,
                  "refuse a solution whose residual RMS exceeds this (px per coordinate; default 1)")
      ->check(CLI::PositiveNumber);
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
