#include "vision/pixel_noise.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/statistics.h"

namespace mcms {

bool PixelNoiseOptions::IsValid(std::string* why) const {
  auto fail = [why](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (!(plateau_margin_px >= 0 && std::isfinite(plateau_margin_px))) return fail("plateau_margin_px must be >= 0");
  if (min_plateau_px < 4) return fail("min_plateau_px must be >= 4 (a plane and a residual)");
  if (quadratic_min_px < 12) return fail("quadratic_min_px must be >= 12 (a quadratic and a residual)");
  if (!(ring_gap_px >= 0 && std::isfinite(ring_gap_px))) return fail("ring_gap_px must be >= 0");
  if (!(ring_width_px >= 1 && std::isfinite(ring_width_px))) return fail("ring_width_px must be >= 1");
  if (min_ring_px < 4) return fail("min_ring_px must be >= 4");
  if (!(clip_sigma >= 3)) return fail("clip_sigma must be >= 3 (tighter clipping biases the variance)");
  if (!(min_signal_snr >= 0 && std::isfinite(min_signal_snr))) return fail("min_signal_snr must be >= 0");
  if (why) why->clear();
  return true;
}

namespace {

struct Px {
  double dx, dy, v;
};

struct SurfaceFit {
  double level = 0;     // the surface at (0, 0)
  double mean = 0;      // mean value of the inliers
  double var = 0;       // residual variance of the inliers, dof-corrected
  int dof = 0;
};

// Least-squares surface (1, dx, dy[, dx^2, dx dy, dy^2]) with iterated clip_sigma
// clipping from a median/MAD start. False when too few inliers remain.
bool FitSurface(const std::vector<Px>& px, bool quadratic, double clip_sigma, SurfaceFit* out) {
  const int np = quadratic ? 6 : 3;
  const int n_all = static_cast<int>(px.size());
  if (n_all < np + 1) return false;
  std::vector<double> v(n_all);
  for (int i = 0; i < n_all; ++i) v[i] = px[i].v;
  std::vector<int> counts;
  double med = 0, mad_raw = 0;
  MedianAndMad(v, &counts, &med, &mad_raw);
  // Floor: the quantization of an integer image, so that a noise-free image still fits.
  const double mad = std::max(1.4826 * mad_raw, 0.5);
  auto basis = [&](const Px& p) {
    Eigen::Matrix<double, 6, 1> a;
    a << 1, p.dx, p.dy, p.dx * p.dx, p.dx * p.dy, p.dy * p.dy;
    return a;
  };
  Eigen::Matrix<double, 6, 1> beta = Eigen::Matrix<double, 6, 1>::Zero();
  beta[0] = med;
  // The first clip is around the median: wide, since a sloped plateau inflates the MAD.
  double clip = 2 * clip_sigma * mad;
  SurfaceFit fit;
  for (int iter = 0; iter < 4; ++iter) {
    Eigen::MatrixXd AtA = Eigen::MatrixXd::Zero(np, np);
    Eigen::VectorXd Atv = Eigen::VectorXd::Zero(np);
    int n = 0;
    double sum = 0;
    for (const Px& p : px) {
      const auto a = basis(p);
      if (std::abs(p.v - a.dot(beta)) > clip) continue;
      AtA.noalias() += a.head(np) * a.head(np).transpose();
      Atv.noalias() += a.head(np) * p.v;
      sum += p.v;
      ++n;
    }
    if (n < np + 1) return false;
    Eigen::LDLT<Eigen::MatrixXd> ldlt(AtA);
    if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > 1e-10)) return false;
    Eigen::Matrix<double, 6, 1> next = Eigen::Matrix<double, 6, 1>::Zero();
    next.head(np) = ldlt.solve(Atv);
    double r2 = 0;
    for (const Px& p : px) {
      const auto a = basis(p);
      if (std::abs(p.v - a.dot(beta)) > clip) continue;
      const double r = p.v - a.dot(next);
      r2 += r * r;
    }
    fit.level = next[0];
    fit.mean = sum / n;
    fit.dof = n - np;
    fit.var = r2 / fit.dof;
    beta = next;
    clip = clip_sigma * std::sqrt(std::max(fit.var, 1.0 / 12));
  }
  *out = fit;
  return true;
}

// The blob's outline as an ellipse: centre, unit major axis, semi-axes (px).
struct Ellipse {
  Vec2 c;
  double cos_t, sin_t, a, b;
  // Generalized radius: 1 on the ellipse with semi-axes grown by `grow` px.
  double Q(double dx, double dy, double grow) const {
    const double u = dx * cos_t + dy * sin_t, v = -dx * sin_t + dy * cos_t;
    const double A = a + grow, B = b + grow;
    return u * u / (A * A) + v * v / (B * B);
  }
};

Ellipse OutlineOf(const Blob& blob) {
  const Mat2& S = blob.shape;
  const double half_tr = 0.5 * S.trace(), d = 0.5 * (S(0, 0) - S(1, 1));
  const double disc = std::sqrt(d * d + S(0, 1) * S(0, 1));
  const double l1 = half_tr + disc, l2 = std::max(half_tr - disc, 0.0);
  const double theta = 0.5 * std::atan2(2 * S(0, 1), S(0, 0) - S(1, 1));
  return {blob.centre, std::cos(theta), std::sin(theta), 2 * std::sqrt(l1), 2 * std::sqrt(l2)};
}

template <typename T>
std::vector<PixelNoiseSample> Measure(const cv::Mat& img, const std::vector<Blob>& blobs, const PixelNoiseOptions& o) {
  const double max_dn = static_cast<double>(std::numeric_limits<T>::max());
  std::vector<Ellipse> outlines;
  for (const Blob& b : blobs) outlines.push_back(OutlineOf(b));
  std::vector<PixelNoiseSample> out;
  std::vector<Px> plateau, ring;
  for (size_t k = 0; k < blobs.size(); ++k) {
    const Blob& blob = blobs[k];
    if (blob.saturated || blob.crowded || blob.touches_border) continue;
    const Ellipse& e = outlines[k];
    if (e.b - o.plateau_margin_px < 1) continue;  // no plateau
    const double outer = o.ring_gap_px + o.ring_width_px;
    const double reach = e.a + outer + 1;
    const int x0 = static_cast<int>(std::floor(e.c.x() - reach)), x1 = static_cast<int>(std::ceil(e.c.x() + reach));
    const int y0 = static_cast<int>(std::floor(e.c.y() - reach)), y1 = static_cast<int>(std::ceil(e.c.y() + reach));
    if (x0 < 0 || y0 < 0 || x1 >= img.cols || y1 >= img.rows) continue;  // ring cut by the border
    plateau.clear();
    ring.clear();
    bool clipped = false;
    for (int y = y0; y <= y1; ++y) {
      const T* row = img.ptr<T>(y);
      for (int x = x0; x <= x1; ++x) {
        const double dx = x - e.c.x(), dy = y - e.c.y();
        const double v = row[x];
        if (e.Q(dx, dy, -o.plateau_margin_px) <= 1) {
          plateau.push_back({dx, dy, v});
          clipped |= v <= 0 || v >= max_dn;
        } else if (e.Q(dx, dy, outer) <= 1 && e.Q(dx, dy, o.ring_gap_px) > 1) {
          bool other = false;
          for (size_t j = 0; j < blobs.size() && !other; ++j)
            other = j != k && outlines[j].Q(x - outlines[j].c.x(), y - outlines[j].c.y(), o.ring_gap_px) <= 1;
          if (!other) ring.push_back({dx, dy, v});
        }
      }
    }
    // A clipped plateau pixel has lost its noise; the detector's saturation flag looks at
    // the whole window, this at the plateau (a dark dot at 0, a bright one at full scale).
    if (clipped || static_cast<int>(plateau.size()) < o.min_plateau_px || static_cast<int>(ring.size()) < o.min_ring_px)
      continue;
    SurfaceFit p, r;
    if (!FitSurface(plateau, static_cast<int>(plateau.size()) >= o.quadratic_min_px, o.clip_sigma, &p)) continue;
    if (!FitSurface(ring, false, o.clip_sigma, &r)) continue;
    PixelNoiseSample s;
    s.centre = blob.centre;
    s.background_dn = r.level;
    s.background_var = r.var;
    s.background_dof = r.dof;
    s.plateau_dn = p.mean;
    s.plateau_var = p.var;
    s.plateau_dof = p.dof;
    if (!(std::abs(s.Signal()) > o.min_signal_snr * std::sqrt(std::max(r.var, 1.0 / 12)))) continue;
    out.push_back(s);
  }
  return out;
}

}  // namespace

