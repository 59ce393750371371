// Never lose a user's data (issue 28): every command that writes refuses an output that
// names one of its inputs, whether given directly, through a symlink, or by another
// spelling of the path (./sub/../x, an absolute path); and an output folder that holds an
// input it would replace. Each refusal: exit 2, one message naming the output and the
// input, the input byte-identical afterwards and nothing written.
#include <gtest/gtest.h>

#include <unistd.h>
#include <algorithm>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "core/output_folder.h"
#include "tests/cli_runner.h"
#include "tests/fuse_logs.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;
using test::CliRun;

using test::Snapshot;

const fs::path& Recording() {
  static const fs::path dir = [] {
    const fs::path d = test::ScratchDir("output_guard_recording_" + std::to_string(::getpid())) / "rec";
    const CliRun r = test::Mcms(d.parent_path(), "render --frames 4 --quiet --threads 2 -o rec");
    EXPECT_EQ(r.code, 0) << r.err;
    return d;
  }();
  return dir;
}

std::string RobotLogCsv() {
  std::string s = "time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad,x_m,y_m,z_m\n";
  for (int k = 0; k < 30; ++k)
    s += std::to_string(60 * k) + ",0.1,-0.5," + std::to_string(0.8 + 0.01 * k) + ",0.2,0.6,0.1,1.2," +
         std::to_string(0.01 * k) + ",0.9\n";
  return s;
}

const char* kCameramodel =
    "{'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [534, 531, 322, 245, -0.28, 0.09, 0.001, -0.0005], "
    "'imagersize': [640, 480], 'rt_cam_ref': [0, 0, 0, 0, 0, 0]}\n";

struct Case {
  std::string name;
  std::function<void(const fs::path&)> setup;  // writes the inputs into the case's folder
  std::string command;                         // mcms arguments; {OUT} is the output under test
  std::string collide;                         // the input file (or, for a folder output, the folder holding it)
  std::string input_named;                     // how the message names the input
  bool folder = false;                         // the output is a folder
  std::string control;                         // when set: the same command with a free output succeeds
};

std::string Replace(std::string s, const std::string& out) {
  const size_t at = s.find("{OUT}");
  return s.replace(at, 5, out);
}

void Fuse(const fs::path& d) {
  test::Write(d, test::CleanLogs());
}
void FuseIn(const fs::path& d, const std::string& sub) {
  fs::create_directories(d / sub);
  test::Write(d / sub, test::CleanLogs());
}
void CopyRecording(const fs::path& d) {
  fs::copy(Recording(), d / "rec", fs::copy_options::recursive);
}

const std::string kFuse =
    "fuse --quiet --tracker poses.csv --robot joints.csv --inclinometer incl.csv --setup setup.yaml -o ";
const std::string kAuditFusion =
    "audit fusion -q --tracker logs/poses.csv --robot logs/joints.csv --setup logs/setup.yaml ";

