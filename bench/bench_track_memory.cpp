// Peak memory of tracking long recordings: `mcms track` (which streams each frame's row to
// the output as it finishes) against the old store-everything path (TrackImageSequence
// keeping every FrameResult, then WritePoseCsv) as the named peer, in the same run, on the
// same recordings. Not a test: the figures depend on the machine.
//
// The recording is cheap on purpose: `mcms render` of 10 frames of a 4-camera rig cropped to
// 320 x 256 pixels (the default lens, so the balls' images are as large as in the default
// 1280 x 1024 recording), and a recording of N frame sets whose images are symbolic links to
// those 10 (frames.csv at 10 Hz). Memory per frame result does not depend on the image size;
// time does, so sizes of 100,000 frame sets take minutes.
//
// Every run is a child process (posix_spawn) whose peak resident set is wait4's ru_maxrss
// (the library paths also print their own VmHWM in their log). The peer keeps the compact
// image listing of this version; the listing before it kept a std::filesystem::path per
// image, another 2.8 KB per frame set.
//
//   bench_track_memory [--sizes 100,10000,100000] [--threads N] [--paths cli,stream,store]
//                      [--dir SCRATCH] [--mcms PATH]
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/io.h"
#include "synthetic/scenario.h"
#include "tracking/noise_estimate.h"
#include "tracking/sequence.h"
#include "tracking/tracker.h"

extern char** environ;

namespace mcms {
namespace {

namespace fs = std::filesystem;

constexpr size_t kDistinctFrames = 10;

double VmHwmMb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

std::string Replace(std::string s, const std::string& from, const std::string& to) {
  const size_t p = s.find(from);
  if (p == std::string::npos) Throw("bench: the default scenario has no '", from, "' any more; update the bench");
  return s.replace(p, from.size(), to);
}

struct ChildRun {
  int status = -1;
  double seconds = 0;
  double maxrss_mb = 0;
};

ChildRun Spawn(const std::vector<std::string>& args, const fs::path& log) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, 2, (log.string() + ".err").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  const auto t0 = std::chrono::steady_clock::now();
  pid_t pid = 0;
  if (posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ) != 0) Throw("bench: cannot run ", args[0]);
  posix_spawn_file_actions_destroy(&fa);
  ChildRun r;
  struct rusage ru {};
  if (wait4(pid, &r.status, 0, &ru) != pid) Throw("bench: wait4 failed for ", args[0]);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.maxrss_mb = static_cast<double>(ru.ru_maxrss) / 1024.0;  // KB on Linux
  return r;
}

// The 10-frame base recording, rendered by `mcms render` in a child process.
fs::path RenderBase(const fs::path& scratch, const std::string& mcms) {
  const fs::path base = scratch / "base";
  if (fs::exists(base / "frames.csv")) return base;
  std::string text = Scenario::DefaultText();
  text = Replace(text, "imagersize: [1280, 1024]", "imagersize: [320, 256]");
  text = Replace(text, "639.5, 511.5", "159.5, 127.5");
  text = Replace(text, "frames: 120", "frames: " + std::to_string(kDistinctFrames));
  text = Replace(text, "amplitude_m: [0.3, 0.2, 0.3]", "amplitude_m: [0.03, 0.03, 0.03]");
  text = Replace(text, "rotation_amplitude_deg: 30", "rotation_amplitude_deg: 10");
  fs::create_directories(scratch);
  const fs::path scenario = scratch / "small.yaml";
  std::ofstream(scenario) << text;
  const ChildRun r = Spawn({mcms, "render", "--quiet", scenario.string(), "-o", base.string()}, scratch / "render.log");
  if (r.status != 0) Throw("bench: mcms render failed; see ", (scratch / "render.log.err").string());
  return base;
}

// A recording of n frame sets whose images link to the base's.
fs::path MakeLongRecording(const fs::path& base, const fs::path& scratch, size_t n) {
  const fs::path d = scratch / ("rec_" + std::to_string(n));
  if (fs::exists(d / "frames.csv")) return d;
  fs::remove_all(d);
  fs::create_directories(d);
  for (const char* f : {"rig.yaml", "target.yaml"}) fs::copy_file(base / f, d / f);
  std::vector<std::string> cams;
  for (const auto& e : fs::directory_iterator(base / "images")) cams.push_back(e.path().filename().string());
  char name[32];
  for (const auto& c : cams) {
    fs::create_directories(d / "images" / c);
    for (size_t i = 0; i < n; ++i) {
      std::snprintf(name, sizeof(name), "%06zu.png", i % kDistinctFrames);
      const fs::path target = fs::absolute(base / "images" / c / name);
      std::snprintf(name, sizeof(name), "%06zu.png", i);
      fs::create_symlink(target, d / "images" / c / name);
    }
  }
  std::ofstream t(d / "frames.csv.tmp");
  t << "frame,time_s\n";
  for (size_t i = 0; i < n; ++i) t << i << "," << 0.1 * static_cast<double>(i) << "\n";
  t.close();
  fs::rename(d / "frames.csv.tmp", d / "frames.csv");
  return d;
}

