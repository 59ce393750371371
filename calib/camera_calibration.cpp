#include "calib/camera_calibration.h"

#include <algorithm>
#include <array>
#include <cmath>
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

#include "core/error.h"
#include "core/svg_plot.h"

namespace mcms {

bool CameraCalibrationOptions::IsValid(std::string* why) const {
  std::ostringstream s;
  if (!(outlier_k == 0.0 || outlier_k >= 2.0)) s << "outlier_k must be 0 (off) or >= 2 (got " << outlier_k << ")";
  else if (!(outlier_trigger >= 0.0)) s << "outlier_trigger must be >= 0 (got " << outlier_trigger << ")";
  else if (max_outlier_rounds < 0) s << "max_outlier_rounds must be >= 0";
  else if (max_iterations < 1) s << "max_iterations must be >= 1";
  else if (min_points_per_observation < 4) s << "min_points_per_observation must be >= 4 (a pose needs 4 points)";
  else if (max_init_views < 3) s << "max_init_views must be >= 3";
  else if (fix_intrinsics && (initial_intrinsics.empty() ||
                              std::any_of(initial_intrinsics.begin(), initial_intrinsics.end(),
                                          [](const auto& v) { return v.empty(); })))
    s << "fix_intrinsics needs initial intrinsics for every camera";
  if (why) *why = s.str();
  return s.str().empty();
}

namespace {

// Number of OpenCV distortion coefficients behind each supported mrcal model, and
// the cv::calibrateCamera flags that fit exactly those.
struct LensSupport {
  int num_distortions;
  int cv_flags;
};

LensSupport SupportOf(const std::string& lensmodel) {
  if (lensmodel == "LENSMODEL_PINHOLE")
    return {0, cv::CALIB_ZERO_TANGENT_DIST | cv::CALIB_FIX_K1 | cv::CALIB_FIX_K2 | cv::CALIB_FIX_K3};
  if (lensmodel == "LENSMODEL_OPENCV4") return {4, cv::CALIB_FIX_K3};
  if (lensmodel == "LENSMODEL_OPENCV5") return {5, 0};
  if (lensmodel == "LENSMODEL_OPENCV8") return {8, cv::CALIB_RATIONAL_MODEL};
  if (lensmodel == "LENSMODEL_OPENCV12") return {12, cv::CALIB_RATIONAL_MODEL | cv::CALIB_THIN_PRISM_MODEL};
  Throw("lens model '", lensmodel,
        "' cannot be calibrated here: use LENSMODEL_PINHOLE, LENSMODEL_OPENCV4, LENSMODEL_OPENCV5, "
        "LENSMODEL_OPENCV8 or LENSMODEL_OPENCV12");
}

// p_cam = R(rc) (R(rb) P' + tb) + tc; residual = weight * (Project(p_cam) - q_obs),
// with P' = P + (wx a + wy b) e_z when the board warp is solved (a, b: the point's
// warp shape factors 1 - u^2, 1 - v^2).
// Parameter blocks: intrinsics (n), rt_rig_board (6), then rt_cam_rig (6) unless the
// camera is camera 0 (the rig frame), then the warp (2) when solved.
class ReprojectionCost : public ceres::CostFunction {
 public:
  ReprojectionCost(const CameraModel& model, const Vec3& P, const Vec2& q, double weight, bool has_extrinsics,
                   std::optional<Eigen::Vector2d> warp_shape)
      : model_(model), P_(P), q_(q), w_(weight), has_extrinsics_(has_extrinsics), warp_shape_(warp_shape) {
    set_num_residuals(2);
    mutable_parameter_block_sizes()->push_back(model.NumIntrinsics());
    mutable_parameter_block_sizes()->push_back(6);
    if (has_extrinsics) mutable_parameter_block_sizes()->push_back(6);
    if (warp_shape) mutable_parameter_block_sizes()->push_back(2);
  }

  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    const int n = model_.NumIntrinsics();
    CameraModel model = model_;  // a private copy: Evaluate may run on several threads
    std::copy(params[0], params[0] + n, model.MutableIntrinsics().begin());
    const Vec3 rb(params[1][0], params[1][1], params[1][2]), tb(params[1][3], params[1][4], params[1][5]);
    const Mat3 Rb = ExpSO3(rb);
    const int warp_block = has_extrinsics_ ? 3 : 2;
    Vec3 P = P_;
    if (warp_shape_) P.z() += params[warp_block][0] * warp_shape_->x() + params[warp_block][1] * warp_shape_->y();
    const Vec3 RbP = Rb * P;
    const Vec3 p_rig = RbP + tb;
    Mat3 Rc = Mat3::Identity();
    Vec3 rc = Vec3::Zero(), tc = Vec3::Zero();
    if (has_extrinsics_) {
      rc = Vec3(params[2][0], params[2][1], params[2][2]);
      tc = Vec3(params[2][3], params[2][4], params[2][5]);
      Rc = ExpSO3(rc);
    }
    const Vec3 Rc_prig = Rc * p_rig;
    const Vec3 p_cam = Rc_prig + tc;
    if (!(p_cam.z() > 1e-9) && !model.CanProjectBehindCamera()) return false;
    Eigen::Matrix<double, 2, 3> dq_dp;
    std::vector<double> dq_di;
    const bool want = jacobians != nullptr;
    const Vec2 q = model.Project(p_cam, want ? &dq_dp : nullptr, want ? &dq_di : nullptr);
    if (!q.allFinite()) return false;
    residuals[0] = w_ * (q.x() - q_.x());
    residuals[1] = w_ * (q.y() - q_.y());
    if (!want) return true;
    dq_dp *= w_;
    if (jacobians[0])
      for (size_t k = 0; k < dq_di.size(); ++k) jacobians[0][k] = w_ * dq_di[k];
    if (jacobians[1]) {
      Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(jacobians[1]);
      const Eigen::Matrix<double, 2, 3> dq_dprig = dq_dp * Rc;
      J.leftCols<3>() = dq_dprig * (-Skew(RbP) * LeftJacobianSO3(rb));
      J.rightCols<3>() = dq_dprig;
    }
    if (has_extrinsics_ && jacobians[2]) {
      Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(jacobians[2]);
      J.leftCols<3>() = dq_dp * (-Skew(Rc_prig) * LeftJacobianSO3(rc));
      J.rightCols<3>() = dq_dp;
    }
    if (warp_shape_ && jacobians[warp_block]) {
      Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[warp_block]);
      J = (dq_dp * Rc * Rb.col(2)) * warp_shape_->transpose();
    }
    return true;
  }

