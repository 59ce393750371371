// The photon-transfer estimate from blob images (vision/pixel_noise.h) on images made
// here with a known noise model: flat discs on a sloped background, Poisson photon noise
// at a known gain, Gaussian read noise, rounding to 8 or 16 bits.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "vision/blob_detector.h"
#include "vision/pixel_noise.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

struct Synth {
  double gain = 2;          // e-/DN
  double read_noise = 3;    // DN
  double background = 12;   // DN
  double level = 150;       // DN of the discs (bright) or of the dots (dark); unclipped at gain 0.5
  bool dark = false;
  bool sixteen_bit = false;
};

// A 640 x 480 image with 12 discs of radius 5 to 9 px (area-weighted at the edge).
cv::Mat Make(const Synth& s, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const int W = 640, H = 480;
  cv::Mat mean(H, W, CV_64F);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) mean.at<double>(y, x) = s.background + 3.0 * x / W + 2.0 * y / H;
  std::uniform_real_distribution<double> u(0, 1);
  for (int k = 0; k < 12; ++k) {
    const double cx = 60 + (k % 4) * 160 + 20 * u(rng), cy = 70 + (k / 4) * 150 + 20 * u(rng), r = 5 + 4 * u(rng);
    for (int y = static_cast<int>(cy - r - 2); y <= cy + r + 2; ++y)
      for (int x = static_cast<int>(cx - r - 2); x <= cx + r + 2; ++x) {
        int in = 0;
        for (int j = 0; j < 8; ++j)
          for (int i = 0; i < 8; ++i) in += std::hypot(x - 0.4375 + i / 8.0 - cx, y - 0.4375 + j / 8.0 - cy) <= r;
        const double f = in / 64.0;
        double& m = mean.at<double>(y, x);
        m = (1 - f) * m + f * s.level;
      }
  }
  const double max_dn = s.sixteen_bit ? 65535 : 255;
  cv::Mat img(H, W, s.sixteen_bit ? CV_16U : CV_8U);
  std::normal_distribution<double> read(0, s.read_noise);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      std::poisson_distribution<long> photons(mean.at<double>(y, x) * s.gain);
      const double v = std::clamp(std::round(photons(rng) / s.gain + read(rng)), 0.0, max_dn);
      if (s.sixteen_bit)
        img.at<uint16_t>(y, x) = static_cast<uint16_t>(v);
      else
        img.at<uint8_t>(y, x) = static_cast<uint8_t>(v);
    }
  return img;
}

PixelNoiseEstimate Estimate(const Synth& s, int images, uint64_t seed) {
  BlobDetectorOptions o;
  o.polarity = s.dark ? Polarity::kDark : Polarity::kBright;
  std::vector<PixelNoiseSample> all;
  for (int i = 0; i < images; ++i) {
    const cv::Mat im = Make(s, seed + i);
    const auto blobs = DetectBlobs(im, o);
    const auto samples = MeasurePixelNoise(im, blobs);
    all.insert(all.end(), samples.begin(), samples.end());
  }
  return EstimatePixelNoise(all);
}

void ExpectGain(const Synth& s, const PixelNoiseEstimate& e) {
  std::printf("true gain %.3g, read noise %.3g: %s; scatter chi2/dof %.2f\n", s.gain, s.read_noise,
              e.Describe().c_str(), e.scatter_chi2_per_dof);
  ASSERT_TRUE(e.valid());
  EXPECT_GE(e.blobs, 30);
  EXPECT_TRUE(e.PhotonNoiseSeen());
  // Within 4 standard errors of the truth, and the standard error itself small (10 %).
  EXPECT_NEAR(e.inv_gain, 1 / s.gain, 4 * e.inv_gain_sigma);
  EXPECT_LT(e.inv_gain_sigma, 0.1 / s.gain);
  // The per-blob errors are honest: the slopes scatter as predicted.
  EXPECT_LT(e.scatter_chi2_per_dof, 1.6);
  const double bg = s.background + 2.5;  // mean background level
  EXPECT_NEAR(e.background_noise_dn, std::sqrt(s.read_noise * s.read_noise + bg / s.gain + 1.0 / 12), 0.4);
}

