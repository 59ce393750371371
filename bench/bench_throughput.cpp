// Throughput of processing a recording, frame sets per second, against the OpenCV baseline
// in the same process, on 1 to N threads.
//
//   from files  every frame set read from its 4 files (decoding included), as `mcms track`
//               reads a recording, once per reader and format (vision/image_file.h):
//                 png          our PNG reader (ISA-L inflate, our unfiltering): `mcms track`
//                 png/opencv   the same PNG files through cv::imread (libpng)
//                 png/libspng  the same PNG files through libspng (when built with it)
//                 pgm, tiff    the same frames as binary PGM and uncompressed TIFF files
//                              (written beside, in a temporary folder), memory-mapped
//                 png/rows     with predicted windows only: our PNG reader in two steps
//                              (ImageFileRows): frames inflated on the worker threads, and
//                              only the rows the detector reads unfiltered (its windows and
//                              sample), as `mcms track --predicted-windows` reads PNG files
//                              (a PNG whose rows are all filtered None is unfiltered whole)
//   in memory   the same frame sets decoded once beforehand (the images handed over as
//               cv::Mat, no copy).
//
//   OURS        TrackFramesStreaming (tracking/sequence.h), the pipeline of `mcms track`:
//               PNG decoding and DetectBlobs on `threads` worker threads, a reorder window,
//               then matching, triangulation, identification and the pose bundle adjustment
//               with its covariance, frame after frame in the calling thread.
//   BASELINE    the OpenCV pipeline of bench_pipeline (bench/opencv_baseline.h): cv::imread,
//               cv::SimpleBlobDetector and cv::undistortPoints on the 4 images, epipolar
//               matching, cv::triangulatePoints and the closed-form pose; frame sets spread
//               over `threads` threads (each frame set on one thread, OpenCV itself held to
//               one thread so that the two pipelines parallelize the same way).
//
// The recording is a run of consecutive frames of Scenario::Default() (4 cameras, 1280 x
// 1024, 8-bit PNG) rendered into a temporary folder with the project's renderer; the PGM and
// TIFF copies are written from its decoded frames. A table of the decoding alone follows
// (one thread, every reader and format). Every
// configuration runs --repeat times; the figures are the median wall-clock rate, and the
// process CPU time per frame set (the figure that does not depend on what else the machine
// runs, for one thread). At the end, the results of ours on N threads are compared with
// those on 1 thread (they must be identical, in frame order).
//
//   bench_throughput [--frames N] [--threads N] [--repeat N] [--keep DIR | --recording DIR]
//                    [--poses FILE]
//
// --keep DIR renders into DIR and keeps it; --recording DIR uses a recording made before
// (by --keep or `mcms render`: rig.yaml, target.yaml, frames.csv, images/) instead of
// rendering, all its frames unless --frames is given. --poses FILE writes the poses of ours
// (the pose CSV of `mcms track`), to compare builds.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#ifdef MCMS_HAVE_SPNG
#include <spng.h>
#endif

#include "bench/opencv_baseline.h"
#include "core/parallel.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "synthetic/scenario.h"
#include "tracking/sequence.h"
#include "tracking/tracker.h"
#include "vision/image_file.h"

namespace fs = std::filesystem;

