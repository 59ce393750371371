// The residual tests of the robot audit (audit/robot_audit_residuals.h): the covariates a
// residual is tested against (time, each joint's angle, gravity torque, move direction,
// temperature), the repeats' lack of fit, and the tests at a family-wise false-alarm rate.
#include "audit/robot_audit_residuals.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numeric>
#include <optional>
#include <set>
#include <sstream>

#include "audit/model_selection.h"
#include "audit/robot_audit_problem.h"
#include "audit/robot_audit_selection.h"
#include "core/format.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/statistics.h"

namespace mcms::robot_audit {


// ---------------------------------------------------------------------------------
// Residual tests of the nominal fit

// A joint as reports name it: "joint 3", or a URDF chain's joint by its name.
std::string JointText(const RobotModel& robot, int j) {
  return Extension{Effect::kJointOffset, j, 0}.Where(robot);
}

// The covariate an effect depends on, for plots.
std::string CovariateOf(const RobotModel& robot, const Extension& e, bool has_temperature) {
  const int n = robot.NumJoints();
  switch (e.effect) {
    case Effect::kGravityCompliance:
      return JointText(robot, e.index) + " gravity torque";
    case Effect::kBacklash:
      return JointText(robot, e.index) + " move direction";
    case Effect::kThermalDrift:
      return e.variant == 1 && has_temperature ? "temperature" : "time";
    case Effect::kGeometry:
    case Effect::kClockOffset:
      return "time";
    case Effect::kLinkLength:
    case Effect::kLinkTwist:
      return JointText(robot, std::min(e.index + 1, n - 1)) + " angle";
    default:
      return JointText(robot, e.index) + " angle";
  }
}

std::vector<Covariate> Covariates(const RobotModel& robot, const RobotLog& log, const Problem& s) {
  std::vector<Covariate> cv;
  const int n = robot.NumJoints();
  const size_t N = log.rows.size();
  Covariate t{"time", {}};
  for (const auto& r : log.rows) t.v.push_back(r.time_s);
  cv.push_back(t);
  for (int j = 0; j < n; ++j) {
    Covariate a{JointText(robot, j) + " angle", {}};
    Covariate g{JointText(robot, j) + " gravity torque", {}};
    Covariate d{JointText(robot, j) + " move direction", {}};
    for (size_t i = 0; i < N; ++i) {
      a.v.push_back(log.rows[i].q[j]);
      g.v.push_back(s.rows[i].c.gravity_torque[j]);
      d.v.push_back(s.rows[i].c.move_direction[j]);
    }
    cv.push_back(a);
    cv.push_back(g);
    cv.push_back(d);
  }
  if (log.has_temperature) {
    Covariate c{"temperature", {}};
    for (const auto& r : log.rows) c.v.push_back(r.temperature_c.value_or(std::nan("")));
    cv.push_back(c);
  }
  return cv;
}

namespace {

// Groups of rows with the same joint values (repeats of a pose).
std::vector<std::vector<int>> RepeatGroups(const RobotLog& log, const Eigen::VectorXd& tol) {
  const int N = log.rows.size();
  std::vector<int> order(N);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return log.rows[a].q[0] < log.rows[b].q[0]; });
  std::vector<int> group(N, -1);
  std::vector<std::vector<int>> groups;
  for (int ii = 0; ii < N; ++ii) {
    const int a = order[ii];
    if (group[a] >= 0) continue;
    group[a] = groups.size();
    groups.push_back({a});
    for (int jj = ii + 1; jj < N; ++jj) {
      const int b = order[jj];
      if (log.rows[b].q[0] - log.rows[a].q[0] > tol[0]) break;
      if (group[b] < 0 && ((log.rows[b].q - log.rows[a].q).cwiseAbs().array() <= tol.array()).all()) {
        group[b] = group[a];
        groups.back().push_back(b);
      }
    }
  }
  return groups;
}

}  // namespace

