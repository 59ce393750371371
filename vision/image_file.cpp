#include "vision/image_file.h"
#include "vision/image_file_internal.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <isa-l/crc.h>
#include <isa-l/igzip_lib.h>

#include <algorithm>
#include <cctype>
#include <cstdarg>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <tiffio.h>
#include <zlib.h>

#include "core/error.h"

namespace mcms {

namespace fs = std::filesystem;

uint32_t image_file_internal::Be32(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

void image_file_internal::SwapBytes16(const unsigned char* src, unsigned char* dst, size_t samples) {
  for (size_t i = 0; i < samples; ++i) {
    const unsigned char hi = src[2 * i], lo = src[2 * i + 1];
    dst[2 * i] = lo;
    dst[2 * i + 1] = hi;
  }
}

using image_file_internal::Be32;
using image_file_internal::SwapBytes16;
using image_file_internal::ReadFrame;

namespace {

// ---------------------------------------------------------------------------------------
// Files: opened once, read whole or mapped.

struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

// The whole file into *bytes (resized to its length); false with errno's reason otherwise.
bool ReadWholeFile(const fs::path& p, std::vector<unsigned char>* bytes, std::string* why) {
  Fd f{::open(p.c_str(), O_RDONLY | O_CLOEXEC)};
  struct stat st;
  if (f.fd < 0 || ::fstat(f.fd, &st) != 0) {
    *why = std::strerror(errno);
    return false;
  }
  // A frame file is far smaller than this; a larger one (or a device) is not read whole.
  if (!S_ISREG(st.st_mode) || st.st_size > (int64_t{1} << 30)) {
    *why = "not a regular file of at most 1 GB";
    return false;
  }
  bytes->resize(static_cast<size_t>(st.st_size));
  size_t done = 0;
  while (done < bytes->size()) {
    const ssize_t r = ::read(f.fd, bytes->data() + done, bytes->size() - done);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      *why = std::strerror(errno);
      return false;
    }
    if (r == 0) break;  // shrank since fstat
    done += static_cast<size_t>(r);
  }
  bytes->resize(done);
  return true;
}

// A read-only file mapping (private, so that a caller writing into the image gets its own
// copy of the page and the file is never changed). The mapping's pages are the file's
// page-cache pages: no copy.
struct Mapping {
  unsigned char* base = nullptr;
  size_t length = 0;
};

bool MapFile(const fs::path& p, Mapping* m, std::string* why) {
  Fd f{::open(p.c_str(), O_RDONLY | O_CLOEXEC)};
  struct stat st;
  if (f.fd < 0 || ::fstat(f.fd, &st) != 0) {
    *why = std::strerror(errno);
    return false;
  }
  if (!S_ISREG(st.st_mode) || st.st_size <= 0) {
    *why = "not a regular, non-empty file";
    return false;
  }
  void* a = ::mmap(nullptr, static_cast<size_t>(st.st_size), PROT_READ | PROT_WRITE, MAP_PRIVATE, f.fd, 0);
  if (a == MAP_FAILED) {
    *why = std::string("cannot map it: ") + std::strerror(errno);
    return false;
  }
  m->base = static_cast<unsigned char*>(a);
  m->length = static_cast<size_t>(st.st_size);
  // Every page mapped (readable, copy-on-write) in one call rather than one fault per 64 KB
  // as the pixels are first read: about a third less time. Kernels before 5.14 lack it.
#ifdef MADV_POPULATE_READ
  ::madvise(a, m->length, MADV_POPULATE_READ);
#endif
  return true;
}

// Owns a file mapping for cv::Mat: the Mat's UMatData holds the mapping (origdata, size)
// and its reference count; when the last Mat sharing it is released, OpenCV calls unmap()
// then deallocate() here, which unmaps the file. It never allocates: a Mat that is
// create()d anew takes the default allocator (the Mat's own `allocator` stays null).
class MappedFileAllocator : public cv::MatAllocator {
 public:
  cv::UMatData* allocate(int, const int*, int, void*, size_t*, cv::AccessFlag, cv::UMatUsageFlags) const override {
    return nullptr;
  }
  bool allocate(cv::UMatData*, cv::AccessFlag, cv::UMatUsageFlags) const override { return false; }
  void deallocate(cv::UMatData* u) const override {
    if (!u) return;
    ::munmap(u->origdata, u->size);
    delete u;
  }
};

const MappedFileAllocator& TheMappedFileAllocator() {
  static const MappedFileAllocator* a = new MappedFileAllocator;  // outlives every Mat (never destroyed)
  return *a;
}

// A Mat of `rows` x `cols` of `type` over m.base + offset (row stride = cols x element size),
// owning the mapping.
cv::Mat MatOverMapping(const Mapping& m, size_t offset, int rows, int cols, int type) {
  cv::Mat im(rows, cols, type, m.base + offset);
  cv::UMatData* u = new cv::UMatData(&TheMappedFileAllocator());
  u->data = u->origdata = m.base;
  u->size = m.length;
  u->refcount = 1;
  im.u = u;
  return im;
}


// ---------------------------------------------------------------------------------------
// The header sniffer.

std::optional<ImageFileHeader> SniffHeader(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<unsigned char> h(4096);
  in.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()));
  h.resize(static_cast<size_t>(in.gcount()));
  const size_t n = h.size();
  auto le = [&](size_t o, int bytes) {
    uint32_t v = 0;
    for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | h[o + i];
    return v;
  };
  auto size_of = [](int64_t w, int64_t hh) -> std::optional<std::array<int, 2>> {
    if (w > 0x7fffffff || hh > 0x7fffffff || w < 0 || hh < 0) return std::array<int, 2>{-1, -1};
    return std::array<int, 2>{static_cast<int>(w), static_cast<int>(hh)};
  };
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n >= 8 && std::equal(kPng, kPng + 8, h.begin())) {
    ImageFileHeader r{"PNG", std::nullopt};
    if (n >= 24 && std::string(reinterpret_cast<const char*>(&h[12]), 4) == "IHDR") r.size = size_of(Be32(&h[16]), Be32(&h[20]));
    return r;
  }
  if (n >= 2 && h[0] == 'P' && h[1] >= '1' && h[1] <= '6') {  // PNM: "P5 <w> <h> ..." with # comments
    ImageFileHeader r{"PNM", std::nullopt};
    int64_t v[2] = {-1, -1};
    size_t i = 2;
    for (int k = 0; k < 2; ++k) {
      while (i < n && (std::isspace(h[i]) || h[i] == '#')) {
        if (h[i] == '#')
          while (i < n && h[i] != '\n') ++i;
        else
          ++i;
      }
      if (i >= n || !std::isdigit(h[i])) return r;
      v[k] = 0;
      while (i < n && std::isdigit(h[i]) && v[k] < (int64_t{1} << 40)) v[k] = 10 * v[k] + (h[i++] - '0');
    }
    r.size = size_of(v[0], v[1]);
    return r;
  }
  const bool tiff_le = n >= 4 && h[0] == 'I' && h[1] == 'I' && h[2] == 42 && h[3] == 0;
  const bool tiff_be = n >= 4 && h[0] == 'M' && h[1] == 'M' && h[2] == 0 && h[3] == 42;
  if (tiff_le || tiff_be) {  // the first IFD's ImageWidth (256) and ImageLength (257), wherever it is
    ImageFileHeader r{"TIFF", std::nullopt};
    auto rd = [&](const unsigned char* b, int bytes) {
      uint32_t v = 0;
      for (int i = 0; i < bytes; ++i) v = tiff_le ? v | (uint32_t{b[i]} << (8 * i)) : (v << 8) | b[i];
      return v;
    };
    if (n < 8) return r;
    std::ifstream f(p, std::ios::binary);
    unsigned char c[2];
    f.seekg(rd(&h[4], 4));
    if (!f.read(reinterpret_cast<char*>(c), 2)) return r;
    int64_t wh[2] = {-1, -1};
    const uint32_t count = rd(c, 2);
    for (uint32_t e = 0; e < count; ++e) {
      unsigned char t[12];
      if (!f.read(reinterpret_cast<char*>(t), 12)) return r;
      const uint32_t tag = rd(t, 2), type = rd(t + 2, 2);
      if (tag == 256 || tag == 257) wh[tag - 256] = type == 3 ? rd(t + 8, 2) : type == 4 ? rd(t + 8, 4) : -1;
    }
    if (wh[0] >= 0 && wh[1] >= 0) r.size = size_of(wh[0], wh[1]);
    return r;
  }
  if (n >= 3 && h[0] == 0xff && h[1] == 0xd8 && h[2] == 0xff) {  // JPEG: the first SOFn segment
    ImageFileHeader r{"JPEG", std::nullopt};
    std::ifstream f(p, std::ios::binary);
    f.seekg(2);
    for (int segments = 0; segments < 1000; ++segments) {
      unsigned char m[2];
      if (!f.read(reinterpret_cast<char*>(m), 2) || m[0] != 0xff) return r;
      while (m[1] == 0xff)  // fill bytes
        if (!f.read(reinterpret_cast<char*>(m + 1), 1)) return r;
      const unsigned char marker = m[1];
      if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd7)) continue;  // no length field
      unsigned char l[2];
      if (!f.read(reinterpret_cast<char*>(l), 2)) return r;
      const int len = (l[0] << 8) | l[1];
      if (len < 2) return r;
      // SOF0..SOF15 except DHT (c4), JPG (c8), DAC (cc): precision, height, width.
      if (marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc) {
        unsigned char sof[5];
        if (!f.read(reinterpret_cast<char*>(sof), 5)) return r;
        r.size = size_of((sof[3] << 8) | sof[4], (sof[1] << 8) | sof[2]);
        return r;
      }
      if (marker == 0xd9 || marker == 0xda) return r;  // end of image / scan before any frame header
      f.seekg(len - 2, std::ios::cur);
    }
    return r;
  }
  if (n >= 26 && h[0] == 'B' && h[1] == 'M') {  // BMP: the DIB header's width and height
    ImageFileHeader r{"BMP", std::nullopt};
    const uint32_t dib = le(14, 4);
    if (dib == 12) {
      r.size = size_of(le(18, 2), le(20, 2));
    } else {
      const int64_t w = static_cast<int32_t>(le(18, 4)), hh = static_cast<int32_t>(le(22, 4));
      r.size = size_of(w, hh < 0 ? -hh : hh);
    }
    return r;
  }
  if (n >= 2 && h[0] == 'B' && h[1] == 'M') return ImageFileHeader{"BMP", std::nullopt};
  return std::nullopt;
}

}  // namespace

