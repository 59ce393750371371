#include "audit/camera_audit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numeric>
#include <set>

#include <ceres/ceres.h>

#include "core/error.h"
#include "core/statistics.h"
#include "audit/model_selection.h"
#include "tracking/pose_refinement.h"
#include "vision/blob_detector.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms {

bool CameraAuditOptions::IsValid(std::string* why) const {
  auto fail = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (folds < 2) return fail("folds must be >= 2");
  if (!(false_alarm > 0 && false_alarm < 0.5)) return fail("false_alarm must be in (0, 0.5)");
  if (!(noise_tolerance >= 0 && noise_tolerance < 1)) return fail("noise_tolerance must be in [0, 1)");
  if (!(undecided_nats >= 0)) return fail("undecided_nats must be >= 0");
  if (max_effects < 1) return fail("max_effects must be >= 1");
  if (change_points < 0) return fail("change_points must be >= 0");
  if (!(gate_px > 0)) return fail("gate_px must be > 0");
  return true;
}

namespace {

// Outline to outline, the reach of another ball's light into a blob's measurement: the
// detector's window margin (its background ring is fitted robustly), the crowding margin of
// the field-of-view prediction (tracking/fov_prediction.h) too.
const double kCrowdedGapPx = BlobDetectorOptions{}.window_margin_px;

bool HasK1(const CameraModel& cam) {
  return cam.LensModelName().rfind("LENSMODEL_OPENCV", 0) == 0 && cam.NumIntrinsics() > 4;
}

Pose ToPose(const PoseT<double>& p) { return Pose{p.R, p.t}; }

// The intrinsics of camera `c` with the named intrinsics effects applied.
void ApplyIntrinsics(const std::vector<CameraModelTerm>& terms, int c, std::vector<double>* in) {
  for (const auto& t : terms)
    if (t.extension.index == c && t.extension.effect != Effect::kTargetGeometry)
      ExtendIntrinsicsT<double>(t.extension, t.parameters.data(), in->data(), static_cast<int>(in->size()));
}

// At time `t`: a camera moved from a change time on has its old pose before it.
CameraRig ExtendRig(const CameraRig& rig, const std::vector<CameraModelTerm>& terms,
                    double t = std::numeric_limits<double>::infinity()) {
  CameraRig out = rig;
  for (size_t c = 0; c < rig.size(); ++c) {
    ApplyIntrinsics(terms, static_cast<int>(c), &out.cameras[c].MutableIntrinsics());
    Pose T_rig_cam = rig.cameras[c].T_cam_rig().Inverse();
    for (const auto& m : terms)
      if (m.extension.effect == Effect::kCameraMoved && m.extension.index == static_cast<int>(c) &&
          t >= m.from_time_s)
        T_rig_cam = ToPose(MovedCameraT<double>(T_rig_cam, m.parameters.data()));
    out.cameras[c].SetT_cam_rig(T_rig_cam.Inverse());
  }
  return out;
}

Target ExtendTarget(const Target& target, const std::vector<CameraModelTerm>& terms) {
  Target out = target;
  for (const auto& t : terms)
    if (t.extension.effect == Effect::kTargetGeometry)
      out.balls_target[t.extension.index] = MovedBallT<double>(target.balls_target[t.extension.index], t.parameters.data());
  return out;
}

struct Obs {
  int camera, ball;
  Vec2 q;  // a late camera's blob moved back by its time offset's shift (see Associate)
  Mat2 cov;
  Vec2 raw;  // the blob as detected
};

struct Frame {
  size_t result;
  double t;
  Pose T;      // the tracker's pose
  // The move to the pose dt later (TimeShiftedPoseT): twist dt + accel dt^2; twist is
  // [omega; v] in the rig frame with v = pdot - omega x p.
  Vec6 twist, accel;
  int block;
  std::vector<double> lag;  // per camera: its exposure time - t (FrameResult::camera_time_s), or 0
};

struct Sample {
  int camera, ball, block;
  double t;
  Pose T;  // leave-one-out pose
  Vec6 twist, accel;
  Vec2 q, bias;
  double lag;  // the camera's exposure time - t (known), before any camera_time_offset
};

// The samples of one unit in one frame, whitened together: they share the error of the
// leave-one-out pose. W = L^-1 for S = L L^T, S = blockdiag(blob covariances) + J C_pose J^T
// (camera units: with the pose part / s_c^2, the whitened residual then divided by s_c;
// ball units: the cameras' s_c^2 built in).
struct Group {
  int begin = 0, n = 0, block = 0;
  int camera = -1;  // camera units: the camera whose s divides the residual; -1: built in
  Eigen::MatrixXd W;
};

struct UnitData {
  std::vector<Sample> s;
  std::vector<Group> g;
  bool empty() const { return s.empty(); }
  size_t size() const { return s.size(); }
};

// Prediction of a sample's ball image through the extension units.
Vec2 Predict(const CameraRig& rig, const Target& target, const Sample& s, const std::vector<CameraModelTerm>& terms,
             CameraModel* cam) {
  const CameraModel& nom = rig.cameras[s.camera];
  std::vector<double>& in = cam->MutableIntrinsics();
  in = nom.Intrinsics();
  Pose T_rig_cam = nom.T_cam_rig().Inverse();
  double dt = s.lag;  // when this camera saw the target, relative to the pose's time
  Vec3 ball = target.balls_target[s.ball];
  for (const auto& term : terms) {
    const Extension& e = term.extension;
    const double* p = term.parameters.data();
    if (e.effect == Effect::kTargetGeometry) {
      if (e.index == s.ball) ball = MovedBallT<double>(target.balls_target[s.ball], p);
      continue;
    }
    if (e.index != s.camera) continue;
    switch (e.effect) {
      case Effect::kCameraMoved:
        if (s.t >= term.from_time_s) T_rig_cam = ToPose(MovedCameraT<double>(T_rig_cam, p));
        break;
      case Effect::kCameraTimeOffset: dt += p[0]; break;
      default: ExtendIntrinsicsT<double>(e, p, in.data(), static_cast<int>(in.size()));
    }
  }
  const Pose T = dt == 0 ? s.T : ToPose(TimeShiftedPoseT<double>(s.T, s.twist, s.accel, &dt));
  const Vec3 p_cam = T_rig_cam.Inverse() * (T * ball);
  return cam->Project(p_cam) + s.bias;
}

// A least-squares solve on one thread, without Ceres' log.
ceres::Solver::Summary SolveSilently(ceres::LinearSolverType solver, int max_iterations, ceres::Problem* problem) {
  ceres::Solver::Options so;
  so.linear_solver_type = solver;
  so.max_num_iterations = max_iterations;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, problem, &summary);
  return summary;
}

// One sample's whitened residual as a function of the free terms' parameter blocks.
struct GroupResidual {
  const CameraRig* rig;
  const Target* target;
  const Sample* s;  // the group's first sample
  const Group* g;
  const std::vector<CameraModelTerm>* terms;
  std::vector<int> free;
  double inv_scale;
  mutable std::vector<CameraModel> cams;
  mutable std::vector<CameraModelTerm> work;
  bool operator()(double const* const* p, double* r) const {
    work = *terms;
    for (size_t k = 0; k < free.size(); ++k) {
      auto& v = work[free[k]].parameters;
      std::copy(p[k], p[k] + v.size(), v.begin());
    }
    Eigen::VectorXd d(2 * g->n);
    for (int i = 0; i < g->n; ++i) d.segment<2>(2 * i) = s[i].q - Predict(*rig, *target, s[i], work, &cams[s[i].camera]);
    const Eigen::VectorXd e = inv_scale * (g->W * d);
    for (int i = 0; i < 2 * g->n; ++i) {
      r[i] = e[i];
      if (!std::isfinite(r[i])) return false;
    }
    return true;
  }
};

// One ball image's whitened residual in the joint fit, as a function of its frame's pose
// (a rotation vector and a translation on the tracker's pose: R = Exp(dr) R0, t = t0 + dt)
// and of the free terms' parameter blocks.
struct JointResidual {
  const CameraRig* rig;
  const Target* target;
  Sample s;  // its pose is the tracker's, T0
  Vec2 q;
  Mat2 W;  // L^-1 of the blob covariance times the camera's s^2
  const std::vector<CameraModelTerm>* terms;
  std::vector<int> free;
  mutable std::vector<CameraModel> cams;
  mutable std::vector<CameraModelTerm> work;
  bool operator()(double const* const* p, double* r) const {
    if (work.empty()) work = *terms;  // the fixed blocks once; the free ones every call
    for (size_t k = 0; k < free.size(); ++k) {
      auto& v = work[free[k]].parameters;
      std::copy(p[k + 1], p[k + 1] + v.size(), v.begin());
    }
    Sample x = s;
    x.T = Pose{ExpSO3(Vec3(p[0][0], p[0][1], p[0][2])) * s.T.R, s.T.t + Vec3(p[0][3], p[0][4], p[0][5])};
    const Vec2 e = W * (q - Predict(*rig, *target, x, work, &cams[x.camera]));
    r[0] = e[0];
    r[1] = e[1];
    return std::isfinite(r[0]) && std::isfinite(r[1]);
  }
};

struct Eval {
  double ll = 0, sq = 0, chi2 = 0;
  long n = 0;  // samples (2 residuals each)
};

// A fitted model of one unit (a camera or a ball): its terms and, for a camera, s.
struct UnitFit {
  std::vector<CameraModelTerm> terms;
  double scale = 1;
};

enum class ScaleMode { kBand, kFree, kFixed };

