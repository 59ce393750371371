// The frame reader (vision/image_file.h): every image it decodes equals OpenCV's
// cv::imread(IMREAD_UNCHANGED) bit for bit (PNGs of every filter type written here, PNGs
// written by OpenCV at every compression setting, the real PNGs of shared/data, the fuzz
// seeds; binary PGM and uncompressed TIFF mapped from the file); bad files give an empty
// image and a reason naming the file and what was wrong.
#include <gtest/gtest.h>

#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "vision/image_file.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<unsigned char>;

// ---- A PNG writer with every choice this reader must handle --------------------------

void Put32(Bytes* b, uint32_t v) {
  for (int k = 3; k >= 0; --k) b->push_back(static_cast<unsigned char>(v >> (8 * k)));
}

void Chunk(Bytes* png, const std::string& type, const Bytes& data) {
  Put32(png, static_cast<uint32_t>(data.size()));
  const size_t start = png->size();
  png->insert(png->end(), type.begin(), type.end());
  png->insert(png->end(), data.begin(), data.end());
  Put32(png, static_cast<uint32_t>(crc32(0, png->data() + start, static_cast<uInt>(png->size() - start))));
}

int Paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

// Filters one row of raw bytes (PNG spec section 9) with `type`, `prior` the raw row above.
Bytes FilterRow(int type, const Bytes& raw, const Bytes& prior, int bpp) {
  Bytes out(raw.size());
  for (size_t i = 0; i < raw.size(); ++i) {
    const int a = i >= size_t(bpp) ? raw[i - bpp] : 0, b = prior[i], c = i >= size_t(bpp) ? prior[i - bpp] : 0;
    const int pred = type == 0 ? 0 : type == 1 ? a : type == 2 ? b : type == 3 ? (a + b) / 2 : Paeth(a, b, c);
    out[i] = static_cast<unsigned char>(raw[i] - pred);
  }
  return out;
}

struct PngOptions {
  int bit_depth = 8;                        // 1, 2, 4, 8, 16 (grey)
  std::function<int(int)> filter = [](int) { return 0; };  // filter type of row y
  size_t idat_size = 0;                     // split the stream into IDATs of this size (0: one)
  bool empty_idats = false;                 // zero-length IDATs between the others
  bool interlace = false;                   // Adam7
  std::vector<std::pair<std::string, Bytes>> before_idat, after_idat;  // extra chunks
  int level = 6;                            // zlib compression level
};

// The rows of `im` (CV_8UC1 or CV_16UC1; at bit depths below 8 the low bits of CV_8U
// values), filtered, in PNG byte order.
Bytes FilteredRows(const cv::Mat& im, const PngOptions& o) {
  const int bpp = std::max(1, o.bit_depth / 8);
  const size_t row_bytes = (size_t(im.cols) * o.bit_depth + 7) / 8;
  Bytes out, prior(row_bytes, 0);
  for (int y = 0; y < im.rows; ++y) {
    Bytes raw(row_bytes, 0);
    for (int x = 0; x < im.cols; ++x) {
      if (o.bit_depth == 16) {
        raw[2 * x] = static_cast<unsigned char>(im.at<uint16_t>(y, x) >> 8);
        raw[2 * x + 1] = static_cast<unsigned char>(im.at<uint16_t>(y, x) & 0xff);
      } else if (o.bit_depth == 8) {
        raw[x] = im.at<uint8_t>(y, x);
      } else {
        const int per = 8 / o.bit_depth, v = im.at<uint8_t>(y, x) & ((1 << o.bit_depth) - 1);
        raw[x / per] |= static_cast<unsigned char>(v << (8 - o.bit_depth * (x % per + 1)));
      }
    }
    const int type = o.filter(y);
    out.push_back(static_cast<unsigned char>(type));
    const Bytes f = FilterRow(type, raw, prior, bpp);
    out.insert(out.end(), f.begin(), f.end());
    prior = raw;
  }
  return out;
}

Bytes Deflate(const Bytes& raw, int level) {
  uLongf size = compressBound(static_cast<uLong>(raw.size()));
  Bytes z(size);
  EXPECT_EQ(compress2(z.data(), &size, raw.data(), static_cast<uLong>(raw.size()), level), Z_OK);
  z.resize(size);
  return z;
}

Bytes Ihdr(uint32_t w, uint32_t h, int depth, int colour, int interlace) {
  Bytes d;
  Put32(&d, w);
  Put32(&d, h);
  for (int v : {depth, colour, 0, 0, interlace}) d.push_back(static_cast<unsigned char>(v));
  return d;
}

Bytes AssemblePng(const Bytes& ihdr, const Bytes& zlib, const PngOptions& o) {
  Bytes png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  Chunk(&png, "IHDR", ihdr);
  for (const auto& [type, data] : o.before_idat) Chunk(&png, type, data);
  const size_t step = o.idat_size ? o.idat_size : std::max<size_t>(zlib.size(), 1);
  for (size_t p = 0; p < zlib.size(); p += step) {
    Chunk(&png, "IDAT", Bytes(zlib.begin() + long(p), zlib.begin() + long(std::min(zlib.size(), p + step))));
    if (o.empty_idats) Chunk(&png, "IDAT", {});
  }
  for (const auto& [type, data] : o.after_idat) Chunk(&png, type, data);
  Chunk(&png, "IEND", {});
  return png;
}

