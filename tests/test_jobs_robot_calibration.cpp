// Robot measurements as measured (model/robot_measurements.h): CSV logs with joint columns
// named as the URDF names them, one point or K points of a rigid body, the other session's
// posture groups; the bad inputs of a real log each named; and a URDF robot calibrated from
// four points of a rigid body, its calibrated URDF written back.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include <nlohmann/json.hpp>

#include "calib/robot_calibration.h"
#include "jobs/robot_calibration_job.h"
#include "model/robot_measurements.h"
#include "core/random.h"
#include "model/urdf.h"
#include "tests/test_util.h"
#include "tests/urdf_robots.h"

namespace mcms {
namespace {

using test::ErrorOf;

RobotModel Seven() { return ParseUrdf(test::SevenJointUrdf(), "seven.urdf", {"world", "tool"}); }

// Four points of a body on the tool, in the tool frame.
const std::vector<Vec3>& BodyPoints() {
  static const std::vector<Vec3> p = {Vec3(0.05, 0.02, 0.10), Vec3(-0.04, 0.03, 0.12), Vec3(-0.03, -0.05, 0.09),
                                      Vec3(0.06, -0.04, 0.11)};
  return p;
}

struct Truth {
  RobotModel robot;
  Pose T_meas_base;
};

Truth MakeTruth(uint64_t seed, double error_sigma) {
  const RobotModel nominal = Seven();
  Rng rng(seed);
  Eigen::VectorXd delta(nominal.NumGeometryParameters());
  for (int k = 0; k < delta.size(); ++k) delta[k] = rng.Normal(0.0, error_sigma);
  return {WithGeometryErrors(nominal, delta), Pose{ExpSO3(Vec3(0.02, -0.03, 0.4)), Vec3(0.3, -0.2, 0.1)}};
}

// A CSV log of the truth at `rows` random postures with 0.1 mm point noise: a time column,
// the joints by name, points x1..z4, and a column the reader does not know.
std::string MakeCsv(const Truth& t, int rows, uint64_t seed, double noise = 1e-4) {
  Rng rng(seed);
  const RobotModel& r = t.robot;
  std::ostringstream s;
  s.precision(17);
  s << "t_start_robot,t_end_robot";
  for (const Joint& j : r.Joints()) s << "," << j.name;
  for (int k = 1; k <= 4; ++k) s << ",x" << k << ",y" << k << ",z" << k;
  s << ",marker_std_mm\n";
  for (int i = 0; i < rows; ++i) {
    Eigen::VectorXd q(r.NumJoints());
    q[0] = rng.Uniform(0.02, 0.38);
    for (int j = 1; j < q.size(); ++j) q[j] = rng.Uniform(-1.4, 1.4);
    const Pose T = t.T_meas_base * r.T_base_tool(q);
    s << 100.0 + 10 * i << "," << 105.0 + 10 * i;
    for (int j = 0; j < q.size(); ++j) s << "," << q[j];
    for (const Vec3& p : BodyPoints()) {
      const Vec3 m = T * p + Vec3(rng.Normal(0, noise), rng.Normal(0, noise), rng.Normal(0, noise));
      s << "," << m.x() << "," << m.y() << "," << m.z();
    }
    s << ",0.2\n";
  }
  return s.str();
}

TEST(RobotMeasurements, ReadsJointsByNameAndPointsOfARigidBody) {
  const auto dir = test::ScratchDir("robot_measurements_read");
  const Truth t = MakeTruth(1, 0.0);
  test::WriteText(dir / "log.csv", MakeCsv(t, 20, 2));
  const RobotLog log = ReadRobotLog(dir / "log.csv", Seven());
  ASSERT_EQ(log.rows.size(), 20u);
  EXPECT_EQ(log.NumPoints(), 4);
  EXPECT_TRUE(log.has_time);
  EXPECT_DOUBLE_EQ(log.rows[1].time_s, 112.5);  // the middle of the averaging window
  EXPECT_EQ(log.ignored_columns, std::vector<std::string>{"marker_std_mm"});
  // The rigid body's poses reproduce its points (the shape is the mean one).
  const RigidBody body = FitRigidBody(log);
  ASSERT_EQ(body.points_body.size(), 4u);
  for (size_t i = 0; i < log.rows.size(); ++i) EXPECT_LT(body.fit_rms_m[i], 5e-4);
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b)
      EXPECT_NEAR((body.points_body[a] - body.points_body[b]).norm(), (BodyPoints()[a] - BodyPoints()[b]).norm(), 1e-4);
  // The body's pose of a row with its shape given.
  const RigidBody again = RigidBodyPoses(log, body.points_body);
  EXPECT_LT((again.T_meas_body[3].t - body.T_meas_body[3].t).norm(), 1e-12);
}

// A URDF that names its joints q7 .. q1 down the chain (the reverse of the log's numbered
// convention): its q<k>_rad / q<k>_m columns are its joint names and are read by name, never
// as "joint k of the chain".
TEST(RobotMeasurements, JointsNamedQInReverseAreReadByName) {
  const auto dir = test::ScratchDir("robot_measurements_q_reverse");
  const Truth t = MakeTruth(1, 0.0);
  const std::string csv = MakeCsv(t, 12, 3);
  test::WriteText(dir / "log.csv", csv);
  const RobotLog by_name = ReadRobotLog(dir / "log.csv", Seven());
  // The same robot with its chain's joints renamed q7 (lift_joint) .. q1 (j6), and the log's
  // columns renamed so, with their units: lift_joint -> q7_m, j1 -> q6_rad ...
  std::string urdf = test::SevenJointUrdf();
  std::string header = csv.substr(0, csv.find('\n'));
  const std::vector<std::string> names = {"lift_joint", "j1", "j2", "j3", "j4", "j5", "j6"};
  for (size_t k = 0; k < names.size(); ++k) {
    const std::string q = std::string("q").append(std::to_string(7 - k));
    const std::string quoted = "\"" + names[k] + "\"";
    for (size_t at; (at = urdf.find(quoted)) != std::string::npos;) urdf.replace(at, quoted.size(), "\"" + q + "\"");
    const std::string col = "," + names[k] + ",";
    const size_t at = header.find(col);
    ASSERT_NE(at, std::string::npos) << names[k];
    header.replace(at, col.size(), "," + q + (k == 0 ? "_m," : "_rad,"));
  }
  test::WriteText(dir / "q.csv", header + csv.substr(csv.find('\n')));
  const RobotModel renamed = ParseUrdf(urdf, "q.urdf", {"world", "tool"});
  ASSERT_EQ(renamed.ActuatedJoints()[0].name, "q7");
  const RobotLog by_q = ReadRobotLog(dir / "q.csv", renamed);
  ASSERT_EQ(by_q.rows.size(), by_name.rows.size());
  for (size_t i = 0; i < by_q.rows.size(); ++i) EXPECT_EQ(by_q.rows[i].q, by_name.rows[i].q) << "row " << i;
}

TEST(RobotMeasurements, PostureGroupsOfAnotherSession) {
  RobotLog fitted, other;
  const auto Row = [](double a, double b) {
    RobotMeasurement m;
    m.q = Eigen::Vector2d(a, b);
    return m;
  };
  fitted.rows = {Row(0.0, 0.0), Row(1.0, 1.0)};
  other.rows = {Row(0.005, -0.004), Row(0.5, 0.5), Row(1.2, 0.5), Row(0.5, 1.02)};
  const auto g = PostureGroups(fitted, other, 0.01);
  ASSERT_EQ(g.size(), 4u);
  EXPECT_EQ(g[0], PostureGroup::kRepeated);
  EXPECT_EQ(g[1], PostureGroup::kNewInRange);
  EXPECT_EQ(g[2], PostureGroup::kOutOfRange);
  EXPECT_EQ(g[3], PostureGroup::kOutOfRange);
}

TEST(RobotMeasurements, BadLogsAreNamed) {
  const auto dir = test::ScratchDir("robot_measurements_bad");
  const RobotModel robot = Seven();
  const Truth t = MakeTruth(1, 0.0);
  const std::string good = MakeCsv(t, 15, 3);
  const auto Try = [&](const std::string& name, const std::string& text) {
    test::WriteText(dir / name, text);
    return ErrorOf([&] {
      const RobotLog log = ReadRobotLog(dir / name, robot);
      CheckRobotLogPlausible(log, robot);
    });
  };
  const auto Replace = [](std::string s, const std::string& a, const std::string& b) {
    const size_t p = s.find(a);
    if (p != std::string::npos) s.replace(p, a.size(), b);
    return s;
  };
  EXPECT_EQ(Try("good.csv", good), "(no InputError)");
  // A chain joint missing from the log.
  std::string e = Try("missing.csv", Replace(good, ",j3,", ",jx,"));
  EXPECT_NE(e.find("missing.csv: the chain's joint j3 is not in the log"), std::string::npos) << e;
  // A URDF joint that is not in the chain.
  e = Try("head.csv", Replace(good, "marker_std_mm", "head_joint"));
  EXPECT_NE(e.find("column 'head_joint' is joint head_joint of the URDF, which is not in the chain"),
            std::string::npos)
      << e;
  // Degrees in a radian column: every j2 value times 57.3.
  {
    std::istringstream in(good);
    std::ostringstream out;
    std::string line;
    std::getline(in, line);
    out << line << "\n";
    while (std::getline(in, line)) {
      std::vector<std::string> c;
      std::stringstream ss(line);
      std::string cell;
      while (std::getline(ss, cell, ',')) c.push_back(cell);
      c[4] = std::to_string(std::stod(c[4]) * 180.0 / std::numbers::pi);  // j2
      for (size_t k = 0; k < c.size(); ++k) out << (k ? "," : "") << c[k];
      out << "\n";
    }
    e = Try("deg.csv", out.str());
    EXPECT_NE(e.find("deg.csv line"), std::string::npos) << e;
    EXPECT_NE(e.find("looks like degrees"), std::string::npos) << e;
  }
  // Millimetres in the prismatic column.
  {
    std::istringstream in(good);
    std::ostringstream out;
    std::string line;
    std::getline(in, line);
    out << line << "\n";
    while (std::getline(in, line)) {
      std::vector<std::string> c;
      std::stringstream ss(line);
      std::string cell;
      while (std::getline(ss, cell, ',')) c.push_back(cell);
      c[2] = std::to_string(std::stod(c[2]) * 1000.0);  // lift_joint
      for (size_t k = 0; k < c.size(); ++k) out << (k ? "," : "") << c[k];
      out << "\n";
    }
    e = Try("mm.csv", out.str());
    EXPECT_NE(e.find("looks like millimetres"), std::string::npos) << e;
  }
  // Points that are not one rigid body: row 5's point 3 moved by 5 mm.
  {
    std::istringstream in(good);
    std::ostringstream out;
    std::string line;
    int n = 0;
    while (std::getline(in, line)) {
      if (n == 5) {
        std::vector<std::string> c;
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, ',')) c.push_back(cell);
        c[2 + 7 + 6] = std::to_string(std::stod(c[2 + 7 + 6]) + 0.005);  // x3
        line.clear();
        for (size_t k = 0; k < c.size(); ++k) line += (k ? "," : "") + c[k];
      }
      out << line << "\n";
      ++n;
    }
    e = Try("loose.csv", out.str());
    EXPECT_NE(e.find("loose.csv: the 4 points are not one rigid body"), std::string::npos) << e;
    EXPECT_NE(e.find("line 6"), std::string::npos) << e;
  }
  // Two points per row.
  {
    std::string two = "time_s";
    for (const Joint& j : robot.Joints()) two += "," + j.name;
    two += ",x1,y1,z1,x2,y2,z2\n0,0.1,0,0,0,0,0,0,1,2,3,1,2,3.1\n";
    e = Try("two.csv", two);
    EXPECT_NE(e.find("2 points per row"), std::string::npos) << e;
  }
  // A joint given twice (a bare name and its _rad column).
  e = Try("twice.csv", Replace(good, "marker_std_mm", "j2_rad"));
  EXPECT_NE(e.find("joint j2 has two columns, 'j2_rad' and 'j2'"), std::string::npos) << e;
}