namespace mcms {
namespace {

double CpuSeconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Timing {
  double wall_s = 0, cpu_s = 0;
};

// Runs fn `repeat` times; the median wall time and the median CPU time.
Timing Measure(int repeat, const std::function<void()>& fn) {
  std::vector<double> wall, cpu;
  for (int r = 0; r < repeat; ++r) {
    const double c0 = CpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    fn();
    wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(CpuSeconds() - c0);
  }
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  return {wall[wall.size() / 2], cpu[cpu.size() / 2]};
}

// The tracker of bench_pipeline: the renderer's gain for the photon-noise term.
TrackerOptions OurOptions(double gain_e_per_dn) {
  TrackerOptions o;
  o.detector.gain_e_per_dn = gain_e_per_dn;
  return o;
}

struct Row {
  std::string source;
  int threads;
  Timing ours;
  std::optional<Timing> base;  // the OpenCV pipeline, from PNG files and from memory
};

#ifdef MCMS_HAVE_SPNG
// libspng's decode of a grey 8- or 16-bit PNG (16-bit samples in host order, as OpenCV
// returns them); empty when it refuses the file. CRC errors are errors, as in our reader.
cv::Mat DecodeWithSpng(const fs::path& p) {
  thread_local std::vector<unsigned char> bytes;
  FILE* f = std::fopen(p.c_str(), "rb");
  if (!f) return {};
  std::fseek(f, 0, SEEK_END);
  bytes.resize(static_cast<size_t>(std::ftell(f)));
  std::fseek(f, 0, SEEK_SET);
  const size_t got = std::fread(bytes.data(), 1, bytes.size(), f);
  std::fclose(f);
  if (got != bytes.size()) return {};
  spng_ctx* ctx = spng_ctx_new(0);
  cv::Mat im;
  spng_ihdr ihdr;
  size_t size = 0;
  if (ctx && spng_set_crc_action(ctx, SPNG_CRC_ERROR, SPNG_CRC_ERROR) == 0 &&
      spng_set_png_buffer(ctx, bytes.data(), bytes.size()) == 0 && spng_get_ihdr(ctx, &ihdr) == 0 &&
      ihdr.color_type == SPNG_COLOR_TYPE_GRAYSCALE && (ihdr.bit_depth == 8 || ihdr.bit_depth == 16) &&
      spng_decoded_image_size(ctx, SPNG_FMT_PNG, &size) == 0) {
    im.create(static_cast<int>(ihdr.height), static_cast<int>(ihdr.width), ihdr.bit_depth == 8 ? CV_8UC1 : CV_16UC1);
    if (size != im.total() * im.elemSize() || spng_decode_image(ctx, im.data, size, SPNG_FMT_PNG, 0) != 0) im.release();
  }
  spng_ctx_free(ctx);
  return im;
}
#endif

int Usage(const char* argv0) {
  std::fprintf(stderr, "usage: %s [--frames N (>= 2, default 40)] [--threads N (default: all cores)] "
               "[--repeat N (default 3)] [--keep DIR (render into DIR and keep it) | --recording DIR (use it)] "
               "[--poses FILE]\n", argv0);
  return 2;
}

int Main(int argc, char** argv) {
  size_t frames = 40;
  int max_threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  int repeat = 3;
  fs::path keep, recording, poses;
  bool frames_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return Usage(argv[0]);
    const std::string v = argv[++i];
    char* end = nullptr;
    const long n = std::strtol(v.c_str(), &end, 10);
    const bool number = !v.empty() && *end == '\0';
    if (a == "--frames" && number && n >= 2 && n <= 100000) {
      frames = static_cast<size_t>(n);
      frames_given = true;
    }
    else if (a == "--threads" && number && n >= 1 && n <= 1024)
      max_threads = static_cast<int>(n);
    else if (a == "--repeat" && number && n >= 1 && n <= 100)
      repeat = static_cast<int>(n);
    else if (a == "--keep" && recording.empty())
      keep = v;
    else if (a == "--recording" && keep.empty())
      recording = v;
    else if (a == "--poses")
      poses = v;
    else
      return Usage(argv[0]);
  }
  cv::setNumThreads(1);

  // 1. The recording: the first `frames` frames of the default scenario, as PNG files.
  Scenario sc = Scenario::Default();
  if (frames > sc.NumFrames() && recording.empty()) {
    std::fprintf(stderr, "--frames %zu: the default scenario has %zu frames\n", frames, sc.NumFrames());
    return 2;
  }
  sc.times.resize(frames);
  sc.T_rig_target.resize(frames);
  const fs::path dir = !recording.empty() ? recording
                       : !keep.empty()    ? keep
                                          : fs::temp_directory_path() / ("mcms_bench_throughput_" + std::to_string(::getpid()));
  struct Cleanup {
    fs::path d;
    ~Cleanup() {
      std::error_code ec;
      if (!d.empty()) fs::remove_all(d, ec);
    }
  } cleanup{keep.empty() && recording.empty() ? dir : fs::path()};
  if (recording.empty()) {
    std::printf("rendering %zu frames of Scenario::Default() into %s ...\n", frames, dir.string().c_str());
    std::fflush(stdout);
    RenderSequence(sc, dir, true, max_threads);
  }

