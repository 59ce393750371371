// Speed and accuracy of the vision pipeline against an OpenCV baseline, one thread.
//
//   OURS      Tracker::ProcessFrame: DetectBlobs on each of the 4 images (1280 x 1024),
//             N-view MatchAndTriangulate with sphere-bias correction, IdentifyTarget,
//             RefinePose (bundle adjustment of the pose on all 2-D observations).
//   BASELINE  what an "OpenCV + hand-written script" pipeline does: cv::SimpleBlobDetector
//             on each image, cv::undistortPoints, one-to-one nearest-epipolar matching
//             between cameras 0 and 1, cv::triangulatePoints, the same distance-signature
//             identification (mcms::IdentifyTarget with an isotropic (0.2 mm)^2 point
//             covariance) and its closed-form rigid fit as the pose.
//
// Both run on the same frames of Scenario::Default(), rendered once before the
// benchmarks (every kFrameStride-th frame, so that the set spans the working volume).
// Accuracy against the renderer's truth is computed once, outside the timed loops, and
// attached to the pipeline benchmarks as counters. After the benchmarks, a summary block
// gives the rates and their ratios: fps of both pipelines, the image-scan rate of
// DetectBlobs next to this machine's memcpy rate, and a per-stage time breakdown of ours.
//
// Times are CPU time of the one benchmark thread (Google Benchmark's default), the figure
// that does not depend on what else the machine runs; wall time is printed beside it.
// OpenCV is held to one thread (cv::setNumThreads(1)) so that both pipelines run on a
// single core and the two times agree on an idle machine.
#include <numbers>
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <unistd.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "bench/opencv_baseline.h"
#include "core/pose_math.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "synthetic/scenario.h"
#include "tracking/identify.h"
#include "tracking/pose_refinement.h"
#include "tracking/tracker.h"
#include "vision/blob_detector.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms {
namespace {

using bench::Baseline;

constexpr size_t kNumFrames = 20;
constexpr size_t kFrameStride = 6;  // frames 0, 6, ..., 114 of the default 120

// ---------------------------------------------------------------------------------
// Data shared by every benchmark (rendered once in main before the benchmarks run).

struct BenchData {
  Scenario sc;
  std::vector<std::vector<cv::Mat>> images;  // [frame][camera]
  std::vector<FrameTruth> truth;
  // Precomputed inputs of the individual stages of our pipeline, per frame.
  std::vector<std::vector<std::vector<ImagePoint>>> points;           // [frame][camera]
  std::vector<std::vector<TriangulatedPoint>> triangulated;           // [frame]
  std::vector<std::optional<Identification>> identified;              // [frame]
  std::vector<std::vector<BallObservation>> observations;             // [frame]
  // images[0][0] with its balls painted over in its background level: what DetectBlobs
  // costs without any blob to measure (the scan and the global statistics).
  cv::Mat no_blobs;
  size_t blobs_in_first_image = 0;

