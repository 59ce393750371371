#include "vision/blob_detector.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/statistics.h"

namespace mcms {

bool BlobDetectorOptions::IsValid(std::string* why) const {
  auto fail = [why](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (polarity != Polarity::kBright && polarity != Polarity::kDark) return fail("polarity must be kBright or kDark");
  if (!(std::isfinite(threshold_dn) && threshold_dn >= 0)) return fail("threshold_dn must be finite and >= 0");
  if (!(std::isfinite(k_sigma) && k_sigma > 0)) return fail("k_sigma must be finite and > 0");
  if (min_area_px < 1) return fail("min_area_px must be >= 1");
  if (max_area_px < min_area_px) return fail("max_area_px must be >= min_area_px");
  if (!(min_circularity >= 0 && min_circularity <= 1)) return fail("min_circularity must be in [0, 1]");
  if (!(std::isfinite(min_peak_snr) && min_peak_snr >= 0)) return fail("min_peak_snr must be finite and >= 0");
  if (!(max_ellipse_residual_px >= 0)) return fail("max_ellipse_residual_px must be >= 0");
  if (!(std::isfinite(read_noise_dn) && read_noise_dn >= 0)) return fail("read_noise_dn must be finite and >= 0");
  if (!(std::isfinite(gain_e_per_dn) && gain_e_per_dn >= 0)) return fail("gain_e_per_dn must be finite and >= 0");
  if (!(std::isfinite(saturation_dn) && saturation_dn >= 0)) return fail("saturation_dn must be finite and >= 0");
  if (window_margin_px < 1 || window_margin_px > 1000) return fail("window_margin_px must be in [1, 1000]");
  if (max_window_margin_px < window_margin_px || max_window_margin_px > 1000)
    return fail("max_window_margin_px must be in [window_margin_px, 1000]");
  if (ring_width_px < 1 || ring_width_px > 1000) return fail("ring_width_px must be in [1, 1000]");
  if (why) why->clear();
  return true;
}

namespace {

// The quantization noise of an integer image, DN: the floor of every noise estimate, so
// that a noise-free image still gets a positive threshold and covariance.
constexpr double kQuantSigma = 0.28867513459481287;  // 1/sqrt(12)
// Robust clipping of the background ring, in noise sigmas: symmetric, so it does not bias
// the fitted level for symmetric noise, and wide enough to keep ~all Gaussian inliers.
constexpr double kRingClip = 4.0;
// How many sigmas of signal in the window's outer shell make the window too small.
constexpr double kShellSignificance = 3.0;
// The outer shell of the window used for that test, px.
constexpr double kShellWidth = 1.5;
// A widened window's shell signal must fall below this fraction of the previous one (a
// PSF tail decays; background structure does not).
constexpr double kTailDecay = 0.7;
// A region with a lower circularity and a larger ellipse residual (px) than these is taken
// for two merged blobs (Blob::crowded). Two discs of radius 5 whose centres are 1.6 to 2.4
// radii apart give circularity 0.43..0.64 and residual 0.27..1.0 px. A single disc's region
// gives 0.03..0.2 px at a peak SNR >= 15; at a peak SNR near 10 with a PSF sigma of 1.5 px
// its ragged edge reaches 0.6 px, but its circularity stays that of the disc.
constexpr double kMergedMaxCircularity = 0.7;
constexpr double kMergedMinResidualPx = 0.25;
// A widened window whose ring keeps fewer inliers than this has reached clutter.
constexpr double kMinRingInlierFraction = 0.7;

struct Run {
  int y, xs, xe;  // inclusive columns
};

// Moments of the pixels of one 8-connected region, pixel centres at integer coordinates.
struct Region {
  double n = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  int x0 = std::numeric_limits<int>::max(), x1 = -1, y0 = std::numeric_limits<int>::max(), y1 = -1;
  int head = -1, tail = -1;  // its runs, linked through next_run
};

// A region's centroid, second moments (each pixel a unit square, hence + 1/12) and their
// eigen-decomposition: l1 >= l2 along the angle theta of the major axis from +x.
struct RegionShape {
  double cx, cy, l1, l2, theta;
  Mat2 S;
};

RegionShape ShapeOf(const Region& r) {
  RegionShape s;
  s.cx = r.sx / r.n;
  s.cy = r.sy / r.n;
  s.S(0, 0) = r.sxx / r.n - s.cx * s.cx + 1.0 / 12;
  s.S(1, 1) = r.syy / r.n - s.cy * s.cy + 1.0 / 12;
  s.S(0, 1) = s.S(1, 0) = r.sxy / r.n - s.cx * s.cy;
  const double half_tr = 0.5 * s.S.trace();
  const double d = 0.5 * (s.S(0, 0) - s.S(1, 1));
  const double disc = std::sqrt(d * d + s.S(0, 1) * s.S(0, 1));
  s.l1 = half_tr + disc;
  s.l2 = half_tr - disc;
  s.theta = 0.5 * std::atan2(2 * s.S(0, 1), s.S(0, 0) - s.S(1, 1));
  return s;
}

// Mean distance (px) between the region's boundary and its moment-equivalent ellipse
// (x-c)^T S^-1 (x-c) <= 4: the pixel count of region xor ellipse divided by the ellipse's
// perimeter. Boundary digitization alone gives <= ~0.12 px at any size; a square gives
// 0.4 px at 8 px side and 0.9 px at 16, two merged discs of radius 5 to 10 0.45 to 1.4 px.
double EllipseResidual(const Region& g,
                       const RegionShape& shape,
                       const std::vector<Run>& runs,
                       const std::vector<int>& next_run) {
  const double cx = shape.cx, cy = shape.cy;
  const Mat2& S = shape.S;
  const Mat2 Q = S.inverse() / 4;
  const double p = Q(0, 0), q = Q(0, 1), r = Q(1, 1);
  // Chord of the ellipse on row y, as an inclusive integer column range (empty if lo > hi).
  auto chord = [&](int y, int* lo, int* hi) {
    const double dy = y - cy;
    const double disc = q * q * dy * dy - p * (r * dy * dy - 1);
    if (disc < 0) {
      *lo = 1;
      *hi = 0;
      return;
    }
    const double sq = std::sqrt(disc);
    *lo = static_cast<int>(std::ceil(cx + (-q * dy - sq) / p));
    *hi = static_cast<int>(std::floor(cx + (-q * dy + sq) / p));
  };
  double inter = 0;
  for (int i = g.head; i >= 0; i = next_run[i]) {
    int lo, hi;
    chord(runs[i].y, &lo, &hi);
    inter += std::max(0, std::min(hi, runs[i].xe) - std::max(lo, runs[i].xs) + 1);
  }
  const double ey = 2 * std::sqrt(S(1, 1));
  double n_ellipse = 0;
  for (int y = static_cast<int>(std::ceil(cy - ey)); y <= static_cast<int>(std::floor(cy + ey)); ++y) {
    int lo, hi;
    chord(y, &lo, &hi);
    n_ellipse += std::max(0, hi - lo + 1);
  }
  // Ramanujan's perimeter of the ellipse with semi-axes a >= b (S's eigenvalues are a^2/4, b^2/4).
  const double a = 2 * std::sqrt(shape.l1), b = 2 * std::sqrt(std::max(shape.l2, 0.0));
  const double h = (a - b) * (a - b) / ((a + b) * (a + b));
  const double perimeter = std::numbers::pi * (a + b) * (1 + 3 * h / (10 + std::sqrt(4 - 3 * h)));
  return (g.n + n_ellipse - 2 * inter) / perimeter;
}

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];  // path halving
    i = parent[i];
  }
  return i;
}

