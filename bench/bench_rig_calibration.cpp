// Rig-calibration time against mrcal's own tool, on the same observations.
//
//   OURS   CalibrateCameras (calib/camera_calibration.h): OpenCV seed, Ceres bundle
//          adjustment of LENSMODEL_OPENCV8 intrinsics, board poses and board warp,
//          outlier rejection with re-solves, intrinsics covariance. One thread.
//   PEER   mrcal-calibrate-cameras (Debian's mrcal 2.x) as a subprocess, reading the same
//          corners from a corners cache: its seed, staged solves, outlier rejection,
//          uncertainty and the model file it writes. Held to one BLAS/OpenMP thread.
//
// The observations are mrcal's real Figueroa calibration: the 186 chessboard views
// (10 x 10 corners, 77 mm spacing, 6016 x 4016 imager) embedded in
// mrcal-figueroa/opencv8-0.cameramodel. Debian's /usr/bin/python3 extracts them once
// into a scratch folder, both as our input and as the "# filename x y level" corners
// cache mrcal-calibrate-cameras reads (mrcal's weight w of a corner is 0.5^level of the
// detector's decimation level, so level = -log2|w|; mrcal stores its outliers as
// negative weights, which are given back as the original level here so that both
// solvers see every point and reject outliers themselves).
//
// Times: each solver runs a few times (Iterations(1), several repetitions: one mrcal run
// takes many seconds). Wall time is what a user waits for; the CPU time (ours: this
// process; mrcal: the child's user + sys from wait4) is the figure that depends less on
// what else the machine runs. Python's start-up plus `import mrcal` is timed alone so
// that the reader can subtract it from the tool's time; the summary prints the ratios
// mrcal / ours with and without it, and both solvers' residual RMS so that the reader can
// see they solved the same problem.
//
// Skips (prints the reason, exits 0) when the data, /usr/bin/python3 with mrcal, or
// mrcal-calibrate-cameras is missing. Environment: MCMS_DATA_DIR (default: shared/data
// beside the source tree), MCMS_PYTHON3 (default /usr/bin/python3),
// MCMS_MRCAL_CALIBRATE_CAMERAS (default: found on PATH), MCMS_BENCH_SCRATCH (default: a
// folder under the system temporary directory).
#include <benchmark/benchmark.h>

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "calib/camera_calibration.h"

extern char** environ;

namespace mcms {
namespace {

namespace fs = std::filesystem;

constexpr const char* kDataSet = "mrcal-figueroa";
constexpr const char* kModelFile = "opencv8-0.cameramodel";
constexpr const char* kLensModel = "LENSMODEL_OPENCV8";
// Initial focal length given to mrcal-calibrate-cameras (it requires one without a
// --seed): a round number within 4 % of the solved 2074 px, as a user would derive it
// from the lens and the pixel pitch. Ours needs none (cv::calibrateCamera seeds it).
constexpr double kFocalGuessPx = 2000.0;
// Runs per solver (Iterations(1) each: one mrcal run takes seconds to tens of seconds);
// the summary takes the median, which one slow mrcal run does not move.
constexpr int kRepetitions = 5;
// mrcal's published solution of these observations (data README): RMS per coordinate
// over its inliers, and how many points it kept.
constexpr double kMrcalPublishedRmsPx = 0.551;
constexpr int kMrcalPublishedInliers = 18597;

// Writes "W H spacing nx ny", then one line "frame row col x y weight" per corner, to
// argv[2], and the mrcal corners cache to argv[3].
const char* kExtractPy = R"(
import sys, math, mrcal
oi = mrcal.cameramodel(sys.argv[1]).optimization_inputs()
ob = oi['observations_board']
idx = oi['indices_frame_camintrinsics_camextrinsics']
if oi['lensmodel'] != 'LENSMODEL_OPENCV8' or len(oi['imagersizes']) != 1:
    sys.exit('expected one LENSMODEL_OPENCV8 camera, got %s' % oi['lensmodel'])
W, H = oi['imagersizes'][0]
with open(sys.argv[2], 'w') as f, open(sys.argv[3], 'w') as c:
    f.write('%d %d %.17g %d %d\n' % (W, H, oi['calibration_object_spacing'], ob.shape[2], ob.shape[1]))
    c.write('# filename x y level\n')
    for k in range(ob.shape[0]):
        name = 'frame%04d.png' % idx[k, 0]
        for i in range(ob.shape[1]):
            for j in range(ob.shape[2]):
                x, y, w = ob[k, i, j]
                f.write('%d %d %d %.17g %.17g %.17g\n' % (idx[k, 0], i, j, x, y, abs(w)))
                if w == 0:
                    c.write('%s %.17g %.17g -\n' % (name, x, y))
                else:
                    c.write('%s %.17g %.17g %d\n' % (name, x, y, round(-math.log2(abs(w)))))
)";

// Prints "inliers rms_inliers rms_all" of the model mrcal-calibrate-cameras wrote: RMS
// per coordinate of the weighted residuals over its final inliers, and over every point
// (outliers re-evaluated), the two conventions the summary compares.
const char* kResidualsPy = R"(
import sys, numpy as np, mrcal
oi = mrcal.cameramodel(sys.argv[1]).optimization_inputs()
w = oi['observations_board'][..., 2].ravel().copy()
inlier = w > 0
oi['observations_board'][..., 2] = np.abs(oi['observations_board'][..., 2])
oi['do_apply_outlier_rejection'] = False
x = mrcal.optimizer_callback(**oi)[1]
n = oi['observations_board'][..., 0].size
e = x[:2 * n].reshape(-1, 2)
print(int(inlier.sum()), np.sqrt(np.mean(e[inlier] ** 2)), np.sqrt(np.mean(e ** 2)))
)";