 private:
  CameraModel model_;
  Vec3 P_;
  Vec2 q_;
  double w_;
  bool has_extrinsics_;
  std::optional<Eigen::Vector2d> warp_shape_;
};

using Rt = std::array<double, 6>;
Rt ToRt(const Pose& T) {
  Rt rt;
  T.ToRt(rt.data());
  return rt;
}
Pose FromRt(const Rt& rt) { return Pose::FromRt(rt.data()); }

std::vector<cv::Point3f> CvObject(const BoardObservation& o) {
  std::vector<cv::Point3f> v;
  for (const Vec3& p : o.points_board) v.emplace_back(float(p.x()), float(p.y()), float(p.z()));
  return v;
}
std::vector<cv::Point2f> CvImage(const BoardObservation& o) {
  std::vector<cv::Point2f> v;
  for (const Vec2& q : o.pixels) v.emplace_back(float(q.x()), float(q.y()));
  return v;
}

// Intrinsics of one camera from OpenCV: a 4-coefficient fit first (robust for any
// lens), then the model's full set starting from it.
std::vector<double> InitIntrinsics(const std::vector<const BoardObservation*>& obs, int w, int h,
                                   const LensSupport& lens, int max_views) {
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  const size_t n = std::min(obs.size(), static_cast<size_t>(max_views));
  for (size_t k = 0; k < n; ++k) {
    const BoardObservation* o = obs[k * obs.size() / n];
    object.push_back(CvObject(*o));
    image.push_back(CvImage(*o));
  }
  cv::Mat K, D;
  std::vector<cv::Mat> rvecs, tvecs;
  const cv::TermCriteria term(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-10);
  cv::calibrateCamera(object, image, cv::Size(w, h), K, D, rvecs, tvecs,
                      lens.num_distortions == 0 ? lens.cv_flags : cv::CALIB_FIX_K3, term);
  if (lens.num_distortions > 4) {
    D = D.reshape(1, 1);
    cv::Mat D_full = cv::Mat::zeros(1, lens.num_distortions, CV_64F);
    for (int i = 0; i < std::min<int>(4, D.cols); ++i) D_full.at<double>(0, i) = D.at<double>(0, i);
    D = D_full;
    cv::calibrateCamera(object, image, cv::Size(w, h), K, D, rvecs, tvecs,
                        lens.cv_flags | cv::CALIB_USE_INTRINSIC_GUESS, term);
  }
  std::vector<double> intr = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2), K.at<double>(1, 2)};
  D = D.reshape(1, 1);
  for (int i = 0; i < lens.num_distortions; ++i) intr.push_back(i < D.cols ? D.at<double>(0, i) : 0.0);
  return intr;
}

