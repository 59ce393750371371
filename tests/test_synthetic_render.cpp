// The synthetic renderer and its scenarios: the ray table's interpolation error, the
// rendered blobs' centroids against the exact sphere-image centroid (the
// sphere-projection bias must be in the images), determinism of the output, the
// default scenario's geometry, the effect options against the truth, scenario file
// round trips and bad scenario files.
#include <numbers>
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "synthetic/renderer.h"
#include "synthetic/recording.h"
#include "synthetic/scenario.h"
#include "tests/test_util.h"
#include "tracking/sequence.h"
#include "vision/sphere_projection.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

// The required agreement of a rendered blob's centroid with SphereImageCentroid.
constexpr double kCentroidTolerancePx = 0.005;
// The ray table's interpolation error bound.
constexpr double kRayTableTolerancePx = 1e-3;

CameraModel PinholeCamera() {
  return CameraModel("LENSMODEL_PINHOLE", {900, 900, 639.5, 511.5}, 1280, 1024);
}
// The default scenario's lens.
CameraModel OpenCv8Camera() {
  return CameraModel("LENSMODEL_OPENCV8", {900, 900, 639.5, 511.5, -0.1, 0.03, 0.0002, -0.0001, 0, 0, 0, 0}, 1280,
                     1024);
}

std::string ReadBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Every regular file under `dir`, relative path -> bytes.
std::map<std::string, std::string> Tree(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = ReadBytes(e.path());
  return files;
}

TEST(RayTable, InterpolationErrorIsBelowTolerance) {
  for (const CameraModel& cam : {PinholeCamera(), OpenCv8Camera()}) {
    SCOPED_TRACE(cam.LensModelName());
    const RayTable table(cam, 8.0);
    std::printf("[ figures ] %s: ray table step %.1f px, error at cell centres %.2e px\n",
                cam.LensModelName().c_str(), table.StepPx(), table.MeasuredErrorPx());
    EXPECT_LT(table.MeasuredErrorPx(), kRayTableTolerancePx);
    // Independent check at random points, including the pad beyond the image.
    Rng rng(7);
    double worst = 0;
    for (int i = 0; i < 5000; ++i) {
      const Vec2 q(rng.Uniform(-8, cam.Width() + 7), rng.Uniform(-8, cam.Height() + 7));
      double x, y;
      ASSERT_TRUE(table.Normalized(q.x(), q.y(), &x, &y));
      worst = std::max(worst, (cam.Project(Vec3(x, y, 1.0)) - q).norm());
    }
    std::printf("[ figures ] %s: worst reprojection error at 5000 random points %.2e px\n",
                cam.LensModelName().c_str(), worst);
    EXPECT_LT(worst, kRayTableTolerancePx);
    double x, y;
    EXPECT_FALSE(table.Normalized(-30, 100, &x, &y));
  }
}

// Background-subtracted intensity centroid of the blob inside the box.
Vec2 BlobCentroid(const cv::Mat& img, double background, const cv::Rect& box) {
  double s = 0, su = 0, sv = 0;
  for (int v = box.y; v < box.y + box.height; ++v)
    for (int u = box.x; u < box.x + box.width; ++u) {
      const double w = img.at<uint16_t>(v, u) - background;
      s += w;
      su += w * u;
      sv += w * v;
    }
  return {su / s, sv / s};
}

TEST(RenderSpheres, BlobCentroidMatchesSphereImageCentroid) {
  RenderOptions o;
  o.bit_depth = 16;
  o.noise_free = true;
  o.background_dn = 1000;
  o.background_gradient_dn = Vec2::Zero();
  o.ball_dn = 41000;
  o.blur_sigma_px = 0.6;
  const double radius = 0.0125, distance = 1.0;
  for (const CameraModel& cam : {PinholeCamera(), OpenCv8Camera()}) {
    SCOPED_TRACE(cam.LensModelName());
    const RayTable table(cam, RenderPadPx(o) + 2.0);
    double worst = 0, corner_bias = 1e9;
    for (double u : {40.0, 333.3, 639.5, 950.7, 1239.0})
      for (double v : {40.0, 270.2, 511.5, 760.9, 983.0}) {
        // The ball 1 m away on the ray of pixel (u, v).
        const Vec3 c = *cam.Unproject(Vec2(u, v)) * distance;
        const cv::Mat img = RenderSpheres(table, {c}, radius, o, nullptr);
        const Ellipse e = EllipseFromOutline(SphereOutline(cam, c, radius));
        const int half = static_cast<int>(std::ceil(e.a)) + 6;
        const cv::Rect box(static_cast<int>(e.centre.x()) - half, static_cast<int>(e.centre.y()) - half, 2 * half + 1,
                           2 * half + 1);
        ASSERT_EQ(box & cv::Rect(0, 0, cam.Width(), cam.Height()), box);
        const Vec2 measured = BlobCentroid(img, o.background_dn, box);
        const Vec2 truth = SphereImageCentroid(cam, c, radius);
        const double err = (measured - truth).norm();
        worst = std::max(worst, err);
        EXPECT_LT(err, kCentroidTolerancePx) << "ball at pixel " << u << ", " << v;
        const double bias = (truth - cam.Project(c)).norm();
        const bool corner = (u < 100 || u > 1200) && (v < 100 || v > 950);
        if (corner) corner_bias = std::min(corner_bias, bias);
      }
    std::printf("[ figures ] %s: worst |rendered centroid - SphereImageCentroid| %.5f px over 25 positions; "
                "smallest corner bias |SphereImageCentroid - Project(c)| %.3f px\n",
                cam.LensModelName().c_str(), worst, corner_bias);
    // The sphere-projection bias near the corners is far above the tolerance: the
    // renderer must not be drawing the disc around Project(c).
    EXPECT_GT(corner_bias, 20 * kCentroidTolerancePx);
  }
}