class Auditor {
 public:
  Auditor(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results,
          const CameraAuditOptions& o)
      : rig_(rig), target_(target), results_(results), o_(o) {
    for (size_t i = 0; i < results.size(); ++i)
      if (results[i].T_rig_target) {
        std::vector<double> lag(rig.size(), 0.0);
        const std::vector<double>& tc = results[i].camera_time_s;
        for (size_t c = 0; c < lag.size() && c < tc.size(); ++c)
          if (std::isfinite(tc[c])) lag[c] = tc[c] - results[i].time_s;
        frames_.push_back(
            {i, results[i].time_s, *results[i].T_rig_target, Vec6::Zero(), Vec6::Zero(), 0, std::move(lag)});
      }
    std::sort(frames_.begin(), frames_.end(), [](const Frame& a, const Frame& b) { return a.t < b.t; });
    std::vector<double> dts;
    for (size_t i = 1; i < frames_.size(); ++i) dts.push_back(frames_[i].t - frames_[i - 1].t);
    double med = 0;
    if (!dts.empty()) med = SelectedMedian(dts);
    for (size_t i = 0; i < frames_.size(); ++i) {
      frames_[i].block = TimeBlockFold(static_cast<long>(i), static_cast<long>(frames_.size()), o.folds);
      size_t a = i, b = i;
      if (i > 0 && frames_[i].t - frames_[i - 1].t <= 3 * med) a = i - 1;
      if (i + 1 < frames_.size() && frames_[i + 1].t - frames_[i].t <= 3 * med) b = i + 1;
      if (a == b || !(frames_[b].t > frames_[a].t)) continue;
      // The moves x = [phi; u] (MovedCameraT) that take this frame's pose to its
      // neighbours', and the quadratic x(dt) = twist dt + accel dt^2 through them and 0
      // (a line where there is one neighbour).
      const Frame& f = frames_[i];
      auto move_to = [&f](const Frame& g) {
        const Mat3 dR = g.T.R * f.T.R.transpose();
        Vec6 x;
        x << LogSO3(dR), g.T.t - dR * f.T.t;
        return x;
      };
      if (a < i && b > i) {
        const double ha = f.t - frames_[a].t, hb = frames_[b].t - f.t;
        const Vec6 xa = move_to(frames_[a]), xb = move_to(frames_[b]);
        const double d = ha * hb * (ha + hb);
        frames_[i].twist = (ha * ha * xb - hb * hb * xa) / d;
        frames_[i].accel = (ha * xb + hb * xa) / d;
      } else {
        const Frame& g = frames_[a < i ? a : b];
        frames_[i].twist = move_to(g) / (g.t - f.t);
      }
    }
  }

  size_t NumFrames() const { return frames_.size(); }
  const UnitData& CameraSamples(int c) const { return cam_samples_[c]; }
  const UnitData& BallSamples(int b) const { return ball_samples_[b]; }

  // The pose at which camera c saw frame f's target: moved along the frame's motion by the
  // camera's known exposure lag and its fitted time offset (camera_time_offset).
  static Pose ViewPose(const Frame& f, int c, const std::vector<CameraModelTerm>& terms) {
    double dt = f.lag[c];
    for (const auto& t : terms)
      if (t.extension.effect == Effect::kCameraTimeOffset && t.extension.index == c) dt += t.parameters[0];
    return dt == 0 ? f.T : ToPose(TimeShiftedPoseT<double>(f.T, f.twist, f.accel, &dt));
  }

  // Every camera's blobs of one frame associated with the balls under the model (rig_x,
  // target_x: extended by `terms` at the frame's time).
  std::vector<Obs> Associate(const Frame& f, const CameraRig& rig_x, const Target& target_x,
                             const std::vector<CameraModelTerm>& terms) const {
    const FrameResult& r = results_[f.result];
    const int nc = static_cast<int>(rig_.size()), nb = static_cast<int>(target_.balls_target.size());
    std::vector<Obs> obs;
    for (int c = 0; c < nc && c < static_cast<int>(r.image_points.size()); ++c) {
      const CameraModel& cam = rig_x.cameras[c];
      // A late camera's images (its known exposure lag, its fitted time offset): predicted
      // at the shifted pose; its blobs are moved back by the difference so that the other
      // cameras' poses are not pulled.
      const Pose T_c = ViewPose(f, c, terms);
      const auto& blobs = r.image_points[c];
      std::vector<bool> used(blobs.size(), false);
      // A ball whose image another ball's crowds may be hidden in part, merged with it or
      // lit by it inside its measurement window and ring: its centre is the detector's
      // limit, not a test of the camera model.
      const std::vector<bool> crowded = CrowdedBallImages(cam, target_x, f.T, kCrowdedGapPx);
      for (int b = 0; b < nb; ++b) {
        const Vec3 p_cam = cam.T_cam_rig() * (f.T * target_x.balls_target[b]);
        if (crowded[b] || !cam.Sees(p_cam, 10)) continue;
        const Vec3 p_cam_c = cam.T_cam_rig() * (T_c * target_x.balls_target[b]);
        const Vec2 q0 = cam.Project(p_cam);
        const Vec2 q = cam.Project(p_cam_c) + SphereProjectionBias(cam, p_cam_c, target_x.ball_radius, 32);
        const int best = ClaimNearest(blobs, q, o_.gate_px, &used);
        if (best < 0) continue;
        obs.push_back({c, b, blobs[best].q - (cam.Project(p_cam_c) - q0), blobs[best].cov, blobs[best].q});
      }
    }
    return obs;
  }

  // The joint fit (a bundle adjustment of the rig's model): every frame's pose and the
  // terms' parameters (all but the noise scales, which stay as given) fitted together to
  // every ball image, each whitened by its blob covariance times its camera's s^2; the
  // ball images associated under the terms as given. Returns the log-likelihood (up to a
  // constant) and leaves the fitted parameters in *terms. It is what a change to one
  // camera is judged by: unlike the leave-one-out residuals, where a camera's fault pulls
  // the poses its neighbours are tested against (and a neighbour made to agree with the
  // pulled poses also lowers the faulty camera's residuals), a fault here costs what it
  // costs once, and only its own correction removes all of it; and unlike the units' fits
  // on leave-one-out poses, whose optimum is not the joint one, every term is refitted
  // beside every other.
  // *sigma (optional) receives each term's parameter sigmas (the noise scales' empty), the
  // poses marginalised (the covariance of the whole fit, inverted).
  // *state (optional): the frames' poses to start from (when it holds one per frame) and,
  // on return, the poses reached with each camera's chi-square at unit noise scale and its
  // number of ball images (what the camera's scale is refitted from).
  struct JointState {
    std::vector<std::array<double, 6>> pose;
    std::vector<double> chi2;  // per camera, whitened by the blob covariances alone
    std::vector<long> n;       // ball images per camera
  };
  double JointFit(std::vector<CameraModelTerm>* terms_io, const std::vector<double>& scale,
                  std::vector<std::vector<double>>* sigma = nullptr, JointState* state = nullptr) const {
    std::vector<CameraModelTerm>& terms = *terms_io;
    const Target target_x = ExtendTarget(target_, terms);
    std::vector<int> free;
    for (size_t k = 0; k < terms.size(); ++k)
      if (terms[k].extension.effect != Effect::kPixelNoiseScale) free.push_back(static_cast<int>(k));
    const std::vector<CameraModelTerm> frozen = terms;  // the functors' copy; free blocks overwrite
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    std::vector<std::array<double, 6>> pose(frames_.size(), std::array<double, 6>{});
    if (state && state->pose.size() == frames_.size()) pose = state->pose;
    std::vector<bool> used(frames_.size(), false);
    std::vector<std::pair<ceres::ResidualBlockId, int>> block_camera;
    double log_scales = 0;
    for (size_t i = 0; i < frames_.size(); ++i) {
      const Frame& f = frames_[i];
      const CameraRig rig_x = ExtendRig(rig_, terms, f.t);
      const std::vector<Obs> obs = Associate(f, rig_x, target_x, terms);
      std::set<int> balls;
      for (const Obs& x : obs) balls.insert(x.ball);
      if (balls.size() < 3) continue;
      used[i] = true;
      for (const Obs& x : obs) {
        const CameraModel& cam = rig_x.cameras[x.camera];
        const Vec3 p_cam = cam.T_cam_rig() * (f.T * target_x.balls_target[x.ball]);
        const Mat2 L = Mat2(x.cov * scale[x.camera] * scale[x.camera]).llt().matrixL();
        const Sample at{x.camera, x.ball, f.block, f.t, f.T, f.twist, f.accel, x.raw,
                        SphereProjectionBias(cam, p_cam, target_x.ball_radius, 32), f.lag[x.camera]};
        auto* r = new JointResidual{&rig_, &target_, at, x.raw, L.inverse(), &frozen, free, rig_.cameras, {}};
        auto* cost = new ceres::DynamicNumericDiffCostFunction<JointResidual, ceres::CENTRAL>(r);
        std::vector<double*> blocks{pose[i].data()};
        cost->AddParameterBlock(6);
        for (int k : free) {
          cost->AddParameterBlock(static_cast<int>(terms[k].parameters.size()));
          blocks.push_back(terms[k].parameters.data());
        }
        cost->SetNumResiduals(2);
        block_camera.emplace_back(problem.AddResidualBlock(cost, nullptr, blocks), x.camera);
        log_scales += 2 * std::log(scale[x.camera]);
      }
    }
    if (problem.NumResidualBlocks() == 0) return 0;
    const ceres::Solver::Summary summary = SolveSilently(ceres::DENSE_SCHUR, 50, &problem);
    if (state) {
      state->pose = pose;
      state->chi2.assign(rig_.size(), 0.0);
      state->n.assign(rig_.size(), 0);
      for (const auto& [id, c] : block_camera) {
        double cost = 0;
        problem.EvaluateResidualBlock(id, false, &cost, nullptr, nullptr);
        state->chi2[c] += 2 * cost * scale[c] * scale[c];
        ++state->n[c];
      }
    }
    if (sigma) {
      // The terms' covariance with the poses marginalised: the inverse of the Schur
      // complement of the information matrix, the poses eliminated frame by frame (each
      // ball image touches one pose; a dense inverse of the whole would cost the cube of
      // six times the frames).
      sigma->assign(terms.size(), {});
      std::vector<double*> order;
      for (size_t i = 0; i < frames_.size(); ++i)
        if (used[i]) order.push_back(pose[i].data());
      const int np = 6 * static_cast<int>(order.size());
      int nf = 0;
      for (int k : free) {
        order.push_back(terms[k].parameters.data());
        nf += static_cast<int>(terms[k].parameters.size());
      }
      ceres::Problem::EvaluateOptions eo;
      eo.parameter_blocks = order;
      ceres::CRSMatrix J;
      problem.Evaluate(eo, nullptr, nullptr, nullptr, &J);
      Eigen::MatrixXd Hff = Eigen::MatrixXd::Zero(nf, nf);
      std::vector<Mat6> Hee(np / 6, Mat6::Zero());
      std::vector<Eigen::MatrixXd> Hfe(np / 6, Eigen::MatrixXd::Zero(nf, 6));
      Eigen::VectorXd jf(nf);
      for (int r = 0; r < J.num_rows; ++r) {
        Vec6 je = Vec6::Zero();
        jf.setZero();
        int pose_of = -1;
        for (int i = J.rows[r]; i < J.rows[r + 1]; ++i) {
          const int c = J.cols[i];
          if (c < np) {
            pose_of = c / 6;
            je[c % 6] = J.values[i];
          } else {
            jf[c - np] = J.values[i];
          }
        }
        Hff += jf * jf.transpose();
        if (pose_of >= 0) {
          Hee[pose_of] += je * je.transpose();
          Hfe[pose_of] += jf * je.transpose();
        }
      }
      for (size_t i = 0; i < Hee.size(); ++i) Hff -= Hfe[i] * Hee[i].ldlt().solve(Hfe[i].transpose());
      // A term the images do not constrain gets an infinite sigma, not a rounding residue.
      const Eigen::VectorXd s = MarginalSigmas(Hff);
      int j = 0;
      for (int k : free)
        for (size_t i = 0; i < terms[k].parameters.size(); ++i, ++j) (*sigma)[k].push_back(s[j]);
    }
    return -summary.final_cost - log_scales;  // final_cost = chi2 / 2
  }

