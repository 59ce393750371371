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

bool CameraCalibrationOptions::IsValid(std::string* why) const {
  std::ostringstream s;
  if (!(outlier_k == 0.0 || outlier_k >= 2.0)) s << "outlier_k must be 0 (off) or >= 2 (got " << outlier_k << ")";
  else if (!(outlier_trigger >= 0.0)) s << "outlier_trigger must be >= 0 (got " << outlier_trigger << ")";
  else if (max_outlier_rounds < 0) s << "max_outlier_rounds must be >= 0";
  else if (max_iterations < 1) s << "max_iterations must be >= 1";
  else if (lensmodel == "auto" && auto_lensmodels.empty()) s << "lensmodel auto needs at least one candidate in auto_lensmodels";
  else if (!(auto_max_distortion_std > 0.0)) s << "auto_max_distortion_std must be > 0";
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
        "' cannot be calibrated here: use auto, LENSMODEL_PINHOLE, LENSMODEL_OPENCV4, LENSMODEL_OPENCV5, "
        "LENSMODEL_OPENCV8 or LENSMODEL_OPENCV12");
}

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

// Intrinsics of one camera from OpenCV: a 4-coefficient fit (robust for any lens);
// the model's further coefficients start at zero and are left to the joint
// least-squares refinement. A second, full-model cv::calibrateCamera is not run: on
// few views its rational / thin-prism fit is ill-conditioned and its result then
// depends on the heap layout (differences of 1e-10 that the refinement amplifies),
// so the same data would not always give the same calibration.
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
  std::vector<double> intr = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2), K.at<double>(1, 2)};
  D = D.reshape(1, 1);
  for (int i = 0; i < lens.num_distortions; ++i) intr.push_back(i < 4 && i < D.cols ? D.at<double>(0, i) : 0.0);
  return intr;
}

// A view's board pose from its points alone: from `seed` (T_cam_board) when given,
// refined; else from OpenCV's planar solution (IPPE, iterative as a fallback).
std::optional<Pose> SolveBoardPose(const BoardObservation& o, const CameraModel& cam,
                                   const std::optional<Pose>& seed = std::nullopt) {
  const auto& in = cam.Intrinsics();
  cv::Mat K = (cv::Mat_<double>(3, 3) << in[0], 0, in[2], 0, in[1], in[3], 0, 0, 1);
  cv::Mat D(1, static_cast<int>(in.size()) - 4, CV_64F);
  for (int i = 4; i < static_cast<int>(in.size()); ++i) D.at<double>(0, i - 4) = in[i];
  cv::Mat rvec, tvec;
  if (seed) {
    const Rt rt = ToRt(*seed);
    rvec = (cv::Mat_<double>(3, 1) << rt[0], rt[1], rt[2]);
    tvec = (cv::Mat_<double>(3, 1) << rt[3], rt[4], rt[5]);
  } else if (!cv::solvePnP(CvObject(o), CvImage(o), K, D.cols ? D : cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_IPPE) &&
             !cv::solvePnP(CvObject(o), CvImage(o), K, D.cols ? D : cv::Mat(), rvec, tvec, false,
                           cv::SOLVEPNP_ITERATIVE)) {
    return std::nullopt;
  }
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

using LogFn = std::function<void(const std::string&)>;

// --- Step 1: the observations that take part, validated ---------------------------

struct Observations {
  std::vector<BoardObservation> obs;                     // only points with weight > 0
  std::vector<std::vector<const BoardObservation*>> per_cam;
  int nframes = 0;
};

Observations PrepareObservations(const CameraCalibrationInput& input, const CameraCalibrationOptions& options) {
  const int ncam = static_cast<int>(input.camera_names.size());
  if (ncam == 0) Throw("camera calibration: no cameras given");
  if (!options.initial_intrinsics.empty() && static_cast<int>(options.initial_intrinsics.size()) != ncam)
    Throw("camera calibration: ", options.initial_intrinsics.size(), " sets of initial intrinsics for ", ncam, " cameras");
  if (static_cast<int>(input.widths.size()) != ncam || static_cast<int>(input.heights.size()) != ncam)
    Throw("camera calibration: ", ncam, " camera names but ", input.widths.size(), " widths and ",
          input.heights.size(), " heights");
  Observations out;
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
    out.obs.push_back(std::move(kept));
    out.nframes = std::max(out.nframes, o.frame + 1);
  }
  out.per_cam.resize(ncam);
  for (const BoardObservation& o : out.obs) out.per_cam[o.camera].push_back(&o);
  for (int c = 0; c < ncam; ++c) {
    if (input.widths[c] <= 0 || input.heights[c] <= 0)
      Throw("camera ", input.camera_names[c], ": image size ", input.widths[c], "x", input.heights[c], " is not valid");
    if (out.per_cam[c].size() < 3)
      Throw("camera ", input.camera_names[c], " saw the calibration board (with at least ",
            options.min_points_per_observation, " points) in only ", out.per_cam[c].size(),
            " images; at least 3 views are needed: take more images with the whole board in view, tilted in "
            "different directions, or check the board description");
  }
  return out;
}