  // Benchmarks cycle through the rendered frames; the tracker needs frames in time order,
  // so the k-th frame handed over (k counts on across cycles) gets the frame number and
  // the time of frame k % n shifted by whole cycles.
  size_t FrameAt(size_t k) const { return truth[k % truth.size()].frame + (k / truth.size()) * sc.NumFrames(); }
  double TimeAt(size_t k) const {
    const double dt = truth.size() > 1 ? truth[1].time_s - truth[0].time_s : 0.1;
    const double cycle = truth.back().time_s - truth.front().time_s + dt;
    return truth[k % truth.size()].time_s + static_cast<double>(k / truth.size()) * cycle;
  }
};

BenchData* g_data = nullptr;

TrackerOptions OurOptions(const Scenario& sc) {
  TrackerOptions o;
  o.detector.gain_e_per_dn = sc.render.gain_e_per_dn;
  return o;
}

// The tracker's own blob filter (tracking/tracker.cpp): cut or pulled centres are dropped.
std::vector<ImagePoint> DetectForTracker(const cv::Mat& image, const BlobDetectorOptions& o) {
  std::vector<ImagePoint> v;
  for (const Blob& b : DetectBlobs(image, o)) {
    if (b.touches_border || b.crowded) continue;
    v.push_back({b.centre, b.cov});
  }
  return v;
}

// ---------------------------------------------------------------------------------
// Accuracy against the truth (not timed).

struct Accuracy {
  int frames = 0, posed = 0;
  double pos_rms_m = 0, rot_rms_rad = 0, pos_max_m = 0, rot_max_rad = 0;
  int balls = 0;           // identified ball centres compared with the truth
  double ball_rms_m = 0;
};

class AccuracyAccumulator {
 public:
  void Add(const std::optional<Pose>& T, const std::vector<TriangulatedPoint>& points,
           const std::vector<int>& point_of_ball, const FrameTruth& truth) {
    ++a_.frames;
    if (T) {
      const Vec6 e = BoxMinus(*T, truth.T_rig_target);
      const double r = e.head<3>().norm(), p = e.tail<3>().norm();
      ++a_.posed;
      sr_ += r * r;
      sp_ += p * p;
      a_.rot_max_rad = std::max(a_.rot_max_rad, r);
      a_.pos_max_m = std::max(a_.pos_max_m, p);
    }
    for (size_t b = 0; b < point_of_ball.size() && b < truth.balls_rig.size(); ++b) {
      if (point_of_ball[b] < 0) continue;
      sb_ += (points[point_of_ball[b]].p_rig - truth.balls_rig[b]).squaredNorm();
      ++a_.balls;
    }
  }
  Accuracy Get() const {
    Accuracy a = a_;
    if (a.posed > 0) {
      a.pos_rms_m = std::sqrt(sp_ / a.posed);
      a.rot_rms_rad = std::sqrt(sr_ / a.posed);
    }
    if (a.balls > 0) a.ball_rms_m = std::sqrt(sb_ / a.balls);
    return a;
  }

 private:
  Accuracy a_;
  double sp_ = 0, sr_ = 0, sb_ = 0;
};

Accuracy g_ours_accuracy, g_baseline_accuracy;

Accuracy MeasureOurs(const BenchData& d) {
  Tracker tracker(d.sc.rig, d.sc.target, OurOptions(d.sc));
  AccuracyAccumulator acc;
  for (size_t f = 0; f < d.images.size(); ++f) {
    const FrameResult r = tracker.ProcessFrame(d.truth[f].frame, d.truth[f].time_s, d.images[f]);
    acc.Add(r.T_rig_target, r.points, r.point_of_ball, d.truth[f]);
  }
  return acc.Get();
}

Accuracy MeasureBaseline(const BenchData& d) {
  Baseline base(d.sc.rig, d.sc.target);
  AccuracyAccumulator acc;
  for (size_t f = 0; f < d.images.size(); ++f) {
    const Baseline::Result r = base.Process(d.images[f]);
    std::optional<Pose> T;
    std::vector<int> pob;
    if (r.id) {
      T = r.id->T_rig_target;
      pob = r.id->point_of_ball;
    }
    acc.Add(T, r.points, pob, d.truth[f]);
  }
  return acc.Get();
}

void SetAccuracyCounters(benchmark::State& state, const Accuracy& a) {
  state.counters["pos_rms_um"] = a.pos_rms_m * 1e6;
  state.counters["rot_rms_mdeg"] = a.rot_rms_rad * 180 / std::numbers::pi * 1e3;
  state.counters["ball_rms_um"] = a.ball_rms_m * 1e6;
  state.counters["posed_frames"] = a.posed;
}

// ---------------------------------------------------------------------------------
// The benchmarks. Every per-frame benchmark cycles through the rendered frames.

void BM_OursPipeline(benchmark::State& state) {
  const BenchData& d = *g_data;
  Tracker tracker(d.sc.rig, d.sc.target, OurOptions(d.sc));
  size_t k = 0;
  for (auto _ : state) {
    FrameResult r = tracker.ProcessFrame(d.FrameAt(k), d.TimeAt(k), d.images[k % d.images.size()]);
    benchmark::DoNotOptimize(r);
    ++k;
  }
  state.SetItemsProcessed(state.iterations());  // items/s = frames per second
  SetAccuracyCounters(state, g_ours_accuracy);
}
BENCHMARK(BM_OursPipeline)->Unit(benchmark::kMillisecond);

void BM_BaselinePipeline(benchmark::State& state) {
  const BenchData& d = *g_data;
  Baseline base(d.sc.rig, d.sc.target);
  size_t f = 0;
  for (auto _ : state) {
    Baseline::Result r = base.Process(d.images[f]);
    benchmark::DoNotOptimize(r);
    f = (f + 1) % d.images.size();
  }
  state.SetItemsProcessed(state.iterations());
  SetAccuracyCounters(state, g_baseline_accuracy);
}
BENCHMARK(BM_BaselinePipeline)->Unit(benchmark::kMillisecond);

// DetectBlobs alone on one 1280 x 1024 image: bytes/s is the image-scan rate.
void BM_DetectBlobs(benchmark::State& state) {
  const BenchData& d = *g_data;
  const cv::Mat& image = d.images[0][0];
  const BlobDetectorOptions o = OurOptions(d.sc).detector;
  for (auto _ : state) {
    std::vector<Blob> blobs = DetectBlobs(image, o);
    benchmark::DoNotOptimize(blobs);
  }
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(image.total() * image.elemSize()));
}
BENCHMARK(BM_DetectBlobs)->Unit(benchmark::kMicrosecond);