  // The joint fit with camera `camera`'s noise scale refitted too (mode: free, within the
  // band, or fixed), alternating the least squares and the scale's closed form
  // s^2 = chi2 / (2 n), from *state's poses: every step raises the likelihood, so a model
  // started at the solution of the one it contains never ends below it. *scale_io holds
  // the scale used on return.
  double JointFitWithScale(std::vector<CameraModelTerm>* terms_io, std::vector<double>* scale_io, int camera,
                           ScaleMode mode, JointState* state) const {
    double ll = JointFit(terms_io, *scale_io, nullptr, state);
    if (camera < 0 || mode == ScaleMode::kFixed) return ll;
    for (int it = 0; it < 8; ++it) {
      const double chi2 = state->chi2[camera];
      const long n = state->n[camera];
      if (n == 0) break;
      double s = std::sqrt(chi2 / (2.0 * n));
      if (mode == ScaleMode::kBand) s = std::clamp(s, 1.0 / (1.0 + o_.noise_tolerance), 1.0 + o_.noise_tolerance);
      const double s0 = (*scale_io)[camera];
      // The likelihood at the same poses and terms with the new scale, in closed form.
      const double ll_s = ll + 0.5 * chi2 * (1 / (s0 * s0) - 1 / (s * s)) - 2.0 * n * std::log(s / s0);
      if (!(ll_s > ll + 1e-9 * std::max(1.0, std::abs(ll)))) break;
      (*scale_io)[camera] = s;
      std::vector<CameraModelTerm> t = *terms_io;
      JointState st = *state;
      const double ll_next = JointFit(&t, *scale_io, nullptr, &st);
      if (!(ll_next >= ll_s)) return ll_s;  // the least squares lost its start: the scale step alone
      *terms_io = std::move(t);
      *state = std::move(st);
      ll = ll_next;
    }
    return ll;
  }

  // Associates every camera's blobs with the balls and re-fits the leave-one-out poses
  // under the model (terms, per-camera noise scales).
  void Rebuild(const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale) {
    const Target target_x = ExtendTarget(target_, terms);
    const int nc = static_cast<int>(rig_.size()), nb = static_cast<int>(target_.balls_target.size());
    cam_samples_.assign(nc, {});
    ball_samples_.assign(nb, {});
    PoseRefinementOptions po;
    po.outlier_sigma = 1e9;
    for (const Frame& f : frames_) {
      const CameraRig rig_x = ExtendRig(rig_, terms, f.t);
      const std::vector<Obs> obs = Associate(f, rig_x, target_x, terms);
      // Leave one camera out, then one ball out.
      for (int pass = 0; pass < 2; ++pass) {
        const int units = pass == 0 ? nc : nb;
        for (int u = 0; u < units; ++u) {
          std::vector<BallObservation> others;
          std::set<int> balls;
          bool any = false;
          for (const Obs& x : obs) {
            const bool out = pass == 0 ? x.camera == u : x.ball == u;
            if (out) {
              any = true;
              continue;
            }
            others.push_back({x.camera, x.ball, x.q, x.cov * scale[x.camera] * scale[x.camera]});
            balls.insert(x.ball);
          }
          if (!any || balls.size() < 3) continue;
          const PoseRefinement pr = RefinePose(rig_x, target_x, f.T, others, po);
          UnitData& ud = pass == 0 ? cam_samples_[u] : ball_samples_[u];
          Group grp;
          grp.begin = static_cast<int>(ud.s.size());
          grp.block = f.block;
          grp.camera = pass == 0 ? u : -1;
          std::vector<Mat2> blob;
          std::vector<Eigen::Matrix<double, 2, 6>> Js;
          for (const Obs& x : obs) {
            if ((pass == 0 ? x.camera : x.ball) != u) continue;
            // Undo this camera's own lag and time-offset correction: its prediction applies it.
            const CameraModel& cam = rig_x.cameras[x.camera];
            const Vec2 q = x.raw;
            const Vec3 p_cam = cam.T_cam_rig() * (pr.T_rig_target * target_x.balls_target[x.ball]);
            Eigen::Matrix<double, 2, 3> dq;
            cam.Project(p_cam, &dq);
            Eigen::Matrix<double, 3, 6> dp;
            dp.leftCols<3>() = -Skew(pr.T_rig_target.R * target_x.balls_target[x.ball]);
            dp.rightCols<3>() = Mat3::Identity();
            const Eigen::Matrix<double, 2, 6> J = dq * cam.T_cam_rig().R * dp;
            const double s2 = scale[x.camera] * scale[x.camera];
            blob.push_back(pass == 0 ? x.cov : Mat2(x.cov * s2));
            Js.push_back(pass == 0 ? Eigen::Matrix<double, 2, 6>(J / scale[x.camera]) : J);
            ud.s.push_back({x.camera, x.ball, f.block, f.t, pr.T_rig_target, f.twist, f.accel, q,
                            SphereProjectionBias(cam, p_cam, target_x.ball_radius, 32), f.lag[x.camera]});
          }
          grp.n = static_cast<int>(blob.size());
          Eigen::MatrixXd S = Eigen::MatrixXd::Zero(2 * grp.n, 2 * grp.n);
          Eigen::MatrixXd Jall(2 * grp.n, 6);
          for (int i = 0; i < grp.n; ++i) {
            S.block<2, 2>(2 * i, 2 * i) = blob[i];
            Jall.middleRows<2>(2 * i) = Js[i];
          }
          S += Jall * pr.cov * Jall.transpose();
          const Eigen::LLT<Eigen::MatrixXd> llt(S);
          grp.W = llt.matrixL().solve(Eigen::MatrixXd::Identity(2 * grp.n, 2 * grp.n));
          ud.g.push_back(std::move(grp));
        }
      }
    }
  }

  // Log-likelihood (up to a constant) of the samples outside (fold < 0: all) or inside
  // block `fold` (inside = true), and the raw squared residuals (px^2).
  Eval Evaluate(const UnitData& u, const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
                int fold, bool inside) const {
    Eval e;
    std::vector<CameraModel> cams = rig_.cameras;
    for (const Group& g : u.g) {
      if (fold >= 0 && (g.block == fold) != inside) continue;
      Eigen::VectorXd d(2 * g.n);
      for (int i = 0; i < g.n; ++i) {
        const Sample& x = u.s[g.begin + i];
        d.segment<2>(2 * i) = x.q - Predict(rig_, target_, x, terms, &cams[x.camera]);
        e.sq += d.segment<2>(2 * i).squaredNorm();
      }
      const double sc = g.camera >= 0 ? scale[g.camera] : 1.0;
      const double c2 = (g.W * d).squaredNorm() / (sc * sc);
      e.chi2 += c2;
      e.ll += -0.5 * c2 - 2 * g.n * std::log(sc);
      e.n += g.n;
    }
    return e;
  }

  // The whitened residuals of a unit's samples (under the model: i.i.d. N(0, 1), in time
  // order), each with the covariates it may depend on.
  std::vector<WhitenedResidual> Whitened(const UnitData& u, const std::vector<CameraModelTerm>& terms,
                                         const std::vector<double>& scale) const {
    std::vector<WhitenedResidual> out;
    std::vector<CameraModel> cams = rig_.cameras;
    for (const Group& g : u.g) {
      Eigen::VectorXd d(2 * g.n);
      std::vector<Vec2> q(g.n);
      for (int i = 0; i < g.n; ++i) {
        const Sample& x = u.s[g.begin + i];
        q[i] = Predict(rig_, target_, x, terms, &cams[x.camera]);
        d.segment<2>(2 * i) = x.q - q[i];
      }
      const double sc = g.camera >= 0 ? scale[g.camera] : 1.0;
      const Eigen::VectorXd w = g.W * d / sc;
      for (int i = 0; i < g.n; ++i) {
        const Sample& x = u.s[g.begin + i];
        const CameraModel& cam = rig_.cameras[x.camera];
        WhitenedResidual r;
        r.camera = x.camera;
        r.ball = x.ball;
        r.time_s = x.t;
        r.q = q[i];
        r.w = w.segment<2>(2 * i);
        r.range_m = (cam.T_cam_rig() * (x.T * target_.balls_target[x.ball])).norm();
        r.radius_px = (q[i] - Vec2(0.5 * (cam.Width() - 1), 0.5 * (cam.Height() - 1))).norm();
        out.push_back(r);
      }
    }
    return out;
  }

  // Fits the terms `free` (indices into terms) of a unit on its samples outside block
  // `fold` (-1: all): Ceres least squares, then the camera's noise scale (camera units) by
  // maximum likelihood, free or within the tolerance band. *sigma (optional) receives the
  // free parameters' sigmas, in order (MarginalSigmas: infinite where unconstrained).
  UnitFit Fit(const UnitData& s, int camera, std::vector<CameraModelTerm> terms,
              const std::vector<int>& free, std::vector<double> scale, ScaleMode mode, int fold,
              Eigen::VectorXd* sigma = nullptr) const {
    std::vector<int> geo;
    for (int k : free)
      if (terms[k].extension.effect != Effect::kPixelNoiseScale) geo.push_back(k);
    if (!geo.empty()) {
      ceres::Problem::Options po;
      po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
      ceres::Problem problem(po);
      std::vector<double*> blocks;
      for (int k : geo) blocks.push_back(terms[k].parameters.data());
      std::vector<CameraModelTerm> frozen = terms;  // the functors' copy; free blocks overwrite
      for (const Group& g : s.g) {
        if (fold >= 0 && g.block == fold) continue;
        const Sample& x = s.s[g.begin];
        auto* f = new GroupResidual{&rig_, &target_, &x, &g, &frozen, geo, 1.0, rig_.cameras, {}};
        auto* cost = new ceres::DynamicNumericDiffCostFunction<GroupResidual, ceres::CENTRAL>(f);
        for (int k : geo) cost->AddParameterBlock(static_cast<int>(terms[k].parameters.size()));
        cost->SetNumResiduals(2 * g.n);
        problem.AddResidualBlock(cost, nullptr, blocks);
      }
      if (problem.NumResidualBlocks() > 0) {
        SolveSilently(ceres::DENSE_QR, 30, &problem);
        if (sigma) {
          ceres::Problem::EvaluateOptions eo;
          eo.parameter_blocks = blocks;
          ceres::CRSMatrix crs;
          problem.Evaluate(eo, nullptr, nullptr, nullptr, &crs);
          Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
          for (int r = 0; r < crs.num_rows; ++r)
            for (int i = crs.rows[r]; i < crs.rows[r + 1]; ++i) J(r, crs.cols[i]) = crs.values[i];
          *sigma = MarginalSigmas(J.transpose() * J);
        }
      }
    }
    UnitFit out;
    if (camera >= 0) {
      scale[camera] = 1.0;
      const Eval e = Evaluate(s, terms, scale, fold, false);
      double sc = e.n > 0 ? std::sqrt(e.chi2 / (2.0 * e.n)) : 1.0;
      if (mode == ScaleMode::kBand) sc = std::clamp(sc, 1.0 / (1.0 + o_.noise_tolerance), 1.0 + o_.noise_tolerance);
      if (mode == ScaleMode::kFixed) sc = 1.0;
      out.scale = sc;
      if (sigma) *sigma *= sc;
      for (int k : free)
        if (terms[k].extension.effect == Effect::kPixelNoiseScale) terms[k].parameters[0] = sc;
    }
    out.terms = std::move(terms);
    return out;
  }

