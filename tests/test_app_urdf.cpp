// Robots as ROS describes them, end to end through `mcms`: the real TIAGo measured by motion
// capture reproduces FIGAROH's published calibration and held-out scores, its calibrated URDF
// agrees with the reported parameters, the audit runs on it with another day frozen; and the
// examples' DH robots written as URDF give the same audit findings and calibration.
#include <gtest/gtest.h>

#include <cmath>

#include <nlohmann/json.hpp>

#include "model/robot_model.h"
#include "model/urdf.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"
#include "tests/urdf_robots.h"

namespace mcms {
namespace {

using test::Mcms;

nlohmann::json ReadJson(const std::filesystem::path& p) { return nlohmann::json::parse(test::ReadAll(p)); }

const nlohmann::json& Model(const nlohmann::json& session, const std::string& name) {
  for (const auto& m : session["models"])
    if (m["model"] == name) return m;
  throw std::runtime_error("no model " + name);
}

const nlohmann::json& Parameter(const nlohmann::json& report, const std::string& name) {
  for (const auto& p : report["parameters"])
    if (p["name"] == name) return p;
  throw std::runtime_error("no parameter " + name);
}

std::string Tiago(const std::filesystem::path& d, const std::string& more) {
  return "calib-robot " + (d / "qualisys_2021-11-30_static_postures.csv").string() + " --robot " +
         (d / "tiago_48_hey5.urdf").string() + " --tip-link wrist_ft_tool_link --points 1 --validate " +
         (d / "qualisys_2021-11-26_static_postures.csv").string() + " --quiet --folds 0 " + more;
}

// FIGAROH (fit on 2021-11-30, score 2021-11-26 frozen, point 1): registration only 3.37 /
// 4.87 mm (max 12.2); + joint offsets of arm_2..arm_6 2.88 / 4.23 mm (max 12.0), arm_5's
// offset -49.8 +- 10.1 mrad. Within 0.02 mm (the published figures' last digit for the max).
TEST(AppUrdf, RealTiagoReproducesFigaroh) {
  MCMS_REQUIRE_DATA(d, "tiago-mocap");
  const auto dir = test::ScratchDir("app_urdf_figaroh");
  auto run = Mcms(dir, Tiago(d, "--registration-only -o reg.urdf --json reg.json"));
  ASSERT_EQ(run.code, 0) << run.err;
  const nlohmann::json reg = ReadJson(dir / "reg.json");
  EXPECT_NEAR(reg["residuals"]["geometry"][0]["rms_mm"].get<double>(), 3.37, 0.02);
  EXPECT_NEAR(Model(reg["validation"][0], "geometry")["points"][0]["rms_mm"].get<double>(), 4.87, 0.02);
  EXPECT_NEAR(Model(reg["validation"][0], "geometry")["points"][0]["max_mm"].get<double>(), 12.2, 0.05);
  EXPECT_EQ(reg["validation"][0]["rows"], 62);

  run = Mcms(dir, Tiago(d, "--estimate 'arm_[2-6]_joint.offset' -o offsets.urdf --json offsets.json"));
  ASSERT_EQ(run.code, 0) << run.err;
  const nlohmann::json off = ReadJson(dir / "offsets.json");
  EXPECT_NEAR(off["residuals"]["registration"][0]["rms_mm"].get<double>(), 3.37, 0.02);
  EXPECT_NEAR(off["residuals"]["geometry"][0]["rms_mm"].get<double>(), 2.88, 0.02);
  const auto& val = Model(off["validation"][0], "geometry");
  EXPECT_NEAR(val["points"][0]["rms_mm"].get<double>(), 4.23, 0.02);
  EXPECT_NEAR(val["points"][0]["max_mm"].get<double>(), 12.0, 0.05);
  const auto& a5 = Parameter(off, "arm_5_joint.offset");
  EXPECT_NEAR(a5["estimate"].get<double>() * 1e3, -49.8, 0.1);
  EXPECT_NEAR(a5["sigma"].get<double>() * 1e3, 10.1, 0.1);
  EXPECT_TRUE(Parameter(off, "arm_1_joint.offset")["fixed"].get<bool>());
  EXPECT_TRUE(Parameter(off, "arm_7_joint.offset")["fixed"].get<bool>());

  // The calibrated URDF is the TIAGo's with the offsets folded into the joints' origins: it
  // parses with urdfdom, keeps every other element, and its forward kinematics are the
  // nominal chain with the reported parameters applied (1e-9 m).
  const std::string text = test::ReadAll(dir / "offsets.urdf");
  EXPECT_NE(text.find("hand_thumb_joint"), std::string::npos);
  EXPECT_NE(text.find("<transmission"), std::string::npos);
  EXPECT_NE(text.find("mcms calib-robot: corrections folded into this origin"), std::string::npos);
  const RobotModel nominal = RobotModel::Read(d / "tiago_48_hey5.urdf", {"", "wrist_ft_tool_link"});
  const RobotModel written = RobotModel::Read(dir / "offsets.urdf", {"", "wrist_ft_tool_link"});
  Eigen::VectorXd delta = Eigen::VectorXd::Zero(nominal.NumGeometryParameters());
  const auto names = GeometryParameterNames(nominal);
  for (size_t k = 0; k < names.size(); ++k) delta[k] = Parameter(off, names[k])["estimate"].get<double>();
  const RobotModel calibrated = WithGeometryErrors(nominal, delta);
  Eigen::VectorXd q(8);
  q << 0.2, 1.2, -0.4, -0.7, 2.0, -0.5, 0.6, -0.5;
  EXPECT_LT((written.T_base_flange(q).t - calibrated.T_base_flange(q).t).norm(), 1e-9);
  EXPECT_LT((written.T_base_flange(q).R - calibrated.T_base_flange(q).R).norm(), 1e-9);
  EXPECT_GT((written.T_base_flange(q).t - nominal.T_base_flange(q).t).norm(), 1e-4);

  // FIGAROH's full geometric level (every identifiable placement error) reported beside its
  // 1.64 / 3.07 mm: it runs and is scored frozen.
  run = Mcms(dir, Tiago(d, "-o full.urdf --json full.json"));
  ASSERT_EQ(run.code, 0) << run.err;
  const nlohmann::json full = ReadJson(dir / "full.json");
  const double train = full["residuals"]["geometry"][0]["rms_mm"], held = Model(full["validation"][0], "geometry")["points"][0]["rms_mm"];
  RecordProperty("full_level_train_mm", std::to_string(train));
  RecordProperty("full_level_heldout_mm", std::to_string(held));
  EXPECT_LT(train, 1.7);
  EXPECT_GT(held, train);
}

// The real TIAGo explained (issue 34; docs/tiago.md): the audit fitted on 2021-11-30 alone,
// 2021-11-26 frozen.
TEST(AppUrdf, RealTiagoAuditExplainsAnotherDayBetterThanFigaroh) {
  MCMS_REQUIRE_DATA(d, "tiago-mocap");
  const auto dir = test::ScratchDir("app_urdf_tiago_audit");
  const auto run = Mcms(dir, "audit robot " + (d / "qualisys_2021-11-30_static_postures.csv").string() + " --robot " +
                                 (d / "tiago_48_hey5.urdf").string() + " --tip-link wrist_ft_tool_link --validate " +
                                 (d / "qualisys_2021-11-26_static_postures.csv").string() + " -o audit -q");
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_NE(run.out.find("4 points of a rigid body"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("columns not used: shipped_row marker_std_mm"), std::string::npos) << run.out;
  const nlohmann::json rep = ReadJson(dir / "audit" / "report.json");
  ASSERT_EQ(rep["validation"].size(), 1u);
  // Issue 51: no nested fit below the model it extends on the real TIAGo.
  EXPECT_EQ(rep["nested_fits"]["failed"].get<long>(), 0);
  EXPECT_GE(rep["nested_fits"]["worst_relative_lr"].get<double>(), -1e-6);
  const auto& s = rep["validation"][0];
  EXPECT_EQ(s["rows"], 62);
  for (const char* m : {"registration", "geometry", "final"}) {
    const auto& model = Model(s, m);
    ASSERT_EQ(model["points"].size(), 4u) << m;
    EXPECT_GT(model["points"][0]["rms_mm"].get<double>(), 0.5) << m;
    EXPECT_TRUE(model["groups"].contains("repeated")) << m;
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "audit" / "robot.urdf"));
  EXPECT_TRUE(std::filesystem::exists(dir / "audit" / "validation.csv"));
  EXPECT_TRUE(std::filesystem::exists(dir / "audit" / "plots" / "validation1.svg"));
  const std::string text = test::ReadAll(dir / "audit" / "report.txt");
  // The arm's weight comes from the URDF's inertials: gravity compliance is a candidate with
  // the robot's own masses (no lumped-mass note).
  EXPECT_EQ(text.find("lumped"), std::string::npos);
  EXPECT_NE(text.find("what each cause moved there"), std::string::npos) << text;
  EXPECT_TRUE(rep.contains("tests_after")) << "what remains unexplained";

  // Issue 34: the final model, fitted on 2021-11-30 alone, beats FIGAROH's best (its
  // 31-parameter geometry: 3.07 mm held out, 2.84 mm on the new postures inside the range).
  const double final_rms = Model(s, "final")["points"][0]["rms_mm"].get<double>();
  const double final_new = Model(s, "final")["groups"]["new_in_range"]["points"][0]["rms_mm"].get<double>();
  RecordProperty("final_heldout_mm", std::to_string(final_rms));
  RecordProperty("final_new_in_range_mm", std::to_string(final_new));
  EXPECT_LT(final_rms, 3.07);
  EXPECT_LT(final_new, 2.84);
  EXPECT_LT(final_rms, Model(s, "geometry")["points"][0]["rms_mm"].get<double>());
  // Every named non-geometric cause helps on the other day (the final model refitted
  // without it predicts 11-26 worse), and has a physical size.
  int physical = 0;
  for (const auto& e : rep["effects"]) {
    const std::string name = e["name"];
    if (name == "geometry") continue;
    ++physical;
    const std::string label = name + " at " + e["where"].get<std::string>();
    const double without = Model(s, "final without " + label)["points"][0]["rms_mm"].get<double>();
    EXPECT_GT(without, final_rms) << label << " does not help on 11-26";
    EXPECT_FALSE(e.contains("held")) << label << " at a physical bound";
    for (const auto& [key, v] : e["parameters"].items()) {
      if (name == "gravity_compliance") {
        EXPECT_GT(v.get<double>(), 0.0) << label;
      }
      if (name == "backlash") {
        EXPECT_GT(v.get<double>(), 0.0) << label;
        EXPECT_LT(v.get<double>(), 0.1) << label << ": more play than a joint could have";
      }
    }
  }
  EXPECT_GE(physical, 1) << "nothing beyond geometry named";
}

// The examples' DH robots written as URDF: the same audit findings (effect and joint) and
// the same calibration (forward kinematics of both calibrated robots to 1e-9 m).
TEST(AppUrdf, DhRobotAndItsUrdfGiveTheSameAuditAndCalibration) {
  const auto dir = test::ScratchDir("app_urdf_parity");
  const auto ex = std::filesystem::path(MCMS_SOURCE_DIR) / "examples";
  ASSERT_EQ(Mcms(dir, "convert-robot -o kr5.urdf").code, 0);
  // The committed example is what convert-robot writes.
  EXPECT_EQ(test::ReadAll(dir / "kr5.urdf"), test::ReadAll(ex / "robots" / "kuka_kr5_arc.urdf"));
  auto a = Mcms(dir, "audit robot " + (ex / "robot_log.csv").string() + " -q --json dh.json");
  ASSERT_EQ(a.code, 0) << a.err;
  auto b = Mcms(dir, "audit robot " + (ex / "robot_log.csv").string() + " --robot kr5.urdf -q --json urdf.json");
  ASSERT_EQ(b.code, 0) << b.err;
  const nlohmann::json dh = ReadJson(dir / "dh.json"), ur = ReadJson(dir / "urdf.json");
  ASSERT_EQ(dh["effects"].size(), ur["effects"].size());
  for (size_t k = 0; k < dh["effects"].size(); ++k) {
    EXPECT_EQ(dh["effects"][k]["name"], ur["effects"][k]["name"]);
    // "joint 3" of the DH table is joint "A3" of its URDF.
    const std::string w = dh["effects"][k]["where"];
    EXPECT_EQ(std::string("A").append(w.substr(w.rfind(' ') + 1)), ur["effects"][k]["where"]);
    const double x = dh["effects"][k]["parameters"]["offset_rad"], y = ur["effects"][k]["parameters"]["offset_rad"];
    EXPECT_NEAR(x, y, 1e-3 * std::abs(x));
  }
  EXPECT_EQ(dh["effects"][0]["name"], "joint_offset");

  // Calibration: the joint offsets are the same parameters in both descriptions, so the
  // offsets-only calibrations agree (estimates and residuals); the registration too. (A
  // URDF joint's placement error has 6 components where a DH joint has 4, so its full
  // geometric level fits at least as well, not the same.)
  const auto meas = (ex / "robot_measurements.yaml").string();
  auto c = Mcms(dir, "calib-robot " + meas + " --estimate '*.theta_offset' -o dh.yaml --json dh-cal.json --quiet");
  ASSERT_EQ(c.code, 0) << c.err;
  c = Mcms(dir, "calib-robot " + meas + " --robot kr5.urdf --estimate '*.offset' -o cal.urdf --json urdf-cal.json --quiet");
  ASSERT_EQ(c.code, 0) << c.err;
  const nlohmann::json cd = ReadJson(dir / "dh-cal.json"), cu = ReadJson(dir / "urdf-cal.json");
  EXPECT_NEAR(cd["residuals"]["geometry"][0]["rms_mm"].get<double>(), cu["residuals"]["geometry"][0]["rms_mm"].get<double>(),
              1e-6);
  EXPECT_NEAR(cd["residuals"]["registration"][0]["rms_mm"].get<double>(),
              cu["residuals"]["registration"][0]["rms_mm"].get<double>(), 1e-6);
  for (int j = 2; j <= 6; ++j) {
    const std::string n = std::string("A").append(std::to_string(j));
    const auto& pd = Parameter(cd, n + ".theta_offset");
    const auto& pu = Parameter(cu, n + ".offset");
    EXPECT_EQ(pd["fixed"], pu["fixed"]) << n;
    EXPECT_NEAR(pd["estimate"].get<double>(), pu["estimate"].get<double>(), 1e-8) << n;
    EXPECT_NEAR(pd["sigma"].get<double>(), pu["sigma"].get<double>(), 1e-6 * pd["sigma"].get<double>() + 1e-12) << n;
  }
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// Issue 53: URDF -> YAML -> URDF -> YAML: convert-robot reads back what it wrote (a URDF
// chain's YAML form written as a new URDF, mimic joints with their driver on a branch),
// and the forward kinematics stay the robot's.
TEST(AppUrdf, ConvertRobotReadsBackWhatItWrote) {
  const auto dir = test::ScratchDir("app_urdf_roundtrip");
  test::WriteText(dir / "seven.urdf", test::SevenJointUrdf());
  ASSERT_EQ(Mcms(dir, "convert-robot seven.urdf -o a.yaml").code, 0);
  auto r = Mcms(dir, "convert-robot a.yaml -o b.urdf");
  ASSERT_EQ(r.code, 0) << r.err;
  r = Mcms(dir, "convert-robot b.urdf -o c.yaml");
  ASSERT_EQ(r.code, 0) << r.err;
  const RobotModel a = RobotModel::Read(dir / "seven.urdf"), c = RobotModel::Read(dir / "c.yaml");
  ASSERT_EQ(a.NumJoints(), c.NumJoints());
  Eigen::VectorXd q(a.NumJoints());
  for (int k = 0; k < 5; ++k) {
    for (int j = 0; j < q.size(); ++j) {
      const Joint& jt = a.Joints()[j];
      const double lo = std::isfinite(jt.lower) ? jt.lower : -3, hi = std::isfinite(jt.upper) ? jt.upper : 3;
      q[j] = lo + (hi - lo) * (0.1 + 0.2 * k);
    }
    const Pose x = a.T_base_tool(q), y = c.T_base_tool(q);
    EXPECT_LT((x.t - y.t).norm(), 1e-9);
    EXPECT_LT((x.R - y.R).norm(), 1e-9);
  }
  // The construction robot's column: two mimic segments driven by one joint the chain does
  // not hold.
  if (const auto data = test::RealData("hilti-trailblazer")) {
    const auto hilti = *data / "trailblazer.urdf";
    ASSERT_EQ(Mcms(dir, "convert-robot " + hilti.string() + " --tip-link prism -o h.yaml").code, 0);
    r = Mcms(dir, "convert-robot h.yaml -o h.urdf");
    ASSERT_EQ(r.code, 0) << r.err;
    r = Mcms(dir, "convert-robot h.urdf -o h2.yaml");
    ASSERT_EQ(r.code, 0) << r.err;
    const RobotModel h = RobotModel::Read(hilti, {"", "prism"}), h2 = RobotModel::Read(dir / "h2.yaml");
    ASSERT_EQ(h.NumActuated(), h2.NumActuated());
    Eigen::VectorXd qa(h.NumActuated());
    qa << 2.5, 0.3, -0.4, 1.2, 0.2, -0.7, 0.9;
    EXPECT_LT((h.T_base_tool(h.ChainValues(qa)).t - h2.T_base_tool(h2.ChainValues(qa)).t).norm(), 1e-9);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace mcms