void Unite(std::vector<int>& parent, int a, int b) {
  a = Find(parent, a);
  b = Find(parent, b);
  if (a == b) return;
  if (a < b) std::swap(a, b);
  parent[a] = b;  // the earliest run is the root: a stable label
}

template <bool kDark>
inline bool Pass(int v, int t) {
  return kDark ? v < t : v > t;
}

// The extreme (maximum for bright, minimum for dark) of the kCount pixels at p. Written
// as a min/max reduction over a fixed count so that the compiler vectorizes it: this is
// the only code that touches every pixel of the image.
template <typename T, bool kDark, int kCount>
inline T Extreme(const T* p) {
  // Start from the identity so that all kCount elements go through the vector loop.
  T m = kDark ? std::numeric_limits<T>::max() : 0;
  for (int k = 0; k < kCount; ++k) m = kDark ? std::min(m, p[k]) : std::max(m, p[k]);
  return m;
}

// True when any of the kChunk pixels at p passes the threshold.
template <typename T, bool kDark, int kChunk>
inline bool AnyPass(const T* p, int t) {
  return Pass<kDark>(Extreme<T, kDark, kChunk>(p), t);
}

// True when any pixel of the row passes the threshold.
template <typename T, bool kDark>
bool RowPasses(const T* row, int W, int t) {
  constexpr int kBlock = 256 / sizeof(T);
  int x = 0;
  for (; x + kBlock <= W; x += kBlock)
    if (AnyPass<T, kDark, kBlock>(row + x, t)) return true;
  for (; x < W; ++x)
    if (Pass<kDark>(row[x], t)) return true;
  return false;
}

// The row's extreme pixel: its maximum for bright blobs, its minimum for dark ones (a
// reduction the compiler vectorizes; a row passes the threshold t when its extreme does).
// Blocks of 256 bytes are reduced with a fixed count (Extreme: the compiler then keeps
// several vector accumulators, 2.3 times the rate of one loop over the row, cached).
template <typename T, bool kDark>
T RowExtreme(const T* row, int W) {
  constexpr int kBlock = 256 / sizeof(T);
  T m = kDark ? std::numeric_limits<T>::max() : 0;
  int x = 0;
  for (; x + kBlock <= W; x += kBlock) {
    const T b = Extreme<T, kDark, kBlock>(row + x);
    m = kDark ? std::min(m, b) : std::max(m, b);
  }
  for (; x < W; ++x) m = kDark ? std::min(m, row[x]) : std::max(m, row[x]);
  return m;
}