namespace {

// ---------------------------------------------------------------------------------------
// Binary PGM and uncompressed TIFF, mapped.

enum class Mapped { kImage, kNotHandled, kFailed };

// Binary PGM (P5) as OpenCV's PxM decoder reads it: the header is "P5", then width, height
// and maxval, each after white space and # comments, then exactly one byte (white space)
// and the pixels: maxval < 256 is 8-bit (the bytes as they are), otherwise 16-bit
// big-endian. Pixel bytes beyond the image are ignored; fewer is a truncated file.
Mapped MapPgm(const Mapping& m, const std::string& name, cv::Mat* image, bool* copied, std::string* problem) {
  const unsigned char* h = m.base;
  const size_t n = m.length;
  if (n < 3 || h[0] != 'P' || h[1] != '5' || !std::isspace(h[2])) return Mapped::kNotHandled;
  size_t i = 2;
  int64_t v[3] = {0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    while (i < n && !std::isdigit(h[i])) {
      if (h[i] == '#') {
        while (i < n && h[i] != '\n' && h[i] != '\r') ++i;
        if (i < n) ++i;
      } else if (std::isspace(h[i])) {
        ++i;
      } else {
        return Mapped::kNotHandled;  // OpenCV's own message for a malformed header
      }
    }
    if (i >= n) return Mapped::kNotHandled;
    while (i < n && std::isdigit(h[i]) && v[k] <= 0x7fffffff) v[k] = 10 * v[k] + (h[i++] - '0');
    if (v[k] > 0x7fffffff) return Mapped::kNotHandled;
    if (i >= n) return Mapped::kNotHandled;
    ++i;  // the one byte after the number
  }
  const int64_t w = v[0], hh = v[1], maxval = v[2];
  if (w > 0 && hh > 0 && (maxval <= 0 || maxval > 65535)) {  // issue 53: told only "cannot decode"
    *problem = "cannot decode " + name + ": its PGM header gives maxval " + std::to_string(maxval) +
               "; expected 1 to 65535 (the brightest value a pixel may have)";
    return Mapped::kFailed;
  }
  if (w <= 0 || hh <= 0) return Mapped::kNotHandled;
  const int bytes = maxval < 256 ? 1 : 2;
  const size_t need = static_cast<size_t>(w) * static_cast<size_t>(hh) * bytes;
  if (n - i < need) {
    *problem = "cannot decode " + name + ": truncated PGM: " + std::to_string(w) + "x" + std::to_string(hh) + " " +
               std::to_string(8 * bytes) + "-bit pixels need " + std::to_string(need) + " bytes after the header, the file has " +
               std::to_string(n - i);
    return Mapped::kFailed;
  }
  if (bytes == 1) {
    *image = MatOverMapping(m, i, static_cast<int>(hh), static_cast<int>(w), CV_8UC1);
    *copied = false;
  } else {
    cv::Mat im(static_cast<int>(hh), static_cast<int>(w), CV_16UC1);
    SwapBytes16(m.base + i, im.data, static_cast<size_t>(w) * static_cast<size_t>(hh));
    *image = im;
    *copied = true;
  }
  return Mapped::kImage;
}

// An uncompressed, single-sample, 8- or 16-bit TIFF whose first image (IFD) stores its
// rows as one contiguous run of strips; anything else is OpenCV's.
Mapped MapTiff(const Mapping& m, const std::string& name, cv::Mat* image, bool* copied, std::string* problem) {
  const unsigned char* b = m.base;
  const size_t n = m.length;
  if (n < 8) return Mapped::kNotHandled;
  const bool little = b[0] == 'I';
  auto rd = [&](size_t o, int bytes) -> uint32_t {
    uint32_t v = 0;
    for (int i = 0; i < bytes; ++i) v = little ? v | (uint32_t{b[o + i]} << (8 * i)) : (v << 8) | b[o + i];
    return v;
  };
  const size_t ifd = rd(4, 4);
  if (ifd < 8 || ifd > n - 2) return Mapped::kNotHandled;
  const size_t count = rd(ifd, 2);
  if (count == 0 || (n - ifd - 2) / 12 < count) return Mapped::kNotHandled;
  // One tag's values: (type size, count, where); nullopt when absent or out of the file.
  struct Field {
    int size = 0;
    size_t count = 0, where = 0;
  };
  auto field = [&](uint32_t tag) -> std::optional<Field> {
    for (size_t e = 0; e < count; ++e) {
      const size_t o = ifd + 2 + 12 * e;
      if (rd(o, 2) != tag) continue;
      const uint32_t type = rd(o + 2, 2);
      const int size = type == 3 ? 2 : type == 4 ? 4 : 0;  // SHORT or LONG only
      if (size == 0) return std::nullopt;
      Field f{size, rd(o + 4, 4), o + 8};
      if (f.count == 0 || f.count > n) return std::nullopt;
      if (f.count * size > 4) {
        f.where = rd(o + 8, 4);
        if (f.where > n || (n - f.where) / size < f.count) return std::nullopt;
      }
      return f;
    }
    return std::nullopt;
  };
  auto value = [&](const Field& f, size_t k) { return rd(f.where + k * f.size, f.size); };
  // A tag with one value; `otherwise` when absent (its TIFF default); -1 when malformed.
  auto single = [&](uint32_t tag, int64_t otherwise) -> int64_t {
    bool present = false;
    for (size_t e = 0; e < count; ++e) present = present || rd(ifd + 2 + 12 * e, 2) == tag;
    if (!present) return otherwise;
    const auto f = field(tag);
    if (!f || f->count != 1) return -1;
    return value(*f, 0);
  };
  const int64_t w = single(256, -1), hh = single(257, -1), bits = single(258, 1), compression = single(259, 1),
                photometric = single(262, -1), samples = single(277, 1), planar = single(284, 1),
                fill_order = single(266, 1), orientation = single(274, 1), sample_format = single(339, 1),
                rows_per_strip = single(278, 0xffffffff);
  bool tiled = false;
  for (size_t e = 0; e < count; ++e) tiled = tiled || rd(ifd + 2 + 12 * e, 2) == 322;
  if (w <= 0 || hh <= 0 || (bits != 8 && bits != 16) || compression != 1 || photometric != 1 || samples != 1 ||
      planar != 1 || fill_order != 1 || orientation != 1 || sample_format != 1 || rows_per_strip <= 0 || tiled)
    return Mapped::kNotHandled;
  const auto offsets = field(273), counts = field(279);
  if (!offsets || !counts || offsets->count != counts->count) return Mapped::kNotHandled;
  const size_t bytes = static_cast<size_t>(bits / 8);
  const size_t stride = static_cast<size_t>(w) * bytes;
  const size_t strip_rows = static_cast<size_t>(std::min<int64_t>(rows_per_strip, hh));
  const size_t strips = (static_cast<size_t>(hh) + strip_rows - 1) / strip_rows;
  if (offsets->count != strips) return Mapped::kNotHandled;
  const size_t start = value(*offsets, 0);
  size_t next = start;
  for (size_t s = 0; s < strips; ++s) {
    const size_t rows = std::min(strip_rows, static_cast<size_t>(hh) - s * strip_rows);
    if (value(*offsets, s) != next || value(*counts, s) != rows * stride) return Mapped::kNotHandled;
    next += rows * stride;
  }
  if (start > n || n - start < stride * static_cast<size_t>(hh)) {
    *problem = "cannot decode " + name + ": truncated TIFF: its " + std::to_string(w) + "x" + std::to_string(hh) +
               " pixels at byte " + std::to_string(start) + " need " + std::to_string(stride * static_cast<size_t>(hh)) +
               " bytes, the file has " + std::to_string(n) + " in all";
    return Mapped::kFailed;
  }
  if (bytes == 1 || little) {
    *image = MatOverMapping(m, start, static_cast<int>(hh), static_cast<int>(w), bytes == 1 ? CV_8UC1 : CV_16UC1);
    *copied = false;
  } else {
    cv::Mat im(static_cast<int>(hh), static_cast<int>(w), CV_16UC1);
    SwapBytes16(m.base + start, im.data, static_cast<size_t>(w) * static_cast<size_t>(hh));
    *image = im;
    *copied = true;
  }
  return Mapped::kImage;
}

}  // namespace

