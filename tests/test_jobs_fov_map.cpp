// The field-of-view map (issue 12): the predicted precision against Monte Carlo through
// the renderer and the tracker; the noise-model fit naming a hidden effect and its size,
// and no false alarm on clean data; the paper's Tables 1 and 2.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "core/random.h"
#include "core/statistics.h"
#include "jobs/fov_map.h"
#include "audit/repeatability.h"
#include "jobs/fov_map_job.h"
#include "synthetic/scenario.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

// Predicted (Cramer-Rao) sigma against the sample sigma of rendered, tracked repeats at
// three points of the default rig's volume (centre, a low corner, a high edge). Pooled
// over points and axes, sum (n-1) s^2 / sigma^2 ~ chi-square(sum (n-1)) when the
// prediction is right; each axis's ratio s / sigma must also lie within its own 99.9 %
// band for n - 1 degrees of freedom.
TEST(FovMap, PredictionMatchesMonteCarlo) {
  const Scenario sc = Scenario::Default();
  FovMapOptions mo;
  mo.grid = FovGrid::Parse("-0.4:0.4:3,-0.3:0.3:3,0.1:0.9:3", "test grid");
  mo.noise.render = sc.render;
  mo.threads = 2;
  const FovMap map = ComputeFovMap(sc.rig, sc.target, mo);
  ASSERT_EQ(map.points.size(), 27u);
  for (const auto& p : map.points) EXPECT_TRUE(p.prediction.trackable) << p.p_rig.transpose();

  FovSimulationOptions so;
  so.repeats = 24;
  so.threads = 2;
  so.seed = 3;
  // Grid order: x fastest. Centre (13), low corner (0), high edge (25).
  const std::vector<size_t> pick{13, 0, 25};
  const auto sim = SimulateFovPoints(map, pick, so);
  ASSERT_EQ(sim.size(), 3u);
  double stat_p = 0, stat_r = 0, dof = 0;
  for (const auto& s : sim) {
    ASSERT_GE(s.tracked, so.repeats - 1) << "point " << s.p_rig.transpose() << " lost " << s.lost;
    const double n1 = s.tracked - 1;
    const double lo = std::sqrt(ChiSquareQuantile(0.0005, n1) / n1), hi = std::sqrt(ChiSquareQuantile(0.9995, n1) / n1);
    for (int a = 0; a < 3; ++a) {
      const double rp = s.simulated_sigma_p[a] / s.predicted_sigma_p[a];
      const double rr = s.simulated_sigma_r[a] / s.predicted_sigma_r[a];
      EXPECT_GT(rp, lo) << "position axis " << a << " at " << s.p_rig.transpose();
      EXPECT_LT(rp, hi) << "position axis " << a << " at " << s.p_rig.transpose();
      EXPECT_GT(rr, lo) << "rotation axis " << a << " at " << s.p_rig.transpose();
      EXPECT_LT(rr, hi) << "rotation axis " << a << " at " << s.p_rig.transpose();
      stat_p += n1 * rp * rp;
      stat_r += n1 * rr * rr;
      dof += n1;
    }
  }
  EXPECT_GT(stat_p, ChiSquareQuantile(0.0005, dof));
  EXPECT_LT(stat_p, ChiSquareQuantile(0.9995, dof));
  EXPECT_GT(stat_r, ChiSquareQuantile(0.0005, dof));
  EXPECT_LT(stat_r, ChiSquareQuantile(0.9995, dof));
  std::printf("pooled (n-1) s^2/sigma^2 over %g dof: position %.1f, rotation %.1f (ratio of variances %.3f, %.3f)\n", dof,
              stat_p, stat_r, stat_p / dof, stat_r / dof);
}

