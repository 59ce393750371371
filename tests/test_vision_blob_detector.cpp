// Blob detector: centres against the analytic area centroid of discs and ellipses rendered
// here by supersampling, Monte-Carlo bias and covariance honesty (NEES) under Poisson and
// read noise, dark dots, merged blobs, flags, bad input, and two real ViSP data sets.
#include <numbers>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numeric>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/random.h"
#include "tests/test_util.h"
#include "vision/blob_detector.h"

namespace mcms {
namespace {

// ---------------------------------------------------------------------------------------
// Rendering. The physical order is: the uniformly bright outline, blurred by the PSF, then
// integrated over each pixel. Blurring an already pixel-integrated image instead would
// give a pixel centroid that is off the area centroid by up to 0.01 px for a sharp disc of
// radius 2.5 (the pixelization error the detector must not be blamed for). So the outline
// is sampled on a grid of 16 x 16 sub-samples per pixel, each sub-sample anti-aliased by its
// signed distance to the outline (plain point sampling leaves a 0.002 px centroid error),
// blurred there, and then summed per pixel.
// ---------------------------------------------------------------------------------------
constexpr int kSub = 16;

struct EllipseShape {
  Vec2 centre;
  double a, b, angle;  // semi-axes (px) and the angle of `a` from +x (rad)
};

// Expected image in DN: background + amplitude * (ellipse (x) Gaussian PSF, pixel-integrated).
// Negative amplitude renders a dark dot.
cv::Mat RenderExpected(int width,
                       int height,
                       const std::vector<EllipseShape>& shapes,
                       double background,
                       double amplitude,
                       double psf_sigma) {
  const int W = width * kSub, H = height * kSub;
  cv::Mat fine(H, W, CV_32F, cv::Scalar(0));
  const double h = 1.0 / kSub;
  for (const EllipseShape& e : shapes) {
    // M maps the ellipse onto the unit circle.
    const double c = std::cos(e.angle), s = std::sin(e.angle);
    Mat2 M;
    M << c / e.a, s / e.a, -s / e.b, c / e.b;
    const double reach = e.a + 1;
    const int x0 = std::max(0, static_cast<int>((e.centre.x() - reach + 0.5) * kSub));
    const int x1 = std::min(W - 1, static_cast<int>((e.centre.x() + reach + 0.5) * kSub));
    const int y0 = std::max(0, static_cast<int>((e.centre.y() - reach + 0.5) * kSub));
    const int y1 = std::min(H - 1, static_cast<int>((e.centre.y() + reach + 0.5) * kSub));
    for (int j = y0; j <= y1; ++j) {
      float* row = fine.ptr<float>(j);
      for (int i = x0; i <= x1; ++i) {
        // Sub-sample centre in pixel coordinates (pixel u covers [u-0.5, u+0.5]).
        const Vec2 p((i + 0.5) * h - 0.5, (j + 0.5) * h - 0.5);
        const Vec2 m = M * (p - e.centre);
        const double r = m.norm();
        // Signed distance to the outline, to first order: (|M d| - 1) / |grad |M d||.
        const double grad = r > 0 ? (M.transpose() * m).norm() / r : 1.0;
        const double d = (r - 1) / grad;
        row[i] += static_cast<float>(std::clamp(0.5 - d / h, 0.0, 1.0));
      }
    }
  }
  cv::Mat blurred;
  const double sigma_fine = psf_sigma * kSub;
  const int k = 2 * static_cast<int>(std::ceil(4 * sigma_fine)) + 1;
  cv::GaussianBlur(fine, blurred, cv::Size(k, k), sigma_fine, sigma_fine, cv::BORDER_CONSTANT);
  cv::Mat image(height, width, CV_64F);
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      double sum = 0;
      for (int j = 0; j < kSub; ++j) {
        const float* row = blurred.ptr<float>(v * kSub + j) + u * kSub;
        for (int i = 0; i < kSub; ++i) sum += row[i];
      }
      image.at<double>(v, u) = background + amplitude * sum / (kSub * kSub);
    }
  return image;
}

// Camera noise: Poisson photo-electrons (gain e-/DN) plus Gaussian read noise, rounded to
// integer DN and clipped to the type's range.
cv::Mat AddNoise(const cv::Mat& expected, double gain, double read_noise, int depth, Rng* rng) {
  const double max_dn = depth == CV_8U ? 255 : 65535;
  cv::Mat out(expected.size(), depth);
  for (int v = 0; v < expected.rows; ++v)
    for (int u = 0; u < expected.cols; ++u) {
      const double mean = expected.at<double>(v, u);
      double x = gain > 0 ? rng->Poisson(gain * std::max(mean, 0.0)) / gain : mean;
      x += read_noise * rng->Normal();
      x = std::clamp(std::round(x), 0.0, max_dn);
      if (depth == CV_8U)
        out.at<uint8_t>(v, u) = static_cast<uint8_t>(x);
      else
        out.at<uint16_t>(v, u) = static_cast<uint16_t>(x);
    }
  return out;
}

cv::Mat Quantize(const cv::Mat& expected, int depth) {
  Rng unused(0);
  return AddNoise(expected, 0, 0, depth, &unused);
}

// Quantiles of chi-square(k) by the Wilson-Hilferty approximation (good to 1e-3 at k >= 100).
double ChiSquareQuantile(double k, double z) {
  const double t = 2.0 / (9.0 * k);
  return k * std::pow(1 - t + z * std::sqrt(t), 3);
}

// ---------------------------------------------------------------------------------------
// Noise-free accuracy.
// ---------------------------------------------------------------------------------------

// Centre error budget in a noise-free 16-bit image (rendering error is ~1e-4 px).
constexpr double kNoiseFreeTolPx = 0.005;

TEST(BlobDetector, NoiseFreeCentreIsAreaCentroidAtSubPixelOffsets) {
  const std::vector<EllipseShape> shapes = {
      {{0, 0}, 2.5, 2.5, 0.0},   // small disc
      {{0, 0}, 6.0, 6.0, 0.0},   // disc
      {{0, 0}, 7.0, 4.0, 0.6},   // tilted ellipse
      {{0, 0}, 5.0, 4.6, -1.1},  // a sphere's slightly elliptical image
  };
  double worst = 0;
  for (const EllipseShape& base : shapes)
    for (int i = 0; i < 5; ++i)
      for (int j = 0; j < 5; ++j) {
        EllipseShape e = base;
        // Offsets spread over the pixel, none symmetric about the pixel grid.
        e.centre = Vec2(24 + 0.13 + 0.19 * i, 23 + 0.07 + 0.21 * j);
        const cv::Mat image = Quantize(RenderExpected(48, 48, {e}, 1000, 20000, 0.8), CV_16U);
        const auto blobs = DetectBlobs(image);
        ASSERT_EQ(blobs.size(), 1u) << "a=" << e.a << " b=" << e.b << " offset " << i << "," << j;
        const double err = (blobs[0].centre - e.centre).norm();
        worst = std::max(worst, err);
        EXPECT_LT(err, kNoiseFreeTolPx) << "a=" << e.a << " b=" << e.b << " centre " << e.centre.transpose()
                                        << " found " << blobs[0].centre.transpose();
        EXPECT_FALSE(blobs[0].touches_border || blobs[0].saturated || blobs[0].crowded);
      }
  std::printf("noise-free: worst centre error %.5f px over %zu shapes x 25 offsets\n", worst, shapes.size());
  RecordProperty("worst_centre_error_px", std::to_string(worst));
}

TEST(BlobDetector, DescribesTheBlob) {
  const EllipseShape e{{30.4, 28.7}, 8.0, 5.0, 0.3};
  const double amplitude = 3000, background = 200;
  const cv::Mat image = Quantize(RenderExpected(64, 60, {e}, background, amplitude, 0.7), CV_16U);
  BlobImageStats stats;
  const auto blobs = DetectBlobs(image, {}, &stats);
  ASSERT_EQ(blobs.size(), 1u);
  const Blob& b = blobs[0];
  EXPECT_NEAR(b.flux, amplitude * std::numbers::pi * e.a * e.b, 1e-3 * amplitude * std::numbers::pi * e.a * e.b);
  EXPECT_NEAR(b.background, background, 0.5);
  EXPECT_NEAR(b.peak, amplitude, 0.02 * amplitude);
  EXPECT_NEAR(b.radius_px, std::sqrt(b.area_px / std::numbers::pi), 1e-12);
  // The region is the blurred ellipse above a low threshold: a little larger than a*b.
  EXPECT_GT(b.area_px, std::numbers::pi * e.a * e.b);
  EXPECT_LT(b.area_px, std::numbers::pi * (e.a + 3) * (e.b + 3));
  EXPECT_NEAR(b.circularity, e.b / e.a, 0.1);
  const double angle = 0.5 * std::atan2(2 * b.shape(0, 1), b.shape(0, 0) - b.shape(1, 1));
  EXPECT_NEAR(angle, e.angle, 0.05);
  EXPECT_LT(b.ellipse_residual_px, 0.2);
  EXPECT_NEAR(stats.background_dn, background, 1);
}

// ---------------------------------------------------------------------------------------
// Monte Carlo: bias and covariance honesty.
// ---------------------------------------------------------------------------------------

// Mean error must lie within this many standard errors of zero (per axis).
constexpr double kBiasStandardErrors = 3.0;
constexpr int kMonteCarloRuns = 500;

struct MonteCarloResult {
  Vec2 mean_error, standard_error;
  double mean_nees, rms_reported_sigma, rms_error;
};

MonteCarloResult RunMonteCarlo(const cv::Mat& expected,
                               const Vec2& truth,
                               double gain,
                               double read_noise,
                               const BlobDetectorOptions& options,
                               uint64_t seed) {
  Rng rng(seed);
  std::vector<Vec2> errors;
  double nees = 0, reported = 0;
  for (int k = 0; k < kMonteCarloRuns; ++k) {
    const cv::Mat image = AddNoise(expected, gain, read_noise, CV_16U, &rng);
    const auto blobs = DetectBlobs(image, options);
    EXPECT_EQ(blobs.size(), 1u) << "run " << k;
    if (blobs.size() != 1) continue;
    const Vec2 e = blobs[0].centre - truth;
    errors.push_back(e);
    nees += e.dot(blobs[0].cov.inverse() * e);
    reported += blobs[0].cov.trace();
  }
  MonteCarloResult r;
  const double n = errors.size();
  r.mean_error = std::accumulate(errors.begin(), errors.end(), Vec2(Vec2::Zero())) / n;
  Vec2 var = Vec2::Zero();
  double sq = 0;
  for (const Vec2& e : errors) {
    var += (e - r.mean_error).cwiseAbs2();
    sq += e.squaredNorm();
  }
  r.standard_error = (var / (n - 1)).cwiseSqrt() / std::sqrt(n);
  r.mean_nees = nees / n;
  r.rms_reported_sigma = std::sqrt(reported / n);
  r.rms_error = std::sqrt(sq / n);
  return r;
}

void CheckMonteCarlo(const MonteCarloResult& r, const std::string& what) {
  const double lo = ChiSquareQuantile(2.0 * kMonteCarloRuns, -1.959964) / kMonteCarloRuns;
  const double hi = ChiSquareQuantile(2.0 * kMonteCarloRuns, 1.959964) / kMonteCarloRuns;
  std::printf("%s: mean error (%+.5f, %+.5f) px, standard error (%.5f, %.5f), mean NEES %.3f in [%.3f, %.3f], "
              "rms error %.4f px, reported %.4f px\n",
              what.c_str(), r.mean_error.x(), r.mean_error.y(), r.standard_error.x(), r.standard_error.y(),
              r.mean_nees, lo, hi, r.rms_error, r.rms_reported_sigma);
  EXPECT_LT(std::abs(r.mean_error.x()), kBiasStandardErrors * r.standard_error.x()) << what;
  EXPECT_LT(std::abs(r.mean_error.y()), kBiasStandardErrors * r.standard_error.y()) << what;
  EXPECT_GT(r.mean_nees, lo) << what;
  EXPECT_LT(r.mean_nees, hi) << what;
}

// Camera used for the Monte Carlo: 2 e-/DN, 3 DN read noise, 16-bit output.
constexpr double kGain = 2.0, kReadNoise = 3.0;

TEST(BlobDetector, MonteCarloBrightDiscIsUnbiasedWithHonestCovariance) {
  const double background = 50;
  const EllipseShape e{{20.37, 19.81}, 4.0, 4.0, 0.0};
  const cv::Mat expected = RenderExpected(40, 40, {e}, background, 400, 0.8);
  BlobDetectorOptions options;
  options.gain_e_per_dn = kGain;
  // Noise measured from the ring around each blob (read_noise_dn = 0).
  CheckMonteCarlo(RunMonteCarlo(expected, e.centre, kGain, kReadNoise, options, 11), "disc, noise from ring");
  // Noise given: a background pixel's noise is read noise, its shot noise and quantization.
  options.read_noise_dn = std::sqrt(kReadNoise * kReadNoise + background / kGain + 1.0 / 12);
  CheckMonteCarlo(RunMonteCarlo(expected, e.centre, kGain, kReadNoise, options, 12), "disc, noise given");
}

TEST(BlobDetector, MonteCarloBrightEllipseIsUnbiasedWithHonestCovariance) {
  const EllipseShape e{{22.71, 21.26}, 6.0, 3.5, 0.5};
  const cv::Mat expected = RenderExpected(44, 44, {e}, 30, 250, 1.0);
  BlobDetectorOptions options;
  options.gain_e_per_dn = kGain;
  CheckMonteCarlo(RunMonteCarlo(expected, e.centre, kGain, kReadNoise, options, 13), "ellipse, noise from ring");
}

TEST(BlobDetector, MonteCarloDarkDotIsUnbiasedWithHonestCovariance) {
  const EllipseShape e{{21.58, 20.44}, 5.0, 4.2, -0.7};
  // A dark dot on a bright background: shot noise is largest outside the dot.
  const cv::Mat expected = RenderExpected(42, 42, {e}, 2000, -1500, 0.9);
  BlobDetectorOptions options;
  options.polarity = Polarity::kDark;
  options.gain_e_per_dn = kGain;
  CheckMonteCarlo(RunMonteCarlo(expected, e.centre, kGain, kReadNoise, options, 14), "dark dot, noise from ring");
}

// ---------------------------------------------------------------------------------------
// Dark dots, several blobs, flags.
// ---------------------------------------------------------------------------------------

TEST(BlobDetector, FindsDarkDotsOnBrightAndOnlyWithDarkPolarity) {
  std::vector<EllipseShape> dots;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dots.push_back({{20.3 + 30 * i + 0.11 * j, 19.6 + 30 * j + 0.17 * i}, 6, 5.5, 0.2 * i});
  const cv::Mat image = Quantize(RenderExpected(100, 100, dots, 3000, -2500, 0.8), CV_16U);
  BlobDetectorOptions dark;
  dark.polarity = Polarity::kDark;
  const auto blobs = DetectBlobs(image, dark);
  ASSERT_EQ(blobs.size(), dots.size());
  for (const EllipseShape& d : dots) {
    const auto it = std::min_element(blobs.begin(), blobs.end(), [&](const Blob& x, const Blob& y) {
      return (x.centre - d.centre).norm() < (y.centre - d.centre).norm();
    });
    EXPECT_LT((it->centre - d.centre).norm(), kNoiseFreeTolPx);
    EXPECT_GT(it->flux, 0);
    EXPECT_NEAR(it->background, 3000, 0.5);
  }
  // Bright polarity sees no bright blob on this image.
  EXPECT_TRUE(DetectBlobs(image).empty());
}

TEST(BlobDetector, EightBitAndColourInputs) {
  const std::vector<EllipseShape> shapes = {{{15.3, 14.8}, 4, 4, 0}, {{45.6, 20.2}, 3, 3, 0}, {{30.1, 44.9}, 5, 4, 1}};
  const cv::Mat expected = RenderExpected(64, 64, shapes, 10, 200, 0.8);
  Rng rng(5);
  const cv::Mat gray = AddNoise(expected, 0, 1.5, CV_8U, &rng);
  const auto blobs = DetectBlobs(gray);
  ASSERT_EQ(blobs.size(), 3u);
  // Ordered by decreasing flux: the largest shape first, the smallest last.
  EXPECT_LT((blobs[0].centre - shapes[2].centre).norm(), 0.1);
  EXPECT_LT((blobs[2].centre - shapes[1].centre).norm(), 0.1);
  for (const Blob& b : blobs) {
    // Every error within 4 reported sigmas (a loose, per-blob check).
    const Vec2 err = b.centre - std::min_element(shapes.begin(), shapes.end(), [&](auto& x, auto& y) {
                                  return (x.centre - b.centre).norm() < (y.centre - b.centre).norm();
                                })->centre;
    EXPECT_LT(std::sqrt(err.dot(b.cov.inverse() * err)), 4.0);
  }
  cv::Mat bgr;
  cv::cvtColor(gray, bgr, cv::COLOR_GRAY2BGR);
  const auto from_bgr = DetectBlobs(bgr);
  ASSERT_EQ(from_bgr.size(), blobs.size());
  for (size_t i = 0; i < blobs.size(); ++i) EXPECT_LT((from_bgr[i].centre - blobs[i].centre).norm(), 1e-12);
}

// With the default options (min_area_px * min_circularity > 1) the scan reads only the
// even rows and labels the rows around their hits: every region of two rows or more, on
// any row parity and at the last row, must still be found whole, giving the same blobs as
// the full scan (forced here by a lower min_circularity, whose extra candidates are then
// filtered out), in 8 and 16 bits.
TEST(BlobDetector, EvenRowScanFindsTheSameBlobsAsTheFullScan) {
  const std::vector<EllipseShape> shapes = {{{20.3, 20.8}, 4, 4, 0},   {{60.6, 21.2}, 3, 2.2, 0.3},
                                            {{100.1, 40.5}, 5, 4, 1},  {{30.2, 61.0}, 1.4, 1.4, 0},
                                            {{80.7, 62.0}, 1.2, 1.0, 0}, {{120.4, 77.6}, 3, 3, 0}};
  const cv::Mat expected = RenderExpected(140, 80, shapes, 10, 200, 0.8);
  for (int depth : {CV_8U, CV_16U}) {
    Rng rng(11);
    cv::Mat img = AddNoise(expected, 0, 1.5, depth, &rng);
    // A one-row streak of 6 px on an odd row whose neighbours hold no blob (circularity 1/6).
    for (int x = 40; x < 46; ++x) {
      if (depth == CV_8U)
        img.at<uint8_t>(51, x) = 220;
      else
        img.at<uint16_t>(51, x) = 220;
    }
    BlobDetectorOptions fast;  // the defaults: min_area_px 3 x min_circularity 0.5 > 1
    ASSERT_GT(fast.min_area_px * fast.min_circularity, 1.0);
    BlobDetectorOptions full = fast;
    full.min_circularity = 0.3;  // 3 x 0.3 < 1: every row is labelled
    BlobImageStats fast_stats, full_stats;
    const std::vector<Blob> a = DetectBlobs(img, fast, &fast_stats);
    std::vector<Blob> b = DetectBlobs(img, full, &full_stats);
    b.erase(std::remove_if(b.begin(), b.end(), [&](const Blob& x) { return x.circularity < fast.min_circularity; }),
            b.end());
    EXPECT_EQ(full_stats.num_regions, fast_stats.num_regions + 1) << "the lone streak is only seen by the full scan";
    EXPECT_GE(a.size(), 5u);
    ASSERT_EQ(a.size(), b.size()) << "depth " << depth;
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].centre, b[i].centre) << i;
      EXPECT_EQ(a[i].cov, b[i].cov) << i;
      EXPECT_EQ(a[i].flux, b[i].flux) << i;
      EXPECT_EQ(a[i].area_px, b[i].area_px) << i;
      EXPECT_EQ(a[i].crowded, b[i].crowded) << i;
    }
  }
}

