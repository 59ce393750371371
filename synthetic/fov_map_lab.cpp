#include "synthetic/fov_map_lab.h"

#include <cmath>
#include <cstdio>

#include <Eigen/Eigenvalues>

#include "core/random.h"
#include "synthetic/lab_experiment.h"
#include "synthetic/lab_scenario.h"

namespace mcms {

namespace {
// A draw from N(0, C) (C symmetric positive semi-definite).
Vec6 Draw(const Mat6& C, Rng* rng) {
  Eigen::SelfAdjointEigenSolver<Mat6> es(C);
  Vec6 z;
  for (int i = 0; i < 6; ++i) z[i] = rng->Normal() * std::sqrt(std::max(0.0, es.eigenvalues()[i]));
  return es.eigenvectors() * z;
}

double Get(const LabResult& r, const std::string& method) {
  for (const auto& s : r.summary)
    if (s.name == method) return s.position_3sigma_m;
  return std::nan("");
}

LabReduction RunOne(const LabScenario& lab, const std::string& label, bool use_fit, const Mat6& fitted, const Mat6& nominal_cov,
                    int seeds) {
  const int points = lab.options.points;
  const size_t nf = lab.vision.NumFrames();
  std::vector<int> frames_of_point(points, 0);
  for (size_t k = 0; k < nf; ++k)
    if (lab.point_of_frame[k] >= 0) ++frames_of_point[lab.point_of_frame[k]];

  LabReduction red;
  red.camera_model = label;
  red.seeds = seeds;
  std::vector<double> rm, rk;
  for (int s = 0; s < seeds; ++s) {
    Rng rng(1000 + 17 * s + (use_fit ? 1 : 0));
    std::vector<Vec6> visit(points);
    for (auto& v : visit) v = Draw(fitted, &rng);
    std::vector<FrameResult> tracked(nf);
    for (size_t k = 0; k < nf; ++k) {
      FrameResult& f = tracked[k];
      f.frame = k;
      f.time_s = lab.vision.times[k];
      const int p = lab.point_of_frame[k];
      const Vec6 e = use_fit ? (p >= 0 ? visit[p] : Draw(fitted, &rng)) : Draw(nominal_cov, &rng);
      f.T_rig_target = BoxPlus(lab.vision.T_rig_target[k], e);
      f.cov = use_fit ? Mat6(fitted * (p >= 0 ? frames_of_point[p] : 1)) : nominal_cov;
      f.status = FrameStatus::kOk;
      f.balls_identified = 5;
    }
    const LabResult r = RunLabExperiment(lab, tracked);
    const double cam = Get(r, "camera"), rob = Get(r, "robot"), moifa = Get(r, "MOIFA"), kf = Get(r, "KF");
    red.camera_3sigma_m += cam / seeds;
    red.robot_3sigma_m += rob / seeds;
    red.moifa_3sigma_m += moifa / seeds;
    red.kf_3sigma_m += kf / seeds;
    rm.push_back(1 - moifa / cam);
    rk.push_back(1 - kf / cam);
  }
  auto stats = [](const std::vector<double>& v, double* mean, double* sd) {
    *mean = 0;
    for (double x : v) *mean += x / v.size();
    *sd = 0;
    for (double x : v) *sd += (x - *mean) * (x - *mean) / std::max<size_t>(1, v.size() - 1);
    *sd = std::sqrt(*sd);
  };
  stats(rm, &red.moifa_reduction, &red.moifa_reduction_sd);
  stats(rk, &red.kf_reduction, &red.kf_reduction_sd);
  return red;
}
}  // namespace

std::vector<LabReduction> PredictLabReductions(const NoiseModelFit& fit, const Mat6& nominal_cov, int seeds, int points,
                                               double paper_robot_3sigma_m) {
  LabOptions lo;
  lo.points = points;
  const LabScenario lab = MakeLabScenario(lo);
  Mat6 fitted = Mat6::Zero();
  fitted.topLeftCorner<3, 3>() = fit.scale * fit.scale * nominal_cov.topLeftCorner<3, 3>();
  fitted.bottomRightCorner<3, 3>() = fit.scale * fit.scale * nominal_cov.bottomRightCorner<3, 3>();
  fitted.bottomRightCorner<3, 3>().diagonal() += Vec3::Constant(fit.floor * fit.floor) + fit.anisotropy.cwiseAbs2();
  std::vector<LabReduction> out;
  out.push_back(RunOne(lab, "nominal camera, forward-model robot", false, fitted, nominal_cov, seeds));
  out.push_back(RunOne(lab, "fitted camera, forward-model robot", true, fitted, nominal_cov, seeds));
  if (paper_robot_3sigma_m > 0) {
    // The robot made as bad as the paper's: its DH errors scaled so that its three-sigma
    // position error matches (the error is linear in them to first order).
    const double ratio = paper_robot_3sigma_m / out[1].robot_3sigma_m;
    LabOptions bad = lo;
    bad.dh_length_sigma_m *= ratio;
    bad.dh_angle_sigma_rad *= ratio;
    const LabScenario lab2 = MakeLabScenario(bad);
    char label[160];
    std::snprintf(label, sizeof(label), "fitted camera, robot DH errors x%.1f (the paper's robot)", ratio);
    out.push_back(RunOne(lab2, label, true, fitted, nominal_cov, seeds));
  }
  return out;
}

}  // namespace mcms
