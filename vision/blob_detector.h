// Blob (ball / dot) detection with sub-pixel, unbiased centres and their covariance.
//
// Finds the images of retro-reflective balls (bright discs on a dark background,
// Polarity::kBright) or printed dots (dark discs on a bright background, Polarity::kDark).
//
// Contract on the centre: for a uniformly bright outline of any shape (the image of a
// sphere is a slightly elliptical disc) blurred by a symmetric PSF, the expected value of
// Blob::centre is the AREA CENTROID of the outline. It is the background-subtracted
// intensity centroid over an elliptical window that holds the whole blurred blob, with a
// robust plane fitted to a ring around the window as the background. No pixel weight is
// clipped or thresholded, because either would bias the centre towards the brighter side
// of the PSF tail. (The centroid of a sphere's outline is not the image of its centre;
// vision/sphere_projection.h corrects for that, this detector does not.)
//
// Pixel noise model (DN^2): var = noise_bg^2 + (I - background)/gain, where noise_bg is
// the noise of a background pixel (read noise, the background's own shot noise and the
// quantization of the stored image) and the second term is the shot noise of the signal
// above (or, for dark dots, below) the background. With read_noise_dn == 0, noise_bg is
// measured per blob from the residuals of the ring's plane fit. Blob::cov propagates this
// noise, through both the window pixels and the background fit, to the centre to first
// order; it does not contain model errors (non-uniform balls, clutter in the ring).
//
// Detection is one global level (background median + threshold), so an image whose
// background varies by more than the threshold (shading, clutter) needs threshold_dn set
// between background and blob levels; the local tests (ring noise, shape) then reject the
// clutter that passes.
//
// Cost: one pass over the image (a row scan that skips blocks of pixels below the
// threshold with a vectorizable max/min test, run-length labelling with union-find), a
// sparse sample of about 4096 pixels for the global background and noise, and per blob
// a local pass over its window and ring. When no region within a single row can be
// accepted (min_area_px * min_circularity > 1, as by default: such a region of length L
// has circularity 1/L), the pass tests only the even rows, and labels only the rows
// with a pixel beyond the threshold and their neighbours: half the work on an image in
// the cache (from main memory the hardware prefetcher still brings in the odd rows, and
// the pass stays bound by memory bandwidth). About 0.025 ms for a cached 1280x1024 8-bit
// image without blobs, plus about 10 us per blob, on one core.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/pose_math.h"

namespace mcms {

struct Blob {
  Vec2 centre = Vec2::Zero();  // px, background-subtracted intensity centroid ((0,0) = centre of top-left pixel)
  Mat2 cov = Mat2::Zero();     // px^2, covariance of `centre` propagated from the pixel noise model
  double flux = 0;             // DN, background-subtracted sum over the window (> 0 for both polarities)
  double background = 0;       // DN, the fitted background plane at `centre`
  double peak = 0;             // DN, largest |pixel - background| on the signal side
  double noise_dn = 0;         // DN, noise std of a background pixel used for `cov`
  int area_px = 0;             // pixels beyond the detection threshold (one 8-connected region)
  double radius_px = 0;        // sqrt(area_px / pi)
  Mat2 shape = Mat2::Zero();   // px^2, second central moments of the region's pixels (each a unit square)
  double circularity = 0;      // minor/major axis ratio of `shape`: 1 for a disc, 0.45 for two touching discs
  // Mean distance (px) between the region's boundary and its moment-equivalent ellipse,
  // |region xor ellipse| / perimeter: <= ~0.12 for a digitized ellipse of any size, 0.4 to
  // 0.9 for squares of side 8 to 16, 0.45 to 1.4 for two merged discs of radius 5 to 10.
  double ellipse_residual_px = 0;
  // The region reaches the image border, or its measurement window (blob plus margin) is
  // cut by it: flux may be missing on one side and the centre pulled inwards.
  bool touches_border = false;
  // A window pixel reached the clip level on the signal side (>= saturation level for
  // bright blobs, 0 for dark dots): the response is not linear there.
  bool saturated = false;
  // Another blob interferes, so the centre may be pulled: the window holds above-threshold
  // pixels of another region, or the region does not fit its elliptical window, or the
  // region is elongated and not elliptical (circularity < 0.7 and ellipse residual
  // > 0.25 px: two blobs merged into one region).
  bool crowded = false;
};

enum class Polarity { kBright, kDark };

struct BlobDetectorOptions {
  Polarity polarity = Polarity::kBright;
  // Detection threshold in DN beyond the image's global background (the median of a sparse
  // pixel sample): above it for kBright, below it for kDark. 0 = k_sigma * noise, with the
  // noise from read_noise_dn or, when that is 0, estimated from the same sparse sample.
  double threshold_dn = 0;
  double k_sigma = 8;
  int min_area_px = 3, max_area_px = 20000;  // of the above-threshold region
  double min_circularity = 0.5;              // regions below are rejected (merged blobs, edges)
  double max_ellipse_residual_px = 0.5;      // regions above are rejected (not an ellipse: merged, ragged)
  // Local significance: a blob whose peak is below min_peak_snr * (noise of its own
  // background ring) is rejected. This rejects bright texture in clutter, whose ring is
  // as rough as the blob is bright, which no global threshold can do. 0 = off.
  double min_peak_snr = 5;
  // Noise std of a background pixel, DN (read noise plus the background's shot noise).
  // 0 = measure it per blob from the ring around the blob.
  double read_noise_dn = 0;
  // Electrons per DN for the shot noise of the signal above the background; 0 = no
  // photon-noise term.
  double gain_e_per_dn = 0;
  // Bright pixels at or above this are saturated; 0 = the maximum of the image type.
  double saturation_dn = 0;
  // The window is the region's equivalent ellipse widened by this margin (px); it is
  // widened further, up to max_window_margin_px, while the window's outermost shell still
  // holds significant signal (a blurred tail) or the region does not fit in it, unless the
  // wider window would take in another region, a ring of outliers or a signal that does
  // not decay outwards (clutter rather than a PSF tail).
  int window_margin_px = 3;
  int max_window_margin_px = 24;
  // Width (px) of the background ring outside the window.
  int ring_width_px = 3;

