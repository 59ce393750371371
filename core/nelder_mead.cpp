#include "core/nelder_mead.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace mcms {

std::vector<double> NelderMead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                               double step, int max_iter, double* fbest) {
  const size_t n = x0.size();
  if (n == 0) {
    *fbest = f(x0);
    return x0;
  }
  std::vector<std::vector<double>> s(n + 1, x0);
  for (size_t i = 0; i < n; ++i) s[i + 1][i] += step;
  std::vector<double> fs(n + 1);
  for (size_t i = 0; i <= n; ++i) fs[i] = f(s[i]);
  for (int it = 0; it < max_iter; ++it) {
    std::vector<size_t> idx(n + 1);
    std::iota(idx.begin(), idx.end(), 0);
    std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return fs[a] < fs[b]; });
    std::vector<std::vector<double>> s2(n + 1);
    std::vector<double> f2(n + 1);
    for (size_t i = 0; i <= n; ++i) s2[i] = s[idx[i]], f2[i] = fs[idx[i]];
    s.swap(s2);
    fs.swap(f2);
    if (std::abs(fs[n] - fs[0]) < 1e-10 * (1 + std::abs(fs[0]))) {
      double spread = 0;
      for (size_t i = 1; i <= n; ++i)
        for (size_t j = 0; j < n; ++j) spread = std::max(spread, std::abs(s[i][j] - s[0][j]));
      if (spread < 1e-7) break;
    }
    std::vector<double> c(n, 0.0);
    for (size_t i = 0; i < n; ++i)
      for (size_t j = 0; j < n; ++j) c[j] += s[i][j] / n;
    auto along = [&](double t) {
      std::vector<double> x(n);
      for (size_t j = 0; j < n; ++j) x[j] = c[j] + t * (s[n][j] - c[j]);
      return x;
    };
    const std::vector<double> xr = along(-1.0);
    const double fr = f(xr);
    if (fr < fs[0]) {
      const std::vector<double> xe = along(-2.0);
      const double fe = f(xe);
      if (fe < fr) s[n] = xe, fs[n] = fe;
      else s[n] = xr, fs[n] = fr;
    } else if (fr < fs[n - 1]) {
      s[n] = xr, fs[n] = fr;
    } else {
      const bool outside = fr < fs[n];
      const std::vector<double> xc = along(outside ? -0.5 : 0.5);
      const double fc = f(xc);
      if (fc < std::min(fr, fs[n])) {
        s[n] = xc, fs[n] = fc;
      } else {
        for (size_t i = 1; i <= n; ++i) {
          for (size_t j = 0; j < n; ++j) s[i][j] = s[0][j] + 0.5 * (s[i][j] - s[0][j]);
          fs[i] = f(s[i]);
        }
      }
    }
  }
  size_t best = 0;
  for (size_t i = 1; i <= n; ++i)
    if (fs[i] < fs[best]) best = i;
  *fbest = fs[best];
  return s[best];
}

}  // namespace mcms
