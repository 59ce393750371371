#include "vision/image_file.h"

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

namespace {

uint32_t Be32(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

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

void SwapBytes16(const unsigned char* src, unsigned char* dst, size_t samples) {
  for (size_t i = 0; i < samples; ++i) {
    const unsigned char hi = src[2 * i], lo = src[2 * i + 1];
    dst[2 * i] = lo;
    dst[2 * i + 1] = hi;
  }
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

// ---------------------------------------------------------------------------------------
// PNG.

// The PNG predictors of byte x from a (left), b (above) and c (above left), branch-free:
// the Paeth choice depends on the data, so branches would be mispredicted on noise.
template <int type>
inline int Predict(int a, int b, int c) {
  if constexpr (type == 1) {
    return a;
  } else if constexpr (type == 2) {
    return b;
  } else if constexpr (type == 3) {
    return (a + b) >> 1;
  } else {
    const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
    const int b_or_c = pb <= pc ? b : c;
    return ((pa <= pb) & (pa <= pc)) ? a : b_or_c;
  }
}

// Reverses one row's filter (PNG spec, section 9): `f` the filtered bytes (without the
// filter-type byte), `prior` the previous row already unfiltered (zeros for the first
// row), `x` the output; n bytes, bpp bytes per pixel.
template <int bpp>
void Unfilter(int type, const unsigned char* f, const unsigned char* prior, unsigned char* x, size_t n) {
  switch (type) {
    case 0:
      std::memcpy(x, f, n);
      return;
    case 2:
      for (size_t i = 0; i < n; ++i) x[i] = static_cast<unsigned char>(f[i] + prior[i]);
      return;
  }
  // Sub, Average, Paeth: a serial recurrence along the row, per byte lane (a pixel's
  // bytes are independent); a and c are 0 left of the first pixel.
  for (int j = 0; j < bpp; ++j) {
    int a = 0, c = 0;
    for (size_t i = j; i < n; i += bpp) {
      const int b = prior[i];
      const int pred = type == 1 ? Predict<1>(a, b, c) : type == 3 ? Predict<3>(a, b, c) : Predict<4>(a, b, c);
      a = (f[i] + pred) & 0xff;
      x[i] = static_cast<unsigned char>(a);
      c = b;
    }
  }
}

// The same for 4 consecutive rows that share one filter type (Sub, Average or Paeth),
// interleaved: byte i of row k needs byte i of row k-1 (computed just before in the same
// step) and byte i-bpp of its own row, so the 4 rows' serial recurrences overlap instead of
// running one after the other (the Average filter, which libpng picks for almost every row
// of a noisy camera image, runs about three times faster so). `prior` is the row above
// the first; f[k] and x[k] are row k's filtered bytes and output.
template <int bpp, int type>
void UnfilterRows4(const unsigned char* const* f, const unsigned char* prior, unsigned char* const* x, size_t n) {
  const unsigned char *f0 = f[0], *f1 = f[1], *f2 = f[2], *f3 = f[3];
  unsigned char *x0 = x[0], *x1 = x[1], *x2 = x[2], *x3 = x[3];
  for (int j = 0; j < bpp; ++j) {
    int a0 = 0, a1 = 0, a2 = 0, a3 = 0, c0 = 0, c1 = 0, c2 = 0, c3 = 0;
    for (size_t i = j; i < n; i += bpp) {
      const int b0 = prior[i];
      const int v0 = (f0[i] + Predict<type>(a0, b0, c0)) & 0xff;
      const int v1 = (f1[i] + Predict<type>(a1, v0, c1)) & 0xff;
      const int v2 = (f2[i] + Predict<type>(a2, v1, c2)) & 0xff;
      const int v3 = (f3[i] + Predict<type>(a3, v2, c3)) & 0xff;
      x0[i] = static_cast<unsigned char>(v0);
      x1[i] = static_cast<unsigned char>(v1);
      x2[i] = static_cast<unsigned char>(v2);
      x3[i] = static_cast<unsigned char>(v3);
      c0 = b0, c1 = v0, c2 = v1, c3 = v2;
      a0 = v0, a1 = v1, a2 = v2, a3 = v3;
    }
  }
}

std::string ChunkName(const unsigned char* t) {
  std::string s = "'";
  for (int i = 0; i < 4; ++i) s += std::isprint(t[i]) ? static_cast<char>(t[i]) : '?';
  return s + "'";
}

// What DecodePng's checks and inflate leave for the unfiltering.
struct InflatedPng {
  uint32_t width = 0, height = 0;
  int bpp = 0;                              // bytes per pixel: 1 or 2
  size_t row_bytes = 0;                     // bytes per row, without the filter-type byte
  const unsigned char* filtered = nullptr;  // height x (filter-type byte, row_bytes bytes)
  const unsigned char* Row(uint32_t y) const { return filtered + size_t{y} * (row_bytes + 1); }
};

// DecodePng up to the unfiltering: the chunks walked and checked, the zlib stream inflated
// into buffer(size) (exactly the size the header gives; Buffer: size_t -> unsigned char*),
// every row's filter type checked, so that every error is found here. false with the
// reason in *problem; true with *handled false when the PNG is valid so far but not one
// this decoder handles (the general reader's case).
template <typename Buffer>
bool InflatePng(std::vector<unsigned char>& bytes, const std::string& name, double max_pixels, Buffer buffer,
                InflatedPng* out, bool* handled_out, std::string* problem) {
  *handled_out = false;
  const size_t n = bytes.size();
  auto fail = [&](const auto&... parts) {
    std::ostringstream s;
    s << "cannot decode " << name << ": ";
    (s << ... << parts);
    *problem = s.str();
    return false;
  };
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n < 8 || !std::equal(kSignature, kSignature + 8, bytes.begin())) return fail("not a PNG file (no PNG signature)");

  // The chunks: length, type, data, CRC over type and data. IHDR first; every chunk's CRC
  // checked; the IDAT payloads moved together (in place, in order) into one zlib stream.
  uint32_t width = 0, height = 0;
  int bit_depth = 0, color_type = -1, interlace = 0;
  bool handled = false;
  size_t pos = 8, idat_end = 0;  // the zlib stream is bytes[8, idat_end) once moved together
  size_t idat_chunks = 0;
  bool idat_done = false, iend = false;
  for (size_t index = 0; !iend; ++index) {
    if (n - pos < 12) {
      if (pos == n)
        return fail("truncated PNG: the file ends after ", n, " bytes without an IEND chunk");
      return fail("truncated PNG: ", n - pos, " bytes at byte ", pos, " where a chunk (at least 12 bytes) was expected");
    }
    const uint32_t length = Be32(&bytes[pos]);
    const unsigned char* type = &bytes[pos + 4];
    const std::string cname = ChunkName(type);
    for (int i = 0; i < 4; ++i)
      if (!std::isalpha(type[i]))
        return fail("chunk ", index, " at byte ", pos, " has the invalid type ", cname, " (4 ASCII letters expected)");
    if (length > 0x7fffffffu || length > n - pos - 12)
      return fail("truncated PNG: chunk ", cname, " at byte ", pos, " declares ", length, " bytes of data but the file ends after ",
                  n, " bytes");
    const unsigned char* data = type + 4;
    const uint32_t stored = Be32(data + length);
    const uint32_t crc = crc32_gzip_refl(0, type, 4 + uint64_t{length});  // CRC-32 of ISO 3309, as PNG
    if (crc != stored) {
      char hex[64];
      std::snprintf(hex, sizeof(hex), "stored 0x%08x, computed 0x%08x", stored, crc);
      return fail("chunk ", cname, " at byte ", pos, " has a wrong CRC (", hex, "): the file is damaged");
    }
    const bool is_ihdr = std::memcmp(type, "IHDR", 4) == 0, is_idat = std::memcmp(type, "IDAT", 4) == 0;
    if (index == 0 && !is_ihdr) return fail("the first chunk is ", cname, ", not IHDR");
    if (is_ihdr) {
      if (index != 0) return fail("a second IHDR chunk at byte ", pos);
      if (length != 13) return fail("IHDR chunk of ", length, " bytes (13 expected)");
      width = Be32(data);
      height = Be32(data + 4);
      bit_depth = data[8];
      color_type = data[9];
      interlace = data[12];
      if (width == 0 || height == 0 || width > 0x7fffffffu || height > 0x7fffffffu)
        return fail("IHDR says ", width, "x", height, " (1 to 2^31-1 pixels each way expected)");
      const bool depth_ok = (color_type == 0 && (bit_depth == 1 || bit_depth == 2 || bit_depth == 4 || bit_depth == 8 ||
                                                 bit_depth == 16)) ||
                            (color_type == 3 && (bit_depth == 1 || bit_depth == 2 || bit_depth == 4 || bit_depth == 8)) ||
                            ((color_type == 2 || color_type == 4 || color_type == 6) && (bit_depth == 8 || bit_depth == 16));
      if (!depth_ok) return fail("IHDR has colour type ", color_type, " with bit depth ", bit_depth, ", which PNG does not allow");
      if (data[10] != 0 || data[11] != 0 || interlace > 1)
        return fail("IHDR has compression method ", int(data[10]), ", filter method ", int(data[11]), ", interlace method ",
                    interlace, " (0, 0 and 0 or 1 expected)");
      if (double(width) * double(height) > max_pixels)
        return fail("IHDR says ", width, "x", height, ", more than ", max_pixels, " pixels; not decoded");
      // Other types go to the general reader (cv::imread), but only once the walk below
      // found every chunk whole with its CRC: libpng would print its own errors on stderr
      // ("libpng error: Read Error") naming neither the file nor the frame.
      handled = color_type == 0 && (bit_depth == 8 || bit_depth == 16) && interlace == 0;
    } else if (is_idat) {
      if (idat_done) return fail("IDAT chunk at byte ", pos, " after other chunks that followed the first IDATs");
      // Moved down over the chunk headers before it: bytes [8, idat_end) hold the stream.
      if (idat_chunks == 0) idat_end = 8;
      std::memmove(bytes.data() + idat_end, data, length);
      idat_end += length;
      ++idat_chunks;
    } else {
      if (idat_chunks > 0) idat_done = true;
      if (std::memcmp(type, "IEND", 4) == 0) {
        iend = true;
      } else if (!(type[0] & 0x20) && std::memcmp(type, "PLTE", 4) != 0) {
        // An unknown critical chunk (upper-case first letter): its meaning cannot be ignored.
        return fail("unknown critical chunk ", cname, " at byte ", pos);
      }
      // PLTE in a grey image and ancillary chunks (gAMA, sBIT, tRNS, text...) change nothing
      // of what cv::imread(IMREAD_UNCHANGED) returns for grey: skipped.
    }
    pos += 12 + static_cast<size_t>(length);
  }
  if (idat_chunks == 0) return fail("no IDAT chunk (no image data)");
  if (!handled) return true;  // the general reader's case (see IHDR above)

  // One inflate of the whole stream into exactly the size the header gives: a stream that
  // would inflate to more is refused when it gets there (nothing beyond is allocated), one
  // that inflates to less is refused after. ISA-L's inflate (igzip): on the literal-only
  // streams of noisy camera images it runs 1.4-1.6x faster than libdeflate and 2.5x faster
  // than zlib (libpng's), all three exact; it checks the zlib header and the Adler-32.
  const int bpp = bit_depth / 8;
  const size_t row_bytes = size_t{width} * bpp;
  const size_t needed = size_t{height} * (row_bytes + 1);
  if (needed > UINT32_MAX) return fail("IHDR says ", width, "x", height, ": more than 4 GB of pixels; not decoded");
  unsigned char* const filtered = buffer(needed);
  thread_local std::unique_ptr<inflate_state> inflater = std::make_unique<inflate_state>();  // 87 KB
  isal_inflate_init(inflater.get());
  inflater->next_in = bytes.data() + 8;
  inflater->avail_in = static_cast<uint32_t>(idat_end - 8);
  inflater->next_out = filtered;
  inflater->avail_out = static_cast<uint32_t>(needed);
  inflater->crc_flag = ISAL_ZLIB;
  const int r = isal_inflate_stateless(inflater.get());
  const size_t actual = inflater->total_out;
  const std::string what = std::to_string(width) + "x" + std::to_string(height) + " " + std::to_string(bit_depth) +
                           "-bit grey image";
  if (r == ISAL_OUT_OVERFLOW)
    return fail("the IDAT zlib stream inflates to more than the ", needed, " bytes a ", what,
                " holds (a zlib bomb, or a wrong header); not decoded");
  if (r == ISAL_END_INPUT) return fail("the IDAT zlib stream is truncated (it ends before its last deflate block)");
  if (r == ISAL_INCORRECT_CHECKSUM) return fail("the IDAT zlib stream has a wrong Adler-32 checksum");
  if (r != ISAL_DECOMP_OK)
    return fail("the IDAT zlib stream is corrupt (", r == ISAL_INVALID_WRAPPER || r == ISAL_UNSUPPORTED_METHOD || r == ISAL_NEED_DICT
                                                       ? "a bad zlib header"
                                                       : "bad deflate data",
                ")");
  if (actual != needed)
    return fail("the IDAT zlib stream inflates to ", actual, " bytes but a ", what, " holds ", needed,
                " (1 filter byte and ", row_bytes, " bytes per row)");

  for (uint32_t y = 0; y < height; ++y) {
    const unsigned char type = filtered[size_t{y} * (row_bytes + 1)];
    if (type > 4) return fail("row ", y, " has filter type ", int(type), " (0 to 4 expected)");
  }
  out->width = width;
  out->height = height;
  out->bpp = bpp;
  out->row_bytes = row_bytes;
  out->filtered = filtered;
  *handled_out = true;
  return true;
}

// Unfilters rows [a, b) of `png` into `im` (runs of 4 rows of one serial filter type
// together, UnfilterRows4). `prior` is row a-1 as the file holds it (zeros for a = 0); it
// is read only when row a's filter predicts from above. 16-bit samples are big-endian in
// the file; the rows are unfiltered as bytes (the previous row in file order is the
// prior), and each row's bytes are swapped once the next row no longer needs it.
void UnfilterRows(const InflatedPng& png, uint32_t a, uint32_t b, const unsigned char* prior_a, cv::Mat& im) {
  const int bpp = png.bpp;
  const size_t row_bytes = png.row_bytes;
  auto filtered_row = [&](uint32_t y) { return png.Row(y); };
  auto row = [&](uint32_t y) { return im.ptr<unsigned char>(static_cast<int>(y)); };
  constexpr uint32_t K = 4;
  uint32_t swapped = a;  // 16-bit: rows [a, swapped) are in native byte order
  for (uint32_t y = a; y < b;) {
    const unsigned char* prior = y == a ? prior_a : row(y - 1);
    const int type = filtered_row(y)[0];
    bool run = (type == 1 || type == 3 || type == 4) && b - y >= K;
    for (uint32_t k = 1; run && k < K; ++k) run = filtered_row(y + k)[0] == type;
    if (run) {
      const unsigned char* f[K];
      unsigned char* x[K];
      for (uint32_t k = 0; k < K; ++k) {
        f[k] = filtered_row(y + k) + 1;
        x[k] = row(y + k);
      }
      if (bpp == 1) {
        if (type == 1) UnfilterRows4<1, 1>(f, prior, x, row_bytes);
        if (type == 3) UnfilterRows4<1, 3>(f, prior, x, row_bytes);
        if (type == 4) UnfilterRows4<1, 4>(f, prior, x, row_bytes);
      } else {
        if (type == 1) UnfilterRows4<2, 1>(f, prior, x, row_bytes);
        if (type == 3) UnfilterRows4<2, 3>(f, prior, x, row_bytes);
        if (type == 4) UnfilterRows4<2, 4>(f, prior, x, row_bytes);
      }
      y += K;
    } else {
      if (bpp == 1)
        Unfilter<1>(type, filtered_row(y) + 1, prior, row(y), row_bytes);
      else
        Unfilter<2>(type, filtered_row(y) + 1, prior, row(y), row_bytes);
      y += 1;
    }
    if (bpp == 2) {
      for (; swapped + 1 < y; ++swapped) SwapBytes16(row(swapped), row(swapped), png.width);  // the last stays the prior
      if (y == b)
        for (; swapped < y; ++swapped) SwapBytes16(row(swapped), row(swapped), png.width);
    }
  }
}

// n zero bytes: the prior of the first row.
const unsigned char* Zeros(size_t n) {
  thread_local std::vector<unsigned char> zeros;
  if (zeros.size() < n) zeros.assign(n, 0);
  return zeros.data();
}

}  // namespace

bool DecodePng(std::vector<unsigned char>* bytes, const std::string& name, double max_pixels, cv::Mat* image,
               std::string* problem) {
  image->release();
  thread_local std::vector<unsigned char> filtered;  // reused: no allocation per frame
  auto buffer = [](size_t size) {
    if (filtered.size() < size) filtered.resize(size);
    return filtered.data();
  };
  InflatedPng png;
  bool handled = false;
  if (!InflatePng(*bytes, name, max_pixels, buffer, &png, &handled, problem)) return false;
  if (!handled) return true;
  cv::Mat im(static_cast<int>(png.height), static_cast<int>(png.width), png.bpp == 1 ? CV_8UC1 : CV_16UC1);
  UnfilterRows(png, 0, png.height, Zeros(png.row_bytes), im);
  *image = im;
  return true;
}

// ---------------------------------------------------------------------------------------
// A PNG read in two steps.

namespace {

// The inflated rows' buffers of ImageFileRows, kept for the next frames instead of freed:
// a fresh 1.3 MB buffer per image is faulted in page by page as the inflate first writes
// it (glibc hands freed memory at the top of its heap back to the system), which made
// reading in part slower than decoding whole (13.8 against 7.6 ms per frame set). At
// most kKept buffers are kept (the tracker holds 4 frame sets per thread).
class BufferPool {
 public:
  std::unique_ptr<unsigned char[]> Take(size_t size, size_t* capacity) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (size_t i = free_.size(); i-- > 0;)  // the last given first: the likeliest still in cache
        if (free_[i].first >= size) {
          *capacity = free_[i].first;
          std::unique_ptr<unsigned char[]> b = std::move(free_[i].second);
          free_.erase(free_.begin() + static_cast<std::ptrdiff_t>(i));
          return b;
        }
    }
    *capacity = size;
    return std::unique_ptr<unsigned char[]>(new unsigned char[size]);  // not zeroed: the inflate writes all of it
  }
  void Give(std::unique_ptr<unsigned char[]> b, size_t capacity) {
    if (!b) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (free_.size() < kKept) free_.emplace_back(capacity, std::move(b));
  }

