// The "OpenCV + hand-written script" pipeline that bench_pipeline and bench_throughput
// compare ours with (header-only, for the benchmarks): cv::SimpleBlobDetector on each
// image, cv::undistortPoints, one-to-one nearest-epipolar matching between cameras 0 and
// 1, cv::triangulatePoints, the same distance-signature identification as ours
// (mcms::IdentifyTarget with an isotropic (0.2 mm)^2 point covariance) and its
// closed-form rigid fit as the pose.
#pragma once

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "core/pose_math.h"
#include "tracking/identify.h"
#include "tracking/target.h"
#include "vision/camera_model.h"
#include "vision/triangulation.h"

namespace mcms::bench {

// Baseline: isotropic covariance given to its triangulated points for identification.
constexpr double kBaselinePointSigmaM = 0.2e-3;
// Baseline: epipolar gate of a match, pixels (symmetric point-to-line distance).
constexpr double kBaselineEpipolarGatePx = 3.0;

// OpenCV's defaults (17 thresholds from 50 to 210 DN, repeatability 2, inertia and
// convexity filters) except for the polarity and the area limits.
inline cv::SimpleBlobDetector::Params BaselineBlobParams() {
  cv::SimpleBlobDetector::Params p;
  p.filterByColor = true;
  p.blobColor = 255;  // bright balls on a dark background
  p.filterByArea = true;
  // Ball images in the default rig are discs of radius ~4 to ~10 px (area ~50 to ~320).
  p.minArea = 10;
  p.maxArea = 3000;
  return p;
}

class Baseline {
 public:
  Baseline(const CameraRig& rig, const Target& target) : target_(target) {
    detector_ = cv::SimpleBlobDetector::create(BaselineBlobParams());
    for (const CameraModel& cam : rig.cameras) {
      const std::vector<double>& in = cam.Intrinsics();
      if (cam.LensModelName() != "LENSMODEL_OPENCV8" || in.size() != 12)
        throw std::runtime_error("the baseline needs LENSMODEL_OPENCV8 cameras, got " + cam.LensModelName());
      K_.push_back((cv::Mat_<double>(3, 3) << in[0], 0, in[2], 0, in[1], in[3], 0, 0, 1));
      D_.push_back(cv::Mat(std::vector<double>(in.begin() + 4, in.end()), true).reshape(1, 1));
      cv::Mat P(3, 4, CV_64F);
      const Pose& T = cam.T_cam_rig();
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) P.at<double>(r, c) = T.R(r, c);
        P.at<double>(r, 3) = T.t(r);
      }
      P_.push_back(P);  // normalized-coordinate projection matrix [R | t] of T_cam_rig
      f_.push_back(0.5 * (in[0] + in[1]));
    }
    // x1^T E x0 = 0 for normalized points, with T_c1_c0 = (R, t): E = [t]x R.
    const Pose T10 = rig.cameras[1].T_cam_rig() * rig.cameras[0].T_cam_rig().Inverse();
    E_ = Skew(T10.t) * T10.R;
  }

  struct Result {
    std::vector<TriangulatedPoint> points;  // triangulated from cameras 0 and 1
    std::optional<Identification> id;
  };

  Result Process(const std::vector<cv::Mat>& images) const { return Solve(Detect(images)); }

  // 1. Detection and undistortion on every image (a two-view script still reads and
  //    detects all cameras; only cameras 0 and 1 are matched). Normalized image points.
  std::vector<std::vector<Vec2>> Detect(const std::vector<cv::Mat>& images) const {
    std::vector<std::vector<Vec2>> norm(images.size());
    std::vector<cv::KeyPoint> kp;
    std::vector<cv::Point2f> pix, und;
    for (size_t c = 0; c < images.size(); ++c) {
      if (images[c].empty()) continue;
      detector_->detect(images[c], kp);
      if (kp.empty()) continue;
      pix.clear();
      for (const auto& k : kp) pix.push_back(k.pt);
      cv::undistortPoints(pix, und, K_[c], D_[c]);
      for (const auto& u : und) norm[c].emplace_back(u.x, u.y);
    }
    return norm;
  }

  // 2. to 4.: matching, triangulation, identification and pose.
  Result Solve(const std::vector<std::vector<Vec2>>& norm) const {
    Result res;
    // 2. Epipolar matching between cameras 0 and 1: all pairs within the gate, nearest
    //    first, each point used once.
    const std::vector<Vec2>& a = norm[0];
    const std::vector<Vec2>& b = norm[1];
    struct Cand {
      double d;
      int i, j;
    };
    std::vector<Cand> cand;
    for (size_t i = 0; i < a.size(); ++i) {
      const Vec3 x0(a[i].x(), a[i].y(), 1.0);
      const Vec3 l1 = E_ * x0;  // the epipolar line of x0 in camera 1
      for (size_t j = 0; j < b.size(); ++j) {
        const Vec3 x1(b[j].x(), b[j].y(), 1.0);
        const Vec3 l0 = E_.transpose() * x1;
        const double e = x1.dot(l1);
        const double d1 = std::abs(e) / l1.head<2>().norm() * f_[1];
        const double d0 = std::abs(e) / l0.head<2>().norm() * f_[0];
        const double d = 0.5 * (d0 + d1);
        if (d <= kBaselineEpipolarGatePx) cand.push_back({d, static_cast<int>(i), static_cast<int>(j)});
      }
    }
    std::sort(cand.begin(), cand.end(), [](const Cand& x, const Cand& y) { return x.d < y.d; });
    std::vector<bool> used0(a.size(), false), used1(b.size(), false);
    std::vector<cv::Point2d> m0, m1;
    for (const Cand& c : cand) {
      if (used0[c.i] || used1[c.j]) continue;
      used0[c.i] = used1[c.j] = true;
      m0.emplace_back(a[c.i].x(), a[c.i].y());
      m1.emplace_back(b[c.j].x(), b[c.j].y());
    }
    if (m0.empty()) return res;
    // 3. Linear (DLT) triangulation.
    cv::Mat X;
    cv::triangulatePoints(P_[0], P_[1], m0, m1, X);
    X.convertTo(X, CV_64F);
    for (int k = 0; k < X.cols; ++k) {
      const double w = X.at<double>(3, k);
      if (std::abs(w) < 1e-12) continue;
      TriangulatedPoint tp;
      tp.p_rig = Vec3(X.at<double>(0, k), X.at<double>(1, k), X.at<double>(2, k)) / w;
      tp.cov = Mat3::Identity() * (kBaselinePointSigmaM * kBaselinePointSigmaM);
      tp.observations = {{0, -1}, {1, -1}};
      res.points.push_back(std::move(tp));
    }
    // 4. Identification by the distance signature, and its closed-form rigid fit.
    res.id = IdentifyTarget(target_, res.points);
    return res;
  }

 private:
  Target target_;
  cv::Ptr<cv::SimpleBlobDetector> detector_;
  std::vector<cv::Mat> K_, D_, P_;
  std::vector<double> f_;
  Mat3 E_;
};

}  // namespace mcms::bench
