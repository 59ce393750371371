// Camera frames from image files: the one place that reads (and writes) the images of a
// recording (tracking/sequence.h LoadFrameImages, `mcms render --format`).
//
// Readers, chosen by the file's first bytes (never by its name):
//   PNG, 8- or 16-bit grey, not interlaced: our decoder. The chunks' CRCs are checked, the
//     IDAT chunks' zlib stream is inflated in one call (ISA-L) into a buffer of exactly
//     height x (1 + row bytes), the size the header gives, and the rows are unfiltered into
//     the image. The result equals OpenCV's cv::imread(IMREAD_UNCHANGED) bit for bit
//     (16-bit samples in native byte order, as OpenCV returns them). It is stricter than
//     libpng: a wrong CRC on any chunk, a wrong zlib checksum, and a stream that inflates
//     to more or less than the header's size are errors, where libpng only warns on some.
//   binary PGM (P5) and uncompressed TIFF (one sample, 8 or 16 bits, black is zero, pixels
//     in one contiguous run of strips): memory-mapped, the cv::Mat a header over the mapped
//     pixels that keeps the mapping alive (no copy; 16-bit samples stored big-endian, which
//     OpenCV returns native, are copied once with their bytes swapped).
//   anything else (colour PNG, other bit depths, interlaced PNG, compressed TIFF, JPEG,
//     BMP, ASCII PNM): cv::imread(IMREAD_UNCHANGED), after the header's size was checked.
// ImageFileRows reads a frame in two steps, for detection in predicted windows: a PNG is
// read, checked and inflated first, and only the rows the detector reads are unfiltered.
#pragma once

#include <array>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace mcms {

// The formats a frame may come in, recognised by their first bytes, with the {width,
// height} the header claims, without decoding. cv::imread picks its decoder by content,
// not by name: a file named .png that holds, say, a DICOM header goes to GDCM, which
// asserts on malformed input (a fuzz finding); and a header may claim any size (OpenCV
// allocates up to 2^30 pixels before it decodes). Only these formats, with a size checked
// first, reach a decoder.
struct ImageFileHeader {
  std::string format;                      // "PNG", "PNM", "TIFF", "JPEG" or "BMP"
  std::optional<std::array<int, 2>> size;  // nullopt: the header is truncated or malformed
};
// nullopt: not one of these formats (or the file cannot be read).
std::optional<ImageFileHeader> ReadImageFileHeader(const std::filesystem::path& path);

// Larger images are not camera frames of this tool (67 MP): refused before decoding.
constexpr double kMaxImageFilePixels = double(1 << 26);

// Which reader produced an image.
enum class ImageFileReader {
  kPng,     // our PNG decoder
  kMapped,  // PGM/TIFF pixels mapped from the file, no copy
  kCopied,  // PGM/TIFF read without the general reader, one copy (16-bit big-endian samples)
  kLibtiff, // a TIFF the mapper does not take (compressed, scattered strips), grey 8/16-bit
  kOpenCv,  // cv::imread
};
const char* ToString(ImageFileReader r);

struct ImageFileOptions {
  // {width, height} the image must have (the rig's camera); empty: any size.
  std::optional<std::array<int, 2>> expected_size;
  // Every file through cv::imread (benchmarks and tests compare the readers with it).
  bool opencv_only = false;
  // False with the reason (an expected size that is not positive).
  bool IsValid(std::string* why) const;
};

// Reads one camera frame. On failure an empty Mat and the reason in *problem, naming the
// file and what was expected: not an image format by its first bytes, a truncated or
// malformed header, a size other than options.expected_size or an absurd one (the
// pixels are then never allocated), a wrong CRC, a truncated file, a zlib stream that
// does not inflate to exactly the header's size, a bad filter type, or OpenCV refusing
// it. Thread-safe. `reader` (optional) receives which reader decoded the image.
cv::Mat ReadImageFile(const std::filesystem::path& path, const ImageFileOptions& options, std::string* problem,
                      ImageFileReader* reader = nullptr);

