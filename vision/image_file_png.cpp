// The PNG decoder of vision/image_file.h (DecodePng, ImageFileRows): chunks walked and
// checked, one inflate into exactly the size the header gives, the rows unfiltered (whole or
// by ranges, in parallel), into buffers from a pool.
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

using image_file_internal::Be32;
using image_file_internal::SwapBytes16;
using image_file_internal::ReadFrame;

namespace {

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

}  // namespace mcms
