// mcms fov-map on the command line: the interface scripts rely on (-o DIR alone maps the
// default rig and writes map.csv with the promised columns), the measured tables, and bad
// input refused with a clear error naming it, a non-zero exit and nothing written.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <unistd.h>

#include "core/io.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

using test::CliRun;

// Runs `mcms ARGS` in `scratch`.
CliRun Mcms(const std::string& args, const fs::path& scratch) { return test::Mcms(scratch, args); }


TEST(FovMapCli, DefaultRigMapWithPromisedColumns) {
  const fs::path s = test::ScratchDir("fovmap_default");
  const CliRun r = Mcms("fov-map -o " + (s / "map").string(), s);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(s / "map" / "map.csv");
  for (const char* c : {"x_m", "y_m", "z_m", "sigma_x_mm", "sigma_y_mm", "sigma_z_mm", "sigma_d_mm", "sigma_rx_mdeg",
                        "cameras", "trackable", "balls_cam0"})
    EXPECT_TRUE(t.HasColumn(c)) << c;
  EXPECT_EQ(t.rows.size(), 11u * 9u * 11u);  // the default working volume's grid
  // Every point of the default volume is tracked, to a few hundredths of a millimetre.
  const int cd = t.Column("sigma_d_mm"), ck = t.Column("trackable");
  for (size_t i = 0; i < t.rows.size(); ++i) {
    EXPECT_EQ(t.Number(i, ck), 1) << "row " << i;
    EXPECT_GT(t.Number(i, cd), 0.005);
    EXPECT_LT(t.Number(i, cd), 0.06);
  }
  for (const char* f : {"heatmap_z00.svg", "heatmap_z10.svg", "heatmap_x_centre.svg", "heatmap_y_centre.svg",
                        "sigma_vs_distance.svg", "region.txt"})
    EXPECT_TRUE(fs::exists(s / "map" / f)) << f;
  // The vertical slices: z against y at the middle x, z against x at the middle y.
  const std::string xs = test::ReadAll(s / "map" / "heatmap_x_centre.svg");
  EXPECT_NE(xs.find("plane x = 0.000 m"), std::string::npos);
  EXPECT_NE(xs.find("z (m, rig frame)"), std::string::npos);
  EXPECT_NE(test::ReadAll(s / "map" / "heatmap_y_centre.svg").find("plane y = 0.000 m"), std::string::npos);
  // No temporary folder left beside the output.
  for (const auto& e : fs::directory_iterator(s)) EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos);
  // A rerun replaces the earlier map.
  EXPECT_EQ(Mcms("fov-map --grid=0:0:1,0:0:1,0.5:0.5:1 -o " + (s / "map").string(), s).code, 0);
  EXPECT_EQ(ReadCsv(s / "map" / "map.csv").rows.size(), 1u);
}

TEST(FovMapCli, PaperTablesAndJson) {
  MCMS_REQUIRE_DATA(paper, "paper");
  const fs::path s = test::ScratchDir("fovmap_paper");
  const CliRun r = Mcms("fov-map --quiet --grid=-0.5:0.5:3,-0.4:0.4:3,0:1:3 --measured " +
                            (paper / "table1_point_repeatability.csv").string() + " --lines " +
                            (paper / "table2_line_lengths.csv").string() + " --json " + (s / "fit.json").string() + " -o " +
                            (s / "out").string(),
                        s);
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream in(s / "fit.json");
  std::stringstream j;
  j << in.rdbuf();
  for (const char* key : {"\"effects\"", "\"name\"", "\"parameters\"", "\"sigma\"", "\"heldout_loglik_gain\"",
                          "\"table2_prediction\"", "\"misidentification\"", "\"layout_sensitivity\""})
    EXPECT_NE(j.str().find(key), std::string::npos) << key;
  for (const char* f : {"measured.csv", "measured_fit.txt", "measured_sigma.svg", "lines.csv", "map.csv"})
    EXPECT_TRUE(fs::exists(s / "out" / f)) << f;
}

