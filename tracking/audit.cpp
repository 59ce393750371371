#include "tracking/audit.h"

#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <cstdio>
#include <set>
#include <algorithm>
#include <vector>

#include "tracking/pose_refinement.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms {

namespace {

// Association gate for a camera's blobs around the predicted ball images: wide enough
// for a camera moved by a few mrad, narrow against the other balls (tens of px apart).
constexpr double kAuditGatePx = 8.0;
// A sample beyond the chi-square(2) quantile 1 - kOutlierP, scaled by the camera's robust
// spread, is a gross outlier.
constexpr double kOutlierP = 1e-5;
// Factor on the 99.9 % chi-square quantile before a camera is called inconsistent.
constexpr double kModelMargin = 1.3;

struct Sample {
  Pose T_rig_target;  // from the other cameras
  int ball;
  Vec2 q;
  Mat2 W;             // whitening of the observation covariance
};

Vec2 PredictBall(const CameraModel& cam, const Pose& T_cam_rig, const Target& target, const Pose& T, int ball,
                 Eigen::Matrix<double, 2, 3>* dq_dpcam, Vec3* p_cam_out) {
  const Vec3 p_cam = T_cam_rig * (T * target.balls_target[ball]);
  if (p_cam_out) *p_cam_out = p_cam;
  CameraModel c = cam;
  c.SetT_cam_rig(T_cam_rig);
  return c.Project(p_cam, dq_dpcam) + SphereProjectionBias(c, p_cam, target.ball_radius, 32);
}

double Chi2(const CameraModel& cam, const Pose& T_cam_rig, const Target& target, const std::vector<Sample>& s,
            double radial_k = 0) {
  double chi2 = 0;
  const Vec2 c(cam.Intrinsics()[2], cam.Intrinsics()[3]);
  for (const Sample& x : s) {
    Vec2 q = PredictBall(cam, T_cam_rig, target, x.T_rig_target, x.ball, nullptr, nullptr);
    q += radial_k * (q - c).squaredNorm() * (q - c);
    chi2 += (x.W * (x.q - q)).squaredNorm();
  }
  return chi2;
}

// Gauss-Newton on T_cam_rig = BoxPlus(T0, [dtheta; dt]): p_cam = Exp(dtheta) R p + t + dt.
Pose FitCameraPose(const CameraModel& cam, const Target& target, const std::vector<Sample>& s) {
  Pose T = cam.T_cam_rig();
  for (int it = 0; it < 10; ++it) {
    Mat6 H = Mat6::Zero();
    Vec6 g = Vec6::Zero();
    for (const Sample& x : s) {
      Eigen::Matrix<double, 2, 3> dq;
      Vec3 p_cam;
      const Vec2 q = PredictBall(cam, T, target, x.T_rig_target, x.ball, &dq, &p_cam);
      Eigen::Matrix<double, 2, 6> J;
      J.leftCols<3>() = dq * -Skew(p_cam - T.t);
      J.rightCols<3>() = dq;
      const Eigen::Matrix<double, 2, 6> Jw = x.W * J;
      H += Jw.transpose() * Jw;
      g += Jw.transpose() * (x.W * (x.q - q));
    }
    const Vec6 d = H.ldlt().solve(g);
    T = BoxPlus(T, d);
    if (d.norm() < 1e-12) break;
  }
  return T;
}

double FitRadial(const CameraModel& cam, const Target& target, const std::vector<Sample>& s) {
  const Vec2 c(cam.Intrinsics()[2], cam.Intrinsics()[3]);
  double num = 0, den = 0;
  for (const Sample& x : s) {
    const Vec2 q = PredictBall(cam, cam.T_cam_rig(), target, x.T_rig_target, x.ball, nullptr, nullptr);
    const Vec2 j = x.W * ((q - c).squaredNorm() * (q - c));
    num += j.dot(x.W * (x.q - q));
    den += j.dot(j);
  }
  return den > 0 ? num / den : 0.0;
}

}  // namespace

