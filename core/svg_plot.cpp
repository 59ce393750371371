#include "core/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "core/error.h"
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

namespace {
// A tick value as text: values within rounding of zero print as 0, never 1e-17.
std::string TickLabel(double v, double step) {
  if (std::abs(v) < 1e-9 * std::abs(step)) v = 0.0;
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}
// Ticks of a logarithmic axis over [lo, hi] (lo > 0): 1, 2, 5 times the powers of ten
// when the range spans few decades, the powers of ten alone when it spans many.
std::vector<double> LogTicks(double lo, double hi) {
  std::vector<double> t;
  const double decades = std::log10(hi / lo);
  const std::vector<double> mult = decades > 4 ? std::vector<double>{1.0} : std::vector<double>{1.0, 2.0, 5.0};
  for (double d = std::pow(10.0, std::floor(std::log10(lo))); d <= hi * 1.0001; d *= 10)
    for (double m : mult)
      if (m * d >= lo * 0.9999 && m * d <= hi * 1.0001) t.push_back(m * d);
  return t;
}
}  // namespace

namespace {

// One legend entry: the series' marker (a dot or a line) and its label at (x, y).
struct Entry {
  double x, y;
  const PlotSeries* s;
};
std::string LegendEntrySvg(double x, double y, const PlotSeries& s) {
  char buf[320];
  std::string o;
  if (s.points)
    std::snprintf(buf, sizeof(buf), "<circle cx='%.1f' cy='%.1f' r='4' fill='%s'/>", x + 14, y - 4, s.color.c_str());
  else
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='%s' stroke-width='2'/>", x + 2,
                  y - 4, x + 26, y - 4, s.color.c_str());
  o += buf;
  std::snprintf(buf, sizeof(buf), "<text x='%.1f' y='%.1f'>", x + 32, y);
  return o + buf + Escape(s.label) + "</text>\n";
}

}  // namespace