Bytes EncodePng(const cv::Mat& im, const PngOptions& o = {}) {
  Bytes stream;
  if (!o.interlace) {
    stream = FilteredRows(im, o);
  } else {  // Adam7: seven sub-images, each filtered on its own
    const int x0[7] = {0, 4, 0, 2, 0, 1, 0}, y0[7] = {0, 0, 4, 0, 2, 0, 1};
    const int dx[7] = {8, 8, 4, 4, 2, 2, 1}, dy[7] = {8, 8, 8, 4, 4, 2, 2};
    for (int p = 0; p < 7; ++p) {
      const int w = (im.cols - x0[p] + dx[p] - 1) / dx[p], h = (im.rows - y0[p] + dy[p] - 1) / dy[p];
      if (w <= 0 || h <= 0) continue;
      cv::Mat sub(h, w, im.type());
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (im.depth() == CV_8U)
            sub.at<uint8_t>(y, x) = im.at<uint8_t>(y0[p] + y * dy[p], x0[p] + x * dx[p]);
          else
            sub.at<uint16_t>(y, x) = im.at<uint16_t>(y0[p] + y * dy[p], x0[p] + x * dx[p]);
      const Bytes rows = FilteredRows(sub, o);
      stream.insert(stream.end(), rows.begin(), rows.end());
    }
  }
  return AssemblePng(Ihdr(im.cols, im.rows, o.bit_depth, 0, o.interlace ? 1 : 0), Deflate(stream, o.level), o);
}

// A frame-like image: a sloped background with noise, bright discs, and the extremes
// (0 and the maximum, where the filters' byte arithmetic wraps around).
cv::Mat FrameLike(int w, int h, int depth, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const double max = depth == CV_8U ? 255 : 65535, scale = max / 255;
  std::normal_distribution<double> noise(0, 2 * scale);
  cv::Mat im(h, w, depth == CV_8U ? CV_8UC1 : CV_16UC1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double v = scale * (12 + 4.0 * x / w + 3.0 * y / h) + noise(rng);
      const double dxc = x - 0.3 * w, dyc = y - 0.6 * h;
      if (dxc * dxc + dyc * dyc < 0.02 * w * h) v = 200 * scale + noise(rng);
      if ((x + 3 * y) % 23 == 0) v = 0;
      if ((2 * x + y) % 29 == 0) v = max;
      v = std::clamp(std::round(v), 0.0, max);
      if (depth == CV_8U)
        im.at<uint8_t>(y, x) = static_cast<uint8_t>(v);
      else
        im.at<uint16_t>(y, x) = static_cast<uint16_t>(v);
    }
  return im;
}

void WriteBytes(const fs::path& p, const Bytes& b) {
  std::ofstream(p, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(b.data()), long(b.size()));
}

Bytes ReadBytes(const fs::path& p) {
  const std::string s = test::ReadAll(p);
  return Bytes(s.begin(), s.end());
}

bool SameImage(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && (a.empty() || cv::norm(a, b, cv::NORM_INF) == 0.0);
}

struct Read {
  cv::Mat image;
  std::string problem;
  ImageFileReader reader = ImageFileReader::kOpenCv;
};

Read ReadIt(const fs::path& p, std::optional<std::array<int, 2>> expected = std::nullopt) {
  Read r;
  ImageFileOptions o;
  o.expected_size = expected;
  r.image = ReadImageFile(p, o, &r.problem, &r.reader);
  return r;
}

// Reads `p` with our reader and with cv::imread: the same image, and our reader is `want`.
void ExpectSameAsOpenCv(const fs::path& p, ImageFileReader want) {
  SCOPED_TRACE(p.string());
  const Read r = ReadIt(p);
  ASSERT_FALSE(r.image.empty()) << r.problem;
  EXPECT_EQ(ToString(r.reader), std::string(ToString(want)));
  const cv::Mat cv_image = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(cv_image.empty());
  EXPECT_TRUE(SameImage(r.image, cv_image)) << "differs from cv::imread";
}

// ---- Exact decoding --------------------------------------------------------------------

TEST(PngReader, EveryFilterTypeEqualsOpenCv) {
  const fs::path d = test::ScratchDir("png_filters");
  int files = 0;
  for (const int depth : {CV_8U, CV_16U})
    for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {1, 7}, {3, 5}, {17, 9}, {64, 48}, {640, 480}}) {
      const cv::Mat im = FrameLike(w, h, depth, 7 + w);
      std::mt19937 rng(w * 31 + h);
      const std::vector<std::pair<std::string, std::function<int(int)>>> patterns = {
          {"none", [](int) { return 0; }},        {"sub", [](int) { return 1; }},
          {"up", [](int) { return 2; }},          {"average", [](int) { return 3; }},
          {"paeth", [](int) { return 4; }},       {"cycle", [](int y) { return y % 5; }},
          {"random", [&rng](int) { return int(rng() % 5); }}};
      for (const auto& [name, filter] : patterns) {
        PngOptions o;
        o.bit_depth = depth == CV_8U ? 8 : 16;
        o.filter = filter;
        const fs::path p = d / (name + "_" + std::to_string(w) + "x" + std::to_string(h) + "_" + std::to_string(o.bit_depth) + ".png");
        WriteBytes(p, EncodePng(im, o));
        ExpectSameAsOpenCv(p, ImageFileReader::kPng);
        EXPECT_TRUE(SameImage(ReadIt(p).image, im)) << p;
        ++files;
      }
    }
  EXPECT_EQ(files, 2 * 6 * 7);
}

