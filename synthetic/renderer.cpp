#include "synthetic/renderer.h"


#include <numbers>
#include <atomic>
#include <cstdio>
#include <exception>
#include <fstream>
#include <limits>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"

namespace mcms {

namespace fs = std::filesystem;

bool RenderOptions::IsValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  auto finite_nonneg = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!(std::isfinite(exposure) && exposure > 0)) return fail("exposure must be a positive number");
  if (!finite_nonneg(ball_dn)) return fail("ball_dn must be a number >= 0");
  if (!finite_nonneg(background_dn)) return fail("background_dn must be a number >= 0");
  if (!background_gradient_dn.allFinite()) return fail("background_gradient_dn must be two finite numbers");
  if (!finite_nonneg(blur_sigma_px) || blur_sigma_px > 20) return fail("blur_sigma_px must be in [0, 20] px");
  if (!finite_nonneg(gain_e_per_dn)) return fail("gain_e_per_dn must be a number >= 0 (0 = no photon noise)");
  if (!finite_nonneg(read_noise_dn)) return fail("read_noise_dn must be a number >= 0");
  if (bit_depth != 8 && bit_depth != 16) return fail("bit_depth must be 8 or 16");
  if (supersampling < 1 || supersampling > 64) return fail("supersampling must be an integer in [1, 64]");
  if (!finite_nonneg(spurious_per_image) || spurious_per_image > 1000)
    return fail("spurious_per_image must be in [0, 1000]");
  if (!(std::isfinite(spurious_radius_min_px) && spurious_radius_min_px > 0 &&
        std::isfinite(spurious_radius_max_px) && spurious_radius_max_px >= spurious_radius_min_px &&
        spurious_radius_max_px <= 1000))
    return fail("spurious radius must satisfy 0 < min <= max <= 1000 (px; a reflection is a spot, not the image)");
  if (!finite_nonneg(spurious_dn)) return fail("spurious_dn must be a number >= 0");
  if (!(occlusion_probability >= 0 && occlusion_probability <= 1))
    return fail("occlusion_probability must be in [0, 1]");
  if (!(dropout_probability >= 0 && dropout_probability <= 1)) return fail("dropout_probability must be in [0, 1]");
  return true;
}

// ---------------------------------------------------------------------------------
// RayTable

RayTable::RayTable(const CameraModel& cam, double pad_px, double tolerance_px) : cam_(cam), pad_(pad_px) {
  MCMS_CHECK(pad_px >= 0 && pad_px < 1e4 && tolerance_px > 0, "RayTable: pad must be in [0, 1e4) px and the tolerance positive");
  // Bilinear error falls with the square of the step: measure it on an 8 px grid,
  // go to the power-of-two step that this predicts meets the tolerance, and halve
  // further if it does not. 1 px is the finest grid kept (about 21 MB for
  // 1280 x 1024); a lens that still misses the tolerance there keeps its error.
  double step = 8.0;
  Build(step);
  while (error_px_ > tolerance_px && step > 1.0) {
    const double predicted = step * std::sqrt(tolerance_px / error_px_);
    double next = step / 2;
    while (next > 1.0 && next > predicted) next /= 2;
    step = std::max(next, 1.0);
    Build(step);
  }
}