// The same on every image in turn (80 images, 105 MB: more than the caches hold), as
// the pipeline meets them: the image comes from main memory.
void BM_DetectBlobs_ColdImages(benchmark::State& state) {
  const BenchData& d = *g_data;
  const BlobDetectorOptions o = OurOptions(d.sc).detector;
  const size_t ncam = d.images[0].size();
  size_t k = 0;
  for (auto _ : state) {
    std::vector<Blob> blobs = DetectBlobs(d.images[k / ncam][k % ncam], o);
    benchmark::DoNotOptimize(blobs);
    k = (k + 1) % (d.images.size() * ncam);
  }
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(d.images[0][0].total()));
}
BENCHMARK(BM_DetectBlobs_ColdImages)->Unit(benchmark::kMicrosecond);

// One image without blobs (cached): the scan and the global statistics alone.
void BM_DetectBlobs_NoBlobs(benchmark::State& state) {
  const BenchData& d = *g_data;
  const BlobDetectorOptions o = OurOptions(d.sc).detector;
  for (auto _ : state) {
    std::vector<Blob> blobs = DetectBlobs(d.no_blobs, o);
    benchmark::DoNotOptimize(blobs);
  }
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(d.no_blobs.total()));
}
BENCHMARK(BM_DetectBlobs_NoBlobs)->Unit(benchmark::kMicrosecond);

// ---- Stages of our pipeline, for the breakdown (each on precomputed inputs).

