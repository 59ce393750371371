// Bad inputs through the real `mcms` binary (issue 14): each is refused with one line
// naming the input and the bad value, a non-zero exit and nothing written, or (a frame's
// image, an inclinometer row) left out with the reason while the rest is processed.
#include <numbers>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <unistd.h>
#include <opencv2/imgcodecs.hpp>
#include <zlib.h>

#include "core/io.h"
#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "tests/fuse_logs.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"
#include "vision/camera_model.h"
#include "vision/image_file.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;
using Lines = std::vector<std::string>;

using test::CliRun;

// Runs `mcms ARGS` in `cwd`.
CliRun Mcms(const std::string& args, const fs::path& cwd) { return test::Mcms(cwd, args); }

const fs::path& Recording() {
  static const fs::path dir = [] {
    const fs::path d = test::ScratchDir("inputs_recording_" + std::to_string(::getpid())) / "rec";
    const CliRun r = Mcms("render --frames 5 --quiet -o " + d.string(), d.parent_path());
    EXPECT_EQ(r.code, 0) << r.err;
    return d;
  }();
  return dir;
}

fs::path Copy(const std::string& name) {
  const fs::path d = test::ScratchDir("inputs_" + name) / "rec";
  fs::copy(Recording(), d, fs::copy_options::recursive);
  fs::remove(d / "poses.csv");
  return d;
}

std::string Num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

// Writes the recording's rig inline, with the text of a camera's fields replaced by `edit`
// (camera index, field name, text) when it returns a value.
void WriteRig(const fs::path& dir, const std::function<std::string(size_t, const std::string&, const std::string&)>& edit) {
  const CameraRig rig = CameraRig::Read(Recording() / "rig.yaml");
  std::ofstream o(dir / "rig.yaml", std::ios::trunc);
  o << "cameras:\n";
  for (size_t c = 0; c < rig.size(); ++c) {
    const CameraModel& m = rig.cameras[c];
    std::ostringstream intr, rt, size;
    intr << "[";
    for (size_t i = 0; i < m.Intrinsics().size(); ++i) intr << (i ? ", " : "") << Num(m.Intrinsics()[i]);
    intr << "]";
    double r[6];
    m.T_cam_rig().ToRt(r);
    rt << "[";
    for (int i = 0; i < 6; ++i) rt << (i ? ", " : "") << Num(r[i]);
    rt << "]";
    size << "[" << m.Width() << ", " << m.Height() << "]";
    const std::map<std::string, std::string> fields = {{"name", rig.names[c]},
                                                       {"lensmodel", m.LensModelName()},
                                                       {"intrinsics", intr.str()},
                                                       {"imagersize", size.str()},
                                                       {"rt_cam_rig", rt.str()}};
    bool first = true;
    for (const char* key : {"name", "lensmodel", "intrinsics", "imagersize", "rt_cam_rig"}) {
      const std::string text = edit(c, key, fields.at(key));
      o << (first ? "  - " : "    ") << key << ": " << text << "\n";
      first = false;
    }
  }
}

void ExpectRefused(const fs::path& d, const std::string& args, const std::vector<std::string>& needles,
                   const fs::path& output) {
  const CliRun r = Mcms(args, d);
  EXPECT_EQ(r.code, 2) << r.err;
  for (const auto& n : needles) EXPECT_NE(r.err.find(n), std::string::npos) << "expected '" << n << "' in: " << r.err;
  EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(output)) << "no output may be written";
  for (const auto& e : fs::directory_iterator(output.parent_path()))
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << "left behind: " << e.path();
}

void ExpectTrackRefused(const fs::path& d, const std::vector<std::string>& needles) {
  ExpectRefused(d, "track --quiet " + d.string(), needles, d / "poses.csv");
}

TEST(Inputs, AbsurdIntrinsicsAreRefused) {
  const fs::path d = Copy("intrinsics");
  WriteRig(d, [](size_t c, const std::string& key, const std::string& text) {
    return c == 1 && key == "intrinsics" ? "[1e308" + text.substr(text.find(',')) : text;
  });
  ExpectTrackRefused(d, {"rig.yaml, camera cam1", "fx = 1e+308", "within +-1e+06"});
  WriteRig(d, [](size_t c, const std::string& key, const std::string& text) {
    return c == 2 && key == "intrinsics" ? "[-900" + text.substr(text.find(',')) : text;
  });
  ExpectTrackRefused(d, {"camera cam2", "focal length fx = -900 px must be positive"});
}