void RayTable::Build(double step) {
  step_ = step;
  inv_step_ = 1.0 / step;
  u0_ = -0.5 - pad_;
  v0_ = -0.5 - pad_;
  nu_ = static_cast<int>(std::ceil((cam_.Width() + 2 * pad_) / step)) + 1;
  nv_ = static_cast<int>(std::ceil((cam_.Height() + 2 * pad_) / step)) + 1;
  const size_t n = static_cast<size_t>(nu_) * nv_;
  std::vector<Vec2> q(n);
  for (int j = 0; j < nv_; ++j)
    for (int i = 0; i < nu_; ++i) q[static_cast<size_t>(j) * nu_ + i] = Vec2(u0_ + i * step, v0_ + j * step);
  const auto rays = cam_.Unproject(q);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  xy_.assign(2 * n, nan);
  // Rays within about 87 degrees of the axis: beyond that x/z and y/z blow up and
  // bilinear interpolation of them means nothing.
  for (size_t k = 0; k < n; ++k)
    if (rays[k] && (*rays[k]).z() > 0.05) {
      xy_[2 * k] = (*rays[k]).x() / (*rays[k]).z();
      xy_[2 * k + 1] = (*rays[k]).y() / (*rays[k]).z();
    }

  // Error at the cell centres, and the largest angular rate of the ray per pixel.
  std::vector<Vec3> mid;
  std::vector<Vec2> mid_q;
  mid.reserve(n);
  mid_q.reserve(n);
  double rate = 0.0;
  auto unit = [&](size_t k) { return Vec3(xy_[2 * k], xy_[2 * k + 1], 1.0).normalized(); };
  auto angle = [](const Vec3& a, const Vec3& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); };
  for (int j = 0; j + 1 < nv_; ++j)
    for (int i = 0; i + 1 < nu_; ++i) {
      const size_t k00 = static_cast<size_t>(j) * nu_ + i, k10 = k00 + 1, k01 = k00 + nu_, k11 = k01 + 1;
      if (!std::isfinite(xy_[2 * k00]) || !std::isfinite(xy_[2 * k10]) || !std::isfinite(xy_[2 * k01]) ||
          !std::isfinite(xy_[2 * k11]))
        continue;
      const double x = 0.25 * (xy_[2 * k00] + xy_[2 * k10] + xy_[2 * k01] + xy_[2 * k11]);
      const double y = 0.25 * (xy_[2 * k00 + 1] + xy_[2 * k10 + 1] + xy_[2 * k01 + 1] + xy_[2 * k11 + 1]);
      mid.emplace_back(x, y, 1.0);
      mid_q.push_back(q[k00] + Vec2(0.5 * step, 0.5 * step));
      const Vec3 r00 = unit(k00);
      // Frobenius norm of the angular Jacobian bounds its spectral norm (the largest
      // rate in any direction).
      const double au = angle(r00, unit(k10)) / step, av = angle(r00, unit(k01)) / step;
      rate = std::max(rate, std::hypot(au, av));
    }
  const auto back = cam_.Project(mid);
  error_px_ = 0.0;
  for (size_t k = 0; k < mid.size(); ++k) {
    const double e = (back[k] - mid_q[k]).norm();
    error_px_ = std::isfinite(e) ? std::max(error_px_, e) : std::numeric_limits<double>::infinity();
  }
  // The rate varies within a cell; 10 % covers that for any sane lens.
  angle_per_px_ = 1.1 * rate;
}

// ---------------------------------------------------------------------------------
// Pixels

int RenderPadPx(const RenderOptions& options) {
  return static_cast<int>(std::ceil(4.0 * options.blur_sigma_px)) + 2;
}

