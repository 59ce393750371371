#include "tracking/sequence.h"

#include <algorithm>
#include <cerrno>
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
#include <set>
#include <unistd.h>

#include "core/error.h"
#include "core/io.h"
#include "vision/image_file.h"

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
// Reads one frame (vision/image_file.h): empty with the reason in *problem when it cannot
// be read or its (header) size differs from `expected` (when given).
cv::Mat ReadImage(const fs::path& p, const std::array<int, 2>* expected, std::string* problem) {
  ImageFileOptions o;
  if (expected) o.expected_size = *expected;
  return ReadImageFile(p, o, problem);
}
}  // namespace

ImageSequence ScanImageSequence(const SequenceInput& in, const CameraRig& rig) {
  if (!fs::is_directory(in.images_dir)) {
    std::error_code ec;
    if (fs::exists(in.images_dir, ec))
      Throw("image folder ", in.images_dir.string(), " is not a folder; expected a folder of one sub-folder of images "
            "per rig camera");
    Throw("image folder ", in.images_dir.string(), " does not exist");
  }
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
  // map: 16 bytes per frame. Cameras not triggered together: each camera's exposure times
  // from the columns time_s_<camera> (NaN where a cell is empty or the column absent),
  // ncam per row in the rows' order, and each sorted row's original index.
  std::vector<std::pair<size_t, double>> times;
  std::vector<double> camera_times;
  std::vector<size_t> row_of;
  const size_t ncam = rig.size();
  if (!in.frames_csv.empty() && fs::exists(in.frames_csv)) {
    const CsvTable t = ReadCsv(in.frames_csv);
    const int cf = t.Column("frame"), ct = t.Column("time_s");
    std::vector<int> camera_column(ncam, -1);
    bool any_camera_time = false;
    for (size_t k = 0; k < t.header.size(); ++k) {
      const std::string& h = t.header[k];
      if (h.rfind("time_s_", 0) != 0) continue;
      const auto c = std::find(rig.names.begin(), rig.names.end(), h.substr(7));
      if (c == rig.names.end()) {
        std::string names;
        for (const auto& n : rig.names) names += (names.empty() ? "" : ", ") + n;
        Throw(in.frames_csv.string(), ": column '", h, "' names no camera of the rig; expected time_s_<camera> with one of: ",
              names);
      }
      camera_column[c - rig.names.begin()] = static_cast<int>(k);
      any_camera_time = true;
    }
    if (t.rows.empty())
      Throw(in.frames_csv.string(), ": a header and no rows; expected one row (frame, time_s) per frame, or no "
            "frames.csv and the frame rate given");
    double last = -1e300;
    for (size_t r = 0; r < t.rows.size(); ++r) {
      const double f = t.Number(r, cf), time = t.Number(r, ct);
      if (!(time > last))
        Throw(in.frames_csv.string(), " line ", t.line_of_row[r], ": time_s must increase from row to row");
      last = time;
      times.emplace_back(static_cast<size_t>(f), time);
      if (any_camera_time)
        for (size_t c = 0; c < ncam; ++c) {
          const int k = camera_column[c];
          camera_times.push_back(k < 0 || t.rows[r][k].empty() ? std::nan("") : t.Number(r, k));
        }
    }
    if (any_camera_time) {
      row_of.resize(times.size());
      for (size_t r = 0; r < row_of.size(); ++r) row_of[r] = r;
      std::stable_sort(row_of.begin(), row_of.end(), [&](size_t a, size_t b) { return times[a].first < times[b].first; });
    }
    std::stable_sort(times.begin(), times.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  } else if (!(in.frame_rate_hz > 0)) {
    Throw("frame rate must be positive, got ", in.frame_rate_hz);
  }
  // Two passes over the camera folders: the frame numbers first (8 bytes per image), then
  // each image's name into its place. No path object per image, and no second copy of the
  // names: a long recording's listing stays small.
  ImageSequence seq;
  for (size_t c = 0; c < ncam; ++c) seq.camera_dirs.push_back(in.images_dir / rig.names[c]);
  // An image's entry: a file, or a link named like one that does not resolve (a loop, a
  // dangling target), kept so that the frame reader names it and degrades that frame only.
  const auto is_image = [](const fs::directory_entry& e) {
    std::error_code ec;
    if (!IsImageFile(e.path())) return false;
    if (e.is_regular_file(ec)) return true;
    return e.is_symlink(ec) && !fs::exists(e.path(), ec);
  };
  for (size_t c = 0; c < ncam; ++c)
    for (const auto& e : fs::directory_iterator(seq.camera_dirs[c])) {
      if (!is_image(e)) continue;
      if (const auto f = FrameNumber(e.path())) seq.frames.push_back(*f);
    }
  std::sort(seq.frames.begin(), seq.frames.end());
  seq.frames.erase(std::unique(seq.frames.begin(), seq.frames.end()), seq.frames.end());
  seq.frames.shrink_to_fit();
  if (seq.frames.empty()) Throw("image folder ", in.images_dir.string(), " holds no images (expected <camera>/<frame>.png)");
  seq.image_names.resize(seq.frames.size() * ncam);
  for (size_t c = 0; c < ncam; ++c)
    for (const auto& e : fs::directory_iterator(seq.camera_dirs[c])) {
      if (!is_image(e)) continue;
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
      if (!camera_times.empty()) {
        const size_t row = row_of[static_cast<size_t>(it - 1 - times.begin())];
        seq.camera_times_s.insert(seq.camera_times_s.end(), camera_times.begin() + static_cast<std::ptrdiff_t>(row * ncam),
                                  camera_times.begin() + static_cast<std::ptrdiff_t>((row + 1) * ncam));
      }
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

std::vector<ImageFileRows> LoadFrameRows(const ImageSequence& seq, size_t i, std::vector<std::string>* problems) {
  const size_t ncam = seq.cameras();
  if (i >= seq.frames.size()) Throw("LoadFrameRows: frame index ", i, " of a sequence of ", seq.frames.size());
  std::vector<ImageFileRows> images(ncam);
  problems->assign(ncam, std::string());
  for (size_t c = 0; c < ncam; ++c) {
    const fs::path p = seq.ImagePath(i, c);
    if (p.empty()) {
      (*problems)[c] = "image missing";
      continue;
    }
    ImageFileOptions o;
    if (c < seq.image_sizes.size()) o.expected_size = seq.image_sizes[c];
    images[c].Read(p, o, &(*problems)[c]);
  }
  return images;
}

size_t SequenceWindow(int threads) { return 4 * static_cast<size_t>(std::max(threads, 1)); }

FrameSource FilesOf(const ImageSequence& seq) {
  FrameSource s;
  s.count = seq.frames.size();
  s.frame = [&seq](size_t i) { return seq.frames[i]; };
  s.time_s = [&seq](size_t i) { return seq.times_s[i]; };
  if (!seq.camera_times_s.empty())
    s.camera_time_s = [&seq](size_t i) {
      const auto at = seq.camera_times_s.begin() + static_cast<std::ptrdiff_t>(i * seq.cameras());
      return std::vector<double>(at, at + static_cast<std::ptrdiff_t>(seq.cameras()));
    };
  s.images = [&seq](size_t i, std::vector<std::string>* problems) { return LoadFrameImages(seq, i, problems); };
  s.image_rows = [&seq](size_t i, std::vector<std::string>* problems) { return LoadFrameRows(seq, i, problems); };
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
    std::vector<ImageFileRows> rows;  // the same images read in part (source.image_rows)
  };
  // Detection in windows needs the track of the frames before, so then the workers only
  // read the images, and this thread detects. The windows are known only then, so the
  // workers leave PNG rows inflated but not unfiltered (the costly inflate stays parallel),
  // and this thread unfilters the rows the detector reads.
  const bool in_order = tracker.options().predicted_windows;
  const bool in_part = in_order && static_cast<bool>(source.image_rows);
  auto detect = [&](size_t i, Detected* d) {
    d->problems.assign(tracker.rig().size(), std::string());
    if (in_part) {
      d->rows = source.image_rows(i, &d->problems);
      for (const ImageFileRows& r : d->rows) d->images.push_back(r.image());
      return;
    }
    std::vector<cv::Mat> images = source.images(i, &d->problems);
    if (in_order)
      d->images = std::move(images);
    else
      d->points = tracker.DetectPoints(images, &d->problems);
  };
  auto deliver = [&](size_t i, Detected& d) {
    if (in_part) {
      const Tracker::PrepareRows prepare = [&d](size_t c, const std::vector<cv::Range>* rows) {
        if (c >= d.rows.size()) return;
        if (rows)
          d.rows[c].Prepare(*rows);
        else
          d.rows[c].PrepareAll();
      };
      FrameResult r = tracker.ProcessFrame(source.frame(i), source.time_s(i), d.images, d.problems, prepare);
      if (source.camera_time_s) r.camera_time_s = source.camera_time_s(i);
      on_frame(std::move(r));
    } else {
      FrameResult r = in_order ? tracker.ProcessFrame(source.frame(i), source.time_s(i), d.images, d.problems)
                               : tracker.ProcessPoints(source.frame(i), source.time_s(i), d.points, d.problems);
      if (source.camera_time_s) r.camera_time_s = source.camera_time_s(i);
      on_frame(std::move(r));
    }
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
  RemoveStaleTemporaries(path_.parent_path(), path_.filename().string() + ".rows.partial-");  // of killed runs
  rows_path_ = path_.string() + ".rows.partial-" + std::to_string(::getpid());
  rows_guard_ = std::make_unique<RemovedOnInterrupt>(rows_path_);
  errno = 0;
  rows_out_ = std::make_unique<std::ofstream>(rows_path_, std::ios::binary | std::ios::trunc);
  if (!*rows_out_) Throw("cannot write output file ", path_.string(), SystemWriteReason());
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
  errno = 0;
  std::string reason = f.reason;
  std::replace(reason.begin(), reason.end(), ',', ';');
  std::replace(reason.begin(), reason.end(), '"', '\'');
  o << f.frame << "," << CsvTime(f.time_s, 10) << "," << ToString(f.status) << ",\"" << reason << "\"";
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
  if (!o) Throw("error while writing output file ", path_.string(), SystemWriteReason());
  ++rows_;
}

void PoseCsvWriter::Finish(const std::vector<std::string>& comments) {
  if (finished_) return;
  errno = 0;
  rows_out_->flush();
  if (!*rows_out_) Throw("error while writing output file ", path_.string(), SystemWriteReason());
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
