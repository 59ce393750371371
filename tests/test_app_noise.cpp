// Honest defaults: `mcms track` and `mcms audit` with no noise options on rendered
// recordings whose noise is not the tracker's default. The pixel-noise model is measured
// from the images (tracking/noise_estimate.h); the covariance must then match the one
// from the true noise model, the NEES must lie in its band, and the audit must name no
// camera. Recordings are 10 frames of 3 cameras, rendered once per process.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <unistd.h>

#include "core/io.h"
#include "jobs/evaluation.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "synthetic/scenario.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"
#include "tracking/noise_estimate.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

using test::CliRun;

// Runs `mcms ARGS` in `scratch`.
CliRun Mcms(const std::string& args, const fs::path& scratch) { return test::Mcms(scratch, args); }

struct Noise {
  double gain, read_noise;
  uint64_t seed;
  double ball_dn = 200;
};

Scenario ThreeCameras(const Noise& n) {
  Scenario sc = Scenario::Default();
  sc.rig.cameras.pop_back();
  sc.rig.names.pop_back();
  sc.times.resize(10);
  sc.T_rig_target.resize(10);
  sc.render.gain_e_per_dn = n.gain;
  sc.render.read_noise_dn = n.read_noise;
  sc.render.ball_dn = n.ball_dn;
  sc.seed = n.seed;
  return sc;
}

// A rendered recording per noise model, shared by the tests (ctest runs each in its own
// process, possibly in parallel): rendered into a folder of this process and renamed into
// place; a process that finds it in place uses it.
fs::path Recording(const Noise& n) {
  char key[96];
  std::snprintf(key, sizeof(key), "noise_rec_g%g_r%g_s%llu_b%g", n.gain, n.read_noise,
                static_cast<unsigned long long>(n.seed), n.ball_dn);
  const fs::path shared = fs::path(MCMS_BINARY_DIR) / "test-scratch" / key / "rec";
  const Scenario sc = ThreeCameras(n);
  if (fs::exists(shared / "truth" / "poses.csv") && test::ReadAll(shared / "scenario.yaml") == sc.ToYaml()) return shared;
  std::error_code ec;
  fs::remove_all(shared, ec);  // absent, incomplete or of another scenario
  const fs::path mine = test::ScratchDir(std::string(key) + "_" + std::to_string(::getpid())) / "rec";
  RenderSequence(sc, mine, true, 2);
  fs::create_directories(shared.parent_path());
  fs::rename(mine, shared, ec);  // fails when another process was first: use its copy
  fs::remove_all(mine.parent_path(), ec);
  return shared;
}

struct TrackStats {
  double mean_nees = 0, band_lo = 0, band_hi = 0;
  double mean_position_var = 0;  // mean trace of the position block, m^2
  int frames = 0;
  std::vector<std::string> comments;
};

// poses.csv against truth/poses.csv.
TrackStats Evaluate(const fs::path& poses, const fs::path& truth_csv) {
  const CsvTable t = ReadCsv(poses), truth = ReadCsv(truth_csv);
  std::map<long, Pose> truth_of;
  for (size_t r = 0; r < truth.rows.size(); ++r) {
    Eigen::Quaterniond q(truth.Number(r, truth.Column("qw")), truth.Number(r, truth.Column("qx")), truth.Number(r, truth.Column("qy")),
           truth.Number(r, truth.Column("qz")));
    truth_of[static_cast<long>(truth.Number(r, truth.Column("frame")))] =
        Pose{q.normalized().toRotationMatrix(),
             Vec3(truth.Number(r, truth.Column("x_m")), truth.Number(r, truth.Column("y_m")),
                  truth.Number(r, truth.Column("z_m")))};
  }
  static const char* kAxes[6] = {"rx", "ry", "rz", "px", "py", "pz"};
  TrackStats s;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    if (t.rows[r][t.Column("status")] == "lost") continue;
    Eigen::Quaterniond q(t.Number(r, t.Column("qw")), t.Number(r, t.Column("qx")), t.Number(r, t.Column("qy")), t.Number(r, t.Column("qz")));
    const Pose est{q.normalized().toRotationMatrix(),
                   Vec3(t.Number(r, t.Column("x_m")), t.Number(r, t.Column("y_m")), t.Number(r, t.Column("z_m")))};
    Mat6 cov;
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j)
        cov(i, j) = t.Number(r, t.Column(std::string("cov_") + kAxes[i] + "_" + kAxes[j]));
    const Vec6 e = BoxMinus(est, truth_of.at(static_cast<long>(t.Number(r, t.Column("frame")))));
    s.mean_nees += e.dot(cov.ldlt().solve(e));
    s.mean_position_var += cov.block<3, 3>(3, 3).trace();
    ++s.frames;
  }
  s.mean_nees /= s.frames;
  s.mean_position_var /= s.frames;
  Chi2Band(6.0 * s.frames, 0.95, &s.band_lo, &s.band_hi);
  s.band_lo /= s.frames;
  s.band_hi /= s.frames;
  std::istringstream in(test::ReadAll(poses));
  for (std::string line; std::getline(in, line) && !line.empty() && line[0] == '#';) s.comments.push_back(line);
  return s;
}

