// `mcms audit robot LOG.csv` end to end: a CSV log with a hidden joint offset is audited,
// the JSON names the effect; bad logs (one row, time going backwards, joints beyond the
// limits, a NaN temperature, a different joint count) get an error naming the file and
// the problem, a non-zero exit and no output.
#include <gtest/gtest.h>
#include <numbers>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>

#include "core/random.h"
#include "model/extensions.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

using test::CliRun;

// Runs `mcms ARGS` in `cwd`.
CliRun Mcms(const std::string& args, const fs::path& cwd) {
  return test::Mcms(cwd, args);
}

// A CSV log of the default robot: 30 poses x 4 passes over 2 h, a hidden joint 3 offset
// of `offset_deg`, anisotropic noise, a temperature column.
std::string LogCsv(double offset_deg, uint64_t seed) {
  Rng rng(seed);
  const RobotModel robot = RobotModel::Default();
  std::vector<Eigen::VectorXd> poses;
  const double lo[6] = {-1.2, -1.6, 0.2, -2.5, -1.6, -3.0}, hi[6] = {1.2, 0.4, 2.2, 2.5, 1.6, 3.0};
  for (int i = 0; i < 30; ++i) {
    Eigen::VectorXd q(6);
    for (int j = 0; j < 6; ++j) q[j] = rng.Uniform(lo[j], hi[j]);
    poses.push_back(q);
  }
  const Pose T_meas_base{ExpSO3(Vec3(0.0, 0.0, 2.5)), Vec3(2.0, 0.5, -0.2)};
  const Extension ext{Effect::kJointOffset, 2, 0};
  const double p = offset_deg * std::numbers::pi / 180;
  const double* params[1] = {&p};
  std::ostringstream o;
  o.precision(12);
  o << "time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad,x_m,y_m,z_m,temperature_c\n";
  for (int k = 0; k < 120; ++k) {
    const Eigen::VectorXd& q = poses[k % 30];
    MeasurementContext c;
    const PoseT<double> F = ExtendedFlangeT<double>(robot, {ext}, params, q, c);
    const Vec3 x = T_meas_base.R * (F.R * robot.T_flange_tool().t + F.t) + T_meas_base.t +
                   1e-3 * Vec3(0.02 * rng.Normal(), 0.03 * rng.Normal(), 0.05 * rng.Normal());
    o << 60.0 * k;
    for (int j = 0; j < 6; ++j) o << "," << q[j];
    o << "," << x[0] << "," << x[1] << "," << x[2] << "," << 21.0 + 0.01 * rng.Normal() << "\n";
  }
  return o.str();
}

TEST(AppAuditRobot, NamesAHiddenJointOffsetInACsvLog) {
  const fs::path d = test::ScratchDir("audit_robot_e2e");
  test::WriteText(d / "log.csv", LogCsv(0.006, 3));
  const CliRun r = Mcms("audit robot -q log.csv --json audit.json -o out", d);
  ASSERT_EQ(r.code, 0) << r.err;
  std::printf("%s", r.out.c_str());
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(d / "audit.json"));
  EXPECT_EQ(j["mode"], "robot");
  EXPECT_FALSE(j["clean"].get<bool>());
  ASSERT_GE(j["effects"].size(), 1u);
  EXPECT_EQ(j["effects"][0]["name"], "joint_offset");
  EXPECT_EQ(j["effects"][0]["where"], "joint 3");
  const double est = j["effects"][0]["parameters"]["offset_rad"].get<double>();
  const double sig = j["effects"][0]["sigma"]["offset_rad"].get<double>();
  EXPECT_LT(std::abs(est - 0.006 * std::numbers::pi / 180), 3 * sig);
  EXPECT_GT(j["effects"][0]["heldout_loglik_gain"].get<double>(), 0.0);
  for (const char* f : {"report.txt", "report.json", "robot.yaml", "residuals.csv", "plots/effect1.svg"})
    EXPECT_TRUE(fs::exists(d / "out" / f)) << f;
  // The extended robot carries the offset: auditing the same log against it is clean.
  const CliRun again = Mcms("audit robot -q log.csv --robot out/robot.yaml --json again.json", d);
  ASSERT_EQ(again.code, 0) << again.err;
  const nlohmann::json j2 = nlohmann::json::parse(std::ifstream(d / "again.json"));
  EXPECT_TRUE(j2["effects"].empty()) << again.out;
}