// The runs of above-threshold pixels of each row, united with the overlapping runs of the
// previous row (8-connectivity). Returns runs and their parents.
//
// With skip_single_rows, regions that lie within one row may be left out (those that
// touch a row next to a row with a region pixel are still found): only even rows that
// hold a pixel beyond the threshold and the odd rows next to them are labelled. Every
// region that spans two rows or more is found whole, because each of its odd rows has a
// neighbouring even row in the region. For the detector's usual options no one-row
// region can be accepted (DetectBlobs).
//
// `extremes`, when given, holds each row's extreme pixel (RowExtreme), read beforehand.
template <typename T, bool kDark>
void LabelRuns(const cv::Mat& img, int t, bool skip_single_rows, const std::vector<T>* extremes,
               std::vector<Run>* runs, std::vector<int>* parent) {
  // Blocks of 256 bytes are skipped first (one horizontal reduction per block), then
  // chunks of 64 bytes within the block that passed, then single pixels.
  constexpr int kChunk = 64 / sizeof(T), kBlock = 4 * kChunk;
  const int W = img.cols, H = img.rows;
  // label[y]: row y is labelled. A row without a pixel beyond the threshold has no runs,
  // so leaving it out changes nothing. Every row is tested, in memory order: reading
  // only the even rows skips half of the bytes but defeats the hardware prefetcher, and
  // from main memory it took 2.4 times as long as reading them all (143 against 60 us
  // for a 1280 x 1024 image on the 2-core bench machine).
  std::vector<char> label(H);
  for (int y = 0; y < H; ++y)
    label[y] = extremes ? Pass<kDark>((*extremes)[y], t) : RowPasses<T, kDark>(img.ptr<T>(y), W, t);
  if (skip_single_rows)  // an odd row only next to an even row with such a pixel
    for (int y = 1; y < H; y += 2) label[y] = label[y] && (label[y - 1] || (y + 1 < H && label[y + 1]));
  int prev_begin = 0, prev_end = 0;
  for (int y = 0; y < H; ++y) {
    const int row_begin = static_cast<int>(runs->size());
    if (!label[y]) {  // no runs here: the next row has no previous runs to join
      prev_begin = prev_end = row_begin;
      continue;
    }
    const T* row = img.ptr<T>(y);
    int x = 0;
    while (x < W) {
      while (x + kBlock <= W && !AnyPass<T, kDark, kBlock>(row + x, t)) x += kBlock;
      while (x + kChunk <= W && !AnyPass<T, kDark, kChunk>(row + x, t)) x += kChunk;
      const int end = std::min(W, x + kChunk);
      while (x < end && !Pass<kDark>(row[x], t)) ++x;
      if (x == end) continue;
      const int xs = x;
      while (x < W && Pass<kDark>(row[x], t)) ++x;
      runs->push_back({y, xs, x - 1});
      parent->push_back(static_cast<int>(parent->size()));
    }
    const int row_end = static_cast<int>(runs->size());
    // Runs of both rows are sorted and disjoint: a previous run that ends left of the
    // current run's reach cannot reach any later current run either.
    int j = prev_begin;
    for (int i = row_begin; i < row_end; ++i) {
      const Run& r = (*runs)[i];
      while (j < prev_end && (*runs)[j].xe < r.xs - 1) ++j;
      for (int k = j; k < prev_end && (*runs)[k].xs <= r.xe + 1; ++k) Unite(*parent, i, k);
    }
    prev_begin = row_begin;
    prev_end = row_end;
  }
}

// Sum of k^2 for k = 0..n (n >= -1).
inline double SumSquares(double n) { return n * (n + 1) * (2 * n + 1) / 6.0; }

// Median of v (reorders v).
template <typename V>
double Median(std::vector<V>& v) {
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  const double upper = v[h];
  if (v.size() % 2) return upper;
  const double lower = *std::max_element(v.begin(), v.begin() + h);
  return 0.5 * (lower + upper);
}

// Median of the counts hist[0..bins) over `total` samples (the mean of the two middle
// ranks for an even total), by counting: no reordering, no log factor.
double MedianOfHistogram(const int* hist, int bins, size_t total) {
  const size_t lo_rank = (total - 1) / 2, hi_rank = total / 2;
  size_t seen = 0;
  int lo = -1;
  for (int i = 0; i < bins; ++i) {
    seen += hist[i];
    if (lo < 0 && seen > lo_rank) lo = i;
    if (seen > hi_rank) return 0.5 * (lo + i);
  }
  return lo;
}

// The sparse grid's spacing (px) for a W x H image: about 4096 points. Rows
// min(step / 2, H - 1) + k step are sampled (and the row below each where the last sampled
// column is the image's last: its difference is vertical); RowsReadInWindows lists them.
int SampleStep(int W, int H) {
  return std::max(1, static_cast<int>(std::sqrt(static_cast<double>(W) * H / 4096.0)));
}

// Global background (median) and noise of about 4096 pixels on a sparse grid. The noise
// comes from differences of horizontal neighbours, which cancel any smooth background: the
// median absolute difference gives a robust scale, then the RMS of the differences within
// 3.5 of those scales gives an estimate that is not quantized like the median of integers.
// Rows are added in increasing order (AddRow of each row for which Samples is true), so
// that the sample can be taken while a pass reads the image; Finish gives the figures.
// 8-bit images are counted in histograms of the values and of the signed differences (the
// same results as the general code, without storing or sorting the samples).
template <typename T>
class SparseSample {
 public:
  explicit SparseSample(const cv::Mat& img)
      : img_(img),
        step_(SampleStep(img.cols, img.rows)),
        y0_(std::min(step_ / 2, img.rows - 1)),
        x0_(std::min(step_ / 2, img.cols - 1)) {
    if constexpr (!kByte) {
      values_.reserve(static_cast<size_t>(img.cols / step_ + 1) * (img.rows / step_ + 1));
      diffs_.reserve(values_.capacity());
    }
  }
  int first_row() const { return y0_; }
  int step() const { return step_; }
  bool Samples(int y) const { return y >= y0_ && (y - y0_) % step_ == 0; }