TEST(Inputs, DuplicateCameraNamesAreRefused) {
  const fs::path d = Copy("duplicate");
  WriteRig(d, [](size_t c, const std::string& key, const std::string& text) {
    return c == 2 && key == "name" ? std::string("cam1") : text;
  });
  ExpectTrackRefused(d, {"rig.yaml line", "camera name 'cam1' is used twice"});
}

TEST(Inputs, NonFiniteExtrinsicsAndADegenerateRigAreRefused) {
  const fs::path d = Copy("inf");
  WriteRig(d, [](size_t c, const std::string& key, const std::string& text) {
    return c == 3 && key == "rt_cam_rig" ? "[0, 0, 0, .inf, 0, 0]" : text;
  });
  ExpectTrackRefused(d, {"rig.yaml", "camera cam3", "field 'rt_cam_rig' holds .inf"});
  WriteRig(d, [](size_t, const std::string& key, const std::string& text) {
    return key == "rt_cam_rig" ? "[0.1, 0, 0, 0.5, 0.2, 3]" : text;
  });
  ExpectTrackRefused(d, {"rig.yaml: cameras 'cam0' and 'cam1' are both at", "a rig needs a baseline"});
}

// Issue 53: a scenario whose generated rig puts two cameras at one position is refused by
// render with the check track applies (it rendered, and track then refused).
TEST(Inputs, ScenarioWithTwoCamerasAtOnePositionIsNotRendered) {
  const fs::path d = test::ScratchDir("inputs_two_cams_one_place");
  std::string s = test::ReadAll(fs::path(MCMS_SOURCE_DIR) / "examples" / "short_scenario.yaml");
  const std::string from = "[[0.8, 0.7, 2.2], [-0.8, 0.7, 2.2]";
  ASSERT_NE(s.find(from), std::string::npos);
  s.replace(s.find(from), from.size(), "[[0.8, 0.7, 2.2], [0.8, 0.7, 2.2]");
  test::WriteText(d / "s.yaml", s);
  ExpectRefused(d, "render --quiet " + (d / "s.yaml").string() + " -o " + (d / "out").string(),
                {"s.yaml", "cameras 'cam0' and 'cam1' are both at (0.8, 0.7, 2.2) m", "a rig needs a baseline"},
                d / "out");
}

TEST(Inputs, RigThatIsAFolderOrAScalarIsRefused) {
  const fs::path d = Copy("rigfile");
  fs::remove(d / "rig.yaml");
  fs::create_directories(d / "rig.yaml");
  ExpectTrackRefused(d, {"rig.yaml: it is a folder, expected a text file"});
  fs::remove_all(d / "rig.yaml");
  std::ofstream(d / "rig.yaml") << "hello\n";
  ExpectTrackRefused(d, {"rig.yaml: expected a YAML map with a list 'cameras', found a single value 'hello'"});
}

TEST(Inputs, OpenCvCameraMatrixWithEightNumbersIsRefused) {
  const fs::path d = Copy("opencv");
  std::ofstream(d / "cv.yaml") << "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 1024\n"
                                  "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                                  "   data: [ 1100., 0., 640., 0., 1100., 512., 0., 0. ]\n";
  WriteRig(d, [](size_t c, const std::string& key, const std::string& text) {
    if (c != 0) return text;
    if (key == "lensmodel") return std::string("LENSMODEL_PINHOLE\n    model: cv.yaml");
    return text;
  });
  // A camera with 'model' reads the file; the inline fields are then ignored.
  ExpectTrackRefused(d, {"cv.yaml", "field camera_matrix (line 5) declares 3x3 but data has 8 numbers"});
}

TEST(Inputs, NanBallPositionIsRefused) {
  const fs::path d = Copy("target");
  std::ofstream(d / "target.yaml", std::ios::trunc)
      << "name: t\nball_radius_m: 0.01\nballs_m:\n  - [0, 0, 0]\n  - [0.1, .nan, 0]\n  - [0, 0.1, 0]\n";
  ExpectTrackRefused(d, {"target.yaml line 5: ball 1 has y = nan m"});
}

