// OpenMP f32 kernel of reduce_sum, accumulated in double. The dims of x are coalesced into
// alternating kept / reduced groups; the innermost group decides the loop:
//   innermost reduced (sum over W, over H*W keeping C, over everything): each output sums
//     contiguous runs; parallel over outputs, or over runs with per-thread partial sums when
//     there are too few outputs to occupy the threads;
//   innermost kept (sum over N, over rows of a matrix): vectors of the row are accumulated;
//     parallel over (output row, 256-element chunk), or over the reduced rows with per-thread
//     partial rows when there are too few chunks.
#include <algorithm>
#include <cstring>
#include <vector>

#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

double contiguous_sum(const float* p, int64_t n) {
  double s = 0.0;
#pragma omp simd reduction(+ : s)
  for (int64_t i = 0; i < n; ++i) s += static_cast<double>(p[i]);
  return s;
}

// Element offsets of every multi-index over `sizes` (row-major) with the given strides.
std::vector<int64_t> offset_table(const std::vector<int64_t>& sizes,
                                  const std::vector<int64_t>& strides) {
  int64_t n = 1;
  for (int64_t s : sizes) n *= s;
  std::vector<int64_t> table(static_cast<size_t>(n));
  std::vector<int64_t> index(sizes.size(), 0);
  int64_t off = 0;
  for (int64_t i = 0; i < n; ++i) {
    table[static_cast<size_t>(i)] = off;
    for (int d = static_cast<int>(sizes.size()) - 1; d >= 0; --d) {
      off += strides[d];
      if (++index[d] < sizes[d]) break;
      off -= index[d] * strides[d];
      index[d] = 0;
    }
  }
  return table;
}

struct Group {
  int64_t size;
  bool reduced;
};

// Sums of contiguous runs of length `len`: y[o] = sum_r sum_l x[kept[o] + red[r] + l].
void reduce_inner_runs(const float* x, float* y, const std::vector<int64_t>& kept,
                       const std::vector<int64_t>& red, int64_t len) {
  const int64_t nk = static_cast<int64_t>(kept.size()), nr = static_cast<int64_t>(red.size());
  const int threads = max_threads();
  if (nk >= 4 * threads || nk * nr * len < kParallelGrain) {
    parallel_ranges(nk, nr * len, [&](int64_t b, int64_t e) {
      for (int64_t o = b; o < e; ++o) {
        double s = 0.0;
        for (int64_t r = 0; r < nr; ++r) s += contiguous_sum(x + kept[o] + red[r], len);
        y[o] = static_cast<float>(s);
      }
    });
    return;
  }
  // Few outputs: split the runs (and long runs into pieces) across threads, partial sums each.
  constexpr int64_t kMinPiece = 4096;
  int64_t pieces = 1;
  if (nr < 4 * threads && len >= 2 * kMinPiece) {
    pieces = std::min((4 * threads + nr - 1) / nr, len / kMinPiece);
  }
  const int64_t piece_len = (len + pieces - 1) / pieces;
  std::vector<double> partial(static_cast<size_t>(threads * nk), 0.0);
  const int used = parallel_ranges_indexed(
      nr * pieces, nk * piece_len, threads, [&](int t, int64_t b, int64_t e) {
        double* part = partial.data() + t * nk;
        for (int64_t task = b; task < e; ++task) {
          const int64_t r = task / pieces, start = (task % pieces) * piece_len;
          const int64_t n = std::min(piece_len, len - start);
          for (int64_t o = 0; o < nk; ++o) {
            part[o] += contiguous_sum(x + kept[o] + red[r] + start, n);
          }
        }
      });
  for (int64_t o = 0; o < nk; ++o) {
    double s = 0.0;
    for (int t = 0; t < used; ++t) s += partial[t * nk + o];
    y[o] = static_cast<float>(s);
  }
}