// Windows around blobs measure them as the whole image does; a window that cuts a blob
// flags it; windows that overlap are merged (each blob found once).
TEST(BlobDetector, WindowsMeasureAsTheWholeImageAndFlagACutBlob) {
  const std::vector<EllipseShape> shapes = {{{30.3, 30.8}, 4, 4, 0}, {{90.6, 31.2}, 3, 2.2, 0.3},
                                            {{100.1, 60.5}, 5, 4, 1}, {{40.2, 66.0}, 3, 3, 0}};
  const cv::Mat expected = RenderExpected(140, 90, shapes, 10, 200, 0.8);
  for (int depth : {CV_8U, CV_16U}) {
    Rng rng(5);
    const cv::Mat img = AddNoise(expected, 0, 1.5, depth, &rng);
    BlobImageStats whole_stats, window_stats;
    const std::vector<Blob> whole = DetectBlobs(img, {}, &whole_stats);
    ASSERT_EQ(whole.size(), 4u);
    // Windows of +-22 px around the first three blobs (two of them overlap), none around
    // the fourth; one far outside the image.
    std::vector<cv::Rect> windows;
    for (size_t i = 0; i < 3; ++i)
      windows.emplace_back(static_cast<int>(shapes[i].centre.x()) - 22, static_cast<int>(shapes[i].centre.y()) - 22, 45, 45);
    windows.emplace_back(500, 500, 10, 10);
    EXPECT_EQ(MergeWindows(windows, img.size()).size(), 2u);
    const std::vector<Blob> in = DetectBlobsInWindows(img, windows, {}, &window_stats);
    EXPECT_EQ(window_stats.threshold_dn, whole_stats.threshold_dn);
    EXPECT_EQ(window_stats.background_dn, whole_stats.background_dn);
    // The whole image takes its sample during the pass that reads every row; windows take
    // it alone: the same figures.
    EXPECT_EQ(window_stats.noise_dn, whole_stats.noise_dn);
    ASSERT_EQ(in.size(), 3u) << "depth " << depth;
    for (const Blob& b : in) {
      const auto same = std::find_if(whole.begin(), whole.end(),
                                     [&](const Blob& w) { return (w.centre - b.centre).norm() < 1e-9; });
      ASSERT_NE(same, whole.end()) << b.centre.transpose();
      EXPECT_NEAR(same->cov(0, 0), b.cov(0, 0), 1e-12);
      EXPECT_NEAR(same->flux, b.flux, 1e-9);
      EXPECT_EQ(same->area_px, b.area_px);
      EXPECT_FALSE(b.touches_border);
    }
    // A window that holds the blob's region but not its measurement window and ring.
    const std::vector<Blob> cut = DetectBlobsInWindows(img, {cv::Rect(24, 24, 14, 14)});
    ASSERT_EQ(cut.size(), 1u);
    EXPECT_TRUE(cut[0].touches_border);
  }
  EXPECT_THROW(DetectBlobsInWindows(cv::Mat(), {cv::Rect(0, 0, 5, 5)}), InputError);
}

