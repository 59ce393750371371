// The lens model chosen by the data (CameraCalibrationOptions::lensmodel "auto"), and the
// entry CalibrateCameras (calib/camera_calibration.h): each candidate lens model solved by
// CalibrateWithLensModel (camera_calibration.cpp, all steps of one model).
#include "calib/camera_calibration.h"
#include "calib/camera_calibration_internal.h"

#include <numbers>
#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCore>
#include <opencv2/calib3d.hpp>

#include "calib/reprojection_cost.h"
#include "core/error.h"
#include "core/svg_plot.h"

namespace mcms {

double LargestDistortionStd(const CameraCalibrationResult& r) {
  double m = 0.0;
  for (const Eigen::VectorXd& s : r.intrinsics_std)
    for (int i = 4; i < s.size(); ++i) m = std::max(m, s[i]);
  return m;
}

namespace {

using LogFn = std::function<void(const std::string&)>;

// --- Lens-model selection ("auto") -------------------------------------------------


CameraCalibrationResult SelectLensModel(const CameraCalibrationInput& input, const CameraCalibrationOptions& options) {
  if (options.auto_lensmodels.empty()) Throw("camera calibration: lensmodel auto needs at least one candidate model");
  const LogFn log = [&](const std::string& s) {
    if (options.log) options.log(s);
  };
  std::vector<CameraCalibrationResult> results;
  for (const std::string& model : options.auto_lensmodels) {
    CameraCalibrationOptions o = options;
    o.lensmodel = model;
    log("lens model auto: trying " + model);
    results.push_back(CalibrateWithLensModel(input, o));
  }
  // Compare on the same points: those every candidate kept as inliers (the inlier sets
  // differ by a few points between models; comparing each on its own set would
  // favour the model that rejected more).
  const size_t ncam = results[0].residuals.size();
  bool same_points = true;
  for (const auto& r : results)
    for (size_t c = 0; c < ncam; ++c) same_points &= r.residuals[c].num_points == results[0].residuals[c].num_points;
  std::vector<LensModelTrial> trials;
  for (const auto& r : results) {
    LensModelTrial t;
    t.lensmodel = r.lensmodel;
    t.converged = r.converged;
    t.iterations = r.iterations;
    t.rms_px = r.rms_px;
    t.num_parameters = r.num_parameters;
    t.largest_distortion_std = LargestDistortionStd(r);
    double ss = 0.0;
    int n = 0;
    for (size_t c = 0; c < ncam; ++c)
      for (size_t i = 0; i < r.residuals[c].residuals.size(); ++i) {
        bool common = r.residuals[c].inlier[i];
        if (same_points)
          for (const auto& other : results) common = common && other.residuals[c].inlier[i];
        if (common) ss += r.residuals[c].residuals[i].squaredNorm(), ++n;
      }
    t.num_residuals = 2 * n;
    t.bic = t.num_residuals * std::log(ss / std::max(1, t.num_residuals)) + t.num_parameters * std::log(t.num_residuals);
    trials.push_back(t);
  }
  // Eligible: converged, every distortion coefficient determined (1 sigma below
  // kMaxDistortionStd); the lowest BIC among the eligible wins. Fallbacks: the lowest
  // BIC among the converged, then among all (the result then says it did not converge).
  auto pick = [&](auto&& eligible) {
    int best = -1;
    for (size_t k = 0; k < trials.size(); ++k)
      if (eligible(trials[k]) && (best < 0 || trials[k].bic < trials[best].bic)) best = static_cast<int>(k);
    return best;
  };
  int best = pick([&](const LensModelTrial& t) {
    return t.converged && t.largest_distortion_std < options.auto_max_distortion_std;
  });
  std::string why;
  if (best >= 0) {
    why = "lowest BIC among the converged candidates with every distortion coefficient determined (1 sigma < " +
          std::to_string(options.auto_max_distortion_std).substr(0, 4) + ")";
  } else if ((best = pick([](const LensModelTrial& t) { return t.converged; })) >= 0) {
    why = "lowest BIC among the converged candidates; WARNING: no candidate determines every distortion "
          "coefficient (1 sigma < " + std::to_string(options.auto_max_distortion_std).substr(0, 4) +
          "): the views do not constrain the lens well";
  } else {
    best = pick([](const LensModelTrial&) { return true; });
    why = "lowest BIC; WARNING: no candidate converged";
  }
  trials[best].chosen = true;
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(1);
  s << "lens model auto: chose " << trials[best].lensmodel << " (" << why << ")";
  for (const LensModelTrial& t : trials) {
    if (t.chosen) continue;
    s << "; " << t.lensmodel << ": ";
    if (!t.converged) s << "did not converge in " << t.iterations << " iterations";
    else if (t.largest_distortion_std >= options.auto_max_distortion_std)
      s << "a distortion coefficient is undetermined (1 sigma " << std::setprecision(3) << std::defaultfloat
        << t.largest_distortion_std << std::fixed << std::setprecision(1) << ")";
    else
      s << "BIC " << (t.bic > trials[best].bic ? "higher" : "lower") << " by " << std::abs(t.bic - trials[best].bic);
  }
  CameraCalibrationResult res = std::move(results[best]);
  res.lens_model_trials = trials;
  res.lens_model_choice = s.str();
  log(res.lens_model_choice);
  return res;
}

}  // namespace

CameraCalibrationResult CalibrateCameras(const CameraCalibrationInput& input, const CameraCalibrationOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("camera calibration options: ", why);
  if (options.lensmodel == "auto") return SelectLensModel(input, options);
  return CalibrateWithLensModel(input, options);
}

}  // namespace mcms