TEST(PngReader, SplitStreamsAndAncillaryChunksEqualOpenCv) {
  const fs::path d = test::ScratchDir("png_chunks");
  for (const int depth : {CV_8U, CV_16U}) {
    const cv::Mat im = FrameLike(200, 150, depth, 3);
    PngOptions o;
    o.bit_depth = depth == CV_8U ? 8 : 16;
    o.filter = [](int y) { return (y * 7) % 5; };
    for (const size_t split : {size_t{1}, size_t{13}, size_t{8192}}) {
      o.idat_size = split;
      o.empty_idats = split == 13;
      // gAMA, sBIT and tRNS change nothing that IMREAD_UNCHANGED returns for grey; a
      // PLTE in a grey image is ignored (libpng warns); text and time are metadata.
      o.before_idat = {{"gAMA", {0, 0, 0xb1, 0x8f}},
                       {"sBIT", {static_cast<unsigned char>(o.bit_depth == 8 ? 6 : 12)}},
                       {"tRNS", {0, 7}},
                       {"PLTE", {1, 2, 3}},
                       {"tEXt", {'C', 'o', 'm', 'm', 'e', 'n', 't', 0, 'h', 'i'}}};
      o.after_idat = {{"tIME", {0x07, 0xe8, 1, 2, 3, 4, 5}}, {"zzZz", {9, 9}}};
      const fs::path p = d / ("split" + std::to_string(split) + "_" + std::to_string(o.bit_depth) + ".png");
      WriteBytes(p, EncodePng(im, o));
      ExpectSameAsOpenCv(p, ImageFileReader::kPng);
      EXPECT_TRUE(SameImage(ReadIt(p).image, im));
    }
  }
}

TEST(PngReader, OpenCvWrittenPngsAtEveryCompressionSettingEqualOpenCv) {
  const fs::path d = test::ScratchDir("png_opencv");
  for (const int depth : {CV_8U, CV_16U}) {
    const cv::Mat im = FrameLike(320, 256, depth, 11);
    for (int level = 0; level <= 9; level += 3)
      for (const int strategy : {cv::IMWRITE_PNG_STRATEGY_DEFAULT, cv::IMWRITE_PNG_STRATEGY_FILTERED,
                                 cv::IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY, cv::IMWRITE_PNG_STRATEGY_RLE,
                                 cv::IMWRITE_PNG_STRATEGY_FIXED}) {
        char name[64];
        std::snprintf(name, sizeof(name), "level%d_strategy%d_depth%d.png", level, strategy, depth);
        const fs::path p = d / name;
        ASSERT_TRUE(cv::imwrite(p.string(), im, {cv::IMWRITE_PNG_COMPRESSION, level, cv::IMWRITE_PNG_STRATEGY, strategy}));
        ExpectSameAsOpenCv(p, ImageFileReader::kPng);
      }
    const fs::path p = d / ("write_image_file_" + std::to_string(depth) + ".png");
    WriteImageFile(p, im, ImageFileFormat::kPng);
    ExpectSameAsOpenCv(p, ImageFileReader::kPng);
    EXPECT_TRUE(SameImage(ReadIt(p).image, im));
  }
}

// ---- Frames read in part (ImageFileRows) ---------------------------------------------

// The rows Prepare(asked) must unfilter when the rows in `ready` are ready: the rows
// asked for and, for a row filtered Up, Average or Paeth (2..4), the row above, and so on
// up to a row filtered None or Sub or the first one (or a row already ready).
std::vector<char> RowsNeeded(const std::vector<cv::Range>& asked, const std::function<int(int)>& filter, int h,
                             const std::vector<char>& ready) {
  std::vector<char> need(h, 0);
  for (const cv::Range& r : asked)
    for (int y = std::max(r.start, 0); y < std::min(r.end, h); ++y)
      for (int k = y; k >= 0 && !ready[k] && !need[k]; --k) {
        need[k] = 1;
        if (filter(k) < 2) break;
      }
  return need;
}