// The PNG decoder on bytes in memory (ReadImageFile's PNG path without the file): true
// and the image in *image, or false with the reason in *problem (naming `name`); or true
// and an empty *image when the PNG is valid so far but not one this decoder handles
// (colour, a bit depth other than 8 or 16, interlaced): the general reader's case.
// `max_pixels` bounds width x height before anything is allocated. The bytes may be
// modified (the IDAT payloads are moved together in place).
bool DecodePng(std::vector<unsigned char>* bytes, const std::string& name, double max_pixels, cv::Mat* image,
               std::string* problem);

// A frame read in two steps, for a caller that learns which rows it needs only after the
// costly part: the tracker's predicted windows come from the frame before, while the next
// frames are read ahead on other threads (tracking/sequence.h). Read() does everything
// that can fail and most of the work: ReadImageFile's checks and errors, and for a PNG our
// decoder takes, the file read, every CRC checked, the zlib stream inflated (with its
// Adler-32) and every row's filter type checked; only the unfiltering is left. Prepare()
// then unfilters the rows asked for and the rows their filters depend on: a row filtered
// Up, Average or Paeth is predicted from the row above, so that row is unfiltered too,
// and so on back to a row filtered None or Sub (or the first), which needs nothing above
// it. Every other row is left alone. A PNG whose rows are all filtered None (what `mcms
// render` writes) is unfiltered whole by Read(): its unfiltering is a copy, cheaper than
// zeroing the rows to skip. Other files (PGM, TIFF, colour PNGs, JPEG...) are read whole
// by Read(): every row is ready at once. Movable, not copyable; one thread at a
// time.
class ImageFileRows {
 public:
  ImageFileRows();
  ~ImageFileRows();
  ImageFileRows(ImageFileRows&&) noexcept;
  ImageFileRows& operator=(ImageFileRows&&) noexcept;

  // ReadImageFile's checks, errors and readers: true, or false with the reason in
  // *problem naming the file (image() is then empty).
  bool Read(const std::filesystem::path& path, const ImageFileOptions& options, std::string* problem,
            ImageFileReader* reader = nullptr);
  // The PNG decoder's counterpart of DecodePng: true and rows to prepare, false with the
  // reason, or true and an empty image() when it is not a PNG this decoder handles.
  bool DecodePng(std::vector<unsigned char>* bytes, const std::string& name, double max_pixels, std::string* problem);

  // Makes every row of `rows` (ranges [start, end) of row indices, clipped to the image,
  // in any order, overlapping or not) hold its pixels in image(), with the rows they
  // depend on (see above). Returns how many rows this call unfiltered.
  size_t Prepare(const std::vector<cv::Range>& rows);
  // Every row.
  void PrepareAll();

  // The image, full size; a row not yet prepared reads as zero. Later Prepare() calls
  // fill this same buffer.
  const cv::Mat& image() const { return image_; }
  // Rows that hold their pixels, of image().rows.
  size_t rows_ready() const { return rows_ready_; }

 private:
  struct Png;                  // the inflated rows still to unfilter (null once all are ready)
  std::unique_ptr<Png> png_;
  cv::Mat image_;
  size_t rows_ready_ = 0;
};

// The formats `mcms render --format` writes.
enum class ImageFileFormat { kPng, kPgm, kTiff };
const char* ToString(ImageFileFormat f);            // "png", "pgm", "tiff"
const char* ExtensionOf(ImageFileFormat f);         // ".png", ".pgm", ".tif"
// "png", "pgm", "tiff" (or "tif"); InputError naming `what` otherwise.
ImageFileFormat ParseImageFileFormat(const std::string& text, const std::string& what);

// Writes a CV_8UC1 or CV_16UC1 image: PNG (filter None and Huffman coding only: for
// camera frames the smallest files, and the fastest to decode; see EncodePng in the .cpp),
// binary PGM, or TIFF without compression. The same image gives the same bytes.
// InputError naming the file when it cannot be written.
void WriteImageFile(const std::filesystem::path& path, const cv::Mat& image, ImageFileFormat format);

}  // namespace mcms