// DetectBlobsInWindows reads only the rows RowsReadInWindows lists (a frame read in part,
// vision/image_file.h ImageFileRows, holds only those): with every other row overwritten,
// the same blobs and statistics. 637 px wide, the sample's last column is the image's
// last, so the row below each sampled row is read too.
TEST(BlobDetector, WindowsReadOnlyTheRowsRowsReadInWindowsLists) {
  const std::vector<EllipseShape> shapes = {{{100.3, 80.8}, 4, 4, 0}, {{400.6, 300.2}, 3, 2.2, 0.3},
                                            {{420.1, 330.5}, 5, 4, 1}, {{600.2, 450.0}, 3, 3, 0}};
  const cv::Mat rendered = RenderExpected(640, 480, shapes, 10, 200, 0.8);
  for (const int width : {640, 637}) {
    const cv::Mat expected = rendered.colRange(0, width).clone();
    for (int depth : {CV_8U, CV_16U}) {
      SCOPED_TRACE(std::to_string(width) + " px, depth " + std::to_string(depth));
      Rng rng(7);
      const cv::Mat img = AddNoise(expected, 0, 1.5, depth, &rng);
      std::vector<cv::Rect> windows;
      for (size_t i = 0; i < 3; ++i)
        windows.emplace_back(static_cast<int>(shapes[i].centre.x()) - 25, static_cast<int>(shapes[i].centre.y()) - 25, 51, 51);
      const std::vector<cv::Range> rows = RowsReadInWindows(img.size(), windows);
      cv::Mat part(img.size(), img.type(), cv::Scalar(depth == CV_8U ? 255 : 65535));
      int listed = 0, previous_end = -1;
      for (const cv::Range& r : rows) {
        EXPECT_GT(r.start, previous_end) << "ranges sorted, disjoint and not touching";
        previous_end = r.end;
        img.rowRange(r).copyTo(part.rowRange(r));
        listed += r.size();
      }
      EXPECT_LT(listed, img.rows / 2);
      BlobImageStats a, b;
      const std::vector<Blob> in_img = DetectBlobsInWindows(img, windows, {}, &a);
      const std::vector<Blob> in_part = DetectBlobsInWindows(part, windows, {}, &b);
      EXPECT_EQ(a.background_dn, b.background_dn);
      EXPECT_EQ(a.noise_dn, b.noise_dn);
      EXPECT_EQ(a.threshold_dn, b.threshold_dn);
      EXPECT_EQ(a.num_regions, b.num_regions);
      ASSERT_EQ(in_img.size(), 3u);
      ASSERT_EQ(in_img.size(), in_part.size());
      for (size_t i = 0; i < in_img.size(); ++i) {
        EXPECT_EQ(in_img[i].centre, in_part[i].centre) << i;
        EXPECT_EQ(in_img[i].cov, in_part[i].cov) << i;
        EXPECT_EQ(in_img[i].flux, in_part[i].flux) << i;
      }
    }
  }
}