TEST(RenderSpheres, NoisyBlobCentroidIsUnbiased) {
  // Photon and read noise on a 16-bit image: the centroids of 10 noise draws scatter
  // around the exact one; their mean is within 4 standard errors (plus the
  // noise-free tolerance) of it, and the noise is really there.
  RenderOptions o;
  o.bit_depth = 16;
  o.background_dn = 1000;
  o.background_gradient_dn = Vec2::Zero();
  o.ball_dn = 41000;
  o.gain_e_per_dn = 1.0;
  o.read_noise_dn = 20;
  const CameraModel cam = OpenCv8Camera();
  const RayTable table(cam, RenderPadPx(o) + 2.0);
  const Vec3 c = *cam.Unproject(Vec2(1100, 200)) * 1.0;
  const Vec2 truth = SphereImageCentroid(cam, c, 0.0125);
  const cv::Rect box(static_cast<int>(truth.x()) - 20, static_cast<int>(truth.y()) - 20, 41, 41);
  const int n = 10;
  std::vector<Vec2> draws;
  for (int i = 0; i < n; ++i) {
    Rng rng(100 + i);
    draws.push_back(BlobCentroid(RenderSpheres(table, {c}, 0.0125, o, &rng), o.background_dn, box) - truth);
  }
  Vec2 mean = Vec2::Zero();
  for (const Vec2& d : draws) mean += d / n;
  double var = 0;
  for (const Vec2& d : draws) var += (d - mean).squaredNorm() / (2 * (n - 1));
  const double sigma = std::sqrt(var);
  std::printf("[ figures ] noisy 16-bit blob: centroid spread %.4f px per axis, mean error over %d draws %.4f px\n",
              sigma, n, mean.norm());
  EXPECT_GT(sigma, 1e-4);
  EXPECT_LT(mean.norm(), 4 * sigma * std::sqrt(2.0 / n) + kCentroidTolerancePx);
}

TEST(RenderSpheres, NearerBallCoversFartherOne) {
  // Two balls on nearly the same ray: the image is their union, so its lit area is
  // less than the sum of the two alone, and equals the nearer one's when it covers
  // the farther one completely.
  RenderOptions o;
  o.bit_depth = 16;
  o.noise_free = true;
  o.background_dn = 0;
  o.background_gradient_dn = Vec2::Zero();
  o.ball_dn = 40000;
  const CameraModel cam = PinholeCamera();
  const RayTable table(cam, RenderPadPx(o) + 2.0);
  const Vec3 dir = Vec3(0.1, -0.05, 1.0).normalized();
  const Vec3 near = dir * 0.8, far = dir * 1.6;
  auto lit = [&](const std::vector<Vec3>& cs) { return cv::sum(RenderSpheres(table, cs, 0.0125, o, nullptr))[0]; };
  EXPECT_NEAR(lit({near, far}), lit({near}), 1e-6 * lit({near}));
  const Vec3 beside = (dir + Vec3(0.012, 0, 0)).normalized() * 1.2;
  EXPECT_LT(lit({near, beside}), lit({near}) + lit({beside}) - 0.05 * lit({beside}));
}