TrackStats Track(const fs::path& rec, const std::string& options, const std::string& tag) {
  const fs::path dir = test::ScratchDir("noise_track_" + tag + "_" + std::to_string(::getpid()));
  const fs::path out = dir / "poses.csv";
  const CliRun r = Mcms("track --quiet " + options + " -o " + out.string() + " " + rec.string(), dir);
  EXPECT_EQ(r.code, 0) << r.err;
  std::printf("mcms track %s:\n%s", options.c_str(), r.out.c_str());
  return Evaluate(out, rec / "truth" / "poses.csv");
}

const Noise kNoises[] = {{2.0, 3.0, 7}, {6.0, 1.5, 8}};

TEST(HonestDefaults, TrackMeasuresTheNoiseModelAndItsCovarianceIsHonest) {
  for (const Noise& n : kNoises) {
    const fs::path rec = Recording(n);
    char truth_gain[32];
    std::snprintf(truth_gain, sizeof(truth_gain), "--gain %g", n.gain);
    const std::string tag = std::to_string(n.seed);
    const TrackStats est = Track(rec, "", "default" + tag);
    const TrackStats exact = Track(rec, truth_gain, "exact" + tag);
    const TrackStats none = Track(rec, "--gain 0", "gain0" + tag);
    std::printf("gain %g, read noise %g DN, seed %llu: mean NEES default %.2f, --gain %g %.2f, --gain 0 %.2f "
                "(band %.2f-%.2f, %d frames); position sigma ratio to the true model: default %.3f, gain 0 %.3f\n",
                n.gain, n.read_noise, static_cast<unsigned long long>(n.seed), est.mean_nees, n.gain, exact.mean_nees,
                none.mean_nees, est.band_lo, est.band_hi, est.frames,
                std::sqrt(est.mean_position_var / exact.mean_position_var),
                std::sqrt(none.mean_position_var / exact.mean_position_var));
    EXPECT_EQ(est.frames, 10);
    EXPECT_GE(est.mean_nees, est.band_lo);
    EXPECT_LE(est.mean_nees, est.band_hi);
    // The covariance from the measured model is the true model's within 5 % in sigma;
    // leaving photon noise out (the old default) makes it at least 20 % too small.
    EXPECT_NEAR(std::sqrt(est.mean_position_var / exact.mean_position_var), 1.0, 0.05);
    EXPECT_LT(std::sqrt(none.mean_position_var / exact.mean_position_var), 0.8);
    // The model is written at the top of poses.csv, with the residual check.
    ASSERT_GE(est.comments.size(), 3u);
    std::string all;
    for (const auto& c : est.comments) all += c + "\n";
    EXPECT_NE(all.find("# noise model: one gain for every camera"), std::string::npos) << all;
    EXPECT_NE(all.find("# pose-fit residuals: chi2/dof"), std::string::npos) << all;
    EXPECT_NE(exact.comments.front().find("(--gain)"), std::string::npos);
    // The pose fits' residuals confirm the measured model and catch the missing photon noise.
    EXPECT_NE(est.comments.back().find("the noise model explains them"), std::string::npos) << est.comments.back();
    EXPECT_NE(none.comments.back().find("LARGER than the noise model predicts"), std::string::npos)
        << none.comments.back();
  }
}

TEST(HonestDefaults, AuditNamesNoCameraOnCleanRecordings) {
  for (const Noise& n : kNoises) {
    const fs::path rec = Recording(n);
    const CliRun r = Mcms("audit cameras --quiet " + rec.string(), test::ScratchDir("noise_audit_" + std::to_string(::getpid())));
    std::printf("%s", r.out.c_str());
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("every camera is consistent"), std::string::npos) << r.out;
  }
}