// Each bad input: exit non-zero, one error line naming the input, no output folder, no JSON.
TEST(FovMapCli, BadInputRefusedNothingWritten) {
  const fs::path s = test::ScratchDir("fovmap_bad");
  const std::string t1_header = "plane,point,sigma_x_mm,sigma_y_mm,sigma_z_mm,sigma_d_mm\n";
  test::WriteText(s / "one_point_plane.csv", t1_header + "1,1,0.1,1.0,0.3,1.049\n1,2,0.1,1.0,0.3,1.049\n2,3,0.1,1.0,0.3,1.049\n");
  test::WriteText(s / "nan.csv", t1_header + "1,1,0.1,nan,0.3,1.049\n1,2,0.1,1.0,0.3,1.049\n1,3,0.1,1.0,0.3,1.049\n");
  test::WriteText(s / "bad_d.csv", t1_header + "1,1,0.1,1.0,0.3,2.0\n1,2,0.1,1.0,0.3,1.049\n1,3,0.1,1.0,0.3,1.049\n");
  std::string raw = "point,repeat,x_m,y_m,z_m\n";
  for (int p = 1; p <= 3; ++p)
    for (int k = 1; k <= 4; ++k)
      raw += std::to_string(p) + "," + std::to_string(k) + "," + std::to_string(0.1 * p + 1e-4 * k) + "," +
             std::to_string(0.02 * k * k * 1e-3) + "," + std::to_string(0.5 + 3e-5 * k) + "\n";
  test::WriteText(s / "raw.csv", raw);
  test::WriteText(s / "raw_one_repeat.csv", raw + "4,1,0.4,0.0,0.5\n");
  test::WriteText(s / "reference_mismatch.csv", "point,x_m,y_m,z_m\n1,0.1,0,0.5\n2,0.2,0,0.5\n9,0.3,0,0.5\n");
  test::WriteText(s / "lines_bad.csv", "plane,line,d_laser_mm,d_camera_mm,delta_mm\n1,1,400.2,400.0,5.0\n");

  struct Case {
    std::string args, must_name;
  };
  const std::vector<Case> cases{
      {"--measured " + (s / "one_point_plane.csv").string(), "plane 2 has one point"},
      {"--measured " + (s / "nan.csv").string(), "nan.csv line 2, column 'sigma_y_mm'"},
      {"--measured " + (s / "bad_d.csv").string(), "bad_d.csv line 2, column 'sigma_d_mm'"},
      {"--measured " + (s / "raw_one_repeat.csv").string(), "point 4 has 1 repeat"},
      {"--measured " + (s / "raw.csv").string() + " --reference " + (s / "reference_mismatch.csv").string(),
       "reference_mismatch.csv: no reference for point 3"},
      {"--measured " + (s / "raw.csv").string() + " --lines " + (s / "lines_bad.csv").string(), "lines_bad.csv line 2"},
      {"--measured " + (s / "nan.csv").string() + " --measured-repeats 1", "--measured-repeats"},
      {"--measured " + (s / "raw.csv").string() + " --grid=0:1:3,0:1", "--grid"},
      {"--measured " + (s / "raw.csv").string() + " --grid=0:1:3,0:1:2,1:0:3", "--grid"},
      {"--measured " + (s / "raw.csv").string() + " --grid=0:1:3,0:1:2,0:nan:3", "--grid"},
  };
  for (const auto& c : cases) {
    const fs::path out = s / "out", json = s / "fit.json";
    const CliRun r = Mcms("fov-map --quiet " + c.args + " --json " + json.string() + " -o " + out.string(), s);
    EXPECT_NE(r.code, 0) << c.args;
    EXPECT_NE(r.err.find(c.must_name), std::string::npos) << c.args << "\nstderr: " << r.err;
    EXPECT_FALSE(fs::exists(out)) << c.args;
    EXPECT_FALSE(fs::exists(json)) << c.args;
    for (const auto& e : fs::directory_iterator(s))
      EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << c.args;
  }
  // The raw CSV itself is accepted (the reference then matches the points).
  test::WriteText(s / "reference.csv", "point,x_m,y_m,z_m\n1,0.1,0,0.5\n2,0.2,0,0.5\n3,0.3,0,0.5\n");
  const CliRun ok = Mcms("fov-map --quiet --grid=0:0:1,0:0:1,0.5:0.5:1 --measured " + (s / "raw.csv").string() +
                             " --reference " + (s / "reference.csv").string() + " -o " + (s / "good").string(),
                         s);
  EXPECT_EQ(ok.code, 0) << ok.err;
  // A poses.csv of mcms track with a point column: the frame is the repeat, lost frames skipped.
  std::string poses = "frame,time_s,status,reason,x_m,y_m,z_m,point\n";
  int frame = 0;
  for (int p = 1; p <= 3; ++p)
    for (int k = 1; k <= 4; ++k, ++frame)
      poses += std::to_string(frame) + ",0," + (k == 2 ? "lost,no target,,,," : "ok,,") +
               (k == 2 ? "" : std::to_string(0.1 * p + 1e-4 * k) + "," + std::to_string(2e-5 * k * k) + "," +
                                  std::to_string(0.5 + 3e-5 * k) + ",") +
               std::to_string(p) + "\n";
  test::WriteText(s / "poses.csv", poses);
  const CliRun pr = Mcms("fov-map --quiet --grid=0:0:1,0:0:1,0.5:0.5:1 --measured " + (s / "poses.csv").string() + " -o " +
                             (s / "from_poses").string(),
                         s);
  EXPECT_EQ(pr.code, 0) << pr.err;
  const CsvTable m = ReadCsv(s / "from_poses" / "measured.csv");
  ASSERT_EQ(m.rows.size(), 3u);
  EXPECT_EQ(m.Number(0, m.Column("repeats")), 3);
}

}  // namespace
}  // namespace mcms