// A scenario on the default rig with every effect switched on; `half_size` halves
// the cameras' images (same views) to keep file tests fast.
Scenario EffectsScenario(size_t frames, bool half_size = false) {
  Scenario s = Scenario::Default();
  s.times.resize(frames);
  s.T_rig_target.resize(frames);
  s.render.occlusion_probability = 0.3;
  s.render.dropout_probability = 0.2;
  s.render.spurious_per_image = 2.0;
  if (half_size)
    for (CameraModel& c : s.rig.cameras) {
      std::vector<double> intr = c.Intrinsics();
      for (int i = 0; i < 4; ++i) intr[i] = i < 2 ? intr[i] / 2 : (intr[i] + 0.5) / 2 - 0.5;
      c = CameraModel(c.LensModelName(), intr, c.Width() / 2, c.Height() / 2, c.T_cam_rig());
    }
  return s;
}

TEST(RenderSequence, SameSeedSameBytesOtherSeedOtherBytes) {
  // Two half-size pinhole cameras keep the four renders fast; determinism does not
  // depend on the lens.
  Scenario s = EffectsScenario(4, true);
  s.rig.cameras.resize(2);
  s.rig.names.resize(2);
  for (CameraModel& c : s.rig.cameras) {
    const std::vector<double> intr(c.Intrinsics().begin(), c.Intrinsics().begin() + 4);
    c = CameraModel("LENSMODEL_PINHOLE", intr, c.Width(), c.Height(), c.T_cam_rig());
  }
  const fs::path dir = test::ScratchDir("render_determinism");
  RenderSequence(s, dir / "a", true, 2);
  RenderSequence(s, dir / "b", true, 1);
  const auto a = Tree(dir / "a"), b = Tree(dir / "b");
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [name, bytes] : a) {
    ASSERT_TRUE(b.count(name)) << name;
    EXPECT_TRUE(bytes == b.at(name)) << name << " differs between two renders of the same scenario";
  }
  // No temporary folders left beside the output.
  for (const auto& e : fs::directory_iterator(dir)) EXPECT_TRUE(e.path().filename() == "a" || e.path().filename() == "b");

  // Frames render independently: frame 3 alone equals the sequence's frame 3.
  const RenderedFrame f3 = RenderFrame(s, 3);
  for (size_t c = 0; c < s.rig.size(); ++c) {
    const fs::path png = dir / "a" / "images" / s.rig.names[c] / "000003.png";
    ASSERT_EQ(f3.images[c].empty(), !fs::exists(png));
    if (f3.images[c].empty()) continue;
    const cv::Mat back = cv::imread(png.string(), cv::IMREAD_UNCHANGED);
    EXPECT_EQ(cv::norm(back, f3.images[c], cv::NORM_INF), 0.0);
  }

  Scenario t = s;
  t.seed = s.seed + 1;
  RenderSequence(t, dir / "c", true, 2);
  const auto c = Tree(dir / "c");
  int png_same = 0, png_compared = 0;
  for (const auto& [name, bytes] : c)
    if (name.size() > 4 && name.substr(name.size() - 4) == ".png" && a.count(name)) {
      ++png_compared;
      png_same += bytes == a.at(name);
    }
  EXPECT_GT(png_compared, 0);
  EXPECT_EQ(png_same, 0);

  // Rendering into an existing earlier render replaces it; a foreign folder is refused.
  RenderSequence(s, dir / "a", true, 2);
  EXPECT_EQ(Tree(dir / "a"), a);
  fs::create_directories(dir / "foreign");
  std::ofstream(dir / "foreign" / "notes.txt") << "keep me";
  EXPECT_THROW(RenderSequence(s, dir / "foreign", true), InputError);
  EXPECT_TRUE(fs::exists(dir / "foreign" / "notes.txt"));
}