TEST(BlobDetector, FlagsSaturationAndTheBorder) {
  const std::vector<EllipseShape> shapes = {{{20.2, 20.4}, 4, 4, 0}, {{2.5, 30.3}, 4, 4, 0}};
  // 8-bit with a peak of 10 + 400 DN: the first disc clips at 255.
  const cv::Mat image = Quantize(RenderExpected(48, 48, shapes, 10, 400, 0.8), CV_8U);
  const auto blobs = DetectBlobs(image);
  ASSERT_EQ(blobs.size(), 2u);
  const Blob& inner = (blobs[0].centre.x() > 10) ? blobs[0] : blobs[1];
  const Blob& edge = (blobs[0].centre.x() > 10) ? blobs[1] : blobs[0];
  EXPECT_TRUE(inner.saturated);
  EXPECT_FALSE(inner.touches_border);
  EXPECT_TRUE(edge.touches_border);
  // A lower saturation level for a sensor whose range is not the type's.
  BlobDetectorOptions options;
  options.saturation_dn = 4095;
  const cv::Mat unclipped = Quantize(RenderExpected(48, 48, {shapes[0]}, 10, 400, 0.8), CV_16U);
  ASSERT_EQ(DetectBlobs(unclipped, options).size(), 1u);
  EXPECT_FALSE(DetectBlobs(unclipped, options)[0].saturated);
  options.saturation_dn = 300;
  EXPECT_TRUE(DetectBlobs(unclipped, options)[0].saturated);
}