void ExpectRefused(const std::string& name, const std::string& csv, const std::vector<std::string>& words) {
  const fs::path d = test::ScratchDir("audit_robot_bad_" + name);
  test::WriteText(d / "log.csv", csv);
  const CliRun r = Mcms("audit robot -q log.csv --json audit.json -o out", d);
  EXPECT_NE(r.code, 0) << name;
  for (const auto& w : words)
    EXPECT_NE(r.err.find(w), std::string::npos) << name << ": '" << w << "' not in: " << r.err;
  EXPECT_FALSE(fs::exists(d / "audit.json")) << name;
  EXPECT_FALSE(fs::exists(d / "out")) << name;
}

// The CSV with cell `col` of data row `row` (1-based) replaced by `value`.
std::string Edit(const std::string& csv, int row, int col, std::string value) {
  std::istringstream in(csv);
  std::ostringstream out;
  std::string line;
  int k = 0;
  while (std::getline(in, line)) {
    if (k == row) {
      std::vector<std::string> cells;
      std::stringstream ls(line);
      std::string c;
      while (std::getline(ls, c, ',')) cells.push_back(c);
      cells[col] = std::move(value);
      for (size_t i = 0; i < cells.size(); ++i) out << (i ? "," : "") << cells[i];
      out << "\n";
    } else {
      out << line << "\n";
    }
    ++k;
  }
  return out.str();
}

// A log in millimetres under x_m headers (issue 29: it ran past 120 s fitting effects of
// likelihood ratios near 4,000): refused at once, the unit named.
TEST(AppAuditRobot, MillimetresUnderMetreHeadersAreNamed) {
  std::istringstream in(LogCsv(0.0, 4));
  std::ostringstream mm;
  std::string line;
  std::getline(in, line);
  mm << line << "\n";
  while (std::getline(in, line)) {
    std::vector<std::string> c;
    std::stringstream ls(line);
    std::string cell;
    while (std::getline(ls, cell, ',')) c.push_back(cell);
    for (int k = 7; k <= 9; ++k) c[k] = std::to_string(std::stod(c[k]) * 1000.0);
    for (size_t i = 0; i < c.size(); ++i) mm << (i ? "," : "") << c[i];
    mm << "\n";
  }
  ExpectRefused("millimetres", mm.str(), {"log.csv", "1000 times", "millimetres", "metres"});
}

TEST(AppAuditRobot, RefusesBadLogs) {
  const std::string good = LogCsv(0.0, 9);
  const std::string header = good.substr(0, good.find('\n') + 1);
  const std::string first = good.substr(header.size(), good.find('\n', header.size()) + 1 - header.size());
  ExpectRefused("one_row", header + first, {"log.csv", "1 measurement", "at least"});
  ExpectRefused("time_backwards", Edit(good, 5, 0, "1"), {"log.csv", "line 6", "time order"});
  ExpectRefused("beyond_limits", Edit(good, 3, 2, "2.5"), {"log.csv", "line 4", "A2"});
  ExpectRefused("nan_temperature", Edit(good, 2, 10, "nan"), {"log.csv", "temperature_c"});
  // A 7-joint log for the 6-joint robot.
  std::string seven = "time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad,q7_rad,x_m,y_m,z_m\n";
  for (int i = 0; i < 20; ++i) seven += std::to_string(i) + ",0,0,0.5,0,0,0,0,1,2,3\n";
  ExpectRefused("seven_joints", seven, {"log.csv", "7 joint columns", "6 joints", "--robot"});
  ExpectRefused("no_joints", "time_s,x_m,y_m,z_m\n0,1,2,3\n", {"log.csv", "q1_rad"});
}