struct BenchData {
  fs::path model, scratch, python, mrcal_tool;
  fs::path corners, mrcal_outdir, mrcal_log;
  int width = 0, height = 0, nx = 0, ny = 0;
  double spacing_m = 0;
  CameraCalibrationInput input;
  int num_points = 0;
  std::vector<std::string> mrcal_argv;
};
BenchData* g_data = nullptr;

struct Sample {
  double wall_s = 0, cpu_s = 0;
};
std::vector<Sample> g_python_samples, g_ours_samples, g_mrcal_samples;
std::optional<CameraCalibrationResult> g_ours_result;

double ProcessCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct ChildRun {
  int exit_status = -1;  // exit code, or -1 when it did not exit normally
  Sample time;
};

// Runs argv[0] (an absolute path) with stdout and stderr into `log`, the environment of
// this process plus `extra_env` ("NAME=value"), and returns its exit status, wall time
// and CPU time (user + sys of the child, from wait4). Throws when it cannot be started.
ChildRun RunChild(const std::vector<std::string>& argv, const fs::path& log,
                  const std::vector<std::string>& extra_env = {}) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  std::vector<std::string> env_store;
  for (char** e = environ; *e; ++e) {
    const std::string s = *e;
    const bool overridden = std::any_of(extra_env.begin(), extra_env.end(), [&](const std::string& x) {
      return s.compare(0, x.find('=') + 1, x, 0, x.find('=') + 1) == 0;
    });
    if (!overridden) env_store.push_back(s);
  }
  env_store.insert(env_store.end(), extra_env.begin(), extra_env.end());
  std::vector<char*> envp;
  for (const std::string& s : env_store) envp.push_back(const_cast<char*>(s.c_str()));
  envp.push_back(nullptr);

  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, STDOUT_FILENO, STDERR_FILENO);
  ChildRun run;
  const double t0 = WallSeconds();
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, args[0], &fa, nullptr, args.data(), envp.data());
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(rc));
  int status = 0;
  rusage ru{};
  while (wait4(pid, &status, 0, &ru) < 0) {
    if (errno != EINTR) throw std::runtime_error("wait4 failed for " + argv[0] + ": " + std::strerror(errno));
  }
  run.time.wall_s = WallSeconds() - t0;
  auto tv = [](const timeval& t) { return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec); };
  run.time.cpu_s = tv(ru.ru_utime) + tv(ru.ru_stime);
  run.exit_status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