  const CameraRig& rig_;
  const Target& target_;
  const std::vector<FrameResult>& results_;
  const CameraAuditOptions& o_;
  std::vector<Frame> frames_;
  std::vector<UnitData> cam_samples_, ball_samples_;
};

struct Candidate {
  CameraModelTerm term;
  bool camera_unit = true;
  int unit = 0;
  int k = 0;           // parameters it adds (a change time counts as one)
  bool step = false;   // camera_moved from a change time on
  bool pair = false;   // two intrinsic effects of one camera at once: term and term2
  CameraModelTerm term2;
  double lr = 0, bic_gain = 0, heldout_gain = 0, rms_before = 0, rms_after = 0, p_value = 1;
  double base_ll = 0;  // the log-likelihood of the model it extends (issue 51: lr >= 0)
  bool eligible = false;
  std::vector<CameraModelTerm> fitted;  // the unit's terms fitted on all data
  double scale = 1;
  std::vector<double> sigma;            // of the candidate's parameters
  std::string label;
};


}  // namespace

CameraRig CameraAuditResult::ExtendedRig(const CameraRig& rig) const { return ExtendRig(rig, terms); }
Target CameraAuditResult::ExtendedTarget(const Target& target) const { return ExtendTarget(target, terms); }
bool CameraAuditResult::ChangesRig() const {
  for (const auto& t : terms)
    if (t.extension.effect != Effect::kPixelNoiseScale && t.extension.effect != Effect::kCameraTimeOffset &&
        t.extension.effect != Effect::kTargetGeometry)
      return true;
  return false;
}