// --- Step 2: initial values ---------------------------------------------------------

struct State {
  std::vector<std::vector<double>> intrinsics;
  std::vector<Rt> rt_cam_rig;                 // [0] stays identity
  std::vector<std::optional<Rt>> rt_rig_board;
  Eigen::Vector2d warp = Eigen::Vector2d::Zero();
};

// Every camera's intrinsics: given, or from cv::calibrateCamera.
std::vector<CameraModel> InitialCameras(const CameraCalibrationInput& input, const Observations& ob,
                                        const CameraCalibrationOptions& options, const LogFn& log) {
  const LensSupport lens = SupportOf(options.lensmodel);
  std::vector<CameraModel> models;
  for (size_t c = 0; c < input.camera_names.size(); ++c) {
    std::vector<double> intrinsics;
    if (!options.initial_intrinsics.empty() && !options.initial_intrinsics[c].empty()) {
      intrinsics = options.initial_intrinsics[c];
    } else {
      log("initialising intrinsics of " + input.camera_names[c] + " from " +
          std::to_string(std::min<size_t>(ob.per_cam[c].size(), options.max_init_views)) + " of " +
          std::to_string(ob.per_cam[c].size()) + " views (cv::calibrateCamera)");
      intrinsics = InitIntrinsics(ob.per_cam[c], input.widths[c], input.heights[c], lens, options.max_init_views);
    }
    // Validates the count against the lens model (InputError naming both).
    models.emplace_back(options.lensmodel, intrinsics, input.widths[c], input.heights[c]);
  }
  return models;
}

// RMS (per coordinate) of the observation's pixels against its board points mapped by
// S and projected at T_cam_board; +infinity where a point is behind the camera.
double ReprojectionRms(const CameraModel& cam, const BoardObservation& o, const Pose& T_cam_board, const Pose& S) {
  double ss = 0.0;
  for (size_t k = 0; k < o.pixels.size(); ++k) {
    const Vec3 p = T_cam_board * (S * o.points_board[k]);
    if (!(p.z() > 0.0)) return std::numeric_limits<double>::infinity();
    const Vec2 q = cam.Project(p);
    if (!q.allFinite()) return std::numeric_limits<double>::infinity();
    ss += (q - o.pixels[k]).squaredNorm();
  }
  return std::sqrt(ss / std::max<size_t>(1, 2 * o.pixels.size()));
}

// Symmetric boards: a candidate T_cam_rig agrees with a frame when one of the frame's
// candidates lies within this distance (rotation angle in rad + translation / the
// typical board distance). A wrong numbering turns the candidate by 90 or 180 deg about
// the board normal, so the exact value is not critical; it must exceed the scatter of
// PnP poses from the initial intrinsics (a few degrees at worst).
constexpr double kConsensusTolerance = 0.25;
// ... and a frame's numbering is taken when its reprojection error is below this
// fraction of the next best numbering's (a wrong numbering moves the corners by up to
// the board's size in the image, the right one leaves the initial rig's error).
constexpr double kDecisiveRatio = 0.5;

std::string FrameCameraList(const CameraCalibrationInput& input, const std::vector<int>& cams) {
  std::string s;
  for (size_t k = 0; k < cams.size(); ++k) s += (k ? ", " : "") + input.camera_names[cams[k]];
  return s;
}