std::string Plot::ToSvg(int W, int H) const {
  auto usable_y = [&](double v) { return std::isfinite(v) && (!log_y || v > 0); };
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  auto extend_y = [&](double v) {
    if (!usable_y(v)) return;
    y0 = std::min(y0, v);
    y1 = std::max(y1, v);
  };
  auto has_vector = [](const PlotSeries& s, size_t i) {
    return i < s.dx.size() && i < s.dy.size() && std::isfinite(s.dx[i]) && std::isfinite(s.dy[i]);
  };
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i])) continue;
      const bool band = i < s.y_low.size() && i < s.y_high.size();
      if (!usable_y(s.y[i]) && !band) continue;
      x0 = std::min(x0, s.x[i]);
      x1 = std::max(x1, s.x[i]);
      extend_y(s.y[i]);
      if (band) extend_y(s.y_low[i]), extend_y(s.y_high[i]);
      if (has_vector(s, i) && usable_y(s.y[i])) {
        const double tx = s.x[i] + s.vector_scale * s.dx[i];
        x0 = std::min(x0, tx), x1 = std::max(x1, tx);
        extend_y(s.y[i] + s.vector_scale * s.dy[i]);
      }
    }
  if (x_range) x0 = x_range->first, x1 = x_range->second;
  if (y_range) y0 = y_range->first, y1 = y_range->second;
  const bool fixed_y = y_range.has_value();
  if (!(x1 >= x0)) x0 = 0, x1 = 1;
  if (!(y1 >= y0)) y0 = log_y ? 1 : 0, y1 = log_y ? 10 : 1;
  if (log_y) {
    // Whole decades (or 1-2-5 steps) at both ends, so the extremes carry a label.
    const std::vector<double> nice = {1, 2, 5, 10};
    const double d0 = std::pow(10.0, std::floor(std::log10(y0)));
    double lo = d0;
    for (double m : nice)
      if (m * d0 <= y0 * 1.0000001) lo = m * d0;
    const double d1 = std::pow(10.0, std::floor(std::log10(y1)));
    double hi = 10 * d1;
    for (double m : {10.0, 5.0, 2.0, 1.0})
      if (m * d1 >= y1 * 0.9999999) hi = m * d1;
    y0 = lo, y1 = hi;
    if (y1 <= y0) y1 = 10 * y0;
  } else if (!fixed_y) {
    // A constant is drawn in the middle of the axis, not on its frame.
    if (y1 == y0) y0 -= 1, y1 += 1;
    if (y0 > 0 && y0 < 0.5 * y1) y0 = 0;
    // A margin of 4 % above and below, so no marker sits on the frame.
    const double m = 0.04 * (y1 - y0);
    y1 += m;
    if (y0 != 0) y0 -= m;
  }
  if (y1 <= y0) y1 = y0 + 1;
  if (x1 <= x0) x0 -= 0.5, x1 += 0.5;
  if (!x_range) {
    // A margin of 2 % left and right, so no marker sits on the frame.
    const double xm = 0.02 * (x1 - x0);
    x0 -= xm, x1 += xm;
  }
  // The legend gets its own band under the title: rows of entries, wrapped to the width.
  const double L = 80, R = 24, B = 55;
  std::vector<Entry> entries;
  double lx = L, ly = 44;
  for (const auto& s : series) {
    if (s.label.empty()) continue;
    const double w = 34 + 6.8 * static_cast<double>(s.label.size()) + 18;
    if (lx > L && lx + w > W - R) lx = L, ly += 18;
    entries.push_back({lx, ly, &s});
    lx += w;
  }
  const double T = entries.empty() ? 40 : ly + 16;
  // The plot area [AL, AR] x [AT, AB] in SVG pixels; with equal_scale one unit is as long
  // on both axes and the area shrinks along one of them.
  double AL = L, AR = W - R, AT = T, AB = H - B;
  if (equal_scale && !log_y) {
    const double k = std::min((AR - AL) / (x1 - x0), (AB - AT) / (y1 - y0));
    AR = AL + k * (x1 - x0);
    AB = AT + k * (y1 - y0);
  }
  auto X = [&](double x) { return AL + (x - x0) / (x1 - x0) * (AR - AL); };
  auto F = [&](double y) { return log_y ? std::log10(y / y0) / std::log10(y1 / y0) : (y - y0) / (y1 - y0); };
  auto Y = [&](double y) { return y_down ? AT + F(y) * (AB - AT) : AB - F(y) * (AB - AT); };
  std::ostringstream o;
  char buf[320];
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H << "' viewBox='0 0 " << W << " " << H
    << "' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n";
  o << "<text x='" << W / 2 << "' y='22' text-anchor='middle' font-size='15'>" << Escape(title) << "</text>\n";
  const double xs = NiceStep(x1 - x0);
  for (double v = std::ceil(x0 / xs - 1e-9) * xs; v <= x1 + 1e-9 * xs; v += xs) {
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/><text x='%.1f' y='%.1f' text-anchor='middle'>%s</text>\n",
                  X(v), AT, X(v), AB, X(v), AB + 16, TickLabel(v, xs).c_str());
    o << buf;
  }
  std::vector<double> yticks;
  double ys = 1;
  if (log_y) {
    yticks = LogTicks(y0, y1);
  } else {
    ys = NiceStep(y1 - y0);
    for (double v = std::ceil(y0 / ys - 1e-9) * ys; v <= y1 + 1e-9 * ys; v += ys) yticks.push_back(v);
  }
  for (double v : yticks) {
    std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/><text x='%.1f' y='%.1f' text-anchor='end'>%s</text>\n",
                  AL, Y(v), AR, Y(v), AL - 6, Y(v) + 4, TickLabel(v, log_y ? v : ys).c_str());
    o << buf;
  }
  o << "<rect x='" << AL << "' y='" << AT << "' width='" << AR - AL << "' height='" << AB - AT
    << "' fill='none' stroke='black'/>\n";
  o << "<text x='" << (AL + AR) / 2 << "' y='" << AB + 43 << "' text-anchor='middle'>" << Escape(x_label) << "</text>\n";
  o << "<text transform='translate(18," << (AT + AB) / 2 << ") rotate(-90)' text-anchor='middle'>"
    << Escape(y_label + (log_y ? " (log scale)" : "")) << "</text>\n";
  // Data, clipped to the plot area and a marker's radius around it (the ranges cover
  // every value, so the clip only guards against rounding).
  std::snprintf(buf, sizeof(buf), "<clipPath id='plotarea'><rect x='%.1f' y='%.1f' width='%.1f' height='%.1f'/></clipPath>\n<g clip-path='url(#plotarea)'>\n",
                AL - 4, AT - 4, AR - AL + 8, AB - AT + 8);
  o << buf;
  for (const auto& s : series) {
    // Band first, under the data.
    std::string upper, lower;
    for (size_t i = 0; i < s.x.size() && i < s.y_low.size() && i < s.y_high.size(); ++i)
      if (std::isfinite(s.x[i]) && usable_y(s.y_low[i]) && usable_y(s.y_high[i])) {
        std::snprintf(buf, sizeof(buf), "%.1f,%.1f ", X(s.x[i]), Y(s.y_high[i]));
        upper += buf;
        std::snprintf(buf, sizeof(buf), "%.1f,%.1f ", X(s.x[i]), Y(s.y_low[i]));
        lower = buf + lower;
      }
    if (!upper.empty())
      o << "<polygon fill='" << s.color << "' fill-opacity='0.18' stroke='none' points='" << upper << lower << "'/>\n";
  }
  for (const auto& s : series) {
    // Vectors: a segment from each point with an open arrow head at its tip.
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!has_vector(s, i) || !std::isfinite(s.x[i]) || !usable_y(s.y[i])) continue;
      const double ty = s.y[i] + s.vector_scale * s.dy[i];
      if (!usable_y(ty)) continue;
      const double ax = X(s.x[i]), ay = Y(s.y[i]), bx = X(s.x[i] + s.vector_scale * s.dx[i]), by = Y(ty);
      const double len = std::hypot(bx - ax, by - ay);
      std::snprintf(buf, sizeof(buf), "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='%s' stroke-width='1'/>\n", ax, ay, bx,
                    by, s.color.c_str());
      o << buf;
      if (len > 3) {
        const double ux = (bx - ax) / len, uy = (by - ay) / len, h = std::min(5.0, 0.4 * len);
        std::snprintf(buf, sizeof(buf), "<polyline fill='none' stroke='%s' stroke-width='1' points='%.1f,%.1f %.1f,%.1f %.1f,%.1f'/>\n",
                      s.color.c_str(), bx - h * (ux - 0.5 * uy), by - h * (uy + 0.5 * ux), bx, by, bx - h * (ux + 0.5 * uy),
                      by - h * (uy - 0.5 * ux));
        o << buf;
      }
    }
    if (s.points) {
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
        if (std::isfinite(s.x[i]) && usable_y(s.y[i])) {
          std::snprintf(buf, sizeof(buf), "<circle cx='%.1f' cy='%.1f' r='2.5' fill='%s'/>\n", X(s.x[i]), Y(s.y[i]),
                        s.color.c_str());
          o << buf;
        }
    } else if (s.dx.empty()) {  // a vector series is its arrows: no line through their bases
      // A gap (non-finite value) breaks the line; a value alone between gaps is a dot.
      std::string pts;
      size_t count = 0;
      double last_x = 0, last_y = 0;
      auto flush = [&] {
        if (count == 1) {
          std::snprintf(buf, sizeof(buf), "<circle cx='%.1f' cy='%.1f' r='1.5' fill='%s'/>\n", last_x, last_y, s.color.c_str());
          o << buf;
        } else if (count > 1) {
          o << "<polyline fill='none' stroke='" << s.color << "' stroke-width='1.5' points='" << pts << "'/>\n";
        }
        pts.clear();
        count = 0;
      };
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
        if (!(std::isfinite(s.x[i]) && usable_y(s.y[i]))) {
          flush();
          continue;
        }
        last_x = X(s.x[i]), last_y = Y(s.y[i]);
        std::snprintf(buf, sizeof(buf), "%.1f,%.1f ", last_x, last_y);
        pts += buf;
        ++count;
      }
      flush();
    }
  }
  o << "</g>\n";
  for (const auto& e : entries) o << LegendEntrySvg(e.x, e.y, *e.s);
  o << "</svg>\n";
  return o.str();
}

