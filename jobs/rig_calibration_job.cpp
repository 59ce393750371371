#include "jobs/rig_calibration_job.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <map>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "calib/calibration_board.h"
#include "calib/mrcal_optimization_inputs.h"
#include "core/error.h"
#include "core/format.h"
#include "core/io.h"
#include "core/output_folder.h"

namespace mcms {
namespace {

// A camera is named by its image folder ("left/" names it left; cam<k> when the folder has
// no name, e.g. ".").
std::string CameraNameOfFolder(const std::filesystem::path& dir, size_t c) {
  std::filesystem::path p = dir.lexically_normal();
  if (!p.has_filename()) p = p.parent_path();
  std::string name = p.filename().string();
  if (name.empty() || name == ".") name = "cam" + std::to_string(c);
  return name;
}

namespace fs = std::filesystem;

// Projection uncertainties that cannot come from a sound covariance: exactly zero, or
// beyond this (px; larger than any image: the lens is not determined there).
constexpr double kMaxMeaningfulUncertaintyPx = 1000.0;

bool IsImage(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  static const std::set<std::string> kExt = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"};
  return kExt.count(e) > 0;
}

struct Detected {
  CameraCalibrationInput input;
  std::vector<std::string> frame_names;  // a frame is one file name (stem) shared across the folders
};

// Every image of every camera: the board's corners detected; frames matched by file name.
Detected DetectBoards(const RigCalibrationJob& a, const CalibrationBoard& board) {
  Detected d;
  CameraCalibrationInput& input = d.input;
  std::vector<std::vector<fs::path>> images(a.folders.size());
  std::set<std::string> stems;
  for (size_t c = 0; c < a.folders.size(); ++c) {
    const fs::path dir = a.folders[c];
    if (!fs::is_directory(dir)) Throw("image folder ", dir.string(), " does not exist or is not a folder");
    for (const auto& e : fs::directory_iterator(dir)) {
      if (!IsImage(e.path())) continue;
      std::error_code ec;
      if (e.is_regular_file(ec)) {
        images[c].push_back(e.path());
      } else if (!e.is_directory(ec)) {
        // A pipe, device, socket or dangling link named like an image: reading it would block
        // or fail, and skipping it would silently drop a view.
        Throw("image ", e.path().string(), " is not a regular file (",
              e.is_fifo(ec) ? "a FIFO" : e.is_symlink(ec) ? "a link to nothing" : "a device or socket",
              "); remove it or copy the image there; no output written");
      }
    }
    std::sort(images[c].begin(), images[c].end());
    if (images[c].empty())
      Throw("image folder ", dir.string(), " holds no images (.png, .jpg, .bmp, .tif, .pgm)");
    for (const auto& p : images[c]) stems.insert(p.stem().string());
    input.camera_names.push_back(CameraNameOfFolder(dir, c));
  }
  d.frame_names.assign(stems.begin(), stems.end());
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
      o.frame = static_cast<int>(std::lower_bound(d.frame_names.begin(), d.frame_names.end(), p.stem().string()) -
                                 d.frame_names.begin());
      o.pixels = det.pixels;
      for (int id : det.ids) o.points_board.push_back(board.Point(id));
      input.observations.push_back(std::move(o));
    }
    if (found == 0)
      Throw("the board (", board.Describe(), ", from ", a.board.string(), ") was not found in any of the ",
            images[c].size(), " images of camera ", input.camera_names[c], " (", a.folders[c].string(),
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
  // the calibration renumbers such views to agree (and says so).
  input.board_symmetries = board.NumberingSymmetries();
  return d;
}

// The lens models tried, the renumbered and dropped views.
void ReportSolve(const RigCalibrationJob& a, const CalibrationBoard& board, const Detected& d,
                 const CameraCalibrationResult& r, const std::function<void(const std::string&)>& print) {
  if (!r.lens_model_trials.empty()) {
    print(Format("lens model (auto): BIC = n ln(RSS/n) + k ln(n) over the %d residuals every candidate kept\n",
                 r.lens_model_trials[0].num_residuals));
    for (const LensModelTrial& t : r.lens_model_trials)
      print(Format("  %-18s %s %4d iterations, RMS %.4f px, %d parameters, BIC %.1f, largest distortion 1-sigma %.3g%s\n",
                   t.lensmodel.c_str(), t.converged ? "converged    " : "NOT CONVERGED", t.iterations, t.rms_px,
                   t.num_parameters, t.bic, t.largest_distortion_std, t.chosen ? "  <- chosen" : ""));
    print(r.lens_model_choice + "\n");
  }
  if (!r.converged)
    Throw("calib-rig: the bundle adjustment with ", r.lensmodel, " did not converge in ", r.iterations,
          " iterations (Ceres: ", r.solver_message, "); its parameters are not a solution. Raise --max-iterations "
          "(now ", a.max_iterations, ") or choose a simpler --lensmodel (or auto); no output written");
  if (!r.renumbered.empty() || !r.dropped.empty())
    print(Format("the board's numbering is symmetric (%s: the detector may number it turned by %s); each frame's "
                 "views were matched across the cameras:\n",
                 board.Describe().c_str(), board.cols == board.rows ? "90, 180 or 270 deg" : "180 deg"));
  for (const BoardRenumbering& n : r.renumbered)
    print(Format("  frame %s: %s renumbered (its numbering was turned by %.0f deg against the other cameras'; "
                 "reprojection %.2f px renumbered, %.2f px under the next best numbering)\n",
                 d.frame_names[n.frame].c_str(), d.input.camera_names[n.camera].c_str(), 360.0 - n.angle_deg, n.rms_px,
                 n.next_rms_px));
  for (const DroppedObservation& x : r.dropped)
    print(Format("  frame %s: %s left out: %s\n", d.frame_names[x.frame].c_str(), d.input.camera_names[x.camera].c_str(),
                 x.reason.c_str()));
}

// Is the solution trustworthy? Residual against its noise, outliers, covariance,
// projection uncertainty; all computed before anything is written. Returns the grids.
std::vector<UncertaintyGrid> CheckTrust(const RigCalibrationJob& a, const Detected& d, const CameraCalibrationResult& r,
                                        const std::function<void(const std::string&)>& print) {
  std::vector<std::string> problems = CalibrationProblems(r, a.limits, d.frame_names);
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
    print("WARNING: the calibration is not trustworthy (written because of --allow-poor-fit):" + list + "\n");
  }
  return grids;
}

// The summary: residuals, the board's warp, the noise floor, the projection uncertainty.
void ReportSolution(const RigCalibrationJob& a, const CameraCalibrationResult& r, const std::vector<UncertaintyGrid>& grids,
                    const std::function<void(const std::string&)>& print) {
  print(SummarizeCalibration(r));
  if (a.board_warp)
    print(Format("board warp: %.3f +- %.3f mm (x), %.3f +- %.3f mm (y)\n", r.board_warp_m[0] * 1e3,
                 r.board_warp_std_m[0] * 1e3, r.board_warp_m[1] * 1e3, r.board_warp_std_m[1] * 1e3));
  print(Format("residual against the views' own noise floor (each view's board pose fitted alone): %.4f / %.4f px "
               "per coordinate = %.2f\n",
               std::sqrt(r.residual_variance_px2), std::sqrt(r.views_alone_variance_px2),
               std::sqrt(r.residual_variance_px2 / r.views_alone_variance_px2)));
  for (size_t c = 0; c < r.rig.size(); ++c) {
    const UncertaintyGrid& g = grids[c];
    print(Format("%s: projection uncertainty (worst direction, 1 sigma, px; mrcal's mean-frames method) at %.2f m, "
                 "%dx%d grid over the image:\n",
                 r.rig.names[c].c_str(), a.range_m, g.nx, g.ny));
    for (int j = 0; j < g.ny; ++j) {
      std::string row = "  ";
      for (int i = 0; i < g.nx; ++i) row += Format(" %7.3f", g.sigma_px[j * g.nx + i]);
      print(row + "\n");
    }
  }
}

}  // namespace

