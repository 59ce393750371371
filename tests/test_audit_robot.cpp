// The robot audit (issues 11 and 24) must find what is hidden in a measurement log, and
// nothing else:
//  - one effect hidden (a seed picks the effect, where and its size, detectable but not
//    obvious): named at the right place with its size within 3 of its own sigmas and a
//    positive held-out gain; or, where the logged poses cannot tell it from another
//    candidate, reported undecided with both, and the poses the audit proposes, once
//    measured, name it;
//  - the normal robot (every DH parameter a little off, nothing else): geometry, with a
//    positive held-out gain, and no non-geometric effect, on every seed, for two robots;
//  - a second robot known only from its YAML file (three parallel axes, like a UR10) with
//    the arm's own weight (link masses and a payload), thermal growth of every link and
//    backlash that lags the motor-side encoder: each named at the right place with its
//    size, alone and all at once on top of DH errors;
//  - clean logs of both robots: called clean at the designed rate (1 %) over 100 seeds;
//  - several at once (issue 35): the arm's weight on robot files without masses on top of
//    every DH error, joint scale against offset over the logged spreads, backlash beside
//    the weight; ties decided by measuring the proposed poses as often as the audit says.
// Logs: tests/robot_logs.h (anisotropic noise, unknown registration and tool, 2 h, repeats).
#include <gtest/gtest.h>

#include <yaml-cpp/yaml.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include "audit/robot_audit.h"
#include "calib/robot_calibration.h"
#include "core/error.h"
#include "core/random.h"
#include "model/urdf.h"
#include "positioner.h"
#include "robot_logs.h"
#include "test_util.h"
#include "urdf_robots.h"