  const double gain = fs::exists(dir / "scenario.yaml") ? Scenario::Read(dir / "scenario.yaml").render.gain_e_per_dn
                                                        : sc.render.gain_e_per_dn;
  const CameraRig rig = CameraRig::Read(dir / "rig.yaml");
  const Target target = Target::Read(dir / "target.yaml");
  ImageSequence seq = ScanImageSequence({dir / "images", dir / "frames.csv", 10.0}, rig);
  if (frames_given && seq.frames.size() > frames) {
    seq.frames.resize(frames);
    seq.times_s.resize(frames);
    seq.image_names.resize(frames * seq.cameras());
  }
  const size_t n = seq.frames.size();
  const size_t ncam = seq.cameras();
  uintmax_t file_bytes = 0;
  std::vector<std::vector<cv::Mat>> decoded(n);
  for (size_t i = 0; i < n; ++i) {
    std::vector<std::string> problems;
    decoded[i] = LoadFrameImages(seq, i, &problems);
    for (size_t c = 0; c < ncam; ++c) {
      if (decoded[i][c].empty()) {
        std::fprintf(stderr, "frame %zu camera %zu: %s\n", i, c, problems[c].c_str());
        return 1;
      }
      file_bytes += fs::file_size(seq.ImagePath(i, c));
    }
  }
  const cv::Mat& first = decoded[0][0];
  const double pixel_bytes = static_cast<double>(n * ncam * first.total() * first.elemSize());
  std::printf("%zu frame sets x %zu cameras %dx%d %s; PNG files %.1f MB, decoded %.1f MB\n", n, ncam, first.cols,
              first.rows, first.depth() == CV_8U ? "8-bit" : "16-bit", static_cast<double>(file_bytes) / 1e6,
              pixel_bytes / 1e6);

  // 1b. The same frames as binary PGM and as uncompressed TIFF files (what `mcms render
  // --format pgm|tiff` writes), in a temporary folder.
  const fs::path formats_dir = fs::temp_directory_path() / ("mcms_bench_throughput_formats_" + std::to_string(::getpid()));
  const Cleanup formats_cleanup{formats_dir};
  auto write_copy = [&](ImageFileFormat format) {
    const fs::path images = formats_dir / ToString(format);
    for (const std::string& name : rig.names) fs::create_directories(images / name);
    for (size_t i = 0; i < n; ++i)
      for (size_t c = 0; c < ncam; ++c)
        WriteImageFile(images / rig.names[c] / fs::path(seq.image_names[i * ncam + c]).stem().concat(ExtensionOf(format)),
                       decoded[i][c], format);
    ImageSequence copy = ScanImageSequence({images, dir / "frames.csv", 10.0}, rig);
    if (copy.frames != seq.frames) throw std::runtime_error("the copies' frames differ from the recording's");
    return copy;
  };
  const ImageSequence seq_pgm = write_copy(ImageFileFormat::kPgm), seq_tiff = write_copy(ImageFileFormat::kTiff);

