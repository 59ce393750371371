#include "tracking/sequence.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <unistd.h>

#include "core/error.h"
#include "core/io.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {
bool IsImageFile(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e == ".png" || e == ".pgm" || e == ".tif" || e == ".tiff" || e == ".jpg" || e == ".bmp";
}
std::optional<size_t> FrameNumber(const fs::path& p) {
  const std::string s = p.stem().string();
  std::string digits;
  for (char ch : s)
    if (std::isdigit(static_cast<unsigned char>(ch))) digits += ch;
  if (digits.empty()) return std::nullopt;
  return static_cast<size_t>(std::stoull(digits));
}
// The image formats IsImageFile accepts (PNG, PGM/PNM, TIFF, JPEG, BMP), recognised by
// their first bytes, with the width and height their header claims, without decoding.
// cv::imread picks its decoder by content, not by name: a file named .png that holds, say,
// a DICOM header goes to GDCM, which asserts on malformed input (a fuzz finding) and would
// abort the whole run; and a header may claim any size (OpenCV allocates up to 2^30
// pixels before it decodes). Only these formats, with a size checked first, reach OpenCV.
struct ImageHeader {
  std::string format;
  std::optional<std::array<int, 2>> size;  // nullopt: the header is truncated or malformed
};

std::optional<ImageHeader> ReadImageHeader(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<unsigned char> h(4096);
  in.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()));
  h.resize(static_cast<size_t>(in.gcount()));
  const size_t n = h.size();
  auto be = [&](size_t o, int bytes) {
    uint32_t v = 0;
    for (int i = 0; i < bytes; ++i) v = (v << 8) | h[o + i];
    return v;
  };
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
    ImageHeader r{"PNG", std::nullopt};
    if (n >= 24 && std::string(reinterpret_cast<const char*>(&h[12]), 4) == "IHDR") r.size = size_of(be(16, 4), be(20, 4));
    return r;
  }
  if (n >= 2 && h[0] == 'P' && h[1] >= '1' && h[1] <= '6') {  // PNM: "P5 <w> <h> ..." with # comments
    ImageHeader r{"PNM", std::nullopt};
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
    ImageHeader r{"TIFF", std::nullopt};
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
    ImageHeader r{"JPEG", std::nullopt};
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
    ImageHeader r{"BMP", std::nullopt};
    const uint32_t dib = le(14, 4);
    if (dib == 12) {
      r.size = size_of(le(18, 2), le(20, 2));
    } else {
      const int64_t w = static_cast<int32_t>(le(18, 4)), hh = static_cast<int32_t>(le(22, 4));
      r.size = size_of(w, hh < 0 ? -hh : hh);
    }
    return r;
  }
  if (n >= 2 && h[0] == 'B' && h[1] == 'M') return ImageHeader{"BMP", std::nullopt};
  return std::nullopt;
}

constexpr double kMaxImagePixels = double(1 << 26);  // 67 MP: larger is not a camera frame of this tool

// Reads an image; empty with the reason in *problem when it cannot be read, when its
// (header) size differs from `expected` (when given), or when OpenCV refuses it.
cv::Mat ReadImage(const fs::path& p, const std::array<int, 2>* expected, std::string* problem) {
  const auto header = ReadImageHeader(p);
  if (!header) {
    *problem = "cannot decode " + p.string() + ": not a PNG/PGM/TIFF/JPEG/BMP file by its first bytes";
    return {};
  }
  if (!header->size) {
    *problem = "cannot decode " + p.string() + ": its " + header->format + " header is truncated or malformed";
    return {};
  }
  const auto& hs = *header->size;
  const bool absurd = hs[0] <= 0 || hs[1] <= 0 || double(hs[0]) * double(hs[1]) > kMaxImagePixels;
  if ((expected && hs != *expected) || absurd) {
    std::ostringstream s;
    s << "image " << p.string() << " (" << header->format << ") header says " << hs[0] << "x" << hs[1];
    if (expected) s << " but the rig says " << (*expected)[0] << "x" << (*expected)[1];
    s << "; not decoded";
    *problem = s.str();
    return {};
  }
  cv::Mat im;
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
  if (expected && (im.cols != (*expected)[0] || im.rows != (*expected)[1])) {
    *problem = "image " + p.string() + " is " + std::to_string(im.cols) + "x" + std::to_string(im.rows) +
               " but the rig says " + std::to_string((*expected)[0]) + "x" + std::to_string((*expected)[1]);
    return {};
  }
  return im;
}
}  // namespace

