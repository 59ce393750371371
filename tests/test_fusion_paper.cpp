// Section 3.3 of the paper reproduced: the MOIFA reduction of the composite error (analytic
// 46.8 %, paper 46.1 %) within Monte-Carlo spread, the static KF's averaging figures against
// their closed forms, and the tracking KF equal to MOIFA.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/io.h"
#include "fusion/paper_simulation.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

// Monte-Carlo agreement: within 4 standard errors of the per-repetition mean (a false
// failure rate of 6e-5 per check for a correct simulation).
constexpr double kSpread = 4.0;

void ExpectWithinSpread(const Reduction& r, double expected, const char* what) {
  std::printf("%-40s pooled %6.2f %%, mean %6.2f +- %.2f %% (expected %.2f %%)\n", what, 100 * r.pooled, 100 * r.mean,
              100 * r.standard_error, 100 * expected);
  EXPECT_LT(std::abs(r.mean - expected), kSpread * r.standard_error) << what;
  EXPECT_LT(std::abs(r.pooled - expected), kSpread * r.standard_error) << what;
}

TEST(PaperFusion, AnalyticFigures) {
  const PaperFusionOptions o;
  const double moifa = AnalyticMoifaRmsReduction(o.camera_sigma, o.robot_sigma);
  EXPECT_NEAR(moifa, 0.4676, 5e-4);
  EXPECT_NEAR(moifa, 0.461, 0.01);  // the paper's 46.1 %
  EXPECT_NEAR(RunningMeanRmsFactor(1), 1.0, 1e-15);
  EXPECT_NEAR(RunningMeanRmsFactor(100), std::sqrt(5.187377517639621 / 100), 1e-12);
}

TEST(PaperFusion, SimulationReproducesSection33) {
  PaperFusionOptions o;
  o.repetitions = 300;
  o.seed = 2015;
  const PaperFusionResult r = SimulatePaperFusion(o);
  // Raw sensor errors as simulated (composite RMS: camera sqrt(3) 0.15 mm, robot 0.186 mm).
  EXPECT_NEAR(r.camera.rms / (std::sqrt(3.0) * 0.15e-3), 1.0, 0.01);
  EXPECT_NEAR(r.robot.rms / Vec3(0.157e-3, 0.087e-3, 0.043e-3).norm(), 1.0, 0.01);
  ExpectWithinSpread(r.moifa_rms, r.analytic_moifa_rms_reduction, "MOIFA, RMS");
  ExpectWithinSpread(r.moifa_three_sigma, r.analytic_moifa_rms_reduction, "MOIFA, three-sigma rule");
  ExpectWithinSpread(r.kf_tracking_rms, r.analytic_moifa_rms_reduction, "KF tracking (Q >> R), RMS");
  ExpectWithinSpread(r.kf_static_filter_rms, r.analytic_kf_static_filter_reduction, "static KF camera filter only, RMS");
  ExpectWithinSpread(r.kf_static_rms, r.analytic_kf_static_rms_reduction, "static KF fused, RMS");
  ExpectWithinSpread(r.kf_static_vs_filtered_camera_rms, r.analytic_moifa_rms_reduction,
                     "static KF fused vs filtered camera, RMS");
  // The tracking KF is MOIFA to within the filters' residual memory (R / Q ~ 2e-6).
  EXPECT_NEAR(r.kf_tracking_rms.pooled, r.moifa_rms.pooled, 1e-4);
  // The paper's MOIFA figure lies within 1 point of ours.
  EXPECT_NEAR(r.moifa_rms.pooled, 0.461, 0.01);
  // The static KF's per-sensor averaging alone is the size of the paper's "KF" 78.2 %.
  EXPECT_NEAR(r.analytic_kf_static_filter_reduction, 0.782, 0.015);
}

TEST(PaperFusion, PublishedFiguresFile) {
  MCMS_REQUIRE_DATA(paper, "paper");
  const CsvTable t = ReadCsv(paper / "fusion_results.csv");
  const int method = t.Column("method"), experiment = t.Column("experiment"), reduction = t.Column("reduction_pct");
  bool seen = false;
  for (size_t i = 0; i < t.rows.size(); ++i)
    if (t.rows[i][experiment] == "simulation" && t.rows[i][method] == "MOIFA") {
      const PaperFusionOptions o;
      EXPECT_NEAR(t.Number(i, reduction), 100 * AnalyticMoifaRmsReduction(o.camera_sigma, o.robot_sigma), 1.0);
      seen = true;
    }
  EXPECT_TRUE(seen);
}

TEST(PaperFusion, BadOptions) {
  PaperFusionOptions o;
  o.repetitions = 1;
  EXPECT_THROW(SimulatePaperFusion(o), InputError);
  o = PaperFusionOptions();
  o.robot_sigma.y() = 0;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("robot_sigma"), std::string::npos);
}

}  // namespace
}  // namespace mcms