// PNGs with every filter type forced (one type for all rows, cycles, a Sub row between
// runs of Paeth rows, random), 8- and 16-bit: the rows asked for, in two rounds, are
// bit-exact against cv::imread's decode; exactly the rows they depend on are unfiltered
// too; every other row is zero; then every row equals cv::imread's image. (All rows None:
// unfiltered whole by Read().)
TEST(PngReader, RowsReadInPartEqualOpenCvForEveryFilterType) {
  const fs::path d = test::ScratchDir("png_rows");
  int files = 0;
  for (const int depth : {CV_8U, CV_16U})
    for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {3, 5}, {17, 9}, {64, 48}, {640, 480}}) {
      const cv::Mat im = FrameLike(w, h, depth, 17 + w);
      std::vector<int> random_filters(h);
      std::mt19937 rng(w * 7 + h);
      for (int& f : random_filters) f = int(rng() % 5);
      const std::vector<std::pair<std::string, std::function<int(int)>>> patterns = {
          {"none", [](int) { return 0; }},
          {"sub", [](int) { return 1; }},
          {"up", [](int) { return 2; }},
          {"average", [](int) { return 3; }},
          {"paeth", [](int) { return 4; }},
          {"cycle", [](int y) { return y % 5; }},
          {"paeth_sub_every_7", [](int y) { return y % 7 == 3 ? 1 : 4; }},
          {"average_none_every_11", [](int y) { return y % 11 == 5 ? 0 : 3; }},
          {"random", [&random_filters](int y) { return random_filters[y]; }}};
      for (const auto& [name, filter] : patterns) {
        PngOptions o;
        o.bit_depth = depth == CV_8U ? 8 : 16;
        o.filter = filter;
        const fs::path p = d / (name + "_" + std::to_string(w) + "x" + std::to_string(h) + "_" +
                                std::to_string(o.bit_depth) + ".png");
        SCOPED_TRACE(p.string());
        WriteBytes(p, EncodePng(im, o));
        const cv::Mat theirs = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
        ASSERT_TRUE(SameImage(theirs, im));
        ImageFileRows rows;
        std::string problem;
        ImageFileReader reader = ImageFileReader::kOpenCv;
        ASSERT_TRUE(rows.Read(p, {}, &problem, &reader)) << problem;
        EXPECT_EQ(ToString(reader), std::string("png"));
        ASSERT_EQ(rows.image().size(), theirs.size());
        ASSERT_EQ(rows.image().type(), theirs.type());
        bool all_none = true;
        for (int y = 0; y < h; ++y) all_none = all_none && filter(y) == 0;
        if (all_none) {  // unfiltered whole by Read(): a copy, cheaper than zeroing
          EXPECT_EQ(rows.rows_ready(), static_cast<size_t>(h));
          EXPECT_TRUE(SameImage(rows.image(), theirs));
          EXPECT_EQ(rows.Prepare({cv::Range(0, h)}), 0u);
          ++files;
          continue;
        }
        EXPECT_EQ(rows.rows_ready(), 0u);
        EXPECT_EQ(cv::countNonZero(rows.image()), 0) << "rows not prepared must read as zero";
        // Two windows' rows, then more rows (next to, and below, rows already ready: the
        // prior of a row filtered from above is then a row prepared before).
        const std::vector<std::vector<cv::Range>> rounds = {
            {cv::Range(h / 3, h / 3 + 4), cv::Range(h - 2, h + 5)},
            {cv::Range(h / 3 + 4, h / 3 + 6), cv::Range(h / 2, h / 2 + 1), cv::Range(-4, 1)}};
        std::vector<char> ready(h, 0);
        for (const auto& asked : rounds) {
          const std::vector<char> need = RowsNeeded(asked, filter, h, ready);
          const size_t expected = static_cast<size_t>(std::count(need.begin(), need.end(), 1));
          EXPECT_EQ(rows.Prepare(asked), expected);
          for (int y = 0; y < h; ++y) ready[y] = ready[y] || need[y];
          for (int y = 0; y < h; ++y) {
            const cv::Mat ours = rows.image().row(y), cv_row = theirs.row(y);
            if (ready[y])
              EXPECT_EQ(cv::norm(ours, cv_row, cv::NORM_INF), 0.0) << "row " << y << " differs from cv::imread";
            else
              EXPECT_EQ(cv::countNonZero(ours), 0) << "row " << y << " was not needed but is not zero";
          }
        }
        EXPECT_EQ(rows.rows_ready(), static_cast<size_t>(std::count(ready.begin(), ready.end(), 1)));
        rows.PrepareAll();
        EXPECT_EQ(rows.rows_ready(), static_cast<size_t>(h));
        EXPECT_TRUE(SameImage(rows.image(), theirs));
        ++files;
      }
    }
  EXPECT_EQ(files, 2 * 5 * 9);
}

// Other files are read whole at once; bad ones give ReadImageFile's reasons.
TEST(PngReader, RowsReadInPartOfOtherFilesAreWholeAndBadFilesRefused) {
  const fs::path d = test::ScratchDir("png_rows_other");
  const cv::Mat grey = FrameLike(37, 23, CV_8U, 5);
  WriteImageFile(d / "a.pgm", grey, ImageFileFormat::kPgm);
  PngOptions interlaced;
  interlaced.interlace = true;
  WriteBytes(d / "interlaced.png", EncodePng(grey, interlaced));
  for (const char* name : {"a.pgm", "interlaced.png"}) {
    SCOPED_TRACE(name);
    ImageFileRows rows;
    std::string problem;
    ASSERT_TRUE(rows.Read(d / name, {}, &problem)) << problem;
    EXPECT_EQ(rows.rows_ready(), 23u);
    EXPECT_TRUE(SameImage(rows.image(), grey));
    EXPECT_EQ(rows.Prepare({cv::Range(0, 5)}), 0u);
  }
  Bytes png = EncodePng(grey);
  png[png.size() - 20] ^= 1;  // in the IDAT: a wrong CRC
  WriteBytes(d / "bad.png", png);
  ImageFileRows rows;
  std::string problem;
  EXPECT_FALSE(rows.Read(d / "bad.png", {}, &problem));
  EXPECT_TRUE(rows.image().empty());
  EXPECT_EQ(problem, ReadIt(d / "bad.png").problem);
  EXPECT_NE(problem.find((d / "bad.png").string()), std::string::npos) << problem;
  ImageFileOptions o;
  o.expected_size = std::array<int, 2>{40, 23};
  WriteBytes(d / "good.png", EncodePng(grey));
  EXPECT_FALSE(rows.Read(d / "good.png", o, &problem));
  EXPECT_NE(problem.find("but the rig says 40x23"), std::string::npos) << problem;
}

// Colour, bit depths below 8 and interlaced PNGs are the general reader's: the same image
// as cv::imread, through it.
TEST(PngReader, OtherPngsGoToTheGeneralReader) {
  const fs::path d = test::ScratchDir("png_general");
  const cv::Mat grey = FrameLike(37, 23, CV_8U, 5);
  cv::Mat colour;
  cv::merge(std::vector<cv::Mat>{grey, 255 - grey, grey / 2}, colour);
  ASSERT_TRUE(cv::imwrite((d / "colour.png").string(), colour));
  ExpectSameAsOpenCv(d / "colour.png", ImageFileReader::kOpenCv);
  for (const int bits : {1, 2, 4}) {
    PngOptions o;
    o.bit_depth = bits;
    o.filter = [](int y) { return y % 5; };
    const fs::path p = d / ("grey" + std::to_string(bits) + ".png");
    WriteBytes(p, EncodePng(grey, o));
    ExpectSameAsOpenCv(p, ImageFileReader::kOpenCv);
  }
  for (const int depth : {CV_8U, CV_16U}) {
    PngOptions o;
    o.bit_depth = depth == CV_8U ? 8 : 16;
    o.interlace = true;
    o.filter = [](int y) { return (y + 2) % 5; };
    const cv::Mat im = FrameLike(37, 23, depth, 6);
    const fs::path p = d / ("interlaced" + std::to_string(o.bit_depth) + ".png");
    WriteBytes(p, EncodePng(im, o));
    ExpectSameAsOpenCv(p, ImageFileReader::kOpenCv);
    EXPECT_TRUE(SameImage(ReadIt(p).image, im));
  }
}