TEST(Inputs, Utf8BomInFramesCsvIsAccepted) {
  const fs::path d = Copy("bom");
  const std::string text = ReadTextFile(d / "frames.csv");
  std::ofstream(d / "frames.csv", std::ios::trunc | std::ios::binary) << "\xEF\xBB\xBF" << text;
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(ReadCsv(d / "poses.csv").rows.size(), 5u);
}

// Issue 14 item 3: frames with spurious reflections or occluded ball images are not "ok"
// with an empty reason; the reason names what was rejected and in which camera.
TEST(Inputs, SpuriousBlobsAndMissingBallImagesAreNamedPerCamera) {
  const fs::path d = test::ScratchDir("inputs_spurious");
  ASSERT_EQ(std::system((std::string(MCMS_CLI) + " render --print-default > " + (d / "default.yaml").string()).c_str()), 0);
  std::string text = ReadTextFile(d / "default.yaml");
  for (const auto& [key, value] : {std::pair<std::string, std::string>{"spurious_per_image: 0", "spurious_per_image: 20"},
                                   {"occlusion_probability: 0", "occlusion_probability: 0.3"}}) {
    const auto at = text.find(key);
    ASSERT_NE(at, std::string::npos) << key;
    text.replace(at, key.size(), value);
  }
  std::ofstream(d / "scenario.yaml") << text;
  const CliRun render = Mcms("render scenario.yaml --frames 4 --quiet -o rec", d);
  ASSERT_EQ(render.code, 0) << render.err;
  const CliRun r = Mcms("track --quiet rec", d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "rec" / "poses.csv");
  ASSERT_EQ(t.rows.size(), 4u);
  int spurious = 0, missing = 0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    const std::string& reason = t.rows[i][t.Column("reason")];
    EXPECT_NE(t.rows[i][t.Column("status")], "ok") << reason;
    EXPECT_FALSE(reason.empty());
    spurious += reason.find("blobs matching no ball (spurious reflections?) rejected (cam") != std::string::npos;
    missing += reason.find("ball images expected but not observed (cam") != std::string::npos;
  }
  EXPECT_EQ(spurious, 4);
  EXPECT_GT(missing, 0);
}

// A bumped camera (rotated by 5 mrad after calibration): its dropped observations are
// attributed to it by name.
TEST(Inputs, OutliersAreAttributedToTheirCamera) {
  const fs::path d = Copy("bumped");
  WriteRig(d, [](size_t c, const std::string& key, const std::string& text) {
    if (c != 1 || key != "rt_cam_rig") return text;
    const double rx = std::stod(text.substr(1));
    return "[" + Num(rx + 0.005) + text.substr(text.find(','));
  });
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "poses.csv");
  int named = 0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    const std::string& reason = t.rows[i][t.Column("reason")];
    EXPECT_NE(t.rows[i][t.Column("status")], "ok") << reason;
    named += reason.find("outlier observation(s) dropped (cam1 ") != std::string::npos;
  }
  EXPECT_GT(named, 0);
}

TEST(Inputs, StrayImageNameIsBlamedNotFramesCsv) {
  const fs::path d = Copy("stray");
  fs::copy_file(d / "images" / "cam0" / "000001.png", d / "images" / "cam0" / "copy of 000001 (2).png");
  ExpectTrackRefused(d, {"copy of 000001 (2).png is frame 12 (the digits of its name)", "remove the stray image"});
}

TEST(Inputs, BoardFileThatIsAFolderOrAScalarIsRefused) {
  const fs::path d = test::ScratchDir("inputs_board");
  fs::create_directories(d / "cam0");
  fs::create_directories(d / "board_dir");
  std::ofstream(d / "board.yaml") << "hello\n";
  ExpectRefused(d, "calib-rig board_dir cam0 -o out", {"board file board_dir: cannot read it as YAML", "it is a folder"},
                d / "out");
  ExpectRefused(d, "calib-rig board.yaml cam0 -o out", {"board file board.yaml: expected a Kalibr YAML map"}, d / "out");
}