  void AddRow(int y) {
    const int W = img_.cols, H = img_.rows;
    const T* row = img_.ptr<T>(y);
    const T* below = y + 1 < H ? img_.ptr<T>(y + 1) : nullptr;
    for (int x = x0_; x < W; x += step_) {
      Value(row[x]);
      if (x + 1 < W)
        Diff(static_cast<int>(row[x + 1]) - row[x]);
      else if (below)
        Diff(static_cast<int>(below[x]) - row[x]);
    }
  }

  void Finish(double* background, double* noise) {
    double sigma = 0;
    if constexpr (kByte) {
      *background = MedianOfHistogram(values_, 256, nv_);
      if (nd_ > 0) {
        int absd[256] = {0};
        for (int d = -255; d <= 255; ++d) absd[std::abs(d)] += diffs_[255 + d];
        const double scale = 1.4826 * MedianOfHistogram(absd, 256, nd_);  // sigma of a difference, robustly
        const double clip = std::max(3.5 * scale, 2.0);
        double s2 = 0;
        int n = 0;
        for (int d = -255; d <= 255; ++d)
          if (diffs_[255 + d] > 0 && std::abs(d) <= clip) {
            s2 += static_cast<double>(diffs_[255 + d]) * d * d;
            n += diffs_[255 + d];
          }
        if (n > 0) sigma = std::sqrt(s2 / n / 2.0);  // a difference has twice a pixel's variance
      }
    } else {
      *background = Median(values_);
      if (!diffs_.empty()) {
        std::vector<int> absd(diffs_.size());
        for (size_t i = 0; i < diffs_.size(); ++i) absd[i] = std::abs(diffs_[i]);
        const double scale = 1.4826 * Median(absd);  // sigma of a difference, robustly
        const double clip = std::max(3.5 * scale, 2.0);
        double s2 = 0;
        int n = 0;
        for (int d : diffs_)
          if (std::abs(d) <= clip) {
            s2 += static_cast<double>(d) * d;
            ++n;
          }
        if (n > 0) sigma = std::sqrt(s2 / n / 2.0);  // a difference has twice a pixel's variance
      }
    }
    *noise = std::max(sigma, kQuantSigma);
  }

 private:
  static constexpr bool kByte = sizeof(T) == 1;
  void Value(T v) {
    if constexpr (kByte) {
      ++values_[v];
      ++nv_;
    } else {
      values_.push_back(v);
    }
  }
  void Diff(int d) {
    if constexpr (kByte) {
      ++diffs_[255 + d];
      ++nd_;
    } else {
      diffs_.push_back(d);
    }
  }

  const cv::Mat& img_;
  const int step_, y0_, x0_;
  // 8-bit: histograms of the values and of the signed differences (diffs_[255 + d]).
  std::conditional_t<kByte, int[256], std::vector<int>> values_{};
  std::conditional_t<kByte, int[511], std::vector<int>> diffs_{};
  size_t nv_ = 0, nd_ = 0;
};

template <typename T>
void SampleStats(const cv::Mat& img, double* background, double* noise) {
  SparseSample<T> sample(img);
  for (int y = sample.first_row(); y < img.rows; y += sample.step()) sample.AddRow(y);
  sample.Finish(background, noise);
}

// A pixel of the measurement window or ring, relative to the region centroid.
struct Px {
  double dx, dy, v, q;  // q: the window ellipse's quadratic form (<= 1 inside)
};

// The background around a blob: b(dx, dy) = b0 + gx dx + gy dy, fitted by least squares to
// the ring pixels within kRingClip sigmas of the ring's median (MAD sigmas), then refitted
// to those within kRingClip sigmas of the first fit; a constant when the ring is too small
// or too thin to fix a gradient.
struct Background {
  Eigen::Vector3d beta = Eigen::Vector3d::Zero();  // b0, gx, gy
  Mat3 cov_unit = Mat3::Zero();                     // (A^T A)^-1 of the inliers: Cov(beta) / sigma^2
  double sigma = 0;                                 // RMS residual of the inliers (dof-corrected)
  int n = 0;
  double At(double dx, double dy) const { return beta[0] + beta[1] * dx + beta[2] * dy; }
};

struct RingScratch {
  std::vector<double> values;
  std::vector<int> counts;
};