// Tracking a rendered recording from PNG with predicted windows, the frames read in part
// (FilesOf's image_rows: only the rows the detector reads unfiltered) writes the same
// poses.csv, byte for byte, as with every frame decoded whole, on 1 and 2 threads; also
// from the same frames re-encoded by OpenCV (libpng's filters: rows predicted from the
// row above, so chains of rows are unfiltered).
TEST(RenderSequence, TrackedFromPngRowsInPartGivesTheSamePosesAsWholeFrames) {
  Scenario sc = Scenario::Default();
  sc.times.resize(60);
  sc.T_rig_target.resize(60);
  const fs::path dir = test::ScratchDir("render_png_rows");
  RenderSequence(sc, dir / "rec", true, 2);
  const CameraRig rig = CameraRig::Read(dir / "rec" / "rig.yaml");
  const Target target = Target::Read(dir / "rec" / "target.yaml");
  // The same frames written by OpenCV (libpng's adaptive filters), in a second folder.
  for (const std::string& name : rig.names) {
    fs::create_directories(dir / "libpng" / name);
    for (const auto& e : fs::directory_iterator(dir / "rec" / "images" / name)) {
      const cv::Mat im = cv::imread(e.path().string(), cv::IMREAD_UNCHANGED);
      ASSERT_TRUE(cv::imwrite((dir / "libpng" / name / e.path().filename()).string(), im));
    }
  }
  for (const fs::path& images : {dir / "rec" / "images", dir / "libpng"}) {
    SCOPED_TRACE(images.string());
    const ImageSequence seq = ScanImageSequence({images, dir / "rec" / "frames.csv", 10.0}, rig);
    ASSERT_EQ(seq.frames.size(), 60u);
    auto track = [&](bool in_part, int threads, const std::string& csv) {
      TrackerOptions o;
      o.detector.gain_e_per_dn = sc.render.gain_e_per_dn;
      o.predicted_windows = true;
      Tracker tracker(rig, target, o);
      FrameSource source = FilesOf(seq);
      if (!in_part) source.image_rows = nullptr;
      std::vector<FrameResult> results;
      TrackFramesStreaming(source, tracker, [&](FrameResult&& r) { results.push_back(std::move(r)); }, {}, threads);
      WritePoseCsv(dir / csv, results);
      EXPECT_GT(tracker.window_detections(), 4 * tracker.whole_image_detections());
      return test::ReadAll(dir / csv);
    };
    const std::string whole = track(false, 1, "whole.csv");
    EXPECT_EQ(track(true, 1, "rows_1.csv"), whole);
    EXPECT_EQ(track(true, 2, "rows_2.csv"), whole);
    EXPECT_NE(whole.find("\n59,"), std::string::npos);  // every frame has its row
  }
}

TEST(RenderSequence, OutputFilesMatchTheTruth) {
  Scenario s = EffectsScenario(6, true);
  const fs::path dir = test::ScratchDir("render_files") / "out";
  RenderSequence(s, dir, true, 2);
  for (const char* f : {"scenario.yaml", "rig.yaml", "target.yaml", "frames.csv", "truth/poses.csv", "truth/balls.csv",
                        "truth/observations.csv", "truth/spurious.csv", "truth/dropouts.csv"})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  for (const auto& n : s.rig.names) EXPECT_TRUE(fs::exists(dir / "cameras" / (n + ".cameramodel"))) << n;
  // The written files read back.
  const Scenario back = Scenario::Read(dir / "scenario.yaml");
  EXPECT_EQ(back.NumFrames(), s.NumFrames());
  EXPECT_EQ(CameraRig::Read(dir / "rig.yaml").size(), s.rig.size());
  EXPECT_EQ(Target::Read(dir / "target.yaml").balls_target.size(), s.target.balls_target.size());

  size_t dropped = 0, spurious = 0, obs = 0;
  for (size_t f = 0; f < s.NumFrames(); ++f) {
    const FrameTruth t = FrameTruthOf(s, f);
    dropped += t.dropped_cameras.size();
    spurious += t.spurious.size();
    obs += t.observations.size();
  }
  size_t pngs = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir / "images")) pngs += e.path().extension() == ".png";
  EXPECT_EQ(pngs, s.NumFrames() * s.rig.size() - dropped);
  EXPECT_EQ(ReadCsv(dir / "truth" / "dropouts.csv").rows.size(), dropped);
  EXPECT_EQ(ReadCsv(dir / "truth" / "spurious.csv").rows.size(), spurious);
  EXPECT_EQ(ReadCsv(dir / "truth" / "observations.csv").rows.size(), obs);
  EXPECT_EQ(ReadCsv(dir / "truth" / "poses.csv").rows.size(), s.NumFrames());
  EXPECT_EQ(ReadCsv(dir / "truth" / "balls.csv").rows.size(), s.NumFrames() * s.target.balls_target.size());
  const CsvTable frames = ReadCsv(dir / "frames.csv");
  ASSERT_EQ(frames.rows.size(), s.NumFrames());
  EXPECT_DOUBLE_EQ(frames.Number(5, frames.Column("time_s")), s.times[5]);
  const CsvTable o = ReadCsv(dir / "truth" / "observations.csv");
  for (const char* col : {"frame", "camera", "ball", "visible", "occluded", "u_centre_px", "v_centre_px",
                          "u_centroid_px", "v_centroid_px", "ellipse_a_px", "ellipse_b_px", "ellipse_angle_rad"})
    EXPECT_TRUE(o.HasColumn(col)) << col;
}