TEST(PixelNoise, RecoversTheGainOfBrightDiscs) {
  for (double g : {0.5, 2.0, 8.0}) {
    Synth s;
    s.gain = g;
    ExpectGain(s, Estimate(s, 4, 100));
  }
}

TEST(PixelNoise, RecoversTheGainOfDarkDotsAnd16BitImages) {
  Synth dark;
  dark.dark = true;
  dark.background = 180;
  dark.level = 20;
  dark.gain = 1.5;
  ExpectGain(dark, Estimate(dark, 4, 200));
  Synth deep;
  deep.sixteen_bit = true;
  deep.background = 800;
  deep.level = 20000;
  deep.gain = 0.25;
  deep.read_noise = 12;
  ExpectGain(deep, Estimate(deep, 4, 300));
}

TEST(PixelNoise, ImagesWithoutPhotonNoiseShowNone) {
  Synth s;
  s.gain = 1e6;  // photon noise negligible against 3 DN of read noise
  const PixelNoiseEstimate e = Estimate(s, 4, 400);
  std::printf("%s\n", e.Describe().c_str());
  ASSERT_TRUE(e.valid());
  EXPECT_FALSE(e.PhotonNoiseSeen());
  EXPECT_NEAR(e.inv_gain, 0, 4 * e.inv_gain_sigma);
}

TEST(PixelNoise, SmallOrSaturatedBlobsAreNotUsed) {
  Synth s;
  s.level = 255;  // every plateau clipped
  const cv::Mat im = Make(s, 500);
  EXPECT_TRUE(MeasurePixelNoise(im, DetectBlobs(im)).empty());
  EXPECT_FALSE(EstimatePixelNoise({}).valid());
  EXPECT_NE(EstimatePixelNoise({}).Describe().find("no usable blob"), std::string::npos);
}

TEST(PixelNoise, BadArgumentsAreRefused) {
  EXPECT_THROW(MeasurePixelNoise(cv::Mat(), {}), InputError);
  EXPECT_THROW(MeasurePixelNoise(cv::Mat(10, 10, CV_32F, cv::Scalar(1)), {}), InputError);
  PixelNoiseOptions o;
  o.clip_sigma = 1;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_THROW(MeasurePixelNoise(cv::Mat(10, 10, CV_8U, cv::Scalar(1)), {}, o), InputError);
}

// Real images (no ground truth): the estimate from frames 1-12 of a real sequence of
// bright dots and the one from frames 13-24 must agree within their errors. (This camera's
// dots are quieter than its background, a compressed response: the estimate says so and
// the tracker then leaves the photon term out, as before.)
TEST(PixelNoise, RealImagesGiveSelfConsistentEstimates) {
  MCMS_REQUIRE_DATA(mire, "visp-mire-sequence");
  auto estimate = [&](int first, int last) {
    std::vector<PixelNoiseSample> all;
    for (int i = first; i <= last; ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "image.%04d.png", i);
      const cv::Mat im = cv::imread((mire / name).string(), cv::IMREAD_UNCHANGED);
      EXPECT_FALSE(im.empty()) << name;
      if (im.empty()) continue;
      const auto s = MeasurePixelNoise(im, DetectBlobs(im));
      all.insert(all.end(), s.begin(), s.end());
    }
    return EstimatePixelNoise(all);
  };
  const PixelNoiseEstimate a = estimate(1, 12), b = estimate(13, 24);
  std::printf("visp-mire-sequence frames 1-12: %s; scatter chi2/dof %.2f\n", a.Describe().c_str(),
              a.scatter_chi2_per_dof);
  std::printf("visp-mire-sequence frames 13-24: %s; scatter chi2/dof %.2f\n", b.Describe().c_str(),
              b.scatter_chi2_per_dof);
  ASSERT_TRUE(a.valid());
  ASSERT_TRUE(b.valid());
  EXPECT_NEAR(a.inv_gain, b.inv_gain, 4 * std::hypot(a.inv_gain_sigma, b.inv_gain_sigma));
}

}  // namespace
}  // namespace mcms