uint32_t Crc32(const unsigned char* p, size_t n) {
  uint32_t c = 0xffffffffu;
  for (size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}

// A PNG whose header (with a valid CRC) claims 60000 x 60000: that frame is degraded
// with the reason, every other frame is tracked, the run ends with exit 0.
TEST(Inputs, HugePngHeaderDegradesItsFrameOnly) {
  const fs::path d = Copy("hugepng");
  const fs::path png = d / "images" / "cam2" / "000003.png";
  std::string bytes = ReadTextFile(png);
  ASSERT_GT(bytes.size(), 33u);
  auto put = [&](size_t o, uint32_t v) {
    for (int k = 0; k < 4; ++k) bytes[o + k] = static_cast<char>((v >> (24 - 8 * k)) & 0xff);
  };
  put(16, 60000);
  put(20, 60000);
  put(29, Crc32(reinterpret_cast<const unsigned char*>(bytes.data()) + 12, 17));
  std::ofstream(png, std::ios::trunc | std::ios::binary) << bytes;
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "poses.csv");
  ASSERT_EQ(t.rows.size(), 5u);
  const int st = t.Column("status"), re = t.Column("reason");
  EXPECT_EQ(t.rows[3][st], "degraded");
  EXPECT_NE(t.rows[3][re].find("header says 60000x60000 but the rig says 1280x1024"), std::string::npos)
      << t.rows[3][re];
  EXPECT_FALSE(t.rows[3][t.Column("x_m")].empty()) << "three cameras still give a pose";
}

// Issue 53: a 32-bit float TIFF among the frames (not what a camera stores) degrades its
// frame with the file named; the run goes on (it aborted the whole track, no file named).
TEST(Inputs, FloatTiffDegradesItsFrameNamingTheFile) {
  const fs::path d = Copy("floattiff");
  const fs::path png = d / "images" / "cam1" / "000002.png";
  const cv::Mat f(1024, 1280, CV_32FC1, cv::Scalar(12.0f));
  ASSERT_TRUE(cv::imwrite((d / "float.tif").string(), f));
  fs::copy_file(d / "float.tif", png, fs::copy_options::overwrite_existing);  // read by its first bytes
  fs::remove(d / "float.tif");
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "poses.csv");
  ASSERT_EQ(t.rows.size(), 5u);
  const int st = t.Column("status"), re = t.Column("reason");
  EXPECT_EQ(t.rows[2][st], "degraded");
  EXPECT_NE(t.rows[2][re].find("cam1/000002.png holds CV_32FC1 samples; expected 8- or 16-bit integer images"),
            std::string::npos)
      << t.rows[2][re];
}