// A synthetic measurement campaign: 5 planes x 9 points, nominal sigmas that grow with the
// distance as a camera's do, `repeats` Gaussian repeats per point with the nominal
// variance plus the hidden effect.
VarianceData Campaign(uint64_t seed, int repeats, const Vec3& extra_sigma, double floor) {
  Rng rng(seed);
  VarianceData d;
  for (int plane = 0; plane < 5; ++plane)
    for (int k = 0; k < 9; ++k) {
      const double dist = 1.0 + 0.25 * plane + 0.02 * k;
      const Vec3 nominal_sigma = Vec3(0.010, 0.012, 0.025) * 1e-3 * dist * dist;
      const Vec3 var = nominal_sigma.cwiseAbs2() + extra_sigma.cwiseAbs2() + Vec3::Constant(floor * floor);
      Vec3 mean = Vec3::Zero(), sq = Vec3::Zero();
      std::vector<Vec3> x(repeats);
      for (auto& v : x) {
        for (int a = 0; a < 3; ++a) v[a] = std::sqrt(var[a]) * rng.Normal();
        mean += v;
      }
      mean /= repeats;
      for (const auto& v : x) sq += (v - mean).cwiseAbs2();
      d.nominal.push_back(nominal_sigma.cwiseAbs2());
      d.measured.push_back(sq / (repeats - 1));
      d.repeats.push_back(repeats);
    }
  return d;
}

double ParameterOf(const NoiseModelFit& f, const std::string& name, double* se) {
  for (size_t i = 0; i < f.parameters.size(); ++i)
    if (f.parameters[i].first == name) {
      *se = f.standard_errors[i].second;
      return f.parameters[i].second;
    }
  ADD_FAILURE() << "no parameter " << name;
  return NAN;
}

// The seed chooses the hidden effect (a floor, or one axis inflated) and its size
// (0.02 to 0.06 mm, twice to six times the nominal sigma at the nearest plane); the
// selection must name it, and only it, and recover its size within 3 standard errors
// and 25 %.
TEST(FovNoiseFit, HiddenEffectNamedAndSizeRecovered) {
  const char* axis_effect[3] = {"anisotropy_x", "anisotropy_y", "anisotropy_z"};
  const char* axis_param[3] = {"sigma_x_m", "sigma_y_m", "sigma_z_m"};
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    Rng choose(1000 + seed);
    const int kind = static_cast<int>(choose.Uniform() * 4);  // 0: floor, 1-3: axis
    const double size = choose.Uniform(0.02e-3, 0.06e-3);
    Vec3 extra = Vec3::Zero();
    double floor = 0;
    if (kind == 0) floor = size;
    else extra[kind - 1] = size;
    const VarianceData d = Campaign(seed, 8, extra, floor);
    const NoiseModelFit f = SelectNoiseModel(d);
    const std::string expected = kind == 0 ? "noise_floor" : axis_effect[kind - 1];
    ASSERT_EQ(f.effects, std::vector<std::string>{expected}) << "seed " << seed << "\n" << f.selection_log;
    double se = 0;
    const double got = ParameterOf(f, kind == 0 ? "floor_m" : axis_param[kind - 1], &se);
    EXPECT_NEAR(got, size, 3 * se) << "seed " << seed << " " << expected;
    EXPECT_NEAR(got, size, 0.25 * size) << "seed " << seed << " " << expected;
    std::printf("seed %llu: hidden %s %.4f mm -> named %s %.4f +- %.4f mm\n", static_cast<unsigned long long>(seed),
                expected.c_str(), size * 1e3, f.effects[0].c_str(), got * 1e3, se * 1e3);
  }
}

// Clean data (the nominal model is the truth): nothing is named, over several seeds.
TEST(FovNoiseFit, CleanDataNoFalseAlarm) {
  for (uint64_t seed = 1; seed <= 8; ++seed) {
    const VarianceData d = Campaign(100 + seed, 8, Vec3::Zero(), 0.0);
    const NoiseModelFit f = SelectNoiseModel(d);
    EXPECT_TRUE(f.effects.empty()) << "seed " << seed << "\n" << f.selection_log;
  }
}

