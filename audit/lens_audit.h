// The lens mode of the model audit (issue 11, `mcms audit lens MODEL.cameramodel`): does
// a richer lens model than the nominal one (the model a .cameramodel was solved with)
// earn its place on the chessboard observations stored in the file's
// optimization_inputs (vision/mrcal_file.h)?
//
// Every fit is libmrcal's own solver (mrcal_optimize), with mrcal's regularisation, on
// one camera (the file's icam_intrinsics; each of its board observations gets its own
// board pose, so a camera of a rig is audited alone): the nominal model, then each
// candidate (default: OPENCV8 and OPENCV12 where richer than the nominal, and mrcal's
// splined stereographic model, Nx x Ny knots over the nominal's horizontal field of
// view; the splined model is solved with the intrinsics core held at the nominal's, as
// mrcal's own splined Figueroa fit is). The outliers marked in the file are kept out of
// every fit and no new ones are rejected: every model is scored on the same points.
//
// Scores (the rule of audit/model_selection.h, one step, catalog name `lens_model`):
//  - all data: lr = n ln(RSS_nominal / RSS_candidate) (Gaussian noise of unknown sigma,
//    profiled; n weighted residual coordinates), k = the candidate's free lens
//    parameters minus the nominal's (a 30 x 20 spline adds 1,188), BIC gain lr - k ln n;
//  - held out: folds of board observations (interleaved by default, see
//    LensAuditOptions::contiguous_folds); a
//    model is solved on the other folds, its sigma^2 = RSS / (n - parameters) there,
//    then each held-out board's pose is solved alone with the lens fixed and its
//    residuals scored: RMS (per coordinate) and the Gaussian log-likelihood with the
//    training sigma. The gain is the candidate's log-likelihood minus the nominal's,
//    summed over the folds.
// The nominal chi2/dof of the report is the nominal's residual variance over the
// richest candidate's (the best estimate of the pixel noise the data give), so that
// 1 means "no richer model fits better".
#pragma once

#include <array>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "vision/mrcal_file.h"
#include "audit/audit_report.h"

namespace mcms {

struct LensAuditOptions {
  double false_alarm = 0.01;  // designed probability of naming a richer lens on a clean data set
  int folds = 5;
  // How boards are split into folds. Interleaved (board i in fold i mod folds, the
  // default): each training set covers the view as the whole capture does, so the score
  // is the prediction of a new board where boards were taken. Contiguous blocks of
  // capture order (the time-blocked folds of the other audit modes, against drift):
  // captures usually sweep the view, so a held-out block is often a region no training
  // board covers, and the score becomes extrapolation, which a local (splined) model
  // loses by construction.
  bool contiguous_folds = false;
  // mrcal lens model names; empty: the default candidates (see above). "splined" stands
  // for the default splined model (knots spline_nx x spline_ny, fov from the nominal).
  std::vector<std::string> candidates;
  int spline_nx = 30;
  int spline_ny = 0;  // 0: square knot cells (spline_nx * height / width)
  // Threads solving a model's held-out folds side by side (0: all cores); the result does
  // not depend on it.
  int threads = 0;
  std::function<void(const std::string&)> progress;
  bool IsValid(std::string* why) const;
};

// One lens model fitted to all observations and scored on the held-out folds.
struct LensFit {
  std::string lensmodel;
  int free_intrinsics = 0;     // lens parameters solved
  std::vector<double> intrinsics;
  bool converged = false;
  double rss = 0.0;            // sum of squared weighted residuals (px^2), all data
  long n = 0;                  // residual coordinates (2 per inlier point)
  double rms_px = 0.0;         // per coordinate, all data
  double heldout_rms_px = 0.0; // per coordinate, over every held-out board
  double heldout_loglik = 0.0; // nats, summed over the folds
  double seconds = 0.0;        // wall time of its fits
  // All-data residuals (predicted - observed, weighted px), 2 per board point in the
  // order of LensAuditResult::observed; 0 for the file's outliers.
  std::vector<double> residuals;
};

struct LensAuditResult {
  AuditReport report;               // mode "lens"
  std::string camera;               // the `where` of the effect, "cam<icam_intrinsics>"
  int width = 0, height = 0;
  std::vector<LensFit> fits;        // [0] the nominal, then the candidates in order
  int chosen = -1;                  // index into fits of the named model, -1 when none
  // The board points: observed pixel (u, v) and weight (< 0: the file's outlier), per
  // board observation of the camera, row-major over the board.
  std::vector<std::array<double, 3>> observed;
  int points_per_board = 1;
  // The candidate the plots compare with the nominal: the named one, else the best by
  // held-out log-likelihood; -1 without candidates.
  int Compared() const;
};

// InputError for a problem without observations of the camera, invalid options or a
// candidate name mrcal does not know.
LensAuditResult AuditLens(const MrcalOptimizationInputsData& data, const LensAuditOptions& options = {});

// Writes report.txt, report.json, residuals.csv (every board point: observed pixel, the
// nominal's and the compared candidate's residuals), plots/<camera>.svg (both models'
// residuals binned over the image as magnified vectors, and their radial component
// against the distance from the image centre) and, when a richer model was named,
// <camera>.cameramodel (its intrinsics) into dir (a new folder, written atomically).
void WriteLensAuditFiles(const LensAuditResult& r, const std::filesystem::path& dir);


}  // namespace mcms