namespace {

// The residual tests of a model (terms, per-camera noise scales) on the leave-one-out
// residuals the auditor holds: each camera's chi-square, allowing the noise tolerance,
// two-sided (a noise model too pessimistic is also wrong), at alpha / (4 cameras); and each
// camera's whitened residuals (u, v) against time (lag-1 autocorrelation, trend), the
// position in the view (u, v, distance from the image centre) and the distance to the
// camera, Bonferroni over their number at alpha / 4: an effect the catalog lacks shows
// here first. All tests into *tests (the residual tests sorted by p), a line for the notes
// into *note, the whitened residuals into *residuals (optional); returns the number of
// scalar residuals and their chi-square (*chi2_total).
long TestModel(const Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
               const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
               std::vector<AuditTest>* tests_out, std::string* note, std::vector<std::string>* unaudited,
               double* chi2_total, std::vector<std::vector<WhitenedResidual>>* residuals = nullptr) {
  const int nc = static_cast<int>(rig.size());
  long n_total = 0;
  *chi2_total = 0;
  const double tol2 = (1 + options.noise_tolerance) * (1 + options.noise_tolerance);
  for (int c = 0; c < nc; ++c) {
    const Eval e = a.Evaluate(a.CameraSamples(c), terms, scale, -1, false);
    n_total += 2 * e.n;
    *chi2_total += e.chi2;
    if (e.n == 0) {
      unaudited->push_back(rig.names[c] + ": no ball image predicted from the other cameras; not audited");
      continue;
    }
    const double dof = 2.0 * e.n;
    const double p_hi = ChiSquareSurvival(e.chi2 / tol2, dof);
    const double p_lo = ChiSquareCdf(e.chi2 * tol2, dof);
    const double p = std::min(1.0, 2 * std::min(p_hi, p_lo));
    tests_out->push_back({"chi-square of " + rig.names[c] + "'s leave-one-out residuals (chi2/dof, noise tolerance " +
                              std::to_string(static_cast<int>(std::lround(100 * options.noise_tolerance))) + " %)",
                          e.chi2 / dof, p, p < options.false_alarm / (4.0 * nc)});
  }
  std::vector<AuditTest> tests;
  for (int c = 0; c < nc; ++c) {
    if (a.CameraSamples(c).empty()) continue;
    const std::vector<WhitenedResidual> rs = a.Whitened(a.CameraSamples(c), terms, scale);
    std::vector<double> cov[5];
    const char* cov_name[5] = {"time", "image u", "image v", "distance from the image centre", "distance to the camera"};
    for (const auto& r : rs) {
      cov[0].push_back(r.time_s);
      cov[1].push_back(r.q.x());
      cov[2].push_back(r.q.y());
      cov[3].push_back(r.radius_px);
      cov[4].push_back(r.range_m);
    }
    for (int k = 0; k < 2; ++k) {
      std::vector<double> w;
      for (const auto& r : rs) w.push_back(r.w[k]);
      const std::string comp = k == 0 ? "u" : "v";
      tests.push_back(AutocorrelationTest(rig.names[c] + ": autocorrelation in time (" + comp + ")", w));
      for (int j = 0; j < 5; ++j)
        if (auto t = TrendTest(rig.names[c] + ": trend vs " + cov_name[j] + " (" + comp + ")", cov[j], w))
          tests.push_back(*t);
    }
    if (residuals) (*residuals)[c] = rs;
  }
  const double per = options.false_alarm / 4 / std::max<size_t>(1, tests.size());
  for (auto& t : tests) t.failed = t.p_value < per;
  std::stable_sort(tests.begin(), tests.end(),
                   [](const AuditTest& x, const AuditTest& y) { return x.p_value < y.p_value; });
  tests_out->insert(tests_out->end(), tests.begin(), tests.end());
  char b[200];
  std::snprintf(b, sizeof b, "%zu residual tests against time, the position in the view and the distance (each at %.3g)",
                tests.size(), per);
  *note = b;
  return n_total;
}

// The nominal model's tests, into res->report.tests (the failed ones and the three
// strongest residual tests besides) and res->residuals; returns the number of scalar
// residuals.
long TestNominalModel(Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
                      const std::vector<CameraModelTerm>& terms, CameraAuditResult* res_out) {
  CameraAuditResult& res = *res_out;
  AuditReport& rep = res.report;
  const int nc = static_cast<int>(rig.size());
  std::vector<AuditTest> tests;
  std::string note;
  double chi2_total = 0;
  const long n_total = TestModel(a, rig, options, terms, std::vector<double>(nc, 1.0), &tests, &note, &rep.notes,
                                 &chi2_total, &res.residuals);
  int shown = 0;
  for (const auto& t : tests)
    if (t.failed || t.name.rfind("chi-square", 0) == 0 || shown++ < 3) rep.tests.push_back(t);
  rep.notes.push_back(note);
  rep.nominal_n = n_total;
  rep.nominal_chi2_per_dof = n_total > 0 ? chi2_total / n_total : 0.0;
  if (n_total == 0) Throw("audit cameras: no ball image could be predicted from the other cameras");
  return n_total;
}

// The noise model first: each camera's scale, fitted within the tolerance band.
void FitNoiseScales(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options,
                    const std::vector<CameraModelTerm>& terms, std::vector<double>* scale_out, AuditReport* rep_out) {
  std::vector<double>& scale = *scale_out;
  AuditReport& rep = *rep_out;
  const int nc = static_cast<int>(rig.size());
  for (int c = 0; c < nc; ++c) {
    const auto& s = a.CameraSamples(c);
    if (s.empty()) continue;
    scale[c] = a.Fit(s, c, terms, {}, scale, ScaleMode::kBand, -1).scale;
    const UnitFit f = a.Fit(s, c, terms, {}, scale, ScaleMode::kFree, -1);
    std::vector<double> sc = scale;
    sc[c] = f.scale;
    const double lr = 2 * (a.Evaluate(s, terms, sc, -1, false).ll - a.Evaluate(s, terms, scale, -1, false).ll);
    rep.tests.push_back({"pixel noise scale of " + rig.names[c] + " (estimated factor on sigma; p against the band)",
                         f.scale, ChiSquareSurvival(lr, 1),
                         ChiSquareSurvival(lr, 1) < options.false_alarm / (2.0 * (7 * nc + nb))});
  }

}

// The indices of the terms of one unit (a camera: every effect but target_geometry at it;
// a ball: its target_geometry).
std::vector<int> UnitTerms(const std::vector<CameraModelTerm>& terms, bool cam_unit, int u) {
  std::vector<int> f;
  for (size_t k = 0; k < terms.size(); ++k)
    if ((terms[k].extension.effect != Effect::kTargetGeometry) == cam_unit && terms[k].extension.index == u)
      f.push_back(static_cast<int>(k));
  return f;
}

// How a unit's fit treats the camera's noise scale: free once named, else within the band;
// a ball unit has none.
ScaleMode UnitScaleMode(bool cam_unit, int u, const std::vector<bool>& noise_named) {
  if (!cam_unit) return ScaleMode::kFixed;
  return noise_named[u] ? ScaleMode::kFree : ScaleMode::kBand;
}

// Held-out evaluation of a unit's model (the terms `free` of `terms` fitted): each fold of
// time fitted on the others and evaluated on it, summed over the folds.
Eval CameraHeldOut(const Auditor& a, const CameraAuditOptions& options, bool cam_unit, int u,
             const std::vector<CameraModelTerm>& terms, const std::vector<int>& free, const std::vector<double>& scale,
             ScaleMode mode) {
  const auto& s = cam_unit ? a.CameraSamples(u) : a.BallSamples(u);
  Eval out;
  for (int f = 0; f < options.folds; ++f) {
    const UnitFit fit = a.Fit(s, cam_unit ? u : -1, terms, free, scale, mode, f);
    std::vector<double> sc = scale;
    if (cam_unit) sc[u] = fit.scale;
    const Eval e = a.Evaluate(s, fit.terms, sc, f, true);
    out.ll += e.ll;
    out.sq += e.sq;
    out.n += e.n;
  }
  return out;
}

// The candidates of one selection round, each fitted on all data and on the folds, with
// its likelihood ratio and held-out gain against its unit's current model; *tested
// receives the number of single candidates (the pairs fitted count on top of it).
std::vector<Candidate> RoundCandidates(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options,
                                       const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
                                       const std::set<std::pair<bool, int>>& blocked,
                                       const std::vector<bool>& noise_named, int* tested) {
  const int nc = static_cast<int>(rig.size());
  // The candidates.
  std::vector<Candidate> cands, pairs;
  auto has = [&](Effect e, int idx) {
    for (const auto& t : terms)
      if (t.extension.effect == e && t.extension.index == idx) return true;
    return false;
  };
  for (int c = 0; c < nc; ++c) {
    if (blocked.count({true, c}) || a.CameraSamples(c).empty()) continue;
    for (Effect e : {Effect::kPixelNoiseScale, Effect::kCameraMoved, Effect::kFocalLength, Effect::kPrincipalPoint,
                     Effect::kRadialDistortion, Effect::kCameraTimeOffset}) {
      if (has(e, c)) continue;
      if (e == Effect::kRadialDistortion && !HasK1(rig.cameras[c])) continue;
      Candidate x;
      x.term.extension = Extension{e, c, 0};
      x.term.parameters = x.term.extension.InitialParameters();
      x.unit = c;
      x.k = x.term.extension.NumParameters();
      cands.push_back(x);
      if (e == Effect::kCameraMoved && options.change_points > 0) {
        x.k += 1;
        x.step = true;  // the change time is scanned below
        cands.push_back(x);
      }
    }
    // Two effects of the camera's own at once: a camera whose focal length and principal
    // point (or any two of these) are both off is fitted by a 6-parameter move better than
    // by either alone; the pair, with fewer parameters than the move, is its own candidate.
    // A moved camera that is also late: a principal point and a time offset otherwise fit
    // it better than the move alone (a move with a principal point or a focal length is
    // not a pair: the move takes them up).
    const Effect own[] = {Effect::kCameraMoved, Effect::kFocalLength, Effect::kPrincipalPoint,
                          Effect::kRadialDistortion, Effect::kCameraTimeOffset};
    for (size_t i = 0; i < 5; ++i)
      for (size_t j = i + 1; j < 5; ++j) {
        const Effect e1 = own[i], e2 = own[j];
        if (e1 == Effect::kCameraMoved && e2 != Effect::kCameraTimeOffset) continue;
        if (has(e1, c) || has(e2, c)) continue;
        if ((e1 == Effect::kRadialDistortion || e2 == Effect::kRadialDistortion) && !HasK1(rig.cameras[c])) continue;
        Candidate x;
        x.term.extension = Extension{e1, c, 0};
        x.term.parameters = x.term.extension.InitialParameters();
        x.term2.extension = Extension{e2, c, 0};
        x.term2.parameters = x.term2.extension.InitialParameters();
        x.pair = true;
        x.unit = c;
        x.k = x.term.extension.NumParameters() + x.term2.extension.NumParameters();
        pairs.push_back(x);
      }
  }
  for (int b = 0; b < nb; ++b) {
    if (blocked.count({false, b}) || has(Effect::kTargetGeometry, b) || a.BallSamples(b).empty()) continue;
    Candidate x;
    x.term.extension = Extension{Effect::kTargetGeometry, b, 0};
    x.term.parameters = x.term.extension.InitialParameters();
    x.camera_unit = false;
    x.unit = b;
    x.k = 3;
    cands.push_back(x);
  }
  *tested = static_cast<int>(cands.size());
  if (cands.empty()) return cands;

  // The current model of each unit, fitted on all data and on each fold, once.
  auto unit_free = [&](bool cam_unit, int u) { return UnitTerms(terms, cam_unit, u); };
  auto mode_of = [&](bool cam_unit, int u) { return UnitScaleMode(cam_unit, u, noise_named); };
  // Held-out evaluation of a unit model `t_all` with its free terms `free`: sum over folds.
  auto heldout = [&](bool cam_unit, int u, const std::vector<CameraModelTerm>& t0, const std::vector<int>& free,
                     ScaleMode mode, double* ll, double* sq, long* n) {
    const Eval e = CameraHeldOut(a, options, cam_unit, u, t0, free, scale, mode);
    *ll = e.ll;
    *sq = e.sq;
    *n = e.n;
  };
  struct Base {
    double ll_all = 0, ll_held = 0, sq_held = 0;
    long n_held = 0;
  };
  std::map<std::pair<bool, int>, Base> base;
  for (const auto& x : cands) {
    const auto key = std::make_pair(x.camera_unit, x.unit);
    if (base.count(key)) continue;
    Base bs;
    const auto& s = x.camera_unit ? a.CameraSamples(x.unit) : a.BallSamples(x.unit);
    const auto free = unit_free(x.camera_unit, x.unit);
    const UnitFit fit = a.Fit(s, x.camera_unit ? x.unit : -1, terms, free, scale, mode_of(x.camera_unit, x.unit), -1);
    std::vector<double> sc = scale;
    if (x.camera_unit) sc[x.unit] = fit.scale;
    bs.ll_all = a.Evaluate(s, fit.terms, sc, -1, false).ll;
    heldout(x.camera_unit, x.unit, terms, free, mode_of(x.camera_unit, x.unit), &bs.ll_held, &bs.sq_held,
            &bs.n_held);
    base[key] = bs;
  }

  auto fit_candidate = [&](Candidate& x) {
    const auto& s = x.camera_unit ? a.CameraSamples(x.unit) : a.BallSamples(x.unit);
    std::vector<CameraModelTerm> t = terms;
    std::vector<int> free = unit_free(x.camera_unit, x.unit);
    t.push_back(x.term);
    free.push_back(static_cast<int>(t.size()) - 1);
    if (x.pair) {
      t.push_back(x.term2);
      free.push_back(static_cast<int>(t.size()) - 1);
    }
    const bool noise = x.term.extension.effect == Effect::kPixelNoiseScale;
    const ScaleMode mode = noise ? ScaleMode::kFree : mode_of(x.camera_unit, x.unit);
    const int cu = x.camera_unit ? x.unit : -1;
    // A part-way move: the change time that fits all data best, among the candidates.
    if (x.step) {
      std::vector<double> times;
      for (const auto& smp : s.s) times.push_back(smp.t);
      std::sort(times.begin(), times.end());
      times.erase(std::unique(times.begin(), times.end()), times.end());
      double best_ll = -std::numeric_limits<double>::infinity(), best_t = 0;
      for (int g = 1; g <= options.change_points; ++g) {
        const double tc = times[times.size() * g / (options.change_points + 1)];
        t.back().from_time_s = tc;
        const UnitFit fit = a.Fit(s, cu, t, free, scale, mode, -1);
        std::vector<double> sc = scale;
        if (cu >= 0) sc[cu] = fit.scale;
        const double ll = a.Evaluate(s, fit.terms, sc, -1, false).ll;
        if (ll > best_ll) {
          best_ll = ll;
          best_t = tc;
        }
      }
      t.back().from_time_s = best_t;
      x.term.from_time_s = best_t;
    }
    Eigen::VectorXd par_sigma;
    const UnitFit fit = a.Fit(s, cu, t, free, scale, mode, -1, &par_sigma);
    std::vector<double> sc = scale;
    if (cu >= 0) sc[cu] = fit.scale;
    const Base& bs = base[{x.camera_unit, x.unit}];
    const double ll_all = a.Evaluate(s, fit.terms, sc, -1, false).ll;
    x.lr = 2 * (ll_all - bs.ll_all);
    x.base_ll = bs.ll_all;
    double ll_h, sq_h;
    long n_h;
    heldout(x.camera_unit, x.unit, t, free, mode, &ll_h, &sq_h, &n_h);
    x.heldout_gain = ll_h - bs.ll_held;
    x.rms_before = bs.n_held > 0 ? std::sqrt(bs.sq_held / bs.n_held) : 0;
    x.rms_after = n_h > 0 ? std::sqrt(sq_h / n_h) : 0;
    x.fitted = fit.terms;
    x.scale = fit.scale;
    x.term = fit.terms[fit.terms.size() - (x.pair ? 2 : 1)];
    if (x.pair) x.term2 = fit.terms.back();
    if (noise) {
      // s from a sample variance: sd(s) = s / sqrt(2 n) for n residuals.
      x.sigma = {fit.scale / std::sqrt(4.0 * s.size())};
    } else {
      // The candidate's blocks are the last fitted.
      const int np = x.term.extension.NumParameters() + (x.pair ? x.term2.extension.NumParameters() : 0);
      for (int i = 0; i < np; ++i) {
        const int j = static_cast<int>(par_sigma.size()) - np + i;
        x.sigma.push_back(j >= 0 ? par_sigma[j] : std::nan(""));
      }
    }
    x.label = x.term.extension.Label(rig.names);
    if (x.pair) x.label = std::string(Name(x.term.extension.effect)) + " + " + x.term2.extension.Label(rig.names);
    if (x.step)
      x.label += " from t = " + std::to_string(x.term.from_time_s) + " s";
  };
  for (auto& x : cands) fit_candidate(x);
  // Pairs are fitted only at cameras where a single candidate passes its test (the others
  // have no residual two effects could explain). On a clean recording a pair is therefore
  // tested only after a single candidate passed, which happens at the designed rate: the
  // gate keeps the family-wise rate, and the pairs fitted count in the round's m.
  std::set<int> residual_at;
  for (const auto& x : cands)
    if (x.camera_unit && ChiSquareSurvival(x.lr, x.k) < options.false_alarm / 2 / *tested) residual_at.insert(x.unit);
  for (auto& x : pairs)
    if (residual_at.count(x.unit)) {
      fit_candidate(x);
      cands.push_back(x);
    }
  return cands;
}

// The units (cameras, balls) that carry terms.
std::set<std::pair<bool, int>> TermUnits(const std::vector<CameraModelTerm>& terms) {
  std::set<std::pair<bool, int>> units;
  for (const auto& t : terms) units.insert({t.extension.effect != Effect::kTargetGeometry, t.extension.index});
  return units;
}

// One unit's terms fitted on all its samples, written back with the camera's noise scale;
// returns the indices of the unit's terms (*sigma, optional: their parameters' sigmas, in order).
std::vector<int> RefitUnit(const Auditor& a, const std::vector<bool>& noise_named, bool cam_unit, int u,
                           std::vector<CameraModelTerm>* terms, std::vector<double>* scale,
                           Eigen::VectorXd* sigma = nullptr) {
  const std::vector<int> free = UnitTerms(*terms, cam_unit, u);
  const auto& s = cam_unit ? a.CameraSamples(u) : a.BallSamples(u);
  const UnitFit fit = a.Fit(s, cam_unit ? u : -1, *terms, free, *scale, UnitScaleMode(cam_unit, u, noise_named), -1, sigma);
  for (int k : free) (*terms)[k].parameters = fit.terms[k].parameters;
  if (cam_unit) (*scale)[u] = fit.scale;
  return free;
}

// After an effect is taken: every unit's terms fitted again on the poses re-fitted with
// it, and the poses again, until the cameras' leave-one-out log-likelihood gains less than
// half a nat in a sweep (at most `iterations` sweeps: two moved cameras pull each other's
// poses, and the sweeps converge by a constant factor each). A term fitted while another camera's fault
// was still unmodelled carries that fault's pull on the leave-one-out poses; once the
// fault is in the model the pull is gone, and the term must be fitted without it, or its
// stale part is charged to the next round's candidates elsewhere.
void RefitUnits(Auditor& a, const std::vector<bool>& noise_named, int iterations,
                std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out) {
  std::vector<CameraModelTerm>& terms = *terms_out;
  std::vector<double>& scale = *scale_out;
  double last = -std::numeric_limits<double>::infinity();
  for (int it = 0; it < iterations; ++it) {
    for (const auto& [cam_unit, u] : TermUnits(terms))
      if (!(cam_unit ? a.CameraSamples(u) : a.BallSamples(u)).empty()) RefitUnit(a, noise_named, cam_unit, u, &terms, &scale);
    a.Rebuild(terms, scale);
    double ll = 0;
    for (int c = 0; c < static_cast<int>(scale.size()); ++c) ll += a.Evaluate(a.CameraSamples(c), terms, scale, -1, false).ll;
    if (std::abs(ll - last) < 0.5) break;
    last = ll;
  }
}

// Backward pruning: an effect named early (e.g. the noise scale, taking up the residual of
// a large effect named later) must still earn its place once the others are in: each
// named effect is removed in turn when the likelihood ratio for it, on the poses
// re-fitted with every effect, no longer passes the test or its BIC gain is <= 0.
void PruneNamedEffects(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options, double ln_n,
                       std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out,
                       std::vector<bool>* noise_named_out, AuditReport* rep_out) {
  std::vector<CameraModelTerm>& terms = *terms_out;
  std::vector<double>& scale = *scale_out;
  std::vector<bool>& noise_named = *noise_named_out;
  AuditReport& rep = *rep_out;
  const int nc = static_cast<int>(rig.size());
  for (bool changed = true; changed;) {
    changed = false;
    for (size_t k = terms.size(); k-- > 0;) {
      if (terms[k].undecided) continue;
      const Extension x = terms[k].extension;
      const bool cam_unit = x.effect != Effect::kTargetGeometry;
      const auto& s = cam_unit ? a.CameraSamples(x.index) : a.BallSamples(x.index);
      std::vector<CameraModelTerm> without = terms;
      without.erase(without.begin() + static_cast<long>(k));
      auto free_of = [&](const std::vector<CameraModelTerm>& t) { return UnitTerms(t, cam_unit, x.index); };
      const bool noise = x.effect == Effect::kPixelNoiseScale;
      const ScaleMode with_mode = UnitScaleMode(cam_unit, x.index, noise_named);
      const ScaleMode without_mode = noise ? ScaleMode::kBand : with_mode;
      const UnitFit f1 = a.Fit(s, cam_unit ? x.index : -1, terms, free_of(terms), scale, with_mode, -1);
      const UnitFit f0 = a.Fit(s, cam_unit ? x.index : -1, without, free_of(without), scale, without_mode, -1);
      std::vector<double> s1 = scale, s0 = scale;
      if (cam_unit) s1[x.index] = f1.scale, s0[x.index] = f0.scale;
      const double lr = 2 * (a.Evaluate(s, f1.terms, s1, -1, false).ll - a.Evaluate(s, f0.terms, s0, -1, false).ll);
      const int kp = x.NumParameters() + (terms[k].from_time_s > -std::numeric_limits<double>::infinity() ? 1 : 0);
      const double m = static_cast<double>(nc * 7 + nb);
      if (EarnsPlace(lr, kp, options.false_alarm / (2 * m), ln_n)) continue;
      const std::string label = x.Label(rig.names);
      rep.notes.push_back(label + " was named, then no longer earned its place once the other effects were in " +
                          "(likelihood ratio " + std::to_string(lr) + "): removed");
      for (size_t e = 0; e < rep.effects.size(); ++e)
        if (rep.effects[e].name == Name(x.effect) && rep.effects[e].where == x.Where(rig.names)) {
          rep.effects.erase(rep.effects.begin() + static_cast<long>(e));
          break;
        }
      if (noise) noise_named[x.index] = false;
      terms = f0.terms;
      if (cam_unit) scale[x.index] = f0.scale;
      a.Rebuild(terms, scale);
      changed = true;
      break;
    }
  }
}

// The report's named effect `name` at `where` taken out (it joins an undecided group).
void Unname(const std::string& name, const std::string& where, AuditReport* rep) {
  auto& ef = rep->effects;
  ef.erase(std::remove_if(ef.begin(), ef.end(), [&](const AuditEffect& e) { return e.name == name && e.where == where; }),
           ef.end());
}

// A move named while another camera's fault was still unmodelled may have won by what its
// six parameters took of that fault through the shared poses (a 3-camera rig: a focal length
// of one camera and a k1 of another; the move, a shift along the axis, took the focal
// length's place). Once every effect is in, each named move for the whole recording is
// judged again against its camera's simpler intrinsic explanations (focal length, principal
// point, both), each fitted in its place with every other term and the poses (the joint
// fit): where the move's extra parameters are no evidence against one of them (its
// likelihood ratio over it below the chi-square quantile at the recording's false-alarm
// rate itself, without the candidates' Bonferroni: the move keeps its place on any evidence
// that it is one), the one of these with the best BIC that earns its own place (the test,
// BIC and a held-out gain, as the move did) is named instead, with a note.
void SimplifyNamedMoves(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options, double ln_n,
                        const std::vector<double>& scale, const std::vector<bool>& noise_named,
                        std::vector<CameraModelTerm>* terms_io, AuditReport* rep) {
  std::vector<CameraModelTerm>& terms = *terms_io;
  const double m = static_cast<double>(static_cast<int>(rig.size()) * 7 + nb);  // as the pruning's
  for (size_t k = 0; k < terms.size(); ++k) {
    const Extension x = terms[k].extension;
    if (terms[k].undecided || x.effect != Effect::kCameraMoved ||
        terms[k].from_time_s > -std::numeric_limits<double>::infinity())
      continue;
    auto has = [&](Effect e) {
      for (const auto& t : terms)
        if (t.extension.effect == e && t.extension.index == x.index) return true;
      return false;
    };
    std::vector<CameraModelTerm> with = terms;
    const double ll_move = a.JointFit(&with, scale);
    std::vector<CameraModelTerm> without = terms;
    without.erase(without.begin() + static_cast<long>(k));
    std::vector<CameraModelTerm> none = without;
    const double ll_none = a.JointFit(&none, scale);
    std::vector<CameraModelTerm> best;
    double best_bic = -std::numeric_limits<double>::infinity(), best_ll = 0, best_lr = 0;
    int best_k = 0;
    for (const std::vector<Effect>& r : std::vector<std::vector<Effect>>{
             {Effect::kFocalLength}, {Effect::kPrincipalPoint}, {Effect::kFocalLength, Effect::kPrincipalPoint}}) {
      bool taken = false;
      int kr = 0;
      std::vector<CameraModelTerm> t = without;
      for (Effect e : r) {
        taken = taken || has(e);
        CameraModelTerm term;
        term.extension = Extension{e, x.index, 0};
        term.parameters = term.extension.InitialParameters();
        kr += term.extension.NumParameters();
        t.push_back(term);
      }
      if (taken) continue;
      const double ll = a.JointFit(&t, scale);
      const double lr = 2 * (ll_move - ll);
      // Among those the move does not beat and that earn their own place as the move did
      // (the candidates' test and BIC), the one of the best BIC (a principal point must earn
      // its two parameters beside a focal length).
      const double bic = 2 * ll - kr * ln_n;
      if (ChiSquareSurvival(lr, x.NumParameters() - kr) < options.false_alarm ||
          !EarnsPlace(2 * (ll - ll_none), kr, options.false_alarm / (2 * m), ln_n) || bic <= best_bic)
        continue;
      best = t;
      best_bic = bic;
      best_ll = ll;
      best_lr = lr;
      best_k = kr;
    }
    if (best.empty()) continue;
    // Named in the move's place: its held-out figures on its camera's samples against the
    // camera without the move, the poses re-fitted without it.
    const std::string move_label = x.Label(rig.names);
    a.Rebuild(without, scale);
    const ScaleMode mode = UnitScaleMode(true, x.index, noise_named);
    const Eval h0 = CameraHeldOut(a, options, true, x.index, without, UnitTerms(without, true, x.index), scale, mode);
    const Eval h1 = CameraHeldOut(a, options, true, x.index, best, UnitTerms(best, true, x.index), scale, mode);
    if (!(h1.ll > h0.ll)) {  // no held-out gain of its own: the move stays
      a.Rebuild(terms, scale);
      continue;
    }
    // In the report's order, where the move was.
    auto at = std::find_if(rep->effects.begin(), rep->effects.end(), [&](const AuditEffect& e) {
      return e.name == Name(x.effect) && e.where == x.Where(rig.names);
    });
    if (at != rep->effects.end()) at = rep->effects.erase(at);
    std::string named;
    for (size_t j = without.size(); j < best.size(); ++j) {
      const Extension& y = best[j].extension;
      AuditEffect ef;
      ef.name = Name(y.effect);
      ef.where = y.Where(rig.names);
      for (const std::string& p : y.ParameterNames()) {
        ef.parameters.push_back({p, 0.0});
        ef.sigma.push_back({p, std::nan("")});
      }
      ef.heldout_rms_before = h0.n > 0 ? std::sqrt(h0.sq / h0.n) : 0;
      ef.heldout_rms_after = h1.n > 0 ? std::sqrt(h1.sq / h1.n) : 0;
      ef.heldout_loglik_gain = h1.ll - h0.ll;
      ef.bic_gain = BicGain(2 * (best_ll - ll_none), best_k, ln_n);
      at = rep->effects.insert(at, ef) + 1;
      named += (named.empty() ? "" : " + ") + y.Label(rig.names);
    }
    char lr[32];
    std::snprintf(lr, sizeof lr, "%.1f", best_lr);
    rep->notes.push_back(move_label + " was selected, but once the other effects were in, " + named +
                         " explains the images as well with " + std::to_string(x.NumParameters() - best_k) +
                         " fewer parameters (the move's likelihood ratio over it " + lr +
                         ", no evidence of a move at the false-alarm rate): named in the move's place");
    terms = best;
    a.Rebuild(terms, scale);
    k = static_cast<size_t>(-1);  // the terms changed: judge the remaining moves afresh
  }
}

// A last fit of every unit with named effects on the poses re-fitted with all of them
// (the noise scale, in particular, whitens with the pose covariances of its own value).
void RefitNamedUnits(Auditor& a, const CameraRig& rig, const std::vector<bool>& noise_named,
                     std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out, AuditReport* rep_out) {
  std::vector<CameraModelTerm>& terms = *terms_out;
  std::vector<double>& scale = *scale_out;
  AuditReport& rep = *rep_out;
  for (const auto& [cam_unit, u] : TermUnits(terms)) {
    const auto& s = cam_unit ? a.CameraSamples(u) : a.BallSamples(u);
    Eigen::VectorXd par_sigma;
    const std::vector<int> free = RefitUnit(a, noise_named, cam_unit, u, &terms, &scale, &par_sigma);
    int j = 0;
    for (int k : free) {
      const Extension& x = terms[k].extension;
      std::vector<double> sg;
      if (x.effect == Effect::kPixelNoiseScale) {
        sg.push_back(scale[u] / std::sqrt(4.0 * s.size()));
      } else {
        for (int i = 0; i < x.NumParameters(); ++i, ++j)
          sg.push_back(j < par_sigma.size() ? par_sigma[j] : std::nan(""));
      }
      for (auto& e : rep.effects)
        if (!terms[k].undecided && e.name == Name(x.effect) && e.where == x.Where(rig.names))
          for (size_t i = 0; i < sg.size(); ++i) {
            e.parameters[i].second = terms[k].parameters[i];
            e.sigma[i].second = sg[i];
          }
    }
  }
}

// Moves for the whole recording at all cameras but one (or at all) are not identifiable:
// the target's poses are free, so camera a moved by Ma and camera b by Mb give the same
// images as every other camera moved by Ma^-1 and b by Ma^-1 Mb (two cameras: a move of
// either). Time offsets likewise: the same offset at every camera is a shift of the
// target's (free) trajectory, so offsets (0, a, b) of three cameras give the same images as
// (-a, 0, b - a) or (-b, a - b, 0). The images cannot say which cameras moved (or lag); the
// terms stay in the model (the poses need them) but are reported as one undecided group of
// every camera seen.
void UndecideUnidentifiable(const Auditor& a, const CameraRig& rig, Effect effect, std::vector<CameraModelTerm>* terms,
                            AuditReport* rep) {
  const int nc = static_cast<int>(rig.size());
  int seen = 0;
  for (int c = 0; c < nc; ++c) seen += a.CameraSamples(c).empty() ? 0 : 1;
  std::vector<CameraModelTerm*> found;
  for (auto& t : *terms)
    if (!t.undecided && t.extension.effect == effect && !(t.from_time_s > -std::numeric_limits<double>::infinity()))
      found.push_back(&t);
  if (seen < 2 || found.empty() || static_cast<int>(found.size()) < seen - 1) return;
  std::vector<std::string> group;
  for (int c = 0; c < nc; ++c)
    if (!a.CameraSamples(c).empty()) group.push_back(Extension{effect, c, 0}.Label(rig.names));
  std::string named;
  for (CameraModelTerm* t : found) {
    t->undecided = true;
    const std::string where = t->extension.Where(rig.names);
    named += (named.empty() ? "" : ", ") + where;
    Unname(Name(effect), where, rep);
  }
  rep->undecided.push_back(group);
  const std::string what = effect == Effect::kCameraMoved ? "moves" : "time offsets";
  rep->notes.push_back(std::string(Name(effect)) + " fitted at " + named + " of " + std::to_string(seen) +
                       " cameras: " + what +
                       " at all cameras but one are not identifiable (the target's poses are free, so the same images "
                       "come from the other cameras' instead); which cameras is undecided");
}

// A named intrinsic effect or time offset is judged against what could stand in its place
// with as many parameters: the same effect at every other camera, and the camera's other
// effects of its size (focal length, k1 and time offset have one parameter each), by the
// joint fit (Auditor::JointFit: every term and every frame's pose fitted together). A fault
// of one camera pulls the poses all cameras share, so in a small rig the same effect
// elsewhere, with the other terms, may explain the images as well; and a focal length and a
// k1 differ only in how the image scales with the distance from its centre, which a target
// seen near the centre does not show. Where a stand-in explains the images as well (within
// undecided_nats of log-likelihood), the images do not say which it is: the group is
// reported undecided and the term kept in the model, unnamed.
void UndecideSwappableEffects(const Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
                              const std::vector<double>& scale, const std::vector<bool>& noise_named,
                              std::vector<CameraModelTerm>* terms_io, AuditReport* rep) {
  std::vector<CameraModelTerm>& terms = *terms_io;
  const int nc = static_cast<int>(rig.size());
  std::vector<CameraModelTerm> fitted = terms;
  const double base = a.JointFit(&fitted, scale);
  for (size_t k = 0; k < terms.size(); ++k) {
    const Extension x = terms[k].extension;
    if (terms[k].undecided ||
        (x.effect != Effect::kFocalLength && x.effect != Effect::kPrincipalPoint &&
         x.effect != Effect::kRadialDistortion && x.effect != Effect::kCameraTimeOffset))
      continue;
    std::vector<Extension> stand_ins;
    for (int c = 0; c < nc; ++c)
      if (c != x.index) stand_ins.push_back(Extension{x.effect, c, 0});
    for (Effect e : {Effect::kFocalLength, Effect::kPrincipalPoint, Effect::kRadialDistortion,
                     Effect::kCameraTimeOffset})
      if (e != x.effect && Extension{e, x.index, 0}.NumParameters() == x.NumParameters())
        stand_ins.push_back(Extension{e, x.index, 0});
    std::vector<std::string> group;
    for (const Extension& y : stand_ins) {
      if (a.CameraSamples(y.index).empty()) continue;
      if (y.effect == Effect::kRadialDistortion && !HasK1(rig.cameras[y.index])) continue;
      bool taken = false;
      for (const auto& t : terms) taken = taken || (t.extension.effect == y.effect && t.extension.index == y.index);
      if (taken) continue;
      std::vector<CameraModelTerm> t = terms;
      t[k].extension = y;
      t[k].parameters = y.InitialParameters();
      // A stand-in at the same camera is judged on the same samples as the term was
      // selected on: it must also predict the held-out folds as well (the selection's tie
      // rule), not only fit the joint likelihood as well.
      if (y.index == x.index) {
        const ScaleMode mode = UnitScaleMode(true, x.index, noise_named);
        const double named_ll = CameraHeldOut(a, options, true, x.index, terms, UnitTerms(terms, true, x.index), scale, mode).ll;
        const double stand_ll = CameraHeldOut(a, options, true, x.index, t, UnitTerms(t, true, x.index), scale, mode).ll;
        if (stand_ll < named_ll - options.undecided_nats) continue;
      }
      const double ll = a.JointFit(&t, scale);
      if (ll >= base - options.undecided_nats) group.push_back(t[k].extension.Label(rig.names));
    }
    if (group.empty()) continue;
    const std::string label = x.Label(rig.names), where = x.Where(rig.names);
    group.insert(group.begin(), label);
    terms[k].undecided = true;
    Unname(Name(x.effect), where, rep);
    rep->undecided.push_back(group);
    std::string others;
    for (size_t i = 1; i < group.size(); ++i) others += (i > 1 ? ", " : "") + group[i];
    char band[32];
    std::snprintf(band, sizeof band, "%.3g", options.undecided_nats);
    // Principal points of different cameras trade against each other through the target's
    // free poses: say so, so that the group is not read as a want of frames.
    bool elsewhere = false;
    for (size_t i = 1; i < group.size(); ++i)
      elsewhere = elsewhere || group[i].substr(group[i].rfind(" at ") + 4) != where;
    const std::string why =
        x.effect == Effect::kPrincipalPoint && elsewhere
            ? "; principal points of different cameras trade against each other through the target's free poses "
              "(moving the target along one camera's line of sight leaves that camera's image nearly unchanged and "
              "shifts the other cameras' images nearly uniformly), so a small one is not placed at its camera by "
              "these images"
            : "";
    rep->notes.push_back(label + " was selected, but " + others + " in its place, with every other term and the poses " +
                         "refitted, explains the images as well (joint log-likelihood within " + band +
                         " nats): which is undecided" + why);
  }
}

// The named terms' values and sigmas from the joint fit (every term and every frame's pose
// together: the maximum likelihood, its covariance with the poses marginalised), not from
// each unit's fit on leave-one-out poses, which a neighbour's fault still pulls and whose
// sigma leaves out the poses' own error. The noise scales stay the units' fits.
void JointEstimates(const Auditor& a, const CameraRig& rig, const std::vector<double>& scale,
                    std::vector<CameraModelTerm>* terms_io, AuditReport* rep) {
  std::vector<CameraModelTerm>& terms = *terms_io;
  if (terms.empty()) return;
  std::vector<CameraModelTerm> joint = terms;
  std::vector<std::vector<double>> sigma;
  a.JointFit(&joint, scale, &sigma);
  for (size_t k = 0; k < terms.size(); ++k) {
    const Extension& x = terms[k].extension;
    if (x.effect == Effect::kPixelNoiseScale) continue;
    terms[k].parameters = joint[k].parameters;
    if (terms[k].undecided) continue;
    for (auto& e : rep->effects)
      if (e.name == Name(x.effect) && e.where == x.Where(rig.names))
        for (size_t i = 0; i < sigma[k].size() && i < e.sigma.size(); ++i) {
          e.parameters[i].second = terms[k].parameters[i];
          e.sigma[i].second = sigma[k][i];
        }
  }
}

}  // namespace

