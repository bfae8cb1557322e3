// SceneRandom: the seeded random numbers of the synthetic scene. Built on SplitMix64 with our own
// integer-to-float mappings, so the same seed gives the same scene on every platform and standard
// library (std::*_distribution results are implementation-defined).
#pragma once
#include <cstdint>

namespace cvd {

class SceneRandom {
 public:
  explicit SceneRandom(uint64_t seed) : state_(seed) {}
  uint64_t next_u64() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double uniform() { return double(next_u64() >> 11) * 0x1.0p-53; }
  // Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [lo, hi] (inclusive); requires lo <= hi.
  int integer(int lo, int hi) { return lo + int(next_u64() % uint64_t(hi - lo + 1)); }
  // An independent stream derived from this one (for per-texture / per-object randomness).
  SceneRandom fork() { return SceneRandom(next_u64()); }

 private:
  uint64_t state_;
};

}  // namespace cvd
