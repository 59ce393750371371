// The only translation unit with Ceres cost functions for pose tracking (Ceres
// headers compile slowly; keep them here).
#include "tracking/pose_refinement.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>

#include "core/error.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms {

bool PoseRefinementOptions::IsValid(std::string* why) const {
  if (max_outer_iterations < 1) return (*why = "max_outer_iterations must be >= 1", false);
  if (!(outlier_sigma > 0)) return (*why = "outlier_sigma must be positive", false);
  if (bias_outline_points < 8) return (*why = "bias_outline_points must be >= 8", false);
  return true;
}

namespace {

// Residual of one ball observation in one camera as a function of the pose
// increment delta = [dtheta; dp] about the linearization pose (R0, p0):
//   p_rig = Exp(dtheta) R0 b + p0 + dp,  q = Project(T_cam_rig p_rig) + bias,
//   r = W (q_obs - q).
// Analytic derivatives: d(Exp(w) v)/dw = -[Exp(w) v]x J_l(w); the projection's
// gradient comes from libmrcal. The sphere bias is held constant within one solve.
class BallReprojectionCost : public ceres::SizedCostFunction<2, 6> {
 public:
  BallReprojectionCost(const CameraModel* cam, const Pose& T0, const Vec3& ball_target, const Vec2& q_minus_bias,
                       const Mat2& W)
      : cam_(cam), R0b_(T0.R * ball_target), p0_(T0.t), q_(q_minus_bias), W_(W) {}

  // The same residual about another linearization pose and sphere bias (RefinePose's
  // outer iterations change these in place instead of building a new problem).
  void Relinearize(const Pose& T0, const Vec3& ball_target, const Vec2& q_minus_bias) {
    R0b_ = T0.R * ball_target;
    p0_ = T0.t;
    q_ = q_minus_bias;
  }

  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    const Eigen::Map<const Vec6> d(params[0]);
    const Vec3 w = d.head<3>();
    const Vec3 Rb = ExpSO3(w) * R0b_;
    const Vec3 p_rig = Rb + p0_ + d.tail<3>();
    const Pose& T = cam_->T_cam_rig();
    const Vec3 p_cam = T * p_rig;
    if (!(p_cam.z() > 0) && !cam_->CanProjectBehindCamera()) return false;
    Eigen::Matrix<double, 2, 3> dq_dpcam;
    const Vec2 q = cam_->Project(p_cam, jacobians ? &dq_dpcam : nullptr);
    Eigen::Map<Vec2> r(residuals);
    r = W_ * (q_ - q);
    if (jacobians && jacobians[0]) {
      Eigen::Matrix<double, 2, 6> J;
      const Eigen::Matrix<double, 2, 3> dq_dprig = dq_dpcam * T.R;
      J.leftCols<3>() = -dq_dprig * (-Skew(Rb) * LeftJacobianSO3(w));
      J.rightCols<3>() = -dq_dprig;
      Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> out(jacobians[0]);
      out = W_ * J;
    }
    return true;
  }

 private:
  const CameraModel* cam_;
  Vec3 R0b_, p0_;
  Vec2 q_;
  Mat2 W_;
};

struct Linearized {
  Mat6 H = Mat6::Zero();
  double chi2 = 0, sq = 0;
  std::vector<double> whitened2;  // per observation
};

Vec2 Bias(const CameraModel& cam, const Pose& T, const Vec3& ball, double radius, int n) {
  return SphereProjectionBias(cam, cam.T_cam_rig() * (T * ball), radius, n);
}

}  // namespace

ceres::CostFunction* NewBallReprojectionCost(const CameraModel& cam, const Pose& T0, const Vec3& ball_target,
                                             const Vec2& q_minus_bias, const Mat2& W) {
  return new BallReprojectionCost(&cam, T0, ball_target, q_minus_bias, W);
}