// Damaged PNG frames (vision/image_file.h): a wrong CRC, a truncated file and a zlib bomb
// (a valid stream that inflates to twice the 1280 x 1024 the header gives) each degrade
// their frame only, with the reason naming the file; nothing of the bomb is inflated beyond
// the header's size.
TEST(Inputs, DamagedPngFramesDegradeTheirFrameOnly) {
  const fs::path d = Copy("damagedpng");
  auto image = [&](const char* cam, int frame) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.png", frame);
    return d / "images" / cam / name;
  };
  auto write = [](const fs::path& p, const std::string& bytes) {
    std::ofstream(p, std::ios::trunc | std::ios::binary) << bytes;
  };
  std::string crc = ReadTextFile(image("cam1", 1));
  ASSERT_GT(crc.size(), 1000u);
  crc[crc.size() / 2] = static_cast<char>(crc[crc.size() / 2] ^ 0x10);  // inside an IDAT chunk's data
  write(image("cam1", 1), crc);
  const std::string whole = ReadTextFile(image("cam2", 2));
  write(image("cam2", 2), whole.substr(0, whole.size() / 2));
  {
    std::string png = "\x89PNG\r\n\x1a\n";
    auto chunk = [&](const std::string& type, const std::string& data) {
      const uint32_t n = static_cast<uint32_t>(data.size());
      for (int k = 3; k >= 0; --k) png += static_cast<char>((n >> (8 * k)) & 0xff);
      const std::string body = type + data;
      const uint32_t c = Crc32(reinterpret_cast<const unsigned char*>(body.data()), body.size());
      png += body;
      for (int k = 3; k >= 0; --k) png += static_cast<char>((c >> (8 * k)) & 0xff);
    };
    chunk("IHDR", std::string("\0\0\x05\0\0\0\x04\0\x08\0\0\0\0", 13));  // 1280 x 1024, 8-bit grey
    std::vector<unsigned char> zeros(2 * 1024 * 1281, 0), z(compressBound(2 * 1024 * 1281));
    uLongf size = static_cast<uLongf>(z.size());
    ASSERT_EQ(compress2(z.data(), &size, zeros.data(), static_cast<uLong>(zeros.size()), 9), Z_OK);
    chunk("IDAT", std::string(reinterpret_cast<const char*>(z.data()), size));
    chunk("IEND", "");
    write(image("cam3", 3), png);
  }
  const CliRun r = Mcms("track --quiet " + d.string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  const CsvTable t = ReadCsv(d / "poses.csv");
  ASSERT_EQ(t.rows.size(), 5u);
  const int st = t.Column("status"), re = t.Column("reason");
  const std::vector<std::pair<int, std::string>> expected = {
      {1, "cam1: cannot decode " + image("cam1", 1).string() + ": chunk 'IDAT' at byte "},
      {2, "cam2: cannot decode " + image("cam2", 2).string() + ": truncated PNG"},
      {3, "cam3: cannot decode " + image("cam3", 3).string() + ": the IDAT zlib stream inflates to more than the 1311744 bytes"}};
  for (const auto& [f, reason] : expected) {
    EXPECT_EQ(t.rows[f][st], "degraded") << f;
    EXPECT_NE(t.rows[f][re].find(reason), std::string::npos) << t.rows[f][re];
  }
  EXPECT_NE(t.rows[1][re].find("has a wrong CRC"), std::string::npos) << t.rows[1][re];
  EXPECT_NE(t.rows[3][re].find("zlib bomb"), std::string::npos) << t.rows[3][re];
  for (size_t f : {0u, 4u}) EXPECT_EQ(t.rows[f][st], "ok") << f;
}

// `mcms render --format pgm|tiff` writes the same frames as PNG in those formats, and
// `mcms track` reads them (memory-mapped) to the same poses; an unknown format is refused.
TEST(Inputs, RenderFormatsTrackToTheSamePoses) {
  const fs::path d = test::ScratchDir("inputs_formats");
  const CsvTable png = [&] {
    const fs::path rec = Copy("formats_png");
    EXPECT_EQ(Mcms("track --quiet " + rec.string(), rec).code, 0);
    return ReadCsv(rec / "poses.csv");
  }();
  for (const std::string format : {"pgm", "tiff"}) {
    SCOPED_TRACE(format);
    const fs::path rec = d / format;
    const CliRun r = Mcms("render --frames 5 --quiet --format " + format + " -o " + rec.string(), d);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(fs::exists(rec / "images" / "cam0" / (format == "pgm" ? "000000.pgm" : "000000.tif")));
    EXPECT_FALSE(fs::exists(rec / "images" / "cam0" / "000000.png"));
    const cv::Mat a = cv::imread((Recording() / "images" / "cam0" / "000002.png").string(), cv::IMREAD_UNCHANGED);
    const cv::Mat b = cv::imread((rec / "images" / "cam0" / (format == "pgm" ? "000002.pgm" : "000002.tif")).string(),
                                 cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(a.empty());
    ASSERT_FALSE(b.empty());
    EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0) << "the same pixels in every format";
    // Every rendered frame, read by the reader of `mcms track`, equals cv::imread's decode.
    for (const fs::path& images : {Recording() / "images", rec / "images"})
      for (const auto& e : fs::recursive_directory_iterator(images)) {
        if (!e.is_regular_file()) continue;
        std::string problem;
        ImageFileReader reader = ImageFileReader::kOpenCv;
        const cv::Mat ours = ReadImageFile(e.path(), {}, &problem, &reader);
        const cv::Mat theirs = cv::imread(e.path().string(), cv::IMREAD_UNCHANGED);
        ASSERT_FALSE(ours.empty()) << problem;
        EXPECT_NE(reader, ImageFileReader::kOpenCv) << e.path();
        EXPECT_TRUE(ours.type() == theirs.type() && ours.size() == theirs.size() && cv::norm(ours, theirs, cv::NORM_INF) == 0)
            << e.path();
      }
    ASSERT_EQ(Mcms("track --quiet " + rec.string(), rec).code, 0);
    const CsvTable t = ReadCsv(rec / "poses.csv");
    ASSERT_EQ(t.rows.size(), png.rows.size());
    for (size_t f = 0; f < t.rows.size(); ++f)
      for (const char* col : {"status", "x_m", "y_m", "z_m", "qw", "qx"})
        EXPECT_EQ(t.rows[f][t.Column(col)], png.rows[f][png.Column(col)]) << f << " " << col;
  }
  const CliRun bad = Mcms("render --frames 1 --quiet --format jpeg -o " + (d / "jpeg").string(), d);
  EXPECT_NE(bad.code, 0);
  EXPECT_NE(bad.err.find("--format"), std::string::npos) << bad.err;
  EXPECT_FALSE(fs::exists(d / "jpeg"));
}

