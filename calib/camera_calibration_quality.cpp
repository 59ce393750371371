// The checks and the uncertainty of a solved rig calibration (calib/camera_calibration.h):
// its quality limits and problems, the projection covariance and its grid, the summary and
// the residual plot. The solve itself is camera_calibration.cpp.
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


#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCore>
#include <opencv2/calib3d.hpp>

#include "calib/reprojection_cost.h"
#include "core/error.h"
#include "core/svg_plot.h"

namespace mcms {

bool CalibrationQualityLimits::IsValid(std::string* why) const {
  std::ostringstream s;
  if (!(max_noise_ratio >= 1.0)) s << "max_noise_ratio must be >= 1 (got " << max_noise_ratio << ")";
  else if (!(max_rms_px > 0.0)) s << "max_rms_px must be > 0 px (got " << max_rms_px << ")";
  else if (!(max_outlier_fraction >= 0.0 && max_outlier_fraction <= 1.0))
    s << "max_outlier_fraction must be within 0..1 (got " << max_outlier_fraction << ")";
  else if (!(max_view_outlier_fraction >= 0.0 && max_view_outlier_fraction <= 1.0))
    s << "max_view_outlier_fraction must be within 0..1 (got " << max_view_outlier_fraction << ")";
  if (why) *why = s.str();
  return s.str().empty();
}

std::vector<std::string> CalibrationProblems(const CameraCalibrationResult& r, const CalibrationQualityLimits& limits,
                                             const std::vector<std::string>& frame_names) {
  std::string why;
  if (!limits.IsValid(&why)) Throw("calibration quality limits: ", why);
  std::vector<std::string> out;
  auto add = [&](auto&&... parts) {
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(3);
    (s << ... << parts);
    out.push_back(s.str());
  };
  if (r.rig.size() == 0 || r.residuals.size() != r.rig.size() || r.intrinsics_std.size() != r.rig.size()) {
    add("the result holds no solved rig");
    return out;
  }
  if (!r.converged)
    add("the last bundle adjustment did not converge in ", r.iterations, " iterations (", r.solver_message, ")");
  if (!(r.rms_px <= limits.max_rms_px))
    add("the residual RMS is ", r.rms_px, " px per coordinate, above the limit of ", limits.max_rms_px, " px");
  const double ratio = std::sqrt(r.residual_variance_px2 / r.views_alone_variance_px2);
  if (std::isfinite(ratio) && ratio > limits.max_noise_ratio)
    add("the residual (", std::sqrt(r.residual_variance_px2), " px per coordinate) is ", std::setprecision(2), ratio,
        " times the views' own noise floor (", std::setprecision(3), std::sqrt(r.views_alone_variance_px2),
        " px, each view's board pose fitted alone; limit ", std::setprecision(2), limits.max_noise_ratio,
        "): the views do not agree with one rig (a board numbered differently in two cameras, images of different "
        "moments under one frame name, a camera that moved, a board that is not flat)");
  const int total = r.num_inliers + r.num_outliers;
  if (total > 0 && r.num_outliers > limits.max_outlier_fraction * total) {
    std::ostringstream per;
    for (size_t c = 0; c < r.residuals.size(); ++c)
      per << (c ? ", " : "") << r.rig.names[c] << " " << r.residuals[c].num_outliers << "/" << r.residuals[c].num_points;
    add(r.num_outliers, " of ", total, " points (", std::setprecision(1), 100.0 * r.num_outliers / total,
        " %) were rejected as outliers (", per.str(), "), more than ", 100.0 * limits.max_outlier_fraction, " %");
  }
  for (size_t i = 0; i < r.observations.size() && i < r.observation_inliers.size(); ++i) {
    const auto& inl = r.observation_inliers[i];
    const int n = static_cast<int>(inl.size());
    const int rejected = static_cast<int>(std::count(inl.begin(), inl.end(), false));
    if (n > 0 && rejected > limits.max_view_outlier_fraction * n)
      add("frame ",
          r.observations[i].frame < static_cast<int>(frame_names.size()) ? frame_names[r.observations[i].frame]
                                                                         : std::to_string(r.observations[i].frame),
          ", ", r.rig.names[r.observations[i].camera], ": ", rejected, " of ", n,
          " points were rejected as outliers (more than ", std::setprecision(0),
          100.0 * limits.max_view_outlier_fraction, std::setprecision(3),
          " %): the view as a whole disagrees with the others (numbered differently, taken at another moment, or "
          "of another board)");
  }
  bool any_bad_std = false;
  for (size_t c = 0; c < r.rig.size(); ++c) {
    const Eigen::VectorXd& sd = r.intrinsics_std[c];
    bool bad = false;
    for (int i = 0; i < sd.size(); ++i) bad |= !(sd[i] > 0.0 && std::isfinite(sd[i]));
    const bool fixed = sd.size() > 0 && sd.isZero(0.0);  // intrinsics held fixed
    any_bad_std |= bad && !fixed;
    if (bad && !fixed)
      add(r.rig.names[c], ": an intrinsic parameter's standard deviation is zero, infinite or not a number (the "
                          "normal matrix is singular or not positive definite: the views do not determine it)");
    if (c > 0) {
      bool bad_ext = false;
      for (int i = 0; i < 6; ++i) bad_ext |= !(r.extrinsics_std[c][i] > 0.0 && std::isfinite(r.extrinsics_std[c][i]));
      any_bad_std |= bad_ext;
      if (bad_ext)
        add(r.rig.names[c], ": a standard deviation of its pose in the rig is zero, infinite or not a number (the "
                            "normal matrix is singular or not positive definite)");
    }
  }
  if (r.covariance_singular && !any_bad_std)
    add("the parameter covariance is singular or not positive definite: some parameters of ", r.lensmodel,
        " are not determined by the views (their standard deviations and the projection uncertainty mean nothing)");
  return out;
}

std::optional<Mat2> ProjectionCovariance(const CameraModel& camera, const Eigen::MatrixXd& cov_intrinsics,
                                         const Vec2& q, double range_m) {
  const int n = camera.NumIntrinsics();
  if (cov_intrinsics.rows() != n || cov_intrinsics.cols() != n)
    Throw("ProjectionCovariance: covariance is ", cov_intrinsics.rows(), "x", cov_intrinsics.cols(), ", the camera has ",
          n, " intrinsics");
  const auto v = camera.Unproject(q);
  if (!v) return std::nullopt;
  std::vector<double> dq_di;
  camera.Project(*v * range_m, nullptr, &dq_di);
  const Eigen::Map<const Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>> J(dq_di.data(), 2, n);
  return Mat2(J * cov_intrinsics * J.transpose());
}

double WorstDirectionStdev(const Mat2& cov) {
  // Largest eigenvalue of the symmetric part, closed form (as mrcal.worst_direction_stdev).
  const double a = cov(0, 0), c = cov(1, 1), b = 0.5 * (cov(0, 1) + cov(1, 0));
  return std::sqrt(std::max(0.0, 0.5 * (a + c) + std::sqrt(0.25 * (a - c) * (a - c) + b * b)));
}

std::optional<Mat2> ProjectionCovarianceMeanFrames(const CameraCalibrationResult& result, int camera, const Vec2& q,
                                                   double range_m, std::optional<double> pixel_sigma_px) {
  const int ncam = static_cast<int>(result.rig.size());
  if (camera < 0 || camera >= ncam)
    Throw("ProjectionCovarianceMeanFrames: camera ", camera, " does not exist (the calibration has ", ncam, ")");
  if (!(range_m > 0.0)) Throw("ProjectionCovarianceMeanFrames: range_m must be > 0 or +infinity (got ", range_m, ")");
  if (pixel_sigma_px && !(*pixel_sigma_px > 0.0 && std::isfinite(*pixel_sigma_px)))
    Throw("ProjectionCovarianceMeanFrames: pixel_sigma_px must be a finite value > 0 (got ", *pixel_sigma_px, ")");
  const CalibrationCovariance& C = result.covariance;
  const int na = static_cast<int>(C.a_cov.rows());
  if (static_cast<int>(C.intrinsics_offset.size()) != ncam || static_cast<int>(C.extrinsics_offset.size()) != ncam ||
      C.frame_in_solve.size() != C.frame_gain.size() || C.frame_in_solve.size() != C.frame_conditional_cov.size())
    Throw("ProjectionCovarianceMeanFrames: the calibration result carries no parameter covariance (it must come "
          "from CalibrateCameras)");
  const CameraModel& cam = result.rig.cameras[camera];
  const auto v = cam.Unproject(q);
  if (!v) return std::nullopt;
  // At infinity only rotations act; any positive scale of the direction gives the
  // same q, and dq/dp scales as 1/|p| while the rotation derivatives scale as |p|.
  const bool at_infinity = std::isinf(range_m);
  const Vec3 p_cam = at_infinity ? *v : Vec3(*v * range_m);
  Eigen::Matrix<double, 2, 3> dq_dp;
  std::vector<double> dq_di;
  if (!cam.Project(p_cam, &dq_dp, &dq_di).allFinite()) return std::nullopt;

  // dq/da for the dense block; the board blocks are folded in on the fly.
  Eigen::MatrixXd dq_da = Eigen::MatrixXd::Zero(2, na);
  if (const int o = C.intrinsics_offset[camera]; o >= 0)
    dq_da.middleCols(o, cam.NumIntrinsics()) =
        Eigen::Map<const Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>>(dq_di.data(), 2, cam.NumIntrinsics());
  const Pose& T_cam_rig = cam.T_cam_rig();
  const Vec3 p_rig = at_infinity ? Vec3(T_cam_rig.R.transpose() * p_cam) : T_cam_rig.Inverse() * p_cam;
  if (const int o = C.extrinsics_offset[camera]; o >= 0) {
    double rt[6];
    T_cam_rig.ToRt(rt);
    dq_da.middleCols(o, 3) = dq_dp * (-Skew(T_cam_rig.R * p_rig) * LeftJacobianSO3(Vec3(rt[0], rt[1], rt[2])));
    if (!at_infinity) dq_da.middleCols(o + 3, 3) = dq_dp;
  }
  const Eigen::Matrix<double, 2, 3> dq_dprig = dq_dp * T_cam_rig.R;

  // Mean-frames: p_rig' = (1/F) sum_f T_rig_board_f(b_f) * (T_rig_board_f_hat^-1 * p_rig).
  const size_t nframes = C.frame_in_solve.size();
  if (result.T_rig_board.size() != nframes)
    Throw("ProjectionCovarianceMeanFrames: the result has ", result.T_rig_board.size(), " board poses but covariance "
          "for ", nframes, " frames");
  const int F = static_cast<int>(std::count(C.frame_in_solve.begin(), C.frame_in_solve.end(), true));
  // Var(q) = (Ga - sum_f Gf K_f) a_cov (Ga - sum_f Gf K_f)^T + sum_f Gf Cov(b_f | a) Gf^T:
  // the full G Cov(b) G^T written with the block identities of CalibrationCovariance.
  Eigen::MatrixXd H = dq_da;
  Mat2 V = Mat2::Zero();
  for (size_t f = 0; f < nframes; ++f) {
    if (!C.frame_in_solve[f]) continue;
    if (!result.T_rig_board[f])
      Throw("ProjectionCovarianceMeanFrames: frame ", f, " has a covariance but no board pose in the result");
    const Pose& T = *result.T_rig_board[f];
    double rt[6];
    T.ToRt(rt);
    const Vec3 Rp = at_infinity ? p_rig : Vec3(p_rig - T.t);  // R_f * p_board
    Eigen::Matrix<double, 2, 6> G = Eigen::Matrix<double, 2, 6>::Zero();
    G.leftCols<3>() = dq_dprig * (-Skew(Rp) * LeftJacobianSO3(Vec3(rt[0], rt[1], rt[2]))) / F;
    if (!at_infinity) G.rightCols<3>() = dq_dprig / F;
    H.noalias() -= G * C.frame_gain[f];
    V.noalias() += G * C.frame_conditional_cov[f] * G.transpose();
  }
  V.noalias() += H * C.a_cov * H.transpose();
  if (pixel_sigma_px) {
    if (!(result.residual_variance_px2 > 0.0))
      Throw("ProjectionCovarianceMeanFrames: cannot rescale to pixel_sigma_px = ", *pixel_sigma_px,
            ": the solution's residual variance is ", result.residual_variance_px2, " px^2");
    V *= *pixel_sigma_px * *pixel_sigma_px / result.residual_variance_px2;
  }
  return V;
}

namespace {
// Cell centres of an nx x ny tiling of the image, each with sigma(q) (NaN when absent).
UncertaintyGrid Grid(const CameraModel& camera, int nx, int ny,
                     const std::function<std::optional<Mat2>(const Vec2&)>& cov) {
  if (nx < 1 || ny < 1) Throw("ProjectionUncertaintyGrid: grid ", nx, "x", ny, " must be at least 1x1");
  UncertaintyGrid g;
  g.nx = nx;
  g.ny = ny;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const Vec2 q((i + 0.5) * camera.Width() / nx - 0.5, (j + 0.5) * camera.Height() / ny - 0.5);
      g.pixels.push_back(q);
      const auto C = cov(q);
      g.sigma_px.push_back(C ? WorstDirectionStdev(*C) : std::numeric_limits<double>::quiet_NaN());
    }
  return g;
}
}  // namespace