bool FitBackground(const std::vector<Px>& ring, RingScratch* scratch, Background* bg) {
  const int n_all = static_cast<int>(ring.size());
  if (n_all < 3) return false;
  // Robust start: median and MAD of the ring.
  double m0, mad;
  scratch->values.resize(n_all);
  for (int i = 0; i < n_all; ++i) scratch->values[i] = ring[i].v;
  MedianAndMad(scratch->values, &scratch->counts, &m0, &mad);  // pixel values: counted
  const double s0 = std::max(1.4826 * mad, 2 * kQuantSigma);

  // Least squares over the pixels within `clip` of `ref` (the start, then the first fit).
  Background fit = *bg;
  fit.beta = Eigen::Vector3d(m0, 0, 0);
  double clip = kRingClip * s0;
  for (int iter = 0; iter < 2; ++iter) {
    double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, sv = 0, sxv = 0, syv = 0;
    for (const Px& p : ring) {
      if (std::abs(p.v - fit.At(p.dx, p.dy)) > clip) continue;
      n += 1;
      sx += p.dx;
      sy += p.dy;
      sxx += p.dx * p.dx;
      sxy += p.dx * p.dy;
      syy += p.dy * p.dy;
      sv += p.v;
      sxv += p.dx * p.v;
      syv += p.dy * p.v;
    }
    if (n < 3) return false;
    // A gradient needs a ring that spreads in both directions (it may be cut by the border).
    const double vxx = sxx / n - (sx / n) * (sx / n), vyy = syy / n - (sy / n) * (sy / n);
    const double vxy = sxy / n - (sx / n) * (sy / n);
    const double det = vxx * vyy - vxy * vxy, tr = vxx + vyy;
    const bool plane = n >= 12 && std::min(vxx, vyy) > 0.5 && det > 0.05 * tr * tr;
    Background next;
    if (plane) {
      Mat3 AtA;
      AtA << n, sx, sy, sx, sxx, sxy, sy, sxy, syy;
      next.cov_unit = AtA.inverse();
      next.beta = next.cov_unit * Eigen::Vector3d(sv, sxv, syv);
    } else {
      next.beta = Eigen::Vector3d(sv / n, 0, 0);
      next.cov_unit(0, 0) = 1.0 / n;
    }
    // RMS residual of the same pixels (selected against the previous reference).
    double r2 = 0;
    for (const Px& p : ring)
      if (std::abs(p.v - fit.At(p.dx, p.dy)) <= clip) {
        const double r = p.v - next.At(p.dx, p.dy);
        r2 += r * r;
      }
    const double dof = n - (plane ? 3 : 1);
    next.sigma = dof > 0 ? std::sqrt(r2 / dof) : 0.0;
    next.n = static_cast<int>(n);
    fit = next;
    clip = kRingClip * std::max(fit.sigma, 2 * kQuantSigma);
  }
  *bg = fit;
  return true;
}

struct Context {
  const cv::Mat* img;
  int threshold;       // integer detection level (Pass<kDark>)
  double saturation;   // bright clip level
  const BlobDetectorOptions* opts;
  double global_noise;
};

struct Scratch {
  std::vector<Px> window, ring;
  RingScratch background;
};