// The same for the other formats a frame may hold under its .png name (BMP, PGM, JPEG, TIFF):
// OpenCV would allocate whatever the header claims (up to 2^30 pixels) before decoding, so
// every header's size is checked first, and that frame alone is degraded with the reason.
TEST(Inputs, HugeHeaderOfEveryFormatDegradesItsFrameOnly) {
  struct Case {
    std::string ext, format;
    std::function<void(std::vector<unsigned char>*)> patch;
  };
  const std::vector<Case> cases = {
      {".bmp", "BMP",
       [](std::vector<unsigned char>* b) {
         for (int k = 0; k < 4; ++k) (*b)[18 + k] = (*b)[22 + k] = static_cast<unsigned char>((60000 >> (8 * k)) & 0xff);
       }},
      {".pgm", "PNM",
       [](std::vector<unsigned char>* b) {
         const std::string head = "P5\n60000 60000\n255\n";
         const std::string old(b->begin(), b->end());
         const size_t data = old.size() - 1280u * 1024u;  // binary PGM: header then the pixels
         b->assign(head.begin(), head.end());
         b->insert(b->end(), old.begin() + static_cast<long>(data), old.end());
       }},
      {".jpg", "JPEG",
       [](std::vector<unsigned char>* b) {
         for (size_t o = 2; o + 9 < b->size(); ++o)
           if ((*b)[o] == 0xff && (*b)[o + 1] == 0xc0) {  // SOF0: length, precision, height, width
             (*b)[o + 5] = (*b)[o + 7] = 0xea;
             (*b)[o + 6] = (*b)[o + 8] = 0x60;
             return;
           }
         FAIL() << "no SOF0 marker";
       }},
      {".tiff", "TIFF",
       [](std::vector<unsigned char>* b) {  // little-endian, IFD at the offset in bytes 4-7
         ASSERT_EQ((*b)[0], 'I');
         const uint32_t ifd = (*b)[4] | ((*b)[5] << 8) | ((*b)[6] << 16) | (uint32_t{(*b)[7]} << 24);
         const int count = (*b)[ifd] | ((*b)[ifd + 1] << 8);
         for (int e = 0; e < count; ++e) {
           unsigned char* t = b->data() + ifd + 2 + 12 * e;
           const int tag = t[0] | (t[1] << 8);
           if (tag != 256 && tag != 257) continue;
           t[2] = 4, t[3] = 0;  // LONG
           for (int k = 0; k < 4; ++k) t[8 + k] = static_cast<unsigned char>((60000 >> (8 * k)) & 0xff);
         }
       }},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.format);
    const fs::path d = Copy("huge" + c.ext.substr(1));
    const fs::path png = d / "images" / "cam2" / "000003.png";
    const cv::Mat im = cv::imread(png.string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(im.empty());
    std::vector<unsigned char> bytes;
    ASSERT_TRUE(cv::imencode(c.ext, im, bytes));
    {  // unpatched, the format is decoded as any frame
      const fs::path d0 = Copy("valid" + c.ext.substr(1));
      const fs::path f0 = d0 / "images" / "cam2" / "000003.png";
      std::ofstream(f0, std::ios::trunc | std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()),
                                                                  static_cast<std::streamsize>(bytes.size()));
      const CliRun r0 = Mcms("track --quiet " + d0.string(), d0);
      ASSERT_EQ(r0.code, 0) << r0.err;
      const CsvTable t0 = ReadCsv(d0 / "poses.csv");
      ASSERT_EQ(t0.rows.size(), 5u);
      EXPECT_EQ(t0.rows[3][t0.Column("status")], "ok") << t0.rows[3][t0.Column("reason")];
    }
    c.patch(&bytes);
    std::ofstream(png, std::ios::trunc | std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()),
                                                                   static_cast<std::streamsize>(bytes.size()));
    const CliRun r = Mcms("track --quiet " + d.string(), d);
    ASSERT_EQ(r.code, 0) << r.err;
    const CsvTable t = ReadCsv(d / "poses.csv");
    ASSERT_EQ(t.rows.size(), 5u);
    const int st = t.Column("status"), re = t.Column("reason");
    EXPECT_EQ(t.rows[3][st], "degraded");
    EXPECT_NE(t.rows[3][re].find("(" + c.format + ") header says 60000x60000 but the rig says 1280x1024"), std::string::npos)
        << t.rows[3][re];
    for (size_t f : {0u, 1u, 2u, 4u}) EXPECT_EQ(t.rows[f][st], "ok") << f;
  }
}