  // 2. The sources: every reader and format, and memory.
  FrameSource memory;
  memory.count = n;
  memory.frame = [&](size_t i) { return seq.frames[i]; };
  memory.time_s = [&](size_t i) { return seq.times_s[i]; };
  memory.images = [&](size_t i, std::vector<std::string>*) { return decoded[i]; };
  // A source of the PNG files decoded by `decode` (path -> image, empty when refused).
  auto png_source = [&](std::function<cv::Mat(const fs::path&)> decode) {
    FrameSource s = memory;
    s.images = [&seq, ncam, decode](size_t i, std::vector<std::string>* problems) {
      std::vector<cv::Mat> images(ncam);
      for (size_t c = 0; c < ncam; ++c) {
        images[c] = decode(seq.ImagePath(i, c));
        if (images[c].empty()) (*problems)[c] = "cannot decode " + seq.ImagePath(i, c).string();
      }
      return images;
    };
    return s;
  };
  auto opencv_decode = [](const fs::path& p) { return cv::imread(p.string(), cv::IMREAD_UNCHANGED); };
  struct Source {
    std::string name;
    FrameSource frames;
    std::function<cv::Mat(size_t, size_t)> decode_one;  // (frame index, camera) -> image
  };
  auto decode_file = [](const ImageSequence& s) {
    return [&s](size_t i, size_t c) {
      std::string problem;
      ImageFileOptions o;
      o.expected_size = s.image_sizes[c];
      return ReadImageFile(s.ImagePath(i, c), o, &problem);
    };
  };
  std::vector<Source> sources = {
      {"png", FilesOf(seq), decode_file(seq)},
      {"png/opencv", png_source(opencv_decode), [&](size_t i, size_t c) { return opencv_decode(seq.ImagePath(i, c)); }},
  };
#ifdef MCMS_HAVE_SPNG
  sources.push_back({"png/libspng", png_source(DecodeWithSpng), [&](size_t i, size_t c) { return DecodeWithSpng(seq.ImagePath(i, c)); }});
#endif
  sources.push_back({"pgm", FilesOf(seq_pgm), decode_file(seq_pgm)});
  sources.push_back({"tiff", FilesOf(seq_tiff), decode_file(seq_tiff)});
  sources.push_back({"memory", memory, [&](size_t i, size_t c) { return decoded[i][c]; }});
  // Every reader gives the same pixels (the tracking results are compared below too).
  for (const Source& src : sources)
    for (size_t c = 0; c < ncam; ++c) {
      const cv::Mat im = src.decode_one(0, c);
      if (im.empty() || im.size() != decoded[0][c].size() || im.type() != decoded[0][c].type() ||
          cv::norm(im, decoded[0][c], cv::NORM_INF) != 0) {
        std::fprintf(stderr, "reader %s: frame 0 camera %zu differs from the recording's decode\n", src.name.c_str(), c);
        return 1;
      }
    }

  std::vector<FrameResult> reference;  // ours, in memory, 1 thread
  bool identical = true;
  size_t max_held = 0;
  auto ours = [&](const FrameSource& src, int threads, bool check) {
    Tracker tracker(rig, target, OurOptions(gain));
    size_t k = 0;
    const size_t held = TrackFramesStreaming(
        src, tracker,
        [&](FrameResult&& r) {
          if (check) {
            if (reference.size() < n) {
              reference.push_back(std::move(r));
            } else {
              const FrameResult& e = reference[k];
              identical = identical && r.frame == e.frame && r.status == e.status &&
                          r.T_rig_target.has_value() == e.T_rig_target.has_value() && r.cov == e.cov &&
                          (!r.T_rig_target || (r.T_rig_target->R == e.T_rig_target->R && r.T_rig_target->t == e.T_rig_target->t));
            }
          }
          ++k;
        },
        {}, threads);
    max_held = std::max(max_held, held);
  };
  std::atomic<size_t> posed_baseline{0};
  auto baseline = [&](bool from_files, int threads) {
    ParallelFor(n, threads, [&](size_t i) {
      const bench::Baseline base(rig, target);  // per frame set: nothing shared between threads
      std::vector<cv::Mat> images(ncam);
      for (size_t c = 0; c < ncam; ++c)
        images[c] = from_files ? cv::imread(seq.ImagePath(i, c).string(), cv::IMREAD_UNCHANGED) : decoded[i][c];
      const bench::Baseline::Result r = base.Process(images);
      posed_baseline += r.id.has_value();
    });
  };