// Misidentified points (a few points with gross scatter) are named and flagged.
TEST(FovNoiseFit, MisidentifiedPointsFlagged) {
  VarianceData d = Campaign(7, 5, Vec3::Zero(), 0.0);
  const std::vector<size_t> bad{4, 17, 40};
  for (size_t i : bad) d.measured[i] = Vec3(4e-6, 9e-6, 2e-6);  // 2-3 mm
  const NoiseModelFit f = SelectNoiseModel(d);
  ASSERT_EQ(f.effects, std::vector<std::string>{"misidentification"}) << f.selection_log;
  for (size_t i = 0; i < d.size(); ++i)
    EXPECT_EQ(f.outlier_posterior[i] > 0.5, std::find(bad.begin(), bad.end(), i) != bad.end()) << "point " << i;
}

// The paper's Tables 1 and 2 against the default rig: the extended model beats the
// nominal model and the paper's own isotropic 0.15 mm held out; the three gross points of
// plane 5 are flagged; Table 2 is predicted and its error stated.
// The measured analysis's options each checked and named.
TEST(FovNoiseFit, OptionsOutsideTheirRangeAreNamed) {
  MeasuredAnalysisOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why));
  o.laser_sigma_m = -1e-5;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("laser_sigma_m must be positive"), std::string::npos) << why;
  o = MeasuredAnalysisOptions{};
  o.repeats_per_line_end = 0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("repeats_per_line_end"), std::string::npos) << why;
}

TEST(FovNoiseFit, PaperTables) {
  MCMS_REQUIRE_DATA(paper, "paper");
  const Scenario sc = Scenario::Default();
  FovMapOptions mo;
  mo.noise.render = sc.render;
  mo.threads = 2;
  const MeasuredPoints m = ReadMeasuredPoints(paper / "table1_point_repeatability.csv", 5);
  ASSERT_EQ(m.points.size(), 17u);
  const MeasuredLines lines = ReadMeasuredLines(paper / "table2_line_lengths.csv");
  ASSERT_EQ(lines.lines.size(), 21u);
  MeasuredAnalysisOptions ao;
  ao.sensitivity = false;
  const MeasuredReport r = AnalyseMeasuredAgainstRig(m, &lines, sc.rig, sc.target, mo, ao);
  std::printf("%s", r.text.c_str());
  EXPECT_GT(r.heldout_gain, 0);
  EXPECT_GT(r.heldout_gain_vs_isotropic, 0);
  const auto& e = r.fit.effects;
  EXPECT_NE(std::find(e.begin(), e.end(), "misidentification"), e.end());
  EXPECT_NE(std::find(e.begin(), e.end(), "anisotropy_y"), e.end());
  std::vector<std::string> flagged;
  for (size_t i = 0; i < m.points.size(); ++i)
    if (r.fit.outlier_posterior[i] > 0.5) flagged.push_back(m.points[i].id);
  EXPECT_EQ(flagged, (std::vector<std::string>{"35", "37", "39"}));
  // The fitted inlier sigma_y is the paper's ~1 mm (its centre average 0.997 mm).
  EXPECT_NEAR(std::sqrt(r.fit.InlierVariance(r.data.nominal[0]).y()) * 1e3, 0.997, 0.15);
  // Table 2: the gross lines of plane 5 are the five beyond 2 mm; the prediction is finite
  // and stated with its error.
  EXPECT_EQ(r.table2.inliers, 16);
  EXPECT_NEAR(r.table2.measured_mean_abs_m * 1e3, 0.462, 0.001);
  EXPECT_GT(r.table2.predicted_mean_abs_sd_m, 0);
  EXPECT_GT(r.table2.loglik_extended, r.table2.loglik_isotropic);
  EXPECT_GT(r.table2.loglik_extended, r.table2.loglik_nominal);
  // The lab experiment with the fitted camera: its three-sigma error is of the paper's
  // order (3.94 mm), not the nominal rig's hundredths of a millimetre.
  ASSERT_EQ(r.lab.size(), 3u);
  EXPECT_LT(r.lab[0].camera_3sigma_m, 0.1e-3);
  EXPECT_GT(r.lab[1].camera_3sigma_m, 1.0e-3);
  EXPECT_LT(r.lab[1].camera_3sigma_m, 6.0e-3);
  EXPECT_NEAR(r.lab[2].robot_3sigma_m, 3.379e-3, 0.5e-3);
}

}  // namespace
}  // namespace mcms