SequenceAudit AuditCameras(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results) {
  SequenceAudit audit;
  double worst = 0;
  for (size_t c = 0; c < rig.size(); ++c) {
    CameraAudit a;
    a.name = rig.names[c];
    std::vector<Sample> samples;
    for (const FrameResult& f : results) {
      if (!f.T_rig_target || c >= f.image_points.size()) continue;
      std::vector<BallObservation> others;
      for (const auto& o : f.ball_observations)
        if (o.camera != static_cast<int>(c)) others.push_back(o);
      std::set<int> balls;
      for (const auto& o : others) balls.insert(o.ball);
      if (balls.size() < 3) continue;
      PoseRefinementOptions po;
      po.outlier_sigma = 1e9;  // leave the other cameras' observations as they are
      const PoseRefinement r = RefinePose(rig, target, *f.T_rig_target, others, po);
      // Camera c's blobs, whether or not the tracker used them (a camera that disagrees
      // with the rest has its observations dropped as outliers): the nearest blob to each
      // predicted ball image within a wide gate, each blob used once.
      const auto& blobs = f.image_points[c];
      std::vector<bool> used(blobs.size(), false);
      for (int b = 0; b < static_cast<int>(target.balls_target.size()); ++b) {
        const Vec3 p_cam = rig.cameras[c].T_cam_rig() * (r.T_rig_target * target.balls_target[b]);
        if (!rig.cameras[c].Sees(p_cam, 10)) continue;
        const Vec2 q = PredictBall(rig.cameras[c], rig.cameras[c].T_cam_rig(), target, r.T_rig_target, b, nullptr,
                                   nullptr);
        const int best = ClaimNearest(blobs, q, kAuditGatePx, &used);
        if (best < 0) continue;
        // The prediction carries the leave-one-out pose's error: the residual's covariance
        // is the blob's plus J C_pose J^T, with J = dq/dp_cam R_cam_rig [-(R p_target)x, I]
        // for the pose perturbation of docs/conventions.md.
        Eigen::Matrix<double, 2, 3> dq_dpcam;
        PredictBall(rig.cameras[c], rig.cameras[c].T_cam_rig(), target, r.T_rig_target, b, &dq_dpcam, nullptr);
        Eigen::Matrix<double, 3, 6> dprig;
        dprig.leftCols<3>() = -Skew(r.T_rig_target.R * target.balls_target[b]);
        dprig.rightCols<3>() = Mat3::Identity();
        const Eigen::Matrix<double, 2, 6> J = dq_dpcam * rig.cameras[c].T_cam_rig().R * dprig;
        const Mat2 S = blobs[best].cov + J * r.cov * J.transpose();
        samples.push_back({r.T_rig_target, b, blobs[best].q, WhiteningOf(S)});
      }
    }
    a.observations = static_cast<int>(samples.size());
    if (samples.empty()) {
      audit.cameras.push_back(a);
      continue;
    }
    const CameraModel& cam = rig.cameras[c];
    // Gross outliers (a ball image pulled by another one the detector did not flag) are
    // left out, judged against the camera's own robust spread: the median whitened residual
    // square against chi-square(2)'s, 2 ln 2. A moved camera's residuals are all large
    // together, so its spread grows with them and few are left out.
    {
      std::vector<double> r2(samples.size());
      for (size_t i = 0; i < samples.size(); ++i)
        r2[i] = Chi2(cam, cam.T_cam_rig(), target, std::vector<Sample>{samples[i]});
      std::vector<double> sorted = r2;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double spread = std::max(1.0, sorted[sorted.size() / 2] / (2 * std::log(2.0)));
      const double cut = spread * boost::math::quantile(boost::math::chi_squared(2), 1 - kOutlierP);
      std::vector<Sample> kept;
      for (size_t i = 0; i < samples.size(); ++i)
        if (r2[i] <= cut) kept.push_back(samples[i]);
      a.outliers = static_cast<int>(samples.size() - kept.size());
      samples.swap(kept);
    }
    const double dof = 2.0 * samples.size();
    a.chi2_per_dof = Chi2(cam, cam.T_cam_rig(), target, samples) / dof;
    // The residuals are whitened with the prediction's covariance as well as the
    // observation's; kModelMargin on top of the 99.9 % quantile allows for what the
    // first-order propagation leaves out.
    a.chi2_threshold = kModelMargin * boost::math::quantile(boost::math::chi_squared(dof), 0.999) / dof;
    a.consistent = a.chi2_per_dof <= a.chi2_threshold;
    Vec2 mean = Vec2::Zero();
    for (const Sample& x : samples)
      mean += x.q - PredictBall(cam, cam.T_cam_rig(), target, x.T_rig_target, x.ball, nullptr, nullptr);
    a.mean_residual_px = mean / samples.size();
    a.cause = "none";
    a.corrected_T_cam_rig = cam.T_cam_rig();
    if (!a.consistent) {
      a.corrected_T_cam_rig = FitCameraPose(cam, target, samples);
      a.camera_move = BoxMinus(a.corrected_T_cam_rig, cam.T_cam_rig());
      a.after_moved = Chi2(cam, a.corrected_T_cam_rig, target, samples) / (dof - 6);
      a.radial_k = FitRadial(cam, target, samples);
      a.after_radial = Chi2(cam, cam.T_cam_rig(), target, samples, a.radial_k) / (dof - 1);
      a.cause = a.after_moved <= a.after_radial ? "camera moved" : "lens distortion";
      // A cause explains the residuals when its fit brings chi-square under the threshold
      // and removes most of the excess over 1. When neither does, the residuals are too
      // large everywhere: the pixel noise model is what is wrong (photon noise left out, a
      // gain too high), not this camera.
      const double best = std::min(a.after_moved, a.after_radial);
      const bool explained = best <= a.chi2_threshold && (a.chi2_per_dof - best) >= 0.5 * (a.chi2_per_dof - 1);
      if (!explained) a.cause = "noise model";
    }
    if (!a.consistent && a.chi2_per_dof > worst) {
      worst = a.chi2_per_dof;
      audit.worst = static_cast<int>(c);
    }
    audit.cameras.push_back(a);
  }
  return audit;
}