std::optional<Pose> SolveBoardPose(const BoardObservation& o, const CameraModel& cam) {
  const auto& in = cam.Intrinsics();
  cv::Mat K = (cv::Mat_<double>(3, 3) << in[0], 0, in[2], 0, in[1], in[3], 0, 0, 1);
  cv::Mat D(1, static_cast<int>(in.size()) - 4, CV_64F);
  for (int i = 4; i < static_cast<int>(in.size()); ++i) D.at<double>(0, i - 4) = in[i];
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(CvObject(o), CvImage(o), K, D.cols ? D : cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_IPPE) &&
      !cv::solvePnP(CvObject(o), CvImage(o), K, D.cols ? D : cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_ITERATIVE))
    return std::nullopt;
  cv::solvePnPRefineLM(CvObject(o), CvImage(o), K, D.cols ? D : cv::Mat(), rvec, tvec);
  const double rt[6] = {rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2),
                        tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)};
  const Pose T = Pose::FromRt(rt);
  if (!T.R.allFinite() || !T.t.allFinite()) return std::nullopt;
  return T;
}

// A robust representative of several estimates of one pose: the one with the
// smallest summed distance to the others (rotation angle + translation scaled by
// the typical translation size).
Pose MedoidPose(const std::vector<Pose>& poses) {
  double scale = 0.0;
  for (const Pose& p : poses) scale += p.t.norm();
  scale = std::max(scale / poses.size(), 1e-6);
  size_t best = 0;
  double best_cost = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < poses.size(); ++i) {
    double c = 0.0;
    for (size_t j = 0; j < poses.size(); ++j)
      c += RotationAngle(poses[i].R, poses[j].R) + (poses[i].t - poses[j].t).norm() / scale;
    if (c < best_cost) best_cost = c, best = i;
  }
  return poses[best];
}

struct State {
  std::vector<std::vector<double>> intrinsics;
  std::vector<Rt> rt_cam_rig;                 // [0] stays identity
  std::vector<std::optional<Rt>> rt_rig_board;
};

struct PointRef {
  size_t obs;
  size_t index;
};

}  // namespace

