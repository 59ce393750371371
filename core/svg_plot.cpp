#include "core/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "core/io.h"

namespace mcms {

namespace {
std::string Escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '&') o += "&amp;";
    else o += c;
  }
  return o;
}
// Round tick step: 1, 2 or 5 times a power of ten.
double NiceStep(double span) {
  const double raw = span / 6.0;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= raw) return m * p;
  return 10 * p;
}
}  // namespace

void Plot::WriteSvg(const std::filesystem::path& path, int W, int H) const {
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      x0 = std::min(x0, s.x[i]);
      x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, s.y[i]);
      y1 = std::max(y1, s.y[i]);
    }
  if (!(x1 >= x0)) x0 = 0, x1 = 1;
  if (!(y1 >= y0)) y0 = 0, y1 = 1;
  if (y0 > 0 && y0 < 0.5 * y1) y0 = 0;
  if (x1 == x0) x1 = x0 + 1;
  if (y1 == y0) y1 = y0 + 1;
  const double L = 80, R = 20, T = 40, B = 55;
  auto X = [&](double x) { return L + (x - x0) / (x1 - x0) * (W - L - R); };
  auto Y = [&](double y) { return H - B - (y - y0) / (y1 - y0) * (H - T - B); };
  std::ostringstream o;
  char buf[256];
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
    << "' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n";
  o << "<text x='" << W / 2 << "' y='22' text-anchor='middle' font-size='15'>" << Escape(title) << "</text>\n";
  const double xs = NiceStep(x1 - x0), ys = NiceStep(y1 - y0);
  for (double v = std::ceil(x0 / xs) * xs; v <= x1 + 1e-12; v += xs) {
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/><text x='%.1f' y='%.1f' text-anchor='middle'>%g</text>\n",
                  X(v), T, X(v), H - B, X(v), H - B + 16, v);
    o << buf;
  }
  for (double v = std::ceil(y0 / ys) * ys; v <= y1 + 1e-12; v += ys) {
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/><text x='%.1f' y='%.1f' text-anchor='end'>%g</text>\n",
                  L, Y(v), W - R, Y(v), L - 6, Y(v) + 4, v);
    o << buf;
  }
  o << "<rect x='" << L << "' y='" << T << "' width='" << W - L - R << "' height='" << H - T - B
    << "' fill='none' stroke='black'/>\n";
  o << "<text x='" << (L + W - R) / 2 << "' y='" << H - 12 << "' text-anchor='middle'>" << Escape(x_label) << "</text>\n";
  o << "<text transform='translate(18," << (T + H - B) / 2 << ") rotate(-90)' text-anchor='middle'>" << Escape(y_label)
    << "</text>\n";
  int k = 0;
  for (const auto& s : series) {
    if (s.points) {
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
        if (std::isfinite(s.x[i]) && std::isfinite(s.y[i])) {
          std::snprintf(buf, sizeof(buf), "<circle cx='%.1f' cy='%.1f' r='2.5' fill='%s'/>\n", X(s.x[i]), Y(s.y[i]),
                        s.color.c_str());
          o << buf;
        }
    } else {
      o << "<polyline fill='none' stroke='" << s.color << "' stroke-width='1.5' points='";
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
        if (std::isfinite(s.x[i]) && std::isfinite(s.y[i])) {
          std::snprintf(buf, sizeof(buf), "%.1f,%.1f ", X(s.x[i]), Y(s.y[i]));
          o << buf;
        }
      o << "'/>\n";
    }
    std::snprintf(buf, sizeof(buf), "<rect x='%.1f' y='%.1f' width='12' height='12' fill='%s'/><text x='%.1f' y='%.1f'>",
                  L + 10, T + 8 + 18.0 * k, s.color.c_str(), L + 28, T + 18 + 18.0 * k);
    o << buf << Escape(s.label) << "</text>\n";
    ++k;
  }
  o << "</svg>\n";
  const std::string text = o.str();
  WriteFileAtomically(path, [&](std::ostream& out) { out << text; });
}