// Four points of a rigid body on a URDF robot with every placement a little off: the
// calibration recovers the geometry (predicts held-out postures to the noise), and the
// calibrated URDF parses and reproduces the calibrated model.
TEST(RobotMeasurements, CalibratesAUrdfRobotFromFourPointsAndWritesItBack) {
  const auto dir = test::ScratchDir("robot_measurements_calib");
  const Truth t = MakeTruth(5, 1e-3);
  test::WriteText(dir / "fit.csv", MakeCsv(t, 60, 6));
  test::WriteText(dir / "other.csv", MakeCsv(t, 30, 7));
  test::WriteText(dir / "seven.urdf", test::SevenJointUrdf());
  RobotCalibrationJob job;
  job.measurements = dir / "fit.csv";
  job.robot = dir / "seven.urdf";
  job.chain = {"world", "tool"};
  job.output = dir / "calibrated.urdf";
  job.json = dir / "report.json";
  job.validate = {dir / "other.csv"};
  job.position_sigma_m = 1e-4;
  job.folds = 0;
  std::string report;
  RunRobotCalibrationJob(job, {[&report](const std::string& s) { report += s; }, {}});
  EXPECT_NE(report.find("4 points of a rigid body"), std::string::npos) << report;
  // Frozen on the other session: the calibrated model predicts every point to the noise
  // (0.17 mm RMS in 3-D for 0.1 mm per axis), the registered nominal one does not.
  const nlohmann::json j = nlohmann::json::parse(test::ReadAll(job.json));
  ASSERT_EQ(j["validation"].size(), 1u);
  const auto& models = j["validation"][0]["models"];
  ASSERT_EQ(models.size(), 2u);
  EXPECT_EQ(models[0]["model"], "registration");
  EXPECT_EQ(models[1]["model"], "geometry");
  ASSERT_EQ(models[1]["points"].size(), 4u);
  for (int k = 0; k < 4; ++k) {
    const double cal = models[1]["points"][k]["rms_mm"], nom = models[0]["points"][k]["rms_mm"];
    EXPECT_LT(cal, 0.3) << "point " << k + 1;
    EXPECT_GT(nom, 5 * cal) << "point " << k + 1;
  }
  EXPECT_NE(test::ReadAll(job.output).find("mcms calib-robot: corrections folded into this origin"), std::string::npos);

  // The calibrated URDF parses with urdfdom and its FK equals the calibrated model's.
  const RobotLog log = ReadRobotLog(dir / "fit.csv", Seven());
  RobotCalibrationOptions o;
  o.position_sigma_m = 1e-4;
  const RobotModel nominal = Seven();
  const RobotCalibrationResult r = CalibrateRobot(nominal, InitialBaseGuess(nominal, log.rows), log.rows, o);
  EXPECT_TRUE(r.converged);
  ASSERT_EQ(r.points_tool.size(), 3u);
  WriteUrdf(dir / "back.urdf", r.robot);
  const RobotModel back = RobotModel::Read(dir / "back.urdf", {"world", "tool"});
  Rng rng(9);
  for (int k = 0; k < 20; ++k) {
    Eigen::VectorXd q(7);
    q[0] = rng.Uniform(0.05, 0.35);
    for (int i = 1; i < 7; ++i) q[i] = rng.Uniform(-1.2, 1.2);
    EXPECT_LT((back.T_base_flange(q).t - r.robot.T_base_flange(q).t).norm(), 1e-9);
    EXPECT_LT((back.T_base_flange(q).R - r.robot.T_base_flange(q).R).norm(), 1e-9);
  }
}

}  // namespace
}  // namespace mcms