 private:
  static constexpr size_t kKept = 64;
  std::mutex mutex_;
  std::vector<std::pair<size_t, std::unique_ptr<unsigned char[]>>> free_;
};

BufferPool& TheBufferPool() {
  static BufferPool* p = new BufferPool;  // outlives every ImageFileRows (never destroyed)
  return *p;
}

// The pixels of an ImageFileRows image come from TheBufferPool() too, and go back to it
// when the last Mat sharing them is released (the Mat's UMatData holds the buffer, as
// for a mapped file above). They are zeroed when handed out: a row not prepared reads
// as zero. (An anonymous mapping per image, zero for free, cost more in page faults
// than the unfiltering it saved: 12.7 against 11.3 ms per frame set.)
class PooledPixelAllocator : public cv::MatAllocator {
 public:
  cv::UMatData* allocate(int, const int*, int, void*, size_t*, cv::AccessFlag, cv::UMatUsageFlags) const override {
    return nullptr;
  }
  bool allocate(cv::UMatData*, cv::AccessFlag, cv::UMatUsageFlags) const override { return false; }
  void deallocate(cv::UMatData* u) const override {
    if (!u) return;
    TheBufferPool().Give(std::unique_ptr<unsigned char[]>(u->origdata), u->size);
    delete u;
  }
};

