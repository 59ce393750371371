// The project's only source of randomness. std::normal_distribution and
// std::poisson_distribution are implementation-defined, so a seeded scenario could
// render differently under another standard library; these samplers are ours and
// give the same sequence everywhere for the same seed.
#pragma once

#include <cstdint>
#include <random>

namespace mcms {

class Rng {
 public:
  explicit Rng(uint64_t seed) : engine_(seed) {}

  // Uniform in [0, 1), 53 random bits.
  double Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Standard normal by the Marsaglia polar method (caches the second variate).
  double Normal();
  double Normal(double mean, double sigma) { return mean + sigma * Normal(); }
  // Poisson with mean lambda >= 0: exact (Knuth) below 30, a normal approximation
  // (rounded, clamped at 0) above, where its error is far below the read noise.
  double Poisson(double lambda);
  uint64_t Bits() { return engine_(); }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace mcms