// The real PNGs of shared/data: every one decoded by our reader, equal to cv::imread.
TEST(PngReader, RealPngsEqualOpenCv) {
  MCMS_REQUIRE_DATA(mire, "visp-mire-sequence");
  MCMS_REQUIRE_DATA(grid, "visp-dot-grid");
  size_t n = 0;
  for (const fs::path& dir : {mire, grid})
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().extension() == ".png") {
        ExpectSameAsOpenCv(e.path(), ImageFileReader::kPng);
        ++n;
      }
  std::printf("real PNGs decoded bit-exact: %zu\n", n);
  EXPECT_GE(n, 500u);
}

// The fuzz seeds and regressions: where both readers decode a file, the same image; where
// ours refuses one, the reason names the file.
TEST(PngReader, FuzzSeedsEqualOpenCvOrAreRefusedWithTheFileNamed) {
  size_t both = 0;
  for (const char* sub : {"corpus", "regressions"}) {
    const fs::path dir = fs::path(MCMS_SOURCE_DIR) / "fuzz" / sub / "png";
    for (const auto& e : fs::directory_iterator(dir)) {
      SCOPED_TRACE(e.path().string());
      const Read r = ReadIt(e.path());
      if (r.image.empty()) {
        EXPECT_NE(r.problem.find(e.path().string()), std::string::npos) << r.problem;
        continue;
      }
      const cv::Mat cv_image = cv::imread(e.path().string(), cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(cv_image.empty());
      EXPECT_TRUE(SameImage(r.image, cv_image));
      ++both;
    }
  }
  EXPECT_GE(both, 4u);
}

// ---- Bad PNGs --------------------------------------------------------------------------

// Offset of the first chunk of `type` in `png`.
size_t ChunkAt(const Bytes& png, const std::string& type) {
  for (size_t p = 8; p + 8 <= png.size();) {
    if (std::string(png.begin() + long(p) + 4, png.begin() + long(p) + 8) == type) return p;
    p += 12 + ((size_t{png[p]} << 24) | (size_t{png[p + 1]} << 16) | (size_t{png[p + 2]} << 8) | png[p + 3]);
  }
  ADD_FAILURE() << "no " << type << " chunk";
  return 0;
}

TEST(PngReader, BadPngsAreRefusedWithTheFileAndTheReason) {
  const fs::path d = test::ScratchDir("png_bad");
  const cv::Mat im = FrameLike(64, 48, CV_8U, 9);
  PngOptions o;
  o.filter = [](int y) { return y % 5; };
  o.idat_size = 700;
  o.after_idat = {{"tEXt", {'a', 0, 'b'}}};
  const Bytes good = EncodePng(im, o);
  const size_t idat = ChunkAt(good, "IDAT"), text = ChunkAt(good, "tEXt"), iend = ChunkAt(good, "IEND");
  const uint32_t raw_size = 48 * 65;

  struct Case {
    std::string name, expect;
    Bytes bytes;
  };
  std::vector<Case> cases;
  auto flipped = [&](size_t at) {
    Bytes b = good;
    b[at] ^= 0x40;
    return b;
  };
  cases.push_back({"crc_idat", "has a wrong CRC", flipped(idat + 8 + 100)});
  cases.push_back({"crc_ancillary", "has a wrong CRC", flipped(text + 8)});
  cases.push_back({"crc_ihdr", "has a wrong CRC", flipped(8 + 8 + 9)});  // the colour type
  for (const size_t cut : {size_t{30}, idat + 300, iend, good.size() - 1})
    cases.push_back({"truncated_" + std::to_string(cut), "truncated PNG", Bytes(good.begin(), good.begin() + long(cut))});
  {  // A zlib bomb: a valid stream of zeros (filter None, black) 200 times the image.
    PngOptions z;
    cases.push_back({"bomb", "inflates to more than the " + std::to_string(raw_size) + " bytes",
                     AssemblePng(Ihdr(64, 48, 8, 0, 0), Deflate(Bytes(200 * raw_size, 0), 9), z)});
    cases.push_back({"short_stream", "inflates to " + std::to_string(raw_size - 65) + " bytes but",
                     AssemblePng(Ihdr(64, 48, 8, 0, 0), Deflate(Bytes(raw_size - 65, 0), 9), z)});
    Bytes bad_filter(raw_size, 0);
    bad_filter[65 * 7] = 5;
    cases.push_back({"bad_filter", "row 7 has filter type 5", AssemblePng(Ihdr(64, 48, 8, 0, 0), Deflate(bad_filter, 9), z)});
    Bytes zlib = Deflate(Bytes(raw_size, 0), 9);
    zlib[zlib.size() - 1] ^= 1;  // the Adler-32 checksum
    cases.push_back({"adler", "wrong Adler-32 checksum", AssemblePng(Ihdr(64, 48, 8, 0, 0), zlib, z)});
    Bytes cut = Deflate(Bytes(raw_size, 0), 0);  // stored blocks, cut in the middle
    cut.resize(cut.size() / 2);
    cases.push_back({"cut_stream", "zlib stream is truncated", AssemblePng(Ihdr(64, 48, 8, 0, 0), cut, z)});
    Bytes garbage = Deflate(Bytes(raw_size, 0), 9);
    garbage[2] = 0xff;  // the first block's header: type 3 is reserved
    cases.push_back({"bad_deflate", "corrupt (bad deflate data)", AssemblePng(Ihdr(64, 48, 8, 0, 0), garbage, z)});
    z.before_idat = {{"CrIt", {1}}};
    cases.push_back({"critical", "unknown critical chunk 'CrIt'", AssemblePng(Ihdr(64, 48, 8, 0, 0), Deflate(Bytes(raw_size, 0), 9), z)});
    Bytes no_idat = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    Chunk(&no_idat, "IHDR", Ihdr(64, 48, 8, 0, 0));
    Chunk(&no_idat, "IEND", {});
    cases.push_back({"no_idat", "no IDAT chunk", no_idat});
    Bytes bad_ihdr = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    Chunk(&bad_ihdr, "IHDR", Ihdr(64, 48, 12, 0, 0));
    Chunk(&bad_ihdr, "IEND", {});
    cases.push_back({"bad_depth", "bit depth 12", bad_ihdr});
  }
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path p = d / (c.name + ".png");
    WriteBytes(p, c.bytes);
    const Read r = ReadIt(p, std::array<int, 2>{64, 48});
    EXPECT_TRUE(r.image.empty());
    EXPECT_NE(r.problem.find(p.string()), std::string::npos) << r.problem;
    EXPECT_NE(r.problem.find(c.expect), std::string::npos) << r.problem;
  }
  // The good one decodes; of another size than the rig's it is not decoded.
  WriteBytes(d / "good.png", good);
  EXPECT_TRUE(SameImage(ReadIt(d / "good.png", std::array<int, 2>{64, 48}).image, im));
  const Read other = ReadIt(d / "good.png", std::array<int, 2>{1280, 1024});
  EXPECT_TRUE(other.image.empty());
  EXPECT_NE(other.problem.find("image " + (d / "good.png").string() + " (PNG) header says 64x48 but the rig says 1280x1024"),
            std::string::npos)
      << other.problem;
}