ImageSequence ScanImageSequence(const SequenceInput& in, const CameraRig& rig) {
  if (!fs::is_directory(in.images_dir)) Throw("image folder ", in.images_dir.string(), " does not exist");
  std::set<std::string> folders;
  for (const auto& e : fs::directory_iterator(in.images_dir))
    if (e.is_directory()) folders.insert(e.path().filename().string());
  if (folders.empty())
    Throw("image folder ", in.images_dir.string(), " is empty: expected one sub-folder of images per rig camera (",
          rig.names.empty() ? std::string("cam0, ...") : rig.names.front() + ", ...", ")");
  for (const auto& n : rig.names)
    if (!folders.count(n))
      Throw("image folder ", in.images_dir.string(), " has no sub-folder '", n, "' for rig camera '", n, "' (the rig has ",
            rig.size(), " cameras, the folder holds ", folders.size(), ")");
  if (folders.size() != rig.size()) {
    std::string extra;
    for (const auto& f : folders)
      if (std::find(rig.names.begin(), rig.names.end(), f) == rig.names.end()) extra += (extra.empty() ? "" : ", ") + f;
    Throw("camera count mismatch: the rig has ", rig.size(), " cameras but ", in.images_dir.string(), " holds ",
          folders.size(), " camera folders (not in the rig: ", extra, ")");
  }
  // Times, read before the listing so that the parsed table is gone before the names
  // are allocated (a lower peak for long recordings).
  // (frame, time) sorted by frame; of repeated frames the last row counts. A vector, not a
  // map: 16 bytes per frame.
  std::vector<std::pair<size_t, double>> times;
  if (!in.frames_csv.empty() && fs::exists(in.frames_csv)) {
    const CsvTable t = ReadCsv(in.frames_csv);
    const int cf = t.Column("frame"), ct = t.Column("time_s");
    double last = -1e300;
    for (size_t r = 0; r < t.rows.size(); ++r) {
      const double f = t.Number(r, cf), time = t.Number(r, ct);
      if (!(time > last))
        Throw(in.frames_csv.string(), " line ", t.line_of_row[r], ": time_s must increase from row to row");
      last = time;
      times.emplace_back(static_cast<size_t>(f), time);
    }
    std::stable_sort(times.begin(), times.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  } else if (!(in.frame_rate_hz > 0)) {
    Throw("frame rate must be positive, got ", in.frame_rate_hz);
  }
  // Two passes over the camera folders: the frame numbers first (8 bytes per image), then
  // each image's name into its place. No path object per image, and no second copy of the
  // names: a long recording's listing stays small.
  const size_t ncam = rig.size();
  ImageSequence seq;
  for (size_t c = 0; c < ncam; ++c) seq.camera_dirs.push_back(in.images_dir / rig.names[c]);
  for (size_t c = 0; c < ncam; ++c)
    for (const auto& e : fs::directory_iterator(seq.camera_dirs[c])) {
      if (!e.is_regular_file() || !IsImageFile(e.path())) continue;
      if (const auto f = FrameNumber(e.path())) seq.frames.push_back(*f);
    }
  std::sort(seq.frames.begin(), seq.frames.end());
  seq.frames.erase(std::unique(seq.frames.begin(), seq.frames.end()), seq.frames.end());
  seq.frames.shrink_to_fit();
  if (seq.frames.empty()) Throw("image folder ", in.images_dir.string(), " holds no images (expected <camera>/<frame>.png)");
  seq.image_names.resize(seq.frames.size() * ncam);
  for (size_t c = 0; c < ncam; ++c)
    for (const auto& e : fs::directory_iterator(seq.camera_dirs[c])) {
      if (!e.is_regular_file() || !IsImageFile(e.path())) continue;
      const auto f = FrameNumber(e.path());
      if (!f) continue;
      const auto it = std::lower_bound(seq.frames.begin(), seq.frames.end(), *f);
      if (it == seq.frames.end() || *it != *f) continue;  // appeared since the first pass
      std::string& slot = seq.image_names[static_cast<size_t>(it - seq.frames.begin()) * ncam + c];
      // Two files of one camera with the same frame number (000001.png and 1.png): the
      // last in name order is used.
      std::string name = e.path().filename().string();
      if (slot.empty() || slot < name) slot = std::move(name);
    }
  // Image size check on the first readable image of each camera: a wrong rig is an
  // error. Corrupt images (or a PNG header claiming an absurd size) are per-frame
  // problems, found again when their frame is read.
  for (size_t c = 0; c < rig.size(); ++c) {
    seq.image_sizes.push_back({rig.cameras[c].Width(), rig.cameras[c].Height()});
    int tried = 0;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
      const fs::path p = seq.ImagePath(i, c);
      if (p.empty()) continue;
      if (++tried > 5) break;
      std::string problem;
      const cv::Mat im = ReadImage(p, nullptr, &problem);
      if (im.empty()) continue;
      if (im.cols != rig.cameras[c].Width() || im.rows != rig.cameras[c].Height())
        Throw("image ", p.string(), " is ", im.cols, "x", im.rows, " but the rig says camera '", rig.names[c],
              "' is ", rig.cameras[c].Width(), "x", rig.cameras[c].Height());
      break;
    }
  }
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    const size_t f = seq.frames[i];
    if (!times.empty()) {
      auto it = std::upper_bound(times.begin(), times.end(), f,
                                 [](size_t frame, const std::pair<size_t, double>& t) { return frame < t.first; });
      if (it == times.begin() || (it - 1)->first != f) {
        // Name the image(s) that made this frame: often a stray file whose name holds digits.
        std::string images;
        for (size_t c = 0; c < ncam; ++c)
          if (const fs::path p = seq.ImagePath(i, c); !p.empty()) {
            if (!images.empty()) images += ", ";
            images += p.string();
          }
        Throw("image ", images, " is frame ", f, " (the digits of its name) but ", in.frames_csv.string(),
              " has no time for frame ", f, "; remove the stray image or add the frame to ", in.frames_csv.filename().string());
      }
      seq.times_s.push_back((it - 1)->second);
    } else {
      seq.times_s.push_back(static_cast<double>(f) / in.frame_rate_hz);
    }
  }
  return seq;
}