// Measures one region: window, background, centroid and covariance. False when the window
// holds no positive flux (nothing to centre) or the peak is not locally significant.
template <typename T, bool kDark>
bool Measure(const Context& ctx, const Region& r, const RegionShape& shape, Scratch* s, Blob* blob) {
  const cv::Mat& img = *ctx.img;
  const BlobDetectorOptions& o = *ctx.opts;
  const double sign = kDark ? -1.0 : 1.0;
  const int W = img.cols, H = img.rows;
  const double cx = shape.cx, cy = shape.cy;
  const double c = std::cos(shape.theta), sn = std::sin(shape.theta);
  // A uniform ellipse with semi-axes a >= b has second moments a^2/4 and b^2/4.
  const double a = 2 * std::sqrt(shape.l1), b = 2 * std::sqrt(std::max(shape.l2, 1.0 / 12));

  blob->area_px = static_cast<int>(r.n);
  blob->radius_px = std::sqrt(r.n / std::numbers::pi);
  blob->shape = shape.S;

  // Gathers the window (the equivalent ellipse widened by `margin`) and its ring, and fits
  // the background.
  Background bg;
  bool window_cut = false, saturated = false;
  int n_pass_window = 0;
  auto gather = [&](int margin) {
    const double A = a + margin, B = b + margin;
    const double Ao = A + o.ring_width_px, Bo = B + o.ring_width_px;
    const double ex = std::sqrt(Ao * Ao * c * c + Bo * Bo * sn * sn);
    const double ey = std::sqrt(Ao * Ao * sn * sn + Bo * Bo * c * c);
    const double wx = std::sqrt(A * A * c * c + B * B * sn * sn);
    const double wy = std::sqrt(A * A * sn * sn + B * B * c * c);
    window_cut = cx - wx < 0 || cx + wx > W - 1 || cy - wy < 0 || cy + wy > H - 1;
    const int x_lo = std::max(0, static_cast<int>(std::ceil(cx - ex)));
    const int x_hi = std::min(W - 1, static_cast<int>(std::floor(cx + ex)));
    const int y_lo = std::max(0, static_cast<int>(std::ceil(cy - ey)));
    const int y_hi = std::min(H - 1, static_cast<int>(std::floor(cy + ey)));
    const double iA2 = 1 / (A * A), iB2 = 1 / (B * B), iAo2 = 1 / (Ao * Ao), iBo2 = 1 / (Bo * Bo);
    s->window.clear();
    s->ring.clear();
    n_pass_window = 0;
    saturated = false;
    for (int y = y_lo; y <= y_hi; ++y) {
      const T* row = img.ptr<T>(y);
      const double dy = y - cy;
      for (int x = x_lo; x <= x_hi; ++x) {
        const double dx = x - cx;
        const double u = dx * c + dy * sn, v = -dx * sn + dy * c;
        const double q = u * u * iA2 + v * v * iB2;
        const int val = row[x];
        if (q <= 1) {
          s->window.push_back({dx, dy, static_cast<double>(val), q});
          n_pass_window += Pass<kDark>(val, ctx.threshold);
          saturated |= kDark ? val <= 0 : val >= ctx.saturation;
        } else if (u * u * iAo2 + v * v * iBo2 <= 1) {
          s->ring.push_back({dx, dy, static_cast<double>(val), q});
        }
      }
    }
    return FitBackground(s->ring, &s->background, &bg);
  };
  // Mean signal per pixel in the window's outer shell, and whether it is significant: a
  // blurred tail that the window would cut.
  auto shell = [&](int margin, bool* significant) {
    const double B = b + margin;
    const double q_shell = std::pow(std::max(0.0, 1 - kShellWidth / B), 2);
    double sum = 0;
    int n = 0;
    for (const Px& p : s->window)
      if (p.q > q_shell) {
        sum += sign * (p.v - bg.At(p.dx, p.dy));
        ++n;
      }
    const double sigma = o.read_noise_dn > 0 ? o.read_noise_dn : std::max(bg.sigma, kQuantSigma);
    *significant = n > 0 && sum > kShellSignificance * sigma * std::sqrt(static_cast<double>(n));
    return n > 0 ? sum / n : 0.0;
  };

  // Window size: start at window_margin_px and widen while the region does not fit or the
  // shell holds a significant tail. A widening is undone, and the search ends, when it
  // brings in another region's pixels, a ring that is mostly outliers, or a shell signal
  // that no longer decays (background structure, not a PSF tail): in clutter, growing
  // further would measure the clutter.
  int margin = o.window_margin_px;
  if (!gather(margin)) return false;
  bool significant;
  double shell_mean = shell(margin, &significant);
  while (margin < o.max_window_margin_px && (n_pass_window < r.n || significant)) {
    const int prev_margin = margin;
    const int prev_pass = n_pass_window;
    const double prev_shell = shell_mean;
    margin = std::min(o.max_window_margin_px, margin + std::max(2, margin / 2));
    const bool ok = gather(margin);
    const bool contaminated = !ok || n_pass_window > std::max<double>(prev_pass, r.n) ||
                              bg.n < kMinRingInlierFraction * s->ring.size();
    shell_mean = ok ? shell(margin, &significant) : 0.0;
    const bool not_decaying = significant && prev_pass >= r.n && shell_mean > kTailDecay * prev_shell;
    if (contaminated || not_decaying) {
      margin = prev_margin;
      if (!gather(margin)) return false;
      break;
    }
  }

  // Centroid: every window pixel weighted by its background-subtracted value, negative
  // ones included (clipping them would bias the centre towards the brighter tail).
  double D = 0, Nx = 0, Ny = 0, peak = -std::numeric_limits<double>::infinity();
  for (const Px& p : s->window) {
    const double w = sign * (p.v - bg.At(p.dx, p.dy));
    D += w;
    Nx += w * p.dx;
    Ny += w * p.dy;
    peak = std::max(peak, w);
  }
  if (!(D > 0)) return false;
  // Too few ring pixels estimate the noise poorly: then the image-wide estimate stands in.
  const double ring_noise = bg.n >= 10 ? bg.sigma : ctx.global_noise;
  const double noise_bg = o.read_noise_dn > 0 ? o.read_noise_dn : std::max(ring_noise, kQuantSigma);
  if (peak < o.min_peak_snr * noise_bg) return false;
  const Vec2 off(Nx / D, Ny / D);
  {
    // A centroid outside its own window is not a measurement (flux near zero or clutter).
    const double A = a + margin, B = b + margin;
    const double u = off.x() * c + off.y() * sn, v = -off.x() * sn + off.y() * c;
    if (u * u / (A * A) + v * v / (B * B) > 1) return false;
  }

  // Covariance, first order. d centre / d I_i = sign (x_i - centre) / D for window pixels;
  // through the background, d centre / d beta = -sign M / D with M = sum (x_i - centre) [1 dx dy],
  // and Cov(beta) = sigma^2 (A^T A)^-1 over the ring inliers. Window and ring are disjoint.
  const double var_bg = noise_bg * noise_bg;
  const double inv_gain = o.gain_e_per_dn > 0 ? 1.0 / o.gain_e_per_dn : 0.0;
  Mat2 C = Mat2::Zero();
  Eigen::Matrix<double, 2, 3> M = Eigen::Matrix<double, 2, 3>::Zero();
  for (const Px& p : s->window) {
    const Vec2 d(p.dx - off.x(), p.dy - off.y());
    // Shot noise of the signal: more above a bright background, less in a dark dot.
    const double var = std::max(var_bg + inv_gain * (p.v - bg.At(p.dx, p.dy)), kQuantSigma * kQuantSigma);
    C.noalias() += var * d * d.transpose();
    M.col(0) += d;
    M.col(1) += d * p.dx;
    M.col(2) += d * p.dy;
  }
  C.noalias() += var_bg * M * bg.cov_unit * M.transpose();
  C /= D * D;

  blob->centre = Vec2(cx, cy) + off;
  blob->cov = C;
  blob->flux = D;
  blob->background = bg.At(off.x(), off.y());
  blob->peak = peak;
  blob->noise_dn = noise_bg;
  blob->touches_border = window_cut || r.x0 == 0 || r.y0 == 0 || r.x1 == W - 1 || r.y1 == H - 1;
  blob->saturated = saturated;
  // Two blobs merged into one region look elongated and not elliptical (a waist); a single
  // blob's region is ragged at low SNR but stays as round as the blob.
  const bool merged_shape =
      blob->circularity < kMergedMaxCircularity && blob->ellipse_residual_px > kMergedMinResidualPx;
  blob->crowded = n_pass_window != static_cast<int>(r.n) || merged_shape;
  return true;
}