// ---- PGM and TIFF ------------------------------------------------------------------------

// A big-endian (Motorola) TIFF, one strip, uncompressed: libtiff writes native order.
Bytes BigEndianTiff(const cv::Mat& im) {
  const int bits = im.depth() == CV_8U ? 8 : 16;
  const uint32_t pixels = uint32_t(im.total() * im.elemSize());
  Bytes b = {'M', 'M', 0, 42};
  Put32(&b, 8 + pixels);
  for (int y = 0; y < im.rows; ++y)
    for (int x = 0; x < im.cols; ++x)
      if (bits == 8) {
        b.push_back(im.at<uint8_t>(y, x));
      } else {
        b.push_back(static_cast<unsigned char>(im.at<uint16_t>(y, x) >> 8));
        b.push_back(static_cast<unsigned char>(im.at<uint16_t>(y, x) & 0xff));
      }
  const std::vector<std::array<uint32_t, 3>> tags = {  // tag, type, value
      {256, 4, uint32_t(im.cols)}, {257, 4, uint32_t(im.rows)}, {258, 3, uint32_t(bits)}, {259, 3, 1}, {262, 3, 1},
      {273, 4, 8}, {277, 3, 1}, {278, 4, uint32_t(im.rows)}, {279, 4, pixels}};
  b.push_back(0);
  b.push_back(static_cast<unsigned char>(tags.size()));
  for (const auto& [tag, type, value] : tags) {
    b.push_back(static_cast<unsigned char>(tag >> 8));
    b.push_back(static_cast<unsigned char>(tag & 0xff));
    b.push_back(0);
    b.push_back(static_cast<unsigned char>(type));
    Put32(&b, 1);
    if (type == 3) {
      b.push_back(static_cast<unsigned char>(value >> 8));
      b.push_back(static_cast<unsigned char>(value & 0xff));
      b.push_back(0);
      b.push_back(0);
    } else {
      Put32(&b, value);
    }
  }
  Put32(&b, 0);
  return b;
}

