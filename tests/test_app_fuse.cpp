// mcms fuse through the command line: a clean run on small synthetic logs, and every kind
// of bad input refused with one clear line naming the file and the line, a non-zero exit
// and no output file (nor a temporary left behind).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <tuple>

#include "core/io.h"
#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "tests/cli_runner.h"
#include "tests/fuse_logs.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;
using Lines = std::vector<std::string>;

using test::CliRun;

using test::CleanLogs;
using test::Logs;
using test::N;
using test::Write;

// Replaces cell `col` (0-based) of line `line` (1-based) of a CSV.
void SetCell(Lines& lines, int line, int col, const std::string& v) {
  std::vector<std::string> cells;
  std::stringstream s(lines[line - 1]);
  std::string c;
  while (std::getline(s, c, ',')) cells.push_back(c);
  cells.at(col) = v;
  std::string out;
  for (size_t i = 0; i < cells.size(); ++i) out += (i ? "," : "") + cells[i];
  lines[line - 1] = out;
}

const std::string kArgs =
    "fuse --quiet --tracker poses.csv --robot joints.csv --inclinometer incl.csv --setup "
    "setup.yaml -o fused.csv";

// Runs mcms in `dir` (relative file names, so messages name them as given).
CliRun Fuse(const fs::path& dir, const std::string& args = kArgs) {
  return test::Mcms(dir, args);
}

// Writes the logs into a fresh folder, runs the CLI and expects a refusal whose one line
// contains every needle, and no output.
void ExpectRefused(const std::string& name, const Logs& l, const std::vector<std::string>& needles,
                   const std::string& args = kArgs) {
  SCOPED_TRACE(name);
  const fs::path d = test::ScratchDir("app_fuse_" + name);
  Write(d, l);
  const CliRun r = Fuse(d, args);
  EXPECT_EQ(r.code, 2) << r.err;
  for (const auto& n : needles) EXPECT_NE(r.err.find(n), std::string::npos) << "missing '" << n << "' in: " << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "one line: " << r.err;
  EXPECT_FALSE(fs::exists(d / "fused.csv")) << "no output may be written";
  for (const auto& e : fs::directory_iterator(d))
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << "left behind: " << e.path();
}

TEST(AppFuse, HelpDocumentsTheFormats) {
  const fs::path d = test::ScratchDir("app_fuse_help");
  const std::string cmd = std::string(MCMS_CLI) + " fuse --help > " + (d / "help.txt").string();
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const std::string help = ReadTextFile(d / "help.txt");
  for (const char* s : {"time_s,q1_rad", "tilt_x_rad", "T_base_rig", "T_flange_target", "robot_accuracy", "cov_<a>_<b>",
                        "moifa|kf", "flagged"})
    EXPECT_NE(help.find(s), std::string::npos) << s;
}

TEST(AppFuse, FusesCleanLogs) {
  const fs::path d = test::ScratchDir("app_fuse_clean");
  Write(d, CleanLogs());
  const CliRun r = Fuse(d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "fused.csv");
  ASSERT_EQ(t.rows.size(), 40u);  // 20 frames, moifa and kf
  EXPECT_EQ(t.header.size(), 16u + 36u);
  EXPECT_TRUE(t.HasColumn("excluded") && t.HasColumn("fault"));
  EXPECT_EQ(t.rows[0][t.Column("method")], "moifa");
  EXPECT_EQ(t.rows[1][t.Column("method")], "kf");
  EXPECT_EQ(t.rows[0][t.Column("sensors")], "camera;robot;inclinometer");
  EXPECT_TRUE(t.HasColumn("cov_pz_pz"));
  // --method kf alone, and the robot alone as the second sensor.
  ASSERT_EQ(Fuse(d, "fuse -q --tracker poses.csv --robot joints.csv --setup setup.yaml -o kf.csv --method kf").code, 0);
  const CsvTable k = ReadCsv(d / "kf.csv");
  ASSERT_EQ(k.rows.size(), 20u);
  EXPECT_EQ(k.rows[5][k.Column("sensors")], "camera;robot");
}