// The CSV with `f` applied to the cells of every data row.
std::string MapRows(const std::string& csv, const std::function<void(std::vector<std::string>&)>& f) {
  std::istringstream in(csv);
  std::ostringstream out;
  std::string line;
  std::getline(in, line);
  out << line << "\n";
  while (std::getline(in, line)) {
    std::vector<std::string> c;
    std::stringstream ls(line);
    std::string cell;
    while (std::getline(ls, cell, ',')) c.push_back(cell);
    f(c);
    for (size_t i = 0; i < c.size(); ++i) out << (i ? "," : "") << c[i];
    out << "\n";
  }
  return out.str();
}

// Issue 29: logs whose residual tests all fail for a reason in the input (a mistyped row,
// duplicated rows, swapped axes, empty joint columns, absurd folds) are refused before any
// fit, the likely cause and the row named, nothing written.
TEST(BadInput, RobotLogsWhoseMisfitHasACauseInTheInput) {
  const std::string good = LogCsv(0.0, 11);
  ExpectRefused("mistyped_row", Edit(good, 6, 7, "1e308"), {"log.csv line 7", "absurdly far", "mistyped row"});
  ExpectRefused("one_row_in_mm", Edit(good, 9, 8, "650"), {"log.csv line 10", "mistyped row", "another unit"});
  std::string doubled;
  {
    std::istringstream in(good);
    std::string line;
    std::getline(in, line);
    doubled.append(line).append("\n");
    while (std::getline(in, line)) doubled.append(line).append("\n").append(line).append("\n");
  }
  ExpectRefused("every_row_twice", doubled, {"log.csv line 3 repeats line 2 exactly", "duplicate"});
  std::string same = good.substr(0, good.find('\n') + 1);
  const std::string first = good.substr(same.size(), good.find('\n', same.size()) + 1 - same.size());
  for (int i = 0; i < 100; ++i) same += first;
  ExpectRefused("hundred_identical_rows", same, {"log.csv line 3 repeats line 2 exactly"});
  ExpectRefused("x_y_swapped", MapRows(good, [](std::vector<std::string>& c) { std::swap(c[7], c[8]); }),
                {"log.csv", "mirror image", "swapped"});
  ExpectRefused("joints_all_zero",
                MapRows(good,
                        [](std::vector<std::string>& c) {
                          for (int j = 1; j <= 6; ++j) c[j].assign(1, '0');
                        }),
                {"log.csv", "same place in every row", "joint columns"});
  // Issue 53: positions that never move, and one joint in another unit than its header,
  // are named as such (not "give positions in metres").
  ExpectRefused("positions_never_move",
                MapRows(good,
                        [](std::vector<std::string>& c) {
                          c[7] = "1.5", c[8] = "0.25", c[9] = "0.75";
                        }),
                {"log.csv", "the measured positions do not move", "position columns filled"});
  {
    std::string deg = good;
    deg.replace(deg.find("q3_rad"), 6, "q3_deg");
    ExpectRefused("radians_under_deg", deg, {"log.csv", "once joint A3's logged values are taken 57.3 times as large",
                                             "radians under a _deg header?"});
  }
  {
    const fs::path d = test::ScratchDir("calib_robot_tool_500m");
    test::WriteText(d / "log.csv", good);
    const CliRun r = Mcms("calib-robot log.csv --tool-guess 0 0 500 1 0 0 0 -o robot.yaml", d);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find("--tool-guess puts the tool 500 m from the flange; expected at most 10 m"), std::string::npos)
        << r.err;
    EXPECT_NE(r.err.find("millimetres?"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(d / "robot.yaml"));
  }
  // --folds beyond what the rows allow (audit lens refuses the equivalent).
  const fs::path d = test::ScratchDir("audit_robot_bad_folds");
  test::WriteText(d / "log.csv", good);
  const CliRun r = Mcms("audit robot -q log.csv --folds 100000 --json audit.json", d);
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("--folds 100000"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("log.csv has 120 measurements, enough for at most 30 folds"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "audit.json"));
}

}  // namespace
}  // namespace mcms