TEST(BlobDetector, MergedDiscsAreNotOneConfidentDisc) {
  // Two discs of radius 5 whose centres are 1.6 to 2.2 radii apart: one region, elongated
  // (circularity 0.45..0.65) and with a waist. Noise-free and with camera noise.
  Rng rng(21);
  int reported = 0;
  for (const double separation : {8.0, 9.0, 10.0, 11.0}) {
    const std::vector<EllipseShape> pair = {{{25.3, 30.2}, 5, 5, 0}, {{25.3 + separation, 30.2}, 5, 5, 0}};
    const Vec2 mid = 0.5 * (pair[0].centre + pair[1].centre);
    const cv::Mat expected = RenderExpected(64, 60, pair, 20, 1000, 0.8);
    for (int k = 0; k < 20; ++k) {
      const cv::Mat image = k == 0 ? Quantize(expected, CV_16U) : AddNoise(expected, kGain, kReadNoise, CV_16U, &rng);
      for (const Blob& b : DetectBlobs(image)) {
        ++reported;
        EXPECT_FALSE((b.centre - mid).norm() < 3 && !b.crowded)
            << "separation " << separation << ": merged pair reported as one disc at " << b.centre.transpose()
            << " circularity " << b.circularity << " ellipse residual " << b.ellipse_residual_px;
      }
    }
  }
  std::printf("merged pairs: %d of 80 images gave a (flagged) blob, the others none\n", reported);
  // Far apart they are two clean discs.
  const std::vector<EllipseShape> apart = {{{16.3, 30.2}, 5, 5, 0}, {{46.1, 30.7}, 5, 5, 0}};
  const auto blobs = DetectBlobs(Quantize(RenderExpected(64, 60, apart, 20, 1000, 0.8), CV_16U));
  ASSERT_EQ(blobs.size(), 2u);
  for (const Blob& b : blobs) {
    EXPECT_FALSE(b.crowded);
    EXPECT_LT(std::min((b.centre - apart[0].centre).norm(), (b.centre - apart[1].centre).norm()), kNoiseFreeTolPx);
  }
}

