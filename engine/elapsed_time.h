// Wall time since a point on the steady clock, in seconds (the stages' and tools' timings).
#pragma once
#include <chrono>

namespace cvd {

inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace cvd