// Photon noise far above the read noise (gain 0.5, read noise 1 DN): with --gain 0 the
// audit names pixel_noise_scale (the noise model), no camera move or lens term, and
// refuses to write a "repaired" rig; by default it finds nothing.
TEST(HonestDefaults, AuditBlamesTheNoiseModelNotTheCameras) {
  const fs::path rec = Recording({0.5, 1.0, 7, 100});
  const fs::path dir = test::ScratchDir("noise_audit_blame_" + std::to_string(::getpid()));
  const CliRun bad = Mcms("audit cameras -q --gain 0 --json " + (dir / "audit.json").string() + " --repaired-rig " +
                              (dir / "rig.yaml").string() + " " + rec.string(),
                          dir);
  std::printf("%s%s", bad.out.c_str(), bad.err.c_str());
  EXPECT_NE(bad.code, 0);
  EXPECT_NE(bad.out.find("effect pixel_noise_scale"), std::string::npos) << bad.out;
  EXPECT_EQ(bad.out.find("camera_moved"), std::string::npos) << bad.out;
  EXPECT_NE(bad.err.find("larger than the pixel noise model predicts"), std::string::npos) << bad.err;
  EXPECT_FALSE(fs::exists(dir / "rig.yaml"));
  // The report is written all the same (the rig is what cannot be repaired).
  const std::string json = test::ReadAll(dir / "audit.json");
  EXPECT_NE(json.find("\"mode\": \"cameras\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"name\": \"pixel_noise_scale\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"clean\": false"), std::string::npos) << json;
  const CliRun good = Mcms("audit cameras -q --repaired-rig " + (dir / "rig.yaml").string() + " " + rec.string(), dir);
  std::printf("%s", good.out.c_str());
  EXPECT_EQ(good.code, 0) << good.err;
  EXPECT_NE(good.out.find("every camera is consistent"), std::string::npos) << good.out;
}

// Cameras with different sensors: cam0's images from a recording at gain 2, the others
// from the same scene (same seed) at gain 8.
TEST(HonestDefaults, CamerasWithDifferentGainsGetTheirOwn) {
  const fs::path a = Recording(kNoises[0]), b = Recording({8.0, 3.0, kNoises[0].seed});
  const CameraRig rig = CameraRig::Read(b / "rig.yaml");
  ImageSequence seq = ScanImageSequence({b / "images", b / "frames.csv", 10}, rig);
  const ImageSequence seq_a = ScanImageSequence({a / "images", a / "frames.csv", 10}, rig);
  for (size_t i = 0; i < seq.frames.size(); ++i) seq.SetImagePath(i, 0, seq_a.ImagePath(i, 0));
  const SequenceNoiseModel m = EstimateSequenceNoise(seq, rig, BlobDetectorOptions{}, {}, 2);
  for (const auto& line : m.Describe()) std::printf("%s\n", line.c_str());
  ASSERT_TRUE(m.cameras_differ);
  const double truth[3] = {2.0, 8.0, 8.0};
  for (int c = 0; c < 3; ++c) {
    const PixelNoiseEstimate& e = m.per_camera[c];
    EXPECT_NEAR(e.inv_gain, 1 / truth[c], 4 * e.inv_gain_sigma) << rig.names[c];
    EXPECT_DOUBLE_EQ(m.gain_e_per_dn[c], e.gain_e_per_dn);
  }
  // The same recording with one sensor: the cameras agree and share the pooled gain.
  const SequenceNoiseModel same =
      EstimateSequenceNoise(ScanImageSequence({b / "images", b / "frames.csv", 10}, rig), rig, {}, {}, 1);
  EXPECT_FALSE(same.cameras_differ);
  for (double g : same.gain_e_per_dn) EXPECT_DOUBLE_EQ(g, same.pooled.gain_e_per_dn);
  EXPECT_NEAR(same.pooled.inv_gain, 1 / 8.0, 4 * same.pooled.inv_gain_sigma);
}

// Threads change nothing in the output; progress into a file is one line per update.
TEST(HonestDefaults, ThreadsDoNotChangeTheOutputAndRedirectedProgressIsLines) {
  const fs::path rec = Recording(kNoises[0]);
  const fs::path dir = test::ScratchDir("noise_threads_" + std::to_string(::getpid()));
  const fs::path one = dir / "t1.csv", two = dir / "t2.csv";
  const CliRun r1 = Mcms("track --threads 1 -o " + one.string() + " " + rec.string(), dir);
  ASSERT_EQ(r1.code, 0) << r1.err;
  const CliRun r2 = Mcms("track -q --threads 2 -o " + two.string() + " " + rec.string(), dir);
  ASSERT_EQ(r2.code, 0) << r2.err;
  EXPECT_EQ(test::ReadAll(one), test::ReadAll(two));
  EXPECT_EQ(r1.err.find('\r'), std::string::npos);
  EXPECT_NE(r1.err.find("track: 10/10 (100%)\n"), std::string::npos) << r1.err;
  const fs::path s = test::ScratchDir("noise_help");
  for (const char* c : {"track --help", "audit cameras --help", "render --help"})
    EXPECT_NE(Mcms(c, s).out.find("--threads"), std::string::npos) << c;
}

}  // namespace
}  // namespace mcms