UncertaintyGrid ProjectionUncertaintyGrid(const CameraModel& camera, const Eigen::MatrixXd& cov_intrinsics,
                                          double range_m, int nx, int ny) {
  return Grid(camera, nx, ny, [&](const Vec2& q) { return ProjectionCovariance(camera, cov_intrinsics, q, range_m); });
}

UncertaintyGrid ProjectionUncertaintyGrid(const CameraCalibrationResult& result, int camera, double range_m, int nx,
                                          int ny) {
  if (camera < 0 || camera >= static_cast<int>(result.rig.size()))
    Throw("ProjectionUncertaintyGrid: camera ", camera, " does not exist (the calibration has ", result.rig.size(), ")");
  return Grid(result.rig.cameras[camera], nx, ny,
              [&](const Vec2& q) { return ProjectionCovarianceMeanFrames(result, camera, q, range_m); });
}

std::string SummarizeCalibration(const CameraCalibrationResult& r) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(4);
  s << "residual RMS " << r.rms_px << " px per coordinate, " << r.num_inliers << " inlier points, " << r.num_outliers
    << " rejected\n";
  s << "last solve: " << r.iterations << " iterations, "
    << (r.converged ? "converged" : "NOT CONVERGED (the iteration limit was reached)") << "\n";
  const double limit = CameraCalibrationOptions{}.auto_max_distortion_std;
  if (r.covariance_singular || LargestDistortionStd(r) >= limit)
    s << "WARNING: the views do not determine every parameter of " << r.lensmodel << " (a distortion coefficient's "
      << "1 sigma is " << LargestDistortionStd(r) << (r.covariance_singular ? "; the normal matrix is singular" : "")
      << "): its coefficients trade off against each other; use a simpler lens model (lens model auto picks "
      << "the one the data support) or views that fill the image, corners included\n";
  for (size_t c = 0; c < r.rig.size(); ++c) {
    const auto& st = r.residuals[c];
    const CameraModel& m = r.rig.cameras[c];
    s << r.rig.names[c] << ": " << st.num_observations << " views, " << st.num_points - st.num_outliers << "/"
      << st.num_points << " points, RMS " << st.rms_px << " px per coordinate (" << st.rms_point_px
      << " px per point), max " << st.max_px << " px\n";
    s << "  " << m.LensModelName() << " intrinsics (+- 1 sigma):";
    for (int i = 0; i < m.NumIntrinsics(); ++i) {
      s.precision(i < 4 ? 3 : 6);
      s << " " << m.Intrinsics()[i] << " +- " << r.intrinsics_std[c][i];
    }
    s.precision(4);
    if (c > 0) {
      double rt[6];
      m.T_cam_rig().ToRt(rt);
      s << "\n  rt_cam_rig:";
      for (int i = 0; i < 6; ++i) s << " " << rt[i] << " +- " << r.extrinsics_std[c][i];
      s << " (rad, m); baseline to " << r.rig.names[0] << " " << m.T_cam_rig().t.norm() << " m";
    }
    s << "\n";
  }
  return s.str();
}