  ours(memory, 1, true);  // the reference (and a warm-up)
  if (!poses.empty()) WritePoseCsv(poses, reference);
  std::vector<Row> rows;
  for (const Source& src : sources)
    for (int t = 1; t <= max_threads; ++t) {
      Row row{src.name, t, Measure(repeat, [&] { ours(src.frames, t, true); }), std::nullopt};
      if (src.name == "png" || src.name == "memory")
        row.base = Measure(repeat, [&] { baseline(src.name == "png", t); });
      rows.push_back(row);
      std::printf("  measured %-11s %d thread(s)\n", row.source.c_str(), t);
      std::fflush(stdout);
    }
  // Ours with TrackerOptions::predicted_windows (detection in windows around the predicted
  // ball images; the whole image every 25th frame and where the windows miss a ball).
  struct WindowRow {
    std::string source;
    int threads;
    Timing t;
  };
  std::vector<WindowRow> window_rows;
  std::vector<FrameResult> windowed;
  size_t window_dets = 0, whole_dets = 0;
  auto ours_windows = [&](const FrameSource& src, int threads) {
    TrackerOptions o = OurOptions(gain);
    o.predicted_windows = true;
    Tracker tracker(rig, target, o);
    windowed.clear();
    TrackFramesStreaming(src, tracker, [&](FrameResult&& r) { windowed.push_back(std::move(r)); }, {}, threads);
    window_dets = tracker.window_detections();
    whole_dets = tracker.whole_image_detections();
  };
  // From PNG files twice: every frame decoded whole ("png"), and read in part ("png/rows":
  // FilesOf's image_rows, what `mcms track --predicted-windows` does: only the rows the
  // detector reads are unfiltered).
  FrameSource png_whole = FilesOf(seq);
  png_whole.image_rows = nullptr;
  std::vector<std::pair<std::string, const FrameSource*>> window_sources;
  std::vector<FrameResult> windowed_png;  // "png" with predicted windows, to compare "png/rows" with
  bool rows_identical = true;
  for (const Source& src : sources) {
    if (src.name == "png") {
      window_sources.push_back({"png", &png_whole});
      window_sources.push_back({"png/rows", &src.frames});
    } else if (src.name == "pgm" || src.name == "memory") {
      window_sources.push_back({src.name, &src.frames});
    }
  }
  for (const auto& [name, frames_source] : window_sources) {
    for (int t : max_threads > 1 ? std::vector<int>{1, max_threads} : std::vector<int>{1}) {
      window_rows.push_back({name, t, Measure(repeat, [&] { ours_windows(*frames_source, t); })});
      std::printf("  measured %-11s %d thread(s), predicted windows\n", window_rows.back().source.c_str(), t);
      std::fflush(stdout);
      if (name == "png") windowed_png = windowed;
      if (name == "png/rows") {
        // Exactly the results of the frames decoded whole, frame for frame.
        rows_identical = rows_identical && windowed.size() == windowed_png.size();
        for (size_t i = 0; rows_identical && i < windowed.size(); ++i) {
          const FrameResult &a = windowed[i], &b = windowed_png[i];
          rows_identical = a.status == b.status && a.reason == b.reason && a.cov == b.cov &&
                           a.T_rig_target.has_value() == b.T_rig_target.has_value() &&
                           (!a.T_rig_target || (a.T_rig_target->R == b.T_rig_target->R && a.T_rig_target->t == b.T_rig_target->t));
        }
      }
    }
  }
  // The rows a run with predicted windows asks for, per frame and camera (each request: row
  // ranges; every row when the camera is detected whole), recorded in one thread, to time
  // the decoding they need alone; and how many rows they unfilter.
  std::vector<std::vector<std::vector<std::vector<cv::Range>>>> asked(n, std::vector<std::vector<std::vector<cv::Range>>>(ncam));
  size_t rows_unfiltered = 0, rows_total = 0;
  {
    TrackerOptions o = OurOptions(gain);
    o.predicted_windows = true;
    Tracker tracker(rig, target, o);
    for (size_t i = 0; i < n; ++i) {
      std::vector<std::string> problems;
      std::vector<ImageFileRows> frame_rows = LoadFrameRows(seq, i, &problems);
      std::vector<cv::Mat> images;
      for (const ImageFileRows& r : frame_rows) images.push_back(r.image());
      tracker.ProcessFrame(seq.frames[i], seq.times_s[i], images, problems,
                           [&](size_t c, const std::vector<cv::Range>* rows) {
                             asked[i][c].push_back(rows ? *rows : std::vector<cv::Range>{cv::Range(0, images[c].rows)});
                             frame_rows[c].Prepare(asked[i][c].back());
                           });
      for (const ImageFileRows& r : frame_rows) {
        rows_unfiltered += r.rows_ready();
        rows_total += static_cast<size_t>(r.image().rows);
      }
    }
  }
  // The decoding alone, one thread: every image of every frame set, then one byte read per
  // 4 KB page of its pixels (so that a mapped file's page faults count, as in tracking).
  struct DecodeRow {
    std::string reader;
    Timing t;
  };
  std::vector<DecodeRow> decode_rows;
  volatile unsigned sink = 0;
  auto decode_all = [&](const std::function<cv::Mat(size_t, size_t)>& decode) {
    unsigned sum = 0;
    for (size_t i = 0; i < n; ++i)
      for (size_t c = 0; c < ncam; ++c) {
        const cv::Mat im = decode(i, c);
        const size_t bytes = im.total() * im.elemSize();
        for (size_t b = 0; b < bytes; b += 4096) sum += im.data[b];
      }
    sink = sink + sum;
  };
  for (const Source& src : sources)
    if (src.name != "memory") decode_rows.push_back({src.name, Measure(repeat, [&] { decode_all(src.decode_one); })});
  // Ours read in part: the file read, checked and inflated, no row unfiltered ("png/inflate",
  // the floor); then the rows the run with predicted windows asked for ("png/rows").
  auto decode_in_part = [&](bool prepare) {
    unsigned sum = 0;
    for (size_t i = 0; i < n; ++i) {
      std::vector<std::string> problems;
      std::vector<ImageFileRows> frame_rows = LoadFrameRows(seq, i, &problems);
      for (size_t c = 0; c < ncam; ++c) {
        if (prepare)
          for (const std::vector<cv::Range>& rows : asked[i][c]) frame_rows[c].Prepare(rows);
        sum += frame_rows[c].rows_ready();
      }
    }
    sink = sink + sum;
  };
  decode_rows.push_back({"png/inflate", Measure(repeat, [&] { decode_in_part(false); })});
  decode_rows.push_back({"png/rows", Measure(repeat, [&] { decode_in_part(true); })});
  decode_rows.push_back({"pgm/opencv", Measure(repeat, [&] {
                           decode_all([&](size_t i, size_t c) { return opencv_decode(seq_pgm.ImagePath(i, c)); });
                         })});
  decode_rows.push_back({"tiff/opencv", Measure(repeat, [&] {
                           decode_all([&](size_t i, size_t c) { return opencv_decode(seq_tiff.ImagePath(i, c)); });
                         })});