namespace {

// One sphere's silhouette cone and its bounding box on the canvas.
struct Cone {
  Vec3 dir;                 // unit direction of the centre, camera frame
  double cos2_alpha = 0;    // cos^2 of the cone's half angle
  double cos_in = 2, cos_out = -2;  // pixel-centre tests: whole pixel inside / outside
  int x0 = 0, y0 = 0, x1 = -1, y1 = -1;  // inclusive canvas bounding box
};

// Coverage (0..1) of the union of the spheres' images on a canvas of the image
// padded by `pad` pixels: canvas pixel (i, j) is image pixel (i - pad, j - pad).
void SphereCoverage(const RayTable& table, const std::vector<Vec3>& centres, double radius, int n_sub, int pad,
                    cv::Mat* coverage) {
  const CameraModel& cam = table.Camera();
  const int cw = coverage->cols, ch = coverage->rows;
  double* cov = coverage->ptr<double>();
  // A whole pixel lies within this angle of its centre's ray (half diagonal).
  const double margin = std::sqrt(0.5) * table.MaxAnglePerPx();
  std::vector<Cone> cones;
  for (const Vec3& c : centres) {
    const double d = c.norm();
    if (!(d > radius) || !c.allFinite()) continue;  // camera inside the ball: nothing sensible to draw
    Cone k;
    k.dir = c / d;
    const double alpha = std::asin(radius / d);
    const double off_axis = std::acos(std::clamp(k.dir.z(), -1.0, 1.0));
    if (off_axis - alpha >= std::numbers::pi / 2) continue;  // entirely behind: the table holds forward rays only
    k.cos2_alpha = std::cos(alpha) * std::cos(alpha);
    k.cos_in = alpha > margin ? std::cos(alpha - margin) : 2.0;
    k.cos_out = std::cos(std::min(alpha + margin, std::numbers::pi));
    k.x0 = 0, k.y0 = 0, k.x1 = cw - 1, k.y1 = ch - 1;
    if (off_axis + alpha < std::numbers::pi / 2 - 1e-3) {
      // The outline's box, widened for the inscribed polygon's chords (0.12 % of the
      // size for 64 vertices) and 2 px for the supersampled boundary band.
      const auto outline = SphereOutline(cam, c, radius, 64);
      Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
      bool finite = !outline.empty();
      for (const Vec2& q : outline) {
        finite = finite && q.allFinite();
        lo = lo.cwiseMin(q);
        hi = hi.cwiseMax(q);
      }
      if (finite) {
        const double grow = 2.0 + 0.002 * (hi - lo).maxCoeff() + 2.0 * margin / std::max(table.MaxAnglePerPx(), 1e-12);
        const auto clampi = [](double v, int lo_i, int hi_i) {
          return static_cast<int>(std::clamp(v, static_cast<double>(lo_i), static_cast<double>(hi_i)));
        };
        k.x0 = clampi(std::floor(lo.x() - grow) + pad, 0, cw);
        k.y0 = clampi(std::floor(lo.y() - grow) + pad, 0, ch);
        k.x1 = clampi(std::ceil(hi.x() + grow) + pad, -1, cw - 1);
        k.y1 = clampi(std::ceil(hi.y() + grow) + pad, -1, ch - 1);
      }
    }
    cones.push_back(k);
  }

  // Pass 1: decide each pixel at its centre; collect the boundary pixels.
  std::vector<std::pair<size_t, int>> boundary;  // (canvas index, cone)
  for (int s = 0; s < static_cast<int>(cones.size()); ++s) {
    const Cone& k = cones[s];
    for (int j = k.y0; j <= k.y1; ++j)
      for (int i = k.x0; i <= k.x1; ++i) {
        const size_t idx = static_cast<size_t>(j) * cw + i;
        if (cov[idx] >= 1.0) continue;
        double x, y;
        if (!table.Normalized(i - pad, j - pad, &x, &y)) continue;
        const double cos_t = (x * k.dir.x() + y * k.dir.y() + k.dir.z()) / std::sqrt(x * x + y * y + 1.0);
        if (cos_t >= k.cos_in)
          cov[idx] = 1.0;
        else if (cos_t > k.cos_out)
          boundary.emplace_back(idx, s);
      }
  }
  // Pass 2: supersample the boundary pixels against the cones that cross them.
  std::sort(boundary.begin(), boundary.end());
  const double inv_n = 1.0 / n_sub;
  for (size_t b = 0; b < boundary.size();) {
    size_t e = b;
    while (e < boundary.size() && boundary[e].first == boundary[b].first) ++e;
    const size_t idx = boundary[b].first;
    if (cov[idx] < 1.0) {
      const double u = static_cast<double>(idx % cw) - pad, v = static_cast<double>(idx / cw) - pad;
      int inside = 0;
      for (int sj = 0; sj < n_sub; ++sj) {
        const double sv = v - 0.5 + (sj + 0.5) * inv_n;
        for (int si = 0; si < n_sub; ++si) {
          const double su = u - 0.5 + (si + 0.5) * inv_n;
          double x, y;
          if (!table.Normalized(su, sv, &x, &y)) continue;
          const double r2 = x * x + y * y + 1.0;
          for (size_t m = b; m < e; ++m) {
            const Cone& k = cones[boundary[m].second];
            const double dot = x * k.dir.x() + y * k.dir.y() + k.dir.z();
            if (dot > 0 && dot * dot >= k.cos2_alpha * r2) {
              ++inside;
              break;
            }
          }
        }
      }
      cov[idx] = inside * inv_n * inv_n;
    }
    b = e;
  }
}

// Blends one image-space disc of radiance `level` into the canvas radiance with the
// same centre-margin-supersampling scheme as the spheres.
void DrawDisc(const ImageDisc& disc, double level, int n_sub, int pad, cv::Mat* radiance) {
  const int cw = radiance->cols, ch = radiance->rows;
  const double r = disc.radius_px, half_diag = std::sqrt(0.5);
  const int x0 = std::max(0, static_cast<int>(std::floor(disc.centre_px.x() - r - 1)) + pad);
  const int x1 = std::min(cw - 1, static_cast<int>(std::ceil(disc.centre_px.x() + r + 1)) + pad);
  const int y0 = std::max(0, static_cast<int>(std::floor(disc.centre_px.y() - r - 1)) + pad);
  const int y1 = std::min(ch - 1, static_cast<int>(std::ceil(disc.centre_px.y() + r + 1)) + pad);
  const double inv_n = 1.0 / n_sub;
  for (int j = y0; j <= y1; ++j)
    for (int i = x0; i <= x1; ++i) {
      const double u = i - pad - disc.centre_px.x(), v = j - pad - disc.centre_px.y();
      const double d = std::hypot(u, v);
      double c;
      if (d <= r - half_diag) {
        c = 1.0;
      } else if (d >= r + half_diag) {
        continue;
      } else {
        int inside = 0;
        for (int sj = 0; sj < n_sub; ++sj)
          for (int si = 0; si < n_sub; ++si) {
            const double su = u - 0.5 + (si + 0.5) * inv_n, sv = v - 0.5 + (sj + 0.5) * inv_n;
            inside += su * su + sv * sv <= r * r;
          }
        c = inside * inv_n * inv_n;
      }
      double& L = radiance->at<double>(j, i);
      L = (1.0 - c) * L + c * level;
    }
}

}  // namespace