TEST(MappedReader, PgmAndUncompressedTiffEqualOpenCv) {
  const fs::path d = test::ScratchDir("mapped_formats");
  for (const int depth : {CV_8U, CV_16U}) {
    const cv::Mat im = FrameLike(320, 240, depth, 21);
    const std::string b = depth == CV_8U ? "8" : "16";
    WriteImageFile(d / ("a" + b + ".pgm"), im, ImageFileFormat::kPgm);
    ExpectSameAsOpenCv(d / ("a" + b + ".pgm"), depth == CV_8U ? ImageFileReader::kMapped : ImageFileReader::kCopied);
    EXPECT_TRUE(SameImage(ReadIt(d / ("a" + b + ".pgm")).image, im));
    WriteImageFile(d / ("a" + b + ".tif"), im, ImageFileFormat::kTiff);
    ExpectSameAsOpenCv(d / ("a" + b + ".tif"), ImageFileReader::kMapped);
    EXPECT_TRUE(SameImage(ReadIt(d / ("a" + b + ".tif")).image, im));
    WriteBytes(d / ("be" + b + ".tif"), BigEndianTiff(im));
    ExpectSameAsOpenCv(d / ("be" + b + ".tif"), depth == CV_8U ? ImageFileReader::kMapped : ImageFileReader::kCopied);
    // LZW (OpenCV's default TIFF compression) is libtiff's.
    ASSERT_TRUE(cv::imwrite((d / ("lzw" + b + ".tif")).string(), im));
    ExpectSameAsOpenCv(d / ("lzw" + b + ".tif"), ImageFileReader::kLibtiff);
  }
  // PGM headers with comments, and a maxval below the bit depth's (OpenCV keeps the values).
  const cv::Mat small = FrameLike(7, 5, CV_8U, 1);
  for (const std::string head : {"P5\n# a comment\n7 5\n# another\n100\n", "P5 7\t5 255 ", "P5\n7 5\n255\r"}) {
    Bytes b(head.begin(), head.end());
    b.insert(b.end(), small.data, small.data + small.total());
    b.push_back(0);  // a byte beyond the image is ignored
    WriteBytes(d / "head.pgm", b);
    ExpectSameAsOpenCv(d / "head.pgm", ImageFileReader::kMapped);
  }
  {
    const std::string head = "P5\n7 5\n1000\n";
    Bytes b(head.begin(), head.end());
    for (size_t i = 0; i < 35; ++i) b.insert(b.end(), {static_cast<unsigned char>(i), static_cast<unsigned char>(3 * i)});
    WriteBytes(d / "sixteen.pgm", b);
    ExpectSameAsOpenCv(d / "sixteen.pgm", ImageFileReader::kCopied);
  }
  // ASCII PGM is the general reader's.
  {
    std::ofstream(d / "ascii.pgm") << "P2\n2 2\n255\n1 2\n3 4\n";
    ExpectSameAsOpenCv(d / "ascii.pgm", ImageFileReader::kOpenCv);
  }
}

// Damaged TIFFs the mapper does not take: an LZW file cut in half, and an uncompressed one
// whose strips are scattered (so not the mapper's) with one strip's offset beyond the end.
// Each names the file and the strip libtiff could not read, and nothing reaches stderr
// (OpenCV's TIFF decoder would print libtiff's and its own lines there).
TEST(MappedReader, DamagedTiffIsNamedWithoutLibtiffNoise) {
  const fs::path d = test::ScratchDir("damaged_tiff");
  const cv::Mat im = FrameLike(320, 240, CV_8U, 5);
  ASSERT_TRUE(cv::imwrite((d / "lzw.tif").string(), im));
  const Bytes lzw = ReadBytes(d / "lzw.tif");
  // cv::imwrite puts the directory after the pixels: keep the header and directory, drop the
  // second half of the strips.
  Bytes cut = lzw;
  const uint32_t ifd = cut[4] | cut[5] << 8 | cut[6] << 16 | static_cast<uint32_t>(cut[7]) << 24;
  ASSERT_GT(ifd, lzw.size() / 2);
  std::fill(cut.begin() + static_cast<long>(ifd / 2), cut.begin() + static_cast<long>(ifd), 0);
  WriteBytes(d / "cut.tif", cut);
  // Uncompressed little-endian, one row per strip, the rows written backwards (scattered),
  // strip 7's offset beyond the file.
  {
    Bytes b;
    const uint32_t w = 16, h = 12;
    const uint16_t n = 9;
    const size_t ifd_at = 8, offsets_at = ifd_at + 2 + 12 * n + 4, counts_at = offsets_at + 4 * h,
                 pixels_at = counts_at + 4 * h;
    const auto put16 = [&](uint16_t v) {
      b.push_back(static_cast<unsigned char>(v));
      b.push_back(static_cast<unsigned char>(v >> 8));
    };
    const auto put32 = [&](uint32_t v) { for (int k = 0; k < 4; ++k) b.push_back(static_cast<unsigned char>(v >> (8 * k))); };
    put16(0x4949), put16(42), put32(8);  // "II", 42, the directory at byte 8
    const auto tag = [&](uint16_t t, uint16_t type, uint32_t count, uint32_t value) {
      put16(t), put16(type), put32(count);
      if (type == 3 && count == 1) put16(static_cast<uint16_t>(value)), put16(0);
      else put32(value);
    };
    put16(n);
    tag(256, 3, 1, w), tag(257, 3, 1, h), tag(258, 3, 1, 8), tag(259, 3, 1, 1), tag(262, 3, 1, 1);
    tag(273, 4, h, static_cast<uint32_t>(offsets_at)), tag(277, 3, 1, 1), tag(278, 3, 1, 1);
    tag(279, 4, h, static_cast<uint32_t>(counts_at));
    put32(0);
    ASSERT_EQ(b.size(), offsets_at);
    for (uint32_t y = 0; y < h; ++y) put32(y == 7 ? 100000 : static_cast<uint32_t>(pixels_at + (h - 1 - y) * w));
    for (uint32_t y = 0; y < h; ++y) put32(w);
    for (uint32_t k = 0; k < w * h; ++k) b.push_back(static_cast<unsigned char>(k));
    WriteBytes(d / "scattered.tif", b);
  }
  for (const std::string name : {"cut.tif", "scattered.tif"}) {
    SCOPED_TRACE(name);
    testing::internal::CaptureStderr();
    const Read r = ReadIt(d / name);
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_TRUE(r.image.empty());
    EXPECT_NE(r.problem.find("cannot decode " + (d / name).string() + ": row "), std::string::npos) << r.problem;
    EXPECT_EQ(err, "");
  }
  // The same scattered file with strip 7 in place reads, by libtiff, as written.
  {
    Bytes b = ReadBytes(d / "scattered.tif");
    const size_t offsets_at = 8 + 2 + 12 * 9 + 4, pixels_at = offsets_at + 8 * 12;
    const uint32_t at = static_cast<uint32_t>(pixels_at + (12 - 1 - 7) * 16);
    for (int k = 0; k < 4; ++k) b[offsets_at + 4 * 7 + k] = static_cast<unsigned char>(at >> (8 * k));
    WriteBytes(d / "scattered_ok.tif", b);
    ExpectSameAsOpenCv(d / "scattered_ok.tif", ImageFileReader::kLibtiff);
  }
}