TEST(DefaultScenario, TargetStaysInsideTheVolumeAndInEveryCamera) {
  const Scenario s = Scenario::Default();
  ASSERT_EQ(s.rig.size(), 4u);
  ASSERT_EQ(s.NumFrames(), 120u);
  EXPECT_NEAR(s.times[1] - s.times[0], 0.1, 1e-12);
  EXPECT_DOUBLE_EQ(s.target.ball_radius, 0.0125);
  // The working volume is inside every camera's view.
  for (const CameraModel& cam : s.rig.cameras)
    for (double x : {-0.5, 0.5})
      for (double y : {-0.4, 0.4})
        for (double z : {0.0, 1.0}) EXPECT_TRUE(cam.Sees(cam.T_cam_rig() * Vec3(x, y, z), 20.0));
  size_t visible = 0, total = 0, overlapped = 0;
  double max_angle = 0;
  for (size_t f = 0; f < s.NumFrames(); ++f) {
    const FrameTruth t = FrameTruthOf(s, f);
    EXPECT_TRUE(t.dropped_cameras.empty());
    EXPECT_TRUE(t.spurious.empty());
    for (const Vec3& b : t.balls_rig) {
      EXPECT_LE(std::abs(b.x()), 0.5);
      EXPECT_LE(std::abs(b.y()), 0.4);
      EXPECT_GE(b.z(), 0.0);
      EXPECT_LE(b.z(), 1.0);
    }
    max_angle = std::max(max_angle, RotationAngle(t.T_rig_target.R, Mat3::Identity()));
    EXPECT_EQ(t.observations.size(), s.rig.size() * s.target.balls_target.size());
    for (const BallTruth& o : t.observations) {
      ++total;
      visible += o.visible;
      overlapped += o.overlapped;
      EXPECT_FALSE(o.hidden);
    }
  }
  std::printf("[ figures ] default scenario: %zu/%zu ball images complete in view, %zu overlapped by a nearer "
              "ball, largest rotation %.1f deg\n",
              visible, total, overlapped, max_angle * 180 / std::numbers::pi);
  EXPECT_EQ(visible, total);
  EXPECT_LE(overlapped, total / 50);  // nearly always every ball separately
  EXPECT_LE(max_angle, 30.0 * std::numbers::pi / 180 + 1e-9);
  EXPECT_GE(max_angle, 15.0 * std::numbers::pi / 180);  // the orientation does vary
}

TEST(Effects, EventRatesMatchTheOptions) {
  // 120 frames x 4 cameras of truth (no pixels): the event rates against the options,
  // 4-sigma tolerances for the fixed seed.
  const Scenario s = EffectsScenario(120);
  size_t images = 0, dropped = 0, balls = 0, hidden = 0, spurious = 0;
  for (size_t f = 0; f < s.NumFrames(); ++f) {
    const FrameTruth t = FrameTruthOf(s, f);
    images += s.rig.size();
    dropped += t.dropped_cameras.size();
    spurious += t.spurious.size();
    for (const BallTruth& o : t.observations) {
      ++balls;
      hidden += o.hidden;
    }
  }
  const double p_drop = double(dropped) / images, p_hide = double(hidden) / balls;
  const double spur_rate = double(spurious) / (images - dropped);
  std::printf("[ figures ] events: dropout %.3f (0.2), occlusion %.3f (0.3), spurious per image %.2f (2.0)\n", p_drop,
              p_hide, spur_rate);
  EXPECT_NEAR(p_drop, 0.2, 4 * std::sqrt(0.2 * 0.8 / images));
  EXPECT_NEAR(p_hide, 0.3, 4 * std::sqrt(0.3 * 0.7 / balls));
  EXPECT_NEAR(spur_rate, 2.0, 4 * std::sqrt(2.0 / (images - dropped)));
}

TEST(Effects, ImagesMatchTheTruth) {
  // Blobs in the images (threshold halfway between background and the balls) against
  // the truth: dropped cameras have no image, hidden balls are dark, the others and
  // every spurious reflection bright, and in images without overlapping balls the
  // blob count is exactly visible-and-not-hidden balls plus spurious reflections.
  const Scenario s = EffectsScenario(6);
  const ScenarioRenderer renderer(s, 2);
  size_t exact_images = 0, images = 0;
  for (size_t f = 0; f < s.NumFrames(); ++f) {
    const RenderedFrame r = renderer.Render(f);
    for (size_t c = 0; c < s.rig.size(); ++c) {
      const bool dropped = std::count(r.truth.dropped_cameras.begin(), r.truth.dropped_cameras.end(), int(c)) > 0;
      ASSERT_EQ(r.images[c].empty(), dropped);
      if (dropped) continue;
      ++images;
      const cv::Mat& img = r.images[c];
      auto bright = [&](const Vec2& q) {
        return img.at<uint8_t>(static_cast<int>(std::lround(q.y())), static_cast<int>(std::lround(q.x()))) > 100;
      };
      size_t expected = 0;
      // Images where two shown balls overlap or nearly touch (blur joins them at the
      // threshold) have fewer blobs than balls; their count is not checked.
      bool any_touch = false;
      std::vector<const BallTruth*> shown;
      for (const BallTruth& o : r.truth.observations) {
        if (o.camera != int(c)) continue;
        ASSERT_TRUE(o.visible);
        EXPECT_EQ(bright(o.centroid_px), !o.hidden) << "frame " << f << " camera " << c << " ball " << o.ball;
        if (o.hidden) continue;
        ++expected;
        any_touch = any_touch || o.overlapped;
        for (const BallTruth* p : shown)
          any_touch = any_touch || (o.ellipse.centre - p->ellipse.centre).norm() < o.ellipse.a + p->ellipse.a + 2.0;
        shown.push_back(&o);
      }
      for (const SpuriousTruth& sp : r.truth.spurious)
        if (sp.camera == int(c)) {
          EXPECT_TRUE(bright(sp.centre_px));
          ++expected;
        }
      if (any_touch) continue;
      cv::Mat mask, labels;
      cv::threshold(img, mask, 100, 255, cv::THRESH_BINARY);
      const int blobs = cv::connectedComponents(mask, labels, 8) - 1;
      EXPECT_EQ(static_cast<size_t>(blobs), expected) << "frame " << f << " camera " << c;
      ++exact_images;
    }
  }
  std::printf("[ figures ] blob counts checked exactly in %zu of %zu images\n", exact_images, images);
  EXPECT_GE(exact_images, images / 2);
}