// A zeroed rows x cols Mat of `type` over a pooled buffer.
cv::Mat PooledZeroMat(int rows, int cols, int type) {
  const size_t bytes = size_t(rows) * size_t(cols) * CV_ELEM_SIZE(type);
  size_t capacity = 0;
  std::unique_ptr<unsigned char[]> b = TheBufferPool().Take(bytes, &capacity);
  std::memset(b.get(), 0, bytes);
  static const PooledPixelAllocator* allocator = new PooledPixelAllocator;  // never destroyed
  cv::Mat im(rows, cols, type, b.get());
  cv::UMatData* u = new cv::UMatData(allocator);
  u->data = u->origdata = b.release();
  u->size = capacity;
  u->refcount = 1;
  im.u = u;
  return im;
}

}  // namespace

struct ImageFileRows::Png {
  ~Png() { TheBufferPool().Give(std::move(filtered), capacity); }
  std::unique_ptr<unsigned char[]> filtered;  // what InflatePng left, from TheBufferPool()
  size_t capacity = 0;
  InflatedPng rows;
  std::vector<unsigned char> ready, need;     // per row
  std::vector<unsigned char> prior;           // 16-bit: a prepared row swapped back to the file's order
};

ImageFileRows::ImageFileRows() = default;
ImageFileRows::~ImageFileRows() = default;
ImageFileRows::ImageFileRows(ImageFileRows&&) noexcept = default;
ImageFileRows& ImageFileRows::operator=(ImageFileRows&&) noexcept = default;

