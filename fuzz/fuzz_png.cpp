// A camera frame as `mcms track` reads it (tracking/sequence.h LoadFrameImages, through
// vision/image_file.h ReadImageFile): the header check, then our PNG decoder, the mapped
// PGM/TIFF reader, or OpenCV's decoder. Problems are reported per frame, not thrown, so
// the outcome is an image or a reason naming the file; an image must have the size the
// rig expects. And a differential check: an image our own readers decode must equal
// cv::imread(IMREAD_UNCHANGED)'s bit for bit whenever OpenCV decodes the file too, and the
// file read in part (ImageFileRows, the tracker's reader with predicted windows) gives the
// same rows.
//
// Every input runs twice: as it is, and with its checksums made right (each PNG chunk's
// CRC, the zlib stream's Adler-32), so that mutations reach the inflate and the
// unfiltering rather than stopping at the first checksum.
#include <zlib.h>

#include <opencv2/imgcodecs.hpp>

#include <cstring>
#include <string>
#include <vector>

#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "tracking/sequence.h"
#include "vision/image_file.h"

namespace mcms::fuzz {

namespace {

uint32_t Be32(const uint8_t* p) { return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | p[3]; }
void PutBe32(uint8_t* p, uint32_t v) {
  for (int k = 0; k < 4; ++k) p[k] = static_cast<uint8_t>(v >> (24 - 8 * k));
}

std::vector<uint8_t> WithChecksumsRepaired(const uint8_t* data, size_t size) {
  std::vector<uint8_t> b(data, data + size);
  static const uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (size < 8 || std::memcmp(data, kSignature, 8) != 0) return b;
  struct Chunk {
    size_t pos;
    uint32_t length;
  };
  std::vector<Chunk> chunks, idats;
  uint64_t raw_size = 0;
  for (size_t pos = 8; pos + 12 <= size;) {
    const uint32_t length = Be32(&b[pos]);
    if (length > size - pos - 12) break;
    chunks.push_back({pos, length});
    if (std::memcmp(&b[pos + 4], "IHDR", 4) == 0 && length == 13) {
      const uint64_t w = Be32(&b[pos + 8]), h = Be32(&b[pos + 12]), depth = b[pos + 16];
      raw_size = h * ((w * depth + 7) / 8 + 1);
    }
    if (std::memcmp(&b[pos + 4], "IDAT", 4) == 0) idats.push_back({pos, length});
    pos += 12 + length;
  }
  // The Adler-32 of what the deflate stream (after the zlib header) inflates to, written
  // after its end; only for streams that inflate within the header's size (and 4 MB).
  std::vector<uint8_t> stream;
  for (const Chunk& c : idats) stream.insert(stream.end(), b.begin() + long(c.pos + 8), b.begin() + long(c.pos + 8 + c.length));
  if (stream.size() > 2 && raw_size > 0 && raw_size <= (uint64_t{1} << 22)) {
    std::vector<uint8_t> out(raw_size);
    z_stream z{};
    size_t in_used = 0, out_size = 0;
    bool ok = inflateInit2(&z, -15) == Z_OK;  // the raw deflate stream: no header, no checksum
    if (ok) {
      z.next_in = stream.data() + 2;
      z.avail_in = static_cast<uInt>(stream.size() - 2);
      z.next_out = out.data();
      z.avail_out = static_cast<uInt>(out.size());
      ok = inflate(&z, Z_FINISH) == Z_STREAM_END;
      in_used = z.total_in;
      out_size = z.total_out;
      inflateEnd(&z);
    }
    if (ok && 2 + in_used + 4 <= stream.size()) {
      uint8_t adler[4];
      PutBe32(adler, static_cast<uint32_t>(adler32(1, out.data(), static_cast<uInt>(out_size))));
      size_t at = 2 + in_used, offset = 0;  // stream offset -> file position, across the IDATs
      for (const Chunk& c : idats) {
        for (int k = 0; k < 4; ++k)
          if (at + k >= offset && at + k < offset + c.length) b[c.pos + 8 + (at + k - offset)] = adler[k];
        offset += c.length;
      }
    }
  }
  for (const Chunk& c : chunks)
    PutBe32(&b[c.pos + 8 + c.length], static_cast<uint32_t>(crc32(0, &b[c.pos + 4], 4 + c.length)));
  return b;
}

// The same file read in part (ImageFileRows, as the tracker reads frames for predicted
// windows): rows picked from the input's last bytes, then every row. The rows asked for
// equal ReadImageFile's; any other row is either equal too (a row they depend on) or zero.
void CheckRows(const std::filesystem::path& path, const cv::Mat& whole, const uint8_t* data, size_t size) {
  ImageFileRows rows;
  std::string problem;
  if (!rows.Read(path, {}, &problem))
    throw std::logic_error("ImageFileRows::Read refuses " + path.string() + ", which ReadImageFile decodes: " + problem);
  const int h = whole.rows;
  auto byte = [&](size_t k) { return size > k ? int{data[size - 1 - k]} : 0; };
  const std::vector<cv::Range> asked = {cv::Range(byte(0) % h, byte(0) % h + 1 + byte(1) % 8),
                                        cv::Range(h - 1 - byte(2) % h, h), cv::Range(-3, byte(3) % 4)};
  rows.Prepare(asked);
  const cv::Mat& part = rows.image();
  if (part.size() != whole.size() || part.type() != whole.type())
    throw std::logic_error("ImageFileRows: another size or type than ReadImageFile's for " + path.string());
  for (int y = 0; y < h; ++y) {
    bool wanted = false;
    for (const cv::Range& r : asked) wanted = wanted || (y >= r.start && y < r.end);
    const bool same = cv::norm(part.row(y), whole.row(y), cv::NORM_INF) == 0;
    if (!same && (wanted || cv::countNonZero(part.row(y)) != 0))
      throw std::logic_error("ImageFileRows: row " + std::to_string(y) + " of " + path.string() +
                             (wanted ? " was asked for but differs from ReadImageFile's" : " is neither prepared nor zero"));
  }
  rows.PrepareAll();
  if (rows.rows_ready() != static_cast<size_t>(h) || cv::norm(rows.image(), whole, cv::NORM_INF) != 0)
    throw std::logic_error("ImageFileRows: every row prepared differs from ReadImageFile's image of " + path.string());
}

void Check(const uint8_t* data, size_t size) {
  const auto path = WriteInput(data, size, ".png");
  // Once with the rig's size (the seeds are 64 x 48) and once unchecked.
  for (const bool check_size : {true, false}) {
    ImageSequence seq;
    seq.frames = {0};
    seq.times_s = {0.0};
    seq.camera_dirs = {path.parent_path()};
    seq.image_names = {path.filename().string()};
    if (check_size) seq.image_sizes = {{64, 48}};
    std::vector<std::string> problems;
    ExpectInputError(path.string(), [&] {
      const std::vector<cv::Mat> im = LoadFrameImages(seq, 0, &problems);
      if (im.size() != 1) throw std::logic_error("LoadFrameImages: expected one image per camera");
      if (im[0].empty() && (problems.size() != 1 || problems[0].find(path.string()) == std::string::npos))
        throw std::logic_error("LoadFrameImages: an empty image without a reason naming the file");
      if (check_size && !im[0].empty() && (im[0].cols != 64 || im[0].rows != 48))
        throw std::logic_error("LoadFrameImages: an image of another size than the rig's");
    });
  }
  std::string problem;
  ImageFileReader reader = ImageFileReader::kOpenCv;
  const cv::Mat ours = ReadImageFile(path, {}, &problem, &reader);
  if (ours.empty() || reader == ImageFileReader::kOpenCv) return;
  CheckRows(path, ours, data, size);
  // Only formats whose header our reader checked reach OpenCV here (PNG, PGM, TIFF).
  cv::Mat theirs;
  try {
    theirs = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    return;  // OpenCV refuses a file our reader takes (libpng's own limits): no comparison
  }
  if (theirs.empty()) return;
  if (theirs.size() != ours.size() || theirs.type() != ours.type() || cv::norm(theirs, ours, cv::NORM_INF) != 0)
    throw std::logic_error(std::string("ReadImageFile (") + ToString(reader) + ") decodes " + path.string() +
                           " differently from cv::imread");
}

}  // namespace

int FuzzPng(const uint8_t* data, size_t size) {
  Check(data, size);
  const std::vector<uint8_t> repaired = WithChecksumsRepaired(data, size);
  if (repaired.size() == size && (size == 0 || std::memcmp(repaired.data(), data, size) != 0))
    Check(repaired.data(), repaired.size());
  return 0;
}

}  // namespace mcms::fuzz