// A robot joint offset burst (A2 +0.5 deg for 0.2 s) in the joint log: `mcms fuse` names the
// robot in the rows it corrupts (columns excluded and fault) and leaves it out of them.
TEST(AppFuse, AFaultySensorIsNamedAndLeftOut) {
  Logs l = CleanLogs();
  Lines& j = l.files["joints.csv"];
  for (int k = 140; k < 160; ++k) {  // 1.40 .. 1.59 s; line k + 2
    std::stringstream s(j[k + 1]);
    std::vector<std::string> cells;
    std::string c;
    while (std::getline(s, c, ',')) cells.push_back(c);
    SetCell(j, k + 2, 2, N(std::stod(cells.at(2)) + 0.5));
  }
  const fs::path d = test::ScratchDir("app_fuse_fault");
  Write(d, l);
  const CliRun r = Fuse(d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "fused.csv");
  int named = 0, clean_rows_changed = 0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    const double time = t.Number(i, t.Column("time_s"));
    const std::string& excluded = t.rows[i][t.Column("excluded")];
    const std::string& fault = t.rows[i][t.Column("fault")];
    // MOIFA interpolates the joints at the frame (1.6 s is clean); the KF row at 1.6 s has
    // taken the readings since 1.5 s.
    const bool kf = t.rows[i][t.Column("method")] == "kf";
    if (time > 1.39 && time < (kf ? 1.61 : 1.55)) {
      EXPECT_NE(excluded.find("robot"), std::string::npos) << time << " " << fault;
      EXPECT_NE(fault.find("robot"), std::string::npos) << fault;
      // (A KF row also took the clean readings of its interval: the robot is among its sensors.)
      if (!kf) {
        EXPECT_EQ(t.rows[i][t.Column("sensors")].find("robot"), std::string::npos) << time;
      }
      ++named;
    } else {
      clean_rows_changed += excluded.empty() ? 0 : 1;
    }
  }
  EXPECT_EQ(named, 5);  // frames at 1.4, 1.5 s (MOIFA), 1.4, 1.5, 1.6 s (KF)
  EXPECT_EQ(clean_rows_changed, 0);
}

// The demo fuses the logs it writes by the path `mcms fuse` runs: fusing those files again
// with `mcms fuse --windows` gives the demo's fused file byte for byte, and the demo reports
// the number of points it was asked for.
TEST(AppFuse, TheDemosLogsReproduceItsFusion) {
  const fs::path d = test::ScratchDir("app_fuse_demo");
  const fs::path demo = d / "demo";
  const std::string run_demo = std::string(MCMS_CLI) + " demo -q --no-iso9283 --points 3 --threads 2 -o " +
                               demo.string() + " > " + (d / "demo.txt").string();
  ASSERT_EQ(std::system(run_demo.c_str()), 0) << ReadTextFile(d / "demo.txt");
  const std::string text = ReadTextFile(d / "demo.txt");
  EXPECT_NE(text.find("Flange pose at the 3 points"), std::string::npos) << text;
  EXPECT_EQ(text.find("76 points"), std::string::npos) << text;
  const std::string fuse = "cd " + demo.string() + " && " + std::string(MCMS_CLI) +
                           " fuse -q --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer "
                           "inclinometer.csv --setup fusion_setup.yaml --windows dwells.csv -o " +
                           (d / "refused.csv").string();
  ASSERT_EQ(std::system(fuse.c_str()), 0);
  const std::string demo_fused = ReadTextFile(demo / "fused_poses.csv");
  EXPECT_EQ(ReadTextFile(d / "refused.csv"), demo_fused);
  const CsvTable t = ReadCsv(demo / "fused_poses.csv");
  ASSERT_EQ(t.rows.size(), 6u);  // 3 dwells, MOIFA and KF
  for (size_t i = 0; i < t.rows.size(); ++i) {
    EXPECT_EQ(t.rows[i][t.Column("frame")], std::to_string(i / 2));
    EXPECT_EQ(t.rows[i][t.Column("method")], i % 2 ? "kf" : "moifa");
    EXPECT_EQ(t.rows[i][t.Column("sensors")], "camera;robot;inclinometer");
  }
  // Per frame (no windows) the same logs fuse too, one MOIFA and one KF row per tracked frame.
  const std::string per_frame = "cd " + demo.string() + " && " + std::string(MCMS_CLI) +
                                " fuse -q --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer "
                                "inclinometer.csv --setup fusion_setup.yaml -o " +
                                (d / "frames.csv").string();
  ASSERT_EQ(std::system(per_frame.c_str()), 0);
  EXPECT_GT(ReadCsv(d / "frames.csv").rows.size(), t.rows.size());
}