std::optional<ImageFileHeader> ReadImageFileHeader(const fs::path& path) { return SniffHeader(path); }

const char* ToString(ImageFileReader r) {
  switch (r) {
    case ImageFileReader::kPng: return "png";
    case ImageFileReader::kMapped: return "mapped";
    case ImageFileReader::kCopied: return "copied";
    case ImageFileReader::kLibtiff: return "libtiff";
    case ImageFileReader::kOpenCv: return "opencv";
  }
  return "?";
}

namespace {

// Any TIFF the mapper does not take (compressed, scattered strips, tiles): read by libtiff
// with its messages kept per file (OpenCV's TIFF decoder prints a damaged file's details
// to stderr itself: "failed TIFFReadRGBAStrip", "imread_(...): can't read data"). A grey
// 8- or 16-bit image is decoded here; any other layout only checked (every strip or tile
// read), then decoded by OpenCV, which now cannot fail on it. Returns false with *problem
// naming the file and libtiff's first error.
bool ReadTiffWithLibtiff(const fs::path& p, cv::Mat* image, std::string* problem) {
  struct Messages {
    std::string first_error;
  } messages;
  const auto on_error = [](TIFF*, void* user, const char* module, const char* fmt, va_list ap) -> int {
    auto* m = static_cast<Messages*>(user);
    if (m->first_error.empty()) {
      char buf[512];
      std::vsnprintf(buf, sizeof buf, fmt, ap);
      m->first_error = (module && *module ? std::string(module) + ": " : std::string()) + buf;
    }
    return 1;
  };
  const auto on_warning = [](TIFF*, void*, const char*, const char*, va_list) -> int { return 1; };
  TIFFOpenOptions* opts = TIFFOpenOptionsAlloc();
  TIFFOpenOptionsSetErrorHandlerExtR(opts, on_error, &messages);
  TIFFOpenOptionsSetWarningHandlerExtR(opts, on_warning, &messages);
  TIFF* t = TIFFOpenExt(p.c_str(), "r", opts);
  TIFFOpenOptionsFree(opts);
  const auto fail = [&](const std::string& what) {
    *problem = "cannot decode " + p.string() + ": " + what +
               (messages.first_error.empty() ? std::string() : " (" + messages.first_error + ")");
    return false;
  };
  if (!t) return fail("not a readable TIFF");
  std::unique_ptr<TIFF, void (*)(TIFF*)> close(t, TIFFClose);
  uint32_t w = 0, h = 0;
  uint16_t bits = 1, samples = 1, format = SAMPLEFORMAT_UINT;
  TIFFGetField(t, TIFFTAG_IMAGEWIDTH, &w);
  TIFFGetField(t, TIFFTAG_IMAGELENGTH, &h);
  TIFFGetFieldDefaulted(t, TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLESPERPIXEL, &samples);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLEFORMAT, &format);
  if (w == 0 || h == 0) return fail("its TIFF directory gives no image size");
  if (samples == 1 && (bits == 8 || bits == 16) && format == SAMPLEFORMAT_UINT && !TIFFIsTiled(t)) {
    cv::Mat im(static_cast<int>(h), static_cast<int>(w), bits == 8 ? CV_8UC1 : CV_16UC1);
    if (TIFFScanlineSize64(t) != static_cast<uint64_t>(im.step[0]))
      return fail("its rows are not packed as " + std::to_string(bits) + "-bit grey samples");
    for (uint32_t y = 0; y < h; ++y)
      if (TIFFReadScanline(t, im.ptr(static_cast<int>(y)), y, 0) < 0)
        return fail("row " + std::to_string(y) + " of " + std::to_string(h) + " cannot be read");
    *image = im;
    return true;
  }
  const bool tiled = TIFFIsTiled(t);
  const uint32_t pieces = tiled ? TIFFNumberOfTiles(t) : TIFFNumberOfStrips(t);
  std::vector<unsigned char> buf(static_cast<size_t>(tiled ? TIFFTileSize64(t) : TIFFStripSize64(t)));
  for (uint32_t k = 0; k < pieces; ++k) {
    const tmsize_t got = tiled ? TIFFReadEncodedTile(t, k, buf.data(), static_cast<tmsize_t>(buf.size()))
                               : TIFFReadEncodedStrip(t, k, buf.data(), static_cast<tmsize_t>(buf.size()));
    if (got < 0)
      return fail(std::string(tiled ? "tile " : "strip ").append(std::to_string(k)).append(" of ").append(
          std::to_string(pieces)).append(" cannot be read"));
  }
  return true;  // readable; OpenCV decodes its layout
}

}  // namespace