// Labels the regions of `img` (the whole image or a window of it, whose pixel (0,0) is at
// `origin` in the image) and measures those that pass the shape tests; appends the blobs, in
// image coordinates, to *blobs. Returns the number of regions.
// `extremes`: each row's extreme pixel when read beforehand (LabelRuns).
template <typename T, bool kDark>
int DetectIn(const cv::Mat& img, const cv::Point& origin, const BlobDetectorOptions& o, int t, double noise,
             const std::vector<T>* extremes, std::vector<Blob>* blobs) {
  std::vector<Run> runs;
  std::vector<int> parent;
  // A region within one row of length L has circularity 1/L (second moments L^2/12 and
  // 1/12): it passes min_area_px <= L <= 1/min_circularity, which is impossible when
  // min_area_px * min_circularity > 1 (3 * 0.5 by default). Then one-row regions need not
  // be labelled, and the scan reads only the even rows and the rows next to a hit.
  const bool skip_single_rows = o.min_area_px * o.min_circularity > 1.0 + 1e-6;
  LabelRuns<T, kDark>(img, t, skip_single_rows, extremes, &runs, &parent);

  std::vector<int> region_of(runs.size(), -1), next_run(runs.size(), -1);
  std::vector<Region> regions;
  for (size_t i = 0; i < runs.size(); ++i) {
    const int root = Find(parent, static_cast<int>(i));
    if (region_of[root] < 0) {
      region_of[root] = static_cast<int>(regions.size());
      regions.emplace_back();
    }
    Region& g = regions[region_of[root]];
    const Run& run = runs[i];
    const double n = run.xe - run.xs + 1;
    const double sx = 0.5 * (run.xs + run.xe) * n;
    g.n += n;
    g.sx += sx;
    g.sy += n * run.y;
    g.sxx += SumSquares(run.xe) - SumSquares(run.xs - 1);
    g.syy += n * run.y * run.y;
    g.sxy += sx * run.y;
    g.x0 = std::min(g.x0, run.xs);
    g.x1 = std::max(g.x1, run.xe);
    g.y0 = std::min(g.y0, run.y);
    g.y1 = std::max(g.y1, run.y);
    if (g.tail >= 0)
      next_run[g.tail] = static_cast<int>(i);
    else
      g.head = static_cast<int>(i);
    g.tail = static_cast<int>(i);
  }

  Context ctx;
  ctx.img = &img;
  ctx.threshold = t;
  ctx.saturation = o.saturation_dn > 0 ? o.saturation_dn : static_cast<double>(std::numeric_limits<T>::max());
  ctx.opts = &o;
  ctx.global_noise = noise;
  Scratch scratch;
  for (const Region& g : regions) {
    if (g.n < o.min_area_px || g.n > o.max_area_px) continue;
    // The shape tests need only the region: reject before the (costlier) measurement.
    const RegionShape shape = ShapeOf(g);
    if (!(shape.l2 > 0)) continue;
    Blob blob;
    blob.circularity = std::sqrt(shape.l2 / shape.l1);
    if (blob.circularity < o.min_circularity) continue;
    blob.ellipse_residual_px = EllipseResidual(g, shape, runs, next_run);
    if (blob.ellipse_residual_px > o.max_ellipse_residual_px) continue;
    if (Measure<T, kDark>(ctx, g, shape, &scratch, &blob)) {
      blob.centre += Vec2(origin.x, origin.y);
      blobs->push_back(blob);
    }
  }
  return static_cast<int>(regions.size());
}

// The image-wide statistics, then detection in each window (the whole image when windows
// is null).
template <typename T, bool kDark>
std::vector<Blob> Detect(const cv::Mat& img, const BlobDetectorOptions& o, BlobImageStats* stats,
                         const std::vector<cv::Rect>* windows) {
  double background, noise;
  // The whole image is read once, in memory order (the rate of main memory), for both the
  // sparse sample and each row's extreme pixel; windows read the sample's rows only.
  std::vector<T> extremes;
  if (!windows) {
    SparseSample<T> sample(img);
    extremes.resize(img.rows);
    for (int y = 0; y < img.rows; ++y) {
      extremes[y] = RowExtreme<T, kDark>(img.ptr<T>(y), img.cols);
      if (sample.Samples(y)) sample.AddRow(y);
    }
    sample.Finish(&background, &noise);
  } else {
    SampleStats<T>(img, &background, &noise);
  }
  if (o.read_noise_dn > 0) noise = o.read_noise_dn;
  const double thr = o.threshold_dn > 0 ? o.threshold_dn : o.k_sigma * noise;
  // Integer level for Pass<kDark>: v > floor(bg + thr) <=> v > bg + thr for integer v
  // (bright); v < ceil(bg - thr) <=> v < bg - thr (dark). Clamped to int range.
  const double level = kDark ? std::ceil(background - thr) : std::floor(background + thr);
  const int t = static_cast<int>(std::clamp(level, -1.0, 70000.0));

  std::vector<Blob> blobs;
  int num_regions = 0;
  if (!windows) {
    num_regions = DetectIn<T, kDark>(img, cv::Point(0, 0), o, t, noise, &extremes, &blobs);
  } else {
    for (const cv::Rect& w : *windows)
      num_regions += DetectIn<T, kDark>(img(w), w.tl(), o, t, noise, nullptr, &blobs);
  }
  if (stats) {
    stats->background_dn = background;
    stats->noise_dn = noise;
    stats->threshold_dn = thr;
    stats->num_regions = num_regions;
  }
  std::sort(blobs.begin(), blobs.end(), [](const Blob& x, const Blob& y) { return x.flux > y.flux; });
  return blobs;
}