fs::path ImageSequence::ImagePath(size_t i, size_t c) const {
  const std::string& name = image_names.at(i * cameras() + c);
  if (name.empty()) return {};
  return camera_dirs[c] / name;  // a whole path stays whole
}

void ImageSequence::SetImagePath(size_t i, size_t c, const fs::path& path) {
  image_names.at(i * cameras() + c) = path.empty() ? std::string() : fs::absolute(path).string();
}

std::vector<cv::Mat> LoadFrameImages(const ImageSequence& seq, size_t i, std::vector<std::string>* problems) {
  const size_t ncam = seq.cameras();
  if (i >= seq.frames.size()) Throw("LoadFrameImages: frame index ", i, " of a sequence of ", seq.frames.size());
  std::vector<cv::Mat> images(ncam);
  problems->assign(ncam, std::string());
  for (size_t c = 0; c < ncam; ++c) {
    const fs::path p = seq.ImagePath(i, c);
    if (p.empty()) {
      (*problems)[c] = "image missing";
      continue;
    }
    images[c] = ReadImage(p, c < seq.image_sizes.size() ? &seq.image_sizes[c] : nullptr, &(*problems)[c]);
  }
  return images;
}

void ParallelFor(size_t begin, size_t end, int threads, const std::function<void(size_t)>& fn) {
  threads = std::max(1, std::min<int>(threads, static_cast<int>(std::max<size_t>(end - begin, 1))));
  if (threads == 1) {
    for (size_t i = begin; i < end; ++i) fn(i);
    return;
  }
  std::atomic<size_t> next{begin};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    for (size_t i; (i = next++) < end;) {
      try {
        fn(i);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = end;
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (auto& th : pool) th.join();
  if (error) std::rethrow_exception(error);
}

size_t SequenceWindow(int threads) { return 4 * static_cast<size_t>(std::max(threads, 1)); }

FrameSource FilesOf(const ImageSequence& seq) {
  FrameSource s;
  s.count = seq.frames.size();
  s.frame = [&seq](size_t i) { return seq.frames[i]; };
  s.time_s = [&seq](size_t i) { return seq.times_s[i]; };
  s.images = [&seq](size_t i, std::vector<std::string>* problems) { return LoadFrameImages(seq, i, problems); };
  return s;
}

size_t TrackImageSequenceStreaming(const ImageSequence& seq, Tracker& tracker,
                                   const std::function<void(FrameResult&&)>& on_frame,
                                   const std::function<void(size_t, size_t)>& progress, int threads) {
  return TrackFramesStreaming(FilesOf(seq), tracker, on_frame, progress, threads);
}

size_t TrackFramesStreaming(const FrameSource& source, Tracker& tracker,
                            const std::function<void(FrameResult&&)>& on_frame,
                            const std::function<void(size_t, size_t)>& progress, int threads) {
  const size_t n = source.count;
  threads = std::max(threads, 1);
  struct Detected {
    std::vector<std::optional<std::vector<ImagePoint>>> points;
    std::vector<std::string> problems;
    std::vector<cv::Mat> images;  // with predicted windows: detected in frame order, in deliver
  };
  // Detection in windows needs the track of the frames before, so then the workers only
  // read the images, and this thread detects.
  const bool in_order = tracker.options().predicted_windows;
  auto detect = [&](size_t i, Detected* d) {
    d->problems.assign(tracker.rig().size(), std::string());
    std::vector<cv::Mat> images = source.images(i, &d->problems);
    if (in_order)
      d->images = std::move(images);
    else
      d->points = tracker.DetectPoints(images, &d->problems);
  };
  auto deliver = [&](size_t i, const Detected& d) {
    on_frame(in_order ? tracker.ProcessFrame(source.frame(i), source.time_s(i), d.images, d.problems)
                      : tracker.ProcessPoints(source.frame(i), source.time_s(i), d.points, d.problems));
    if (progress) progress(i + 1, n);
  };
  if (threads == 1 || n <= 1) {
    for (size_t i = 0; i < n; ++i) {
      Detected d;
      detect(i, &d);
      deliver(i, d);
    }
    return n > 0 ? 1 : 0;
  }

  // Reorder window: worker threads claim frames in order, at most `window` ahead of the
  // next frame to deliver, and leave each in its ring slot; this thread takes them out in
  // frame order, processes and delivers them.
  const size_t window = SequenceWindow(threads);
  std::vector<Detected> ring(window);
  std::vector<char> ready(window, 0);
  std::mutex mutex;
  std::condition_variable to_workers, to_main;
  size_t next_claim = 0, delivered = 0, max_held = 0;
  bool stop = false;
  std::exception_ptr error;
  auto work = [&] {
    for (;;) {
      size_t i;
      {
        std::unique_lock<std::mutex> lock(mutex);
        to_workers.wait(lock, [&] { return stop || next_claim >= n || next_claim < delivered + window; });
        if (stop || next_claim >= n) return;
        i = next_claim++;
        max_held = std::max(max_held, next_claim - delivered);
      }
      Detected d;
      try {
        detect(i, &d);
      } catch (...) {
        std::lock_guard<std::mutex> lock(mutex);
        if (!error) error = std::current_exception();
        stop = true;
        to_main.notify_all();
        to_workers.notify_all();
        return;
      }
      {
        std::lock_guard<std::mutex> lock(mutex);
        ring[i % window] = std::move(d);
        ready[i % window] = 1;
      }
      to_main.notify_all();
    }
  };
  // Stops and joins the workers however this function is left (an exception from
  // on_frame included).
  struct Pool {
    std::vector<std::thread> threads;
    std::function<void()> stop;
    ~Pool() {
      stop();
      for (auto& t : threads) t.join();
    }
  } pool;
  pool.stop = [&] {
    {
      std::lock_guard<std::mutex> lock(mutex);
      stop = true;
    }
    to_workers.notify_all();
  };
  for (int t = 0; t < threads; ++t) pool.threads.emplace_back(work);
  for (size_t i = 0; i < n; ++i) {
    Detected d;
    {
      std::unique_lock<std::mutex> lock(mutex);
      to_main.wait(lock, [&] { return error || ready[i % window]; });
      if (error) std::rethrow_exception(error);
      d = std::move(ring[i % window]);
      ready[i % window] = 0;
    }
    deliver(i, d);
    {
      std::lock_guard<std::mutex> lock(mutex);
      delivered = i + 1;
    }
    to_workers.notify_all();
  }
  return max_held;
}

std::vector<FrameResult> TrackImageSequence(const ImageSequence& seq, Tracker& tracker,
                                            const std::function<void(size_t, size_t)>& progress, int threads) {
  std::vector<FrameResult> out;
  out.reserve(seq.frames.size());
  TrackImageSequenceStreaming(
      seq, tracker, [&](FrameResult&& r) { out.push_back(std::move(r)); }, progress, threads);
  return out;
}

namespace {
const char* const kAxes[6] = {"rx", "ry", "rz", "px", "py", "pz"};
}  // namespace

PoseCsvWriter::PoseCsvWriter(fs::path path, std::vector<std::string> extra_columns)
    : path_(std::move(path)), extra_columns_(std::move(extra_columns)) {
  if (path_.has_parent_path() && !path_.parent_path().empty()) {
    std::error_code ec;
    fs::create_directories(path_.parent_path(), ec);
    if (ec) Throw("cannot create folder ", path_.parent_path().string(), " for output ", path_.string(), ": ", ec.message());
  }
  rows_path_ = path_.string() + ".rows.partial-" + std::to_string(::getpid());
  rows_out_ = std::make_unique<std::ofstream>(rows_path_, std::ios::binary | std::ios::trunc);
  if (!*rows_out_) Throw("cannot write output file ", path_.string(), " (its temporary file ", rows_path_.string(), ")");
}

PoseCsvWriter::~PoseCsvWriter() {
  rows_out_.reset();
  std::error_code ec;
  fs::remove(rows_path_, ec);
}

void PoseCsvWriter::Add(const FrameResult& f, const std::vector<double>& extra) {
  if (finished_) Throw("PoseCsvWriter::Add after Finish for ", path_.string());
  if (extra.size() != extra_columns_.size())
    Throw("PoseCsvWriter::Add: ", extra.size(), " extra values for ", extra_columns_.size(), " extra columns");
  char buf[64];
  auto num = [&](double v) {
    std::snprintf(buf, sizeof(buf), "%.10g", v);
    return std::string(buf);
  };
  std::ostream& o = *rows_out_;
  std::string reason = f.reason;
  std::replace(reason.begin(), reason.end(), ',', ';');
  std::replace(reason.begin(), reason.end(), '"', '\'');
  o << f.frame << "," << num(f.time_s) << "," << ToString(f.status) << ",\"" << reason << "\"";
  if (f.T_rig_target) {
    const auto q = f.T_rig_target->Quaternion();
    const Vec3& t = f.T_rig_target->t;
    o << "," << num(t.x()) << "," << num(t.y()) << "," << num(t.z()) << "," << num(q.w()) << "," << num(q.x()) << ","
      << num(q.y()) << "," << num(q.z());
  } else {
    o << ",,,,,,,";
  }
  o << "," << f.balls_identified << "," << f.cameras_used << "," << f.observations << ","
    << num(f.identification_margin) << "," << num(f.rms_px) << "," << num(f.chi2_per_dof);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) o << "," << (f.T_rig_target ? num(f.cov(r, c)) : std::string());
  for (double v : extra) o << "," << (std::isnan(v) ? std::string() : num(v));
  o << "\n";
  if (!o) Throw("error while writing output file ", path_.string(), " (its temporary file ", rows_path_.string(), ")");
  ++rows_;
}

void PoseCsvWriter::Finish(const std::vector<std::string>& comments) {
  if (finished_) return;
  rows_out_->flush();
  if (!*rows_out_) Throw("error while writing output file ", path_.string(), " (its temporary file ", rows_path_.string(), ")");
  rows_out_.reset();
  WriteFileAtomically(path_, [&](std::ostream& o) {
    for (const std::string& line : comments) o << "# " << line << "\n";
    o << "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz,balls,cameras,observations,id_margin_chi2,rms_px,"
         "chi2_per_dof";
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) o << ",cov_" << kAxes[r] << "_" << kAxes[c];
    for (const std::string& c : extra_columns_) o << "," << c;
    o << "\n";
    if (rows_ > 0) {
      std::ifstream rows(rows_path_, std::ios::binary);
      if (!rows) Throw("cannot read back the temporary file ", rows_path_.string(), " of ", path_.string());
      o << rows.rdbuf();
    }
  });
  finished_ = true;
  std::error_code ec;
  fs::remove(rows_path_, ec);
}

void WritePoseCsv(const fs::path& path, const std::vector<FrameResult>& results,
                  const std::vector<std::string>& comments) {
  PoseCsvWriter w(path);
  for (const FrameResult& f : results) w.Add(f);
  w.Finish(comments);
}

}  // namespace mcms
