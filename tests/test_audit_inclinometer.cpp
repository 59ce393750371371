// The inclinometer audit's cost (audit/inclinometer_audit.h) against numeric derivatives,
// and the audit on in-memory data: a bias that only a tilting flange can tell from a
// misalignment is named as undecided on a flange that never tilts; too few frames are
// refused with a message naming the clock.
#include <gtest/gtest.h>


#include <cmath>

#include "audit/inclinometer_audit.h"
#include "core/random.h"
#include "tests/gradient_check.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

// All parameters in one block, split into the extensions' blocks.
struct Packed {
  InclinometerGroupCost cost;
  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    std::vector<const T*> b;
    const T* at = p[0];
    for (const Extension& e : *cost.ext) {
      b.push_back(at);
      at += e.NumParameters();
    }
    return cost(b.data(), r);
  }
};

TEST(InclinometerAudit, CostMatchesNumericDerivatives) {
  Inclinometer incl;
  incl.R_flange_incl = ExpSO3(Vec3(0.2, -0.1, 0.3));
  incl.bias = Vec2(1e-4, -2e-4);
  for (Effect clock : {Effect::kClockOffset, Effect::kClockDrift}) {
    const std::vector<Extension> ext{{Effect::kInclinometerBias, -1, 0},
                                     {Effect::kInclinometerMisalignment, -1, 0},
                                     {clock, -1, 0}};
    Packed f;
    f.cost.incl = &incl;
    f.cost.ext = &ext;
    f.cost.t0 = 0.5;
    f.cost.t_a = 12.3;
    f.cost.t_b = 12.4;
    f.cost.D_a = ExpSO3(Vec3(0.3, 0.2, -0.5));
    f.cost.chi = Vec3(0.001, -0.002, 0.0015);
    f.cost.s = {12.31, 12.33, 12.35};
    // The motion's shape: 10 ms segments around each reading.
    for (double t : f.cost.s) {
      f.cost.m_t0.push_back(t - 0.004);
      f.cost.m_t1.push_back(t + 0.006);
      f.cost.m_R0.push_back(ExpSO3(Vec3(0.1, 0.05 * t, -0.02)));
      f.cost.m_psi.push_back(Vec3(0.002, 0.001, -0.003));
    }
    f.cost.z = {Vec2(0.11, -0.05), Vec2(0.112, -0.049), Vec2(0.113, -0.047)};
    f.cost.whitening = Eigen::MatrixXd::Identity(6, 6) * 5000.0;
    f.cost.whitening(3, 1) = 300.0;
    std::vector<double> x{2e-4, -1e-4, 0.01, -0.02, 0.03, 0.004};
    if (clock == Effect::kClockDrift) x.push_back(3e-4);
    const int n = static_cast<int>(x.size());
    const Eigen::MatrixXd J = test::ExpectGradientsMatch(Packed(f), n, 6, x);
    // Every parameter moves the residual.
    for (int c = 0; c < n; ++c) EXPECT_GT(J.col(c).norm(), 0.0) << c;
  }
}

// A flange turning only about the vertical: its tilt never changes, so a bias and a
// misalignment of the mount make the same readings.
TEST(InclinometerAudit, BiasOnAFlangeThatNeverTiltsIsUndecided) {
  Inclinometer incl;
  Rng rng(3);
  std::vector<OrientationReference> ref;
  std::vector<InclinometerReadingSample> z;
  Inclinometer truth = incl;
  truth.bias = Vec2(3e-4, -2e-4);
  const auto R_at = [](double t) { return ExpSO3(Vec3(0, 0, 0.5 * std::sin(0.3 * t))); };
  for (int k = 0; k <= 2000; ++k) {
    const double t = k / 50.0;
    const Vec2 r = truth.Predict(R_at(t)) + Vec2(rng.Normal(), rng.Normal()) * incl.sigma;
    z.push_back({t, r, k + 2});
  }
  for (int m = 0; m < 390; ++m) {
    const double t = 0.5 + m / 10.0;
    ref.push_back({t, R_at(t), Mat3::Identity() * 1e-12, m + 2});
  }
  const InclinometerAuditResult r = AuditInclinometer(incl, ref, z);
  EXPECT_FALSE(r.report.clean);
  EXPECT_TRUE(r.report.effects.empty()) << r.report.Text();
  ASSERT_EQ(r.report.undecided.size(), 1u) << r.report.Text();
  const auto& g = r.report.undecided[0];
  EXPECT_NE(std::find(g.begin(), g.end(), "inclinometer_bias at inclinometer"), g.end()) << r.report.Text();
  EXPECT_NE(std::find(g.begin(), g.end(), "inclinometer_misalignment at inclinometer"), g.end()) << r.report.Text();
}

TEST(InclinometerAudit, LogsOnDifferentClocksAreRefused) {
  Inclinometer incl;
  std::vector<OrientationReference> ref;
  std::vector<InclinometerReadingSample> z;
  for (int k = 0; k < 100; ++k) z.push_back({k / 50.0, Vec2::Zero(), k + 2});
  for (int m = 0; m < 100; ++m) ref.push_back({3600.0 + m / 10.0, Mat3::Identity(), Mat3::Zero(), m + 2});
  const std::string e = test::ErrorOf([&] { AuditInclinometer(incl, ref, z); });
  EXPECT_NE(e.find("same clock"), std::string::npos) << e;
}

}  // namespace
}  // namespace mcms