// T_cam_rig of every camera, grown from camera 0 through shared frames, the camera
// with the most shared frames first; each from the medoid of its candidates.
//
// With a symmetric board (input.board_symmetries) each shared frame gives one candidate
// per numbering; the candidate that most frames agree with wins (refused when fewer
// than two frames agree, or when a distinct candidate has as much support: the views
// cannot tell the numberings apart). The new camera's observation of every frame it
// shares with placed cameras is then renumbered to the numbering whose points
// reproject best with the board pose the placed cameras saw; observations with no
// decisive numbering are dropped. So all placed cameras of a frame always agree.
std::vector<Pose> PlaceCameras(const CameraCalibrationInput& input, Observations& ob,
                               const std::vector<CameraModel>& models, std::vector<std::optional<Pose>>& T_cam_board,
                               std::vector<std::map<int, size_t>>& obs_of_frame, std::vector<bool>& dropped,
                               const LogFn& log, CameraCalibrationResult& res) {
  const int ncam = static_cast<int>(input.camera_names.size());
  const bool symmetric = !input.board_symmetries.empty();
  std::vector<Pose> numberings = {Pose::Identity()};
  numberings.insert(numberings.end(), input.board_symmetries.begin(), input.board_symmetries.end());
  double scale = 0.0;
  int nscale = 0;
  for (const auto& T : T_cam_board)
    if (T) scale += T->t.norm(), ++nscale;
  scale = std::max(scale / std::max(1, nscale), 1e-6);
  auto distance = [&](const Pose& a, const Pose& b) { return RotationAngle(a.R, b.R) + (a.t - b.t).norm() / scale; };

  std::vector<std::optional<Pose>> T_cam_rig(ncam);
  T_cam_rig[0] = Pose::Identity();
  for (int placed = 1; placed < ncam; ++placed) {
    // The unplaced camera with the most views shared with placed cameras (a frame
    // counts once per placed camera in it).
    int c = -1;
    size_t best_views = 0;
    for (int k = 0; k < ncam; ++k) {
      if (T_cam_rig[k]) continue;
      size_t n = 0;
      for (const auto& frame : obs_of_frame) {
        if (!frame.count(k)) continue;
        for (const auto& [j, oj] : frame) n += j != k && T_cam_rig[j].has_value();
      }
      if (n > best_views) c = k, best_views = n;
    }
    if (c < 0) {
      std::ostringstream s;
      for (int k = 0; k < ncam; ++k)
        if (!T_cam_rig[k]) s << (s.str().empty() ? "" : ", ") << input.camera_names[k];
      Throw("camera calibration: camera(s) ", s.str(), " never saw the board in the same frame as ",
            input.camera_names[0],
            " (directly or through other cameras), so their pose in the rig is unknown; take images where the "
            "board is seen by these cameras and an already connected camera at the same time");
    }
    // Candidates T_c_rig = T_c_board S^-1 T_j_board^-1 T_j_rig, per shared frame f, placed camera j and
    // numbering S (the observation's points renumbered to S P: its pose becomes T_c_board S^-1).
    struct Candidate {
      int frame;
      Pose X;
    };
    std::vector<Candidate> candidates;
    std::vector<int> frames;
    std::set<int> placed_partners;
    for (int f = 0; f < static_cast<int>(obs_of_frame.size()); ++f) {
      const auto it = obs_of_frame[f].find(c);
      if (it == obs_of_frame[f].end()) continue;
      bool any = false;
      for (const auto& [j, oj] : obs_of_frame[f]) {
        if (j == c || !T_cam_rig[j]) continue;
        any = true;
        placed_partners.insert(j);
        for (const Pose& S : numberings)
          candidates.push_back({f, *T_cam_board[it->second] * S.Inverse() * T_cam_board[oj]->Inverse() * *T_cam_rig[j]});
      }
      if (any) frames.push_back(f);
    }
    const std::string partners = FrameCameraList(input, {placed_partners.begin(), placed_partners.end()});
    if (!symmetric) {
      std::vector<Pose> poses;
      for (const Candidate& k : candidates) poses.push_back(k.X);
      T_cam_rig[c] = MedoidPose(poses);
      log("placed " + input.camera_names[c] + " from " + std::to_string(poses.size()) + " shared board views");
      continue;
    }
    // Support of X: the frames with a candidate within the tolerance; cost: truncated distances.
    auto support = [&](const Pose& X, double* cost) {
      std::map<int, double> nearest;
      for (const Candidate& k : candidates) {
        const double d = distance(X, k.X);
        auto [it, fresh] = nearest.emplace(k.frame, d);
        if (!fresh) it->second = std::min(it->second, d);
      }
      int n = 0;
      *cost = 0.0;
      for (const auto& [f, d] : nearest) n += d < kConsensusTolerance, *cost += std::min(d, kConsensusTolerance);
      return n;
    };
    int best = -1, best_support = 0;
    double best_cost = 0.0;
    std::vector<int> supports(candidates.size());
    for (size_t a = 0; a < candidates.size(); ++a) {
      double cost;
      supports[a] = support(candidates[a].X, &cost);
      if (best < 0 || supports[a] > best_support || (supports[a] == best_support && cost < best_cost))
        best = static_cast<int>(a), best_support = supports[a], best_cost = cost;
    }
    int rival_support = 0;
    for (size_t a = 0; a < candidates.size(); ++a)
      if (distance(candidates[a].X, candidates[best].X) > 2 * kConsensusTolerance)
        rival_support = std::max(rival_support, supports[a]);
    if (best_support < 2 || rival_support >= best_support)
      Throw("camera calibration: the board's numbering is symmetric (the detector may number it turned by 90 or "
            "180 deg), and the ", frames.size(), " frame(s) camera ", input.camera_names[c], " shares with ",
            partners, " do not tell which numbering of its views matches theirs (",
            best_support, " frame(s) agree on its best pose, ", rival_support,
            " on a pose turned against it); take more views with the board tilted in different directions, or use "
            "a chessboard with one even and one odd number of inner corners (e.g. 9 x 6), whose numbering is "
            "unique; no output written");
    std::vector<Pose> agreeing;
    for (int f : frames) {
      const Candidate* nearest = nullptr;
      for (const Candidate& k : candidates)
        if (k.frame == f && (!nearest || distance(k.X, candidates[best].X) < distance(nearest->X, candidates[best].X)))
          nearest = &k;
      if (nearest && distance(nearest->X, candidates[best].X) < kConsensusTolerance) agreeing.push_back(nearest->X);
    }
    T_cam_rig[c] = MedoidPose(agreeing);
    log("placed " + input.camera_names[c] + " from " + std::to_string(agreeing.size()) + " of " +
        std::to_string(frames.size()) + " shared frames (numbering of the symmetric board checked per frame)");
    // Per shared frame: the numbering of c's observation that reprojects best with the
    // board pose the frame's placed cameras saw.
    for (int f : frames) {
      const size_t oc = obs_of_frame[f].at(c);
      std::vector<Pose> boards;
      for (const auto& [j, oj] : obs_of_frame[f])
        if (j != c && T_cam_rig[j]) boards.push_back(T_cam_rig[j]->Inverse() * *T_cam_board[oj]);
      const Pose T_c_board = *T_cam_rig[c] * MedoidPose(boards);
      std::vector<std::pair<double, int>> rms;
      for (size_t s = 0; s < numberings.size(); ++s)
        rms.emplace_back(ReprojectionRms(models[c], ob.obs[oc], T_c_board, numberings[s]), static_cast<int>(s));
      std::sort(rms.begin(), rms.end());
      if (!(rms[0].first < kDecisiveRatio * rms[1].first)) {
        std::ostringstream why;
        why.precision(3);
        why << "its numbering of the symmetric board could not be matched with the other cameras' (reprojection "
            << rms[0].first << " px under the best numbering, " << rms[1].first << " px under the next)";
        res.dropped.push_back({c, f, why.str()});
        log("frame " + std::to_string(f) + ", " + input.camera_names[c] + ": left out: " + why.str());
        dropped[oc] = true;
        obs_of_frame[f].erase(c);
        continue;
      }
      if (rms[0].second == 0) continue;
      const Pose& S = numberings[rms[0].second];
      double as_numbered = 0.0;
      for (const auto& [r, s] : rms)
        if (s == 0) as_numbered = r;
      for (Vec3& P : ob.obs[oc].points_board) P = S * P;
      T_cam_board[oc] = *T_cam_board[oc] * S.Inverse();
      const double angle = std::atan2(S.R(1, 0), S.R(0, 0)) * 180.0 / std::numbers::pi;
      res.renumbered.push_back({c, f, angle < 0 ? angle + 360.0 : angle, rms[0].first, rms[1].first});
      std::ostringstream m;
      m.precision(3);
      m << "frame " << f << ", " << input.camera_names[c] << ": the detector numbered the symmetric board turned by "
        << res.renumbered.back().angle_deg << " deg against " << partners << "; renumbered (reprojection "
        << rms[0].first << " px, " << as_numbered << " px as numbered)";
      log(m.str());
    }
  }
  std::vector<Pose> out;
  for (const auto& T : T_cam_rig) out.push_back(*T);
  return out;
}