bool ImageFileRows::DecodePng(std::vector<unsigned char>* bytes, const std::string& name, double max_pixels,
                              std::string* problem) {
  png_.reset();
  image_.release();
  rows_ready_ = 0;
  auto p = std::make_unique<Png>();
  auto buffer = [&p](size_t size) {
    p->filtered = TheBufferPool().Take(size, &p->capacity);
    return p->filtered.get();
  };
  bool handled = false;
  if (!InflatePng(*bytes, name, max_pixels, buffer, &p->rows, &handled, problem)) return false;
  if (!handled) return true;
  const InflatedPng& f = p->rows;
  // Rows filtered None cost only a copy to unfilter, less than zeroing them to skip them:
  // when every row is None (`mcms render`'s PNGs), all are unfiltered now, on the reading
  // thread. Row skipping pays where rows are predicted (Sub, Average, Paeth: the serial
  // recurrences along the row).
  bool all_none = true;
  for (uint32_t y = 0; y < f.height && all_none; ++y) all_none = f.Row(y)[0] == 0;
  if (all_none) {
    cv::Mat im(static_cast<int>(f.height), static_cast<int>(f.width), f.bpp == 1 ? CV_8UC1 : CV_16UC1);
    UnfilterRows(f, 0, f.height, Zeros(f.row_bytes), im);
    image_ = im;
    rows_ready_ = f.height;
    return true;  // the inflated rows go back to the pool with p
  }
  image_ = PooledZeroMat(static_cast<int>(f.height), static_cast<int>(f.width), f.bpp == 1 ? CV_8UC1 : CV_16UC1);
  p->ready.assign(f.height, 0);
  png_ = std::move(p);
  return true;
}