  bool IsValid(std::string* why) const;
};

// What the detector learned about the whole image (for diagnostics and tests).
struct BlobImageStats {
  double background_dn = 0;  // median of the sparse sample
  double noise_dn = 0;       // noise std used for the automatic threshold
  double threshold_dn = 0;   // detection threshold used, DN beyond background_dn
  // Connected regions beyond the threshold, before any filter (without the one-row regions
  // the scan leaves out when none of them can be accepted: see Cost above).
  int num_regions = 0;
};

// Accepts CV_8U and CV_16U images with 1 channel (3 or 4 channels are converted to gray).
// Throws InputError for an empty image, another depth (naming NaN when a float image
// holds one) or invalid options. Blobs are returned in order of decreasing flux; those
// touching the border, saturated or crowded are returned with their flags set.
std::vector<Blob> DetectBlobs(const cv::Mat& image,
                              const BlobDetectorOptions& options = {},
                              BlobImageStats* stats = nullptr);

// Detection restricted to windows of the image (a tracker's predicted ball images): the
// image-wide background, noise and threshold come from the same sparse sample of the whole
// image as in DetectBlobs, so a blob whose region, measurement window and background ring
// lie inside one window is measured as DetectBlobs measures it (the same pixels; the sums
// differ only by rounding). Windows are clipped to the image, and windows that overlap or
// touch are merged (MergeWindows). A blob cut by a window's edge is returned with
// touches_border set, as at the image's border. stats->num_regions counts the regions
// inside the windows. Reads the windows and about 1/17 of the image's rows (the sample).
std::vector<Blob> DetectBlobsInWindows(const cv::Mat& image,
                                       const std::vector<cv::Rect>& windows,
                                       const BlobDetectorOptions& options = {},
                                       BlobImageStats* stats = nullptr);

// The rows DetectBlobsInWindows(image, windows) reads of an image of `image_size`: the
// merged windows' rows and the sparse sample's rows (about 1/17 of a frame's), as
// sorted, disjoint ranges [start, end). An image whose other rows hold anything (a frame
// read in part, vision/image_file.h ImageFileRows) gives the same blobs.
std::vector<cv::Range> RowsReadInWindows(const cv::Size& image_size, const std::vector<cv::Rect>& windows);

// The windows clipped to an image of `image_size`, empty ones dropped, those that overlap
// or touch united (their bounding rectangle) until none do.
std::vector<cv::Rect> MergeWindows(std::vector<cv::Rect> windows, const cv::Size& image_size);

}  // namespace mcms