// Intrinsics, extrinsics and one board pose per frame (medoid of its cameras' PnP poses).
// Observations PlaceCameras drops are removed from `ob`.
State Initialise(const CameraCalibrationInput& input, Observations& ob, const CameraCalibrationOptions& options,
                 const LogFn& log, CameraCalibrationResult& res) {
  const std::vector<CameraModel> models = InitialCameras(input, ob, options, log);
  std::vector<std::optional<Pose>> T_cam_board(ob.obs.size());
  std::vector<std::map<int, size_t>> obs_of_frame(ob.nframes);  // frame -> camera -> obs index
  for (size_t i = 0; i < ob.obs.size(); ++i) {
    T_cam_board[i] = SolveBoardPose(ob.obs[i], models[ob.obs[i].camera]);
    if (T_cam_board[i]) obs_of_frame[ob.obs[i].frame][ob.obs[i].camera] = i;
  }
  std::vector<bool> dropped(ob.obs.size(), false);
  if (!input.board_symmetries.empty())
    for (size_t i = 0; i < ob.obs.size(); ++i) {
      const BoardObservation& o = ob.obs[i];
      if (T_cam_board[i] || obs_of_frame[o.frame].empty()) continue;
      // Its numbering cannot be compared with the frame's other cameras.
      dropped[i] = true;
      res.dropped.push_back({o.camera, o.frame,
                             "its board pose could not be estimated (PnP), so its numbering of the symmetric board "
                             "cannot be matched with the frame's other cameras"});
    }
  const std::vector<Pose> T_cam_rig = PlaceCameras(input, ob, models, T_cam_board, obs_of_frame, dropped, log, res);
  if (std::find(dropped.begin(), dropped.end(), true) != dropped.end()) {
    std::vector<BoardObservation> kept;
    std::vector<std::optional<Pose>> kept_T;
    for (size_t i = 0; i < ob.obs.size(); ++i)
      if (!dropped[i]) kept.push_back(std::move(ob.obs[i])), kept_T.push_back(T_cam_board[i]);
    ob.obs = std::move(kept);
    T_cam_board = std::move(kept_T);
    ob.per_cam.assign(input.camera_names.size(), {});
    for (const BoardObservation& o : ob.obs) ob.per_cam[o.camera].push_back(&o);
    obs_of_frame.assign(ob.nframes, {});
    for (size_t i = 0; i < ob.obs.size(); ++i)
      if (T_cam_board[i]) obs_of_frame[ob.obs[i].frame][ob.obs[i].camera] = i;
  }
  State st;
  for (const CameraModel& m : models) st.intrinsics.push_back(m.Intrinsics());
  for (const Pose& T : T_cam_rig) st.rt_cam_rig.push_back(ToRt(T));
  st.rt_rig_board.resize(ob.nframes);
  for (int f = 0; f < ob.nframes; ++f) {
    std::vector<Pose> candidates;
    for (const auto& [c, oi] : obs_of_frame[f]) candidates.push_back(T_cam_rig[c].Inverse() * *T_cam_board[oi]);
    if (!candidates.empty()) st.rt_rig_board[f] = ToRt(MedoidPose(candidates));
  }
  return st;
}