void WriteResidualPlot(const CameraCalibrationResult& r, int camera, const std::filesystem::path& path) {
  if (camera < 0 || camera >= static_cast<int>(r.rig.size())) Throw("WriteResidualPlot: no camera ", camera);
  const auto& st = r.residuals[camera];
  const CameraModel& cam = r.rig.cameras[camera];
  const double sigma = st.rms_px > 0 ? st.rms_px : 1.0;
  // Residuals are sub-pixel on a megapixel image: draw them as arrows magnified so that the
  // largest inlier is about 6 % of the image width, with a round magnification.
  double largest = 0.0;
  for (size_t i = 0; i < st.pixels.size(); ++i)
    if (st.inlier[i]) largest = std::max(largest, st.residuals[i].norm());
  double scale = 1.0;
  if (largest > 0) {
    const double want = 0.06 * std::max(cam.Width(), 1) / largest;
    const double decade = std::pow(10.0, std::floor(std::log10(want)));
    scale = want >= 5 * decade ? 5 * decade : want >= 2 * decade ? 2 * decade : decade;
  }
  PlotSeries low{"|e| < 1 sigma", {}, {}, "#2ca02c", true}, mid{"1-3 sigma", {}, {}, "#ff7f0e", true},
      high{"> 3 sigma", {}, {}, "#d62728", true}, out{"rejected", {}, {}, "#000000", true};
  for (size_t i = 0; i < st.pixels.size(); ++i) {
    const double e = st.residuals[i].norm() / sigma;
    PlotSeries& s = !st.inlier[i] ? out : e < 1 ? low : e < 3 ? mid : high;
    s.x.push_back(st.pixels[i].x());
    s.y.push_back(st.pixels[i].y());
    // Rejected points can be off by many pixels: markers only, no arrow across the image.
    s.dx.push_back(st.inlier[i] ? st.residuals[i].x() : std::numeric_limits<double>::quiet_NaN());
    s.dy.push_back(st.inlier[i] ? st.residuals[i].y() : std::numeric_limits<double>::quiet_NaN());
  }
  Plot p;
  std::ostringstream t;
  t << r.rig.names[camera] << ": residuals (projected - observed) over the image, arrows x" << scale
    << "; sigma = " << sigma << " px per coordinate";
  p.title = t.str();
  p.x_label = "u (px)";
  p.y_label = "v (px)";
  p.y_down = true;
  p.equal_scale = true;
  if (cam.Width() > 0 && cam.Height() > 0) {
    p.x_range = std::make_pair(-0.5, cam.Width() - 0.5);
    p.y_range = std::make_pair(-0.5, cam.Height() - 0.5);
  }
  for (auto* s : {&low, &mid, &high, &out}) {
    s->vector_scale = scale;
    if (!s->x.empty()) p.series.push_back(*s);
  }
  p.WriteSvg(path, 900, std::clamp(static_cast<int>(900.0 * cam.Height() / std::max(cam.Width(), 1)) + 120, 420, 900));
}

}  // namespace mcms