namespace mcms {
namespace {

using test::Hidden;
using test::MakeRobotLog;
using test::RobotLogSpec;
constexpr double kDeg = std::numbers::pi / 180.0;

RobotModel Ur10Like() {
  return RobotModel::Read(std::filesystem::path(MCMS_SOURCE_DIR) / "examples" / "robots" / "ur10_like.yaml");
}

// The KR 5 arc with a lumped mass at each link frame's origin (kg): the arm's weight in
// the simulation, for an audited robot that gives no masses.
RobotModel Kr5WithLumpedMasses() {
  std::vector<Joint> j = RobotModel::Default().Joints();
  const double m[6] = {0.0, 20.0, 15.0, 8.0, 2.0, 0.5};
  for (int k = 0; k < 6; ++k) {
    j[k].mass_kg = m[k];
    j[k].com_m = Vec3::Zero();
  }
  return RobotModel::Default().WithJoints(j);
}

// UR10 poses: the arm above the table, the wrist anywhere.
RobotLogSpec Ur10Spec() {
  RobotLogSpec s;
  s.lo = {-2.5, -2.6, -2.4, -3.0, -2.5, -3.0};
  s.hi = {2.5, -0.5, 2.4, 3.0, 2.5, 3.0};
  return s;
}

const AuditEffect* Find(const AuditReport& r, const std::string& name, const std::string& where) {
  for (const auto& x : r.effects)
    if (x.name == name && x.where == where) return &x;
  return nullptr;
}
const AuditEffect* Find(const AuditReport& r, const Extension& e) { return Find(r, Name(e.effect), e.Where()); }

bool InUndecided(const AuditReport& r, const Extension& e) {
  for (const auto& g : r.undecided)
    for (const auto& l : g)
      if (l.rfind(e.Label(), 0) == 0) return true;
  return false;
}

// A named effect: positive gains, and every parameter of the truth within 3 of its sigmas.
void ExpectSizes(const AuditEffect& e, const Hidden& h, const std::string& what) {
  EXPECT_GT(e.heldout_loglik_gain, 0.0) << what;
  EXPECT_GT(e.bic_gain, 0.0) << what;
  const auto names = h.ext.ParameterNames();
  for (size_t j = 0; j < e.parameters.size(); ++j) {
    size_t k = 0;
    while (k < names.size() && names[k] != e.parameters[j].first) ++k;
    ASSERT_LT(k, names.size()) << what << ": parameter " << e.parameters[j].first;
    const double truth = h.p[k], est = e.parameters[j].second, sig = e.sigma[j].second;
    if (h.ext.effect == Effect::kErrorMotion && truth == 0.0) continue;
    EXPECT_LT(std::abs(est - truth), 3.0 * sig + 1e-12)
        << what << ": " << names[k] << " estimated " << est << " +- " << sig << ", truth " << truth;
  }
}

// The effect is named; or it is undecided, and measuring the proposed poses names it.
void ExpectNamedOrSeparated(const RobotModel& robot, const RobotAuditResult& res, const Hidden& h,
                            const test::RobotTruth& truth, RobotLog log, const RobotAuditOptions& o,
                            const std::string& what, uint64_t seed) {
  const AuditEffect* e = Find(res.report, h.ext);
  if (e) {
    ExpectSizes(*e, h, what);
    return;
  }
  ASSERT_TRUE(InUndecided(res.report, h.ext)) << what << ": " << h.ext.Label() << " neither named nor undecided\n"
                                              << res.report.Text();
  ASSERT_FALSE(res.next_poses.empty()) << what;
  // Each pose measured as many times as the audit says decides the pair (issue 35).
  std::vector<Eigen::VectorXd> qs;
  for (const auto& np : res.next_poses) {
    ASSERT_GT(np.readings, 0) << what << ": [" << np.a << "] vs [" << np.b << "] said not separable\n"
                              << res.report.Text();
    std::printf("%s: [%s] vs [%s]: %zu poses x %d readings (noncentrality %.1f, needed %.1f, logged %.1f)\n",
                what.c_str(), np.a.c_str(), np.b.c_str(), np.poses.size(), np.readings, np.noncentrality,
                np.noncentrality_needed, np.noncentrality_logged);
    for (const auto& p : np.poses)
      for (int r = 0; r < np.readings; ++r) qs.push_back(p.q);
  }
  Rng rng(seed + 99);
  test::AppendRows(truth, qs, log.rows.back().time_s + 60.0, 30.0, rng, &log);
  const RobotAuditResult again = AuditRobot(robot, log, o);
  std::printf("%s, with the %zu proposed poses measured:\n%s", what.c_str(), qs.size(), again.report.Text().c_str());
  const AuditEffect* e2 = Find(again.report, h.ext);
  ASSERT_NE(e2, nullptr) << what << ": still not named after the proposed poses\n" << again.report.Text();
  ExpectSizes(*e2, h, what + " (after the proposed poses)");
}

// A hidden effect on the KR 5 arc chosen by the seed: kind k (0..7), where and size.
Hidden PickEffect(int kind, Rng& rng) {
  const double sign = rng.Uniform() < 0.5 ? -1.0 : 1.0;
  const double f = 1.0 + rng.Uniform();  // 1..2 times the base size
  switch (kind) {
    case 0: {  // joint offset of joint 2..5: 0.006..0.012 deg (2, 3), 0.02..0.04 deg (4, 5: short levers)
      const int j = 1 + static_cast<int>(rng.Uniform() * 4) % 4;
      return {{Effect::kJointOffset, j, 0}, {sign * f * (j < 3 ? 0.006 : 0.02) * kDeg}};
    }
    case 1: {  // link length: a2, a3 or d4, 0.03..0.06 mm
      const Extension choices[3] = {{Effect::kLinkLength, 1, 0}, {Effect::kLinkLength, 2, 0}, {Effect::kLinkLength, 3, 1}};
      return {choices[static_cast<int>(rng.Uniform() * 3) % 3], {sign * f * 0.03e-3}};
    }
    case 2: {  // link twist of joint 2 or 3: 0.006..0.012 deg
      const int j = 1 + static_cast<int>(rng.Uniform() * 2) % 2;
      return {{Effect::kLinkTwist, j, 0}, {sign * f * 0.006 * kDeg}};
    }
    case 3: {  // joint scale of joint 2..4: 1e-4..2e-4
      const int j = 1 + static_cast<int>(rng.Uniform() * 3) % 3;
      return {{Effect::kJointScale, j, 0}, {sign * f * 1e-4}};
    }
    case 4:  // thermal warm-up: 30..60 ppm, time constant 40 min
      return {{Effect::kThermalDrift, -1, 0}, {f * 30e-6, 2400.0}};
    case 5: {  // backlash of joint 2 or 3 (lags the encoder): 0.006..0.012 deg
      const int j = 1 + static_cast<int>(rng.Uniform() * 2) % 2;
      return {{Effect::kBacklash, j, 0}, {f * 0.006 * kDeg}};
    }
    default: {  // error motion of joint 3: first harmonic axial 0.06..0.12 mm
      std::vector<double> p(12, 0.0);
      // Axial: no DH parameter is a function of the joint angle.
      p[5] = sign * f * 0.06e-3;
      p[6 + 5] = f * 0.04e-3;
      return {{Effect::kErrorMotion, 2, 1}, p};
    }
  }
}

// Whether one of the report's notes holds every one of `parts`.
bool SaysNote(const AuditReport& rep, const std::vector<std::string>& parts) {
  for (const std::string& n : rep.notes) {
    bool all = true;
    for (const std::string& p : parts) all = all && n.find(p) != std::string::npos;
    if (all) return true;
  }
  return false;
}

TEST(RobotAudit, FindsEachHiddenEffect) {
  const char* kinds[7] = {"joint_offset", "link_length", "link_twist", "joint_scale", "thermal_drift", "backlash",
                          "error_motion"};
  const RobotModel robot = RobotModel::Default();
  for (int kind = 0; kind < 7; ++kind) {
    for (int s = 0; s < 2; ++s) {
      const uint64_t seed = 1000 + 17 * kind + s;
      Rng rng(seed * 7919);
      const Hidden h = PickEffect(kind, rng);
      test::RobotTruth truth;
      const RobotLog log = MakeRobotLog(robot, seed, {h}, {}, &truth);
      RobotAuditOptions o;
      const RobotAuditResult res = AuditRobot(robot, log, o);
      const std::string what = std::string(kinds[kind]) + " seed " + std::to_string(seed);
      std::printf("%s: hidden %s", what.c_str(), h.ext.Label().c_str());
      for (double v : h.p) std::printf(" %.4g", v);
      std::printf("\n%s", res.report.Text().c_str());
      EXPECT_FALSE(res.report.clean) << what;
      ExpectNamedOrSeparated(robot, res, h, truth, log, o, what, seed);
    }
  }
}

// Joint scale against joint offset (issue 35): a scale is told from an offset by the spread
// of that joint's angles. Scale errors of joints 1-3 of both robots (DH exact, 80 poses x 5
// readings as a user's log), over the logged spreads of the other tests (the KR 5 arc's
// working region and its narrow wrist-tie region, the UR10-like's poses): the scale is
// named at its joint with its size, or reported undecided with what it ties with; never a
// wrong effect named in its place.
TEST(RobotAudit, JointScaleIsNamedOrUndecidedNeverAnOffsetAlone) {
  const RobotModel kr5 = RobotModel::Default(), ur10 = Ur10Like();
  RobotLogSpec narrow;
  narrow.lo = {-1.2, -1.6, 0.2, -0.4, 0.6, -0.4};
  narrow.hi = {1.2, 0.4, 2.2, 0.4, 1.4, 0.4};
  struct Case {
    const RobotModel* robot;
    RobotLogSpec spec;
    const char* what;
  };
  const Case cases[] = {{&kr5, {}, "KR 5 working region"}, {&kr5, narrow, "KR 5 narrow region"},
                        {&ur10, Ur10Spec(), "UR10-like"}};
  int named = 0, undecided = 0;
  for (size_t c = 0; c < 3; ++c)
    for (int j = 0; j < 3; ++j) {
      const uint64_t seed = 7300 + 10 * c + j;
      Rng rng(seed);
      RobotLogSpec spec = cases[c].spec;
      spec.poses = 80;
      spec.repeats = 5;
      const double size = (rng.Uniform() < 0.5 ? -1 : 1) * (1.2e-4 + 1.0e-4 * rng.Uniform());
      const Hidden h{{Effect::kJointScale, j, 0}, {size}};
      const RobotLog log = MakeRobotLog(*cases[c].robot, seed, {h}, spec);
      const RobotAuditResult res = AuditRobot(*cases[c].robot, log);
      const std::string what = std::string(cases[c].what) + ", " + h.ext.Label() + " " + std::to_string(size * 1e6) +
                               " ppm, seed " + std::to_string(seed);
      std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
      const AuditEffect* e = Find(res.report, h.ext);
      if (e) {
        ++named;
        ExpectSizes(*e, h, what);
      } else {
        ++undecided;
        EXPECT_TRUE(InUndecided(res.report, h.ext)) << what << ": neither named nor undecided\n" << res.report.Text();
      }
      for (const auto& x : res.report.effects)
        EXPECT_TRUE(x.name == "joint_scale" && x.where == h.ext.Where())
            << what << ": " << x.name << " at " << x.where << " named (the DH table is exact)";
    }
  std::printf("joint scale: named on %d, undecided on %d of 9 logs\n", named, undecided);
}

// The arm's own weight on a robot whose masses are not given: lumped masses at the link
// frames' origins and the payload. Named at the right joint, with a deflection that
// matches the truth's, and no negative compliance ever.
// The relative RMS difference between the fitted lumped-mass deflection of `joint` (rad) and
// the truth's (its compliance times the gravity torque of the true masses) over the log's poses.
double DeflectionError(const RobotModel& robot, const RobotModel& massed, const RobotLog& log,
                       const RobotLogSpec& spec, int joint, const AuditEffect& e) {
  const int n = robot.NumJoints();
  double err = 0, ref = 0;
  for (const auto& row : log.rows) {
    const Eigen::MatrixXd L = GravityLever(robot, row.q);
    double d = 0;
    for (const auto& [name, v] : e.parameters) {
      const int col = name == "c_m_tool" ? 2 * n : (name[4] == 'o' ? 0 : n) + std::stoi(name.substr(5)) - 1;
      d += v * L(joint, col) * (col == 2 * n && log.has_payload ? *row.payload_kg : 1.0);
    }
    const double truth = spec.compliance[joint] * GravityTorque(massed, row.q, spec.payload_kg)[joint];
    err += (d - truth) * (d - truth);
    ref += truth * truth;
  }
  return std::sqrt(err / ref);
}

TEST(RobotAudit, GravityOfTheArmWithoutMassesInTheRobotFile) {
  const RobotModel robot = RobotModel::Default();
  const RobotModel massed = Kr5WithLumpedMasses();
  for (int s = 0; s < 4; ++s) {
    const int joint = 1 + s % 2;  // A2 or A3
    RobotLogSpec spec;
    spec.masses = &massed;
    spec.compliance.assign(6, 0.0);
    spec.compliance[joint] = (1.0 + 0.5 * s) * 2e-6;  // rad / N m
    spec.payload_column = s < 2;                        // a log without a payload column still has the arm
    const RobotLog log = MakeRobotLog(robot, 3100 + s, {}, spec);
    const RobotAuditResult res = AuditRobot(robot, log);
    std::printf("gravity seed %d at joint %d:\n%s", 3100 + s, joint + 1, res.report.Text().c_str());
    // The report says which masses were fitted (issue 35).
    EXPECT_TRUE(SaysNote(res.report, {"the robot file gives no masses", "lumped mass moments",
                                      s < 2 ? "scales with the log's payload column" : "the log has no payload column"}))
        << res.report.Text();
    const AuditEffect* e = Find(res.report, "gravity_compliance", "joint " + std::to_string(joint + 1));
    ASSERT_NE(e, nullptr) << res.report.Text();
    EXPECT_GT(e->heldout_loglik_gain, 0.0);
    for (const auto& [name, v] : e->parameters) EXPECT_GE(v, 0.0) << name;
    const double off = DeflectionError(robot, massed, log, spec, joint, *e);
    EXPECT_LT(off, 0.35) << "fitted deflection off the truth's by " << off;
    for (const auto& x : res.report.effects)
      EXPECT_TRUE(x.name == "gravity_compliance" || x.name == "joint_offset" || x.name == "geometry")
          << "named " << x.name << " at " << x.where;
  }
}

TEST(RobotAudit, NamesTwoEffectsAtOnce) {
  const Hidden a{{Effect::kJointOffset, 2, 0}, {0.008 * kDeg}};
  const Hidden b{{Effect::kThermalDrift, -1, 0}, {40e-6, 1200.0}};
  const RobotLog log = MakeRobotLog(RobotModel::Default(), 77, {a, b});
  const RobotAuditResult res = AuditRobot(RobotModel::Default(), log);
  std::printf("%s", res.report.Text().c_str());
  for (const Hidden& h : {a, b}) {
    const AuditEffect* e = Find(res.report, h.ext);
    ASSERT_NE(e, nullptr) << h.ext.Label() << "\n" << res.report.Text();
    ExpectSizes(*e, h, "two effects: " + h.ext.Label());
  }
}

// Every real robot has all its DH parameters a little off. That is geometry, for both
// robots, on every seed; a non-geometric effect on top of it is a false alarm, which the
// selection allows at its designed rate (its share of 1 %): over 100 seeds of each robot,
// at most 4 (P(X >= 5 | n = 100, p = 0.01) = 0.0034). Measured: 1 of 100 for each.
bool Geometric(const std::string& name) {
  return name == "geometry" || name == "joint_offset" || name == "link_length" || name == "link_twist";
}

// The arm's weight when the robot file gives no masses (issue 35), on robots whose every
// DH term is a little off: the UR10-like (its file's masses make the truth, the audit is
// given the table without them) and the KR 5 arc with lumped masses, with and without a
// payload column, 4 seeds each. Gravity compliance named at the right joint (its
// deflection against the truth's), or undecided with it; never a geometric term or another
// effect in its place.
RobotModel WithoutMasses(const RobotModel& r) {
  std::vector<Joint> j = r.Joints();
  for (Joint& x : j) {
    x.mass_kg.reset();  // not given
    x.com_m = Vec3::Zero();
  }
  RobotModel out = r.WithJoints(j);
  out.SetToolMass({});
  return out;
}
TEST(RobotAudit, ArmsWeightWithoutMassesOnTopOfEveryDhError) {
  const RobotModel ur10 = Ur10Like(), kr5m = Kr5WithLumpedMasses();
  const RobotModel* truths[2] = {&ur10, &kr5m};
  int named = 0, undecided = 0;
  for (int r = 0; r < 2; ++r) {
    const RobotModel given = WithoutMasses(*truths[r]);
    ASSERT_FALSE(given.HasMasses());
    for (int s = 0; s < 4; ++s) {
      const uint64_t seed = 7400 + 10 * r + s;
      RobotLogSpec spec = r == 0 ? Ur10Spec() : RobotLogSpec{};
      spec.masses = truths[r];
      const int joint = 1 + s % 2;
      spec.compliance.assign(6, 0.0);
      spec.compliance[joint] = 2e-6 * (1.0 + 0.5 * (s / 2));  // rad / N m
      spec.payload_column = s < 2;
      spec.dh_length_sigma_m = 0.05e-3;
      spec.dh_angle_sigma_rad = 5e-5;
      spec.poses = 60;
      const RobotLog log = MakeRobotLog(given, seed, {}, spec);
      const RobotAuditResult res = AuditRobot(given, log);
      const std::string where = "joint " + std::to_string(joint + 1);
      const std::string what = std::string(r == 0 ? "UR10-like" : "KR 5 arc") + " without masses, weight at " +
                               where + (spec.payload_column ? "" : ", no payload column") + ", seed " +
                               std::to_string(seed);
      std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
      const Extension gc{Effect::kGravityCompliance, joint, 0};
      const AuditEffect* e = Find(res.report, "gravity_compliance", where);
      if (e) {
        ++named;
        EXPECT_GT(e->heldout_loglik_gain, 0.0) << what;
        for (const auto& [name, v] : e->parameters) EXPECT_GE(v, 0.0) << what << ": " << name;
        const double off = DeflectionError(given, *truths[r], log, spec, joint, *e);
        std::printf("%s: fitted deflection off the truth's by %.3f (relative RMS)\n", what.c_str(), off);
        EXPECT_LT(off, 0.35) << what << ": fitted deflection off the truth's by " << off;
      } else {
        ++undecided;
        EXPECT_TRUE(InUndecided(res.report, gc)) << what << ": the arm's weight neither named nor undecided\n"
                                                 << res.report.Text();
      }
      for (const auto& x : res.report.effects)
        EXPECT_TRUE(Geometric(x.name) || (x.name == "gravity_compliance" && x.where == where))
            << what << ": " << x.name << " at " << x.where << " named";
      // A geometric term named alone where the weight is: only with the whole geometry
      // (every DH term is off), never a single term standing in for the deflection.
    }
  }
  std::printf("arm's weight without masses: named on %d, undecided on %d of 8 logs\n", named, undecided);
}

TEST(RobotAudit, NormalRobotIsGeometry) {
  const RobotModel kr5 = RobotModel::Default(), ur10 = Ur10Like();
  for (int r = 0; r < 2; ++r) {
    const RobotModel& robot = r == 0 ? kr5 : ur10;
    int others = 0;
    for (int s = 0; s < 100; ++s) {
      RobotLogSpec spec = r == 0 ? RobotLogSpec{} : Ur10Spec();
      spec.dh_length_sigma_m = 0.1e-3;
      spec.dh_angle_sigma_rad = 1e-4;
      const uint64_t seed = 90000 + s;
      const RobotAuditResult res = AuditRobot(robot, MakeRobotLog(robot, seed, {}, spec));
      const std::string what = robot.Name() + " seed " + std::to_string(seed);
      if (s == 0) std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
      bool geometric = false, other = false;
      for (const auto& e : res.report.effects) {
        if (Geometric(e.name)) {
          geometric = true;
          EXPECT_GT(e.heldout_loglik_gain, 0.0) << what;
        } else {
          other = true;
          std::printf("%s: non-geometric %s at %s\n", what.c_str(), e.name.c_str(), e.where.c_str());
        }
      }
      for (const auto& grp : res.report.undecided)
        for (const auto& l : grp) other |= !Geometric(l.substr(0, l.find(" at ")));
      EXPECT_TRUE(geometric) << what << ": no geometry named\n" << res.report.Text();
      others += other;
    }
    std::printf("%s: a non-geometric effect named on %d of 100 normal robots\n", robot.Name().c_str(), others);
    EXPECT_LE(others, 4) << robot.Name();
  }
}

// The second robot, from its YAML file alone (masses given): each effect named with its
// size, alone; then everything at once on top of DH errors, as a real arm has them.
TEST(RobotAudit, SecondRobotFromItsFile) {
  const RobotModel ur10 = Ur10Like();
  ASSERT_TRUE(ur10.HasMasses());
  struct Case {
    std::string what;
    std::vector<double> compliance;  // rad / N m per joint
    std::vector<Hidden> hidden;
  };
  std::vector<Case> cases;
  for (int s = 0; s < 2; ++s) {
    const double f = 1.0 + 0.6 * s;
    cases.push_back({"gravity", {0, 2e-6 * f, 3e-6 * f, 0, 0, 0}, {}});
    cases.push_back({"thermal", {}, {{{Effect::kThermalDrift, -1, 0}, {40e-6 * f, 2400.0}}}});
    cases.push_back({"backlash", {}, {{{Effect::kBacklash, 1 + s, 0}, {0.01 * kDeg * f}}}});
  }
  cases.push_back({"all at once", {0, 3e-6, 4e-6, 0, 0, 0},
                   {{{Effect::kThermalDrift, -1, 0}, {50e-6, 2400.0}}, {{Effect::kBacklash, 2, 0}, {0.012 * kDeg}}}});
  for (size_t c = 0; c < cases.size(); ++c) {
    RobotLogSpec spec = Ur10Spec();
    spec.masses = &ur10;
    spec.compliance = cases[c].compliance;
    if (cases[c].what == "all at once") {
      spec.dh_length_sigma_m = 0.05e-3;
      spec.dh_angle_sigma_rad = 5e-5;
      spec.poses = 60;
    }
    const uint64_t seed = 5000 + c;
    const RobotLog log = MakeRobotLog(ur10, seed, cases[c].hidden, spec);
    const RobotAuditResult res = AuditRobot(ur10, log);
    const std::string what = "UR10-like " + cases[c].what + " seed " + std::to_string(seed);
    EXPECT_TRUE(SaysNote(res.report, {"the links' masses are the robot file's", "only its compliance is fitted"}))
        << res.report.Text();
    std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
    for (size_t j = 0; j < cases[c].compliance.size(); ++j) {
      if (cases[c].compliance[j] <= 0) continue;
      const Hidden h{{Effect::kGravityCompliance, static_cast<int>(j), 0}, {cases[c].compliance[j]}};
      const AuditEffect* e = Find(res.report, h.ext);
      ASSERT_NE(e, nullptr) << what << ": " << h.ext.Label() << " not named\n" << res.report.Text();
      ExpectSizes(*e, h, what);
    }
    for (const Hidden& h : cases[c].hidden) {
      const AuditEffect* e = Find(res.report, h.ext);
      ASSERT_NE(e, nullptr) << what << ": " << h.ext.Label() << " not named\n" << res.report.Text();
      ExpectSizes(*e, h, what);
    }
    // Nothing else but geometry.
    for (const auto& e : res.report.effects) {
      bool expected = e.name == "geometry" || e.name == "joint_offset" || e.name == "link_length" ||
                      e.name == "link_twist";
      for (size_t j = 0; j < cases[c].compliance.size(); ++j)
        expected |= cases[c].compliance[j] > 0 && e.name == "gravity_compliance" &&
                    e.where == "joint " + std::to_string(j + 1);
      for (const Hidden& h : cases[c].hidden) expected |= e.name == Name(h.ext.effect) && e.where == h.ext.Where();
      EXPECT_TRUE(expected) << what << ": " << e.name << " at " << e.where << " named";
      if (cases[c].what != "all at once") {
        EXPECT_FALSE(e.name == "geometry" || e.name == "link_twist") << what << ": " << e.name << " named";
      }
    }
  }
}

// A robot as real ones are: every DH parameter a little off, the arm's own weight (link
// masses whose centres of mass are off the DH frames' origins, some behind the joint like
// a counterweight, which the lumped model of a robot file without masses only
// approximates) deflecting compliant joints 2 and 3, a warm-up on some logs, a payload
// column on some. Geometry and gravity are named on every seed; the flexible error motion,
// backlash and the other effects never.
TEST(RobotAudit, RealisticRobotEveryErrorAtOnce) {
  const RobotModel robot = RobotModel::Default();
  std::vector<Joint> j = robot.Joints();
  const double m[6] = {25.0, 18.0, 12.0, 4.0, 2.0, 0.5};
  const Vec3 c[6] = {{-0.09, 0.1, 0.0}, {-0.3, 0.0, 0.05}, {-0.05, 0.0, 0.2},
                     {0.0, -0.1, 0.0},  {0.0, 0.0, 0.02},  {0.0, 0.0, -0.02}};
  for (int k = 0; k < 6; ++k) {
    j[k].mass_kg = m[k];
    j[k].com_m = c[k];
  }
  const RobotModel massed = robot.WithJoints(j);
  for (int s = 0; s < 6; ++s) {
    RobotLogSpec spec;
    spec.masses = &massed;
    spec.compliance = {0, 1.5e-6, 2.5e-6, 0, 0, 0};
    spec.dh_length_sigma_m = 0.05e-3;
    spec.dh_angle_sigma_rad = 5e-5;
    spec.payload_column = s % 2 == 0;
    std::vector<Hidden> hidden;
    if (s >= 3) hidden.push_back({{Effect::kThermalDrift, -1, 0}, {40e-6, 2400.0}});
    const RobotAuditResult res = AuditRobot(robot, MakeRobotLog(robot, 8800 + s, hidden, spec));
    const std::string what = "realistic KR 5 arc seed " + std::to_string(8800 + s);
    std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
    bool geometry = false, gravity = false;
    const auto Allowed = [&](const std::string& name) {
      return Geometric(name) || name == "gravity_compliance" || name == "thermal_drift" || name == "joint_scale";
    };
    for (const auto& e : res.report.effects) {
      geometry |= Geometric(e.name);
      gravity |= e.name == "gravity_compliance";
      EXPECT_TRUE(Allowed(e.name)) << what << ": " << e.name << " at " << e.where << " named";
    }
    for (const auto& g : res.report.undecided)
      for (const auto& l : g) {
        gravity |= l.rfind("gravity_compliance", 0) == 0;
        EXPECT_TRUE(Allowed(l.substr(0, l.find(" at ")))) << what << ": undecided " << l;
      }
    EXPECT_TRUE(geometry) << what;
    EXPECT_TRUE(gravity) << what;
  }
}

// A wrist joint offset that a link length mimics on the logged poses (the wrist barely
// moves): undecided with both sizes, and the proposed poses, measured, name the true one.
TEST(RobotAudit, TieIsReportedAndTheProposedPosesSeparateIt) {
  const RobotModel robot = RobotModel::Default();
  RobotLogSpec spec;
  spec.lo = {-1.2, -1.6, 0.2, -0.4, 0.6, -0.4};
  spec.hi = {1.2, 0.4, 2.2, 0.4, 1.4, 0.4};
  const Hidden h{{Effect::kJointOffset, 4, 0}, {0.04 * kDeg}};
  test::RobotTruth truth;
  const RobotLog log = MakeRobotLog(robot, 6100, {h}, spec, &truth);
  RobotAuditOptions o;
  const RobotAuditResult res = AuditRobot(robot, log, o);
  std::printf("%s", res.report.Text().c_str());
  ASSERT_EQ(Find(res.report, h.ext), nullptr) << "the logged poses were meant to leave a tie";
  ASSERT_TRUE(InUndecided(res.report, h.ext)) << res.report.Text();
  ASSERT_EQ(res.report.undecided.size(), res.report.undecided_effects.size());
  for (const auto& g : res.report.undecided_effects) {
    ASSERT_GE(g.size(), 2u);
    for (const auto& e : g) EXPECT_FALSE(e.parameters.empty()) << "an undecided candidate without its size";
  }
  ASSERT_FALSE(res.next_poses.empty());
  // The proposed poses decide, measured as many times as the audit says, with everything
  // refitted: the noncentrality then reaches what the tie band needs (measured below).
  const auto& np = res.next_poses.front();
  ASSERT_GT(np.readings, 0);
  EXPECT_GE(np.noncentrality, np.noncentrality_needed);
  EXPECT_LT(np.noncentrality_logged, np.noncentrality_needed) << "the logged rows alone were undecided";
  // The CSV the command writes.
  const auto csv = std::filesystem::temp_directory_path() / "mcms_test_next_poses.csv";
  WriteNextPoses(csv, res, robot);
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header.rfind("pair,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad,x_a_m", 0), 0u) << header;
  std::filesystem::remove(csv);
  ExpectNamedOrSeparated(robot, res, h, truth, log, o, "wrist offset tie", 6100);
}

// Designed: a clean log is called not clean with probability at most 1 % (Bonferroni over
// the residual tests and the candidates). Observed over 100 seeds of each robot: the count
// must be consistent with it, P(X >= 5 | n = 100, p = 0.01) = 0.0034.
TEST(RobotAudit, CleanLogsAreCleanAtTheDesignedRate) {
  const RobotModel kr5 = RobotModel::Default(), ur10 = Ur10Like();
  for (int robot = 0; robot < 2; ++robot) {
    int alarms = 0;
    const int kRuns = 100;
    RobotLogSpec spec = robot == 0 ? RobotLogSpec{} : Ur10Spec();
    spec.poses = 30;
    spec.repeats = 3;
    const RobotModel& r = robot == 0 ? kr5 : ur10;
    for (int s = 0; s < kRuns; ++s) {
      const RobotLog log = MakeRobotLog(r, 50000 + 1000 * robot + s, {}, spec);
      const RobotAuditResult res = AuditRobot(r, log);
      if (!res.report.clean) {
        ++alarms;
        std::printf("clean %s seed %d called not clean:\n%s", r.Name().c_str(), 50000 + 1000 * robot + s,
                    res.report.Text().c_str());
      }
    }
    std::printf("%s: false alarms: %d of %d clean logs (designed rate 1 %%)\n", r.Name().c_str(), alarms, kRuns);
    EXPECT_LE(alarms, 4) << r.Name();
  }
}

// A URDF robot (tests/urdf_robots.h: a prismatic lift and six revolute joints, masses from
// its inertials, branches off the chain carrying mass): every placement a little off (the
// URDF error model: offsets and 6-D placement errors) and joint j2 compliant under the arm's
// weight. Geometry and the compliance are named, the compliance at j2 within 3 sigma;
// nothing else. Clean logs of it are clean at the designed rate.
using test::SevenJoints;
using test::SevenSpec;

TEST(RobotAudit, UrdfRobotWithPlacementErrorsAndTheArmsWeight) {
  const RobotModel seven = SevenJoints();
  ASSERT_TRUE(seven.HasMasses());
  for (uint64_t seed : {6100u, 6101u}) {
    RobotLogSpec spec = SevenSpec();
    spec.masses = &seven;
    spec.compliance = {0, 0, 2e-5, 0, 0, 0, 0};
    spec.dh_length_sigma_m = 0.05e-3;
    spec.dh_angle_sigma_rad = 5e-5;
    spec.poses = 60;
    const RobotLog log = MakeRobotLog(seven, seed, {}, spec);
    const RobotAuditResult res = AuditRobot(seven, log);
    const std::string what = "seven-joint URDF seed " + std::to_string(seed);
    std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
    const Hidden h{{Effect::kGravityCompliance, 2, 0}, {2e-5}};
    const AuditEffect* e = Find(res.report, Name(h.ext.effect), "j2");
    ASSERT_NE(e, nullptr) << what << ": gravity_compliance at j2 not named\n" << res.report.Text();
    ExpectSizes(*e, h, what);
    for (const auto& x : res.report.effects) {
      const bool expected = x.name == "geometry" || x.name == "joint_offset" ||
                            (x.name == "gravity_compliance" && x.where == "j2");
      EXPECT_TRUE(expected) << what << ": " << x.name << " at " << x.where << " named";
    }
  }
}

// What the real TIAGo shows (docs/tiago.md), simulated on the seven-joint URDF robot: its
// geometry a little off, a joint compliant under the arm's weight, and backlash at a wrist
// joint by approach direction, all at once. Both physical terms named at the right joint
// within 3 sigma of the truth; nothing else but geometry.
TEST(RobotAudit, UrdfRobotWithWristBacklashAndTheArmsWeight) {
  const RobotModel seven = SevenJoints();
  // Backlash at j4 on two seeds, and at j3 on a third. (At j5 this log cannot see it: the tool
  // point lies on j5's axis, its offset is a combination of the tool's; on seed 6201 the
  // arm's weight at j2 was named error_motion at j2 there before the flexible family was
  // re-tested after every accepted effect (issue 35); now gravity_compliance at j2 replaces
  // it, paired z -3.25 in its favour.)
  const std::pair<uint64_t, int> cases[] = {{6200u, 4}, {6201u, 4}, {6202u, 3}};
  for (const auto& [seed, bj] : cases) {
    RobotLogSpec spec = SevenSpec();
    spec.masses = &seven;
    spec.compliance = {0, 0, 2e-5, 0, 0, 0, 0};
    spec.dh_length_sigma_m = 0.05e-3;
    spec.dh_angle_sigma_rad = 5e-5;
    spec.poses = 100;
    const Hidden backlash{{Effect::kBacklash, bj, 0}, {2e-3}};
    const RobotLog log = MakeRobotLog(seven, seed, {backlash}, spec);
    const RobotAuditResult res = AuditRobot(seven, log);
    const std::string jb = "j" + std::to_string(bj);
    const std::string what = "seven-joint URDF with backlash at " + jb + " seed " + std::to_string(seed);
    std::printf("%s:\n%s", what.c_str(), res.report.Text().c_str());
    const AuditEffect* b = Find(res.report, "backlash", jb);
    ASSERT_NE(b, nullptr) << what << ": backlash at " << jb << " not named\n" << res.report.Text();
    ExpectSizes(*b, backlash, what);
    const Hidden compliance{{Effect::kGravityCompliance, 2, 0}, {2e-5}};
    const AuditEffect* c = Find(res.report, "gravity_compliance", "j2");
    ASSERT_NE(c, nullptr) << what << ": gravity_compliance at j2 not named\n" << res.report.Text();
    ExpectSizes(*c, compliance, what);
    for (const auto& x : res.report.effects) {
      const bool expected = x.name == "geometry" || x.name == "joint_offset" ||
                            (x.name == "gravity_compliance" && x.where == "j2") ||
                            (x.name == "backlash" && x.where == jb);
      EXPECT_TRUE(expected) << what << ": " << x.name << " at " << x.where << " named";
    }
  }
}

// Issue 35 item 1: a compliance is bounded by what a joint can physically sag (0.1 rad at
// the largest gravity torque of the log). A joint that sags twice that is not "compliant".
// Issue 51: an effect at its physical bound is no finding: never named, and the report says
// the data ask for more than the physical effect can be.
TEST(RobotAudit, ASagBeyondAnyGearboxIsAtItsBoundNotAFinding) {
  const RobotModel seven = SevenJoints();
  RobotLogSpec spec = SevenSpec();
  spec.masses = &seven;
  spec.poses = 60;
  // The largest gravity torque on j2 over the poses this spec draws.
  const RobotLog probe = MakeRobotLog(seven, 6300, {}, spec);
  double torque = 0;
  for (const auto& r : probe.rows)
    torque = std::max(torque, std::abs(GravityTorque(seven, r.q, spec.payload_kg)[2]));
  ASSERT_GT(torque, 1.0);
  spec.compliance = {0, 0, 1.2 * kMaxGravityDeflectionRad / torque, 0, 0, 0, 0};
  const RobotLog log = MakeRobotLog(seven, 6300, {}, spec);
  const RobotAuditResult res = AuditRobot(seven, log);
  std::printf("largest j2 torque %.1f N m, compliance %.3g rad/(N m):\n%s", torque, spec.compliance[2],
              res.report.Text().c_str());
  EXPECT_EQ(Find(res.report, "gravity_compliance", "j2"), nullptr) << res.report.Text();
  bool said = false;
  for (const auto& n : res.report.notes)
    said |= n.find("gravity_compliance at j2 is at its physical bound") != std::string::npos &&
            n.find("not a finding") != std::string::npos;
  EXPECT_TRUE(said) << res.report.Text();
  for (const AuditEffect& e : res.report.effects) EXPECT_TRUE(e.held.empty() || e.name == "geometry") << e.name;
}

TEST(RobotAudit, CleanLogsOfAUrdfRobotAreCleanAtTheDesignedRate) {
  const RobotModel seven = SevenJoints();
  int alarms = 0;
  const int kRuns = 100;
  RobotLogSpec spec = SevenSpec();
  spec.poses = 30;
  spec.repeats = 3;
  spec.masses = &seven;
  for (int s = 0; s < kRuns; ++s) {
    const RobotLog log = MakeRobotLog(seven, 56000 + s, {}, spec);
    const RobotAuditResult res = AuditRobot(seven, log);
    if (!res.report.clean) {
      ++alarms;
      std::printf("clean seven-joint URDF seed %d called not clean:\n%s", 56000 + s, res.report.Text().c_str());
    }
  }
  std::printf("seven-joint URDF: false alarms: %d of %d clean logs (designed rate 1 %%)\n", alarms, kRuns);
  EXPECT_LE(alarms, 4);
}

// Another design of log: 80 poses x 5 repeats one after the other, noise growing with the
// distance from the base (1x at 1 m, 1.5x at 2 m), no payload column: still clean.
TEST(RobotAudit, CleanLogsOfAnotherDesign) {
  int alarms = 0;
  RobotLogSpec spec;
  spec.poses = 80;
  spec.repeats = 5;
  spec.consecutive = true;
  spec.heteroscedastic = 0.5;
  spec.payload_column = false;
  for (int s = 0; s < 20; ++s) {
    const RobotLog log = MakeRobotLog(RobotModel::Default(), 70000 + s, {}, spec);
    const RobotAuditResult res = AuditRobot(RobotModel::Default(), log);
    if (!res.report.clean) {
      ++alarms;
      std::printf("clean seed %d (other design) called not clean:\n%s", 70000 + s, res.report.Text().c_str());
    }
  }
  std::printf("false alarms: %d of 20 clean logs of another design\n", alarms);
  EXPECT_LE(alarms, 2);
}

// The noise is estimated, not given: a log with 10x the noise gives the same verdict on a
// clean log and reports the noise it found.
TEST(RobotAudit, EstimatesAnisotropicNoise) {
  RobotLogSpec spec;
  spec.noise_mm = Vec3(0.1, 0.2, 0.5);
  const RobotLog log = MakeRobotLog(RobotModel::Default(), 31, {}, spec);
  const RobotAuditResult res = AuditRobot(RobotModel::Default(), log);
  EXPECT_TRUE(res.report.clean) << res.report.Text();
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(res.nominal.noise).eigenvalues();
  // Eigenvalues of the noise covariance (the noise frame is rotated): 0.1, 0.2, 0.5 mm.
  EXPECT_NEAR(std::sqrt(ev[0]) * 1e3, 0.1, 0.03);
  EXPECT_NEAR(std::sqrt(ev[1]) * 1e3, 0.2, 0.05);
  EXPECT_NEAR(std::sqrt(ev[2]) * 1e3, 0.5, 0.1);
}

// Gravity that pushes the wrong way (a counterbalance spring stronger than the arm's
// weight, or masses in the robot file that are too large): no negative stiffness is
// named; the report says what the data asked for.
TEST(RobotAudit, ComplianceBoundTheDataViolateIsSaid) {
  const RobotModel ur10 = Ur10Like();
  RobotLogSpec spec = Ur10Spec();
  spec.masses = &ur10;
  spec.compliance = {0, -4e-6, 0, 0, 0, 0};
  const RobotLog log = MakeRobotLog(ur10, 7001, {}, spec);
  const RobotAuditResult res = AuditRobot(ur10, log);
  std::printf("%s", res.report.Text().c_str());
  for (const auto& e : res.report.effects) {
    if (e.name != "gravity_compliance") continue;
    for (const auto& [name, v] : e.parameters) EXPECT_GE(v, 0.0) << "negative " << name << " named";
  }
  bool said = false;
  for (const auto& n : res.report.notes)
    said |= n.find("gravity_compliance at joint 2") != std::string::npos && n.find("sign no joint") != std::string::npos;
  EXPECT_TRUE(said) << "the negative compliance the data ask for is not said\n" << res.report.Text();
}

TEST(RobotAudit, RefusesBadMassesInTheRobotFile) {
  const std::string base = R"(name: m
convention: standard_dh
joints:
  - {name: J1, d_m: 0.3, a_m: 0.0, alpha_deg: 90, theta_offset_deg: 0, mass_kg: MASS1, com_m: [0, 0, 0]}
  - {name: J2, d_m: 0.0, a_m: 0.5, alpha_deg: 0, theta_offset_deg: 0 MASS2}
)";
  const auto With = [&](const std::string& m1, const std::string& m2) {
    std::string s = base;
    s.replace(s.find("MASS1"), 5, m1);
    s.replace(s.find(" MASS2"), 6, m2);
    return s;
  };
  const auto Err = [&](const std::string& text) {
    return test::ErrorOf([&] { RobotModel::Parse(text, "robot file r.yaml"); });
  };
  EXPECT_NO_THROW(RobotModel::Parse(With("5.0", ", mass_kg: 2.0, com_m: [0.2, 0, 0]"), "r"));
  const std::string nan = Err(With(".nan", ", mass_kg: 2.0"));
  EXPECT_NE(nan.find("r.yaml"), std::string::npos) << nan;
  EXPECT_NE(nan.find("mass_kg"), std::string::npos) << nan;
  const std::string neg = Err(With("-3", ", mass_kg: 2.0"));
  EXPECT_NE(neg.find("mass_kg must be >= 0"), std::string::npos) << neg;
  EXPECT_NE(neg.find("line 4"), std::string::npos) << neg;
  const std::string part = Err(With("5.0", ""));
  EXPECT_NE(part.find("mass_kg is given for 1 of 2 joints"), std::string::npos) << part;
  const std::string com = Err(With("5.0", ", mass_kg: 2.0, com_m: [0, .inf, 0]"));
  EXPECT_NE(com.find("com_m"), std::string::npos) << com;
}