cv::Mat RenderSpheres(const CameraModel& cam, const std::vector<Vec3>& centres_cam, double radius,
                      const RenderOptions& options, Rng* noise) {
  const RayTable table(cam, RenderPadPx(options) + 2.0);
  return RenderSpheres(table, centres_cam, radius, options, noise);
}

cv::Mat RenderSpheres(const RayTable& table, const std::vector<Vec3>& centres_cam, double radius,
                      const RenderOptions& options, Rng* noise, const std::vector<ImageDisc>& discs) {
  std::string why;
  MCMS_CHECK(options.IsValid(&why), "RenderSpheres: bad options: " + why);
  MCMS_CHECK(radius > 0, "RenderSpheres: the sphere radius must be positive");
  const CameraModel& cam = table.Camera();
  const int w = cam.Width(), h = cam.Height(), pad = RenderPadPx(options);
  MCMS_CHECK(table.PadPx() >= pad + 0.5, "RenderSpheres: the ray table's pad is smaller than the blur needs");
  const bool noisy = !options.noise_free && (options.gain_e_per_dn > 0 || options.read_noise_dn > 0);
  MCMS_CHECK(!noisy || noise, "RenderSpheres: noisy options need a random stream");
  const int cw = w + 2 * pad, ch = h + 2 * pad;

  cv::Mat balls = cv::Mat::zeros(ch, cw, CV_64F);
  SphereCoverage(table, centres_cam, radius, options.supersampling, pad, &balls);

  // Radiance: the background's plane, the balls replacing it where they are.
  cv::Mat radiance(ch, cw, CV_64F);
  const double gx = options.background_gradient_dn.x() / std::max(w - 1, 1);
  const double gy = options.background_gradient_dn.y() / std::max(h - 1, 1);
  const double uc = 0.5 * (w - 1), vc = 0.5 * (h - 1);
  for (int j = 0; j < ch; ++j) {
    const double* b = balls.ptr<double>(j);
    double* L = radiance.ptr<double>(j);
    const double bg_row = options.background_dn + gy * (j - pad - vc);
    for (int i = 0; i < cw; ++i) {
      const double bg = bg_row + gx * (i - pad - uc);
      L[i] = options.exposure * (bg + b[i] * (options.ball_dn - bg));
    }
  }
  for (const ImageDisc& d : discs) DrawDisc(d, options.exposure * d.level_dn, options.supersampling, pad, &radiance);
  if (options.blur_sigma_px > 0) {
    // Truncated at 4 sigma; the kernel is symmetric and normalized, so it moves no
    // centroid. Border handling only touches the pad.
    const int k = 2 * static_cast<int>(std::ceil(4.0 * options.blur_sigma_px)) + 1;
    cv::GaussianBlur(radiance, radiance, cv::Size(k, k), options.blur_sigma_px, options.blur_sigma_px,
                     cv::BORDER_REPLICATE);
  }

  // Sensor: photon noise, read noise, rounding, clipping; pixels in row-major order.
  const double max_dn = options.MaxDn();
  cv::Mat out(h, w, options.bit_depth == 16 ? CV_16U : CV_8U);
  const double gain = options.gain_e_per_dn, read = options.read_noise_dn;
  for (int v = 0; v < h; ++v) {
    const double* L = radiance.ptr<double>(v + pad) + pad;
    for (int u = 0; u < w; ++u) {
      double s = L[u];
      if (noisy) {
        if (gain > 0) s = noise->Poisson(std::max(s, 0.0) * gain) / gain;
        if (read > 0) s += read * noise->Normal();
      }
      const double q = std::clamp(std::floor(s + 0.5), 0.0, max_dn);
      if (options.bit_depth == 16)
        out.at<uint16_t>(v, u) = static_cast<uint16_t>(q);
      else
        out.at<uint8_t>(v, u) = static_cast<uint8_t>(q);
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------
// Frames

namespace {
uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

}  // namespace

uint64_t StreamSeed(uint64_t seed, uint64_t frame, uint64_t camera, uint64_t stream) {
  return SplitMix64(SplitMix64(SplitMix64(SplitMix64(seed) ^ frame) ^ camera) ^ stream);
}

}  // namespace mcms
