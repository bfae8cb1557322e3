// Wall time per call of a piece of work on a device, for the plain-main benchmarks
// (bench_cuda_ops, bench_op_table): `warmup` calls, then calls until `min_seconds` have passed (at
// least three), with `sync` (e.g. a device-to-host copy) before each clock read.
#pragma once
#include <chrono>
#include <functional>

namespace cvd::bench {

inline double seconds_per_call(const std::function<void()>& once, const std::function<void()>& sync,
                               double min_seconds, int warmup) {
  for (int w = 0; w < warmup; ++w) once();
  sync();
  int iters = 0;
  const auto t0 = std::chrono::steady_clock::now();
  double elapsed = 0;
  while (iters < 3 || elapsed < min_seconds) {
    once();
    ++iters;
    sync();
    elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return elapsed / iters;
}

}  // namespace cvd::bench
