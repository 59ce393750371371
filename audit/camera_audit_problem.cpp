#include "audit/camera_audit_problem.h"

#include <ceres/ceres.h>

namespace mcms::camera_audit {

namespace {

// Outline to outline, the reach of another ball's light into a blob's measurement: the
// detector's window margin (its background ring is fitted robustly), the crowding margin of
// the field-of-view prediction (tracking/fov_prediction.h) too.
const double kCrowdedGapPx = BlobDetectorOptions{}.window_margin_px;

Pose ToPose(const PoseT<double>& p) {
  return Pose{p.R, p.t};
}

// The intrinsics of camera `c` with the named intrinsics effects applied.
void ApplyIntrinsics(const std::vector<CameraModelTerm>& terms, int c, std::vector<double>* in) {
  for (const auto& t : terms)
    if (t.extension.index == c && t.extension.effect != Effect::kTargetGeometry)
      ExtendIntrinsicsT<double>(t.extension, t.parameters.data(), in->data(), static_cast<int>(in->size()));
}

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
      case Effect::kCameraTimeOffset:
        dt += p[0];
        break;
      default:
        ExtendIntrinsicsT<double>(e, p, in.data(), static_cast<int>(in.size()));
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
    for (int i = 0; i < g->n; ++i)
      d.segment<2>(2 * i) = s[i].q - Predict(*rig, *target, s[i], work, &cams[s[i].camera]);
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

}  // namespace

bool HasK1(const CameraModel& cam) {
  return cam.LensModelName().rfind("LENSMODEL_OPENCV", 0) == 0 && cam.NumIntrinsics() > 4;
}

// At time `t`: a camera moved from a change time on has its old pose before it.
CameraRig ExtendRig(const CameraRig& rig, const std::vector<CameraModelTerm>& terms, double t) {
  CameraRig out = rig;
  for (size_t c = 0; c < rig.size(); ++c) {
    ApplyIntrinsics(terms, static_cast<int>(c), &out.cameras[c].MutableIntrinsics());
    Pose T_rig_cam = rig.cameras[c].T_cam_rig().Inverse();
    for (const auto& m : terms)
      if (m.extension.effect == Effect::kCameraMoved && m.extension.index == static_cast<int>(c) && t >= m.from_time_s)
        T_rig_cam = ToPose(MovedCameraT<double>(T_rig_cam, m.parameters.data()));
    out.cameras[c].SetT_cam_rig(T_rig_cam.Inverse());
  }
  return out;
}

Target ExtendTarget(const Target& target, const std::vector<CameraModelTerm>& terms) {
  Target out = target;
  for (const auto& t : terms)
    if (t.extension.effect == Effect::kTargetGeometry)
      out.balls_target[t.extension.index] =
          MovedBallT<double>(target.balls_target[t.extension.index], t.parameters.data());
  return out;
}

Auditor::Auditor(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results,
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

Pose Auditor::ViewPose(const Frame& f, int c, const std::vector<CameraModelTerm>& terms) {
  double dt = f.lag[c];
  for (const auto& t : terms)
    if (t.extension.effect == Effect::kCameraTimeOffset && t.extension.index == c) dt += t.parameters[0];
  return dt == 0 ? f.T : ToPose(TimeShiftedPoseT<double>(f.T, f.twist, f.accel, &dt));
}

std::vector<Obs> Auditor::Associate(const Frame& f, const CameraRig& rig_x, const Target& target_x,
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

double Auditor::JointFit(std::vector<CameraModelTerm>* terms_io, const std::vector<double>& scale,
                         std::vector<std::vector<double>>* sigma, JointState* state) const {
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
      const Sample at{x.camera,
                      x.ball,
                      f.block,
                      f.t,
                      f.T,
                      f.twist,
                      f.accel,
                      x.raw,
                      SphereProjectionBias(cam, p_cam, target_x.ball_radius, 32),
                      f.lag[x.camera]};
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

double Auditor::JointFitWithScale(std::vector<CameraModelTerm>* terms_io, std::vector<double>* scale_io, int camera,
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

void Auditor::Rebuild(const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale) {
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

Eval Auditor::Evaluate(const UnitData& u, const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
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

std::vector<WhitenedResidual> Auditor::Whitened(const UnitData& u, const std::vector<CameraModelTerm>& terms,
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

UnitFit Auditor::Fit(const UnitData& s, int camera, std::vector<CameraModelTerm> terms, const std::vector<int>& free,
                     std::vector<double> scale, ScaleMode mode, int fold, Eigen::VectorXd* sigma) const {
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

}  // namespace mcms::camera_audit