TEST(AppFuse, BadTrackerLogsAreRefused) {
  const Logs clean = CleanLogs();
  {
    Logs l = clean;
    SetCell(l.files["poses.csv"], 6, 1, "0.3");  // line 6 is frame 4 at 0.6 s; line 5 has 0.5
    ExpectRefused("tracker_time", l, {"poses.csv line 6", "does not increase"});
  }
  {
    Logs l = clean;
    SetCell(l.files["poses.csv"], 1, 7, "q_w");
    ExpectRefused("tracker_column", l, {"poses.csv", "missing column 'qw'"});
  }
  {
    Logs l = clean;
    SetCell(l.files["poses.csv"], 4, 4, "nan");
    ExpectRefused("tracker_nan", l, {"poses.csv line 4, column 'x_m'", "finite number"});
  }
  {
    Logs l = clean;
    SetCell(l.files["poses.csv"], 9, 13, "inf");
    ExpectRefused("tracker_inf", l, {"poses.csv line 9, column 'cov_rx_rz'", "finite number"});
  }
  {
    Logs l = clean;
    l.files["poses.csv"].clear();
    ExpectRefused("tracker_empty", l, {"poses.csv line 1: empty file"});
  }
  {
    Logs l = clean;
    l.files["poses.csv"].resize(1);
    ExpectRefused("tracker_header_only", l, {"poses.csv line 1: header but no data rows"});
  }
  {
    Logs l = clean;
    SetCell(l.files["poses.csv"], 7, 11 + 3, "1e-9");  // cov_rx_px, its mirror stays 0
    ExpectRefused("tracker_asymmetric", l, {"poses.csv line 7: covariance is not symmetric", "cov_rx_px"});
  }
  {
    Logs l = clean;
    SetCell(l.files["poses.csv"], 8, 11 + 35, "-1e-9");  // cov_pz_pz negative
    ExpectRefused("tracker_indefinite", l, {"poses.csv line 8: covariance is not positive definite"});
  }
  {
    Logs l = clean;
    for (size_t i = 1; i < l.files["poses.csv"].size(); ++i)
      SetCell(l.files["poses.csv"], static_cast<int>(i) + 1, 2, "lost");
    ExpectRefused("tracker_all_lost", l, {"poses.csv line 21", "every row has status lost"});
  }
}

TEST(AppFuse, BadRobotLogsAreRefused) {
  const Logs clean = CleanLogs();
  {
    Logs l = clean;
    for (auto& s : l.files["joints.csv"]) s = s.substr(0, s.rfind(','));
    // The joint whose column is missing is named (issue 53), not the count.
    ExpectRefused("robot_count", l,
                  {"joints.csv: no column for joint 6 ('A6') (q6_rad or q6_deg)", "6 joints", "--robot"});
  }
  {
    Logs l = clean;
    for (auto& s : l.files["joints.csv"]) s += s.rfind("time_s", 0) == 0 ? ",q7_rad" : ",0";
    ExpectRefused("robot_extra", l, {"joints.csv: 7 joint columns (q1 .. q7)", "6 joints"});
  }
  {
    Logs l = clean;
    SetCell(l.files["joints.csv"], 30, 5, "140");  // A5 limit is +-130 deg
    ExpectRefused("robot_limit", l, {"joints.csv line 30", "A5", "above its upper limit"});
  }
  {
    Logs l = clean;
    SetCell(l.files["joints.csv"], 12, 0, "0.05");
    ExpectRefused("robot_time", l, {"joints.csv line 12", "does not increase"});
  }
  {
    Logs l = clean;
    SetCell(l.files["joints.csv"], 40, 3, "NaN");
    ExpectRefused("robot_nan", l, {"joints.csv line 40, column 'q3_deg'", "finite number"});
  }
  {
    Logs l = clean;
    l.files["joints.csv"].resize(1);
    ExpectRefused("robot_empty", l, {"joints.csv line 1: header but no data rows"});
  }
  {
    Logs l = clean;
    SetCell(l.files["joints.csv"], 1, 0, "t");
    ExpectRefused("robot_column", l, {"joints.csv line 1: missing column 'time_s'"});
  }
  {
    Logs l = clean;
    for (size_t i = 1; i < l.files["joints.csv"].size(); ++i) {
      std::string& s = l.files["joints.csv"][i];
      s = N(std::stod(s.substr(0, s.find(','))) + 100.0) + s.substr(s.find(','));
    }
    ExpectRefused("robot_no_overlap", l,
                  {"no time overlap", "poses.csv covers [0.2, 2.1] s", "joints.csv covers [100, 102.2] s"});
  }
}