CameraCalibrationResult CalibrateCameras(const CameraCalibrationInput& input, const CameraCalibrationOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("camera calibration options: ", why);
  const LensSupport lens = SupportOf(options.lensmodel);
  const int ncam = static_cast<int>(input.camera_names.size());
  if (ncam == 0) Throw("camera calibration: no cameras given");
  if (!options.initial_intrinsics.empty() && static_cast<int>(options.initial_intrinsics.size()) != ncam)
    Throw("camera calibration: ", options.initial_intrinsics.size(), " sets of initial intrinsics for ", ncam, " cameras");
  if (static_cast<int>(input.widths.size()) != ncam || static_cast<int>(input.heights.size()) != ncam)
    Throw("camera calibration: ", ncam, " camera names but ", input.widths.size(), " widths and ",
          input.heights.size(), " heights");
  auto log = [&](const std::string& s) {
    if (options.log) options.log(s);
  };

  // Usable observations per camera.
  std::vector<BoardObservation> obs;
  int nframes = 0;
  for (const BoardObservation& o : input.observations) {
    if (o.camera < 0 || o.camera >= ncam) Throw("camera calibration: observation of camera ", o.camera, " but only ", ncam, " cameras");
    if (o.frame < 0) Throw("camera calibration: negative frame index ", o.frame);
    if (!o.weights.empty() && o.weights.size() != o.pixels.size())
      Throw("camera calibration: observation (camera ", input.camera_names[o.camera], ", frame ", o.frame, ") has ",
            o.weights.size(), " weights for ", o.pixels.size(), " pixels");
    if (o.points_board.size() != o.pixels.size())
      Throw("camera calibration: observation (camera ", input.camera_names[o.camera], ", frame ", o.frame,
            ") has ", o.points_board.size(), " board points but ", o.pixels.size(), " pixels");
    BoardObservation kept = o;  // only the points with positive weight
    kept.points_board.clear();
    kept.pixels.clear();
    kept.weights.clear();
    for (size_t k = 0; k < o.pixels.size(); ++k)
      if (o.Weight(k) > 0.0) {
        kept.points_board.push_back(o.points_board[k]);
        kept.pixels.push_back(o.pixels[k]);
        if (!o.weights.empty()) kept.weights.push_back(o.weights[k]);
      }
    if (static_cast<int>(kept.pixels.size()) < options.min_points_per_observation) continue;
    obs.push_back(std::move(kept));
    nframes = std::max(nframes, o.frame + 1);
  }
  std::vector<std::vector<const BoardObservation*>> per_cam(ncam);
  for (const BoardObservation& o : obs) per_cam[o.camera].push_back(&o);
  for (int c = 0; c < ncam; ++c) {
    if (input.widths[c] <= 0 || input.heights[c] <= 0)
      Throw("camera ", input.camera_names[c], ": image size ", input.widths[c], "x", input.heights[c], " is not valid");
    if (per_cam[c].size() < 3)
      Throw("camera ", input.camera_names[c], " saw the calibration board (with at least ",
            options.min_points_per_observation, " points) in only ", per_cam[c].size(),
            " images; at least 3 views are needed: take more images with the whole board in view, tilted in "
            "different directions, or check the board description");
  }

  // --- Initialisation ---
  State st;
  std::vector<CameraModel> models;
  for (int c = 0; c < ncam; ++c) {
    if (!options.initial_intrinsics.empty() && !options.initial_intrinsics[c].empty()) {
      st.intrinsics.push_back(options.initial_intrinsics[c]);
      // Validates the count against the lens model (InputError naming both).
      models.emplace_back(options.lensmodel, st.intrinsics.back(), input.widths[c], input.heights[c]);
      continue;
    }
    log("initialising intrinsics of " + input.camera_names[c] + " from " +
        std::to_string(std::min<size_t>(per_cam[c].size(), options.max_init_views)) + " of " +
        std::to_string(per_cam[c].size()) + " views (cv::calibrateCamera)");
    st.intrinsics.push_back(
        InitIntrinsics(per_cam[c], input.widths[c], input.heights[c], lens, options.max_init_views));
    models.emplace_back(options.lensmodel, st.intrinsics.back(), input.widths[c], input.heights[c]);
  }
  // Board pose in each observing camera.
  std::vector<std::optional<Pose>> T_cam_board(obs.size());
  std::vector<std::map<int, size_t>> obs_of_frame(nframes);  // frame -> camera -> obs index
  for (size_t i = 0; i < obs.size(); ++i) {
    T_cam_board[i] = SolveBoardPose(obs[i], models[obs[i].camera]);
    if (T_cam_board[i]) obs_of_frame[obs[i].frame][obs[i].camera] = i;
  }
  // Extrinsics: grow the set of placed cameras from camera 0 through shared frames,
  // taking the camera with the most shared frames first.
  std::vector<std::optional<Pose>> T_cam_rig(ncam);
  T_cam_rig[0] = Pose::Identity();
  for (int placed = 1; placed < ncam; ++placed) {
    int best_cam = -1;
    std::vector<Pose> best_candidates;
    for (int c = 0; c < ncam; ++c) {
      if (T_cam_rig[c]) continue;
      std::vector<Pose> candidates;
      for (const auto& frame : obs_of_frame) {
        const auto it = frame.find(c);
        if (it == frame.end()) continue;
        for (const auto& [j, oj] : frame)
          if (j != c && T_cam_rig[j])
            candidates.push_back(*T_cam_board[it->second] * T_cam_board[oj]->Inverse() * *T_cam_rig[j]);
      }
      if (candidates.size() > best_candidates.size()) best_cam = c, best_candidates = candidates;
    }
    if (best_cam < 0) {
      std::ostringstream s;
      for (int c = 0; c < ncam; ++c)
        if (!T_cam_rig[c]) s << (s.str().empty() ? "" : ", ") << input.camera_names[c];
      Throw("camera calibration: camera(s) ", s.str(), " never saw the board in the same frame as ",
            input.camera_names[0],
            " (directly or through other cameras), so their pose in the rig is unknown; take images where the "
            "board is seen by these cameras and an already connected camera at the same time");
    }
    T_cam_rig[best_cam] = MedoidPose(best_candidates);
    log("placed " + input.camera_names[best_cam] + " from " + std::to_string(best_candidates.size()) +
        " shared board views");
  }
  for (int c = 0; c < ncam; ++c) st.rt_cam_rig.push_back(ToRt(*T_cam_rig[c]));
  st.rt_rig_board.resize(nframes);
  for (int f = 0; f < nframes; ++f) {
    std::vector<Pose> candidates;
    for (const auto& [c, oi] : obs_of_frame[f]) candidates.push_back(T_cam_rig[c]->Inverse() * *T_cam_board[oi]);
    if (!candidates.empty()) st.rt_rig_board[f] = ToRt(MedoidPose(candidates));
  }

  // Points that take part (observation has a board pose).
  std::vector<PointRef> points;
  for (size_t i = 0; i < obs.size(); ++i)
    if (st.rt_rig_board[obs[i].frame])
      for (size_t k = 0; k < obs[i].pixels.size(); ++k) points.push_back({i, k});
  std::vector<bool> inlier(points.size(), true);

  // Board extent for the warp shape (u, v = -1..1 across it).
  Eigen::Vector2d warp = Eigen::Vector2d::Zero();
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const BoardObservation& o : obs)
    for (const Vec3& P : o.points_board) lo = lo.cwiseMin(P.head<2>()), hi = hi.cwiseMax(P.head<2>());
  auto warp_shape = [&](const Vec3& P) -> std::optional<Eigen::Vector2d> {
    if (!options.solve_board_warp) return std::nullopt;
    Eigen::Vector2d s;
    for (int k = 0; k < 2; ++k) {
      const double u = hi[k] > lo[k] ? 2.0 * (P[k] - lo[k]) / (hi[k] - lo[k]) - 1.0 : 0.0;
      s[k] = 1.0 - u * u;
    }
    return s;
  };
  auto warped = [&](const Vec3& P) {
    const auto s = warp_shape(P);
    return s ? Vec3(P.x(), P.y(), P.z() + warp.dot(*s)) : P;
  };

  auto residual_of = [&](const PointRef& pr) -> Vec2 {
    const BoardObservation& o = obs[pr.obs];
    CameraModel m = models[o.camera];
    m.MutableIntrinsics() = st.intrinsics[o.camera];
    const Pose T = FromRt(st.rt_cam_rig[o.camera]) * FromRt(*st.rt_rig_board[o.frame]);
    const Vec3 p = T * warped(o.points_board[pr.index]);
    if (!(p.z() > 0.0) && !m.CanProjectBehindCamera()) return Vec2::Constant(std::numeric_limits<double>::infinity());
    return o.Weight(pr.index) * (m.Project(p) - o.pixels[pr.index]);
  };

  // Builds the problem over the current inliers. Block order (used by the
  // covariance below): intrinsics, extrinsics of cameras 1.., board poses.
  auto build = [&](ceres::Problem& problem) {
    for (size_t i = 0; i < points.size(); ++i) {
      if (!inlier[i]) continue;
      const BoardObservation& o = obs[points[i].obs];
      const bool ext = o.camera != 0;
      const Vec3& P = o.points_board[points[i].index];
      auto* cost = new ReprojectionCost(models[o.camera], P, o.pixels[points[i].index], o.Weight(points[i].index), ext,
                                        warp_shape(P));
      std::vector<double*> blocks = {st.intrinsics[o.camera].data(), st.rt_rig_board[o.frame]->data()};
      if (ext) blocks.push_back(st.rt_cam_rig[o.camera].data());
      if (options.solve_board_warp) blocks.push_back(warp.data());
      problem.AddResidualBlock(cost, nullptr, blocks);
      if (options.fix_intrinsics) problem.SetParameterBlockConstant(st.intrinsics[o.camera].data());
    }
  };
  auto solve = [&]() {
    ceres::Problem problem;
    build(problem);
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_SCHUR;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 1;
    so.function_tolerance = 1e-12;
    so.parameter_tolerance = 1e-12;
    so.gradient_tolerance = 1e-12;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable()) Throw("camera calibration: the bundle adjustment failed: ", summary.message);
    return summary;
  };

  CameraCalibrationResult res;
  int round = 0;
  for (;; ++round) {
    const auto summary = solve();
    double ss = 0.0;
    int n = 0;
    std::vector<Vec2> e(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      e[i] = residual_of(points[i]);
      if (inlier[i]) ss += e[i].squaredNorm(), ++n;
    }
    const double sigma = std::sqrt(ss / std::max(1, 2 * n));
    int added = 0;
    if (options.outlier_k > 0.0 && round < options.max_outlier_rounds) {
      bool triggered = false;
      for (size_t i = 0; i < points.size() && !triggered; ++i)
        triggered = inlier[i] && !(e[i].cwiseAbs().maxCoeff() <= (options.outlier_k + options.outlier_trigger) * sigma);
      if (triggered)
        for (size_t i = 0; i < points.size(); ++i)
          if (inlier[i] && !(e[i].cwiseAbs().maxCoeff() <= options.outlier_k * sigma)) inlier[i] = false, ++added;
    }
    std::ostringstream s;
    s << "solve " << round << ": " << summary.iterations.size() << " iterations, RMS " << sigma
      << " px per coordinate over " << n << " points; " << added << " new outliers";
    log(s.str());
    if (added == 0) break;
  }
  res.outlier_rounds = round;

  // --- Results ---
  for (int c = 0; c < ncam; ++c) {
    CameraModel m(options.lensmodel, st.intrinsics[c], input.widths[c], input.heights[c], FromRt(st.rt_cam_rig[c]));
    res.rig.names.push_back(input.camera_names[c]);
    res.rig.cameras.push_back(m);
  }
  for (int f = 0; f < nframes; ++f)
    res.T_rig_board.push_back(st.rt_rig_board[f] ? std::optional<Pose>(FromRt(*st.rt_rig_board[f])) : std::nullopt);
  res.residuals.resize(ncam);
  double ss_all = 0.0;
  std::vector<double> ss(ncam, 0.0);
  for (size_t i = 0; i < points.size(); ++i) {
    const int c = obs[points[i].obs].camera;
    const Vec2 e = residual_of(points[i]);
    auto& r = res.residuals[c];
    r.pixels.push_back(obs[points[i].obs].pixels[points[i].index]);
    r.residuals.push_back(e);
    r.inlier.push_back(inlier[i]);
    ++r.num_points;
    if (inlier[i]) {
      ss[c] += e.squaredNorm();
      ss_all += e.squaredNorm();
      r.max_px = std::max(r.max_px, e.norm());
      ++res.num_inliers;
    } else {
      ++r.num_outliers;
      ++res.num_outliers;
    }
  }
  for (const BoardObservation& o : obs)
    if (st.rt_rig_board[o.frame]) ++res.residuals[o.camera].num_observations;
  for (int c = 0; c < ncam; ++c) {
    auto& r = res.residuals[c];
    const int n = r.num_points - r.num_outliers;
    r.rms_px = std::sqrt(ss[c] / std::max(1, 2 * n));
    r.rms_point_px = std::sqrt(ss[c] / std::max(1, n));
  }
  res.rms_px = std::sqrt(ss_all / std::max(1, 2 * res.num_inliers));

  // --- Covariance: inverse normal matrix, boards marginalised by the Schur complement ---
  {
    ceres::Problem problem;
    build(problem);
    std::vector<double*> blocks;
    std::vector<int> cam_offset(ncam), ext_offset(ncam, -1);
    int na = 0;
    for (int c = 0; c < ncam && !options.fix_intrinsics; ++c) {
      blocks.push_back(st.intrinsics[c].data());
      cam_offset[c] = na;
      na += static_cast<int>(st.intrinsics[c].size());
    }
    for (int c = 1; c < ncam; ++c) {
      blocks.push_back(st.rt_cam_rig[c].data());
      ext_offset[c] = na;
      na += 6;
    }
    const int warp_offset = na;
    if (options.solve_board_warp) {
      blocks.push_back(warp.data());
      na += 2;
    }
    int nb = 0;
    std::vector<int> frames_in_solve;  // frame index of each 6-column board block, in order
    for (int f = 0; f < nframes; ++f)
      if (st.rt_rig_board[f] && problem.HasParameterBlock(st.rt_rig_board[f]->data())) {
        blocks.push_back(st.rt_rig_board[f]->data());
        frames_in_solve.push_back(f);
        nb += 6;
      }
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = blocks;
    ceres::CRSMatrix crs;
    problem.Evaluate(eo, nullptr, nullptr, nullptr, &crs);
    Eigen::SparseMatrix<double, Eigen::RowMajor> J(crs.num_rows, crs.num_cols);
    std::vector<Eigen::Triplet<double>> trip;
    for (int r = 0; r < crs.num_rows; ++r)
      for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) trip.emplace_back(r, crs.cols[k], crs.values[k]);
    J.setFromTriplets(trip.begin(), trip.end());
    const Eigen::SparseMatrix<double> N = Eigen::SparseMatrix<double>(J.transpose()) * J;
    const Eigen::MatrixXd A = Eigen::MatrixXd(N.topLeftCorner(na, na));
    const Eigen::MatrixXd B = Eigen::MatrixXd(N.block(0, na, na, nb));
    Eigen::MatrixXd S = A;
    std::vector<Mat6> D_inv(frames_in_solve.size());
    std::vector<Eigen::MatrixXd> gain(frames_in_solve.size());  // K_f = D_f^-1 B_f^T
    for (int b = 0; b < nb; b += 6) {
      const Mat6 D = Eigen::MatrixXd(N.block(na + b, na + b, 6, 6));
      const Eigen::MatrixXd Bb = B.middleCols(b, 6);
      D_inv[b / 6] = D.ldlt().solve(Mat6::Identity());
      gain[b / 6] = D_inv[b / 6] * Bb.transpose();
      S -= Bb * gain[b / 6];
    }
    const int dof = 2 * res.num_inliers - na - nb;
    res.residual_variance_px2 = dof > 0 ? ss_all / dof : std::numeric_limits<double>::quiet_NaN();
    const Eigen::MatrixXd cov = S.ldlt().solve(Eigen::MatrixXd::Identity(na, na)) * res.residual_variance_px2;
    CalibrationCovariance& full = res.covariance;
    full.a_cov = cov;
    full.intrinsics_offset.assign(ncam, -1);
    if (!options.fix_intrinsics) full.intrinsics_offset = cam_offset;
    full.extrinsics_offset = ext_offset;
    full.warp_offset = options.solve_board_warp ? warp_offset : -1;
    full.frame_in_solve.assign(nframes, false);
    full.frame_conditional_cov.assign(nframes, Mat6::Zero());
    full.frame_gain.assign(nframes, Eigen::MatrixXd());
    for (size_t k = 0; k < frames_in_solve.size(); ++k) {
      const int f = frames_in_solve[k];
      full.frame_in_solve[f] = true;
      full.frame_conditional_cov[f] = D_inv[k] * res.residual_variance_px2;
      full.frame_gain[f] = std::move(gain[k]);
    }
    for (int c = 0; c < ncam; ++c) {
      const int n = static_cast<int>(st.intrinsics[c].size());
      res.intrinsics_covariance.push_back(options.fix_intrinsics ? Eigen::MatrixXd::Zero(n, n)
                                                                 : Eigen::MatrixXd(cov.block(cam_offset[c], cam_offset[c], n, n)));
      res.intrinsics_std.push_back(res.intrinsics_covariance.back().diagonal().cwiseMax(0.0).cwiseSqrt());
      Vec6 s = Vec6::Zero();
      if (c > 0) s = cov.block<6, 6>(ext_offset[c], ext_offset[c]).diagonal().cwiseMax(0.0).cwiseSqrt();
      res.extrinsics_std.push_back(s);
    }
    if (options.solve_board_warp) {
      res.board_warp_m = warp;
      res.board_warp_std_m = cov.block<2, 2>(warp_offset, warp_offset).diagonal().cwiseMax(0.0).cwiseSqrt();
    }
  }
  return res;
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
  const double sigma = st.rms_px > 0 ? st.rms_px : 1.0;
  PlotSeries low{"|e| < 1 sigma", {}, {}, "#2ca02c", true}, mid{"1-3 sigma", {}, {}, "#ff7f0e", true},
      high{"> 3 sigma", {}, {}, "#d62728", true}, out{"rejected", {}, {}, "#000000", true};
  for (size_t i = 0; i < st.pixels.size(); ++i) {
    const double e = st.residuals[i].norm() / sigma;
    PlotSeries& s = !st.inlier[i] ? out : e < 1 ? low : e < 3 ? mid : high;
    s.x.push_back(st.pixels[i].x());
    s.y.push_back(-st.pixels[i].y());
  }
  Plot p;
  std::ostringstream t;
  t << r.rig.names[camera] << ": residuals over the image (sigma = " << sigma << " px per coordinate)";
  p.title = t.str();
  p.x_label = "u (px)";
  p.y_label = "-v (px)";
  for (auto* s : {&low, &mid, &high, &out})
    if (!s->x.empty()) p.series.push_back(*s);
  p.WriteSvg(path);
}

}  // namespace mcms
