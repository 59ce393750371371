// Hostile inputs of issue 29 (audit lens, fov-map --measured/--lines, demo --camera-model,
// demo -o, audit cameras on damaged frames): each refused with one line naming the input
// and what was expected, exit 2, and nothing written or left behind.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "audit/repeatability.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"
#include "vision/camera_model.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;
using test::CliRun;

using test::Snapshot;

bool Has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// One line: "mcms: error: ...\n".
void ExpectOneErrorLine(const CliRun& r) {
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_EQ(r.err.rfind("mcms: error: ", 0), 0u) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// Runs `args` in `dir` and checks the refusal: exit 2, one error line holding every one of
// `parts`, the folder unchanged (nothing written, nothing left behind).
CliRun ExpectRefused(const fs::path& dir, const std::string& args, const std::vector<std::string>& parts) {
  const auto before = Snapshot(dir);
  const CliRun r = test::Mcms(dir, args);
  ExpectOneErrorLine(r);
  for (const auto& p : parts) EXPECT_TRUE(Has(r.err, p)) << args << "\nmissing: " << p << "\nstderr: " << r.err;
  EXPECT_EQ(Snapshot(dir), before) << args;
  return r;
}

const std::string kIntrinsicsTail = "531, 322, 245, -0.28, 0.09, 0.001, -0.0005]";
std::string Cameramodel(const std::string& lens, const std::string& fx) {
  return "# a camera\n{\n    'lensmodel': '" + lens + "',\n    'intrinsics': [" + fx + ", " + kIntrinsicsTail +
         ",\n    'extrinsics': [0, 0, 0, 0, 0, 0],\n    'imagersize': [640, 480],\n    'optimization_inputs': "
         "b'abc'\n}\n";
}

// 1. A non-finite intrinsic or an unknown lens model is named (file and field), not audited.
TEST(AttackLensFov, AuditLensRefusesNonFiniteIntrinsicsAndUnknownLensModel) {
  const fs::path d = test::ScratchDir("attack_lens_fields");
  test::WriteText(d / "nan.cameramodel", Cameramodel("LENSMODEL_OPENCV4", "nan"));
  test::WriteText(
      d / "inf.cameramodel",
      Cameramodel("LENSMODEL_OPENCV4", "534").replace(Cameramodel("LENSMODEL_OPENCV4", "534").find("0.09"), 4, "inf"));
  test::WriteText(d / "lens.cameramodel", Cameramodel("LENSMODEL_NOSUCH", "534"));
  ExpectRefused(d, "audit lens nan.cameramodel -q -o out --json out.json",
                {"nan.cameramodel", "'intrinsics'", "fx", "'nan'", "expected a finite number"});
  ExpectRefused(d, "audit lens inf.cameramodel -q -o out",
                {"inf.cameramodel", "intrinsics[5]", "expected a finite number"});
  ExpectRefused(d, "audit lens lens.cameramodel -q -o out --json out.json",
                {"lens.cameramodel", "'lensmodel'", "LENSMODEL_NOSUCH", "expected an mrcal lens model name"});
}

// 2. Random bytes or an empty file: not a .cameramodel (not "no optimization_inputs").
TEST(AttackLensFov, AuditLensNamesAFileThatIsNoCameramodel) {
  const fs::path d = test::ScratchDir("attack_lens_format");
  std::string bytes;
  for (int i = 0; i < 4096; ++i) bytes += static_cast<char>((i * 7919 + 13) % 251);
  test::WriteText(d / "random.cameramodel", bytes);
  test::WriteText(d / "empty.cameramodel", "");
  for (const char* f : {"random.cameramodel", "empty.cameramodel"}) {
    const CliRun r = ExpectRefused(d, std::string("audit lens ") + f + " -q -o out --json out.json",
                                   {f, "is not a .cameramodel", "expected mrcal's Python-literal format"});
    EXPECT_FALSE(Has(r.err, "optimization_inputs'")) << r.err;
  }
}

// 3. A UTF-8 byte order mark is skipped by the one .cameramodel reader (and the lens audit's
// format check): the model reads as without it.
TEST(AttackLensFov, CameramodelWithUtf8BomIsRead) {
  const fs::path d = test::ScratchDir("attack_lens_bom");
  const std::string text =
      "{'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [534, 531, 322, 245, -0.28, 0.09, 0.001, -0.0005], "
      "'extrinsics': [0.01, 0, 0, 0.1, 0, 0], 'imagersize': [640, 480]}\n";
  test::WriteText(d / "plain.cameramodel", text);
  test::WriteText(d / "bom.cameramodel", "\xEF\xBB\xBF" + text);
  const CameraModel plain = CameraModel::Read(d / "plain.cameramodel");
  const CameraModel bom = CameraModel::Read(d / "bom.cameramodel");
  EXPECT_EQ(bom.LensModelName(), plain.LensModelName());
  EXPECT_EQ(bom.Intrinsics(), plain.Intrinsics());
  EXPECT_EQ(CameraModel::ReadCameramodel(d / "bom.cameramodel").Intrinsics(), plain.Intrinsics());
  // The audit gets past the format: what it misses is the calibration problem.
  const CliRun r = ExpectRefused(d, "audit lens bom.cameramodel -q -o out", {"bom.cameramodel", "optimization_inputs"});
  EXPECT_FALSE(Has(r.err, "is not a .cameramodel")) << r.err;
}

// Raw repeats of a 3 x 3 grid (0.5 x 0.4 m) in the default rig's working volume: point,repeat,x_m,y_m,z_m.
std::string RawRows(int repeats = 5) {
  std::string s;
  int id = 0;
  for (int j = -1; j <= 1; ++j)
    for (int i = -1; i <= 1; ++i) {
      ++id;
      for (int k = 1; k <= repeats; ++k) {
        char b[160];
        std::snprintf(b, sizeof b, "%d,%d,%.6f,%.6f,%.6f\n", id, k, 0.5 * i + 1e-4 * ((k * 3 + id) % 5),
                      0.4 * j + 1e-4 * ((k * 7 + id) % 4), 0.5 + 1e-4 * ((k + 2 * id) % 3));
        s += b;
      }
    }
  return s;
}

const std::string kTable1Header = "plane,point,sigma_x_mm,sigma_y_mm,sigma_z_mm,sigma_d_mm\n";
const std::string kTable1 =
    kTable1Header +
    "1,1,0.046,0.929,0.303,0.979\n1,2,0.119,0.872,0.246,0.914\n1,3,0.128,1.058,0.242,1.093\n"
    "5,35,0.062,0.950,0.255,0.985\n5,36,0.075,1.057,0.256,1.090\n5,37,0.095,0.920,0.286,0.968\n";

// 4. The point and repeat headers swapped: the columns' values are not what the headers say.
TEST(AttackLensFov, FovMapRefusesSwappedPointAndRepeatColumns) {
  const fs::path d = test::ScratchDir("attack_fov_swapped");
  test::WriteText(d / "swapped.csv", "repeat,point,x_m,y_m,z_m\n" + RawRows());
  const CliRun r = ExpectRefused(d, "fov-map --quiet --measured swapped.csv --json fit.json -o out",
                                 {"swapped.csv", "columns 'point' and 'repeat'", "swapped",
                                  "expected each point's rows to be repeated measurements of one position"});
  EXPECT_FALSE(Has(r.err, "noise_floor")) << r.err;
  // The same rows under the right headers are read.
  test::WriteText(d / "right.csv", "point,repeat,x_m,y_m,z_m\n" + RawRows());
  EXPECT_EQ(ReadMeasuredPoints(d / "right.csv").points.size(), 9u);
}

// 5. --lines on a plane the measurements lack, or joining a point that was not measured.
TEST(AttackLensFov, FovMapRefusesLinesTheMeasurementsLack) {
  const fs::path d = test::ScratchDir("attack_fov_lines");
  test::WriteText(d / "table1.csv", kTable1);
  test::WriteText(d / "plane3.csv",
                  "plane,line,d_laser_mm,d_camera_mm,delta_mm\n1,1,400.202,400.249,-0.047\n"
                  "3,7,500.325,500.498,-0.173\n");
  test::WriteText(d / "ends.csv",
                  "plane,line,d_laser_mm,d_camera_mm,from,to\n1,1,400.202,400.249,1,2\n"
                  "1,2,400.482,400.179,2,99\n");
  ExpectRefused(
      d, "fov-map --quiet --measured table1.csv --lines plane3.csv --json fit.json -o out",
      {"plane3.csv", "line 7", "plane 3", "table1.csv", "planes 1, 5", "expected lines of the measured planes"});
  ExpectRefused(d, "fov-map --quiet --measured table1.csv --lines ends.csv --json fit.json -o out",
                {"ends.csv", "line 2", "point 99", "table1.csv", "1, 2, 3, 35, 36, 37"});
}

// 6. A point 100 m away or at 1e308, a sigma of 1e308: named by file, line, column, value.
TEST(AttackLensFov, FovMapRefusesImplausiblePositionsAndSigmas) {
  const fs::path d = test::ScratchDir("attack_fov_values");
  const std::string header = "point,repeat,x_m,y_m,z_m\n";
  test::WriteText(d / "far.csv", header + RawRows() + "10,1,100,0,1.5\n10,2,100.001,0,1.5\n");
  test::WriteText(d / "huge.csv", header + RawRows() + "10,1,0,1e308,1.5\n10,2,0,1e308,1.5\n");
  test::WriteText(d / "sigma.csv",
                  "plane,point,sigma_x_mm,sigma_y_mm,sigma_z_mm\n1,1,0.046,1e308,0.303\n1,2,0.119,0.872,0.246\n1,3,0."
                  "128,1.058,0.242\n");
  ExpectRefused(d, "fov-map --quiet --measured far.csv --json fit.json -o out",
                {"far.csv line 47, column 'x_m': 100 m", "outside the rig's field of view", "within +-10 m"});
  // Within 10 m but where no camera of the (default) rig looks.
  test::WriteText(d / "side.csv", header + RawRows() + "10,1,6,0,0.5\n10,2,6.001,0.001,0.501\n");
  ExpectRefused(d, "fov-map --quiet --measured side.csv --json fit.json -o out",
                {"side.csv: point 10 at (6.0005, 0.0005, 0.5005) m", "outside the rig's field of view", "needs 2"});
  ExpectRefused(d, "fov-map --quiet --measured huge.csv -o out", {"huge.csv line 47, column 'y_m'", "1e+308 m"});
  ExpectRefused(d, "fov-map --quiet --measured sigma.csv --json fit.json -o out",
                {"sigma.csv line 2, column 'sigma_y_mm'", "1e+308 mm", "expected 0 to 1000 mm"});
}

// 7. demo --camera-model: another command's JSON, and implausible values, refused at reading
// (before the simulation; nothing written).
TEST(AttackLensFov, DemoRefusesForeignJsonAndImplausibleCameraModels) {
  const fs::path d = test::ScratchDir("attack_demo_model");
  test::WriteText(d / "audit_robot.json",
                  "{\"mode\": \"robot\", \"nominal\": {\"chi2_per_dof\": 1.1, \"n\": 30}, \"clean\": true, "
                  "\"rms_unit\": \"mm\", \"tests\": [], \"effects\": [], \"undecided\": false, \"notes\": []}\n");
  test::WriteText(d / "floor.json", "{\"effects\": [{\"name\": \"noise_floor\", \"parameters\": {\"floor_m\": 5}}]}");
  test::WriteText(d / "scale.json",
                  "{\"effects\": [{\"name\": \"pixel_noise_scale\", \"parameters\": {\"scale\": 1e308}}]}");
  const std::string demo = "demo --points 2 --no-iso9283 -q --threads 1 -o out --camera-model ";
  ExpectRefused(d, demo + "audit_robot.json",
                {"--camera-model audit_robot.json", "\"mode\"", "`mcms audit robot`", "expected the keys", "effects"});
  ExpectRefused(d, demo + "floor.json",
                {"--camera-model floor.json", "parameters.floor_m = 5 m", "expected 0 to 0.1 m"});
  ExpectRefused(d, demo + "scale.json",
                {"--camera-model scale.json", "parameters.scale = 1e+308", "expected 0 to 100"});
}

// 8. An output folder that cannot be created is an input error naming the option and path.
TEST(AttackLensFov, DemoOutputFolderThatCannotBeCreated) {
  const fs::path d = test::ScratchDir("attack_demo_out");
  const CliRun r = ExpectRefused(d, "demo --points 2 --no-iso9283 -q --threads 1 -o /proc/mcms-attack-x",
                                 {"demo -o", "/proc/mcms-attack-x"});
  EXPECT_FALSE(Has(r.err, "internal error")) << r.err;
  EXPECT_FALSE(fs::exists("/proc/mcms-attack-x"));
  const CliRun f = ExpectRefused(d, "fov-map --quiet --grid=0:0:1,0:0:1,1:1:1 -o /proc/mcms-attack-y",
                                 {"fov-map -o", "/proc/mcms-attack-y"});
  EXPECT_FALSE(Has(f.err, "internal error")) << f.err;
}

// 9. audit cameras on unreadable frames (a colour PNG cut in half, which only libpng would
// decode, and garbage bytes): each frame named with its file and reason, no libpng noise.
TEST(AttackLensFov, AuditCamerasNamesUnreadableFramesWithoutLibpngNoise) {
  const fs::path d = test::ScratchDir("attack_audit_png");
  const CliRun render = test::Mcms(d, "render --frames 12 --quiet --threads 2 -o rec");
  ASSERT_EQ(render.code, 0) << render.err;
  const fs::path colour = d / "rec" / "images" / "cam1" / "000002.png";
  const cv::Mat grey = cv::imread(colour.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(grey.empty());
  cv::Mat rgb;
  cv::merge(std::vector<cv::Mat>{grey, grey, grey}, rgb);
  ASSERT_TRUE(cv::imwrite(colour.string(), rgb));
  const std::string whole = test::ReadAll(colour);
  test::WriteText(colour, whole.substr(0, whole.size() / 2));
  std::string garbage;
  for (int i = 0; i < 5000; ++i) garbage += static_cast<char>((i * 7919 + 13) % 251);
  const fs::path junk = d / "rec" / "images" / "cam2" / "000003.png";
  test::WriteText(junk, garbage);
  const auto before = Snapshot(d);
  const CliRun r = test::Mcms(d, "audit cameras rec -q");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(Has(r.err, "libpng")) << r.err;
  EXPECT_TRUE(Has(r.out, "frame 2 degraded: camera cam1: cannot decode rec/images/cam1/000002.png: truncated PNG"))
      << r.out;
  EXPECT_TRUE(Has(r.out, "frame 3 degraded: camera cam2: cannot decode rec/images/cam2/000003.png: not a PNG"))
      << r.out;
  EXPECT_EQ(Snapshot(d), before);
}

}  // namespace
}  // namespace mcms
