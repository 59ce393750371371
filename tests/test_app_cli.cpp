// The mcms command line on rendered recordings: a clean run, and every kind of bad
// input the tracker must survive per frame or refuse with a clear error, a non-zero
// exit and no half-written output.
#include <gtest/gtest.h>

#include <unistd.h>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "core/io.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

using test::CliRun;

// Runs `mcms ARGS` in `scratch`.
CliRun Mcms(const std::string& args, const fs::path& scratch) {
  return test::Mcms(scratch, args);
}

// One small rendered recording shared by the tests of this process (copied before each
// is spoiled); ctest runs every test in its own process, possibly in parallel.
const fs::path& Recording() {
  static const fs::path dir = [] {
    const fs::path d = test::ScratchDir("cli_recording_" + std::to_string(::getpid())) / "rec";
    const CliRun r = Mcms("render --frames 6 --quiet -o " + d.string(), d.parent_path());
    EXPECT_EQ(r.code, 0) << r.err;
    return d;
  }();
  return dir;
}

fs::path Copy(const std::string& name) {
  const fs::path d = test::ScratchDir("cli_" + name) / "rec";
  fs::copy(Recording(), d, fs::copy_options::recursive);
  fs::remove(d / "poses.csv");
  return d;
}

TEST(Cli, HelpOnEveryCommand) {
  const fs::path s = test::ScratchDir("cli_help");
  for (const char* c : {"--help", "render --help", "track --help", "demo --help"}) {
    EXPECT_EQ(Mcms(c, s).code, 0) << c;
  }
  EXPECT_NE(Mcms("no-such-command", s).code, 0);
}

TEST(Cli, TracksARenderedRecording) {
  const fs::path d = Copy("clean");
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "poses.csv");
  ASSERT_EQ(t.rows.size(), 6u);
  EXPECT_TRUE(t.HasColumn("x_m"));
  EXPECT_TRUE(t.HasColumn("qw"));
  EXPECT_TRUE(t.HasColumn("cov_pz_pz"));
  EXPECT_EQ(t.header.size(), 17u + 36u);
  for (size_t i = 0; i < t.rows.size(); ++i) EXPECT_NE(t.rows[i][t.Column("status")], "lost");
}

// --predicted-windows: the same poses as the whole-image detection (to the digits written);
// with missing and corrupt images too (those cameras go back to the whole image).
TEST(Cli, PredictedWindowsGiveTheSamePoses) {
  const fs::path d = Copy("windows");
  fs::remove(d / "images" / "cam1" / "000002.png");
  std::ofstream(d / "images" / "cam2" / "000004.png", std::ios::trunc) << "this is not a PNG";
  const CliRun whole = Mcms("track --quiet --gain 0 " + d.string() + " -o " + (d / "whole.csv").string(), d);
  ASSERT_EQ(whole.code, 0) << whole.err;
  const CliRun win =
      Mcms("track --quiet --gain 0 --predicted-windows " + d.string() + " -o " + (d / "win.csv").string(), d);
  ASSERT_EQ(win.code, 0) << win.err;
  // Frames 0 (no track) and 1 (no velocity yet: windows around a still prediction, which
  // the moving target leaves) are detected whole; the cameras with an image missing or
  // corrupt have nothing to detect; the rest in windows.
  EXPECT_NE(win.out.find("predicted windows: "), std::string::npos) << win.out;
  const auto at = win.out.find("predicted windows: ");
  ASSERT_NE(at, std::string::npos);
  EXPECT_GE(std::stoi(win.out.substr(at + 19)), 10) << win.out.substr(at, 120);
  const CsvTable a = ReadCsv(d / "whole.csv"), b = ReadCsv(d / "win.csv");
  ASSERT_EQ(a.rows.size(), 6u);
  ASSERT_EQ(b.rows.size(), a.rows.size());
  for (const char* col : {"status", "reason", "x_m", "y_m", "z_m", "qw", "qx", "cov_pz_pz"})
    for (size_t i = 0; i < a.rows.size(); ++i) {
      const std::string &x = a.rows[i][a.Column(col)], &y = b.rows[i][b.Column(col)];
      if (x == y) continue;
      EXPECT_NEAR(std::stod(x), std::stod(y), 1e-9 * std::max(1.0, std::abs(std::stod(x)))) << col << " row " << i;
    }
}

TEST(Cli, MissingAndCorruptImagesDegradeTheirFrameOnly) {
  const fs::path d = Copy("missing");
  fs::remove(d / "images" / "cam1" / "000002.png");
  std::ofstream(d / "images" / "cam2" / "000004.png", std::ios::trunc) << "this is not a PNG";
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "poses.csv");
  ASSERT_EQ(t.rows.size(), 6u);
  const int st = t.Column("status"), re = t.Column("reason");
  EXPECT_EQ(t.rows[2][st], "degraded");
  EXPECT_NE(t.rows[2][re].find("cam1: image missing"), std::string::npos) << t.rows[2][re];
  EXPECT_EQ(t.rows[4][st], "degraded");
  EXPECT_NE(t.rows[4][re].find("cam2: cannot decode"), std::string::npos) << t.rows[4][re];
  EXPECT_FALSE(t.rows[4][t.Column("x_m")].empty()) << "three cameras still give a pose";
}

