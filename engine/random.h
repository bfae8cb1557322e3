// Seeded random numbers with saveable state (for resumable training).
#pragma once
#include <cstdint>
#include <random>
#include <string>

namespace cvd {

class Generator {
 public:
  explicit Generator(uint64_t seed = 0) : eng_(seed) {}
  void seed(uint64_t s) { eng_.seed(s); }
  uint64_t next_u64() { return eng_(); }
  double uniform() { return std::uniform_real_distribution<double>(0.0, 1.0)(eng_); }
  double normal() { return std::normal_distribution<double>(0.0, 1.0)(eng_); }
  int64_t randint(int64_t lo, int64_t hi) {  // [lo, hi)
    return std::uniform_int_distribution<int64_t>(lo, hi - 1)(eng_);
  }
  std::mt19937_64& engine() { return eng_; }
  std::string state() const;             // textual engine state
  void set_state(const std::string& s);  // throws Error(format) on a malformed state

 private:
  std::mt19937_64 eng_;
};

}  // namespace cvd