// --- Step 3: the least-squares problem ------------------------------------------------

// The bundle adjustment over the state: one ReprojectionCost per observed point
// (created once, evaluated by Ceres and by Residual()), and the inlier set.
class RigProblem {
 public:
  RigProblem(const Observations& ob, State st, const CameraCalibrationOptions& options)
      : ob_(ob), st(std::move(st)), options_(options) {
    // Board extent for the warp shape (u, v = -1..1 across it).
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const BoardObservation& o : ob_.obs)
      for (const Vec3& P : o.points_board) lo = lo.cwiseMin(P.head<2>()), hi = hi.cwiseMax(P.head<2>());
    for (size_t i = 0; i < ob_.obs.size(); ++i) {
      const BoardObservation& o = ob_.obs[i];
      if (!this->st.rt_rig_board[o.frame]) continue;
      for (size_t k = 0; k < o.pixels.size(); ++k) {
        std::optional<Eigen::Vector2d> shape;
        if (options_.solve_board_warp) {
          shape.emplace();
          for (int d = 0; d < 2; ++d) {
            const double u = hi[d] > lo[d] ? 2.0 * (o.points_board[k][d] - lo[d]) / (hi[d] - lo[d]) - 1.0 : 0.0;
            (*shape)[d] = 1.0 - u * u;
          }
        }
        points_.push_back({i, k});
        costs_.push_back(std::make_unique<ReprojectionCost>(options_.lensmodel, o.points_board[k], o.pixels[k],
                                                            o.Weight(k), o.camera != 0, shape));
      }
    }
    inlier.assign(points_.size(), true);
  }

  size_t NumPoints() const { return points_.size(); }
  const BoardObservation& Observation(size_t i) const { return ob_.obs[points_[i].obs]; }
  size_t PointIndex(size_t i) const { return points_[i].index; }

  // Adds the inliers' residuals. Block order (used by the covariance): intrinsics,
  // extrinsics of cameras 1.., warp, board poses.
  void Build(ceres::Problem& problem) {
    for (size_t i = 0; i < points_.size(); ++i) {
      if (!inlier[i]) continue;
      problem.AddResidualBlock(costs_[i].get(), nullptr, Blocks(i));
      if (options_.fix_intrinsics) problem.SetParameterBlockConstant(st.intrinsics[Observation(i).camera].data());
    }
  }

  // Weighted residual of point i at the current state (infinite where it does not project).
  Vec2 Residual(size_t i) {
    const std::vector<double*> blocks = Blocks(i);
    Vec2 r;
    if (!costs_[i]->Evaluate(blocks.data(), r.data(), nullptr)) return Vec2::Constant(std::numeric_limits<double>::infinity());
    return r;
  }

  ceres::Solver::Summary Solve(int max_iterations) {
    ceres::Problem problem(ProblemOptions());
    Build(problem);
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_SCHUR;
    so.max_num_iterations = max_iterations;
    so.num_threads = 1;
    so.function_tolerance = 1e-12;
    so.parameter_tolerance = 1e-12;
    so.gradient_tolerance = 1e-12;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable()) Throw("camera calibration: the bundle adjustment failed: ", summary.message);
    return summary;
  }

  static ceres::Problem::Options ProblemOptions() {
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;  // the costs live in costs_
    return po;
  }

 private:
  struct PointRef {
    size_t obs;
    size_t index;
  };
  std::vector<double*> Blocks(size_t i) {
    const BoardObservation& o = Observation(i);
    std::vector<double*> blocks = {st.intrinsics[o.camera].data(), st.rt_rig_board[o.frame]->data()};
    if (o.camera != 0) blocks.push_back(st.rt_cam_rig[o.camera].data());
    if (options_.solve_board_warp) blocks.push_back(st.warp.data());
    return blocks;
  }

  const Observations& ob_;

 public:
  State st;
  std::vector<bool> inlier;

 private:
  const CameraCalibrationOptions& options_;
  std::vector<PointRef> points_;
  std::vector<std::unique_ptr<ReprojectionCost>> costs_;
};