void ExpectRefused(const fs::path& d, const std::string& args, const std::string& needle) {
  const CliRun r = Mcms(args, d);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find(needle), std::string::npos) << "stderr: " << r.err;
  EXPECT_FALSE(fs::exists(d / "poses.csv")) << "no output may be written";
  for (const auto& e : fs::directory_iterator(d))
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << "left behind: " << e.path();
}

TEST(Cli, ImageSizeThatDisagreesWithTheRigIsRefused) {
  const fs::path d = Copy("size");
  cv::imwrite((d / "images" / "cam0" / "000000.png").string(), cv::Mat(480, 640, CV_8U, cv::Scalar(10)));
  ExpectRefused(d, "track --quiet " + d.string(), "is 640x480 but the rig says camera 'cam0' is 1280x1024");
}

TEST(Cli, EmptyOrMissingImageFolderIsRefused) {
  const fs::path d = Copy("empty");
  fs::remove_all(d / "images");
  fs::create_directories(d / "images");
  ExpectRefused(d, "track --quiet " + d.string(), "is empty");
  fs::remove_all(d / "images");
  ExpectRefused(d, "track --quiet " + d.string(), "does not exist");
}

TEST(Cli, CameraCountMismatchIsRefused) {
  const fs::path d = Copy("count");
  fs::create_directories(d / "images" / "cam4");
  ExpectRefused(d, "track --quiet " + d.string(), "camera count mismatch: the rig has 4 cameras");
  fs::remove_all(d / "images" / "cam4");
  fs::remove_all(d / "images" / "cam3");
  ExpectRefused(d, "track --quiet " + d.string(), "no sub-folder 'cam3'");
}

TEST(Cli, TargetNeverVisibleIsRefused) {
  const fs::path d = Copy("dark");
  for (const auto& cam : fs::directory_iterator(d / "images"))
    for (const auto& im : fs::directory_iterator(cam.path()))
      cv::imwrite(im.path().string(), cv::Mat(1024, 1280, CV_8U, cv::Scalar(12)));
  ExpectRefused(d, "track --quiet " + d.string(), "target never found in any of the 6 frames");
}

TEST(Cli, BadRigTargetAndTimesAreRefused) {
  const fs::path d = Copy("files");
  fs::remove(d / "rig.yaml");
  ExpectRefused(d, "track --quiet " + d.string(), "rig.yaml does not exist");
  const fs::path e = Copy("times");
  std::ofstream(e / "frames.csv", std::ios::trunc) << "frame,time_s\n0,0\n1,0.1\n2,0.1\n3,0.3\n4,0.4\n5,0.5\n";
  ExpectRefused(e, "track --quiet " + e.string(), "frames.csv line 4: time_s must increase");
  const fs::path g = Copy("target");
  std::ofstream(g / "target.yaml", std::ios::trunc) << "name: x\nballs_m: [[0,0,0]]\n";
  ExpectRefused(g, "track --quiet " + g.string(), "ball_radius_m");
}

// An output that cannot be written is refused before the work (seconds to minutes of
// tracking, rendering or simulation), with the option named, exit 2, and the file
// standing in the way untouched.
TEST(Cli, UnusableOutputIsRefusedBeforeTheWork) {
  const fs::path d = Copy("outputs");
  const fs::path file = d / "a_file";
  { std::ofstream(file) << "keep\n"; }
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"track --quiet " + d.string() + " -o " + d.string(), "track -o"},
      {"render -o " + file.string(), "render -o"},
      {"demo -o " + file.string(), "demo -o"},
      {"iso9283 --simulate -o " + d.string(), "iso9283 -o"},
      {"iso9283 --simulate --write-measurements " + file.string(), "iso9283 --write-measurements"},
  };
  for (const auto& [args, needle] : cases) {
    SCOPED_TRACE(args);
    const CliRun r = Mcms(args, d);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << "stderr: " << r.err;
    EXPECT_NE(r.err.find("nothing was written"), std::string::npos) << "stderr: " << r.err;
  }
  std::ifstream in(file);
  std::string text;
  std::getline(in, text);
  EXPECT_EQ(text, "keep");
}

// Issue 29: `mcms audit imu` said "A subcommand is required"; an unknown command or mode
// is named with the choices, exit 2.
TEST(BadInput, UnknownCommandOrModeIsNamedWithTheChoices) {
  const fs::path d = test::ScratchDir("cli_unknown_mode");
  const CliRun mode = Mcms("audit imu", d);
  EXPECT_EQ(mode.code, 2);
  EXPECT_NE(mode.err.find("unknown mode 'imu' of `mcms audit`"), std::string::npos) << mode.err;
  for (const char* m : {"cameras", "robot", "fusion", "lens"}) EXPECT_NE(mode.err.find(m), std::string::npos) << m;
  const CliRun command = Mcms("audti robot log.csv", d);
  EXPECT_EQ(command.code, 2);
  EXPECT_NE(command.err.find("unknown command 'audti' of `mcms`"), std::string::npos) << command.err;
  EXPECT_NE(command.err.find("audit"), std::string::npos) << command.err;
  // Known commands with a bad option are still CLI11's to report (and not "unknown mode").
  const CliRun option = Mcms("audit robot --no-such-option log.csv", d);
  EXPECT_NE(option.code, 0);
  EXPECT_EQ(option.err.find("unknown mode"), std::string::npos) << option.err;
}

}  // namespace
}  // namespace mcms