TEST(Scenario, WriteReadRoundTrip) {
  Scenario s = Scenario::Default();
  s.seed = 0xFEDCBA9876543210ull;
  s.render.spurious_per_image = 0.7;
  s.render.bit_depth = 16;
  s.render.noise_free = true;
  const fs::path dir = test::ScratchDir("scenario_io");
  s.Write(dir / "s.yaml");
  const Scenario r = Scenario::Read(dir / "s.yaml");
  EXPECT_EQ(r.seed, s.seed);
  ASSERT_EQ(r.rig.size(), s.rig.size());
  for (size_t i = 0; i < s.rig.size(); ++i) {
    EXPECT_EQ(r.rig.names[i], s.rig.names[i]);
    EXPECT_EQ(r.rig.cameras[i].Intrinsics(), s.rig.cameras[i].Intrinsics());
    EXPECT_EQ(r.rig.cameras[i].Width(), s.rig.cameras[i].Width());
    EXPECT_LT(BoxMinus(r.rig.cameras[i].T_cam_rig(), s.rig.cameras[i].T_cam_rig()).norm(), 1e-14);
  }
  EXPECT_EQ(r.target.balls_target, s.target.balls_target);
  EXPECT_EQ(r.target.ball_radius, s.target.ball_radius);
  EXPECT_EQ(r.times, s.times);
  ASSERT_EQ(r.T_rig_target.size(), s.T_rig_target.size());
  for (size_t i = 0; i < s.NumFrames(); ++i) EXPECT_LT(BoxMinus(r.T_rig_target[i], s.T_rig_target[i]).norm(), 1e-14);
  EXPECT_EQ(r.render.bit_depth, 16);
  EXPECT_EQ(r.render.noise_free, true);
  EXPECT_EQ(r.render.spurious_per_image, 0.7);
  EXPECT_EQ(r.render.background_gradient_dn, s.render.background_gradient_dn);
  EXPECT_EQ(r.render.blur_sigma_px, s.render.blur_sigma_px);
  // Writing what was read changes nothing but rounding in the last digit of a pose.
  r.Write(dir / "s2.yaml");
  const Scenario r2 = Scenario::Read(dir / "s2.yaml");
  for (size_t i = 0; i < s.NumFrames(); ++i) EXPECT_LT(BoxMinus(r2.T_rig_target[i], s.T_rig_target[i]).norm(), 1e-14);
}