cv::Mat image_file_internal::ReadFrame(const fs::path& p, const ImageFileOptions& options, std::string* problem,
                                       ImageFileReader* reader, ImageFileRows* rows) {
  problem->clear();
  if (std::string why; !options.IsValid(&why)) Throw("image file options: ", why);
  {
    // A link that does not resolve (a loop, a missing target): named with the system's reason.
    std::error_code ec;
    if (!fs::exists(p, ec)) {
      *problem = "cannot read " + p.string() + ": " + (ec ? ec.message() : std::string("no such file"));
      return {};
    }
  }
  const auto header = SniffHeader(p);
  if (!header) {
    *problem = "cannot decode " + p.string() + ": not a PNG/PGM/TIFF/JPEG/BMP file by its first bytes";
    return {};
  }
  if (!header->size) {
    *problem = "cannot decode " + p.string() + ": its " + header->format + " header is truncated or malformed";
    return {};
  }
  const auto& hs = *header->size;
  const auto& expected = options.expected_size;
  const bool absurd = hs[0] <= 0 || hs[1] <= 0 || double(hs[0]) * double(hs[1]) > kMaxImageFilePixels;
  if ((expected && hs != *expected) || absurd) {
    std::ostringstream s;
    s << "image " << p.string() << " (" << header->format << ") header says " << hs[0] << "x" << hs[1];
    if (expected) s << " but the rig says " << (*expected)[0] << "x" << (*expected)[1];
    s << "; not decoded";
    *problem = s.str();
    return {};
  }
  cv::Mat im;
  if (!options.opencv_only && header->format == "PNG") {
    thread_local std::vector<unsigned char> bytes;
    std::string why;
    if (!ReadWholeFile(p, &bytes, &why)) {
      *problem = "cannot read " + p.string() + ": " + why;
      return {};
    }
    if (rows) {
      if (!rows->DecodePng(&bytes, p.string(), kMaxImageFilePixels, problem)) return {};
      im = rows->image();
    } else if (!DecodePng(&bytes, p.string(), kMaxImageFilePixels, &im, problem)) {
      return {};
    }
    if (!im.empty() && reader) *reader = ImageFileReader::kPng;
  } else if (!options.opencv_only && (header->format == "PNM" || header->format == "TIFF")) {
    Mapping m;
    std::string why;
    if (!MapFile(p, &m, &why)) {
      *problem = "cannot read " + p.string() + ": " + why;
      return {};
    }
    bool copied = false;
    const Mapped got = header->format == "PNM" ? MapPgm(m, p.string(), &im, &copied, problem)
                                                 : MapTiff(m, p.string(), &im, &copied, problem);
    if (got != Mapped::kImage || copied) ::munmap(m.base, m.length);  // otherwise the image owns the mapping
    if (got == Mapped::kFailed) return {};
    if (got == Mapped::kImage && reader) *reader = copied ? ImageFileReader::kCopied : ImageFileReader::kMapped;
  }
  if (im.empty() && !options.opencv_only && header->format == "TIFF") {
    if (!ReadTiffWithLibtiff(p, &im, problem)) return {};
    if (!im.empty() && reader) *reader = ImageFileReader::kLibtiff;
  }
  if (im.empty()) {
    try {
      im = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception& e) {
      *problem = "cannot decode " + p.string() + " (" + e.err + ")";
      return {};
    }
    if (im.empty()) {
      *problem = "cannot decode " + p.string();
      return {};
    }
    if (reader) *reader = ImageFileReader::kOpenCv;
  }
  if (im.depth() != CV_8U && im.depth() != CV_16U) {
    // A float or 32-bit image (a float TIFF): not what a camera stores; named with the file.
    *problem = "image " + p.string() + " holds " + cv::typeToString(im.type()) +
               " samples; expected 8- or 16-bit integer images as the camera stores them";
    return {};
  }
  if (expected && (im.cols != (*expected)[0] || im.rows != (*expected)[1])) {
    *problem = "image " + p.string() + " is " + std::to_string(im.cols) + "x" + std::to_string(im.rows) +
               " but the rig says " + std::to_string((*expected)[0]) + "x" + std::to_string((*expected)[1]);
    return {};
  }
  return im;
}

bool ImageFileOptions::IsValid(std::string* why) const {
  if (expected_size && ((*expected_size)[0] < 1 || (*expected_size)[1] < 1)) {
    if (why)
      *why = "the expected image size must be positive, got " + std::to_string((*expected_size)[0]) + " x " +
             std::to_string((*expected_size)[1]);
    return false;
  }
  return true;
}

cv::Mat ReadImageFile(const fs::path& p, const ImageFileOptions& options, std::string* problem,
                      ImageFileReader* reader) {
  return ReadFrame(p, options, problem, reader, nullptr);
}


}  // namespace mcms