std::vector<Case> Cases() {
  std::vector<Case> c;
  c.push_back({"fuse_tracker", Fuse, kFuse + "{OUT}", "poses.csv", "poses.csv", false, kFuse + "fused.csv"});
  c.push_back({"fuse_robot", Fuse, kFuse + "{OUT}", "joints.csv", "joints.csv"});
  c.push_back({"fuse_inclinometer", Fuse, kFuse + "{OUT}", "incl.csv", "incl.csv"});
  c.push_back({"fuse_setup", Fuse, kFuse + "{OUT}", "setup.yaml", "setup.yaml"});
  c.push_back({"audit_fusion_json", [](const fs::path& d) { FuseIn(d, "logs"); }, kAuditFusion + "--json {OUT}",
               "logs/joints.csv", "logs/joints.csv"});
  c.push_back({"audit_fusion_folder", [](const fs::path& d) { FuseIn(d, "logs"); }, kAuditFusion + "-o {OUT}", "logs",
               "logs/poses.csv", true});
  const auto robot_log = [](const fs::path& d) {
    fs::create_directories(d / "logs");
    test::WriteText(d / "logs" / "log.csv", RobotLogCsv());
  };
  c.push_back(
      {"audit_robot_json", robot_log, "audit robot -q logs/log.csv --json {OUT}", "logs/log.csv", "logs/log.csv"});
  c.push_back({"audit_robot_folder", robot_log, "audit robot -q logs/log.csv -o {OUT}", "logs", "logs/log.csv", true});
  c.push_back(
      {"audit_cameras_json", CopyRecording, "audit cameras rec -q --json {OUT}", "rec/frames.csv", "frames.csv"});
  c.push_back({"audit_cameras_repaired_rig", CopyRecording, "audit cameras rec -q --repaired-rig {OUT}", "rec/rig.yaml",
               "rig.yaml"});
  c.push_back({"audit_cameras_repaired_target", CopyRecording, "audit cameras rec -q --repaired-target {OUT}",
               "rec/target.yaml", "target.yaml"});
  c.push_back({"audit_cameras_folder", CopyRecording, "audit cameras rec -q -o {OUT}", "rec", "rig.yaml", true});
  const auto lens = [](const fs::path& d) {
    fs::create_directories(d / "models");
    test::WriteText(d / "models" / "cam.cameramodel", kCameramodel);
  };
  c.push_back({"audit_lens_json", lens, "audit lens -q models/cam.cameramodel --json {OUT}", "models/cam.cameramodel",
               "models/cam.cameramodel"});
  c.push_back({"audit_lens_folder", lens, "audit lens -q models/cam.cameramodel -o {OUT}", "models",
               "models/cam.cameramodel", true});
  c.push_back({"track_frames", CopyRecording, "track rec --quiet -o {OUT}", "rec/frames.csv", "frames.csv", false,
               "track rec --quiet -o poses.csv"});
  c.push_back({"track_rig", CopyRecording, "track rec --quiet -o {OUT}", "rec/rig.yaml", "rig.yaml"});
  c.push_back({"track_truth", CopyRecording, "track rec --quiet --truth rec/truth/poses.csv -o {OUT}",
               "rec/truth/poses.csv", "truth/poses.csv"});
  // calib-rig writes <camera>.cameramodel, <camera>.yml, residuals-<camera>.svg and
  // rig.yaml into its folder: a board file of one of those names there is refused.
  const auto rig = [](const fs::path& d) {
    fs::create_directories(d / "cal");
    fs::create_directories(d / "left");
    test::WriteText(d / "cal" / "rig.yaml",
                    "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.025\n"
                    "colSpacingMeters: 0.025\n");
    test::WriteText(d / "left" / "000.png", "not decoded: refused before the images are read");
  };
  c.push_back({"calib_rig_rig_yaml", rig, "calib-rig cal/rig.yaml left -o {OUT}", "cal", "cal/rig.yaml", true});
  const auto rig_named = [](const fs::path& d) {
    fs::create_directories(d / "out" / "left");
    test::WriteText(d / "out" / "left.yml",
                    "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n"
                    "rowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n");
    test::WriteText(d / "out" / "left" / "000.png", "not decoded");
  };
  c.push_back(
      {"calib_rig_camera_yml", rig_named, "calib-rig out/left.yml out/left -o {OUT}", "out", "out/left.yml", true});
  const auto calib_robot = [](const fs::path& d) {
    test::WriteText(d / "meas.yaml",
                    "measurements:\n  - {q_rad: [0.1, -0.5, 0.8, 0.2, 0.6, 0.1], position_m: [1.2, 0, 0.9]}\n");
    test::WriteText(d / "robot.yaml", "name: from --print? no: refused before it is read\n");
  };
  c.push_back({"calib_robot_output", calib_robot, "calib-robot meas.yaml --robot robot.yaml --quiet -o {OUT}",
               "robot.yaml", "robot.yaml"});
  c.push_back({"calib_robot_report", calib_robot,
               "calib-robot meas.yaml --robot robot.yaml --quiet -o new.yaml --report {OUT}", "meas.yaml",
               "meas.yaml"});
  c.push_back({"calib_robot_plot", calib_robot,
               "calib-robot meas.yaml --robot robot.yaml --quiet -o new.yaml --plot {OUT}", "meas.yaml", "meas.yaml"});
  const auto measured = [](const fs::path& d) {
    fs::create_directories(d / "m");
    std::string s = "point,repeat,x_m,y_m,z_m\n";
    for (int p = 0; p < 3; ++p)
      for (int r = 0; r < 5; ++r)
        s += std::to_string(p) + "," + std::to_string(r) + "," + std::to_string(0.1 * p) + "," +
             std::to_string(1e-5 * r) + ",0.5\n";
    test::WriteText(d / "m" / "raw.csv", s);
  };
  c.push_back({"fov_map_json", measured,
               "fov-map --quiet --grid=0:0:1,0:0:1,0.5:0.5:1 --measured m/raw.csv -o out --json {OUT}", "m/raw.csv",
               "m/raw.csv"});
  c.push_back({"fov_map_folder", measured, "fov-map --quiet --grid=0:0:1,0:0:1,0.5:0.5:1 --measured m/raw.csv -o {OUT}",
               "m", "m/raw.csv", true});
  const auto iso = [](const fs::path& d) {
    test::WriteText(d / "poses.csv",
                    "pose,cycle,cmd_x_m,cmd_y_m,cmd_z_m,cmd_qw,cmd_qx,cmd_qy,cmd_qz,x_m,y_m,z_m,qw,qx,qy,qz\n"
                    "P1,1,0.5,0.1,0.8,1,0,0,0,0.5001,0.1,0.8,1,0,0,0\nP1,2,0.5,0.1,0.8,1,0,0,0,0.5002,0.1,0.8,1,0,0,0\n"
                    "P1,3,0.5,0.1,0.8,1,0,0,0,0.5001,0.1,0.8,1,0,0,0\n");
  };
  c.push_back({"iso9283_output", iso, "iso9283 poses.csv -o {OUT}", "poses.csv", "poses.csv", false,
               "iso9283 poses.csv -o iso.csv"});
  const auto scenario = [](const fs::path& d) {
    fs::create_directories(d / "sc");
    const CliRun r = test::Mcms(d, "render --print-default > sc/scenario.yaml; true");
    ASSERT_EQ(r.code, 0);
  };
  c.push_back({"render_folder_holds_scenario", scenario, "render sc/scenario.yaml --frames 1 --quiet -o {OUT}", "sc",
               "sc/scenario.yaml", true, "render sc/scenario.yaml --frames 1 --quiet -o rendered"});
  c.push_back({"render_folder_is_scenario", scenario, "render sc/scenario.yaml --frames 1 --quiet -o {OUT}",
               "sc/scenario.yaml", "sc/scenario.yaml"});
  const auto camera_model = [](const fs::path& d) {
    fs::create_directories(d / "cm");
    test::WriteText(d / "cm" / "fit.json",
                    R"({"effects": [{"name": "pixel_noise_scale", "parameters": {"scale": 2.0}}]})");
  };
  c.push_back({"demo_folder_holds_camera_model", camera_model,
               "demo --points 2 --no-iso9283 -q --threads 2 --camera-model cm/fit.json -o {OUT}", "cm", "cm/fit.json",
               true});
  const auto map = [](const fs::path& d) {
    ASSERT_EQ(test::Mcms(d, "fov-map --quiet --grid=0:0:1,0:0:1,0.5:0.5:1 -o map").code, 0);
  };
  c.push_back({"report_output_in_folder", map, "report map -o {OUT}", "map/map.csv", "map.csv", false,
               "report map -o page.html"});
  return c;
}