TEST(MappedReader, ImageKeepsItsMappingAliveAndNeverWritesTheFile) {
  const fs::path d = test::ScratchDir("mapped_lifetime");
  const cv::Mat im = FrameLike(64, 48, CV_8U, 2);
  WriteImageFile(d / "a.pgm", im, ImageFileFormat::kPgm);
  const Bytes before = ReadBytes(d / "a.pgm");
  cv::Mat shared;
  {
    Read r = ReadIt(d / "a.pgm");
    ASSERT_EQ(r.reader, ImageFileReader::kMapped);
    shared = r.image;  // a second owner; the first goes out of scope
    cv::Mat roi = r.image(cv::Rect(3, 4, 10, 10));
    roi.setTo(cv::Scalar(255));  // writes into the private mapping, not the file
  }
  fs::remove(d / "a.pgm");  // the mapping outlives the file's name
  EXPECT_EQ(shared.at<uint8_t>(5, 5), 255);
  EXPECT_EQ(shared.at<uint8_t>(40, 40), im.at<uint8_t>(40, 40));
  const cv::Mat copy = shared.clone();
  shared.release();
  EXPECT_EQ(copy.at<uint8_t>(40, 40), im.at<uint8_t>(40, 40));
  WriteBytes(d / "b.pgm", before);
  { const Read r = ReadIt(d / "b.pgm"); EXPECT_TRUE(SameImage(r.image, im)); }
  EXPECT_EQ(ReadBytes(d / "b.pgm"), before);
  // create() of another size on a mapped image allocates anew (the mapping is released).
  Read r = ReadIt(d / "b.pgm");
  r.image.create(10, 10, CV_16UC1);
  r.image.setTo(cv::Scalar(7));
  EXPECT_EQ(r.image.at<uint16_t>(9, 9), 7);
}

TEST(MappedReader, TruncatedPgmAndTiffAreRefusedWithTheFile) {
  const fs::path d = test::ScratchDir("mapped_bad");
  const cv::Mat im = FrameLike(64, 48, CV_16U, 4);
  for (const auto& [name, format] : std::vector<std::pair<std::string, ImageFileFormat>>{{"t.pgm", ImageFileFormat::kPgm}}) {
    WriteImageFile(d / name, im, format);
    Bytes b = ReadBytes(d / name);
    b.resize(b.size() - 100);
    WriteBytes(d / name, b);
    const Read r = ReadIt(d / name, std::array<int, 2>{64, 48});
    EXPECT_TRUE(r.image.empty());
    EXPECT_NE(r.problem.find("cannot decode " + (d / name).string() + ": truncated PGM"), std::string::npos) << r.problem;
  }
  {  // maxval 0 (issue 53: told only "cannot decode")
    std::string pgm = "P5\n64 48\n0\n";
    pgm += std::string(64 * 48, '\0');
    test::WriteText(d / "z.pgm", pgm);
    const Read r = ReadIt(d / "z.pgm", std::array<int, 2>{64, 48});
    EXPECT_TRUE(r.image.empty());
    EXPECT_NE(r.problem.find("z.pgm: its PGM header gives maxval 0; expected 1 to 65535"), std::string::npos)
        << r.problem;
  }
  {  // a TIFF whose strip runs past the end of the file
    Bytes b = BigEndianTiff(im);
    const Bytes tail(b.begin() + 8 + long(im.total() * 2), b.end());
    b.resize(8 + 1000);
    b[4] = 0, b[5] = 0, b[6] = static_cast<unsigned char>((8 + 1000) >> 8), b[7] = static_cast<unsigned char>((8 + 1000) & 0xff);
    b.insert(b.end(), tail.begin(), tail.end());
    WriteBytes(d / "t.tif", b);
    const Read r = ReadIt(d / "t.tif", std::array<int, 2>{64, 48});
    EXPECT_TRUE(r.image.empty());
    EXPECT_NE(r.problem.find("cannot decode " + (d / "t.tif").string() + ": truncated TIFF"), std::string::npos) << r.problem;
  }
}

TEST(ImageFileFormat, ParsesAndRefusesNames) {
  EXPECT_EQ(ParseImageFileFormat("png", "x"), ImageFileFormat::kPng);
  EXPECT_EQ(ParseImageFileFormat("pgm", "x"), ImageFileFormat::kPgm);
  EXPECT_EQ(ParseImageFileFormat("tif", "x"), ImageFileFormat::kTiff);
  EXPECT_EQ(ParseImageFileFormat("tiff", "x"), ImageFileFormat::kTiff);
  EXPECT_NE(test::ErrorOf([] { ParseImageFileFormat("jpeg", "render --format"); })
                .find("render --format: unknown image format 'jpeg'; expected png, pgm or tiff"),
            std::string::npos);
  const fs::path d = test::ScratchDir("image_file_write");
  EXPECT_NE(test::ErrorOf([&] { WriteImageFile(d / "x.png", cv::Mat(4, 4, CV_32F), ImageFileFormat::kPng); })
                .find("expected an 8- or 16-bit grey image"),
            std::string::npos);
}

}  // namespace
}  // namespace mcms