TEST(AppFuse, BadInclinometerLogsAndSetupsAreRefused) {
  const Logs clean = CleanLogs();
  {
    Logs l = clean;
    SetCell(l.files["incl.csv"], 1, 2, "tilt_z_rad");
    ExpectRefused("incl_column", l, {"incl.csv line 1: missing column 'tilt_y_rad' or 'tilt_y_deg'"});
  }
  {
    Logs l = clean;
    SetCell(l.files["incl.csv"], 20, 1, "-inf");
    ExpectRefused("incl_inf", l, {"incl.csv line 20, column 'tilt_x_rad'", "finite number"});
  }
  {
    Logs l = clean;
    SetCell(l.files["incl.csv"], 50, 0, "0.96");  // line 50 has 0.96 s, line 51 0.98 s
    SetCell(l.files["incl.csv"], 51, 0, "0.96");
    ExpectRefused("incl_time", l, {"incl.csv line 51", "does not increase"});
  }
  {
    Logs l = clean;
    l.files["incl.csv"].clear();
    ExpectRefused("incl_empty", l, {"incl.csv line 1: empty file"});
  }
  {
    Logs l = clean;
    l.files["setup.yaml"].erase(l.files["setup.yaml"].begin(), l.files["setup.yaml"].begin() + 5);
    ExpectRefused("setup_missing", l, {"setup file setup.yaml", "missing 'T_base_rig'"});
  }
  {
    Logs l = clean;
    l.files["setup.yaml"].push_back("  orientation_sigma_mrad: 3");
    ExpectRefused("setup_unknown_key", l, {"setup file setup.yaml line 15", "unknown key 'orientation_sigma_mrad'"});
  }
  {
    Logs l = clean;
    l.files["setup.yaml"][6] = "  translation_m: [0, .nan, 0.1]";
    ExpectRefused("setup_nan", l, {"setup file setup.yaml line 7", "T_flange_target.translation_m must be finite"});
  }
  {
    Logs l = clean;
    l.files["setup.yaml"].clear();
    ExpectRefused("setup_empty", l, {"setup file setup.yaml line 1: empty file"});
  }
  {
    Logs l = clean;
    ExpectRefused("no_second_sensor", l, {"--robot and/or --inclinometer"},
                  "fuse --tracker poses.csv --setup setup.yaml -o fused.csv");
  }
}