// The spellings of `collide` (relative to the case folder `d`): itself, through a sub-folder
// and back, through a symlink, absolute.
std::vector<std::string> Spellings(const fs::path& d, const std::string& collide, bool folder) {
  fs::create_directories(d / "sub");
  const std::string alias = "alias_" + fs::path(collide).filename().string();
  fs::create_symlink(fs::absolute(d / collide), d / alias);
  return {collide, "./sub/../" + collide + (folder ? "/" : ""), alias, (d / collide).string()};
}

class OutputGuard : public ::testing::TestWithParam<Case> {};

TEST_P(OutputGuard, AnOutputThatIsAnInputIsRefused) {
  const Case& c = GetParam();
  const fs::path d = test::ScratchDir("output_guard_" + c.name);
  c.setup(d);
  if (!c.control.empty()) {
    // Not a refusal of the inputs themselves: with a free output the command runs.
    const CliRun ok = test::Mcms(d, c.control);
    ASSERT_EQ(ok.code, 0) << c.control << "\n" << ok.err;
  }
  const std::vector<std::string> spellings = Spellings(d, c.collide, c.folder);
  const auto before = Snapshot(d);
  for (const std::string& out : spellings) {
    SCOPED_TRACE(out);
    const std::string args = Replace(c.command, out);
    const CliRun r = test::Mcms(d, args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(out), std::string::npos) << "the message names the output: " << r.err;
    EXPECT_NE(r.err.find(c.input_named), std::string::npos) << "the message names the input: " << r.err;
    EXPECT_NE(r.err.find("the input"), std::string::npos) << "the message says why: " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "one line: " << r.err;
    EXPECT_EQ(Snapshot(d), before) << "an input changed or an output was written";
  }
}