TEST(BlobDetector, EstimatesTheImageNoiseFromASparseSample) {
  // A 1280 x 1024 image with a gentle gradient, a few discs and 4 DN of noise.
  cv::Mat expected(1024, 1280, CV_64F);
  for (int v = 0; v < expected.rows; ++v)
    for (int u = 0; u < expected.cols; ++u) expected.at<double>(v, u) = 100 + 0.01 * u + 0.02 * v;
  Rng rng(9);
  cv::Mat image = AddNoise(expected, 0, 4.0, CV_16U, &rng);
  const std::vector<EllipseShape> shapes = {{{40.3, 50.2}, 4, 4, 0}, {{30.6, 20.1}, 3, 3, 0}};
  const cv::Mat spots = Quantize(RenderExpected(64, 64, shapes, 0, 2000, 0.8), CV_16U);
  for (int k = 0; k < 4; ++k) {
    cv::Mat roi = image(cv::Rect(100 + 300 * k, 200 + 150 * k, 64, 64));
    cv::add(roi, spots, roi);
  }
  BlobImageStats stats;
  const auto blobs = DetectBlobs(image, {}, &stats);
  EXPECT_EQ(blobs.size(), 8u);
  const double true_noise = std::sqrt(16 + 1.0 / 12);
  EXPECT_NEAR(stats.noise_dn, true_noise, 0.1 * true_noise);
  EXPECT_NEAR(stats.threshold_dn, 8 * stats.noise_dn, 1e-9);
  for (const Blob& b : blobs) EXPECT_NEAR(b.noise_dn, true_noise, 0.2 * true_noise);
}

// ---------------------------------------------------------------------------------------
// Bad input.
// ---------------------------------------------------------------------------------------