// The library paths, in a child process: "stream" is what `mcms track` does (rows streamed
// to the output, running sums); "store" is the old path (every FrameResult kept, then the
// summary and the CSV from the vector).
int Child(const std::string& path, const fs::path& rec, int threads, double gain) {
  const CameraRig rig = CameraRig::Read(rec / "rig.yaml");
  const Target target = Target::Read(rec / "target.yaml");
  const ImageSequence seq = ScanImageSequence({rec / "images", rec / "frames.csv", 10.0}, rig);
  TrackerOptions o;
  o.detector.gain_e_per_dn = gain;
  Tracker tracker(rig, target, o);
  const fs::path out = rec / ("poses_" + path + ".csv");
  size_t ok = 0, n = 0;
  std::string summary;
  if (path == "store") {
    const std::vector<FrameResult> results = TrackImageSequence(seq, tracker, {}, threads);
    for (const auto& r : results) ok += r.status != FrameStatus::kLost;
    n = results.size();
    const PoseResidualCheck check = CheckPoseResiduals(results);
    summary = check.Describe();
    WritePoseCsv(out, results, {summary});
  } else if (path == "stream") {
    PoseCsvWriter writer(out);
    PoseResidualCheck check;
    TrackImageSequenceStreaming(
        seq, tracker,
        [&](FrameResult&& r) {
          ++n;
          ok += r.status != FrameStatus::kLost;
          check.Add(r);
          writer.Add(r);
        },
        {}, threads);
    check.Finish();
    summary = check.Describe();
    writer.Finish({summary});
  } else {
    Throw("bench: unknown path ", path);
  }
  std::printf("%zu frames, %zu with a pose; %s; VmHWM %.1f MB\n", n, ok, summary.c_str(), VmHwmMb());
  return 0;
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> v;
  std::stringstream in(s);
  for (std::string x; std::getline(in, x, ',');)
    if (!x.empty()) v.push_back(x);
  return v;
}

int Main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.size() == 5 && args[0] == "--child")
    return Child(args[1], args[2], std::atoi(args[3].c_str()), std::atof(args[4].c_str()));
  std::vector<size_t> sizes = {100, 10000, 100000};
  std::vector<std::string> paths = {"cli", "stream", "store"};
  int threads = 2;
  fs::path scratch = fs::temp_directory_path() / "mcms_bench_track_memory";
  std::string mcms = MCMS_CLI;
  for (size_t i = 0; i + 1 < args.size(); i += 2) {
    if (args[i] == "--sizes") {
      sizes.clear();
      for (const auto& x : Split(args[i + 1])) sizes.push_back(std::stoul(x));
    } else if (args[i] == "--threads") {
      threads = std::atoi(args[i + 1].c_str());
    } else if (args[i] == "--paths") {
      paths = Split(args[i + 1]);
    } else if (args[i] == "--dir") {
      scratch = args[i + 1];
    } else if (args[i] == "--mcms") {
      mcms = args[i + 1];
    } else {
      std::fprintf(stderr, "usage: bench_track_memory [--sizes N,...] [--threads N] [--paths cli,stream,store] "
                           "[--dir SCRATCH] [--mcms PATH]\n");
      return 2;
    }
  }
  const fs::path base = RenderBase(scratch, mcms);
  const double gain = Scenario::Read(base / "scenario.yaml").render.gain_e_per_dn;
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  std::printf("peak RSS of tracking N frame sets (4 cameras, 320x256, images linked to %zu rendered frames), "
              "%d threads; this parent's own peak: %.1f MB\n",
              kDistinctFrames, threads, VmHwmMb());
  std::printf("%-9s %-52s %10s %10s %12s %10s\n", "frames", "path", "peak MB", "seconds", "frames/s", "KB/frame");
  std::fflush(stdout);
  std::vector<double> first_mb(paths.size(), 0.0);
  std::vector<size_t> first_n(paths.size(), 0);
  for (size_t n : sizes) {
    const fs::path rec = MakeLongRecording(base, scratch, n);
    for (size_t p = 0; p < paths.size(); ++p) {
      const std::string& path = paths[p];
      std::vector<std::string> cmd;
      std::string label;
      if (path == "cli") {
        cmd = {mcms, "track", "--quiet", "--threads", std::to_string(threads), "--gain", std::to_string(gain),
               rec.string(), "-o", (rec / "poses_cli.csv").string()};
        label = "mcms track (streams rows)";
      } else {
        cmd = {self, "--child", path, rec.string(), std::to_string(threads), std::to_string(gain)};
        label = path == "stream" ? "TrackImageSequenceStreaming + PoseCsvWriter"
                                 : "peer: TrackImageSequence (keeps all) + WritePoseCsv";
      }
      const fs::path log = scratch / ("log_" + path + "_" + std::to_string(n) + ".txt");
      const ChildRun r = Spawn(cmd, log);
      if (r.status != 0) {
        std::printf("%-9zu %-52s failed (exit status %d); see %s\n", n, label.c_str(), r.status, log.c_str());
        continue;
      }
      std::string growth = "-";
      if (first_n[p] == 0) {
        first_n[p] = n;
        first_mb[p] = r.maxrss_mb;
      } else if (n > first_n[p]) {
        char b[32];
        std::snprintf(b, sizeof(b), "%.2f", (r.maxrss_mb - first_mb[p]) * 1024.0 / static_cast<double>(n - first_n[p]));
        growth = b;
      }
      std::printf("%-9zu %-52s %10.1f %10.1f %12.0f %10s\n", n, label.c_str(), r.maxrss_mb, r.seconds,
                  static_cast<double>(n) / r.seconds, growth.c_str());
      std::fflush(stdout);
    }
  }
  std::printf("KB/frame: growth of the peak per frame set since the smallest size measured\n");
  return 0;
}

}  // namespace
}  // namespace mcms

int main(int argc, char** argv) {
  try {
    return mcms::Main(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_track_memory: %s\n", e.what());
    return 1;
  }
}