size_t ImageFileRows::Prepare(const std::vector<cv::Range>& ranges) {
  if (!png_) return 0;
  const InflatedPng& f = png_->rows;
  const int64_t h = f.height;
  std::vector<unsigned char>& ready = png_->ready;
  std::vector<unsigned char>& need = png_->need;
  need.assign(static_cast<size_t>(h), 0);
  for (const cv::Range& r : ranges)
    for (int64_t y = std::max<int64_t>(r.start, 0); y < std::min<int64_t>(r.end, h); ++y) need[y] = 1;
  // Bottom up, so that a chain of rows predicted from above is followed to its end: a
  // needed row filtered Up (2), Average (3) or Paeth (4) needs the row above unfiltered.
  for (int64_t y = h - 1; y > 0; --y)
    if (need[y] && !ready[y] && f.Row(static_cast<uint32_t>(y))[0] >= 2) need[y - 1] = 1;
  size_t done = 0;
  for (int64_t y = 0; y < h;) {
    if (!need[y] || ready[y]) {
      ++y;
      continue;
    }
    int64_t b = y + 1;
    while (b < h && need[b] && !ready[b]) ++b;
    // Row y's prior: the row above when it is ready (it is whenever row y's filter needs
    // it, by the pass above), as the file holds it; zeros above the first row.
    const unsigned char* prior = Zeros(f.row_bytes);
    if (y > 0 && ready[y - 1]) {
      const unsigned char* above = image_.ptr<unsigned char>(static_cast<int>(y - 1));
      if (f.bpp == 1) {
        prior = above;
      } else {
        png_->prior.resize(f.row_bytes);
        SwapBytes16(above, png_->prior.data(), f.width);
        prior = png_->prior.data();
      }
    }
    UnfilterRows(f, static_cast<uint32_t>(y), static_cast<uint32_t>(b), prior, image_);
    std::fill(ready.begin() + y, ready.begin() + b, 1);
    done += static_cast<size_t>(b - y);
    y = b;
  }
  rows_ready_ += done;
  if (rows_ready_ == static_cast<size_t>(h)) png_.reset();  // the inflated rows are no longer needed
  return done;
}