using test::ErrorOf;

TEST(BlobDetector, RejectsBadImages) {
  EXPECT_NE(ErrorOf([] { DetectBlobs(cv::Mat()); }).find("empty"), std::string::npos);
  const std::string f32 = ErrorOf([] { DetectBlobs(cv::Mat(8, 8, CV_32F, cv::Scalar(1))); });
  EXPECT_NE(f32.find("CV_8U or CV_16U"), std::string::npos) << f32;
  cv::Mat with_nan(8, 8, CV_32F, cv::Scalar(1));
  with_nan.at<float>(3, 4) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(ErrorOf([&] { DetectBlobs(with_nan); }).find("NaN"), std::string::npos);
  EXPECT_NE(ErrorOf([] { DetectBlobs(cv::Mat(8, 8, CV_8S, cv::Scalar(1))); }).find("CV_8U or CV_16U"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { DetectBlobs(cv::Mat(8, 8, CV_8UC2, cv::Scalar(1, 1))); }).find("channels"),
            std::string::npos);
  // A tiny or flat image is valid input with no blobs.
  EXPECT_TRUE(DetectBlobs(cv::Mat(1, 1, CV_8U, cv::Scalar(7))).empty());
  EXPECT_TRUE(DetectBlobs(cv::Mat(30, 40, CV_16U, cv::Scalar(1000))).empty());
}

TEST(BlobDetector, RejectsInvalidOptions) {
  std::string why;
  EXPECT_TRUE(BlobDetectorOptions().IsValid(&why)) << why;
  const std::vector<std::pair<std::string, std::function<void(BlobDetectorOptions&)>>> cases = {
      {"threshold_dn", [](auto& o) { o.threshold_dn = -1; }},
      {"threshold_dn", [](auto& o) { o.threshold_dn = std::numeric_limits<double>::quiet_NaN(); }},
      {"k_sigma", [](auto& o) { o.k_sigma = 0; }},
      {"min_area_px", [](auto& o) { o.min_area_px = 0; }},
      {"max_area_px", [](auto& o) { o.max_area_px = 2, o.min_area_px = 3; }},
      {"min_circularity", [](auto& o) { o.min_circularity = 1.5; }},
      {"max_ellipse_residual_px", [](auto& o) { o.max_ellipse_residual_px = -0.1; }},
      {"min_peak_snr", [](auto& o) { o.min_peak_snr = -1; }},
      {"read_noise_dn", [](auto& o) { o.read_noise_dn = -2; }},
      {"gain_e_per_dn", [](auto& o) { o.gain_e_per_dn = std::numeric_limits<double>::infinity(); }},
      {"saturation_dn", [](auto& o) { o.saturation_dn = -5; }},
      {"window_margin_px", [](auto& o) { o.window_margin_px = 0; }},
      {"max_window_margin_px", [](auto& o) { o.max_window_margin_px = 2, o.window_margin_px = 3; }},
      {"ring_width_px", [](auto& o) { o.ring_width_px = 0; }},
      {"polarity", [](auto& o) { o.polarity = static_cast<Polarity>(7); }},
  };
  const cv::Mat image(16, 16, CV_8U, cv::Scalar(0));
  for (const auto& [field, spoil] : cases) {
    BlobDetectorOptions o;
    spoil(o);
    EXPECT_FALSE(o.IsValid(&why)) << field;
    EXPECT_NE(why.find(field), std::string::npos) << why;
    const std::string message = ErrorOf([&] { DetectBlobs(image, o); });
    EXPECT_NE(message.find("BlobDetectorOptions"), std::string::npos) << field;
    EXPECT_NE(message.find(field), std::string::npos) << message;
  }
}

// ---------------------------------------------------------------------------------------
// Real data.
// ---------------------------------------------------------------------------------------

// ViSP's "mire" sequence: a black plate with one large and four small white dots, moved by
// hand in front of a cluttered scene (posters, a photo with lit windows, white card).
// Options, and why (figures measured over all 501 frames; "clutter" = regions that are not
// dots and pass every other test):
//  - threshold_dn 100 above the image median: the dots are ~250 DN on a ~50 DN plate, the
//    median is 80..130 DN; any level between the plate and the dots separates them.
//  - min_area_px 50: the small dots cover >= 59 px at this level, bright specks <= 39 px.
//  - max_area_px 4000: the large dot covers <= 2660 px; white card regions are larger.
//  - min_circularity 0.25: the plate is seen at up to ~70 degrees, its dots then have an
//    axis ratio down to 0.27.
//  - max_ellipse_residual_px 0.3: the dots' outlines are within 0.17 px of an ellipse on
//    average, clutter (lit windows, card corners, poster text) >= 0.40 px.
//  - min_peak_snr 10: dots stand >= 15.9 ring-noise sigmas above the plate, bright poster
//    texture <= 7.1 above its own rough surroundings.
BlobDetectorOptions MireOptions() {
  BlobDetectorOptions o;
  o.threshold_dn = 100;
  o.min_area_px = 50;
  o.max_area_px = 4000;
  o.min_circularity = 0.25;
  o.max_ellipse_residual_px = 0.3;
  o.min_peak_snr = 10;
  return o;
}

