// Issue 51: the robot a user brings. Nested fits never fit worse than the model they extend
// (a property over robots and seeds), the instrument placed per session and per station
// (stations, stationing rows, an instrument that moved), only terms that predict, and every
// bad input of it named.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <unistd.h>

#include "audit/robot_audit.h"
#include "model/robot_measurements.h"
#include "model/robot_validation.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/random.h"
#include "tests/robot_logs.h"
#include "tests/test_util.h"
#include "model/tilt_sensor.h"
#include "model/urdf.h"
#include "tests/urdf_robots.h"

namespace mcms {
namespace {

using test::ErrorOf;
using test::Hidden;
using test::MakeRobotLog;
using test::RobotLogSpec;
using test::RobotTruth;

RobotModel Kr5() { return RobotModel::Default(); }
using test::SevenJoints;
using test::SevenSpec;

// A realistic log: every DH term off, the arm's weight on joints 2 and 3, noise.
RobotLogSpec Realistic() {
  RobotLogSpec s;
  s.dh_length_sigma_m = 1e-4;
  s.dh_angle_sigma_rad = 1e-4;
  s.compliance = {0, 2e-6, 3e-6, 0, 0, 0};
  return s;
}

void ExpectNestedFitsHold(const AuditReport& rep, const std::string& what) {
  EXPECT_GT(rep.nested.count, 0) << what;
  EXPECT_EQ(rep.nested.failed, 0) << what << "\n" << rep.Text();
  EXPECT_GE(rep.nested.worst_relative_lr, -NestedFits::kTolerance) << what << "\n" << rep.Text();
}

// A model with more free parameters never fits worse than the one it contains: every
// likelihood ratio of the audit against its contained model is >= 0 up to the solver's
// tolerance, over robots, hidden effects and seeds.
TEST(NestedFits, NeverBelowTheModelTheyExtend) {
  const RobotModel kr5 = Kr5();
  const RobotModel ur10 = RobotModel::Read(std::filesystem::path(MCMS_SOURCE_DIR) / "examples/robots/ur10_like.yaml");
  const RobotModel seven = SevenJoints();
  int runs = 0;
  for (uint64_t seed = 0; seed < 6; ++seed) {
    RobotLogSpec spec = Realistic();
    std::vector<Hidden> hidden;
    if (seed % 3 == 1) hidden.push_back({{Effect::kJointOffset, 2, 0}, {2e-4}});
    if (seed % 3 == 2) hidden.push_back({{Effect::kBacklash, 1, 0}, {1.5e-4}});
    const RobotLog a = MakeRobotLog(kr5, 9100 + seed, hidden, spec);
    ExpectNestedFitsHold(AuditRobot(kr5, a).report, "KR 5 seed " + std::to_string(seed));
    RobotLogSpec us = spec;
    us.masses = &ur10;
    us.lo = {-1.2, -2.0, -2.0, -2.5, -1.6, -3.0};
    us.hi = {1.2, -0.8, 2.0, 2.5, 1.6, 3.0};
    const RobotLog b = MakeRobotLog(ur10, 9200 + seed, hidden, us);
    ExpectNestedFitsHold(AuditRobot(ur10, b).report, "UR10-like seed " + std::to_string(seed));
    RobotLogSpec ss = SevenSpec();
    ss.dh_length_sigma_m = 1e-4;
    ss.dh_angle_sigma_rad = 1e-4;
    ss.masses = &seven;
    const RobotLog c = MakeRobotLog(seven, 9300 + seed, {}, ss);
    ExpectNestedFitsHold(AuditRobot(seven, c).report, "seven-joint URDF seed " + std::to_string(seed));
    runs += 3;
  }
  // The README's own example (a geometry fit there once ended 3,043 below the nominal).
  const std::filesystem::path ex = std::filesystem::path(MCMS_SOURCE_DIR) / "examples/robot_log.csv";
  const RobotAuditResult r = AuditRobot(kr5, ReadRobotLog(ex, kr5));
  ExpectNestedFitsHold(r.report, "examples/robot_log.csv");
  std::printf("%d audits: every nested likelihood ratio >= -%g of its contained model's log-likelihood\n", runs + 1,
              NestedFits::kTolerance);
}

// Rows of `log` moved into another placement of the instrument: T applied to every point.
RobotLog Moved(RobotLog log, const Pose& T) {
  for (auto& r : log.rows) r.p_meas = T * r.p_meas;
  return log;
}

// A session measured in stations (the instrument set up anew for each): rows `per` at a
// time, each station's first 4 rows stationing, the rest evaluation, each station's
// placement moved by metres and a rotation about the vertical.
RobotLog InStations(RobotLog log, int per, Rng& rng) {
  log.has_stations = log.has_roles = true;
  Pose T;
  for (size_t i = 0; i < log.rows.size(); ++i) {
    const int st = static_cast<int>(i) / per;
    if (static_cast<int>(i) % per == 0)
      T = Pose{ExpSO3(Vec3(0.01 * rng.Normal(), 0.01 * rng.Normal(), rng.Uniform(-3, 3))),
               Vec3(rng.Uniform(-5, 5), rng.Uniform(-5, 5), rng.Uniform(-1, 1))};
    auto& r = log.rows[i];
    r.p_meas = T * r.p_meas;
    r.station = std::to_string(st + 1);
    r.station.insert(0, 1, 'S');
    r.role = static_cast<int>(i) % per < 4 ? RowRole::kStationing : RowRole::kEvaluation;
  }
  return log;
}

const ModelScore& ModelOf(const SessionScore& s, const std::string& name) {
  for (const ModelScore& m : s.models)
    if (m.model == name) return m;
  throw std::runtime_error("no model " + name);
}

// Another session whose instrument was set up anew (moved by metres, turned), without a
// station column: the frozen placement misses far beyond the noise, the session is placed
// anew and scored within 1.5 times the session that shares the fit's placement; the report
// says how far the instrument moved.
TEST(Sessions, AnInstrumentThatMovedIsPlacedAnewAndSaid) {
  const RobotModel kr5 = Kr5();
  RobotTruth truth;
  RobotLogSpec spec = Realistic();
  const RobotLog fit = MakeRobotLog(kr5, 9400, {}, spec, &truth);
  // Two more sessions of the same robot: new postures, the same placement.
  RobotLogSpec other = spec;
  other.poses = 30;
  other.repeats = 2;
  std::vector<RobotLog> v;
  for (uint64_t s : {9401u, 9402u}) {
    // The same true robot and placement: draw with the fit's seed for the truth, new poses.
    Rng rng(s);
    RobotLog l;
    l.source = std::to_string(s) + ".csv";
    l.has_time = true;
    l.has_payload = true;
    std::vector<Eigen::VectorXd> q = test::DrawPoses(kr5, other, rng);
    test::AppendRows(truth, q, 0.0, 60.0, rng, &l);
    v.push_back(l);
  }
  const Pose move{ExpSO3(Vec3(0.002, -0.001, 0.8)), Vec3(3.2, -1.5, 0.4)};
  v[1] = Moved(v[1], move);
  const RobotAuditResult r = AuditRobot(kr5, fit, {}, v);
  ASSERT_EQ(r.report.validation.size(), 2u) << r.report.Text();
  const ModelScore& same = ModelOf(r.report.validation[0], "final");
  const ModelScore& moved = ModelOf(r.report.validation[1], "final");
  ASSERT_EQ(same.placements.size(), 1u);
  ASSERT_EQ(moved.placements.size(), 1u);
  EXPECT_FALSE(same.placements[0].placed_anew) << r.report.Text();
  EXPECT_TRUE(moved.placements[0].placed_anew) << r.report.Text();
  EXPECT_GT(moved.placements[0].moved_mm, 1000.0);
  EXPECT_NEAR(moved.placements[0].moved_mrad, 1e3 * LogSO3(move.R).norm(), 1.0);
  EXPECT_LT(moved.points[0].mean_m, 1.5 * same.points[0].mean_m) << r.report.Text();
  const std::string text = r.report.Text();
  EXPECT_NE(text.find("placed anew: the fit's placement missed by"), std::string::npos) << text;
  std::printf("%s", text.c_str());
}

// A session in stations: each placed from its four stationing rows, its evaluation rows
// scored, the model frozen; the fit itself may have stations too (a placement each, the
// robot shared), and it names the hidden cause.
TEST(Sessions, EachStationIsPlacedFromItsStationingRows) {
  const RobotModel kr5 = Kr5();
  Rng rng(77);
  RobotLogSpec spec = Realistic();
  spec.poses = 60;
  spec.repeats = 2;
  const std::vector<Hidden> hidden{{{Effect::kJointOffset, 2, 0}, {3e-4}}};
  RobotTruth truth;
  const RobotLog fit = InStations(MakeRobotLog(kr5, 9500, hidden, spec, &truth), 24, rng);
  Rng rng2(9501);
  RobotLog other;
  other.source = "stations.csv";
  other.has_time = other.has_payload = true;
  RobotLogSpec os = spec;
  os.poses = 48;
  test::AppendRows(truth, test::DrawPoses(kr5, os, rng2), 0.0, 30.0, rng2, &other);
  other = InStations(other, 16, rng);
  const RobotAuditResult r = AuditRobot(kr5, fit, {}, {other});
  const std::string text = r.report.Text();
  bool offset = false;
  for (const AuditEffect& e : r.report.effects) offset |= e.name == "joint_offset" && e.where == "joint 3";
  for (const AuditEffect& e : r.report.effects)
    if (e.name == "geometry")
      for (const auto& [name, v] : e.parameters) offset |= name == "A3.theta_offset" && v > 1e-4;
  EXPECT_TRUE(offset) << text;
  ASSERT_EQ(r.report.validation.size(), 1u);
  const ModelScore& fin = ModelOf(r.report.validation[0], "final");
  const ModelScore& reg = ModelOf(r.report.validation[0], "registration");
  ASSERT_EQ(fin.placements.size(), 3u) << text;
  for (const auto& p : fin.placements) {
    EXPECT_TRUE(p.placed_anew);
    EXPECT_EQ(p.stationing_rows, 4);
    EXPECT_EQ(p.scored_rows, 12);
  }
  EXPECT_EQ(fin.stations.size(), 3u);
  EXPECT_EQ(r.report.validation[0].scored_rows, 36);
  // The frozen model predicts the evaluation rows near the noise (tens of micrometres), the
  // registered nominal model not.
  EXPECT_LT(fin.points[0].mean_m, 1.5e-4) << text;
  EXPECT_LT(fin.points[0].mean_m, reg.points[0].mean_m) << text;
  EXPECT_NE(text.find("each of 3 stations placed anew from its stationing rows"), std::string::npos) << text;
  ExpectNestedFitsHold(r.report, "stations");
  std::printf("%s", text.c_str());
}

std::filesystem::path Scratch(const std::string& name) {
  const auto d = std::filesystem::temp_directory_path() / ("mcms_sessions_" + std::to_string(::getpid()));
  std::filesystem::create_directories(d);
  return d / name;
}

// What a station log gets wrong is named: a role not understood, an empty station, a
// station that its stationing rows cannot place, a mimic joint's driver missing from the log.
TEST(Sessions, BadStationInputIsNamed) {
  const RobotModel kr5 = Kr5();
  const std::filesystem::path ex = std::filesystem::path(MCMS_SOURCE_DIR) / "examples/robot_log.csv";
  std::ifstream in(ex);
  std::string header, line;
  std::getline(in, header);
  std::vector<std::string> rows;
  while (std::getline(in, line)) rows.push_back(line);
  const auto Write = [&](const std::string& name, const std::function<std::string(size_t)>& extra,
                         const std::string& cols) {
    const auto p = Scratch(name);
    std::ofstream o(p);
    o << header << cols << "\n";
    for (size_t i = 0; i < rows.size(); ++i) o << rows[i] << extra(i) << "\n";
    return p;
  };
  // A role not understood.
  auto p = Write("role.csv", [](size_t i) { return i == 7 ? ",A,stationnig" : ",A,evaluation"; }, ",station,role");
  std::string e = ErrorOf([&] { ReadRobotLog(p, kr5); });
  EXPECT_NE(e.find("role.csv line 9: role 'stationnig' is not understood"), std::string::npos) << e;
  // An empty station cell.
  p = Write("empty.csv", [](size_t i) { return i == 3 ? "," : ",A"; }, ",station");
  e = ErrorOf([&] { ReadRobotLog(p, kr5); });
  EXPECT_NE(e.find("empty.csv line 5: the station cell is empty"), std::string::npos) << e;
  // A station with one row cannot be placed (the fitted log).
  p = Write("one.csv", [](size_t i) { return i == 0 ? ",lonely" : ",main"; }, ",station");
  e = ErrorOf([&] { AuditRobot(kr5, ReadRobotLog(p, kr5)); });
  EXPECT_NE(e.find("station 'lonely' (1 rows) cannot be placed"), std::string::npos) << e;
  // Stationing rows too few (2) in a validated session.
  const RobotLog fit = ReadRobotLog(ex, kr5);
  p = Write("few.csv", [](size_t i) { return i < 2 ? ",B,stationing" : ",B,evaluation"; }, ",station,role");
  e = ErrorOf([&] { AuditRobot(kr5, fit, {}, {ReadRobotLog(p, kr5)}); });
  EXPECT_NE(e.find("few.csv: station 'B' has 2 stationing points"), std::string::npos) << e;
  // Stationing rows at one place: the same pose measured four times.
  {
    const auto q = Scratch("line.csv");
    std::ofstream o(q);
    o << header << ",station,role\n";
    for (size_t i = 0; i < rows.size(); ++i) {
      std::string r = i < 4 ? rows[0] : rows[i];
      if (i > 0 && i < 4) {
        // The same pose measured again: z (the 10th column) a few micrometres apart.
        size_t at = 0;
        for (int c = 0; c < 9; ++c) at = r.find(',', at) + 1;
        const size_t end = r.find(',', at);
        r = r.substr(0, at) + std::to_string(std::stod(r.substr(at, end - at)) + 3e-6 * static_cast<double>(i)) +
            r.substr(end);
      }
      o << r << (i < 4 ? ",C,stationing" : ",C,") << "\n";
    }
    o.close();
    e = ErrorOf([&] { AuditRobot(kr5, fit, {}, {ReadRobotLog(q, kr5)}); });
    EXPECT_NE(e.find("stationing points of station 'C' lie on one line"), std::string::npos) << e;
  }
  // A mimic joint's driver that the log does not record.
  const std::string urdf = R"(<robot name="m"><link name="b"/>
    <joint name="motor" type="prismatic"><parent link="b"/><child link="ml"/><axis xyz="0 0 1"/>
      <limit lower="0" upper="1" effort="1" velocity="1"/></joint><link name="ml"/>
    <joint name="seg" type="prismatic"><parent link="b"/><child link="s"/><axis xyz="0 0 1"/>
      <limit lower="0" upper="0.5" effort="1" velocity="1"/><mimic joint="motor" multiplier="0.5"/></joint>
    <link name="s"/>
    <joint name="j1" type="revolute"><parent link="s"/><child link="a"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="a"/>
    <joint name="j2" type="revolute"><parent link="a"/><child link="t"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="t"/></robot>)";
  const auto up = Scratch("m.urdf");
  std::ofstream(up) << urdf;
  const RobotModel m = RobotModel::Read(up);
  const auto lp = Scratch("mimic.csv");
  std::ofstream(lp) << "time_s,seg,j1,j2,x_m,y_m,z_m\n0,0.2,0.1,0.2,1,2,3\n";
  e = ErrorOf([&] { ReadRobotLog(lp, m); });
  EXPECT_NE(e.find("joint motor is not in the log"), std::string::npos) << e;
  std::filesystem::remove_all(Scratch("").parent_path());
}

// Issue 53's findings on robot logs: a point named twice, a joint given in two columns, three
// "rigid body" points on one line, a robot of more joints than any chain has.
TEST(Sessions, GarbageInRobotLogsIsNamed) {
  const RobotModel kr5 = Kr5();
  const std::filesystem::path ex = std::filesystem::path(MCMS_SOURCE_DIR) / "examples/robot_log.csv";
  const RobotLog log = ReadRobotLog(ex, kr5);
  std::string e = ErrorOf([&] { KeepPoints(log, {1, 1, 1}, "--points"); });
  EXPECT_NE(e.find("--points names point 1 twice"), std::string::npos) << e;
  // q1_rad and the joint's own name in one log.
  {
    const auto p = Scratch("twice.csv");
    std::ofstream o(p);
    o << "time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad,A1_rad,x_m,y_m,z_m\n0,0,0,0,0,0,0,0.3,1,2,3\n";
    o.close();
    e = ErrorOf([&] { ReadRobotLog(p, kr5); });
    EXPECT_NE(e.find("joint A1 has two columns"), std::string::npos) << e;
  }
  // Three points of a "rigid body" on one line fix no pose.
  RobotLog line = log;
  for (auto& r : line.rows) r.other_points = {r.p_meas + Vec3(0.05, 0, 0), r.p_meas + Vec3(0.1, 0, 0)};
  e = ErrorOf([&] { FitRigidBody(line); });
  EXPECT_NE(e.find("points of the rigid body lie on one line"), std::string::npos) << e;
  // Measured orientations in x, y, z, w order under qw..qz (issue 53: the audit answered
  // with 651 mm residuals): named, where the right order passes.
  {
    RobotLog six = log;
    const Pose T{ExpSO3(Vec3(0.01, -0.02, 1.2)), Vec3(2.0, 0.5, -0.2)};
    const Pose tool{ExpSO3(Vec3(0.3, 0.1, -0.2)), Vec3(0.01, -0.02, 0.06)};
    for (size_t i = 0; i < six.rows.size(); ++i) {
      auto& r = six.rows[i];
      const Pose P = T * kr5.T_base_flange(r.q) * tool;
      const double k = static_cast<double>(i);
      r.p_meas = P.t + 2e-5 * Vec3(std::sin(k), std::cos(3 * k), std::sin(7 * k));  // a tracker's noise
      r.R_meas_tool = P.R;
    }
    EXPECT_NO_THROW(CheckRobotLogPlausible(six, kr5));
    for (auto& r : six.rows) {
      const Eigen::Quaterniond q(*r.R_meas_tool);
      r.R_meas_tool = Eigen::Quaterniond(q.x(), q.y(), q.z(), q.w()).normalized().toRotationMatrix();
    }
    e = ErrorOf([&] { CheckRobotLogPlausible(six, kr5); });
    EXPECT_NE(e.find("quaternions x, y, z, w under qw, qx, qy, qz?"), std::string::npos) << e;
  }
  // Positions in mm from a robot whose telescopic segment mimics its column (the Trailblazer's
  // column_top_joint = 0.5 q - 0.736): named as millimetres, where the unit search's trial of
  // the segment in mm (within the readings' slack, beyond the kinematics' strict limits)
  // answered with a joint-limit message naming neither file nor columns (issue 53, a09_mm).
  {
    const auto up = Scratch("column.urdf");
    std::ofstream(up) << R"(<robot name="col"><link name="b"/>
      <joint name="motor" type="prismatic"><parent link="b"/><child link="ml"/><axis xyz="0 0 1"/>
        <limit lower="1.5" upper="4" effort="1" velocity="1"/></joint><link name="ml"/>
      <joint name="seg" type="prismatic"><parent link="ml"/><child link="s"/><axis xyz="0 0 1"/>
        <limit lower="0.004" upper="1.25" effort="1" velocity="1"/><mimic joint="motor" multiplier="0.5" offset="-0.736"/></joint>
      <link name="s"/>
      <joint name="j1" type="revolute"><parent link="s"/><child link="a"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="a"/>
      <joint name="j2" type="revolute"><parent link="a"/><child link="t"/><origin xyz="0.6 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="t"/></robot>)";
    const RobotModel col = RobotModel::Read(up);
    const auto lp = Scratch("column_mm.csv");
    {
      std::ofstream o(lp);
      o << "time_s,motor,j1,j2,x_m,y_m,z_m\n";
      for (int i = 0; i < 20; ++i)
        o << i << "," << 1.6 + 0.11 * i << "," << std::sin(1.3 * i) << "," << 0.8 * std::cos(2.1 * i) << ",0,0,0\n";
    }
    RobotLog mm = ReadRobotLog(lp, col);
    for (auto& r : mm.rows) r.p_meas = 1000.0 * col.T_base_tool(r.q).t;
    e = ErrorOf([&] { CheckRobotLogPlausible(mm, col); });
    EXPECT_NE(e.find("column_mm.csv: the measured positions are 1000 times as far apart"), std::string::npos) << e;
    EXPECT_EQ(e.find("limit"), std::string::npos) << e;
  }
  // A chain beyond any robot's.
  std::vector<Joint> many(kMaxRobotJoints + 1);
  e = ErrorOf([&] { RobotModel("many", ChainConvention::kStandard, many); });
  EXPECT_NE(e.find("joints; a robot's chain has at most 64"), std::string::npos) << e;
  std::filesystem::remove_all(Scratch("").parent_path());
}

// The construction robot as its publisher ships it: the dataset reader places each column
// height and arm configuration as a station from the four square stationing points.
TEST(Sessions, RealConstructionRobotReadAsPublished) {
  MCMS_REQUIRE_DATA(dir, "hilti-trailblazer");
  const RobotModel r = RobotModel::Read(dir / "trailblazer.urdf", {"", "prism"});
  const RobotLog flat = ReadRobotLog(dir / "flat.yaml", r);
  EXPECT_EQ(flat.rows.size(), 444u);
  EXPECT_EQ(flat.Stations().size(), 15u);
  int st = 0, ev = 0, sp = 0;
  for (const auto& row : flat.rows) {
    st += row.role == RowRole::kStationing;
    ev += row.role == RowRole::kEvaluation;
    sp += row.role == RowRole::kSpare;
  }
  EXPECT_EQ(st, 39);  // the square's points at the 10 stations with stationing points (one lacks one)
  EXPECT_EQ(st + ev + sp, 444);
  EXPECT_EQ(ev, 321);  // the evaluation points of solution spaces 0 and 7
  for (size_t i = 1; i < flat.rows.size(); ++i) EXPECT_LE(flat.rows[i - 1].time_s, flat.rows[i].time_s);
  ASSERT_FALSE(flat.notes.empty());
  EXPECT_NE(flat.notes[0].find("45 evaluation points of 5 stations without stationing points"), std::string::npos)
      << flat.notes[0];
}

// The construction robot fitted on its level-floor session, each of its stations placed
// from its own rows, and scored frozen on the pallet session with each station placed from
// its four square stationing points: no nested fit below its base, the publisher's baseline
// reproduced, the geometry better than the registered robot file on the other session's
// evaluation points.
TEST(Sessions, RealConstructionRobotCalibratedOnFlatScoredOnPallet) {
  MCMS_REQUIRE_DATA(dir, "hilti-trailblazer");
  const RobotModel r = RobotModel::Read(dir / "trailblazer.urdf", {"", "prism"});
  const RobotLog flat = ReadRobotLog(dir / "flat.yaml", r);
  std::vector<RobotLog> others;
  for (const char* f : {"pallet.yaml", "orthogonal_wood.yaml", "wood_left_track.yaml"})
    others.push_back(ReadRobotLog(dir / f, r));
  const RobotAuditResult res = AuditRobot(r, flat, {}, others);
  const std::string text = res.report.Text();
  std::printf("%s", text.c_str());
  ExpectNestedFitsHold(res.report, "construction robot, flat");
  ASSERT_EQ(res.report.validation.size(), 3u);
  // The publisher's baseline (its example_kabsch.py: the URDF as given, each station placed
  // by Kabsch on its four square points), as the data README tabulates it (mean, 95 % xy,
  // 95 % |z| mm): pallet 8.30 / 16.31 / 6.41, orthogonal_wood 7.80 / 16.52 / 6.74,
  // wood_left_track 9.88 / 19.61 / 6.92.
  const double readme[3][3] = {{8.30, 16.31, 6.41}, {7.80, 16.52, 6.74}, {9.88, 19.61, 6.92}};
  for (int k = 0; k < 3; ++k) {
    const SessionScore& s = res.report.validation[k];
    const ModelScore& reg = ModelOf(s, "registration");
    const ModelScore& geo = ModelOf(s, "geometry");
    const ModelScore& fin = ModelOf(s, "final");
    const ModelScore& nom = ModelOf(s, "nominal");
    EXPECT_EQ(geo.placements.size(), 10u);
    for (const auto& p : geo.placements) {
      EXPECT_GE(p.stationing_rows, 3) << p.station;  // the square's four points (one may be missing)
      EXPECT_LE(p.stationing_rows, 4) << p.station;
    }
    EXPECT_NEAR(nom.points[0].mean_m * 1e3, readme[k][0], 0.1) << s.log;
    EXPECT_NEAR(nom.points[0].p95_xy_m * 1e3, readme[k][1], 0.1) << s.log;
    EXPECT_NEAR(nom.points[0].p95_z_m * 1e3, readme[k][2], 0.1) << s.log;
    // Issue 52: calibrated on flat with the accelerometers' measured tilt in the model,
    // frozen, each station placed from its square: at most half the baseline's 95 %
    // horizontal error (measured 2.08, 2.20, 2.20 mm against 16.31, 16.52, 19.61).
    EXPECT_LT(fin.points[0].p95_xy_m, 0.5 * nom.points[0].p95_xy_m) << s.log;
    EXPECT_LT(geo.points[0].p95_xy_m, 0.85 * reg.points[0].p95_xy_m) << s.log;
    EXPECT_LT(geo.points[0].mean_m, 0.75 * reg.points[0].mean_m) << s.log;
    // The measured tilt's own gain: the geometry fitted and scored without it does worse.
    const ModelScore& untilted = ModelOf(s, "geometry without tilt");
    EXPECT_LT(geo.points[0].p95_xy_m, 0.6 * untilted.points[0].p95_xy_m) << s.log;
    EXPECT_LT(ModelOf(s, "nominal + tilt").points[0].p95_xy_m, 0.62 * nom.points[0].p95_xy_m) << s.log;
  }
  EXPECT_EQ(ModelOf(res.report.validation[0], "nominal").points[0].rows, 316);
  // A geometric term the poses cannot see, or that runs to its bound, is held, never named.
  for (const AuditEffect& e : res.report.effects)
    for (const auto& [name, sg] : e.sigma) EXPECT_LT(sg, 0.02) << e.name << " " << name;
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// Issue 52: the construction robot's two accelerometers read as tilt sensors on the URDF's
// links. The robot file as given, each station placed from its four square points, with
// the column's and the base's tilts measured since the stationing rows applied to the chain
// (nothing fitted): the 95 % horizontal error of the publisher's baseline drops by 40-55 %.
TEST(Sessions, ConstructionRobotsMeasuredTiltNearlyHalvesTheBaseline) {
  MCMS_REQUIRE_DATA(dir, "hilti-trailblazer");
  const RobotModel r = RobotModel::Read(dir / "trailblazer.urdf", {"", "prism"});
  EXPECT_EQ(MountOnChain(r, "tilt_sensor_column_tip").frame, 2);  // column_top, after the two mimic segments
  EXPECT_EQ(MountOnChain(r, "tilt_sensor_base").frame, 0);
  for (const char* file : {"pallet.yaml", "orthogonal_wood.yaml", "wood_left_track.yaml"}) {
    const RobotLog log = ReadRobotLog(dir / file, r);
    ASSERT_EQ(log.rows.front().accel.size(), 2u);
    std::vector<std::vector<Vec3>> plain;
    for (const auto& row : log.rows) plain.push_back({r.T_base_tool(row.q).t});
    const std::vector<Pose> C = MeasuredTiltCorrections(r, log);
    ASSERT_EQ(C.size(), log.rows.size());
    std::vector<std::vector<Vec3>> tilted;
    for (size_t i = 0; i < log.rows.size(); ++i) tilted.push_back({C[i] * plain[i][0]});
    const std::vector<PostureGroup> groups(log.rows.size(), PostureGroup::kNewInRange);
    const ModelScore a = ScoreModel("nominal", log, plain, groups, {});
    const ModelScore b = ScoreModel("nominal + tilt", log, tilted, groups, {});
    std::printf("%s: mean %.3f -> %.3f mm, 95 %% xy %.3f -> %.3f mm, 95 %% |z| %.3f -> %.3f mm\n", file,
                a.points[0].mean_m * 1e3, b.points[0].mean_m * 1e3, a.points[0].p95_xy_m * 1e3,
                b.points[0].p95_xy_m * 1e3, a.points[0].p95_z_m * 1e3, b.points[0].p95_z_m * 1e3);
    EXPECT_LT(b.points[0].p95_xy_m, 0.62 * a.points[0].p95_xy_m) << file;
    EXPECT_LT(b.points[0].mean_m, 0.75 * a.points[0].mean_m) << file;
  }
}

TEST(Sessions, BadTiltSensorInputIsNamed) {
  const std::string urdf = R"(<robot name="two"><link name="b"/>
    <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="l1"/>
    <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/><origin xyz="0.5 0 0"/><axis xyz="0 1 0"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="tip"/>
    <joint name="s" type="fixed"><parent link="l1"/><child link="sensor"/><origin rpy="0 0 1.5707963"/></joint>
    <link name="sensor"/>
    <joint name="other" type="revolute"><parent link="b"/><child link="arm2"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="arm2"/>
    <joint name="s2" type="fixed"><parent link="arm2"/><child link="sensor2"/></joint><link name="sensor2"/></robot>)";
  const auto p = Scratch("two.urdf");
  std::ofstream(p) << urdf;
  const RobotModel r = RobotModel::Read(p, {"", "tip"});
  const LinkMount m = MountOnChain(r, "sensor");
  EXPECT_EQ(m.frame, 1);
  EXPECT_NEAR(Eigen::AngleAxisd(m.R_frame_link).angle(), 1.5707963, 1e-6);
  std::string e = ErrorOf([&] { MountOnChain(r, "senser"); });
  EXPECT_NE(e.find("a sensor on link 'senser', which is not a link of the URDF (links: "), std::string::npos) << e;
  e = ErrorOf([&] { MountOnChain(r, "sensor2"); });
  EXPECT_NE(e.find("a sensor on link 'sensor2', which moves with joint 'other', not a joint of the chain"),
            std::string::npos)
      << e;
  e = ErrorOf([&] { CheckAccelerometerReading(Vec3(0.01, 0.02, 0.999), "log.yaml measurement 3"); });
  EXPECT_NE(e.find("log.yaml measurement 3: an accelerometer reading"), std::string::npos) << e;
  EXPECT_NE(e.find("(in g?)"), std::string::npos) << e;
  e = ErrorOf([&] { CheckAccelerometerReading(Vec3(10, 20, 1000), "x"); });
  EXPECT_NE(e.find("(in mg?)"), std::string::npos) << e;
  EXPECT_EQ(ErrorOf([&] { CheckAccelerometerReading(Vec3(0.1, -0.2, 9.8), "x"); }), "(no InputError)");
  // A tilt about x measured since a level reading: the rotation maps the new reading onto it.
  const Mat3 D = TiltSince(Vec3(0, 0, kStandardGravity), ExpSO3(Vec3(0.01, 0, 0)).transpose() * Vec3(0, 0, kStandardGravity));
  EXPECT_LT((LogSO3(D) - Vec3(0.01, 0, 0)).norm(), 1e-12);
  std::filesystem::remove_all(Scratch("").parent_path());
}

}  // namespace
}  // namespace mcms
