#include "core/random.h"

#include <cmath>

namespace mcms {

double Rng::Normal() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  double u, v, s;
  do {
    u = 2.0 * Uniform() - 1.0;
    v = 2.0 * Uniform() - 1.0;
    s = u * u + v * v;
  } while (s >= 1.0 || s == 0.0);
  const double f = std::sqrt(-2.0 * std::log(s) / s);
  spare_ = v * f;
  has_spare_ = true;
  return u * f;
}

double Rng::Poisson(double lambda) {
  if (!(lambda > 0.0)) return 0.0;
  if (lambda < 30.0) {
    const double limit = std::exp(-lambda);
    double p = Uniform();
    int k = 0;
    while (p > limit) {
      p *= Uniform();
      ++k;
    }
    return k;
  }
  const double x = std::round(lambda + std::sqrt(lambda) * Normal());
  return x < 0.0 ? 0.0 : x;
}

}  // namespace mcms