// The child's whole output as one string (for error messages and parsing).
std::string ReadFile(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// Both solvers are held to one thread (ours sets Ceres' num_threads = 1; numpy's BLAS
// and OpenMP would otherwise take every core of a machine that others share).
const std::vector<std::string> kOneThreadEnv = {"OMP_NUM_THREADS=1", "OPENBLAS_NUM_THREADS=1", "MKL_NUM_THREADS=1"};

CameraCalibrationOptions OurOptions() {
  CameraCalibrationOptions opt;
  opt.lensmodel = kLensModel;
  opt.solve_board_warp = true;  // mrcal-calibrate-cameras solves calobject_warp by default
  // outlier_k stays at the project default (4 sigma): both solvers reject their own outliers.
  return opt;
}

// ---------------------------------------------------------------------------------

void BM_PythonImportMrcal(benchmark::State& state) {
  const BenchData& d = *g_data;
  for (auto _ : state) {
    const ChildRun r = RunChild({d.python.string(), "-c", "import mrcal"}, d.scratch / "import.log", kOneThreadEnv);
    if (r.exit_status != 0) {
      state.SkipWithError("python3 -c 'import mrcal' failed");
      return;
    }
    g_python_samples.push_back(r.time);
    state.SetIterationTime(r.time.wall_s);
    state.counters["child_cpu_s"] = r.time.cpu_s;
  }
}
BENCHMARK(BM_PythonImportMrcal)->UseManualTime()->Iterations(1)->Repetitions(kRepetitions)->Unit(benchmark::kSecond);

// CPU time stamps of the solver's progress messages in the last run (a clock read per
// message, a dozen per run): where our time goes, printed in the summary.
struct Stamp {
  double cpu_s;
  std::string what;
};
std::vector<Stamp> g_ours_stamps;

void BM_OursCalibrateCameras(benchmark::State& state) {
  const BenchData& d = *g_data;
  CameraCalibrationOptions opt = OurOptions();
  opt.log = [](const std::string& s) { g_ours_stamps.push_back({ProcessCpuSeconds(), s}); };
  for (auto _ : state) {
    g_ours_stamps.clear();
    const double w0 = WallSeconds(), c0 = ProcessCpuSeconds();
    g_ours_stamps.push_back({c0, "start"});
    CameraCalibrationResult r = CalibrateCameras(d.input, opt);
    const Sample s{WallSeconds() - w0, ProcessCpuSeconds() - c0};
    g_ours_stamps.push_back({c0 + s.cpu_s, "end"});
    g_ours_samples.push_back(s);
    // Kept for the summary, which also keeps the solve from being optimised away. (Not
    // benchmark::DoNotOptimize(r.rms_px): with GCC its "+m,r" constraint on a double
    // can hand back a corrupted value, as it did here.)
    g_ours_result = std::move(r);
  }
  state.counters["rms_px"] = g_ours_result ? g_ours_result->rms_px : 0.0;
}
BENCHMARK(BM_OursCalibrateCameras)->Iterations(1)->Repetitions(kRepetitions)->Unit(benchmark::kSecond);

// mrcal-calibrate-cameras' own report: "## RMS error: <full precision>" (the last one is
// the final solve) and "Noutliers: N out of M total points".
struct MrcalReport {
  std::optional<double> rms_reported;
  std::optional<int> outliers;
};
MrcalReport ParseMrcalLog(const fs::path& log) {
  MrcalReport rep;
  std::ifstream f(log);
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("## RMS error:", 0) == 0) rep.rms_reported = std::atof(line.c_str() + 13);
    if (line.rfind("Noutliers:", 0) == 0) rep.outliers = std::atoi(line.c_str() + 10);
  }
  return rep;
}

// Each run's own report: the tool does not always reach the same solution (its outlier
// rounds can take a different path), which shows in its time.
std::vector<MrcalReport> g_mrcal_reports;

void BM_MrcalCalibrateCameras(benchmark::State& state) {
  const BenchData& d = *g_data;
  for (auto _ : state) {
    const ChildRun r = RunChild(d.mrcal_argv, d.mrcal_log, kOneThreadEnv);
    if (r.exit_status != 0) {
      state.SkipWithError(("mrcal-calibrate-cameras failed; its output is in " + d.mrcal_log.string()).c_str());
      return;
    }
    g_mrcal_samples.push_back(r.time);
    g_mrcal_reports.push_back(ParseMrcalLog(d.mrcal_log));
    state.SetIterationTime(r.time.wall_s);
    state.counters["child_cpu_s"] = r.time.cpu_s;
  }
}
BENCHMARK(BM_MrcalCalibrateCameras)->UseManualTime()->Iterations(1)->Repetitions(kRepetitions)->Unit(benchmark::kSecond);