// --- Step 4: solve, reject outliers, re-solve ---------------------------------------

void SolveWithOutlierRejection(RigProblem& rp, const CameraCalibrationOptions& options, const LogFn& log,
                               CameraCalibrationResult& res) {
  for (int round = 0;; ++round) {
    const ceres::Solver::Summary summary = rp.Solve(options.max_iterations);
    double ss = 0.0;
    int n = 0;
    std::vector<Vec2> e(rp.NumPoints());
    for (size_t i = 0; i < e.size(); ++i) {
      e[i] = rp.Residual(i);
      if (rp.inlier[i]) ss += e[i].squaredNorm(), ++n;
    }
    const double sigma = std::sqrt(ss / std::max(1, 2 * n));
    int added = 0;
    if (options.outlier_k > 0.0 && round < options.max_outlier_rounds) {
      bool triggered = false;
      for (size_t i = 0; i < e.size() && !triggered; ++i)
        triggered = rp.inlier[i] && !(e[i].cwiseAbs().maxCoeff() <= (options.outlier_k + options.outlier_trigger) * sigma);
      if (triggered)
        for (size_t i = 0; i < e.size(); ++i)
          if (rp.inlier[i] && !(e[i].cwiseAbs().maxCoeff() <= options.outlier_k * sigma)) rp.inlier[i] = false, ++added;
    }
    const bool converged = summary.termination_type == ceres::CONVERGENCE;
    const int iterations = static_cast<int>(summary.iterations.size()) - 1;  // [0] is the initial state
    std::ostringstream s;
    s << "solve " << round << ": " << iterations << " iterations" << (converged ? "" : " (NOT CONVERGED)") << ", RMS "
      << sigma << " px per coordinate over " << n << " points; " << added << " new outliers";
    log(s.str());
    res.outlier_rounds = round;
    res.converged = converged;
    res.iterations = iterations;
    res.solver_message = summary.message;
    if (added == 0) break;
  }
}

// --- Step 5: the solution and its residuals -------------------------------------------

