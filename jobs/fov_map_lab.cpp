#include "jobs/fov_map_lab.h"

#include <cmath>
#include <cstdio>


#include "core/random.h"
#include "jobs/lab_experiment.h"
#include "synthetic/lab_scenario.h"

namespace mcms {

namespace {
double Get(const LabResult& r, const std::string& method) {
  for (const auto& s : r.summary)
    if (s.name == method) return s.position_3sigma_m;
  return std::nan("");
}

LabReduction RunOne(const LabScenario& lab, const std::string& label, const CameraErrorModel& model, const Mat6& nominal_cov,
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
    Rng rng(1000 + 17 * s + (model.IsIdeal() ? 0 : 1));
    std::vector<Vec3> visit(points);
    for (auto& v : visit) v = model.DrawVisit(&rng);
    std::vector<FrameResult> tracked(nf);
    for (size_t k = 0; k < nf; ++k) {
      FrameResult& f = tracked[k];
      f.frame = k;
      f.time_s = lab.vision.times[k];
      const int p = lab.point_of_frame[k];
      // What the rendered demo does (jobs/demo.cpp): the visit's rigid error in what
      // the cameras see, the nominal tracker's error, then the pixel-noise excess.
      Pose T = lab.vision.T_rig_target[k];
      T.t += p >= 0 ? visit[p] : model.DrawVisit(&rng);
      T = BoxPlus(T, DrawNormal(nominal_cov, &rng));
      f.cov = nominal_cov;
      model.ScalePixelNoise(&T, &f.cov, &rng);
      model.AddVisitCovariance(&f.cov, p >= 0 ? frames_of_point[p] : 1);
      f.T_rig_target = T;
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

std::vector<LabReduction> PredictLabReductions(const CameraErrorModel& model, const Mat6& nominal_cov, int seeds, int points,
                                               double paper_robot_3sigma_m) {
  LabOptions lo;
  lo.points = points;
  const LabScenario lab = MakeLabScenario(lo);
  std::vector<LabReduction> out;
  out.push_back(RunOne(lab, "nominal camera, forward-model robot", CameraErrorModel{}, nominal_cov, seeds));
  out.push_back(RunOne(lab, "fitted camera, forward-model robot", model, nominal_cov, seeds));
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
    out.push_back(RunOne(lab2, label, model, nominal_cov, seeds));
  }
  return out;
}

}  // namespace mcms
