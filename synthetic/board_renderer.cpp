#include "synthetic/board_renderer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/error.h"

namespace mcms {

bool BoardRenderOptions::IsValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  auto level = [](double v) { return std::isfinite(v) && v >= 0.0 && v <= 255.0; };
  if (!level(dark_dn)) return fail("dark_dn must be in [0, 255]");
  if (!level(light_dn)) return fail("light_dn must be in [0, 255]");
  if (!level(background_dn)) return fail("background_dn must be in [0, 255]");
  if (!(std::isfinite(blur_sigma_px) && blur_sigma_px >= 0.0 && blur_sigma_px <= 20.0))
    return fail("blur_sigma_px must be in [0, 20] px");
  if (!(std::isfinite(read_noise_dn) && read_noise_dn >= 0.0)) return fail("read_noise_dn must be a number >= 0");
  if (supersampling < 1 || supersampling > 64) return fail("supersampling must be in [1, 64]");
  return true;
}

int BoardRenderPadPx(const BoardRenderOptions& options) {
  return static_cast<int>(std::ceil(4.0 * options.blur_sigma_px)) + 2;
}

namespace {

// The scene as a function of the board-plane point: the unit cell (a, b) of the
// square grid it falls in, or "miss" when the ray does not reach the plane.
struct Cell {
  int32_t a = 0, b = 0;
  bool hit = false;
  bool operator==(const Cell& o) const { return hit == o.hit && (!hit || (a == o.a && b == o.b)); }
};

class BoardScene {
 public:
  BoardScene(const CalibrationBoard& board, const Pose& T_cam_board, const BoardRenderOptions& o)
      : inv_s_(1.0 / board.square_m), cols_(board.cols), rows_(board.rows), opt_(o) {
    const Pose T_board_cam = T_cam_board.Inverse();
    Rt_ = T_board_cam.R;
    origin_ = T_board_cam.t;  // the camera centre in the board frame
  }

  // The cell seen along the camera ray (x, y, 1).
  Cell Trace(double x, double y) const {
    Cell c;
    const Vec3 d = Rt_ * Vec3(x, y, 1.0);
    if (d.z() == 0.0) return c;
    const double s = -origin_.z() / d.z();
    if (!(s > 0.0) || !std::isfinite(s)) return c;
    // Far-off intersections (grazing rays) are clamped: they are background anyway.
    constexpr double kFar = 1e6;
    const double X = std::clamp((origin_.x() + s * d.x()) * inv_s_, -kFar, kFar);
    const double Y = std::clamp((origin_.y() + s * d.y()) * inv_s_, -kFar, kFar);
    c.a = static_cast<int32_t>(std::floor(X));
    c.b = static_cast<int32_t>(std::floor(Y));
    c.hit = true;
    return c;
  }

  double Shade(const Cell& c) const {
    if (!c.hit) return opt_.background_dn;
    // Pattern squares a = -1..cols-1, b = -1..rows-1; the margin one square beyond.
    if (c.a >= -1 && c.a <= cols_ - 1 && c.b >= -1 && c.b <= rows_ - 1)
      return ((c.a + c.b) % 2 == 0) ? opt_.dark_dn : opt_.light_dn;
    if (c.a >= -2 && c.a <= cols_ && c.b >= -2 && c.b <= rows_) return opt_.light_dn;
    return opt_.background_dn;
  }

 private:
  double inv_s_;
  int cols_, rows_;
  const BoardRenderOptions& opt_;
  Mat3 Rt_;
  Vec3 origin_;
};

}  // namespace

cv::Mat RenderBoard(const RayTable& table, const CalibrationBoard& board, const Pose& T_cam_board,
                    const BoardRenderOptions& options, Rng* noise) {
  std::string why;
  if (!options.IsValid(&why)) Throw("RenderBoard options: ", why);
  if (board.type != CalibrationBoard::Type::kChessboard)
    Throw("RenderBoard board: only chessboards can be rendered (got ", board.Describe(), ")");
  if (!board.IsValid(&why)) Throw("RenderBoard board: ", why);
  if (!(T_cam_board.R.allFinite() && T_cam_board.t.allFinite()))
    Throw("RenderBoard T_cam_board: expected a finite pose");
  const CameraModel& cam = table.Camera();
  const int w = cam.Width(), h = cam.Height(), pad = BoardRenderPadPx(options);
  if (table.PadPx() < pad)
    Throw("RenderBoard table: its pad (", table.PadPx(), " px) is smaller than the blur needs (", pad, " px)");
  const bool noisy = options.read_noise_dn > 0.0;
  if (noisy && !noise) Throw("RenderBoard noise: read noise needs a random stream");

  const BoardScene scene(board, T_cam_board, options);
  const int cw = w + 2 * pad, ch = h + 2 * pad;

  // Cells at the pixel corners: node (i, j) is image point (i - pad - 0.5, j - pad - 0.5).
  const int nw = cw + 1;
  std::vector<Cell> nodes(static_cast<size_t>(nw) * (ch + 1));
  for (int j = 0; j <= ch; ++j)
    for (int i = 0; i <= cw; ++i) {
      double x, y;
      if (table.Normalized(i - pad - 0.5, j - pad - 0.5, &x, &y)) nodes[static_cast<size_t>(j) * nw + i] = scene.Trace(x, y);
    }

  cv::Mat radiance(ch, cw, CV_64F);
  const int n = options.supersampling;
  const double inv_n = 1.0 / n;
  for (int j = 0; j < ch; ++j) {
    double* L = radiance.ptr<double>(j);
    const Cell* top = &nodes[static_cast<size_t>(j) * nw];
    const Cell* bottom = top + nw;
    for (int i = 0; i < cw; ++i) {
      const Cell& c = top[i];
      if (c == top[i + 1] && c == bottom[i] && c == bottom[i + 1]) {
        L[i] = scene.Shade(c);
        continue;
      }
      // An edge crosses the pixel: average N x N regular sub-samples.
      const double u = i - pad, v = j - pad;
      double sum = 0.0;
      for (int sj = 0; sj < n; ++sj) {
        const double sv = v - 0.5 + (sj + 0.5) * inv_n;
        for (int si = 0; si < n; ++si) {
          const double su = u - 0.5 + (si + 0.5) * inv_n;
          double x, y;
          sum += table.Normalized(su, sv, &x, &y) ? scene.Shade(scene.Trace(x, y)) : options.background_dn;
        }
      }
      L[i] = sum * inv_n * inv_n;
    }
  }

  if (options.blur_sigma_px > 0) {
    // Truncated at 4 sigma; border handling only touches the pad.
    const int k = 2 * static_cast<int>(std::ceil(4.0 * options.blur_sigma_px)) + 1;
    cv::GaussianBlur(radiance, radiance, cv::Size(k, k), options.blur_sigma_px, options.blur_sigma_px,
                     cv::BORDER_REPLICATE);
  }

  // Sensor: read noise, rounding, clipping; pixels in row-major order.
  cv::Mat out(h, w, CV_8U);
  for (int v = 0; v < h; ++v) {
    const double* L = radiance.ptr<double>(v + pad) + pad;
    uint8_t* o = out.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      double s = L[u];
      if (noisy) s += options.read_noise_dn * noise->Normal();
      o[u] = static_cast<uint8_t>(std::clamp(std::floor(s + 0.5), 0.0, 255.0));
    }
  }
  return out;
}

}  // namespace mcms