void ImageFileRows::PrepareAll() {
  if (png_) Prepare({cv::Range(0, image_.rows)});
}

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

// ReadImageFile, and ImageFileRows::Read when `rows` is given: then a PNG our decoder
// handles is inflated into *rows, and the image returned is rows->image(), not yet
// prepared.
cv::Mat ReadFrame(const fs::path& p, const ImageFileOptions& options, std::string* problem, ImageFileReader* reader,
                  ImageFileRows* rows) {
  problem->clear();
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

}  // namespace

cv::Mat ReadImageFile(const fs::path& p, const ImageFileOptions& options, std::string* problem,
                      ImageFileReader* reader) {
  return ReadFrame(p, options, problem, reader, nullptr);
}

bool ImageFileRows::Read(const fs::path& p, const ImageFileOptions& options, std::string* problem,
                         ImageFileReader* reader) {
  png_.reset();
  image_.release();
  rows_ready_ = 0;
  const cv::Mat im = ReadFrame(p, options, problem, reader, options.opencv_only ? nullptr : this);
  if (im.empty()) {
    png_.reset();
    image_.release();
    return false;
  }
  if (!png_) {  // read whole (not a PNG our decoder handles)
    image_ = im;
    rows_ready_ = static_cast<size_t>(im.rows);
  }
  return true;
}