// ---------------------------------------------------------------------------------
// Summary.

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

struct Times {
  bool valid = false;
  double wall_med = 0, wall_min = 0, cpu_med = 0, cpu_min = 0;
  size_t n = 0;
};

Times Summarize(const std::vector<Sample>& s) {
  Times t;
  if (s.empty()) return t;
  std::vector<double> w, c;
  for (const Sample& x : s) w.push_back(x.wall_s), c.push_back(x.cpu_s);
  t.valid = true;
  t.n = s.size();
  t.wall_med = Median(w);
  t.cpu_med = Median(c);
  t.wall_min = *std::min_element(w.begin(), w.end());
  t.cpu_min = *std::min_element(c.begin(), c.end());
  return t;
}

void PrintSummary() {
  const BenchData& d = *g_data;
  const Times py = Summarize(g_python_samples), ours = Summarize(g_ours_samples), mr = Summarize(g_mrcal_samples);
  std::printf("\n==== bench_rig_calibration summary: mrcal Figueroa, %zu views x %dx%d corners (%d points), "
              "%s, one thread each ====\n",
              d.input.observations.size(), d.nx, d.ny, d.num_points, kLensModel);
  std::printf("mrcal-calibrate-cameras command line:\n ");
  for (const std::string& a : d.mrcal_argv) std::printf(" %s", a.find('*') != std::string::npos ? ("'" + a + "'").c_str() : a.c_str());
  std::printf("\n  (environment: OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1)\n");
  auto row = [](const char* what, const Times& t) {
    if (!t.valid) return;
    std::printf("  %-44s wall %8.3f s (min %8.3f)   CPU %8.3f s (min %8.3f)   [%zu runs]\n", what, t.wall_med,
                t.wall_min, t.cpu_med, t.cpu_min, t.n);
  };
  std::printf("times (median over runs):\n");
  row("ours: CalibrateCameras", ours);
  row("mrcal-calibrate-cameras (whole process)", mr);
  row("python3 start-up + import mrcal alone", py);
  if (!g_mrcal_samples.empty()) {
    std::printf("  mrcal runs one by one (wall, CPU, the tool's RMS and outliers):");
    for (size_t k = 0; k < g_mrcal_samples.size(); ++k) {
      const MrcalReport& rep = g_mrcal_reports[k];
      std::printf("%s %.2f s, %.2f s, %.4f, %d", k ? ";" : "", g_mrcal_samples[k].wall_s, g_mrcal_samples[k].cpu_s,
                  rep.rms_reported.value_or(NAN), rep.outliers.value_or(-1));
    }
    std::printf("\n");
  }
  if (ours.valid && mr.valid) {
    std::printf("speed ratio mrcal / ours, wall:  %.2fx", mr.wall_med / ours.wall_med);
    if (py.valid) std::printf("   without python start-up: %.2fx", (mr.wall_med - py.wall_med) / ours.wall_med);
    std::printf("\n");
    std::printf("speed ratio mrcal / ours, CPU:   %.2fx", mr.cpu_med / ours.cpu_med);
    if (py.valid) std::printf("   without python start-up: %.2fx", (mr.cpu_med - py.cpu_med) / ours.cpu_med);
    std::printf("\n");
    const double load = ours.wall_med / std::max(ours.cpu_med, 1e-9);
    if (load > 1.3)
      std::printf("(ours took %.1fx its CPU time in wall time: the machine is busy, the CPU ratio is the fairer "
                  "figure)\n",
                  load);
  }

  if (g_ours_stamps.size() > 2) {
    // The first message comes before the seed, the next ones after each solve (with its
    // outlier check); the last interval is the results and the covariance.
    std::printf("where our CPU time went (last run; each line: the time up to that message):\n");
    for (size_t k = 1; k < g_ours_stamps.size(); ++k) {
      const std::string& what = k + 1 == g_ours_stamps.size() ? std::string("(results, residuals, covariance)")
                                : k == 2 ? "(seed: cv::calibrateCamera, solvePnP) + " + g_ours_stamps[k].what
                                         : g_ours_stamps[k].what;
      std::printf("  %7.3f s  %s\n", g_ours_stamps[k].cpu_s - g_ours_stamps[k - 1].cpu_s, what.c_str());
    }
  }
  std::printf("residuals (weighted, px per coordinate; inliers = each solver's own final inlier set):\n");
  std::optional<double> ours_rms_all, mrcal_rms_all;
  if (g_ours_result) {
    const CameraCalibrationResult& r = *g_ours_result;
    double sum_all = 0;
    size_t n_all = 0;
    for (const CameraResidualStats& s : r.residuals)
      for (const Vec2& e : s.residuals) sum_all += e.squaredNorm(), ++n_all;
    ours_rms_all = std::sqrt(sum_all / (2.0 * std::max<size_t>(n_all, 1)));
    std::printf("  ours   RMS %.4f over %d inliers (%d rejected), %.4f over all %zu points; board warp (%.5f, %.5f) m\n",
                r.rms_px, r.num_inliers, r.num_outliers, *ours_rms_all, n_all, r.board_warp_m[0], r.board_warp_m[1]);
  }
  const fs::path model = d.mrcal_outdir / "camera-0.cameramodel";
  if (!g_mrcal_samples.empty() && fs::exists(model)) {
    const MrcalReport rep = g_mrcal_reports.back();  // the run that wrote the model
    const fs::path script = d.scratch / "residuals.py", out = d.scratch / "residuals.txt";
    std::ofstream(script) << kResidualsPy;
    const ChildRun r = RunChild({d.python.string(), script.string(), model.string()}, out, kOneThreadEnv);
    int inliers = 0;
    double rms_in = 0, rms_all = 0;
    std::istringstream ss(ReadFile(out));
    if (r.exit_status == 0 && (ss >> inliers >> rms_in >> rms_all)) {
      mrcal_rms_all = rms_all;
      std::printf("  mrcal  RMS %.4f over %d inliers (%d rejected), %.4f over all %d points", rms_in, inliers,
                  d.num_points - inliers, rms_all, d.num_points);
    } else {
      std::printf("  mrcal  (could not re-evaluate its residuals: see %s)", out.c_str());
    }
    if (rep.rms_reported)
      std::printf("; the tool itself reports \"RMS error\" %.4f and %d outliers (last run)", *rep.rms_reported,
                  rep.outliers.value_or(-1));
    std::printf("\n");
  }
  std::printf("  (mrcal's published solution in %s: RMS %.3f over %d inliers)\n", kModelFile, kMrcalPublishedRmsPx,
              kMrcalPublishedInliers);
  // The two outlier rules differ (ours: |e| > 4 sigma on a point's error norm; mrcal's
  // own rule), so the inlier sets and their RMS differ; the RMS over every point, each
  // solution evaluated on the same 18600 corners, is the like-for-like figure.
  if (ours_rms_all && mrcal_rms_all)
    std::printf("  RMS over all points, ours / mrcal: %.4f / %.4f (%+.1f %%): %s\n", *ours_rms_all, *mrcal_rms_all,
                100.0 * (*ours_rms_all / *mrcal_rms_all - 1.0),
                std::abs(*ours_rms_all / *mrcal_rms_all - 1.0) < 0.05 ? "the same problem, solved alike"
                                                                         : "the solutions DIFFER by more than 5 %");
}

