// Issue 52: the tilt sensors of a robot's chain audited against their forward model
// (audit/tilt_sensor_audit.h) on a simulated column robot: a tracked base with a tilt
// sensor, a prismatic column with a sensor at its top, a three-joint arm with masses. The
// simulation below writes its own bending (the moment computed here from the links'
// masses, not by the model's function) and reads the sensors as accelerometers with the
// ADXL355's noise (4.4e-4 m/s^2 per axis); each effect is hidden alone and two at once and
// must be named at its link, within 3 sigma of its size; clean logs at the designed rate.
#include <cmath>
#include <cstdio>
#include <algorithm>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "audit/tilt_sensor_audit.h"
#include "core/pose_math.h"
#include "core/random.h"
#include "model/robot_measurements.h"
#include "model/robot_model.h"
#include "model/urdf.h"
#include "model/tilt_sensor.h"
#include "test_util.h"

namespace mcms {
namespace {

std::string ColumnRobotUrdf() {
  return R"(<?xml version="1.0"?>
<robot name="column_robot">
  <link name="base_link"><inertial><mass value="300"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="base_sensor_joint" type="fixed"><parent link="base_link"/><child link="tilt_sensor_base"/>
    <origin xyz="0.2 0.1 0.1" rpy="0 0 1.2"/></joint>
  <link name="tilt_sensor_base"/>
  <joint name="column_joint" type="prismatic"><parent link="base_link"/><child link="column_top"/>
    <origin xyz="0 0 0.9"/><axis xyz="0 0 1"/><limit lower="0" upper="2.0" effort="1000" velocity="0.1"/></joint>
  <link name="column_top"><inertial><origin xyz="0 0 -0.3"/><mass value="20"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="column_sensor_joint" type="fixed"><parent link="column_top"/><child link="tilt_sensor_column_tip"/>
    <origin xyz="0.05 0 0.02" rpy="0 0 -0.4"/></joint>
  <link name="tilt_sensor_column_tip"/>
  <joint name="j1" type="revolute"><parent link="column_top"/><child link="l1"/>
    <origin xyz="0 0 0.15"/><axis xyz="0 0 1"/><limit lower="-3.1" upper="3.1" effort="100" velocity="1"/></joint>
  <link name="l1"><inertial><origin xyz="0.1 0 0.05"/><mass value="8"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0.1"/><axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="100" velocity="1"/></joint>
  <link name="l2"><inertial><origin xyz="0.3 0 0"/><mass value="10"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.6 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="100" velocity="1"/></joint>
  <link name="l3"><inertial><origin xyz="0.25 0 0"/><mass value="5"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="tool_joint" type="fixed"><parent link="l3"/><child link="prism"/><origin xyz="0.5 0 0"/></joint>
  <link name="prism"/>
</robot>)";
}

const RobotModel& ColumnRobot() {
  static const RobotModel robot = [] {
    const auto dir = test::ScratchDir("column_robot");
    test::WriteText(dir / "column.urdf", ColumnRobotUrdf());
    RobotModel r = RobotModel::Read(dir / "column.urdf", {"", "prism"});
    std::filesystem::remove_all(dir);
    return r;
  }();
  return robot;
}

// What is hidden in a simulated log.
struct Hidden {
  double compliance = 0.0;  // rad per N m^2: tilt = c L M_h
  double play = 0.0;        // rad, with the sign of the moment
  // Telescopic play: (a_x s_x, a_y s_y) / (overlap + travel left)^2 rad, s the unit
  // horizontal moment, the travel left to the column's upper limit (2 m).
  Vec2 telescopic = Vec2::Zero();  // rad m^2
  double overlap = 0.15;           // m, left at full extension
  Vec2 bias = Vec2::Zero();     // the column sensor's tilts (rad)
  Vec3 misalignment = Vec3::Zero();  // the column sensor's mounting rotation (column_top frame, rad)
};

// The moment of the arm's weight about the column top (base frame), from the links' masses
// and centres of mass as the URDF above gives them (written here, not the model's).
Vec3 ArmMoment(const RobotModel& r, const Eigen::VectorXd& q) {
  const std::vector<Pose> f = r.LinkFrames(q);
  const struct {
    int frame;
    double m;
    Vec3 c;
  } links[] = {{2, 8.0, Vec3(0.1, 0, 0.05)}, {3, 10.0, Vec3(0.3, 0, 0)}, {4, 5.0, Vec3(0.25, 0, 0)}};
  Vec3 M = Vec3::Zero();
  for (const auto& l : links) M += (f[l.frame] * l.c - f[1].t).cross(Vec3(0, 0, -l.m * kStandardGravity));
  return M;
}

// Stations at column heights uniform in [0.1, top] m (the column's travel is 2 m).
RobotLog Simulate(const Hidden& h, uint64_t seed, int stations = 6, int per_station = 40, double top = 1.9) {
  const RobotModel& r = ColumnRobot();
  Rng rng(seed);
  RobotLog log;
  log.source = std::string("column_robot_").append(std::to_string(seed)).append(".csv");
  log.has_time = true;
  const double sigma_a = 4.3610059e-4;
  const Mat3 R_top_sensor = ExpSO3(Vec3(0, 0, -0.4));
  const Mat3 R_base_bsensor = ExpSO3(Vec3(0, 0, 1.2));
  double t = 0;
  for (int s = 0; s < stations; ++s) {
    // Soft ground: each station's base tilted by up to 15 mrad.
    const Mat3 R_world_base = ExpSO3(Vec3(rng.Uniform(-0.015, 0.015), rng.Uniform(-0.015, 0.015), rng.Uniform(-3, 3)));
    const double height = rng.Uniform(0.1, top);
    for (int k = 0; k < per_station; ++k) {
      Eigen::VectorXd q(4);
      q << height, rng.Uniform(-3.0, 3.0), rng.Uniform(-1.2, 1.2), rng.Uniform(-1.8, 1.8);
      const std::vector<Pose> f = r.LinkFrames(q);
      const Vec3 M = ArmMoment(r, q);
      const Vec3 Mh(M.x(), M.y(), 0.0);
      const double L = (f[1].t - f[0].t).norm();
      Vec3 beta = h.compliance * L * Mh;
      if (Mh.norm() > 1e-9) beta += h.play * Mh.normalized();
      if (Mh.norm() > 1e-9) {
        const double l = h.overlap + (2.0 - height);
        beta += Vec3(h.telescopic.x() * Mh.x(), h.telescopic.y() * Mh.y(), 0.0) / (Mh.norm() * l * l);
      }
      const Mat3 R_world_top = R_world_base * ExpSO3(beta) * f[1].R;
      const Mat3 R_world_csensor = R_world_top * ExpSO3(h.misalignment) * R_top_sensor;
      const Mat3 R_world_bsensor = R_world_base * R_base_bsensor;
      const Vec3 up(0, 0, kStandardGravity);
      Vec3 ac = R_world_csensor.transpose() * up;
      // A bias of the sensor's tilts: its up leans by them.
      ac.x() += kStandardGravity * std::sin(h.bias.x());
      ac.y() += kStandardGravity * std::sin(h.bias.y());
      Vec3 ab = R_world_bsensor.transpose() * up;
      for (int a = 0; a < 3; ++a) ac[a] += rng.Normal(0, sigma_a), ab[a] += rng.Normal(0, sigma_a);
      RobotMeasurement m;
      m.q = q;
      m.time_s = t;
      t += 6.0;
      m.station = std::string("s").append(std::to_string(s));  // (GCC 12 -Wrestrict misfires on "s" + ...)
      m.accel = {{"tilt_sensor_base", ab}, {"tilt_sensor_column_tip", ac}};
      log.rows.push_back(m);
    }
  }
  log.has_stations = true;
  return log;
}

const AuditEffect* Named(const AuditReport& rep, const std::string& name) {
  for (const AuditEffect& e : rep.effects)
    if (e.name == name) return &e;
  return nullptr;
}

// The named effect's parameter k against the truth, within 3 sigma.
void ExpectWithin3Sigma(const AuditEffect& e, size_t k, double truth, const std::string& what) {
  ASSERT_LT(k, e.parameters.size()) << what;
  const double v = e.parameters[k].second, s = e.sigma[k].second;
  EXPECT_GT(s, 0.0) << what;
  EXPECT_LT(std::abs(v - truth), 3 * s) << what << ": " << v << " +- " << s << " against " << truth;
}

TEST(TiltSensors, MountsAndTheCarriedMomentOfTheColumnRobot) {
  const RobotModel& r = ColumnRobot();
  ASSERT_EQ(r.NumJoints(), 4);
  EXPECT_EQ(MountOnChain(r, "tilt_sensor_column_tip").frame, 1);
  EXPECT_EQ(MountOnChain(r, "tilt_sensor_base").frame, 0);
  Rng rng(7);
  for (int k = 0; k < 20; ++k) {
    Eigen::VectorXd q(4);
    q << rng.Uniform(0, 2), rng.Uniform(-3, 3), rng.Uniform(-1.5, 1.5), rng.Uniform(-2, 2);
    EXPECT_LT((CarriedMoment(r, q, 1) - ArmMoment(r, q)).norm(), 1e-9);
  }
}

struct Case {
  const char* name;
  Hidden hidden;
  std::vector<const char*> named;  // in any order
};

void PrintTo(const Case& c, std::ostream* os) { *os << c.name; }

class HiddenTilt : public ::testing::TestWithParam<Case> {};

TEST_P(HiddenTilt, IsNamedAtItsLinkWithin3Sigma) {
  const Case& c = GetParam();
  for (uint64_t seed : {11u, 12u, 13u}) {
    const RobotLog log = Simulate(c.hidden, seed);
    const auto res = AuditTiltSensors(ColumnRobot(), log);
    ASSERT_EQ(res.size(), 1u);
    const TiltSensorAuditResult& t = res[0];
    EXPECT_EQ(t.sensor, "tilt_sensor_column_tip");
    EXPECT_EQ(t.reference, "tilt_sensor_base");
    const std::string text = TiltSensorAuditText(res, ColumnRobot());
    const std::string what = std::string(c.name) + " seed " + std::to_string(seed) + "\n" + text;
    EXPECT_EQ(t.report.effects.size(), c.named.size()) << what;
    for (const char* n : c.named) {
      const AuditEffect* e = Named(t.report, n);
      ASSERT_TRUE(e) << n << " not named: " << what;
      if (std::string(n) == "link_compliance") {
        EXPECT_EQ(e->where, "column_joint") << what;
        ExpectWithin3Sigma(*e, 0, c.hidden.compliance, what);  // the column's section: the same both ways
        ExpectWithin3Sigma(*e, 1, c.hidden.compliance, what);
      } else if (std::string(n) == "segment_play") {
        EXPECT_EQ(e->where, "column_joint") << what;
        if (c.hidden.play > 0) {  // a constant step: variant 0
          ASSERT_EQ(e->parameters.size(), 1u) << what;
          ExpectWithin3Sigma(*e, 0, c.hidden.play, what);
        } else {  // telescopic: variant 1
          ASSERT_EQ(e->parameters.size(), 3u) << what;
          ExpectWithin3Sigma(*e, 0, c.hidden.telescopic.x(), what);
          ExpectWithin3Sigma(*e, 1, c.hidden.telescopic.y(), what);
          ExpectWithin3Sigma(*e, 2, c.hidden.overlap, what);
        }
      } else if (std::string(n) == "inclinometer_bias") {
        EXPECT_EQ(e->where, "tilt_sensor_column_tip") << what;
        ExpectWithin3Sigma(*e, 0, c.hidden.bias.x(), what);
        ExpectWithin3Sigma(*e, 1, c.hidden.bias.y(), what);
      } else if (std::string(n) == "inclinometer_misalignment") {
        EXPECT_EQ(e->where, "tilt_sensor_column_tip") << what;
        ExpectWithin3Sigma(*e, 0, c.hidden.misalignment.z(), what);  // the sensor's z is column_top's
      }
    }
    // After the model, the tilt residuals are in band.
    EXPECT_TRUE(t.report.tests_after.empty()) << what;
    EXPECT_NEAR(std::sqrt(t.noise(0, 0)), 4.3610059e-4 / kStandardGravity * std::sqrt(2.0), 1.5e-5) << what;
    EXPECT_GE(t.report.nested.count, 1) << what;
    EXPECT_EQ(t.report.nested.failed, 0) << what;
  }
}

Hidden Compliance() {
  Hidden h;
  h.compliance = 4e-6;  // 150 N m over 1.5 m: 0.9 mrad
  return h;
}
Hidden Play() {
  Hidden h;
  h.play = 3e-4;
  return h;
}
Hidden TelescopicPlay() {
  Hidden h;
  h.telescopic = Vec2(3e-5, 6e-5);  // 0.5 / 1 mrad at full extension, 0.01 / 0.01 at the bottom
  return h;
}
Hidden CompliancePlusTelescopicPlay() {
  Hidden h = Compliance();
  h.telescopic = TelescopicPlay().telescopic;
  return h;
}
Hidden Bias() {
  Hidden h;
  h.bias = Vec2(6e-4, -4e-4);
  return h;
}
Hidden Misaligned() {
  Hidden h;
  h.misalignment = Vec3(0, 0, 0.06);  // turned about its vertical: what only a misalignment does
  return h;
}
Hidden CompliancePlusBias() {
  Hidden h = Compliance();
  h.bias = Bias().bias;
  return h;
}
Hidden PlayPlusMisaligned() {
  Hidden h = Play();
  h.misalignment = Misaligned().misalignment;
  return h;
}
Hidden CompliancePlusPlay() {
  Hidden h = Compliance();
  h.play = Play().play;
  return h;
}

INSTANTIATE_TEST_SUITE_P(
    Column, HiddenTilt,
    ::testing::Values(Case{"compliance", Compliance(), {"link_compliance"}}, Case{"play", Play(), {"segment_play"}},
                      Case{"bias", Bias(), {"inclinometer_bias"}},
                      Case{"misalignment", Misaligned(), {"inclinometer_misalignment"}},
                      Case{"compliance_and_bias", CompliancePlusBias(), {"link_compliance", "inclinometer_bias"}},
                      Case{"play_and_misalignment", PlayPlusMisaligned(), {"segment_play", "inclinometer_misalignment"}},
                      Case{"compliance_and_play", CompliancePlusPlay(), {"link_compliance", "segment_play"}},
                      Case{"telescopic_play", TelescopicPlay(), {"segment_play"}},
                      Case{"compliance_and_telescopic_play", CompliancePlusTelescopicPlay(),
                           {"link_compliance", "segment_play"}}),
    [](const ::testing::TestParamInfo<Case>& i) { return std::string(i.param.name); });

// A telescopic play where few stations come near full extension (heights up to 1.7 m of
// the 2 m travel; eight stations of 15 rows, 40 logs): the play is small there and the stations'
// heights do not place the overlap. It is not replaced by a compliance: the play is named
// with its overlap held (not a named value), or the audit says it cannot tell it from
// another cause, or it is too small to see; never another cause named in its place.
TEST(TiltSensors, TelescopicPlayBelowFullExtensionIsNotTakenForACompliance) {
  int named = 0, undecided = 0, unseen = 0;
  for (uint64_t seed = 11; seed < 51; ++seed) {
    const auto res = AuditTiltSensors(ColumnRobot(), Simulate(TelescopicPlay(), seed, 8, 15, 1.7));
    ASSERT_EQ(res.size(), 1u);
    const AuditReport& rep = res[0].report;
    const std::string what = "seed " + std::to_string(seed) + "\n" + TiltSensorAuditText(res, ColumnRobot());
    for (const AuditEffect& e : rep.effects) {
      EXPECT_EQ(e.name, "segment_play") << what;
      for (const auto& [n, s] : e.sigma) EXPECT_GT(s, 0.0) << n << ": " << what;
    }
    if (const AuditEffect* p = Named(rep, "segment_play")) {
      ++named;
      bool overlap_named = false;
      for (const auto& [n, v] : p->parameters) overlap_named |= n == "overlap_at_full_extension_m";
      if (overlap_named) {
        ExpectWithin3Sigma(*p, 2, TelescopicPlay().overlap, what);
      } else if (p->parameters.size() == 2) {  // telescopic, its overlap held
        bool held = false;
        for (const auto& [n, v] : p->labels) held |= n == "overlap_at_full_extension_m";
        EXPECT_TRUE(held) << what;
      }
    } else if (!rep.undecided.empty()) {
      bool play = false;
      for (const auto& g : rep.undecided)
        for (const auto& l : g) play |= l.rfind("segment_play", 0) == 0;
      EXPECT_TRUE(play) << what;
      ++undecided;
    } else {
      ++unseen;  // too small to see at these heights: nothing named, nothing wrong
    }
    EXPECT_EQ(rep.nested.failed, 0) << what;
  }
  std::printf("telescopic play below full extension: named %d, undecided %d, not seen %d of 40\n", named, undecided,
              unseen);
}

// Clean logs: nothing named and no residual test failed, at the designed 1 % (each log's
// false-alarm rate, half to the tests, half to the selection): 400 logs.
TEST(TiltSensors, CleanLogsAtTheDesignedFalseAlarmRate) {
  int alarms = 0;
  for (uint64_t seed = 100; seed < 500; ++seed) {
    const auto res = AuditTiltSensors(ColumnRobot(), Simulate({}, seed, 5, 30));
    ASSERT_EQ(res.size(), 1u);
    if (!res[0].report.clean) {
      ++alarms;
      std::printf("seed %llu: %s", static_cast<unsigned long long>(seed),
                  TiltSensorAuditText(res, ColumnRobot()).c_str());
    }
    EXPECT_EQ(res[0].report.nested.failed, 0);
    for (const auto& e : res[0].report.effects)
      for (const auto& [n, s] : e.sigma) EXPECT_GE(s, 0.0);
  }
  std::printf("clean logs not called clean: %d of 400 (designed 1 %%)\n", alarms);
  // Binomial(400, 0.01): 11 or more has probability 0.3 %.
  EXPECT_LE(alarms, 10);
}

TEST(TiltSensors, BadInputIsNamed) {
  // A robot without masses cannot say what its column carries.
  const auto dir = test::ScratchDir("column_nomass");
  std::string urdf = ColumnRobotUrdf();
  for (size_t at; (at = urdf.find("<inertial>")) != std::string::npos;)
    urdf.erase(at, urdf.find("</inertial>", at) + 11 - at);
  test::WriteText(dir / "c.urdf", urdf);
  const RobotModel r = RobotModel::Read(dir / "c.urdf", {"", "prism"});
  const std::string e = test::ErrorOf([&] { AuditTiltSensors(r, Simulate({}, 1, 2, 20)); });
  EXPECT_NE(e.find("the tilt sensor tilt_sensor_column_tip"), std::string::npos) << e;
  EXPECT_NE(e.find("gives no link masses"), std::string::npos) << e;
  // A sensor on a link the URDF lacks.
  RobotLog log = Simulate({}, 2, 2, 20);
  for (auto& row : log.rows) row.accel[1].first = "tilt_sensor_colum_tip";
  const std::string e2 = test::ErrorOf([&] { AuditTiltSensors(ColumnRobot(), log); });
  EXPECT_NE(e2.find("'tilt_sensor_colum_tip', which is not a link of the URDF"), std::string::npos) << e2;
  std::filesystem::remove_all(dir);
  TiltSensorAuditOptions o;
  o.folds = 1;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_EQ(why, "folds must be at least 2");
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// The same sensors from a CSV log (<link>_ax, _ay, _az in m/s^2): read and audited like
// the publisher's YAML; a column naming no link, a reading in g and a sensor on a link off
// the chain are one line each.
TEST(TiltSensors, ReadFromCsvColumns) {
  const auto dir = test::ScratchDir("tilt_csv");
  test::WriteText(dir / "c.urdf", ColumnRobotUrdf());
  const RobotModel& r = ColumnRobot();
  Hidden h;
  h.compliance = 4e-6;
  const RobotLog sim = Simulate(h, 21, 6, 40);
  std::ostringstream csv;
  csv.precision(12);
  csv << "time_s,column_joint,j1,j2,j3,x_m,y_m,z_m,tilt_sensor_base_ax,tilt_sensor_base_ay,tilt_sensor_base_az,"
         "tilt_sensor_column_tip_ax,tilt_sensor_column_tip_ay,tilt_sensor_column_tip_az\n";
  for (const auto& row : sim.rows) {
    const Vec3 p = r.T_base_tool(row.q).t;
    csv << row.time_s;
    for (int j = 0; j < 4; ++j) csv << "," << row.q[j];
    csv << "," << p.x() << "," << p.y() << "," << p.z();
    for (const auto& [link, a] : row.accel) csv << "," << a.x() << "," << a.y() << "," << a.z();
    csv << "\n";
  }
  test::WriteText(dir / "log.csv", csv.str());
  const RobotLog log = ReadRobotLog(dir / "log.csv", r);
  ASSERT_EQ(log.rows.size(), sim.rows.size());
  ASSERT_EQ(log.rows[3].accel.size(), 2u);
  EXPECT_EQ(log.rows[3].accel[1].first, "tilt_sensor_column_tip");
  EXPECT_LT((log.rows[3].accel[1].second - sim.rows[3].accel[1].second).norm(), 1e-9);
  const auto res = AuditTiltSensors(r, log);
  ASSERT_EQ(res.size(), 1u);
  ASSERT_EQ(res[0].report.effects.size(), 1u) << TiltSensorAuditText(res, r);
  EXPECT_EQ(res[0].report.effects[0].name, "link_compliance");

  const std::string text = csv.str();
  const auto Refused = [&](const std::string& name, std::string bad, const std::string& expected) {
    test::WriteText(dir / name, bad);
    const std::string e = test::ErrorOf([&] { ReadRobotLog(dir / name, r); });
    EXPECT_NE(e.find(expected), std::string::npos) << name << ": " << e;
    EXPECT_EQ(std::count(e.begin(), e.end(), '\n'), 0) << e;
  };
  std::string b = text;
  for (size_t at; (at = b.find("tilt_sensor_column_tip_a")) != std::string::npos;) b.replace(at, 22, "tilt_sensor_colum_tip");
  Refused("nolink.csv", b, "a sensor on link 'tilt_sensor_colum_tip', which is not a link of the URDF");
  // Readings in g: every accelerometer value divided by 9.80665 on the first data row.
  std::istringstream in(text);
  std::string header, first, rest, line;
  std::getline(in, header);
  std::getline(in, first);
  while (std::getline(in, line)) rest += line + "\n";
  std::vector<std::string> cells;
  std::stringstream fs(first);
  for (std::string c; std::getline(fs, c, ',');) cells.push_back(c);
  for (size_t k = 8; k < cells.size(); ++k) cells[k] = std::to_string(std::stod(cells[k]) / kStandardGravity);
  std::string g_row;
  for (size_t k = 0; k < cells.size(); ++k) g_row += (k ? "," : "") + cells[k];
  Refused("in_g.csv", header + "\n" + g_row + "\n" + rest, "(in g?)");
  // The column sensor upside down (its z read with the other sign), and its x and z columns
  // swapped: the norm is g in both, the direction is not where the URDF mounts the sensor.
  std::string flipped = header, swapped = header;
  for (const char* c : {"tilt_sensor_column_tip_ax", "tilt_sensor_column_tip_az"})
    ASSERT_NE(header.find(c), std::string::npos);
  swapped.replace(swapped.find("tilt_sensor_column_tip_ax"), 25, "tilt_sensor_column_tip_QQ");
  swapped.replace(swapped.find("tilt_sensor_column_tip_az"), 25, "tilt_sensor_column_tip_ax");
  swapped.replace(swapped.find("tilt_sensor_column_tip_QQ"), 25, "tilt_sensor_column_tip_az");
  {
    std::istringstream rows(first + "\n" + rest);
    std::string body;
    for (std::string l; std::getline(rows, l);) {
      const size_t last = l.rfind(',');
      body += l.substr(0, last + 1) + std::to_string(-std::stod(l.substr(last + 1))) + "\n";
    }
    flipped += "\n" + body;
  }
  Refused("upside_down.csv", flipped,
          "the accelerometer on tilt_sensor_column_tip (tilt_sensor_column_tip_ax, _ay, _az) reads up 1");
  Refused("swapped.csv", swapped + "\n" + first + "\n" + rest, "mounted upside down or turned, or its columns swapped");
  // A sensor on the arm's link l2 is on the chain; one on a link the chain does not reach is not.
  std::string branch = ColumnRobotUrdf();
  branch.insert(branch.rfind("</robot>"),
                "<joint name=\"side\" type=\"revolute\"><parent link=\"base_link\"/><child link=\"side_arm\"/>"
                "<axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>"
                "<link name=\"side_arm\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" "
                "iyz=\"0\" izz=\"1\"/></inertial></link>");
  test::WriteText(dir / "branch.urdf", branch);
  const RobotModel rb = RobotModel::Read(dir / "branch.urdf", {"base_link", "prism"});
  std::string off = text;
  for (size_t at; (at = off.find("tilt_sensor_base_a")) != std::string::npos;) off.replace(at, 16, "side_arm");
  test::WriteText(dir / "off.csv", off);
  const std::string e = test::ErrorOf([&] { ReadRobotLog(dir / "off.csv", rb); });
  EXPECT_NE(e.find("a sensor on link 'side_arm', which moves with joint 'side', not a joint of the chain"),
            std::string::npos)
      << e;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// The construction robot as published: its column's sensor against its base's on the
// calibration session. The column's bending under the arm's moment is named at the link
// the sensor rides on; the sensor's mount is a bias.
TEST(TiltSensors, RealConstructionRobotColumnSensor) {
  MCMS_REQUIRE_DATA(dir, "hilti-trailblazer");
  const RobotModel r = RobotModel::Read(dir / "trailblazer.urdf", {"", "prism"});
  const RobotLog log = ReadRobotLog(dir / "flat.yaml", r);
  const auto res = AuditTiltSensors(r, log);
  ASSERT_EQ(res.size(), 1u);
  const std::string text = TiltSensorAuditText(res, r);
  std::printf("%s", text.c_str());
  const AuditEffect* c = Named(res[0].report, "link_compliance");
  ASSERT_TRUE(c) << text;
  EXPECT_EQ(c->where, "column_top_joint");
  EXPECT_GT(c->parameters[0].second, 10 * c->sigma[0].second);
  EXPECT_GT(c->parameters[1].second, 10 * c->sigma[1].second);
  EXPECT_TRUE(Named(res[0].report, "inclinometer_bias")) << text;
  // The play between the column's telescopic segments, growing as their overlap shrinks:
  // the overlap left at full extension where the publisher's own geometry puts it (its
  // README: l2 = 1.414 m - column_top_joint, 0.164 m at the joint's upper limit 1.25 m),
  // within 0.05 m, the play positive both ways.
  const AuditEffect* p = Named(res[0].report, "segment_play");
  ASSERT_TRUE(p) << text;
  ASSERT_EQ(p->parameters.size(), 3u) << text;
  EXPECT_EQ(p->where, "column_top_joint");
  EXPECT_GT(p->parameters[0].second, 5 * p->sigma[0].second) << text;
  EXPECT_GT(p->parameters[1].second, 5 * p->sigma[1].second) << text;
  EXPECT_NEAR(p->parameters[2].second, 0.164, 0.05) << text;
  EXPECT_EQ(res[0].report.nested.failed, 0);
  // What the model leaves: the residual RMS falls from 12.8 mrad to below 0.25 mrad (0.44
  // without the play), the noise in x (0.58 mrad without it) below 0.3.
  double n0 = 0, n1 = 0;
  for (size_t i = 0; i < res[0].residuals.size(); ++i)
    n0 += res[0].nominal_residuals[i].squaredNorm(), n1 += res[0].residuals[i].squaredNorm();
  EXPECT_LT(n1, 0.01 * n0);
  EXPECT_LT(std::sqrt(n1 / (2.0 * res[0].residuals.size())), 0.25e-3);
  EXPECT_LT(std::sqrt(res[0].noise(0, 0)), 0.3e-3);
}

}  // namespace
}  // namespace mcms