namespace {
// Viridis, 9 stops, linear in between.
std::string Viridis(double t) {
  static const double stops[9][3] = {{68, 1, 84},    {71, 44, 122},  {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
                                     {39, 173, 129}, {92, 200, 99},  {170, 220, 50}, {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 8.0;
  const int i = std::min(7, static_cast<int>(t));
  const double f = t - i;
  char buf[16];
  std::snprintf(buf, sizeof(buf), "#%02x%02x%02x", static_cast<int>(std::lround(stops[i][0] + f * (stops[i + 1][0] - stops[i][0]))),
                static_cast<int>(std::lround(stops[i][1] + f * (stops[i + 1][1] - stops[i][1]))),
                static_cast<int>(std::lround(stops[i][2] + f * (stops[i + 1][2] - stops[i][2]))));
  return buf;
}
}  // namespace

void HeatMap::WriteSvg(const std::filesystem::path& path, int W, int H) const {
  const size_t nx = x.size(), ny = y.size();
  if (nx == 0 || ny == 0 || values.size() != nx * ny)
    throw std::invalid_argument("HeatMap: values must hold x.size() * y.size() entries");
  auto usable = [&](double v) { return std::isfinite(v) && (!log_scale || v > 0); };
  double lo = INFINITY, hi = -INFINITY;
  for (double v : values)
    if (usable(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  if (vmin) lo = *vmin;
  if (vmax) hi = *vmax;
  if (!(hi >= lo)) lo = log_scale ? 1 : 0, hi = lo + 1;
  if (log_scale && !(lo > 0)) lo = hi > 0 ? hi * 1e-3 : 1;
  if (hi == lo) hi = log_scale ? lo * 10 : lo + 1;
  auto T = [&](double v) { return log_scale ? std::log10(v / lo) / std::log10(hi / lo) : (v - lo) / (hi - lo); };
  // Cell edges: half-way between centres, extended by half a step at the ends.
  auto edges = [](const std::vector<double>& c) {
    std::vector<double> e(c.size() + 1);
    const double step = c.size() > 1 ? c[1] - c[0] : 1.0;
    e.front() = c.front() - 0.5 * (c.size() > 1 ? c[1] - c[0] : step);
    for (size_t i = 1; i < c.size(); ++i) e[i] = 0.5 * (c[i - 1] + c[i]);
    e.back() = c.back() + 0.5 * (c.size() > 1 ? c[c.size() - 1] - c[c.size() - 2] : step);
    return e;
  };
  const std::vector<double> ex = edges(x), ey = edges(y);
  const double L = 80, R = 150, Tm = 40, B = 55;
  // Equal scale on both axes when the plot area allows it.
  double pw = W - L - R, ph = H - Tm - B;
  const double sx = pw / (ex.back() - ex.front()), sy = ph / (ey.back() - ey.front());
  const double s = std::min(sx, sy);
  pw = s * (ex.back() - ex.front());
  ph = s * (ey.back() - ey.front());
  auto X = [&](double v) { return L + (v - ex.front()) * s; };
  auto Y = [&](double v) { return Tm + ph - (v - ey.front()) * s; };
  std::ostringstream o;
  char buf[320];
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
    << "' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n";
  o << "<text x='" << W / 2 << "' y='22' text-anchor='middle' font-size='15'>" << Escape(title) << "</text>\n";
  for (size_t iy = 0; iy < ny; ++iy)
    for (size_t ix = 0; ix < nx; ++ix) {
      const double v = values[iy * nx + ix];
      const std::string fill = usable(v) ? Viridis(T(v)) : std::string("#c8c8c8");
      std::snprintf(buf, sizeof(buf), "<rect x='%.2f' y='%.2f' width='%.2f' height='%.2f' fill='%s'/>\n", X(ex[ix]),
                    Y(ey[iy + 1]), X(ex[ix + 1]) - X(ex[ix]), Y(ey[iy]) - Y(ey[iy + 1]), fill.c_str());
      o << buf;
    }
  if (threshold)
    for (size_t iy = 0; iy < ny; ++iy)
      for (size_t ix = 0; ix < nx; ++ix) {
        const double v = values[iy * nx + ix];
        if (!(std::isfinite(v) && v < *threshold)) continue;
        std::snprintf(buf, sizeof(buf),
                      "<rect x='%.2f' y='%.2f' width='%.2f' height='%.2f' fill='none' stroke='#d62728' stroke-width='1.2'/>\n",
                      X(ex[ix]) + 1, Y(ey[iy + 1]) + 1, X(ex[ix + 1]) - X(ex[ix]) - 2, Y(ey[iy]) - Y(ey[iy + 1]) - 2);
        o << buf;
      }
  o << "<rect x='" << L << "' y='" << Tm << "' width='" << pw << "' height='" << ph << "' fill='none' stroke='black'/>\n";
  const double xs = NiceStep(ex.back() - ex.front()), ys = NiceStep(ey.back() - ey.front());
  for (double v = std::ceil(ex.front() / xs) * xs; v <= ex.back() + 1e-12; v += xs) {
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='black'/><text x='%.1f' y='%.1f' text-anchor='middle'>%g</text>\n",
                  X(v), Tm + ph, X(v), Tm + ph + 5, X(v), Tm + ph + 18, std::abs(v) < 1e-12 ? 0.0 : v);
    o << buf;
  }
  for (double v = std::ceil(ey.front() / ys) * ys; v <= ey.back() + 1e-12; v += ys) {
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='black'/><text x='%.1f' y='%.1f' text-anchor='end'>%g</text>\n",
                  L - 5, Y(v), L, Y(v), L - 8, Y(v) + 4, std::abs(v) < 1e-12 ? 0.0 : v);
    o << buf;
  }
  o << "<text x='" << L + pw / 2 << "' y='" << Tm + ph + 40 << "' text-anchor='middle'>" << Escape(x_label) << "</text>\n";
  o << "<text transform='translate(18," << Tm + ph / 2 << ") rotate(-90)' text-anchor='middle'>" << Escape(y_label)
    << "</text>\n";
  // Colour bar.
  const double bx = L + pw + 30, bw = 18, bh = std::max(120.0, ph);
  const int steps = 64;
  for (int i = 0; i < steps; ++i) {
    std::snprintf(buf, sizeof(buf), "<rect x='%.1f' y='%.2f' width='%.1f' height='%.2f' fill='%s'/>\n", bx,
                  Tm + bh - (i + 1) * bh / steps, bw, bh / steps + 0.3, Viridis((i + 0.5) / steps).c_str());
    o << buf;
  }
  o << "<rect x='" << bx << "' y='" << Tm << "' width='" << bw << "' height='" << bh << "' fill='none' stroke='black'/>\n";
  std::vector<double> ticks;
  if (log_scale) {
    for (double d = std::pow(10.0, std::floor(std::log10(lo))); d <= hi * 1.0001; d *= 10)
      for (double m : {1.0, 2.0, 5.0})
        if (m * d >= lo * 0.9999 && m * d <= hi * 1.0001) ticks.push_back(m * d);
  } else {
    const double st = NiceStep(hi - lo);
    for (double v = std::ceil(lo / st) * st; v <= hi + 1e-12; v += st) ticks.push_back(v);
  }
  for (double v : ticks) {
    const double yy = Tm + bh - T(v) * bh;
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='black'/><text x='%.1f' y='%.1f'>%g</text>\n",
                  bx + bw, yy, bx + bw + 4, yy, bx + bw + 7, yy + 4, v);
    o << buf;
  }
  o << "<text transform='translate(" << bx + bw + 60 << "," << Tm + bh / 2 << ") rotate(-90)' text-anchor='middle'>"
    << Escape(value_label) << "</text>\n";
  double ly = Tm + bh + 20;
  o << "<rect x='" << bx << "' y='" << ly - 10 << "' width='12' height='12' fill='#c8c8c8'/><text x='" << bx + 16 << "' y='" << ly
    << "'>no value</text>\n";
  if (threshold) {
    ly += 18;
    std::snprintf(buf, sizeof(buf), "<rect x='%.1f' y='%.1f' width='12' height='12' fill='none' stroke='#d62728'/><text x='%.1f' y='%.1f'>&lt; %g</text>\n",
                  bx, ly - 10, bx + 16, ly, *threshold);
    o << buf;
  }
  o << "</svg>\n";
  const std::string text = o.str();
  WriteFileAtomically(path, [&](std::ostream& out) { out << text; });
}

}  // namespace mcms