// ---------------------------------------------------------------------------------
// Preparation: find the inputs, extract the observations. Returns the reason to skip.

fs::path DataRoot() {
  if (const char* env = std::getenv("MCMS_DATA_DIR")) return env;
  // This file is bench/bench_rig_calibration.cpp in the source tree; the data lives in
  // shared/data beside the tree (as tests/test_util.h finds it).
  return fs::path(__FILE__).parent_path().parent_path() / ".." / "shared" / "data";
}

std::optional<fs::path> FindOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (!path) return std::nullopt;
  std::istringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (dir.empty()) continue;
    const fs::path p = fs::path(dir) / name;
    if (access(p.c_str(), X_OK) == 0) return p;
  }
  return std::nullopt;
}

std::optional<std::string> Prepare(BenchData* d) {
  const fs::path data = DataRoot() / kDataSet;
  d->model = data / kModelFile;
  if (!fs::exists(d->model)) return "real data not present: " + d->model.string();
  const char* py = std::getenv("MCMS_PYTHON3");
  d->python = py ? py : "/usr/bin/python3";
  if (access(d->python.c_str(), X_OK) != 0) return d->python.string() + " (Debian's python3 with mrcal) not present";
  if (const char* tool = std::getenv("MCMS_MRCAL_CALIBRATE_CAMERAS")) {
    d->mrcal_tool = tool;
  } else if (const auto p = FindOnPath("mrcal-calibrate-cameras")) {
    d->mrcal_tool = *p;
  }
  if (d->mrcal_tool.empty() || access(d->mrcal_tool.c_str(), X_OK) != 0)
    return "mrcal-calibrate-cameras not found (PATH or $MCMS_MRCAL_CALIBRATE_CAMERAS)";

  const char* scratch = std::getenv("MCMS_BENCH_SCRATCH");
  d->scratch = scratch ? fs::path(scratch) : fs::temp_directory_path() / "mcms_bench_rig_calibration";
  fs::remove_all(d->scratch);
  fs::create_directories(d->scratch);
  d->corners = d->scratch / "corners.vnl";
  d->mrcal_outdir = d->scratch / "mrcal-out";
  d->mrcal_log = d->scratch / "mrcal-calibrate-cameras.log";
  fs::create_directories(d->mrcal_outdir);

  const fs::path script = d->scratch / "extract.py", obs = d->scratch / "observations.txt";
  std::ofstream(script) << kExtractPy;
  const ChildRun r = RunChild({d->python.string(), script.string(), d->model.string(), obs.string(), d->corners.string()},
                              d->scratch / "extract.log");
  if (r.exit_status != 0)
    return d->python.string() + " could not extract the observations with mrcal (see " +
           (d->scratch / "extract.log").string() + ")";

  std::ifstream f(obs);
  if (!(f >> d->width >> d->height >> d->spacing_m >> d->nx >> d->ny))
    throw std::runtime_error(obs.string() + ": expected the header 'W H spacing nx ny'");
  CameraCalibrationInput& in = d->input;
  in.camera_names = {"figueroa-0"};
  in.widths = {d->width};
  in.heights = {d->height};
  int frame = 0, i = 0, j = 0;
  double x = 0, y = 0, w = 0;
  while (f >> frame >> i >> j >> x >> y >> w) {
    if (in.observations.empty() || in.observations.back().frame != frame) {
      in.observations.emplace_back();
      in.observations.back().frame = frame;
    }
    BoardObservation& o = in.observations.back();
    o.points_board.emplace_back(j * d->spacing_m, i * d->spacing_m, 0.0);
    o.pixels.emplace_back(x, y);
    o.weights.push_back(w);
    ++d->num_points;
  }
  if (in.observations.empty()) throw std::runtime_error(obs.string() + ": no observations");

  // The images do not exist: the glob only names the frames (their number NNN is the
  // frame index), and --imagersize gives the size the images would have had.
  char spacing[32], focal[32];
  std::snprintf(spacing, sizeof spacing, "%.6g", d->spacing_m);
  std::snprintf(focal, sizeof focal, "%.0f", kFocalGuessPx);
  d->mrcal_argv = {d->mrcal_tool.string(),
                   "--corners-cache", d->corners.string(),
                   "--lensmodel", kLensModel,
                   "--focal", focal,
                   "--imagersize", std::to_string(d->width), std::to_string(d->height),
                   "--object-spacing", spacing,
                   "--object-width-n", std::to_string(d->nx),
                   "--object-height-n", std::to_string(d->ny),
                   "--outdir", d->mrcal_outdir.string(),
                   "frame*.png"};
  return std::nullopt;
}

}  // namespace
}  // namespace mcms

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  mcms::BenchData data;
  std::printf("extracting mrcal's Figueroa observations with python3-mrcal ...\n");
  std::fflush(stdout);
  if (const auto why = mcms::Prepare(&data)) {
    std::printf("bench_rig_calibration skipped: %s\n", why->c_str());
    return 0;
  }
  mcms::g_data = &data;
  std::printf("%zu views, %d points, imager %dx%d, spacing %.3f m; scratch %s\n", data.input.observations.size(),
              data.num_points, data.width, data.height, data.spacing_m, data.scratch.c_str());
  std::fflush(stdout);
  benchmark::RunSpecifiedBenchmarks();
  mcms::PrintSummary();
  benchmark::Shutdown();
  return 0;
}