void CollectSolution(RigProblem& rp, const CameraCalibrationInput& input, const Observations& ob,
                     const CameraCalibrationOptions& options, CameraCalibrationResult& res) {
  const int ncam = static_cast<int>(input.camera_names.size());
  const State& st = rp.st;
  for (int c = 0; c < ncam; ++c) {
    res.rig.names.push_back(input.camera_names[c]);
    res.rig.cameras.emplace_back(options.lensmodel, st.intrinsics[c], input.widths[c], input.heights[c],
                                 FromRt(st.rt_cam_rig[c]));
  }
  for (int f = 0; f < ob.nframes; ++f)
    res.T_rig_board.push_back(st.rt_rig_board[f] ? std::optional<Pose>(FromRt(*st.rt_rig_board[f])) : std::nullopt);
  res.residuals.assign(ncam, {});
  double ss_all = 0.0;
  std::vector<double> ss(ncam, 0.0);
  for (size_t i = 0; i < rp.NumPoints(); ++i) {
    const BoardObservation& o = rp.Observation(i);
    const Vec2 e = rp.Residual(i);
    auto& r = res.residuals[o.camera];
    r.pixels.push_back(o.pixels[rp.PointIndex(i)]);
    r.residuals.push_back(e);
    r.inlier.push_back(rp.inlier[i]);
    ++r.num_points;
    if (rp.inlier[i]) {
      ss[o.camera] += e.squaredNorm();
      ss_all += e.squaredNorm();
      r.max_px = std::max(r.max_px, e.norm());
      ++res.num_inliers;
    } else {
      ++r.num_outliers;
      ++res.num_outliers;
    }
  }
  // The observations behind the points, in the same order, for writers that need them
  // (mrcal's optimization_inputs).
  res.observations.clear();
  res.observation_inliers.clear();
  for (size_t i = 0; i < rp.NumPoints(); ++i) {
    if (rp.PointIndex(i) == 0) {
      res.observations.push_back(rp.Observation(i));
      res.observation_inliers.emplace_back();
    }
    res.observation_inliers.back().push_back(rp.inlier[i]);
  }
  for (const BoardObservation& o : ob.obs)
    if (st.rt_rig_board[o.frame]) ++res.residuals[o.camera].num_observations;
  for (int c = 0; c < ncam; ++c) {
    auto& r = res.residuals[c];
    const int n = r.num_points - r.num_outliers;
    r.rms_px = std::sqrt(ss[c] / std::max(1, 2 * n));
    r.rms_point_px = std::sqrt(ss[c] / std::max(1, n));
  }
  res.rms_px = std::sqrt(ss_all / std::max(1, 2 * res.num_inliers));
  res.sum_squared_px2 = ss_all;
  if (options.solve_board_warp) res.board_warp_m = st.warp;
}

// --- Step 6: covariance: inverse normal matrix, boards marginalised (Schur complement)

void ComputeCovariance(RigProblem& rp, const CameraCalibrationOptions& options, CameraCalibrationResult& res) {
  State& st = rp.st;
  const int ncam = static_cast<int>(st.intrinsics.size());
  const int nframes = static_cast<int>(st.rt_rig_board.size());
  ceres::Problem problem(RigProblem::ProblemOptions());
  rp.Build(problem);
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
    blocks.push_back(st.warp.data());
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
  res.num_parameters = na + nb;
  const int dof = 2 * res.num_inliers - na - nb;
  res.residual_variance_px2 = dof > 0 ? res.sum_squared_px2 / dof : std::numeric_limits<double>::quiet_NaN();
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
  // A normal matrix that is singular to working precision (parameters the views do
  // not separate, e.g. the rational model's numerator and denominator on a small
  // board) gives a "covariance" with zero or negative variances: report those
  // parameters' std as infinite, not as zero.
  auto stddev = [](const Eigen::VectorXd& variance) {
    Eigen::VectorXd s(variance.size());
    for (int i = 0; i < variance.size(); ++i)
      s[i] = variance[i] > 0.0 && std::isfinite(variance[i]) ? std::sqrt(variance[i])
                                                             : std::numeric_limits<double>::infinity();
    return s;
  };
  for (int i = 0; i < na; ++i) res.covariance_singular |= !(cov(i, i) > 0.0 && std::isfinite(cov(i, i)));
  // The covariance must be positive definite: the Schur complement, scaled to unit
  // diagonal (its parameters' units differ by orders of magnitude), with no eigenvalue
  // at or below working precision. A solve that went astray (e.g. a board numbered
  // differently by two cameras) can end where it is not, and its "standard deviations"
  // then print as 0 and its projection uncertainties as 0 or 1e6 px.
  if (na > 0 && !res.covariance_singular) {
    const Eigen::VectorXd d = S.diagonal();
    if (!(d.minCoeff() > 0.0) || !d.allFinite()) {
      res.covariance_singular = true;
    } else {
      const Eigen::VectorXd inv_sqrt = d.cwiseSqrt().cwiseInverse();
      const Eigen::MatrixXd Sn = inv_sqrt.asDiagonal() * S * inv_sqrt.asDiagonal();
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Sn, Eigen::EigenvaluesOnly);
      res.covariance_singular = eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 1e-13 * na);
    }
  }
  for (int c = 0; c < ncam; ++c) {
    const int n = static_cast<int>(st.intrinsics[c].size());
    res.intrinsics_covariance.push_back(options.fix_intrinsics ? Eigen::MatrixXd::Zero(n, n)
                                                               : Eigen::MatrixXd(cov.block(cam_offset[c], cam_offset[c], n, n)));
    res.intrinsics_std.push_back(options.fix_intrinsics ? Eigen::VectorXd::Zero(n)
                                                        : stddev(res.intrinsics_covariance.back().diagonal()));
    Vec6 s = Vec6::Zero();
    if (c > 0) s = stddev(cov.block<6, 6>(ext_offset[c], ext_offset[c]).diagonal());
    res.extrinsics_std.push_back(s);
  }
  if (options.solve_board_warp)
    res.board_warp_std_m = stddev(cov.block<2, 2>(warp_offset, warp_offset).diagonal());
}