// Residual tests of a fit (the nominal one; the final one for what remains unexplained).
// Returns the lack-of-fit statistic (chi-square per dof of the pose means against the
// scatter of the repeats), NaN without repeats. `num_tests`: how many tests were run.
double TestResiduals(const RobotLog& log, const Problem& s, const FitResult& nominal, const std::vector<Covariate>& cov,
                     double alpha, int num_params, const Eigen::VectorXd& repeat_tolerance, AuditReport* rep,
                     int* num_tests, int* num_failed) {
  double lack_of_fit = std::nan("");
  const int N = log.rows.size(), m = s.m;
  const Eigen::MatrixXd W = (WhiteningOf(nominal.noise) * nominal.R.transpose()).transpose();  // N x m
  std::vector<AuditTest> tests;
  // Lack of fit against the scatter of repeated poses.
  const auto groups = RepeatGroups(log, repeat_tolerance);
  const int G = groups.size();
  const int df_pe = N - G;
  if (df_pe >= 2 * m + 2 && m * G - num_params > 0) {
    Eigen::MatrixXd Spe = Eigen::MatrixXd::Zero(m, m);
    std::vector<Eigen::VectorXd> mean(G);
    for (int g = 0; g < G; ++g) {
      mean[g] = Eigen::VectorXd::Zero(m);
      for (int i : groups[g]) mean[g] += nominal.R.row(i).transpose();
      mean[g] /= groups[g].size();
      for (int i : groups[g]) {
        const Eigen::VectorXd d = nominal.R.row(i).transpose() - mean[g];
        Spe += d * d.transpose();
      }
    }
    Spe /= df_pe;
    Spe.diagonal().array() += 1e-12 * Spe.trace() / m + 1e-30;
    Eigen::LLT<Eigen::MatrixXd> llt(Spe);
    double chi2 = 0;
    for (int g = 0; g < G; ++g) chi2 += groups[g].size() * llt.matrixL().solve(mean[g]).squaredNorm();
    const double d1 = m * G - num_params, d2 = static_cast<double>(m) * df_pe;
    const double F = (chi2 / d1);
    lack_of_fit = F;
    const double p = FisherSurvival(F, d1, d2);
    tests.push_back({"lack of fit against repeated poses (F, " + std::to_string(G) + " poses)", F, p, false});
  } else {
    rep->notes.push_back(
        "no repeated poses (or too few): the noise is estimated from the residuals with the model, "
        "so the nominal model's chi-square cannot be tested on its own");
  }
  // Lag-1 autocorrelation in time and trends against every covariate, per component.
  const char* comp[6] = {"x", "y", "z", "rx", "ry", "rz"};
  for (int k = 0; k < m; ++k) {
    const std::vector<double> w(W.col(k).data(), W.col(k).data() + N);
    tests.push_back(AutocorrelationTest(std::string("autocorrelation in time (") + comp[k] + ")", w));
    for (const auto& c : cov)
      if (auto t = TrendTest("trend vs " + c.name + " (" + comp[k] + ")", c.v, w)) tests.push_back(*t);
  }
  const double per = alpha / std::max<size_t>(1, tests.size());
  for (auto& t : tests) t.failed = t.p_value < per;
  if (num_tests) *num_tests = static_cast<int>(tests.size());
  if (num_failed) *num_failed = static_cast<int>(std::count_if(tests.begin(), tests.end(), [](const AuditTest& t) { return t.failed; }));
  // Report the failed tests and the strongest few of the rest.
  std::vector<AuditTest> shown;
  int failed = 0;
  for (const auto& t : tests)
    if (t.failed) shown.push_back(t), ++failed;
  std::sort(shown.begin(), shown.end(), [](const AuditTest& a, const AuditTest& b) { return a.p_value < b.p_value; });
  // The ten strongest failures are shown; the rest are counted.
  if (shown.size() > 10) {
    shown.resize(10);
    rep->notes.push_back(std::to_string(failed - 10) + " more residual tests failed (the ten strongest are shown)");
  }
  std::vector<AuditTest> rest;
  for (const auto& t : tests)
    if (!t.failed) rest.push_back(t);
  std::sort(rest.begin(), rest.end(), [](const AuditTest& a, const AuditTest& b) { return a.p_value < b.p_value; });
  for (size_t i = 0; i < rest.size() && i < 3; ++i) shown.push_back(rest[i]);
  rep->tests = shown;
  char buf[160];
  std::snprintf(buf, sizeof buf, "%zu residual tests at a family-wise false-alarm rate of %.3g (each at %.3g)",
                tests.size(), alpha, per);
  rep->notes.push_back(buf);
  return lack_of_fit;
}

}  // namespace mcms::robot_audit