TEST(Scenario, ReadsJsonAndOtherForms) {
  const fs::path dir = test::ScratchDir("scenario_forms");
  // JSON: inline cameras, inline target, explicit poses timed by the rate.
  std::ofstream(dir / "s.json") << R"({
    "seed": 5,
    "rig": {"cameras": [
      {"name": "left", "lensmodel": "LENSMODEL_PINHOLE", "intrinsics": [800, 800, 319.5, 239.5],
       "imagersize": [640, 480], "rt_cam_rig": [0, 0, 0, 0.1, 0, 0]},
      {"name": "right", "lensmodel": "LENSMODEL_PINHOLE", "intrinsics": [800, 800, 319.5, 239.5],
       "imagersize": [640, 480]}]},
    "target": {"name": "three", "ball_radius_m": 0.01, "balls_m": [[0, 0, 0], [0.1, 0, 0], [0, 0.07, 0]]},
    "motion": {"rate_hz": 5, "poses": [
      {"t_m": [0, 0, 1.5], "q_wxyz": [1, 0, 0, 0]},
      {"t_m": [0.02, 0, 1.5], "q_wxyz": [0.7071, 0.7071, 0, 0]}]},
    "render": {"bit_depth": 16, "spurious_radius_px": [2, 3]}
  })";
  const Scenario j = Scenario::Read(dir / "s.json");
  EXPECT_EQ(j.seed, 5u);
  EXPECT_EQ(j.rig.names, (std::vector<std::string>{"left", "right"}));
  EXPECT_NEAR(j.rig.cameras[0].T_cam_rig().t.x(), 0.1, 1e-15);
  EXPECT_EQ(j.target.balls_target.size(), 3u);
  EXPECT_EQ(j.times, (std::vector<double>{0.0, 0.2}));
  EXPECT_NEAR(RotationAngle(j.T_rig_target[1].R, Mat3::Identity()), std::numbers::pi / 2, 1e-4);
  EXPECT_EQ(j.render.bit_depth, 16);
  EXPECT_EQ(j.render.spurious_radius_max_px, 3.0);
  const RenderedFrame fr = RenderFrame(j, 1);
  ASSERT_EQ(fr.images.size(), 2u);
  EXPECT_EQ(fr.images[0].type(), CV_16U);
  EXPECT_EQ(fr.images[0].cols, 640);

  // A ring generator, a rig file reference and a target file reference.
  j.rig.Write(dir / "rig.yaml");
  j.target.Write(dir / "target.yaml");
  std::ofstream(dir / "ring.yaml") << "rig: {type: ring, count: 6, radius_m: 1.5, height_m: 2, lensmodel: "
                                      "LENSMODEL_PINHOLE, intrinsics: [900, 900, 639.5, 511.5], imagersize: [1280, "
                                      "1024], look_at_m: [0, 0, 0.5]}\n"
                                      "target: target.yaml\n"
                                      "motion: {poses: [{time_s: 0, t_m: [0, 0, 0.5], q_wxyz: [1, 0, 0, 0]}]}\n";
  const Scenario ring = Scenario::Read(dir / "ring.yaml");
  ASSERT_EQ(ring.rig.size(), 6u);
  EXPECT_EQ(ring.rig.names[5], "cam5");
  EXPECT_EQ(ring.target.name, "three");
  for (const CameraModel& cam : ring.rig.cameras) {
    // Every camera looks at (0, 0, 0.5): it projects to the principal point.
    EXPECT_LT((cam.Project(cam.T_cam_rig() * Vec3(0, 0, 0.5)) - Vec2(639.5, 511.5)).norm(), 1e-9);
    EXPECT_NEAR((cam.T_cam_rig().Inverse().t - Vec3(0, 0, 2)).head<2>().norm(), 1.5, 1e-12);
  }
  std::ofstream(dir / "byfile.yaml") << "rig: rig.yaml\ntarget: default\n"
                                        "motion: {rate_hz: 1, poses: [{t_m: [0, 0, 1], q_wxyz: [1, 0, 0, 0]}]}\n";
  EXPECT_EQ(Scenario::Read(dir / "byfile.yaml").rig.names[1], "right");
}

