// A camera's pixel noise measured from its own images of blobs: photon transfer without
// a flat-field series.
//
// Model (the one vision/blob_detector.h propagates): the variance of a pixel, DN^2, is
//     var(I) = var_bg + (I - I_bg) / gain
// where I_bg and var_bg are the level and noise of the local background (read noise, the
// background's own shot noise, quantization) and gain is in electrons per DN. The slope
// 1 / gain is what a recording must supply: the detector measures var_bg around every
// blob by itself, but cannot tell the photon noise of the blob's own signal from nothing.
//
// Measurement: a ball's image (retro-reflective, under on-axis light) is a bright disc
// whose interior, away from the blurred outline, is a plateau of nearly constant level.
// For every usable blob a low-order surface (plane, or a quadratic when the plateau is
// large enough to afford one, which absorbs a shaded ball's fall-off) is fitted to the
// plateau pixels and a plane to a ring of background around the blob, both with 5-sigma
// clipping; the residual variances (dof-corrected) give two points of the photon-transfer
// curve at the plateau's and the background's level. Their difference over the signal
// difference is one blob's slope; the slopes of all blobs are combined by inverse-variance
// weighting, the variance of a residual variance with d dof being 2 var^2 / d. Texture on
// the ball or clutter in the ring can only add variance to the plateau or the ring; the
// first biases 1/gain up (a larger, conservative covariance), the second down, which is
// why the ring is local (the detector's own background) and clipped.
//
// Not measured: non-linearity, fixed-pattern noise (it is in the residuals of both fits
// and so partly in var_bg), noise correlated between neighbouring pixels (a Bayer
// demosaic, a sharpening filter): such images give a biased gain.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "vision/blob_detector.h"

namespace mcms {

struct PixelNoiseOptions {
  // Plateau: the blob's moment ellipse (the above-threshold region's outline) shrunk by
  // this margin, px. It must exceed the blurred edge (about 3 PSF sigmas).
  double plateau_margin_px = 2.5;
  int min_plateau_px = 9;             // blobs with fewer plateau pixels are not used
  int quadratic_min_px = 30;          // plateaus this large get a quadratic, smaller a plane
  // Background ring: from the outline plus ring_gap_px to that plus ring_width_px.
  double ring_gap_px = 4.0;
  double ring_width_px = 4.0;
  int min_ring_px = 24;
  double clip_sigma = 5.0;            // residuals beyond this are outliers (hot pixels, glints)
  // A blob's signal (plateau minus background, DN) must exceed this many background
  // noise sigmas: a faint plateau carries no information on the slope.
  double min_signal_snr = 10.0;
  bool IsValid(std::string* why) const;
};

// One blob's two points of the photon-transfer curve.
struct PixelNoiseSample {
  Vec2 centre = Vec2::Zero();   // px
  double background_dn = 0;     // ring plane at the centre
  double background_var = 0;    // DN^2, ring residual variance
  int background_dof = 0;
  double plateau_dn = 0;        // mean plateau level
  double plateau_var = 0;       // DN^2, plateau residual variance
  int plateau_dof = 0;
  double Signal() const { return plateau_dn - background_dn; }  // < 0 for dark dots
};

// The samples of one image: every detected blob that is not saturated, crowded or cut by
// the border, whose plateau and ring are large enough. Ring pixels inside another blob's
// outline-plus-gap are left out. `blobs` are DetectBlobs' result on this image (same
// polarity); InputError for an image DetectBlobs would refuse or invalid options.
std::vector<PixelNoiseSample> MeasurePixelNoise(const cv::Mat& image,
                                                const std::vector<Blob>& blobs,
                                                const PixelNoiseOptions& options = {});

struct PixelNoiseEstimate {
  int blobs = 0;                   // samples used (after dropping outlying blobs)
  int blobs_dropped = 0;           // samples whose slope is > 5 sigma from the rest
  double inv_gain = 0;             // DN per electron: the slope of var against signal
  double inv_gain_sigma = 0;       // its standard error (inflated by the scatter when larger)
  double gain_e_per_dn = 0;        // 1 / inv_gain; 0 when the slope is not positive
  double background_noise_dn = 0;  // median over the blobs of the ring noise std
  double mean_signal_dn = 0;       // mean |plateau - background| of the blobs used
  double scatter_chi2_per_dof = 0; // the blobs' slopes about the mean against their errors
  bool valid() const { return blobs > 0; }
  // True when the slope is more than 3 sigma above zero: photon noise is seen.
  bool PhotonNoiseSeen() const { return valid() && inv_gain > 3 * inv_gain_sigma; }
  // "gain 2.03 +- 0.09 e-/DN (1/gain 0.493 +- 0.022 DN/e-), background noise 3.9 DN, from 150 blobs"
  std::string Describe() const;
};

// Combines samples (of one camera, or of several sharing a sensor) into one estimate;
// an estimate with blobs == 0 when there are none.
PixelNoiseEstimate EstimatePixelNoise(const std::vector<PixelNoiseSample>& samples);

}  // namespace mcms