  // 3. The tables.
  const double dn = static_cast<double>(n);
  std::printf("\n==== bench_throughput: %zu frame sets of %zu cameras, %d core(s), median of %d runs ====\n", n, ncam,
              static_cast<int>(std::thread::hardware_concurrency()), repeat);
  std::printf("%-11s %7s | %12s %12s %8s | %14s %14s %8s\n", "source", "threads", "ours fps", "baseline fps",
              "ratio", "ours CPU ms/set", "base CPU ms/set", "CPU ratio");
  for (const Row& r : rows) {
    const double of = dn / r.ours.wall_s;
    if (r.base) {
      const double bf = dn / r.base->wall_s;
      std::printf("%-11s %7d | %12.1f %12.1f %7.1fx | %14.3f %14.3f %7.1fx\n", r.source.c_str(), r.threads, of, bf,
                  of / bf, 1e3 * r.ours.cpu_s / dn, 1e3 * r.base->cpu_s / dn, r.base->cpu_s / r.ours.cpu_s);
    } else {
      std::printf("%-11s %7d | %12.1f %12s %8s | %14.3f %14s %8s\n", r.source.c_str(), r.threads, of, "-", "-",
                  1e3 * r.ours.cpu_s / dn, "-", "-");
    }
  }
  auto find = [&](const std::string& src, int threads) -> const Row* {
    for (const Row& r : rows)
      if (r.source == src && r.threads == threads) return &r;
    return nullptr;
  };
  std::printf("scaling, wall-clock rate on %d threads / on 1 thread:\n", max_threads);
  for (const Source& src : sources) {
    const Row *one = find(src.name, 1), *all = find(src.name, max_threads);
    if (!one || !all) continue;
    std::printf("  %-11s ours %.2fx", src.name.c_str(), one->ours.wall_s / all->ours.wall_s);
    if (one->base && all->base) std::printf(", baseline %.2fx", one->base->wall_s / all->base->wall_s);
    std::printf("\n");
  }
  if (const Row *png = find("png", 1), *mem = find("memory", 1); png && mem && png->base) {
    std::printf("from PNG files, 1 thread: %.1f frame sets/s, %.2fx OpenCV's imread pipeline (%.1f)\n",
                dn / png->ours.wall_s, png->base->wall_s / png->ours.wall_s, dn / png->base->wall_s);
    for (const char* src : {"pgm", "tiff"})
      if (const Row* r = find(src, 1))
        std::printf("from %s files, 1 thread: %.1f frame sets/s, %.2fx slower than in memory (%.1f)\n", src,
                    dn / r->ours.wall_s, r->ours.wall_s / mem->ours.wall_s, dn / mem->ours.wall_s);
  }
  std::printf("ours with predicted windows (mcms track --predicted-windows):\n");
  for (const WindowRow& w : window_rows) {
    const Row* full = find(w.source == "png/rows" ? "png" : w.source, w.threads);
    const Row* png = find("png", w.threads);
    const double f = dn / w.t.wall_s;
    std::printf("%-11s %7d | %12.1f fps, %.3f ms CPU/set; %.2fx the whole-image rate, %.1fx the baseline from PNG\n",
                w.source.c_str(), w.threads, f, 1e3 * w.t.cpu_s / dn, full ? full->ours.wall_s / w.t.wall_s : 0.0,
                png && png->base ? png->base->wall_s / w.t.wall_s : 0.0);
  }
  double max_dp = 0, max_dr = 0;
  size_t same_status = 0;
  for (size_t i = 0; i < std::min(windowed.size(), reference.size()); ++i) {
    same_status += windowed[i].status == reference[i].status;
    if (windowed[i].T_rig_target && reference[i].T_rig_target) {
      max_dp = std::max(max_dp, (windowed[i].T_rig_target->t - reference[i].T_rig_target->t).norm());
      max_dr = std::max(max_dr, BoxMinus(*windowed[i].T_rig_target, *reference[i].T_rig_target).head<3>().norm());
    }
  }
  std::printf("  detections in windows %zu, whole images %zu (last run); same status as the whole-image "
              "run on %zu/%zu frame sets, poses differ by at most %.3g m and %.3g rad\n",
              window_dets, whole_dets, same_status, n, max_dp, max_dr);
  std::printf("  png/rows: %zu of %zu rows unfiltered (%.1f%%), the rest inflated only; results identical to png "
              "(frames decoded whole): %s\n", rows_unfiltered, rows_total,
              100.0 * static_cast<double>(rows_unfiltered) / static_cast<double>(std::max<size_t>(rows_total, 1)),
              rows_identical ? "yes" : "NO");
  std::printf("decoding alone, 1 thread (then one byte read per 4 KB page of the pixels; png/inflate and "
              "png/rows: ImageFileRows, no page read):\n");
  std::printf("  %-12s %12s %14s %14s\n", "reader", "sets/s", "ms per set", "pixels MB/s");
  for (const DecodeRow& d : decode_rows)
    std::printf("  %-12s %12.1f %14.3f %14.0f\n", d.reader.c_str(), dn / d.t.wall_s, 1e3 * d.t.wall_s / dn,
                pixel_bytes / 1e6 / d.t.wall_s);
  size_t posed = 0;
  for (const FrameResult& r : reference) posed += r.T_rig_target.has_value();
  std::printf("ours posed %zu/%zu frame sets; results on every thread count, reader and source identical to 1 "
              "thread in memory, in frame order: %s; at most %zu frame sets held at once\n",
              posed, n, identical ? "yes" : "NO", max_held);
  return identical && rows_identical ? 0 : 1;
}

}  // namespace
}  // namespace mcms

int main(int argc, char** argv) {
  try {
    return mcms::Main(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_throughput: %s\n", e.what());
    return 1;
  }
}
