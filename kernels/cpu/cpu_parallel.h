// Thread-parallel loops of the OpenMP CPU kernels: static partitions of an index range, run on
// the calling thread when the work is too small to pay for a parallel region.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cstdint>

namespace cvd::cpu {

// Work (in element operations) below which a loop runs on the calling thread.
inline constexpr int64_t kParallelGrain = 32768;

inline int max_threads() { return omp_in_parallel() ? 1 : omp_get_max_threads(); }

// Number of threads worth using for `n` items of `cost` element operations each.
inline int threads_for(int64_t n, int64_t cost) {
  const int64_t work = n * std::max<int64_t>(cost, 1);
  const int64_t by_work = std::max<int64_t>(1, work / kParallelGrain);
  return static_cast<int>(std::min<int64_t>({max_threads(), by_work, std::max<int64_t>(n, 1)}));
}

// Calls fn(begin, end) on disjoint contiguous ranges that cover [0, n), at most one range per
// thread. `cost` is the work of one item in element operations. fn must not throw.
template <class F>
void parallel_ranges(int64_t n, int64_t cost, F&& fn) {
  if (n <= 0) return;
  const int nt = threads_for(n, cost);
  if (nt <= 1) {
    fn(int64_t{0}, n);
    return;
  }
#pragma omp parallel for num_threads(nt) schedule(static, 1)
  for (int t = 0; t < nt; ++t) {
    const int64_t begin = n * t / nt, end = n * (t + 1) / nt;
    if (begin < end) fn(begin, end);
  }
}

// Calls fn(thread_index, begin, end) like parallel_ranges, and returns the number of ranges
// (thread indices run over [0, returned)), for loops that keep per-thread partial results.
template <class F>
int parallel_ranges_indexed(int64_t n, int64_t cost, int max_ranges, F&& fn) {
  if (n <= 0) return 0;
  const int nt = std::min(threads_for(n, cost), std::max(max_ranges, 1));
  if (nt <= 1) {
    fn(0, int64_t{0}, n);
    return 1;
  }
#pragma omp parallel for num_threads(nt) schedule(static, 1)
  for (int t = 0; t < nt; ++t) {
    const int64_t begin = n * t / nt, end = n * (t + 1) / nt;
    if (begin < end) fn(t, begin, end);
  }
  return nt;
}

}  // namespace cvd::cpu