CameraRig RepairRig(const CameraRig& rig, const SequenceAudit& audit) {
  CameraRig out = rig;
  if (audit.worst >= 0 && audit.cameras[audit.worst].cause == "camera moved")
    out.cameras[audit.worst].SetT_cam_rig(audit.cameras[audit.worst].corrected_T_cam_rig);
  return out;
}

std::string SequenceAudit::Report() const {
  std::string s = "camera  observations  chi2/dof  threshold  mean residual (px)      verdict\n";
  char buf[512];
  for (const auto& a : cameras) {
    std::snprintf(buf, sizeof(buf), "%-7s %12d %9.2f %10.2f  (%+.3f, %+.3f)  %s", a.name.c_str(), a.observations,
                  a.chi2_per_dof, a.chi2_threshold, a.mean_residual_px.x(), a.mean_residual_px.y(),
                  a.consistent ? "consistent" : ("INCONSISTENT: " + a.cause).c_str());
    s += buf;
    if (!a.consistent) {
      std::snprintf(buf, sizeof(buf),
                    " (chi2/dof after fitting a camera move %.2f, a radial term %.2f; fitted move %.3f mrad, %.3f mm)",
                    a.after_moved, a.after_radial, 1e3 * a.camera_move.head<3>().norm(),
                    1e3 * a.camera_move.tail<3>().norm());
      s += buf;
    }
    if (a.outliers > 0) s += " (" + std::to_string(a.outliers) + " gross outlier(s) left out)";
    s += "\n";
  }
  return s;
}

}  // namespace mcms