// Largest frame-to-frame motion of a dot: measured 14.9 px (fast hand motion, frame 201).
constexpr double kMaxDotJumpPx = 18.0;

TEST(BlobDetectorRealData, ViSPMireSequenceFiveDotsContinuousOverTime) {
  MCMS_REQUIRE_DATA(dir, "visp-mire-sequence");
  const BlobDetectorOptions options = MireOptions();
  std::vector<Vec2> previous;
  double worst_jump = 0;
  int worst_frame = 0, frames = 0;
  for (int f = 1; f <= 501; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "image.%04d.png", f);
    const cv::Mat image = cv::imread((dir / name).string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(image.empty()) << (dir / name);
    // Blobs cut by the image border are flagged and left to the caller; here they are
    // bright patches entering at the edge, never the dots (which stay inside the frame).
    std::vector<Blob> blobs;
    for (const Blob& b : DetectBlobs(image, options))
      if (!b.touches_border) blobs.push_back(b);
    ASSERT_EQ(blobs.size(), 5u) << name;
    for (const Blob& b : blobs) EXPECT_FALSE(b.crowded || b.saturated) << name << " " << b.centre.transpose();
    ++frames;
    std::vector<Vec2> current;
    for (const Blob& b : blobs) current.push_back(b.centre);
    // One large dot and four small ones: the large one has the largest flux by far.
    EXPECT_GT(blobs[0].flux, 3 * blobs[1].flux) << name;
    if (!previous.empty()) {
      // Nearest neighbour in the previous frame for each dot; the assignment must be
      // one-to-one for the dots to be continuous tracks.
      std::vector<int> used(previous.size(), 0);
      for (const Vec2& c : current) {
        int best = 0;
        for (size_t k = 1; k < previous.size(); ++k)
          if ((previous[k] - c).norm() < (previous[best] - c).norm()) best = static_cast<int>(k);
        ++used[best];
        const double jump = (previous[best] - c).norm();
        if (jump > worst_jump) {
          worst_jump = jump;
          worst_frame = f;
        }
      }
      for (int u : used) EXPECT_EQ(u, 1) << name << ": nearest-neighbour assignment is not one-to-one";
    }
    previous = current;
  }
  std::printf("visp-mire-sequence: 5 dots in each of %d frames, largest frame-to-frame jump %.2f px (frame %d)\n",
              frames, worst_jump, worst_frame);
  RecordProperty("largest_jump_px", std::to_string(worst_jump));
  EXPECT_LT(worst_jump, kMaxDotJumpPx);
}

// ViSP's 6 x 6 grid of dark dots on white paper, photographed in perspective. The paper is
// shaded (~125 to ~175 DN), the dots are 0..60 DN: a level 60 DN below the median separates
// them everywhere. The dots are circles in perspective, so their centroids are not exactly
// the projections of the circle centres: a fraction of a pixel of homography residual is
// expected from that alone.
constexpr double kGridHomographyRmsPx = 0.5;

TEST(BlobDetectorRealData, ViSPDotGridFitsAHomography) {
  MCMS_REQUIRE_DATA(dir, "visp-dot-grid");
  BlobDetectorOptions options;
  options.polarity = Polarity::kDark;
  options.threshold_dn = 60;
  options.min_area_px = 200;
  for (int i = 1; i <= 4; ++i) {
    const std::string name = "grid36-0" + std::to_string(i) + ".png";
    const cv::Mat image = cv::imread((dir / name).string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(image.empty()) << (dir / name);
    const auto blobs = DetectBlobs(image, options);
    ASSERT_EQ(blobs.size(), 36u) << name;
    // Rows: the dots sorted by y come in six groups of six; each row sorted by x.
    std::vector<Vec2> c;
    for (const Blob& b : blobs) c.push_back(b.centre);
    std::sort(c.begin(), c.end(), [](const Vec2& a, const Vec2& b) { return a.y() < b.y(); });
    for (int r = 0; r < 6; ++r)
      std::sort(c.begin() + 6 * r, c.begin() + 6 * r + 6, [](const Vec2& a, const Vec2& b) { return a.x() < b.x(); });
    std::vector<cv::Point2d> grid, centres;
    for (int r = 0; r < 6; ++r)
      for (int k = 0; k < 6; ++k) {
        grid.emplace_back(k, r);
        centres.emplace_back(c[6 * r + k].x(), c[6 * r + k].y());
      }
    const cv::Mat Hm = cv::findHomography(grid, centres, 0);
    ASSERT_FALSE(Hm.empty()) << name;
    std::vector<cv::Point2d> mapped;
    cv::perspectiveTransform(grid, mapped, Hm);
    double sq = 0, worst = 0;
    for (size_t k = 0; k < grid.size(); ++k) {
      const double d2 = std::pow(mapped[k].x - centres[k].x, 2) + std::pow(mapped[k].y - centres[k].y, 2);
      sq += d2;
      worst = std::max(worst, std::sqrt(d2));
    }
    const double rms = std::sqrt(sq / grid.size());
    std::printf("%s: 36 dots, homography RMS residual %.3f px, worst %.3f px\n", name.c_str(), rms, worst);
    RecordProperty(name + "_rms_px", std::to_string(rms));
    EXPECT_LT(rms, kGridHomographyRmsPx) << name;
  }
}

}  // namespace
}  // namespace mcms