TEST(Inputs, RenderOfAnEndlessFileIsBounded) {
  const fs::path d = test::ScratchDir("inputs_render_zero");
  ExpectRefused(d, "render /dev/zero -o " + (d / "out").string(),
                {"/dev/zero: not a regular file (a FIFO, socket or device)"}, d / "out");
}

TEST(Inputs, NonFiniteBaseGuessIsNamed) {
  const fs::path d = test::ScratchDir("inputs_base_guess");
  std::ofstream(d / "m.yaml") << "measurements:\n  - {q_rad: [0, 0, 0, 0, 0, 0], position_m: [1, 0, 1]}\n";
  ExpectRefused(d, "calib-robot m.yaml -o robot.yaml --base-guess nan 0 0 1 0 0 0",
                {"calib-robot: --base-guess x is nan; expected 7 finite numbers"}, d / "robot.yaml");
}

TEST(Inputs, AuditRepairedRigIntoAFolderIsRefusedBeforeTheWork) {
  const fs::path d = Copy("audit");
  fs::create_directories(d / "out");
  ExpectRefused(d, "audit cameras --quiet " + d.string() + " --repaired-rig " + (d / "out").string(),
                {"audit --repaired-rig", "is a folder", "nothing was written"}, d / "out" / "rig.yaml");
}

using test::CleanLogs;
using test::Logs;
using test::N;
using test::Write;

const std::string kFuse = "fuse --quiet --tracker poses.csv --inclinometer incl.csv --setup setup.yaml -o fused.csv";

// An 80 deg reading of a 30 deg inclinometer is left out with a warning naming the file,
// the line and the value; the other rows are fused. Readings all out of range are refused.
TEST(Inputs, InclinometerReadingBeyondItsRangeIsLeftOut) {
  const fs::path d = test::ScratchDir("inputs_incl_range");
  Logs l = CleanLogs();
  l.files.erase("joints.csv");
  Write(d, l);
  const CliRun clean = Mcms(kFuse, d);
  ASSERT_EQ(clean.code, 0) << clean.err;
  const size_t rows = ReadCsv(d / "fused.csv").rows.size();
  fs::remove(d / "fused.csv");
  Lines& in = l.files["incl.csv"];
  in[12] = in[12].substr(0, in[12].find(',')) + "," + Num(80.0 * std::numbers::pi / 180.0) + ",0";
  Write(d, l);
  const CliRun r = Mcms(kFuse, d);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("incl.csv line 13: tilt_x 80 deg is beyond the inclinometer's range of 30 deg"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(ReadCsv(d / "fused.csv").rows.size(), rows);
  fs::remove(d / "fused.csv");
  for (size_t k = 1; k < in.size(); ++k) in[k] = in[k].substr(0, in[k].find(',')) + ",1.4,0";
  Write(d, l);
  ExpectRefused(d, kFuse, {"incl.csv: every inclinometer reading is beyond the sensor's range of 30 deg"},
                d / "fused.csv");
}

}  // namespace
}  // namespace mcms