void Plot::WriteSvg(const std::filesystem::path& path, int W, int H) const {
  const std::string text = ToSvg(W, H);
  WriteFileAtomically(path, [&](std::ostream& out) { out << text; });
}

std::string PlotGridSvg(const std::vector<Plot>& plots, int columns, int cell_w, int cell_h) {
  MCMS_CHECK(!plots.empty() && columns >= 1 && cell_w >= 100 && cell_h >= 100, "PlotGridSvg: expected at least one plot, columns >= 1 and cells of >= 100 px");
  const int n = static_cast<int>(plots.size());
  const int cols = std::min(columns, n), rows = (n + cols - 1) / cols;
  std::ostringstream o;
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << cols * cell_w << "' height='" << rows * cell_h
    << "' font-family='sans-serif' font-size='12'>\n";
  for (int i = 0; i < n; ++i) {
    // Each plot is its own nested <svg> placed at its cell (nested viewports are plain SVG).
    std::string cell = plots[i].ToSvg(cell_w, cell_h);
    const std::string head = "<svg xmlns='http://www.w3.org/2000/svg'";
    MCMS_CHECK(cell.compare(0, head.size(), head) == 0, "PlotGridSvg: unexpected plot document");
    cell.replace(0, head.size(), "<svg x='" + std::to_string((i % cols) * cell_w) + "' y='" +
                                     std::to_string((i / cols) * cell_h) + "'");
    o << cell;
  }
  o << "</svg>\n";
  return o.str();
}

void WritePlotGridSvg(const std::filesystem::path& path, const std::vector<Plot>& plots, int columns, int cell_w,
                      int cell_h) {
  const std::string text = PlotGridSvg(plots, columns, cell_w, cell_h);
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

std::string HeatMap::ToSvg(int W, int H) const {
  const size_t nx = x.size(), ny = y.size();
  MCMS_CHECK(nx > 0 && ny > 0 && values.size() == nx * ny, "HeatMap: values must hold x.size() * y.size() entries");
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
  return o.str();
}

void HeatMap::WriteSvg(const std::filesystem::path& path, int W, int H) const {
  const std::string text = ToSvg(W, H);
  WriteFileAtomically(path, [&](std::ostream& out) { out << text; });
}

}  // namespace mcms