// Sums of rows: y[o * len + l] = sum_r x[kept[o] + red[r] + l].
void reduce_outer_rows(const float* x, float* y, const std::vector<int64_t>& kept,
                       const std::vector<int64_t>& red, int64_t len) {
  const int64_t nk = static_cast<int64_t>(kept.size()), nr = static_cast<int64_t>(red.size());
  const int threads = max_threads();
  constexpr int64_t kChunk = 256;
  const int64_t chunks = (len + kChunk - 1) / kChunk;
  if (nk * chunks >= 2 * threads || nk * nr * len < kParallelGrain || nr < 2 * threads) {
    parallel_ranges(nk * chunks, nr * std::min(len, kChunk), [&](int64_t b, int64_t e) {
      double acc[kChunk];
      for (int64_t task = b; task < e; ++task) {
        const int64_t o = task / chunks, start = (task % chunks) * kChunk;
        const int64_t n = std::min(kChunk, len - start);
        std::fill(acc, acc + n, 0.0);
        for (int64_t r = 0; r < nr; ++r) {
          const float* p = x + kept[o] + red[r] + start;
          for (int64_t l = 0; l < n; ++l) acc[l] += static_cast<double>(p[l]);
        }
        float* out = y + o * len + start;
        for (int64_t l = 0; l < n; ++l) out[l] = static_cast<float>(acc[l]);
      }
    });
    return;
  }
  // Few output chunks: split the reduced rows across threads, a partial output each.
  const int64_t ny = nk * len;
  std::vector<double> partial(static_cast<size_t>(threads * ny), 0.0);
  const int used = parallel_ranges_indexed(nr, ny, threads, [&](int t, int64_t b, int64_t e) {
    double* part = partial.data() + t * ny;
    for (int64_t r = b; r < e; ++r) {
      for (int64_t o = 0; o < nk; ++o) {
        const float* p = x + kept[o] + red[r];
        double* acc = part + o * len;
        for (int64_t l = 0; l < len; ++l) acc[l] += static_cast<double>(p[l]);
      }
    }
  });
  parallel_ranges(ny, used, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      double s = 0.0;
      for (int t = 0; t < used; ++t) s += partial[t * ny + i];
      y[i] = static_cast<float>(s);
    }
  });
}

// in {x (contiguous)}, out {y}: x summed over ReduceParams::dims, which are removed.
void reduce_sum(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  CVD_ASSERT(x.defined() && x.device().is_cpu() && x.dtype() == DType::f32 && x.is_contiguous());
  CVD_ASSERT(y.defined() && y.device().is_cpu() && y.dtype() == DType::f32 && y.is_contiguous());
  const std::vector<int>& dims = a.p<ReduceParams>().dims;
  std::vector<bool> reduced(static_cast<size_t>(x.dim()), false);
  for (size_t i = 0; i < dims.size(); ++i) {
    CVD_ASSERT(dims[i] >= 0 && dims[i] < x.dim() && (i == 0 || dims[i] > dims[i - 1]));
    reduced[static_cast<size_t>(dims[i])] = true;
  }
  int64_t kept_numel = 1;
  std::vector<Group> groups;  // coalesced, size-1 dims dropped, outermost first
  for (int d = 0; d < x.dim(); ++d) {
    const int64_t s = x.shape()[d];
    if (!reduced[d]) kept_numel *= s;
    if (s == 1) continue;
    if (!groups.empty() && groups.back().reduced == reduced[d]) {
      groups.back().size *= s;
    } else {
      groups.push_back({s, reduced[d]});
    }
  }
  CVD_ASSERT(y.numel() == kept_numel);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  if (y.numel() == 0) return;
  if (x.numel() == 0) {
    std::fill(yp, yp + y.numel(), 0.0f);
    return;
  }
  const bool any_reduced =
      std::any_of(groups.begin(), groups.end(), [](const Group& g) { return g.reduced; });
  if (!any_reduced) {  // only size-1 dims were reduced: a copy
    std::memcpy(yp, xp, static_cast<size_t>(y.numel()) * sizeof(float));
    return;
  }
  const Group inner = groups.back();
  std::vector<int64_t> kept_sizes, kept_strides, red_sizes, red_strides;
  int64_t stride = inner.size;
  for (int i = static_cast<int>(groups.size()) - 2; i >= 0; --i) {
    auto& sizes = groups[i].reduced ? red_sizes : kept_sizes;
    auto& strides = groups[i].reduced ? red_strides : kept_strides;
    sizes.insert(sizes.begin(), groups[i].size);
    strides.insert(strides.begin(), stride);
    stride *= groups[i].size;
  }
  const std::vector<int64_t> kept = offset_table(kept_sizes, kept_strides);
  const std::vector<int64_t> red = offset_table(red_sizes, red_strides);
  if (inner.reduced) {
    reduce_inner_runs(xp, yp, kept, red, inner.size);
  } else {
    reduce_outer_rows(xp, yp, kept, red, inner.size);
  }
}

}  // namespace

void register_reduce_kernels(KernelRegistry& r) {
  r.add(OpId::reduce_sum, DeviceType::cpu, DType::f32, reduce_sum, "openmp");
}

}  // namespace cvd::cpu
