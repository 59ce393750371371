// Long recordings: tracking streams each frame's result in frame order with a bounded
// reorder window, `mcms track` keeps its peak memory flat as the recording grows, and an
// error mid-run leaves no poses.csv (issue 14, "Long sequences").
#include <gtest/gtest.h>

#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/io.h"
#include "synthetic/scenario.h"
#include "tests/test_util.h"
#include "tracking/sequence.h"

extern char** environ;

namespace mcms {
namespace {

namespace fs = std::filesystem;

constexpr size_t kDistinct = 6;

std::string Replace(std::string s, const std::string& from, const std::string& to) {
  const size_t p = s.find(from);
  EXPECT_NE(p, std::string::npos) << "the default scenario has no '" << from << "' any more";
  return p == std::string::npos ? s : s.replace(p, from.size(), to);
}

// A recording of kDistinct frames from 4 cameras cropped to 320 x 256 (the default lens:
// the balls look as in the default recording, the images are 16 times cheaper to read),
// rendered once per test process.
const fs::path& SmallRecording() {
  static const fs::path dir = [] {
    const fs::path s = test::ScratchDir("stream_base");
    std::string text = Scenario::DefaultText();
    text = Replace(text, "imagersize: [1280, 1024]", "imagersize: [320, 256]");
    text = Replace(text, "639.5, 511.5", "159.5, 127.5");
    text = Replace(text, "frames: 120", "frames: " + std::to_string(kDistinct));
    text = Replace(text, "amplitude_m: [0.3, 0.2, 0.3]", "amplitude_m: [0.03, 0.03, 0.03]");
    text = Replace(text, "rotation_amplitude_deg: 30", "rotation_amplitude_deg: 10");
    std::ofstream(s / "small.yaml") << text;
    const std::string cmd = std::string(MCMS_CLI) + " render --quiet " + (s / "small.yaml").string() + " -o " +
                            (s / "rec").string() + " > " + (s / "log.txt").string() + " 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    return s / "rec";
  }();
  return dir;
}

// A recording of n frame sets whose images are links to the small recording's.
fs::path LongRecording(const std::string& name, size_t n) {
  const fs::path base = SmallRecording();
  const fs::path d = test::ScratchDir("stream_" + name) / "rec";
  fs::create_directories(d);
  for (const char* f : {"rig.yaml", "target.yaml"}) fs::copy_file(base / f, d / f);
  char file[32];
  for (const char* c : {"cam0", "cam1", "cam2", "cam3"}) {
    fs::create_directories(d / "images" / c);
    for (size_t i = 0; i < n; ++i) {
      std::snprintf(file, sizeof(file), "%06zu.png", i % kDistinct);
      const fs::path target = fs::absolute(base / "images" / c / file);
      std::snprintf(file, sizeof(file), "%06zu.png", i);
      fs::create_symlink(target, d / "images" / c / file);
    }
  }
  std::ofstream t(d / "frames.csv");
  t << "frame,time_s\n";
  for (size_t i = 0; i < n; ++i) t << i << "," << 0.1 * static_cast<double>(i) << "\n";
  return d;
}

struct Run {
  int code = -1;
  double peak_mb = 0;  // the child's peak resident set (wait4's ru_maxrss)
  std::string err;
};

// Runs the mcms binary with `args` in a child process, `shell_prefix` first (ulimit, trap).
Run Mcms(const std::string& args, const fs::path& scratch, const std::string& shell_prefix = "") {
  const fs::path err = scratch / "stderr.txt";
  const std::string script = shell_prefix + "exec " + MCMS_CLI + " " + args + " > /dev/null 2> " + err.string();
  const char* argv[] = {"/bin/sh", "-c", script.c_str(), nullptr};
  pid_t pid = 0;
  Run r;
  if (posix_spawn(&pid, "/bin/sh", nullptr, nullptr, const_cast<char**>(argv), environ) != 0) return r;
  int status = 0;
  struct rusage ru {};
  if (wait4(pid, &status, 0, &ru) != pid) return r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.peak_mb = static_cast<double>(ru.ru_maxrss) / 1024.0;
  std::ifstream in(err);
  std::stringstream s;
  s << in.rdbuf();
  r.err = s.str();
  return r;
}

double OwnPeakMb() {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

void ExpectNoPartialFiles(const fs::path& d) {
  for (const auto& e : fs::directory_iterator(d))
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << "left behind: " << e.path();
}

struct Setup {
  CameraRig rig;
  Target target;
  ImageSequence seq;
  explicit Setup(const fs::path& rec)
      : rig(CameraRig::Read(rec / "rig.yaml")),
        target(Target::Read(rec / "target.yaml")),
        seq(ScanImageSequence({rec / "images", rec / "frames.csv", 10.0}, rig)) {}
  Tracker MakeTracker() const {
    TrackerOptions o;
    o.detector.gain_e_per_dn = 4;
    return Tracker(rig, target, o);
  }
};

TEST(Stream, FramesArriveInOrderAndTheSequenceHoldsAtMostItsWindow) {
  const size_t n = 120;
  const Setup s(LongRecording("order", n));
  ASSERT_EQ(s.seq.frames.size(), n);
  Tracker t1 = s.MakeTracker();
  const std::vector<FrameResult> reference = TrackImageSequence(s.seq, t1, {}, 1);
  ASSERT_EQ(reference.size(), n);
  for (int threads : {1, 2, 3}) {
    Tracker tracker = s.MakeTracker();
    size_t next = 0, progress_calls = 0;
    const size_t held = TrackImageSequenceStreaming(
        s.seq, tracker,
        [&](FrameResult&& r) {
          ASSERT_LT(next, n);
          EXPECT_EQ(r.frame, s.seq.frames[next]) << "frame order, threads " << threads;
          EXPECT_EQ(r.status, reference[next].status) << "frame " << next << ", threads " << threads;
          ASSERT_EQ(r.T_rig_target.has_value(), reference[next].T_rig_target.has_value());
          if (r.T_rig_target) {
            EXPECT_EQ(r.T_rig_target->t, reference[next].T_rig_target->t) << "same result on any thread count";
          }
          ++next;
        },
        [&](size_t done, size_t total) {
          ++progress_calls;
          EXPECT_EQ(done, next);
          EXPECT_EQ(total, n);
        },
        threads);
    EXPECT_EQ(next, n);
    EXPECT_EQ(progress_calls, n);
    EXPECT_GE(held, 1u);
    EXPECT_LE(held, SequenceWindow(threads)) << "threads " << threads;
    EXPECT_LT(SequenceWindow(threads), n / 4) << "the window must be small against the sequence for this test";
  }
  size_t ok = 0;
  for (const auto& r : reference) ok += r.status != FrameStatus::kLost;
  EXPECT_EQ(ok, n) << "every frame of the rendered recording has a pose";
}

TEST(Stream, AnErrorInTheCallbackStopsEveryThreadAndLeavesNoPoseCsv) {
  const fs::path rec = LongRecording("callback_error", 60);
  const Setup s(rec);
  for (int threads : {1, 2}) {
    Tracker tracker = s.MakeTracker();
    const fs::path out = rec / "poses.csv";
    size_t seen = 0;
    try {
      PoseCsvWriter writer(out);
      TrackImageSequenceStreaming(
          s.seq, tracker,
          [&](FrameResult&& r) {
            writer.Add(r);
            if (++seen == 25) throw std::runtime_error("stop at frame 25");
          },
          {}, threads);
      writer.Finish();
      ADD_FAILURE() << "the error was swallowed";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "stop at frame 25");
    }
    EXPECT_EQ(seen, 25u) << "no frame is delivered after the error, threads " << threads;
    EXPECT_FALSE(fs::exists(out));
    ExpectNoPartialFiles(rec);
  }
}

TEST(Stream, PoseCsvWriterMatchesTheWholeVectorWriter) {
  const Setup s(LongRecording("writer", 12));
  Tracker tracker = s.MakeTracker();
  const std::vector<FrameResult> results = TrackImageSequence(s.seq, tracker, {}, 2);
  const fs::path d = test::ScratchDir("stream_writer_out");
  WritePoseCsv(d / "a.csv", results, {"note one", "note two"});
  {
    PoseCsvWriter w(d / "b.csv", {"extra_a", "extra_b"});
    for (const auto& r : results) w.Add(r, {1.5, std::nan("")});
    EXPECT_FALSE(fs::exists(d / "b.csv")) << "nothing in place before Finish";
    w.Finish({"note one", "note two"});
  }
  const CsvTable a = ReadCsv(d / "a.csv"), b = ReadCsv(d / "b.csv");
  ASSERT_EQ(a.rows.size(), results.size());
  ASSERT_EQ(b.rows.size(), results.size());
  ASSERT_EQ(b.header.size(), a.header.size() + 2);
  EXPECT_EQ(b.header.back(), "extra_b");
  for (size_t r = 0; r < a.rows.size(); ++r) {
    for (size_t c = 0; c < a.header.size(); ++c) EXPECT_EQ(a.rows[r][c], b.rows[r][c]);
    EXPECT_EQ(b.rows[r][a.header.size()], "1.5");
    EXPECT_EQ(b.rows[r][a.header.size() + 1], "") << "NaN is an empty cell";
  }
  EXPECT_EQ(ReadTextFile(d / "a.csv").rfind("# note one\n# note two\nframe,time_s,", 0), 0u);
  ExpectNoPartialFiles(d);
}

TEST(Stream, TrackGivesTheSameCsvOnAnyThreadCount) {
  const fs::path rec = LongRecording("threads", 80);
  const Run a = Mcms("track --quiet --gain 4 --threads 1 " + rec.string() + " -o " + (rec / "p1.csv").string(), rec);
  ASSERT_EQ(a.code, 0) << a.err;
  const Run b = Mcms("track --quiet --gain 4 --threads 3 " + rec.string() + " -o " + (rec / "p3.csv").string(), rec);
  ASSERT_EQ(b.code, 0) << b.err;
  const std::string one = ReadTextFile(rec / "p1.csv");
  EXPECT_EQ(one, ReadTextFile(rec / "p3.csv"));
  EXPECT_NE(one.find("# pose-fit residuals: chi2/dof"), std::string::npos) << "the summary heads the file";
  EXPECT_EQ(ReadCsv(rec / "p1.csv").rows.size(), 80u);
}

// The old path kept about 4 KB per frame set: 3,000 frame sets more would add about 12 MB.
// Streaming must add less than a quarter of that; both runs are far above this process's
// own peak (which ru_maxrss of a child can include).
TEST(Stream, TrackPeakMemoryDoesNotGrowWithTheRecording) {
  const fs::path small = LongRecording("rss_small", 100);
  const fs::path large = LongRecording("rss_large", 3100);
  const Run a = Mcms("track --quiet --gain 4 --threads 2 " + small.string(), small);
  ASSERT_EQ(a.code, 0) << a.err;
  const Run b = Mcms("track --quiet --gain 4 --threads 2 " + large.string(), large);
  ASSERT_EQ(b.code, 0) << b.err;
  EXPECT_EQ(ReadCsv(large / "poses.csv").rows.size(), 3100u);
  const double own = OwnPeakMb();
  EXPECT_GT(a.peak_mb, own + 5) << "the measurement must be the child's";
  std::printf("peak RSS of mcms track: %.1f MB at 100 frame sets, %.1f MB at 3100 (this test process: %.1f MB)\n",
              a.peak_mb, b.peak_mb, own);
  EXPECT_LT(b.peak_mb - a.peak_mb, 3.0) << "peak memory grew by " << (b.peak_mb - a.peak_mb) << " MB for 3000 frame sets";
}

// A write error mid-run (the output file hits the file-size limit after about 100 rows, as
// a full disk would stop it): an error naming the output, a non-zero exit, no poses.csv, no
// temporary file left, and an earlier poses.csv untouched.
TEST(Stream, AWriteErrorMidRunLeavesNoPoseCsv) {
  const fs::path rec = LongRecording("write_error", 400);
  const Run fresh = Mcms("track --quiet --gain 4 --threads 2 " + rec.string(), rec, "trap '' XFSZ; ulimit -f 64; ");
  EXPECT_NE(fresh.code, 0);
  EXPECT_NE(fresh.err.find("error while writing output file " + (rec / "poses.csv").string()), std::string::npos)
      << fresh.err;
  EXPECT_FALSE(fs::exists(rec / "poses.csv"));
  ExpectNoPartialFiles(rec);

  std::ofstream(rec / "poses.csv") << "an earlier output\n";
  const Run again = Mcms("track --quiet --gain 4 --threads 1 " + rec.string(), rec, "trap '' XFSZ; ulimit -f 64; ");
  EXPECT_NE(again.code, 0);
  EXPECT_EQ(ReadTextFile(rec / "poses.csv"), "an earlier output\n");
  ExpectNoPartialFiles(rec);
}

}  // namespace
}  // namespace mcms