TEST(RobotAudit, RefusesBadLogs) {
  const RobotModel robot = RobotModel::Default();
  RobotLog log = MakeRobotLog(robot, 5, {});
  RobotLog one = log;
  one.rows.resize(1);
  EXPECT_THROW(AuditRobot(robot, one), InputError);
  RobotLog back = log;
  back.rows[7].time_s = back.rows[6].time_s - 1.0;
  try {
    AuditRobot(robot, back);
    ADD_FAILURE() << "time going backwards accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("time order"), std::string::npos) << e.what();
  }
  RobotLog out = log;
  out.rows[3].q[1] = 2.0;  // A2 beyond +65 deg
  EXPECT_THROW(AuditRobot(robot, out), InputError);
  RobotLog joints = log;
  for (auto& r : joints.rows) r.q.conservativeResize(5);
  EXPECT_THROW(AuditRobot(robot, joints), InputError);
}

// Real data: the two-axis positioner of ROS-Industrial (205 6-D measurements). calib-robot
// found a residual that is a function of q2 that no DH table represents (turntable
// wobble): the audit must name error motion of joint 2.
TEST(RobotAudit, RealPositionerErrorMotion) {
  MCMS_REQUIRE_DATA(dir, "industrial-calibration-positioner");
  const YAML::Node g = YAML::LoadFile((dir / "pose_initial_guesses.yaml").string());
  const RobotModel robot = test::Positioner(test::ReadGuess(g["target_mount_to_target_guess"]));
  RobotAuditOptions o;
  o.base_guess = test::PositionerBaseGuess(g);
  const RobotLog log = ReadRobotLog(dir / "measurements.yaml", robot);
  const RobotAuditResult res = AuditRobot(robot, log, o);
  std::printf("%s", res.report.Text().c_str());
  EXPECT_FALSE(res.report.clean);
  bool em2 = false;
  for (const auto& e : res.report.effects) em2 |= e.name == "error_motion" && e.where == "joint 2";
  for (const auto& g2 : res.report.undecided)
    for (const auto& l : g2) em2 |= l.rfind("error_motion at joint 2", 0) == 0;
  EXPECT_TRUE(em2) << "error motion of joint 2 not named";
  // Issue 51: no nested fit below the model it extends on this real robot either.
  EXPECT_EQ(res.report.nested.failed, 0);
  EXPECT_GE(res.report.nested.worst_relative_lr, -NestedFits::kTolerance);
}

}  // namespace
}  // namespace mcms

