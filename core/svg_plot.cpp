#include "core/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

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

}  // namespace mcms