void BM_Ours_Detect4(benchmark::State& state) {
  const BenchData& d = *g_data;
  const BlobDetectorOptions o = OurOptions(d.sc).detector;
  size_t f = 0;
  for (auto _ : state) {
    for (const cv::Mat& im : d.images[f]) {
      std::vector<ImagePoint> v = DetectForTracker(im, o);
      benchmark::DoNotOptimize(v);
    }
    f = (f + 1) % d.images.size();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Ours_Detect4)->Unit(benchmark::kMicrosecond);

// Everything after detection: Tracker::ProcessPoints.
void BM_Ours_ProcessPoints(benchmark::State& state) {
  const BenchData& d = *g_data;
  Tracker tracker(d.sc.rig, d.sc.target, OurOptions(d.sc));
  std::vector<std::vector<std::optional<std::vector<ImagePoint>>>> in(d.points.size());
  for (size_t f = 0; f < d.points.size(); ++f)
    for (const auto& v : d.points[f]) in[f].emplace_back(v);
  size_t k = 0;
  for (auto _ : state) {
    FrameResult r = tracker.ProcessPoints(d.FrameAt(k), d.TimeAt(k), in[k % in.size()]);
    benchmark::DoNotOptimize(r);
    ++k;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Ours_ProcessPoints)->Unit(benchmark::kMicrosecond);

// state.range(0) = 1: with the sphere-bias model, as the Tracker runs it; 0: without it
// (the plain projection of the centre), to show what the bias model costs.
void BM_Ours_MatchAndTriangulate(benchmark::State& state) {
  const BenchData& d = *g_data;
  MatchingOptions o = OurOptions(d.sc).matching;
  o.triangulation.sphere_radius_m = state.range(0) ? d.sc.target.ball_radius : 0.0;
  size_t f = 0;
  for (auto _ : state) {
    std::vector<TriangulatedPoint> p = MatchAndTriangulate(d.sc.rig, d.points[f], o);
    benchmark::DoNotOptimize(p);
    f = (f + 1) % d.images.size();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Ours_MatchAndTriangulate)->ArgName("sphere_bias")->Arg(1)->Arg(0)->Unit(benchmark::kMicrosecond);

void BM_Ours_IdentifyTarget(benchmark::State& state) {
  const BenchData& d = *g_data;
  const IdentificationOptions o = OurOptions(d.sc).identification;
  size_t f = 0;
  for (auto _ : state) {
    auto id = IdentifyTarget(d.sc.target, d.triangulated[f], o);
    benchmark::DoNotOptimize(id);
    f = (f + 1) % d.images.size();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Ours_IdentifyTarget)->Unit(benchmark::kMicrosecond);

// RefinePose from the closed-form fit on the identified points' 2-D views (the
// observations the tracker starts from; it adds predicted-near blobs only when some
// ball was not triangulated). state.range(0) = max_outer_iterations (4 is the default
// the Tracker uses; each outer iteration is one Ceres solve with the sphere bias
// re-linearized).
void BM_Ours_RefinePose(benchmark::State& state) {
  const BenchData& d = *g_data;
  PoseRefinementOptions o = OurOptions(d.sc).refinement;
  o.max_outer_iterations = static_cast<int>(state.range(0));
  std::vector<size_t> usable;
  for (size_t f = 0; f < d.identified.size(); ++f)
    if (d.identified[f]) usable.push_back(f);
  if (usable.empty()) {
    state.SkipWithError("no identified frame");
    return;
  }
  size_t k = 0;
  for (auto _ : state) {
    const size_t f = usable[k];
    PoseRefinement r = RefinePose(d.sc.rig, d.sc.target, d.identified[f]->T_rig_target, d.observations[f], o);
    benchmark::DoNotOptimize(r);
    k = (k + 1) % usable.size();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Ours_RefinePose)->ArgName("outer")->Arg(4)->Arg(1)->Unit(benchmark::kMicrosecond);

// One sphere-image bias (32 outline points), the unit cost of the sphere model: the
// matching evaluates it for every candidate view, TriangulateNView at every Gauss-Newton
// iteration, RefinePose once per observation and outer iteration.
void BM_Ours_SphereProjectionBias(benchmark::State& state) {
  const BenchData& d = *g_data;
  const CameraModel& cam = d.sc.rig.cameras[0];
  const Vec3 p_cam = cam.T_cam_rig() * d.truth[0].balls_rig[0];
  for (auto _ : state) {
    Vec2 q = SphereProjectionBias(cam, p_cam, d.sc.target.ball_radius, 32);
    benchmark::DoNotOptimize(q);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Ours_SphereProjectionBias)->Unit(benchmark::kMicrosecond);

// ---- Stages of the baseline.

void BM_Baseline_Detect4(benchmark::State& state) {
  const BenchData& d = *g_data;
  const Baseline base(d.sc.rig, d.sc.target);
  size_t f = 0;
  for (auto _ : state) {
    auto norm = base.Detect(d.images[f]);
    benchmark::DoNotOptimize(norm);
    f = (f + 1) % d.images.size();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Baseline_Detect4)->Unit(benchmark::kMillisecond);

void BM_Baseline_Solve(benchmark::State& state) {
  const BenchData& d = *g_data;
  const Baseline base(d.sc.rig, d.sc.target);
  std::vector<std::vector<std::vector<Vec2>>> norm;
  for (const auto& im : d.images) norm.push_back(base.Detect(im));
  size_t f = 0;
  for (auto _ : state) {
    Baseline::Result r = base.Solve(norm[f]);
    benchmark::DoNotOptimize(r);
    f = (f + 1) % d.images.size();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Baseline_Solve)->Unit(benchmark::kMicrosecond);

// ---- Memory-copy rate of this machine.

void BM_Memcpy(benchmark::State& state) {
  const size_t n = static_cast<size_t>(state.range(0));
  std::vector<unsigned char> src(n, 1), dst(n, 0);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), n);
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(n));
}
// One 1280 x 1024 8-bit image (cache-resident, as the image in BM_DetectBlobs), and
// 64 MiB (main memory).
BENCHMARK(BM_Memcpy)->Arg(1280 * 1024)->Arg(64 << 20)->Unit(benchmark::kMicrosecond);

// ---------------------------------------------------------------------------------
// Reporter that keeps the CPU time per iteration of every run for the summary.

class RecordingReporter : public benchmark::ConsoleReporter {
 public:
  // Colours only on a terminal (a custom display reporter does not see --benchmark_color).
  RecordingReporter() : ConsoleReporter(isatty(fileno(stdout)) ? OO_ColorTabular : OO_Tabular) {}
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      if (r.run_type != Run::RT_Iteration || r.error_occurred || r.iterations <= 0) continue;
      seconds_[r.run_name.function_name + (r.run_name.args.empty() ? "" : "/" + r.run_name.args)].push_back(
          r.cpu_accumulated_time / static_cast<double>(r.iterations));
    }
    ConsoleReporter::ReportRuns(runs);
  }
  // Median over repetitions; nullopt when the benchmark did not run (filtered out).
  std::optional<double> Seconds(const std::string& name) const {
    auto it = seconds_.find(name);
    if (it == seconds_.end() || it->second.empty()) return std::nullopt;
    std::vector<double> v = it->second;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  }

 private:
  std::map<std::string, std::vector<double>> seconds_;
};

void PrintSummary(const RecordingReporter& rep) {
  auto s = [&](const std::string& name) { return rep.Seconds(name); };
  const BenchData& d = *g_data;
  const double image_bytes = static_cast<double>(d.images[0][0].total() * d.images[0][0].elemSize());
  const double big_bytes = static_cast<double>(64 << 20);
  std::printf("\n==== bench_pipeline summary: %zu cameras %dx%d, %zu frames of Scenario::Default(), one thread, "
              "CPU time ====\n",
              d.sc.rig.size(), d.images[0][0].cols, d.images[0][0].rows, d.images.size());
  const auto ours = s("BM_OursPipeline"), base = s("BM_BaselinePipeline");
  if (ours) std::printf("ours      %9.1f fps  (%8.3f ms/frame)\n", 1.0 / *ours, *ours * 1e3);
  if (base) std::printf("baseline  %9.1f fps  (%8.3f ms/frame)\n", 1.0 / *base, *base * 1e3);
  if (ours && base)
    std::printf("speed ratio ours/baseline: %.2fx (requirement >= 10x: %s)\n", *base / *ours,
                *base / *ours >= 10 ? "met" : "NOT MET");
  auto acc = [](const char* name, const Accuracy& a) {
    std::printf("%-9s posed %2d/%2d frames  pose position RMS %7.2f um (max %7.2f)  rotation RMS %7.3f mdeg "
                "(max %7.3f)  ball centres RMS %7.2f um (%d)\n",
                name, a.posed, a.frames, a.pos_rms_m * 1e6, a.pos_max_m * 1e6, a.rot_rms_rad * 180 / std::numbers::pi * 1e3,
                a.rot_max_rad * 180 / std::numbers::pi * 1e3, a.ball_rms_m * 1e6, a.balls);
  };
  acc("ours", g_ours_accuracy);
  acc("baseline", g_baseline_accuracy);
  const Accuracy& o = g_ours_accuracy;
  const Accuracy& b = g_baseline_accuracy;
  if (o.pos_rms_m > 0 && o.rot_rms_rad > 0 && o.ball_rms_m > 0)
    std::printf("error ratio baseline/ours: position %.2fx, rotation %.2fx, ball centres %.2fx (%s)\n",
                b.pos_rms_m / o.pos_rms_m, b.rot_rms_rad / o.rot_rms_rad, b.ball_rms_m / o.ball_rms_m,
                o.posed >= b.posed && o.pos_rms_m <= b.pos_rms_m && o.rot_rms_rad <= b.rot_rms_rad &&
                        o.ball_rms_m <= b.ball_rms_m
                    ? "ours equal or better everywhere"
                    : "ours WORSE somewhere");

  const auto det = s("BM_DetectBlobs"), cold = s("BM_DetectBlobs_ColdImages"), empty = s("BM_DetectBlobs_NoBlobs");
  const auto mc = s("BM_Memcpy/1310720"), mcl = s("BM_Memcpy/67108864");
  auto rate = [](const char* what, double bytes, std::optional<double> t) {
    if (t) std::printf("  %-52s %7.2f GB/s  (%7.1f us)\n", what, bytes / *t / 1e9, *t * 1e6);
  };
  std::printf("image scan rate (bytes of image per second) and memory-copy rate:\n");
  rate("DetectBlobs, one image, cached", image_bytes, det);
  rate("DetectBlobs, 80 images in turn (from main memory)", image_bytes, cold);
  rate("DetectBlobs, one image without blobs, cached", image_bytes, empty);
  rate("memcpy 1280x1024 bytes (cached)", image_bytes, mc);
  rate("memcpy 64 MiB (main memory)", big_bytes, mcl);
  if (det && mc) std::printf("  scan/memcpy, cached:              %.3f\n", *mc / *det);
  if (cold && mcl)
    std::printf("  scan/memcpy, main memory:         %.3f\n", (image_bytes / *cold) / (big_bytes / *mcl));

  std::printf("breakdown of ours (each stage timed alone on precomputed inputs; %% of ProcessFrame):\n");
  auto line = [&](const std::string& what, std::optional<double> t, double per = 1.0) {
    if (!t) return;
    std::printf("  %-58s %8.1f us", what.c_str(), *t * per * 1e6);
    if (ours) std::printf("  %5.1f %%", 100 * *t * per / *ours);
    std::printf("\n");
  };
  const auto d4 = s("BM_Ours_Detect4"), pp = s("BM_Ours_ProcessPoints");
  const auto mt = s("BM_Ours_MatchAndTriangulate/sphere_bias:1"), mt0 = s("BM_Ours_MatchAndTriangulate/sphere_bias:0");
  const auto id = s("BM_Ours_IdentifyTarget"), rp = s("BM_Ours_RefinePose/outer:4"), rp1 = s("BM_Ours_RefinePose/outer:1");
  const auto bias = s("BM_Ours_SphereProjectionBias");
  const double ncam = static_cast<double>(d.sc.rig.size());
  line("DetectBlobs x" + std::to_string(d.sc.rig.size()) + " (images from main memory)", d4);
  if (empty && det && d.blobs_in_first_image > 0) {
    const std::string per = std::to_string(d.sc.rig.size()) + " images x ";
    line("  " + per + "scan + global statistics (no blobs, cached)", empty, ncam);
    line("  " + per + "measuring " + std::to_string(d.blobs_in_first_image) + " blobs (cached - no blobs)",
         *det - *empty, ncam);
    if (cold) line("  " + per + "reading from main memory (cold - cached)", *cold - *det, ncam);
  }
  line("ProcessPoints (everything after detection)", pp);
  line("  MatchAndTriangulate (with the sphere-bias model)", mt);
  if (mt && mt0) line("    of which the sphere-bias model (with - without)", *mt - *mt0);
  line("  IdentifyTarget", id);
  line("  RefinePose (4 outer iterations, the default)", rp);
  if (rp && rp1) line("    of which outer iterations 2..4 (4 - 1)", *rp - *rp1);
  if (pp && mt && id && rp) line("  rest of ProcessPoints (association, copies)", *pp - *mt - *id - *rp);
  if (bias) std::printf("  (one SphereProjectionBias with 32 outline points: %.2f us)\n", *bias * 1e6);

  std::printf("breakdown of the baseline (%% of the baseline's frame time):\n");
  auto bline = [&](const char* what, std::optional<double> t) {
    if (!t) return;
    std::printf("  %-58s %8.1f us", what, *t * 1e6);
    if (base) std::printf("  %5.1f %%", 100 * *t / *base);
    std::printf("\n");
  };
  bline("SimpleBlobDetector + undistortPoints x4", s("BM_Baseline_Detect4"));
  bline("epipolar matching, triangulatePoints, identification", s("BM_Baseline_Solve"));
}

void Prepare(BenchData* d) {
  d->sc = Scenario::Default();
  ScenarioRenderer renderer(d->sc, 2);
  const TrackerOptions opts = OurOptions(d->sc);
  MatchingOptions mo = opts.matching;
  mo.triangulation.sphere_radius_m = d->sc.target.ball_radius;
  for (size_t k = 0; k < kNumFrames; ++k) {
    const size_t f = (k * kFrameStride) % d->sc.NumFrames();
    RenderedFrame rf = renderer.Render(f);
    d->images.push_back(std::move(rf.images));
    d->truth.push_back(std::move(rf.truth));
    std::vector<std::vector<ImagePoint>> pts;
    for (const cv::Mat& im : d->images.back()) pts.push_back(DetectForTracker(im, opts.detector));
    d->triangulated.push_back(MatchAndTriangulate(d->sc.rig, pts, mo));
    d->identified.push_back(IdentifyTarget(d->sc.target, d->triangulated.back(), opts.identification));
    std::vector<BallObservation> obs;
    if (const auto& id = d->identified.back())
      for (size_t b = 0; b < id->point_of_ball.size(); ++b) {
        if (id->point_of_ball[b] < 0) continue;
        for (const auto& o : d->triangulated.back()[id->point_of_ball[b]].observations)
          obs.push_back({o.camera, static_cast<int>(b), pts[o.camera][o.index].q, pts[o.camera][o.index].cov});
      }
    d->observations.push_back(std::move(obs));
    d->points.push_back(std::move(pts));
  }
  // The first image with every blob painted over (a disc 3 radii wide) in the background level.
  const cv::Mat& first = d->images[0][0];
  BlobImageStats stats;
  const std::vector<Blob> blobs = DetectBlobs(first, opts.detector, &stats);
  d->blobs_in_first_image = blobs.size();
  d->no_blobs = first.clone();
  for (const Blob& b : blobs)
    cv::circle(d->no_blobs, cv::Point(static_cast<int>(std::lround(b.centre.x())), static_cast<int>(std::lround(b.centre.y()))),
               static_cast<int>(std::ceil(3 * b.radius_px)) + 3, cv::Scalar(std::round(stats.background_dn)), cv::FILLED);
  if (!DetectBlobs(d->no_blobs, opts.detector).empty())
    std::fprintf(stderr, "warning: the image without blobs still has blobs\n");
}

}  // namespace
}  // namespace mcms

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  cv::setNumThreads(1);
  mcms::BenchData data;
  std::printf("rendering %zu frames of Scenario::Default() ...\n", mcms::kNumFrames);
  std::fflush(stdout);
  mcms::Prepare(&data);
  mcms::g_data = &data;
  mcms::g_ours_accuracy = mcms::MeasureOurs(data);
  mcms::g_baseline_accuracy = mcms::MeasureBaseline(data);
  mcms::RecordingReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  mcms::PrintSummary(reporter);
  benchmark::Shutdown();
  return 0;
}