void RunRigCalibrationJob(const RigCalibrationJob& a, const JobOutput& sink) {
  const std::function<void(const std::string&)> print = [&sink](const std::string& s) { sink.Print(s); };
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  const CalibrationBoard board = CalibrationBoard::Read(a.board);
  CameraCalibrationOptions options;
  options.lensmodel = a.lensmodel;
  options.max_iterations = a.max_iterations;
  options.outlier_k = a.outlier_k;
  options.solve_board_warp = a.board_warp;
  if (!a.quiet) options.log = [](const std::string& s) { std::fprintf(stderr, "calib-rig: %s\n", s.c_str()); };
  std::string why;
  if (!options.IsValid(&why)) Throw("calib-rig options: ", why);
  // Refuse an unusable output folder before detection, not after the solve; and one whose
  // rig.yaml would overwrite an input.
  std::vector<fs::path> inputs = a.folders;
  inputs.push_back(a.board);
  // Each camera is named by its folder: two folders of one name would be one camera twice
  // (its model files written over each other).
  for (size_t c = 0; c < a.folders.size(); ++c)
    for (size_t d = 0; d < c; ++d)
      if (CameraNameOfFolder(a.folders[c], c) == CameraNameOfFolder(a.folders[d], d))
        Throw("calib-rig: image folders ", a.folders[d].string(), " and ", a.folders[c].string(),
              " both name camera '", CameraNameOfFolder(a.folders[c], c),
              "' (a camera is named by its folder): give each camera's images a folder of its own name");
  std::vector<RunOutput> outputs{{a.output / "rig.yaml", "calib-rig -o"}, {a.output / "summary.txt", "calib-rig -o"}};
  for (size_t c = 0; c < a.folders.size(); ++c)
    for (const std::string& file : {"residuals-" + CameraNameOfFolder(a.folders[c], c) + ".svg",
                                    CameraNameOfFolder(a.folders[c], c) + ".cameramodel",
                                    CameraNameOfFolder(a.folders[c], c) + ".yml"})
      outputs.push_back({a.output / file, "calib-rig -o"});
  RequireOutputsSpareInputs(outputs, inputs);
  RequireWritableFolder(a.output, "calib-rig -o");
  // The folder is written as a whole: an earlier calib-rig output is replaced, a folder
  // holding anything else (the user's own rig.yaml, notes) is refused before the solve.
  RequireReplaceableFolder(a.output, {"rig.yaml", "summary.txt"}, "calib-rig", "calib-rig -o");

  const Detected d = DetectBoards(a, board);
  const CameraCalibrationResult r = CalibrateCameras(d.input, options);
  ReportSolve(a, board, d, r, print);
  const std::vector<UncertaintyGrid> grids = CheckTrust(a, d, r, print);
  // mrcal's optimization_inputs need the board as a regular grid: chessboards only.
  std::string optimization_inputs, no_inputs_why;
  if (board.type == CalibrationBoard::Type::kChessboard)
    optimization_inputs = MrcalOptimizationInputs(r, MrcalBoardGrid{board.cols, board.rows, board.square_m});
  else
    no_inputs_why = "the models carry no optimization_inputs: mrcal describes a board as a regular grid of points, "
                    "and an AprilTag grid's corners are not one (mrcal's uncertainty tools need a chessboard)";

  // Everything is computed; only now write the outputs, the folder as a whole (renamed into
  // place when complete, so a failure part-way leaves nothing). The summary is printed and kept beside the models (mcms report's first screen reads it).
  std::string summary;
  ReportSolution(a, r, grids, [&](const std::string& s) { summary += s; });
  const fs::path out = a.output;
  WriteFolderAtomically(out, {"rig.yaml", "summary.txt"}, "calib-rig", "calib-rig -o", [&](const fs::path& dir) {
    for (size_t c = 0; c < r.rig.size(); ++c)
      WriteResidualPlot(r, static_cast<int>(c), dir / ("residuals-" + r.rig.names[c] + ".svg"));
    for (size_t c = 0; c < r.rig.size(); ++c) {
      const std::string& name = r.rig.names[c];
      if (optimization_inputs.empty())
        r.rig.cameras[c].WriteCameramodel(dir / (name + ".cameramodel"));
      else
        WriteCameramodelWithOptimizationInputs(r, static_cast<int>(c), optimization_inputs, dir / (name + ".cameramodel"));
      r.rig.cameras[c].WriteOpenCvYaml(dir / (name + ".yml"));
    }
    WriteFileAtomically(dir / "summary.txt", [&](std::ostream& o) { o << summary; });
    r.rig.Write(dir / "rig.yaml");
  });

  print(summary);
  print(Format("wrote %zu camera models (.cameramodel%s, .yml), residual plots, summary.txt and rig.yaml to %s\n", r.rig.size(),
               optimization_inputs.empty() ? "" : " with mrcal's optimization_inputs", out.string().c_str()));
  if (!no_inputs_why.empty()) print("note: " + no_inputs_why + "\n");
}

}  // namespace mcms