// The views' noise floor (CameraCalibrationResult::views_alone_variance_px2).
// The board points carry the solved warp (RigProblem's shape over the same extent), so
// that a warped board's views are compared like with like.
double ViewsAloneVariance(const CameraCalibrationResult& res) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const BoardObservation& o : res.observations)
    for (const Vec3& P : o.points_board) lo = lo.cwiseMin(P.head<2>()), hi = hi.cwiseMax(P.head<2>());
  auto warped = [&](Vec3 P) {
    for (int d = 0; d < 2; ++d) {
      const double u = hi[d] > lo[d] ? 2.0 * (P[d] - lo[d]) / (hi[d] - lo[d]) - 1.0 : 0.0;
      P.z() += res.board_warp_m[d] * (1.0 - u * u);
    }
    return P;
  };
  double ss = 0.0;
  int dof = 0;
  for (size_t i = 0; i < res.observations.size(); ++i) {
    const BoardObservation& o = res.observations[i];
    BoardObservation in = o;
    in.points_board.clear();
    in.pixels.clear();
    in.weights.clear();
    for (size_t k = 0; k < o.pixels.size(); ++k)
      if (res.observation_inliers[i][k]) {
        in.points_board.push_back(warped(o.points_board[k]));
        in.pixels.push_back(o.pixels[k]);
        if (!o.weights.empty()) in.weights.push_back(o.weights[k]);
      }
    if (in.pixels.size() < 4) continue;
    const CameraModel& cam = res.rig.cameras[o.camera];
    // The view's own minimum: refined from the joint solution's pose and from the planar
    // solution, the better kept (the planar one alone can end in a far worse minimum on a
    // view of few corners, which raised the floor 20-fold on caliscope's webcams).
    const auto SumSq = [&](const std::optional<Pose>& T) {
      if (!T) return std::numeric_limits<double>::infinity();
      double sum = 0.0;
      for (size_t k = 0; k < in.pixels.size(); ++k) {
        const Vec3 p = *T * in.points_board[k];
        const Vec2 q = cam.Project(p);
        if (!(p.z() > 0.0 && q.allFinite())) return std::numeric_limits<double>::infinity();
        sum += (in.Weight(k) * (q - in.pixels[k])).squaredNorm();
      }
      return sum;
    };
    std::optional<Pose> joint;
    if (o.frame >= 0 && o.frame < static_cast<int>(res.T_rig_board.size()) && res.T_rig_board[o.frame])
      joint = SolveBoardPose(in, cam, cam.T_cam_rig() * *res.T_rig_board[o.frame]);
    const double view = std::min(SumSq(SolveBoardPose(in, cam)), SumSq(joint));
    if (!std::isfinite(view)) continue;
    ss += view;
    dof += 2 * static_cast<int>(in.pixels.size()) - 6;
  }
  return dof > 0 ? ss / dof : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

// One lens model, all steps.
CameraCalibrationResult CalibrateWithLensModel(const CameraCalibrationInput& input,
                                               const CameraCalibrationOptions& options) {
  SupportOf(options.lensmodel);  // InputError for a model that cannot be calibrated here
  const LogFn log = [&](const std::string& s) {
    if (options.log) options.log(s);
  };
  Observations ob = PrepareObservations(input, options);
  CameraCalibrationResult res;
  RigProblem rp(ob, Initialise(input, ob, options, log, res), options);
  SolveWithOutlierRejection(rp, options, log, res);
  CollectSolution(rp, input, ob, options, res);
  ComputeCovariance(rp, options, res);
  res.views_alone_variance_px2 = ViewsAloneVariance(res);
  res.lensmodel = options.lensmodel;
  return res;
}

}  // namespace mcms