// Issue 29: fusion windows from -1e308 to 1e308 s gave a KF row of -4e294 and NaN
// quaternions (the filter predicted to the window's end); windows wholly outside the logs
// gave a header-only CSV and "0 rows". Both are refused, the windows file and the logs'
// span named; a window a little beyond the logs' end is still fused.
TEST(BadInput, FusionWindowsBeyondOrOutsideTheLogs) {
  const Logs clean = CleanLogs();
  for (const auto& [name, window, needle] :
       {std::tuple<std::string, std::string, std::string>{"outside", "1e6,2e6", "holds no sample of any log"},
        {"absurd", "-1e308,1e308", "reaches far beyond the logs"}}) {
    Logs l = clean;
    l.files["w.csv"] = {"start_s,end_s", window};
    ExpectRefused("windows_" + name, l, {"w.csv: fusion window 0", needle, "the logs span", "clock and units"},
                  kArgs + " --windows w.csv");
  }
  const fs::path d = test::ScratchDir("app_fuse_windows_beyond_end");
  Logs l = clean;
  l.files["w.csv"] = {"start_s,end_s", "0,3"};  // the logs end at 2.2 s
  Write(d, l);
  const CliRun r = Fuse(d, kArgs + " --windows w.csv");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string csv = test::ReadAll(d / "fused.csv");
  EXPECT_EQ(csv.find("nan"), std::string::npos) << csv;
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 3) << "a header, a moifa and a kf row: " << csv;
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// Issue 53: one flange for both descriptions of a robot. The KR 5 as its DH table (the
// default) and as the URDF written from it fuse the same logs to the same poses: the URDF's
// flange is its tip link, through the fixed joint after A6.
TEST(AppFuse, TheSameRobotAsUrdfFusesTheSame) {
  const auto d = test::ScratchDir("fuse_urdf_flange");
  const fs::path ex = fs::path(MCMS_SOURCE_DIR) / "examples";
  const RobotModel dh = RobotModel::Default();
  const RobotModel urdf = RobotModel::Read(ex / "robots" / "kuka_kr5_arc.urdf");
  for (double a : {0.1, 0.7, -0.2}) {
    const Eigen::VectorXd q = Eigen::VectorXd::Constant(6, a);
    const Pose A = dh.T_base_flange(q), B = urdf.T_base_tool(q);
    EXPECT_LT((A.t - B.t).norm(), 1e-12) << a;
    EXPECT_LT((A.R - B.R).norm(), 1e-12) << a;
  }
  for (const char* f : {"tracker_poses.csv", "robot_joints.csv", "inclinometer.csv", "fusion_setup.yaml"})
    fs::copy_file(ex / "fusion" / f, d / f, fs::copy_options::overwrite_existing);
  test::WriteText(d / "setup_urdf.yaml", test::ReadAll(d / "fusion_setup.yaml") + "robot: " +
                                             (ex / "robots" / "kuka_kr5_arc.urdf").string() + "\n");
  const std::string run = "fuse --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer inclinometer.csv -q";
  ASSERT_EQ(test::Mcms(d, run + " --setup fusion_setup.yaml -o dh.csv").code, 0);
  const CliRun r = test::Mcms(d, run + " --setup setup_urdf.yaml -o urdf.csv");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string a = test::ReadAll(d / "dh.csv"), b = test::ReadAll(d / "urdf.csv");
  EXPECT_EQ(b.find("robot excluded"), std::string::npos);
  EXPECT_EQ(std::count(a.begin(), a.end(), '\n'), std::count(b.begin(), b.end(), '\n'));
  // A URDF of two arms: the setup names the chain with tip_link (fuse has no --tip-link).
  test::WriteText(d / "two.urdf", R"(<robot name="two"><link name="b"/>
    <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="l1"/>
    <joint name="j2" type="revolute"><parent link="b"/><child link="l2"/><axis xyz="0 1 0"/>
      <limit lower="-3" upper="3" effort="1" velocity="1"/></joint><link name="l2"/></robot>)");
  test::WriteText(d / "setup_two.yaml", test::ReadAll(d / "fusion_setup.yaml") + "robot: two.urdf\n");
  const CliRun two = test::Mcms(d, run + " --setup setup_two.yaml -o two.csv");
  EXPECT_EQ(two.code, 2);
  EXPECT_NE(two.err.find("setup_two.yaml"), std::string::npos) << two.err;
  EXPECT_NE(two.err.find("give tip_link (a key of the setup)"), std::string::npos) << two.err;
  EXPECT_EQ(two.err.find("--tip-link"), std::string::npos) << two.err;
  EXPECT_FALSE(fs::exists(d / "two.csv"));
  // Issue 53: `robot: .` names the setup, its line and the key.
  test::WriteText(d / "setup_dot.yaml", test::ReadAll(d / "fusion_setup.yaml") + "robot: .\n");
  const CliRun dot = test::Mcms(d, run + " --setup setup_dot.yaml -o dot.csv");
  EXPECT_EQ(dot.code, 2);
  EXPECT_NE(dot.err.find("setup_dot.yaml"), std::string::npos) << dot.err;
  EXPECT_NE(dot.err.find("robot: "), std::string::npos) << dot.err;
  EXPECT_NE(dot.err.find("is a folder; expected the robot's description file"), std::string::npos) << dot.err;
  EXPECT_FALSE(fs::exists(d / "dot.csv"));
}

}  // namespace
}  // namespace mcms