// Expects Read() of `text` to throw an InputError whose message names the file and
// holds every one of `parts`.
void ExpectBadScenario(const std::string& text, const std::vector<std::string>& parts) {
  static int counter = 0;
  const fs::path dir = test::ScratchDir("scenario_bad_" + std::to_string(counter));
  const fs::path file = dir / ("bad" + std::to_string(counter++) + ".yaml");
  std::ofstream(file) << text;
  try {
    Scenario::Read(file);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    for (const auto& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
  }
}

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

TEST(Scenario, BadFilesNameTheFileAndField) {
  const std::string d = Scenario::DefaultText();
  ExpectBadScenario(Replace(d, "  rate_hz: 10\n", ""), {"line", "missing field 'motion.rate_hz'"});
  ExpectBadScenario(Replace(d, "frames: 120", "frames: abc"), {"line 26", "motion.frames", "abc"});
  ExpectBadScenario(Replace(d, "frames: 120", "frames: 0"), {"line 26", "motion.frames", "integer >= 1"});
  ExpectBadScenario(Replace(d, "frames: 120", "frames: [1, 2]"), {"motion.frames", "found a list"});
  ExpectBadScenario(Replace(d, "imagersize: [1280, 1024]", "imagersize: [0, 1024]"),
                    {"line 13", "rig.imagersize", "'0'"});
  ExpectBadScenario(Replace(d, "look_at_m: [0, 0, 0.5]", "look_at_m: [0, 0]"), {"rig.look_at_m", "3 numbers"});
  ExpectBadScenario(Replace(d, "bit_depth: 8", "bit_depth: 12"), {"render.bit_depth", "8 or 16"});
  ExpectBadScenario(Replace(d, "noise_free: false", "noise_free: maybe"), {"render.noise_free"});
  ExpectBadScenario(Replace(d, "dropout_probability: 0 ", "dropout_probability: 1.5 "),
                    {"render", "dropout_probability must be in [0, 1]"});
  ExpectBadScenario(Replace(d, "render:", "rendr:"), {"unknown field 'rendr'"});
  ExpectBadScenario(Replace(d, "LENSMODEL_OPENCV8", "LENSMODEL_FISHEYE9"), {"field 'rig'", "LENSMODEL_FISHEYE9"});
  ExpectBadScenario(Replace(d, "seed: 1", "seed: -3"), {"line 4", "'seed'"});
  ExpectBadScenario(Replace(d, "target: default", "target: missing_target.yaml"), {"field 'target'", "does not exist"});
  ExpectBadScenario("rig:\n  cameras:\n    - {name: a, lensmodel: LENSMODEL_PINHOLE, intrinsics: [1, 1, 0, 0], "
                    "imagersize: [640, 480]}\n    - {name: b, lensmodel: LENSMODEL_PINHOLE, intrinsics: [1, 1, 0, 0], "
                    "imagersize: [640, 0]}\ntarget: default\nmotion: {rate_hz: 1, poses: [{t_m: [0, 0, 1], q_wxyz: "
                    "[1, 0, 0, 0]}]}\n",
                    {"line 4", "rig.cameras[1].imagersize"});
  ExpectBadScenario("rig: {cameras: [{name: a, lensmodel: LENSMODEL_PINHOLE, intrinsics: [1, 1, 0, 0], imagersize: "
                    "[640, 480]}]}\ntarget: default\nmotion: {rate_hz: 1, poses: []}\n",
                    {"motion.poses", "non-empty"});
  ExpectBadScenario("rig: {cameras: [{name: a, lensmodel: LENSMODEL_PINHOLE, intrinsics: [1, 1, 0, 0], imagersize: "
                    "[640, 480]}]}\ntarget: default\nmotion: {poses: [{t_m: [0, 0, 1], q_wxyz: [1, 0, 0, 0]}]}\n",
                    {"motion.rate_hz"});
  ExpectBadScenario("rig: {cameras: [{name: a, lensmodel: LENSMODEL_PINHOLE, intrinsics: [1, 1, 0, 0], imagersize: "
                    "[640, 480]}]}\ntarget: default\nmotion: {rate_hz: 1, poses: [{t_m: [0, 0, 1], q_wxyz: [2, 0, 0, "
                    "0]}]}\n",
                    {"motion.poses[0].q_wxyz", "unit quaternion"});
  ExpectBadScenario("{\"rig\": \"r.yaml\", \"target\": [1,\n 2", {"line", "not valid YAML or JSON"});
  ExpectBadScenario("target: default\nmotion: {type: lissajous}\n", {"missing field 'rig'"});
  ExpectBadScenario(Replace(d, "names: [cam0, cam1, cam2, cam3]", "names: [cam0, cam1, cam2, cam0]"),
                    {"'cam0' is used twice"});
  EXPECT_THROW(Scenario::Read("/nonexistent/scenario.yaml"), InputError);
}

TEST(RenderOptions, IsValidRejectsBadValues) {
  std::string why;
  EXPECT_TRUE(RenderOptions().IsValid(&why)) << why;
  auto bad = [](auto mutate) {
    RenderOptions o;
    mutate(o);
    std::string w;
    return !o.IsValid(&w) && !w.empty();
  };
  EXPECT_TRUE(bad([](RenderOptions& o) { o.bit_depth = 10; }));
  EXPECT_TRUE(bad([](RenderOptions& o) { o.exposure = 0; }));
  EXPECT_TRUE(bad([](RenderOptions& o) { o.blur_sigma_px = -1; }));
  EXPECT_TRUE(bad([](RenderOptions& o) { o.gain_e_per_dn = std::nan(""); }));
  EXPECT_TRUE(bad([](RenderOptions& o) { o.supersampling = 0; }));
  EXPECT_TRUE(bad([](RenderOptions& o) { o.occlusion_probability = -0.1; }));
  EXPECT_TRUE(bad([](RenderOptions& o) { o.spurious_radius_max_px = 0.5; }));
  Scenario s = Scenario::Default();
  s.times[3] = s.times[2];
  EXPECT_FALSE(s.IsValid(&why));
  EXPECT_THROW(RenderSequence(s, test::ScratchDir("render_invalid") / "out", true), InputError);
}

}  // namespace
}  // namespace mcms