INSTANTIATE_TEST_SUITE_P(EveryWritingCommand, OutputGuard, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<Case>& i) { return i.param.name; });

// What a command may replace (issue 53): track's default DIR/poses.csv only when an earlier
// track wrote it, calib-rig's -o folder only when it holds an earlier calib-rig output. The
// user's own poses.csv, rig.yaml and notes are refused before any work and kept.
TEST(OutputGuardCheck, TheUsersOwnFilesAreNeverReplaced) {
  const fs::path d = test::ScratchDir("output_guard_own_files");
  CopyRecording(d);
  test::WriteText(d / "rec" / "poses.csv", "frame,my,own,hand,tracked,poses\n");
  auto before = Snapshot(d);
  CliRun r = test::Mcms(d, "track rec --quiet");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("track rec/poses.csv exists and is not poses an earlier mcms track wrote; it was not replaced"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(Snapshot(d), before);
  // Without it the default is written, and an earlier track's poses are replaced.
  fs::remove(d / "rec" / "poses.csv");
  for (int run = 0; run < 2; ++run) {
    r = test::Mcms(d, "track rec --quiet");
    EXPECT_EQ(r.code, 0) << r.err;
  }
  // calib-rig into a folder with the user's own rig.yaml and notes: refused before the
  // images are read (these are not images).
  fs::create_directories(d / "cal");
  fs::create_directories(d / "left");
  test::WriteText(d / "cal" / "board.yaml",
                  "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.025\n"
                  "colSpacingMeters: 0.025\n");
  test::WriteText(d / "left" / "000.png", "not decoded: refused before the images are read");
  fs::create_directories(d / "mine");
  test::WriteText(d / "mine" / "rig.yaml", "my hand-made rig\n");
  test::WriteText(d / "mine" / "summary.txt", "my notes\n");
  before = Snapshot(d);
  r = test::Mcms(d, "calib-rig cal/board.yaml left -o mine -q");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("calib-rig -o: folder mine exists and does not hold an earlier calib-rig"), std::string::npos)
      << r.err;
  EXPECT_EQ(Snapshot(d), before);
}

// The check itself on what the commands cannot easily be made to meet: an output folder
// inside an input folder that exists (replacing it would change what the run reads), an
// output file inside an input folder (a new file there is allowed, an existing one not),
// and inputs that do not exist (the reader names them).
TEST(OutputGuardCheck, FoldersAndMissingInputs) {
  const fs::path d = test::ScratchDir("output_guard_check");
  fs::create_directories(d / "images" / "cam0");
  test::WriteText(d / "images" / "cam0" / "000.png", "x");
  const auto refused = [&](const std::vector<RunOutput>& o, const std::vector<fs::path>& in) {
    return test::ErrorOf([&] { RequireOutputsSpareInputs(o, in); });
  };
  EXPECT_NE(refused({{d / "images" / "cam0", "x -o", true}}, {d / "images"}).find("lies inside the input folder"),
            std::string::npos);
  // New or not: an output inside a folder the run reads whole would join what the next run
  // reads (a poses.csv among the images is taken for a camera's folder).
  EXPECT_NE(refused({{d / "images" / "new", "x -o", true}}, {d / "images"}).find("lies inside the input folder"),
            std::string::npos);
  EXPECT_NE(refused({{d / "images" / "cam0" / "000.png", "x -o"}}, {d / "images"}).find("inside the input folder"),
            std::string::npos);
  EXPECT_NE(refused({{d / "images" / "cam0" / "001.png", "x -o"}}, {d / "images"}).find("inside the input folder"),
            std::string::npos);
  EXPECT_EQ(refused({{d / "poses.csv", "x -o"}}, {d / "images"}), "(no InputError)");
  EXPECT_EQ(refused({{d / "a.csv", "x -o"}}, {d / "missing.csv", fs::path()}), "(no InputError)");
  EXPECT_EQ(refused({{fs::path(), "x -o"}}, {d / "images"}), "(no InputError)");
  // A file of the same content elsewhere is another file.
  test::WriteText(d / "copy.png", "x");
  EXPECT_EQ(refused({{d / "copy.png", "x -o"}}, {d / "images" / "cam0" / "000.png"}), "(no InputError)");
  // A hard link is the same file.
  fs::create_hard_link(d / "images" / "cam0" / "000.png", d / "hard.png");
  EXPECT_NE(refused({{d / "hard.png", "x -o"}}, {d / "images" / "cam0" / "000.png"}).find("is the input"),
            std::string::npos);
}

}  // namespace
}  // namespace mcms