std::vector<PixelNoiseSample> MeasurePixelNoise(const cv::Mat& image,
                                                const std::vector<Blob>& blobs,
                                                const PixelNoiseOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("MeasurePixelNoise: invalid PixelNoiseOptions: ", why);
  if (image.empty()) Throw("MeasurePixelNoise: image is empty; expected a CV_8U or CV_16U image");
  if (image.depth() != CV_8U && image.depth() != CV_16U)
    Throw("MeasurePixelNoise: image is ", cv::typeToString(image.type()), "; expected a CV_8U or CV_16U image");
  cv::Mat gray = image;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 4) cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  else if (image.channels() != 1)
    Throw("MeasurePixelNoise: image has ", image.channels(), " channels; expected 1 (gray), 3 (BGR) or 4 (BGRA)");
  return gray.depth() == CV_8U ? Measure<uint8_t>(gray, blobs, options) : Measure<uint16_t>(gray, blobs, options);
}

PixelNoiseEstimate EstimatePixelNoise(const std::vector<PixelNoiseSample>& samples) {
  PixelNoiseEstimate e;
  if (samples.empty()) return e;
  const size_t n = samples.size();
  std::vector<double> slope(n);
  for (size_t k = 0; k < n; ++k)
    slope[k] = (samples[k].plateau_var - samples[k].background_var) / samples[k].Signal();
  // Start: the ratio of sums (every blob weighted by its signal), robust enough to set the
  // weights, which depend on the slope through the plateau's expected variance.
  double num = 0, den = 0;
  for (const auto& s : samples) {
    num += (s.plateau_var - s.background_var) * (s.Signal() > 0 ? 1 : -1);
    den += std::abs(s.Signal());
  }
  double b = num / den;
  std::vector<bool> use(n, true);
  std::vector<double> sigma(n);
  double sum_w = 0, chi2 = 0;
  int used = 0;
  for (int iter = 0; iter < 6; ++iter) {
    for (size_t k = 0; k < n; ++k) {
      const auto& s = samples[k];
      // Expected variances (the measured ring variance stands for its own expectation;
      // its dof are many times the plateau's).
      const double vp = std::max(s.background_var + b * s.Signal(), 1.0 / 12);
      const double vr = std::max(s.background_var, 1.0 / 12);
      sigma[k] = std::sqrt(2 * vp * vp / s.plateau_dof + 2 * vr * vr / s.background_dof) / std::abs(s.Signal());
    }
    // Outlying blobs (texture, a glint the clipping missed) are left out, judged against
    // the estimate of the others; re-admitted when the estimate moves.
    if (iter >= 2)
      for (size_t k = 0; k < n; ++k) use[k] = std::abs(slope[k] - b) <= 5 * sigma[k];
    double sw = 0, swb = 0;
    for (size_t k = 0; k < n; ++k)
      if (use[k]) {
        const double w = 1 / (sigma[k] * sigma[k]);
        sw += w;
        swb += w * slope[k];
      }
    if (!(sw > 0)) break;
    b = swb / sw;
    sum_w = sw;
  }
  chi2 = 0;
  used = 0;
  std::vector<double> bg_sigma;
  double signal = 0;
  for (size_t k = 0; k < n; ++k) {
    if (!use[k]) continue;
    chi2 += std::pow((slope[k] - b) / sigma[k], 2);
    ++used;
    bg_sigma.push_back(std::sqrt(samples[k].background_var));
    signal += std::abs(samples[k].Signal());
  }
  if (used == 0) {
    e.blobs_dropped = static_cast<int>(n);
    return e;
  }
  e.blobs = used;
  e.blobs_dropped = static_cast<int>(n) - used;
  e.inv_gain = b;
  e.scatter_chi2_per_dof = used > 1 ? chi2 / (used - 1) : 0.0;
  // A scatter larger than the errors predict (a non-uniform ball, clutter) widens the error.
  e.inv_gain_sigma = std::sqrt(std::max(1.0, e.scatter_chi2_per_dof) / sum_w);
  e.gain_e_per_dn = b > 0 ? 1 / b : 0.0;
  e.background_noise_dn = SelectedMedian(bg_sigma);
  e.mean_signal_dn = signal / used;
  return e;
}