const char* ToString(ImageFileFormat f) {
  switch (f) {
    case ImageFileFormat::kPng: return "png";
    case ImageFileFormat::kPgm: return "pgm";
    case ImageFileFormat::kTiff: return "tiff";
  }
  return "?";
}

const char* ExtensionOf(ImageFileFormat f) {
  switch (f) {
    case ImageFileFormat::kPng: return ".png";
    case ImageFileFormat::kPgm: return ".pgm";
    case ImageFileFormat::kTiff: return ".tif";
  }
  return "";
}

ImageFileFormat ParseImageFileFormat(const std::string& text, const std::string& what) {
  if (text == "png") return ImageFileFormat::kPng;
  if (text == "pgm") return ImageFileFormat::kPgm;
  if (text == "tiff" || text == "tif") return ImageFileFormat::kTiff;
  Throw(what, ": unknown image format '", text, "'; expected png, pgm or tiff");
}

namespace {

// A PNG of a grey 8- or 16-bit image: every row with filter None, the zlib stream made of
// Huffman codes only (zlib level 1, Z_HUFFMAN_ONLY; memory level 9: blocks of 32 K
// symbols, half as many Huffman tables to build when reading), in IDAT chunks of 64 KB. A camera
// frame is white noise on a smooth background: a PNG filter adds the neighbours' noise to
// each pixel's (libpng's adaptive choice, Average, has 1.5x the variance), so None gives
// smaller files (3.6% smaller than OpenCV's writer on the rendered frames) that every
// reader decodes faster (nothing to unfilter); noise defeats dictionary matching, so
// Huffman coding alone loses nothing at the lowest cost.
std::vector<unsigned char> EncodePng(const cv::Mat& image, const fs::path& path) {
  const size_t row_bytes = image.cols * image.elemSize();
  std::vector<unsigned char> raw(image.rows * (row_bytes + 1));
  for (int y = 0; y < image.rows; ++y) {
    unsigned char* out = &raw[y * (row_bytes + 1)];
    out[0] = 0;  // filter None
    if (image.depth() == CV_8U)
      std::memcpy(out + 1, image.ptr(y), row_bytes);
    else
      SwapBytes16(image.ptr(y), out + 1, static_cast<size_t>(image.cols));  // big-endian in PNG
  }
  z_stream z{};
  if (deflateInit2(&z, 1, Z_DEFLATED, 15, 9, Z_HUFFMAN_ONLY) != Z_OK) Throw("cannot write image ", path.string(), ": zlib");
  std::vector<unsigned char> stream(deflateBound(&z, raw.size()));
  z.next_in = raw.data();
  z.avail_in = static_cast<uInt>(raw.size());
  z.next_out = stream.data();
  z.avail_out = static_cast<uInt>(stream.size());
  const int r = deflate(&z, Z_FINISH);
  stream.resize(z.total_out);
  deflateEnd(&z);
  if (r != Z_STREAM_END) Throw("cannot write image ", path.string(), ": zlib deflate failed");

  std::vector<unsigned char> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  auto chunk = [&](const char* type, const unsigned char* data, size_t length) {
    for (int k = 3; k >= 0; --k) png.push_back(static_cast<unsigned char>(length >> (8 * k)));
    const size_t start = png.size();
    png.insert(png.end(), type, type + 4);
    png.insert(png.end(), data, data + length);
    const uint32_t crc = crc32_gzip_refl(0, &png[start], 4 + length);
    for (int k = 3; k >= 0; --k) png.push_back(static_cast<unsigned char>(crc >> (8 * k)));
  };
  unsigned char ihdr[13] = {};
  for (int k = 0; k < 4; ++k) {
    ihdr[k] = static_cast<unsigned char>(static_cast<uint32_t>(image.cols) >> (24 - 8 * k));
    ihdr[4 + k] = static_cast<unsigned char>(static_cast<uint32_t>(image.rows) >> (24 - 8 * k));
  }
  ihdr[8] = image.depth() == CV_8U ? 8 : 16;  // grey; compression, filter, interlace methods 0
  chunk("IHDR", ihdr, 13);
  constexpr size_t kIdat = 65536;
  for (size_t p = 0; p < stream.size(); p += kIdat) chunk("IDAT", stream.data() + p, std::min(kIdat, stream.size() - p));
  chunk("IEND", nullptr, 0);
  return png;
}

}  // namespace

void WriteImageFile(const fs::path& path, const cv::Mat& image, ImageFileFormat format) {
  if (image.empty() || image.channels() != 1 || (image.depth() != CV_8U && image.depth() != CV_16U))
    Throw("cannot write image ", path.string(), ": expected an 8- or 16-bit grey image");
  std::vector<unsigned char> bytes;
  bool ok = false;
  if (format == ImageFileFormat::kPng) {
    bytes = EncodePng(image, path);
    ok = true;
  } else {
    // OpenCV writes PGM and TIFF; by the format, not by the file's extension.
    const std::vector<int> params = format == ImageFileFormat::kPgm ? std::vector<int>{cv::IMWRITE_PXM_BINARY, 1}
                                                                   : std::vector<int>{cv::IMWRITE_TIFF_COMPRESSION, 1};
    try {
      ok = cv::imencode(format == ImageFileFormat::kPgm ? ".pgm" : ".tif", image, bytes, params);
    } catch (const cv::Exception&) {
      ok = false;
    }
  }
  if (ok) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    ok = static_cast<bool>(out);
  }
  if (!ok) Throw("cannot write image ", path.string());
}

}  // namespace mcms