CameraAuditResult AuditCameraModel(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results,
                                   const CameraAuditOptions& options,
                                   const std::function<void(const std::string&)>& log) {
  std::string why;
  if (!options.IsValid(&why)) Throw("camera audit options: ", why);
  const int nc = static_cast<int>(rig.size()), nb = static_cast<int>(target.balls_target.size());
  CameraAuditResult res;
  AuditReport& rep = res.report;
  rep.mode = "cameras";
  rep.rms_unit = "px";
  Auditor a(rig, target, results, options);
  if (a.NumFrames() < static_cast<size_t>(2 * options.folds))
    Throw("audit cameras: ", a.NumFrames(), " tracked frames, expected at least ", 2 * options.folds,
          " (", options.folds, " folds of time)");
  std::vector<double> scale(nc, 1.0);
  std::vector<CameraModelTerm> terms;
  a.Rebuild(terms, scale);
  res.residuals.assign(nc, {});

  const long n_total = TestNominalModel(a, rig, options, terms, &res);
  const double ln_n = std::log(static_cast<double>(n_total));
  FitNoiseScales(a, rig, nb, options, terms, &scale, &rep);

  std::set<std::pair<bool, int>> blocked;  // units in an undecided group
  std::vector<bool> noise_named(nc, false);
  for (int round = 0; round < options.max_effects; ++round) {
    int tested = 0;
    std::vector<Candidate> cands = RoundCandidates(a, rig, nb, options, terms, scale, blocked, noise_named, &tested);
    if (cands.empty()) break;

    // The decision (audit/model_selection.h): candidates on the same data (the same camera,
    // or the same ball) explain the same residual and may tie; candidates elsewhere are
    // each taken in their turn. Part-way moves scan the change time: Bonferroni over it.
    SelectionRule rule;
    rule.alpha = options.false_alarm / 2;
    rule.ln_n = ln_n;
    rule.close_bic = 2 * options.undecided_nats;
    rule.undecided_heldout = options.undecided_nats;
    rule.undecided_bic = 2 * options.undecided_nats;
    std::vector<SelectionCandidate> sel(cands.size());
    for (size_t i = 0; i < cands.size(); ++i) {
      rep.nested.Record(cands[i].lr, cands[i].base_ll);
      sel[i].k = cands[i].k;
      sel[i].lr = cands[i].lr;
      sel[i].group = cands[i].camera_unit ? cands[i].unit : -1 - cands[i].unit;
      sel[i].multiplicity = cands[i].step ? options.change_points : 1;
      sel[i].heldout_gain = cands[i].heldout_gain;
      sel[i].tier = cands[i].pair ? 1 : 0;  // a pair only where neither alone nor a move explains as much
    }
    StepDecision dec = DecideStep(sel, tested, rule);
    // The candidates that pass on their own unit's residuals are then judged by what they
    // do to the whole rig: a camera's fault pulls the leave-one-out poses its neighbours
    // are tested against, so a neighbour's candidate (or a move mimicking an intrinsic
    // error plus that pull) also fits its own unit. The likelihood ratio of each passing
    // candidate becomes that of the joint fit (Auditor::JointFit: every frame's pose and
    // every term fitted to all cameras at once), where only the faulty camera's correction
    // removes the whole cost of its fault; the test, BIC and held-out rules then decide as
    // before.
    if (dec.outcome == StepOutcome::kNamed || dec.outcome == StepOutcome::kUndecided) {
      std::vector<size_t> pool;
      for (size_t i = 0; i < cands.size(); ++i)
        if (sel[i].passes) pool.push_back(i);
      if (pool.size() > 1) {
        // Every term, the candidate's and the named ones, fitted jointly with every frame's
        // pose: a term named while this candidate's fault was unmodelled carries part of
        // it, and only refitted beside it does it give that part back. The noise scales are
        // each model's own (the candidate's camera's fitted with it, within the band).
        std::vector<CameraModelTerm> t0 = terms;
        Auditor::JointState base_state;
        const double base = a.JointFit(&t0, scale, nullptr, &base_state);
        for (size_t i : pool) {
          std::vector<double> sc = scale;
          if (cands[i].camera_unit) sc[cands[i].unit] = cands[i].scale;
          std::vector<CameraModelTerm> t = cands[i].fitted;
          double ll = a.JointFit(&t, sc);
          if (ll < base) {
            // Started from its units' fits (and its camera's scale from them), the candidate
            // ended below the model it extends (issue 51): solved again from that model's
            // joint solution, its terms at no effect and its camera's noise scale refitted
            // beside them; the better of the two solves counts.
            std::vector<CameraModelTerm> t1 = t0;
            for (const CameraModelTerm* term : {&cands[i].term, cands[i].pair ? &cands[i].term2 : nullptr}) {
              if (!term) continue;
              t1.push_back(*term);
              t1.back().parameters = term->extension.InitialParameters();
            }
            std::vector<double> sc1 = scale;
            Auditor::JointState st = base_state;
            const bool noise = cands[i].term.extension.effect == Effect::kPixelNoiseScale;
            const ScaleMode mode =
                noise ? ScaleMode::kFree : UnitScaleMode(cands[i].camera_unit, cands[i].unit, noise_named);
            ll = std::max(ll, a.JointFitWithScale(&t1, &sc1, cands[i].camera_unit ? cands[i].unit : -1, mode, &st));
          }
          cands[i].lr = sel[i].lr = 2 * (ll - base);
          rep.nested.Record(cands[i].lr, base);
        }
        dec = DecideStep(sel, tested, rule);
      }
    }
    for (size_t i = 0; i < cands.size(); ++i) {
      cands[i].bic_gain = sel[i].bic_gain;
      cands[i].p_value = sel[i].p_value;
      cands[i].eligible = sel[i].passes && sel[i].heldout_gain > 0;
    }
    if (log) {
      std::string line = "round " + std::to_string(round + 1) + ":";
      std::vector<const Candidate*> sorted;
      for (const auto& x : cands) sorted.push_back(&x);
      std::sort(sorted.begin(), sorted.end(), [](auto* p, auto* q) { return p->bic_gain > q->bic_gain; });
      for (size_t i = 0; i < std::min<size_t>(4, sorted.size()); ++i) {
        char b[256];
        std::snprintf(b, sizeof b, " [%s: LR %.1f BIC %.1f held-out %.1f%s]", sorted[i]->label.c_str(), sorted[i]->lr,
                      sorted[i]->bic_gain, sorted[i]->heldout_gain, sorted[i]->eligible ? " ok" : "");
        line += b;
      }
      log(line);
    }
    if (dec.outcome == StepOutcome::kNothingPasses || dec.outcome == StepOutcome::kNoHeldoutGain) break;
    const Candidate& best = cands[dec.best];
    std::vector<const Candidate*> tie;
    for (int i : dec.group) tie.push_back(&cands[i]);
    if (tie.size() > 1) {
      std::vector<std::string> group;
      for (const Candidate* c : tie) group.push_back(c->label);
      rep.undecided.push_back(group);
      // The best of the group stays in the model, unnamed, so that its residual does not
      // leak into the other cameras' leave-one-out poses; the group's places are not
      // searched further.
      for (const Candidate* c : tie) blocked.insert({c->camera_unit, c->unit});
      terms = best.fitted;
      terms.back().undecided = true;
      if (best.pair) terms[terms.size() - 2].undecided = true;
      if (best.camera_unit) scale[best.unit] = best.scale;
      a.Rebuild(terms, scale);
      continue;
    }
    // Name it (a pair: both): the unit's terms as fitted with it, the noise scale, and
    // re-fit the poses.
    size_t first_sigma = 0;
    for (const CameraModelTerm* term : {&best.term, best.pair ? &best.term2 : nullptr}) {
      if (!term) continue;
      AuditEffect ef;
      ef.name = Name(term->extension.effect);
      ef.where = term->extension.Where(rig.names);
      const auto names = term->extension.ParameterNames();
      for (size_t i = 0; i < names.size(); ++i) {
        ef.parameters.push_back({names[i], term->parameters[i]});
        ef.sigma.push_back({names[i], best.sigma[first_sigma + i]});
      }
      first_sigma += names.size();
      if (best.step) ef.parameters.push_back({"from_time_s", term->from_time_s});
      ef.heldout_rms_before = best.rms_before;
      ef.heldout_rms_after = best.rms_after;
      ef.heldout_loglik_gain = best.heldout_gain;
      ef.bic_gain = best.bic_gain;
      rep.effects.push_back(ef);
    }
    terms = best.fitted;
    if (best.camera_unit) scale[best.unit] = best.scale;
    if (best.term.extension.effect == Effect::kPixelNoiseScale) noise_named[best.unit] = true;
    a.Rebuild(terms, scale);
    RefitUnits(a, noise_named, 10, &terms, &scale);
  }
  PruneNamedEffects(a, rig, nb, options, ln_n, &terms, &scale, &noise_named, &rep);
  SimplifyNamedMoves(a, rig, nb, options, ln_n, scale, noise_named, &terms, &rep);
  RefitNamedUnits(a, rig, noise_named, &terms, &scale, &rep);
  UndecideUnidentifiable(a, rig, Effect::kCameraMoved, &terms, &rep);
  UndecideUnidentifiable(a, rig, Effect::kCameraTimeOffset, &terms, &rep);
  UndecideSwappableEffects(a, rig, options, scale, noise_named, &terms, &rep);
  JointEstimates(a, rig, scale, &terms, &rep);
  // What a named move cannot be told from.
  for (const auto& t : terms)
    if (!t.undecided && t.extension.effect == Effect::kCameraMoved)
      rep.notes.push_back(t.extension.Label(rig.names) +
                          " also accounts for a change of that camera's principal point (a tilt shifts its image "
                          "the same way) and, with the target at nearly one distance, of its focal length (a shift "
                          "along its axis scales its image): the images do not tell these apart from the move");
  // The named terms with their sigmas.
  for (const auto& t : terms) {
    if (t.undecided) continue;
    CameraModelTerm out = t;
    for (const auto& e : rep.effects)
      if (e.name == Name(t.extension.effect) && e.where == t.extension.Where(rig.names))
        for (const auto& sg : e.sigma) out.sigma.push_back(sg.second);
    res.terms.push_back(out);
  }
  // What remains unexplained: the same tests on the leave-one-out residuals of the final
  // model (the named and undecided terms, the fitted noise scales), poses re-fitted under
  // it. A report that names effects while these still fail names the catalog's nearest
  // terms, not necessarily causes (docs/audits.md, the measured webcams).
  if (!terms.empty()) {
    a.Rebuild(terms, scale);
    std::vector<AuditTest> after;
    std::string note;
    std::vector<std::string> unaudited;
    double chi2 = 0;
    TestModel(a, rig, options, terms, scale, &after, &note, &unaudited, &chi2);
    rep.tests_after_run = static_cast<int>(after.size());
    for (const AuditTest& t : after)
      if (t.failed) rep.tests_after.push_back(t);
  }
  res.noise_scale = scale;
  bool failed = false;
  for (const auto& t : rep.tests) failed = failed || t.failed;
  rep.clean = rep.effects.empty() && rep.undecided.empty() && !failed;
  char note[256];
  std::snprintf(note, sizeof note,
                "%zu tracked frames, %d folds of contiguous time; designed false-alarm rate %.3g per recording "
                "(chi-square at alpha/(4 cameras), residual tests at alpha/4 over their number, candidates at alpha/(2 m), m candidates per round)",
                a.NumFrames(), options.folds, options.false_alarm);
  rep.notes.push_back(note);
  return res;
}

}  // namespace mcms