std::string PixelNoiseEstimate::Describe() const {
  char buf[512];
  if (!valid()) return "no usable blob (none with a plateau of enough pixels, unsaturated, uncrowded)";
  if (gain_e_per_dn > 0) {
    const double g_sigma = inv_gain_sigma / (inv_gain * inv_gain);
    std::snprintf(buf, sizeof(buf),
                  "gain %.3g +- %.2g e-/DN (photon noise 1/gain %.4g +- %.2g DN per DN of signal), background noise "
                  "%.3g DN, from %d blobs (signal %.0f DN)",
                  gain_e_per_dn, g_sigma, inv_gain, inv_gain_sigma, background_noise_dn, blobs, mean_signal_dn);
  } else if (inv_gain < -3 * inv_gain_sigma) {
    // Variance falling with the signal is not photon noise: a response that saturates
    // softly (a knee), compression or denoising in the camera.
    std::snprintf(buf, sizeof(buf),
                  "no photon noise measurable: the plateaus are quieter than the background (1/gain %.3g +- %.2g; a "
                  "saturating, compressed or denoised response), background noise %.3g DN, from %d blobs (signal "
                  "%.0f DN)",
                  inv_gain, inv_gain_sigma, background_noise_dn, blobs, mean_signal_dn);
  } else {
    std::snprintf(buf, sizeof(buf),
                  "no photon noise measurable (1/gain %.3g +- %.2g), background noise %.3g DN, from %d blobs "
                  "(signal %.0f DN)",
                  inv_gain, inv_gain_sigma, background_noise_dn, blobs, mean_signal_dn);
  }
  std::string s = buf;
  if (blobs_dropped > 0) s += ", " + std::to_string(blobs_dropped) + " outlying blob(s) left out";
  return s;
}

}  // namespace mcms