PoseRefinement RefinePose(const CameraRig& rig, const Target& target, const Pose& initial,
                          const std::vector<BallObservation>& observations, const PoseRefinementOptions& options) {
  std::set<int> balls;
  for (const auto& o : observations) balls.insert(o.ball);
  MCMS_CHECK(observations.size() >= 3 && balls.size() >= 3, "RefinePose needs observations of at least 3 distinct balls");

  PoseRefinement out;
  out.T_rig_target = initial;
  std::vector<BallObservation> obs = observations;
  const double radius = options.correct_sphere_bias ? target.ball_radius : 0.0;

  auto solve = [&](const std::vector<BallObservation>& use) {
    // One problem for all outer iterations (each re-linearizes the residuals in place) and
    // one loss for every residual: building them anew cost as much as solving.
    std::optional<ceres::HuberLoss> huber;
    if (options.huber_sigma > 0) huber.emplace(options.huber_sigma);
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    std::vector<BallReprojectionCost*> costs;
    costs.reserve(use.size());
    double delta[6];
    for (int outer = 0; outer < options.max_outer_iterations; ++outer) {
      std::fill(delta, delta + 6, 0.0);
      for (size_t k = 0; k < use.size(); ++k) {
        const BallObservation& o = use[k];
        const CameraModel& cam = rig.cameras[o.camera];
        const Vec3& b = target.balls_target[o.ball];
        const Vec2 bias = radius > 0 ? Bias(cam, out.T_rig_target, b, radius, options.bias_outline_points) : Vec2::Zero();
        if (outer > 0) {
          costs[k]->Relinearize(out.T_rig_target, b, o.q - bias);
          continue;
        }
        costs.push_back(new BallReprojectionCost(&cam, out.T_rig_target, b, o.q - bias, WhiteningOf(o.cov)));
        problem.AddResidualBlock(costs.back(), huber ? &*huber : nullptr, delta);
      }
      ceres::Solver::Options so;
      so.linear_solver_type = ceres::DENSE_QR;
      so.max_num_iterations = 50;
      so.function_tolerance = 1e-12;
      so.gradient_tolerance = 1e-14;
      so.parameter_tolerance = 1e-12;
      so.logging_type = ceres::SILENT;
      so.num_threads = 1;
      ceres::Solver::Summary summary;
      ceres::Solve(so, &problem, &summary);
      const Vec6 d = Eigen::Map<const Vec6>(delta);
      out.T_rig_target = BoxPlus(out.T_rig_target, d);
      out.converged = summary.IsSolutionUsable();
      // Converged when the re-linearized sphere bias moved the pose by less than a
      // micro-radian / micrometre (far below its standard deviation).
      if (d.head<3>().norm() < 1e-6 && d.tail<3>().norm() < 1e-6) break;
    }
  };

  // Information and residuals at the current pose (delta = 0), without the robust loss.
  auto linearize = [&](const std::vector<BallObservation>& use) {
    Linearized L;
    for (const auto& o : use) {
      const CameraModel& cam = rig.cameras[o.camera];
      const Vec3& b = target.balls_target[o.ball];
      const Vec2 bias = radius > 0 ? Bias(cam, out.T_rig_target, b, radius, options.bias_outline_points) : Vec2::Zero();
      const Mat2 W = WhiteningOf(o.cov);
      BallReprojectionCost cost(&cam, out.T_rig_target, b, o.q - bias, W);
      double zero[6] = {0, 0, 0, 0, 0, 0};
      const double* params[1] = {zero};
      double r[2], j[12];
      double* jac[1] = {j};
      if (!cost.Evaluate(params, r, jac)) {
        L.whitened2.push_back(std::numeric_limits<double>::infinity());
        continue;
      }
      const Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(j);
      L.H += J.transpose() * J;
      const double w2 = r[0] * r[0] + r[1] * r[1];
      L.whitened2.push_back(w2);
      L.chi2 += w2;
      L.sq += (W.inverse() * Vec2(r[0], r[1])).squaredNorm();
    }
    return L;
  };

  solve(obs);
  Linearized L = linearize(obs);
  // One round of outlier removal, keeping at least 3 distinct balls.
  std::vector<BallObservation> kept;
  for (size_t k = 0; k < obs.size(); ++k) {
    if (L.whitened2[k] > options.outlier_sigma * options.outlier_sigma)
      out.dropped.push_back(obs[k]);
    else
      kept.push_back(obs[k]);
  }
  std::set<int> kept_balls;
  for (const auto& o : kept) kept_balls.insert(o.ball);
  if (!out.dropped.empty() && kept.size() >= 3 && kept_balls.size() >= 3) {
    solve(kept);
    L = linearize(kept);
    obs = kept;
  } else {
    out.dropped.clear();
  }
  out.kept = obs;
  out.cov = L.H.inverse();
  out.chi2 = L.chi2;
  out.dof = 2 * static_cast<int>(obs.size()) - 6;
  out.rms_px = std::sqrt(L.sq / obs.size());
  out.converged = out.converged && out.cov.allFinite();
  return out;
}

}  // namespace mcms