// The image as one gray channel of 8 or 16 bits; InputError naming what is wrong.
cv::Mat CheckedGray(const cv::Mat& image, const BlobDetectorOptions& options, const char* caller) {
  std::string why;
  if (!options.IsValid(&why)) Throw(caller, ": invalid BlobDetectorOptions: ", why);
  if (image.empty()) Throw(caller, ": image is empty; expected a CV_8U or CV_16U image");
  const int depth = image.depth();
  if (depth != CV_8U && depth != CV_16U) {
    const bool is_float = depth == CV_32F || depth == CV_64F || depth == CV_16F;
    if (is_float && depth != CV_16F && !cv::checkRange(image, true))
      Throw(caller, ": image is ", cv::typeToString(image.type()),
            " and contains NaN or Inf; expected a CV_8U or CV_16U image");
    Throw(caller, ": image is ", cv::typeToString(image.type()), "; expected a CV_8U or CV_16U image");
  }
  cv::Mat gray;
  switch (image.channels()) {
    case 1: gray = image; break;
    case 3: cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY); break;
    case 4: cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY); break;
    default:
      Throw(caller, ": image has ", image.channels(), " channels; expected 1 (gray), 3 (BGR) or 4 (BGRA)");
  }
  return gray;
}

std::vector<Blob> Dispatch(const cv::Mat& gray, const BlobDetectorOptions& options, BlobImageStats* stats,
                           const std::vector<cv::Rect>* windows) {
  const bool dark = options.polarity == Polarity::kDark;
  if (gray.depth() == CV_8U)
    return dark ? Detect<uint8_t, true>(gray, options, stats, windows) : Detect<uint8_t, false>(gray, options, stats, windows);
  return dark ? Detect<uint16_t, true>(gray, options, stats, windows) : Detect<uint16_t, false>(gray, options, stats, windows);
}

}  // namespace

std::vector<Blob> DetectBlobs(const cv::Mat& image, const BlobDetectorOptions& options, BlobImageStats* stats) {
  return Dispatch(CheckedGray(image, options, "DetectBlobs"), options, stats, nullptr);
}

std::vector<cv::Rect> MergeWindows(std::vector<cv::Rect> windows, const cv::Size& image_size) {
  const cv::Rect all(0, 0, image_size.width, image_size.height);
  std::vector<cv::Rect> out;
  for (cv::Rect w : windows) {
    w &= all;
    if (w.area() > 0) out.push_back(w);
  }
  // Union every two windows that overlap or touch (a region on their common edge would be
  // cut in both) until none do.
  for (bool merged = true; merged;) {
    merged = false;
    for (size_t i = 0; i < out.size() && !merged; ++i)
      for (size_t j = i + 1; j < out.size() && !merged; ++j) {
        const cv::Rect grown(out[i].x - 1, out[i].y - 1, out[i].width + 2, out[i].height + 2);
        if ((grown & out[j]).area() > 0) {
          out[i] |= out[j];
          out.erase(out.begin() + static_cast<std::ptrdiff_t>(j));
          merged = true;
        }
      }
  }
  return out;
}

std::vector<cv::Range> RowsReadInWindows(const cv::Size& image_size, const std::vector<cv::Rect>& windows) {
  const int W = image_size.width, H = image_size.height;
  std::vector<cv::Range> rows;
  if (W <= 0 || H <= 0) return rows;
  // SampleStats's rows (the loops there: y and x from min(step / 2, size - 1) by step).
  const int step = SampleStep(W, H);
  const int x0 = std::min(step / 2, W - 1);
  const bool below = x0 + (W - 1 - x0) / step * step == W - 1;  // the last sampled column is the last
  for (int y = std::min(step / 2, H - 1); y < H; y += step) rows.emplace_back(y, std::min(y + (below ? 2 : 1), H));
  for (const cv::Rect& w : MergeWindows(windows, image_size)) rows.emplace_back(w.y, w.y + w.height);
  // Sorted and united.
  std::sort(rows.begin(), rows.end(), [](const cv::Range& a, const cv::Range& b) { return a.start < b.start; });
  std::vector<cv::Range> out;
  for (const cv::Range& r : rows) {
    if (!out.empty() && r.start <= out.back().end)
      out.back().end = std::max(out.back().end, r.end);
    else
      out.push_back(r);
  }
  return out;
}

std::vector<Blob> DetectBlobsInWindows(const cv::Mat& image, const std::vector<cv::Rect>& windows,
                                       const BlobDetectorOptions& options, BlobImageStats* stats) {
  const cv::Mat gray = CheckedGray(image, options, "DetectBlobsInWindows");
  const std::vector<cv::Rect> merged = MergeWindows(windows, gray.size());
  return Dispatch(gray, options, stats, &merged);
}

}  // namespace mcms
